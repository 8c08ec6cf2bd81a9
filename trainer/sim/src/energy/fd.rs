//! Central finite-difference checks of stencil gradients and Hessians, shared by the
//! tests of every energy kernel.

use super::{Local, StencilEnergy, Want, MAX_DOF};

/// Largest relative mismatch between analytic and finite-difference derivatives.
#[derive(Debug, Clone, Copy)]
pub struct FdReport {
    /// max |g - g_fd| / max(1, |g|_inf) over entries.
    pub grad_error: f64,
    /// max |H - H_fd| / max(1, |H|_inf) over entries.
    pub hess_error: f64,
}

/// Compares the analytic gradient (from values) and exact Hessian (from gradients) of
/// stencil `s` at local positions `x` with central differences of step `h`.
pub fn check_stencil(energy: &dyn StencilEnergy, s: usize, x: &[f64], h: f64) -> FdReport {
    let n = x.len();
    assert!(n <= MAX_DOF);
    let mut out = Local::default();
    energy.eval(s, x, Want::Hessian { project: false }, &mut out);
    let grad = out.grad;
    let hess = out.hess;
    let mut xp = [0.0; MAX_DOF];
    xp[..n].copy_from_slice(x);
    let mut scratch = Local::default();
    let mut grad_fd = [0.0; MAX_DOF];
    let mut hess_fd = [0.0; MAX_DOF * MAX_DOF];
    for k in 0..n {
        xp[k] = x[k] + h;
        let ep = energy.eval(s, &xp[..n], Want::Gradient, &mut scratch);
        let gp = scratch.grad;
        xp[k] = x[k] - h;
        let em = energy.eval(s, &xp[..n], Want::Gradient, &mut scratch);
        let gm = scratch.grad;
        xp[k] = x[k];
        grad_fd[k] = (ep - em) / (2.0 * h);
        for r in 0..n {
            hess_fd[r * n + k] = (gp[r] - gm[r]) / (2.0 * h);
        }
    }
    let gscale = grad[..n].iter().fold(1.0f64, |m, v| m.max(v.abs()));
    let hscale = hess[..n * n].iter().fold(1.0f64, |m, v| m.max(v.abs()));
    let grad_error = (0..n).map(|k| (grad[k] - grad_fd[k]).abs()).fold(0.0, f64::max) / gscale;
    let hess_error = (0..n * n).map(|k| (hess[k] - hess_fd[k]).abs()).fold(0.0, f64::max) / hscale;
    FdReport { grad_error, hess_error }
}

/// Asserts that every stencil of `energy` passes [`check_stencil`] at the positions `x`
/// (global, flat) within `tol`, naming the energy and stencil on failure.
pub fn assert_all_stencils(energy: &dyn StencilEnergy, x: &[f64], h: f64, tol: f64) {
    let mut xl = [0.0; MAX_DOF];
    for s in 0..energy.len() {
        let n = super::gather(energy, s, x, &mut xl);
        let r = check_stencil(energy, s, &xl[..n], h);
        assert!(
            r.grad_error < tol && r.hess_error < tol,
            "{} stencil {s}: gradient error {:.3e}, Hessian error {:.3e} (tol {tol:e})",
            energy.name(),
            r.grad_error,
            r.hess_error
        );
    }
}
