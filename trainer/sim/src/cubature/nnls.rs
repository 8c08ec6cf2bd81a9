//! Non-negative least squares, `min ||C x - d||` over `x >= 0`, by the active-set method of
//! Lawson and Hanson ("Solving Least Squares Problems", 1974, chapter 23).
//!
//! Written here because no maintained Rust crate fits: the one NNLS crate on crates.io
//! (`nnls` 0.5, a port of the Fortran routine) works on `ndarray` arrays, which this crate
//! does not otherwise use, panics on empty input and cannot start from a previous solution,
//! which the greedy selection needs: each of its steps re-solves on the previous columns
//! plus one, and starting from the previous weights costs one or two solves instead of one
//! per positive weight. The unconstrained subproblems use nalgebra's Householder QR of the
//! passive columns, falling back to a truncated SVD when those are numerically dependent.

use nalgebra::{DMatrix, DVector};

/// Relative threshold below which a singular value counts as zero in the SVD fallback,
/// and below which a diagonal entry of the QR factor counts as zero.
const RANK_EPS: f64 = 1e-12;

/// Solves `min ||c x - d||` over `x >= 0`, starting from `start` (clamped to `>= 0`;
/// zeros when `None`), whose positive entries form the initial passive set.
///
/// Stops when no zero weight's residual correlation `c_j . (d - c x)` exceeds `1e-12`
/// times `max_j ||c_j|| * ||d||` (the Karush-Kuhn-Tucker conditions up to rounding), or
/// after `3 * cols + 10` outer steps.
pub(crate) fn nnls(c: &DMatrix<f64>, d: &DVector<f64>, start: Option<&DVector<f64>>) -> DVector<f64> {
    let n = c.ncols();
    let mut x = match start {
        Some(s) => s.map(|v| if v > 0.0 { v } else { 0.0 }),
        None => DVector::zeros(n),
    };
    let mut passive: Vec<bool> = x.iter().map(|&v| v > 0.0).collect();
    let max_norm = (0..n).map(|j| c.column(j).norm()).fold(0.0, f64::max);
    let tol = 1e-12 * max_norm * d.norm();
    // A warm start is feasible but not yet optimal on its passive set: settle it first.
    if passive.iter().any(|&p| p) {
        settle(c, d, &mut x, &mut passive, None);
    }
    for _ in 0..3 * n + 10 {
        let w = c.tr_mul(&(d - c * &x));
        let best = (0..n)
            .filter(|&j| !passive[j] && w[j] > tol)
            .max_by(|&a, &b| w[a].total_cmp(&w[b]));
        let Some(t) = best else { break };
        passive[t] = true;
        if !settle(c, d, &mut x, &mut passive, Some(t)) {
            // Rounding made the entering weight non-positive: the current point is optimal
            // to working precision, and trying again would cycle.
            passive[t] = false;
            break;
        }
    }
    x
}

/// The inner loop: solves the unconstrained problem on the passive set and steps back
/// from it towards the current (feasible) point until the solution is positive, moving the
/// weights that reach zero out of the passive set.
///
/// With `entering = Some(t)`, returns `false` (leaving `x` unchanged) when the first solve
/// gives `t` a non-positive weight; otherwise returns `true`.
fn settle(
    c: &DMatrix<f64>,
    d: &DVector<f64>,
    x: &mut DVector<f64>,
    passive: &mut [bool],
    entering: Option<usize>,
) -> bool {
    let n = c.ncols();
    for solve in 0..3 * n + 10 {
        let cols: Vec<usize> = (0..n).filter(|&j| passive[j]).collect();
        if cols.is_empty() {
            x.fill(0.0);
            return true;
        }
        let z = least_squares(c, d, &cols);
        if let (0, Some(t)) = (solve, entering) {
            if cols.iter().zip(z.iter()).any(|(&j, &v)| j == t && v <= 0.0) {
                return false;
            }
        }
        if z.iter().all(|&v| v > 0.0) {
            x.fill(0.0);
            for (&j, &v) in cols.iter().zip(z.iter()) {
                x[j] = v;
            }
            return true;
        }
        // The largest step from x towards z that keeps every weight non-negative; the weight
        // that limits it reaches zero and leaves the passive set.
        let mut alpha = 1.0_f64;
        let mut limiting = cols[0];
        for (&j, &v) in cols.iter().zip(z.iter()) {
            if v <= 0.0 {
                let ratio = if x[j] > 0.0 { x[j] / (x[j] - v) } else { 0.0 };
                if ratio <= alpha {
                    alpha = ratio;
                    limiting = j;
                }
            }
        }
        for (&j, &v) in cols.iter().zip(z.iter()) {
            x[j] += alpha * (v - x[j]);
            if j == limiting || x[j] <= 0.0 {
                x[j] = 0.0;
                passive[j] = false;
            }
        }
    }
    true
}

/// Unconstrained least squares on the columns `cols` of `c`: QR when the columns are
/// independent to working precision, the truncated SVD (minimum-norm solution) otherwise.
fn least_squares(c: &DMatrix<f64>, d: &DVector<f64>, cols: &[usize]) -> DVector<f64> {
    let sub = c.select_columns(cols);
    if cols.len() <= sub.nrows() {
        let qr = sub.clone().qr();
        let r = qr.r();
        let diagonal_max = r.diagonal().amax();
        if diagonal_max > 0.0 && r.diagonal().iter().all(|v| v.abs() > RANK_EPS * diagonal_max) {
            if let Some(z) = r.solve_upper_triangular(&qr.q().tr_mul(d)) {
                if z.iter().all(|v| v.is_finite()) {
                    return z;
                }
            }
        }
    }
    let svd = sub.svd(true, true);
    let eps = RANK_EPS * svd.singular_values.amax();
    svd.solve(d, eps).unwrap_or_else(|_| DVector::zeros(cols.len()))
}
