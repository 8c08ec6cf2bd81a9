//! Preconditioned conjugate gradients with a block-Jacobi preconditioner, for matrix-free
//! symmetric positive definite operators (the Schur complement of the adaptive system, or
//! a full-space Hessian).

use nalgebra::DMatrix;

use super::solve_error::{dimension, SolveError};

/// Settings of a conjugate-gradient solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PcgSettings {
    /// Stop when `|b - A x| <= tolerance |b|` (the recursively updated residual).
    pub tolerance: f64,
    /// Iteration cap; `None` caps at twice the system size (exact arithmetic needs at most
    /// the size; the rest allows for round-off).
    pub max_iterations: Option<usize>,
    /// Size of the preconditioner's diagonal blocks (the coordinates per vertex).
    pub block: usize,
}

impl Default for PcgSettings {
    /// Relative tolerance 1e-5 (the method's choice), 3 x 3 blocks.
    fn default() -> Self {
        PcgSettings {
            tolerance: 1e-5,
            max_iterations: None,
            block: 3,
        }
    }
}

/// What a conjugate-gradient solve did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PcgReport {
    /// Iterations taken (operator products, not counting the final residual check).
    pub iterations: usize,
    /// `|b - A x| / |b|` of the returned `x`, recomputed from the operator (0 for `b = 0`).
    pub relative_residual: f64,
    /// Whether the tolerance was met before the iteration cap.
    pub converged: bool,
}

/// The inverses of the diagonal blocks of a symmetric positive definite matrix.
#[derive(Clone, Debug)]
pub struct BlockJacobi {
    block: usize,
    /// Row-major inverse of each block, one after the other.
    inverses: Vec<f64>,
}

impl BlockJacobi {
    /// Inverts the row-major `block x block` blocks `blocks` (one after the other) of
    /// `matrix` (named in errors).
    pub(crate) fn new(matrix: &'static str, blocks: &[f64], block: usize) -> Result<BlockJacobi, SolveError> {
        let bb = block * block;
        let mut inverses = Vec::with_capacity(blocks.len());
        for (k, b) in blocks.chunks_exact(bb).enumerate() {
            if b.iter().any(|v| !v.is_finite()) {
                return Err(SolveError::NonFinite(matrix));
            }
            let inv = DMatrix::from_row_slice(block, block, b)
                .cholesky()
                .ok_or(SolveError::PreconditionerBlock { matrix, block: k })?
                .inverse();
            inverses.extend(inv.transpose().iter());
        }
        Ok(BlockJacobi { block, inverses })
    }

    /// `z = P^{-1} r`.
    fn apply(&self, r: &[f64], z: &mut [f64]) {
        let b = self.block;
        for ((inv, r), z) in self
            .inverses
            .chunks_exact(b * b)
            .zip(r.chunks_exact(b))
            .zip(z.chunks_exact_mut(b))
        {
            for i in 0..b {
                z[i] = (0..b).map(|j| inv[i * b + j] * r[j]).sum();
            }
        }
    }
}

/// Checks that a system of size `n` splits into blocks of `settings.block`.
pub(crate) fn check_blocks(what: &'static str, n: usize, settings: &PcgSettings) -> Result<(), SolveError> {
    if settings.block == 0 || !n.is_multiple_of(settings.block) {
        return Err(dimension(
            what,
            format!("a size divisible by the block size {}", settings.block),
            n,
        ));
    }
    Ok(())
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

/// Solves `A x = b` from `x = 0` by conjugate gradients preconditioned with `precond`;
/// `apply(v, out)` writes `A v` into `out`. `matrix` names the operator in errors.
pub(crate) fn solve(
    matrix: &'static str,
    mut apply: impl FnMut(&[f64], &mut [f64]),
    precond: &BlockJacobi,
    b: &[f64],
    settings: &PcgSettings,
) -> Result<(Vec<f64>, PcgReport), SolveError> {
    let n = b.len();
    let mut x = vec![0.0; n];
    if b.iter().any(|v| !v.is_finite()) {
        return Err(SolveError::NonFinite("right-hand side"));
    }
    let b_norm = norm(b);
    if b_norm == 0.0 {
        let report = PcgReport {
            iterations: 0,
            relative_residual: 0.0,
            converged: true,
        };
        return Ok((x, report));
    }
    let cap = settings.max_iterations.unwrap_or(2 * n);
    let target = settings.tolerance * b_norm;
    let mut r = b.to_vec();
    let mut z = vec![0.0; n];
    precond.apply(&r, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let mut ap = vec![0.0; n];
    let mut iterations = 0;
    let mut converged = norm(&r) <= target;
    while !converged && iterations < cap {
        apply(&p, &mut ap);
        let curvature = dot(&p, &ap);
        if !curvature.is_finite() {
            return Err(SolveError::NonFinite(matrix));
        }
        if curvature <= 0.0 {
            return Err(SolveError::Indefinite {
                matrix,
                iteration: iterations,
                curvature,
            });
        }
        let alpha = rz / curvature;
        for i in 0..n {
            x[i] += alpha * p[i];
            r[i] -= alpha * ap[i];
        }
        iterations += 1;
        converged = norm(&r) <= target;
        if converged {
            break;
        }
        precond.apply(&r, &mut z);
        let rz_next = dot(&r, &z);
        let beta = rz_next / rz;
        rz = rz_next;
        for i in 0..n {
            p[i] = z[i] + beta * p[i];
        }
    }
    apply(&x, &mut ap);
    let residual = b.iter().zip(&ap).map(|(b, ax)| (b - ax) * (b - ax)).sum::<f64>().sqrt();
    let report = PcgReport {
        iterations,
        relative_residual: residual / b_norm,
        converged,
    };
    Ok((x, report))
}
