//! Symmetric sparse matrices stored as their lower triangle in faer's compressed sparse
//! column format (as the solver's Hessian assembly stores them): checks, the full
//! symmetric product, and the dense diagonal blocks.

use faer::sparse::SparseColMatRef;

use super::solve_error::{dimension, SolveError};

/// Checks that `m` is square of size `n` with finite values and no entry above the
/// diagonal.
pub(crate) fn check_lower<I: faer::Index>(
    name: &'static str,
    m: SparseColMatRef<'_, I, f64>,
    n: usize,
) -> Result<(), SolveError> {
    if m.nrows() != n || m.ncols() != n {
        return Err(dimension(
            name,
            format!("{n} x {n}"),
            format!("{} x {}", m.nrows(), m.ncols()),
        ));
    }
    for c in 0..n {
        if let Some(r) = m.symbolic().row_idx_of_col(c).find(|&r| r < c) {
            return Err(SolveError::UpperEntry {
                matrix: name,
                row: r,
                col: c,
            });
        }
        if m.val_of_col(c).iter().any(|v| !v.is_finite()) {
            return Err(SolveError::NonFinite(name));
        }
    }
    Ok(())
}

/// `y = M x` for the symmetric `M` whose lower triangle `m` stores.
pub(crate) fn symmetric_product<I: faer::Index>(m: SparseColMatRef<'_, I, f64>, x: &[f64], y: &mut [f64]) {
    y.fill(0.0);
    for c in 0..m.ncols() {
        let xc = x[c];
        let mut acc = 0.0;
        for (r, &v) in m.symbolic().row_idx_of_col(c).zip(m.val_of_col(c)) {
            y[r] += v * xc;
            if r != c {
                acc += v * x[r];
            }
        }
        y[c] += acc;
    }
}

/// `Y = M X` for the symmetric `M` whose lower triangle `m` stores and `k` columns `X`, both
/// row-major (`x[r * k + j]`): one pass over `m` serves every column, where `k` calls of
/// [`symmetric_product`] would read it `k` times.
pub(crate) fn symmetric_block_product<I: faer::Index>(
    m: SparseColMatRef<'_, I, f64>,
    x: &[f64],
    k: usize,
    y: &mut [f64],
) {
    y.fill(0.0);
    let mut acc = vec![0.0; k];
    for c in 0..m.ncols() {
        let xc = &x[c * k..(c + 1) * k];
        acc.fill(0.0);
        for (r, &v) in m.symbolic().row_idx_of_col(c).zip(m.val_of_col(c)) {
            // Entries of the pattern the assembly left zero (the elastic stencils the
            // adaptive model approximates) add nothing.
            if v == 0.0 {
                continue;
            }
            for (yr, xj) in y[r * k..(r + 1) * k].iter_mut().zip(xc) {
                *yr += v * xj;
            }
            if r != c {
                for (a, xr) in acc.iter_mut().zip(&x[r * k..(r + 1) * k]) {
                    *a += v * xr;
                }
            }
        }
        for (yc, a) in y[c * k..(c + 1) * k].iter_mut().zip(&acc) {
            *yc += a;
        }
    }
}

/// The dense `block x block` diagonal blocks of the symmetric matrix `m` stores (size a
/// multiple of `block`), each row-major, one after the other.
pub(crate) fn diagonal_blocks<I: faer::Index>(m: SparseColMatRef<'_, I, f64>, block: usize) -> Vec<f64> {
    let n = m.ncols();
    let mut out = vec![0.0; n * block];
    for c in 0..n {
        let k = c / block;
        let lo = k * block;
        for (r, &v) in m.symbolic().row_idx_of_col(c).zip(m.val_of_col(c)) {
            if r < lo + block {
                let (i, j) = (r - lo, c - lo);
                out[k * block * block + i * block + j] = v;
                out[k * block * block + j * block + i] = v;
            }
        }
    }
    out
}
