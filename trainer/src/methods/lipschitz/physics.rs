//! The potential's derivatives at one decoded state that the Lipschitz loss's gradient needs,
//! from the scene's stencil kernels (one definition of each energy):
//!
//! - the gradient `g = dP/dx`;
//! - Hessian-vector products `H u` with the exact (unprojected) stencil Hessians, kept from
//!   one evaluation;
//! - the third derivative contracted twice, `D^3 P[u, u, .]`, as the central difference
//!   `(H(x + h u) - H(x - h u)) u / (2 h)` of those same Hessians (exact up to `O(h^2)`; the
//!   kernels stop at second derivatives).
//!
//! The potentials are usually cubature approximations (few stencils), so every stencil
//! Hessian is kept.

use mochi_sim::energy::{gather, Local, StencilEnergy, Want, MAX_DOF};

/// One stencil's Hessian at the state.
struct StencilHessian {
    term: usize,
    stencil: usize,
    /// The state index of each of the stencil's local coordinates.
    dofs: Vec<usize>,
    hess: Vec<f64>,
}

/// The potential's gradient and stencil Hessians at one state.
pub(crate) struct PotentialAt<'a> {
    potentials: &'a [&'a dyn StencilEnergy],
    x: Vec<f64>,
    /// `dP/dx` (world layout).
    pub grad: Vec<f64>,
    /// `P(x)`.
    pub value: f64,
    hessians: Vec<StencilHessian>,
}

impl<'a> PotentialAt<'a> {
    /// Evaluates `potentials` at `x` (`dim` per vertex).
    pub(crate) fn new(potentials: &'a [&'a dyn StencilEnergy], dim: usize, x: &[f64]) -> Self {
        let mut at = PotentialAt {
            potentials,
            x: x.to_vec(),
            grad: vec![0.0; x.len()],
            value: 0.0,
            hessians: Vec::new(),
        };
        let mut local = Local::default();
        let mut xl = [0.0; MAX_DOF];
        for (term, energy) in potentials.iter().enumerate() {
            for stencil in 0..energy.len() {
                let n = gather(*energy, stencil, x, &mut xl);
                at.value += energy.eval(stencil, &xl[..n], Want::Hessian { project: false }, &mut local);
                let dofs = local_dofs(energy.stencil(stencil), dim);
                for (&d, g) in dofs.iter().zip(&local.grad) {
                    at.grad[d] += g;
                }
                at.hessians.push(StencilHessian {
                    term,
                    stencil,
                    dofs,
                    hess: local.hess[..n * n].to_vec(),
                });
            }
        }
        at
    }

    /// `out = H u` (world layout).
    pub(crate) fn hessian_times(&self, u: &[f64], out: &mut [f64]) {
        out.fill(0.0);
        for h in &self.hessians {
            add_local_product(&h.dofs, &h.hess, u, 1.0, out);
        }
    }

    /// `out = D^3 P[u, u, .]` by the central difference of the stencil Hessians along `u`
    /// with step `h` (module documentation).
    pub(crate) fn third_times(&self, u: &[f64], h: f64, out: &mut [f64]) {
        out.fill(0.0);
        let mut local = Local::default();
        let mut xl = [0.0; MAX_DOF];
        for sh in &self.hessians {
            let energy = self.potentials[sh.term];
            for (sign, weight) in [(1.0, 0.5 / h), (-1.0, -0.5 / h)] {
                let n = gather(energy, sh.stencil, &self.x, &mut xl);
                for (x, &k) in xl.iter_mut().zip(&sh.dofs) {
                    *x += sign * h * u[k];
                }
                energy.eval(sh.stencil, &xl[..n], Want::Hessian { project: false }, &mut local);
                add_local_product(&sh.dofs, &local.hess[..n * n], u, weight, out);
            }
        }
    }
}

/// The state index of each local coordinate of a stencil over `verts` (`dim` per vertex).
fn local_dofs(verts: &[usize], dim: usize) -> Vec<usize> {
    verts.iter().flat_map(|&v| (0..dim).map(move |i| v * dim + i)).collect()
}

/// `out[dofs] += weight * hess * u[dofs]` for one stencil's local Hessian.
fn add_local_product(dofs: &[usize], hess: &[f64], u: &[f64], weight: f64, out: &mut [f64]) {
    let n = dofs.len();
    for (row, &i) in hess.chunks_exact(n).zip(dofs) {
        let sum: f64 = row.iter().zip(dofs).map(|(h, &k)| h * u[k]).sum();
        out[i] += weight * sum;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::samples::fixtures::tiny_beam;

    #[test]
    fn products_match_finite_differences_of_the_gradient() {
        let beam = tiny_beam();
        let pots: Vec<&dyn StencilEnergy> = beam.problem.simulator.potentials().iter().map(|p| p.as_ref()).collect();
        let x = beam.sequences[0].trajectory.positions[8].clone();
        let n = x.len();
        let u: Vec<f64> = (0..n).map(|k| ((k * 7919) % 13) as f64 / 13.0 - 0.5).collect();
        let at = PotentialAt::new(&pots, 3, &x);
        let shifted = |t: f64| {
            let xs: Vec<f64> = x.iter().zip(&u).map(|(a, b)| a + t * b).collect();
            PotentialAt::new(&pots, 3, &xs)
        };
        let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
        // H u against the difference of gradients.
        let eps = 1e-6;
        let (p, m) = (shifted(eps), shifted(-eps));
        let fd: Vec<f64> = p.grad.iter().zip(&m.grad).map(|(a, b)| (a - b) / (2.0 * eps)).collect();
        let mut hu = vec![0.0; n];
        at.hessian_times(&u, &mut hu);
        let err: Vec<f64> = hu.iter().zip(&fd).map(|(a, b)| a - b).collect();
        assert!(norm(&err) < 1e-5 * norm(&hu), "H u: {} vs {}", norm(&err), norm(&hu));
        // D^3[u, u] against the second difference of the gradient along u (gradients only).
        let eps = 1e-3;
        let (p, m) = (shifted(eps), shifted(-eps));
        let fd: Vec<f64> = (0..n)
            .map(|k| (p.grad[k] - 2.0 * at.grad[k] + m.grad[k]) / (eps * eps))
            .collect();
        let mut third = vec![0.0; n];
        at.third_times(&u, 1e-5, &mut third);
        let err: Vec<f64> = third.iter().zip(&fd).map(|(a, b)| a - b).collect();
        assert!(norm(&third) > 0.0);
        assert!(
            norm(&err) < 1e-3 * norm(&third),
            "D3: {} vs {}",
            norm(&err),
            norm(&third)
        );
    }
}
