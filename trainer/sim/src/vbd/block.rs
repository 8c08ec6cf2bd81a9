//! One vertex's block of the incremental potential: its gradient `g_i` and Hessian `H_i`
//! (the `dim x dim` diagonal block), summed over the stencils that touch the vertex from
//! each term's own stencil gradient and Hessian, and the block's Newton step.

use super::colouring::Adjacency;
use crate::energy::{gather, Local, StencilEnergy, Want, MAX_DOF};

/// A term of the incremental potential and its weight (inertia 1, the potentials `dt^2`).
pub type WeightedTerm<'a> = (&'a dyn StencilEnergy, f64);

/// Largest block: one vertex in 3D.
pub(super) const MAX_DIM: usize = 3;

/// Gradient and Hessian (row-major, `dim x dim`) of `sum_t w_t E_t` with respect to vertex
/// `v`'s coordinates at `x`, from the stencils `adjacency` lists for `v` (indices into
/// `terms`). With `project`, each stencil Hessian is first projected to PSD (the energies'
/// own projection), so the block is PSD too.
pub fn vertex_block(
    terms: &[WeightedTerm],
    adjacency: &Adjacency,
    dim: usize,
    v: usize,
    x: &[f64],
    project: bool,
) -> ([f64; MAX_DIM], [f64; MAX_DIM * MAX_DIM]) {
    let mut g = [0.0; MAX_DIM];
    let mut h = [0.0; MAX_DIM * MAX_DIM];
    let mut out = Local::default();
    let mut xl = [0.0; MAX_DOF];
    for inc in adjacency.of(v) {
        let (energy, weight) = terms[inc.term as usize];
        let s = inc.stencil as usize;
        let n = gather(energy, s, x, &mut xl);
        energy.eval(s, &xl[..n], Want::Hessian { project }, &mut out);
        let a = inc.local as usize * dim;
        for i in 0..dim {
            g[i] += weight * out.grad[a + i];
            for j in 0..dim {
                h[i * dim + j] += weight * out.hess[(a + i) * n + a + j];
            }
        }
    }
    (g, h)
}

/// The block Newton step `-H^{-1} g` of a symmetric `dim x dim` block, or `None` when the
/// block is not positive definite: its Cholesky factorisation meets a pivot at most
/// `1e-12` of the largest diagonal entry (the paper's "skip when `det H_i` is tiny", made
/// scale-free).
pub fn block_step(dim: usize, g: &[f64; MAX_DIM], h: &[f64; MAX_DIM * MAX_DIM]) -> Option<[f64; MAX_DIM]> {
    let scale = (0..dim).map(|i| h[i * dim + i].abs()).fold(0.0, f64::max);
    let floor = 1e-12 * scale;
    // Lower-triangular factor, row-major.
    let mut l = [0.0; MAX_DIM * MAX_DIM];
    for i in 0..dim {
        for j in 0..=i {
            let sum: f64 = (0..j).map(|k| l[i * dim + k] * l[j * dim + k]).sum();
            let a = 0.5 * (h[i * dim + j] + h[j * dim + i]) - sum;
            if i == j {
                if a.is_nan() || a <= floor {
                    return None;
                }
                l[i * dim + i] = a.sqrt();
            } else {
                l[i * dim + j] = a / l[j * dim + j];
            }
        }
    }
    // Solve L y = -g, then L^T dx = y.
    let mut y = [0.0; MAX_DIM];
    for i in 0..dim {
        let sum: f64 = (0..i).map(|k| l[i * dim + k] * y[k]).sum();
        y[i] = (-g[i] - sum) / l[i * dim + i];
    }
    let mut dx = [0.0; MAX_DIM];
    for i in (0..dim).rev() {
        let sum: f64 = (i + 1..dim).map(|k| l[k * dim + i] * dx[k]).sum();
        dx[i] = (y[i] - sum) / l[i * dim + i];
    }
    Some(dx)
}

/// Vertex `v`'s update: the Newton step of its block with the exact stencil Hessians when
/// that block is positive definite, else with every stencil Hessian projected to PSD
/// (as the Newton solver falls back to the projected Hessian), else no move. The flag tells
/// whether the exact block was not used.
pub fn vertex_step(
    terms: &[WeightedTerm],
    adjacency: &Adjacency,
    dim: usize,
    v: usize,
    x: &[f64],
) -> ([f64; MAX_DIM], bool) {
    let (g, h) = vertex_block(terms, adjacency, dim, v, x, false);
    if let Some(dx) = block_step(dim, &g, &h) {
        return (dx, false);
    }
    let (g, h) = vertex_block(terms, adjacency, dim, v, x, true);
    (block_step(dim, &g, &h).unwrap_or([0.0; MAX_DIM]), true)
}
