//! The two full-space baselines for a Newton system `H d = -g` (`H` sparse symmetric
//! positive definite, its lower triangle in faer's CSC format): a sparse Cholesky
//! factorisation, and conjugate gradients with a block-Jacobi preconditioner. They solve
//! the system the adaptive model's Schur complement solver replaces, for comparing costs.

use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::SparseColMatRef;
use faer::{MatMut, Side};

use super::lower_csc::{check_lower, diagonal_blocks, symmetric_product};
use super::pcg::{self, check_blocks, BlockJacobi, PcgReport, PcgSettings};
use super::solve_error::{dimension, SolveError};

fn check<I: faer::Index>(h: SparseColMatRef<'_, I, f64>, g: &[f64]) -> Result<(), SolveError> {
    check_lower("H", h, h.nrows())?;
    if g.len() != h.nrows() {
        return Err(dimension("g", h.nrows(), g.len()));
    }
    if g.iter().any(|v| !v.is_finite()) {
        return Err(SolveError::NonFinite("gradient"));
    }
    Ok(())
}

/// `d = -H^{-1} g` by faer's sparse Cholesky factorisation (symbolic and numeric).
pub fn cholesky_direction<I: faer::Index>(h: SparseColMatRef<'_, I, f64>, g: &[f64]) -> Result<Vec<f64>, SolveError> {
    check(h, g)?;
    let n = h.nrows();
    let mut d: Vec<f64> = g.iter().map(|v| -v).collect();
    if n == 0 {
        return Ok(d);
    }
    let symbolic = SymbolicLlt::try_new(h.symbolic(), Side::Lower).map_err(|_| SolveError::NotPositiveDefinite("H"))?;
    let llt = Llt::try_new_with_symbolic(symbolic, h, Side::Lower).map_err(|_| SolveError::NotPositiveDefinite("H"))?;
    llt.solve_in_place(MatMut::from_column_major_slice_mut(&mut d, n, 1));
    Ok(d)
}

/// Whether faer's sparse Cholesky factorisation of `H` succeeds (`H` positive definite).
pub fn factors<I: faer::Index>(h: SparseColMatRef<'_, I, f64>) -> bool {
    SymbolicLlt::try_new(h.symbolic(), Side::Lower)
        .is_ok_and(|symbolic| Llt::try_new_with_symbolic(symbolic, h, Side::Lower).is_ok())
}

/// `d = -H^{-1} g` by conjugate gradients preconditioned with the inverses of `H`'s
/// `settings.block`-sized diagonal blocks.
pub fn pcg_direction<I: faer::Index>(
    h: SparseColMatRef<'_, I, f64>,
    g: &[f64],
    settings: &PcgSettings,
) -> Result<(Vec<f64>, PcgReport), SolveError> {
    check(h, g)?;
    check_blocks("H", h.nrows(), settings)?;
    let precond = BlockJacobi::new("H", &diagonal_blocks(h, settings.block), settings.block)?;
    let rhs: Vec<f64> = g.iter().map(|v| -v).collect();
    pcg::solve("H", |v, out| symmetric_product(h, v, out), &precond, &rhs, settings)
}
