//! IPC's log barrier (Li et al. 2020) and its use on squared primitive distances.
//!
//! `b(d, dhat) = -(d - dhat)^2 ln(d / dhat)` for `0 < d < dhat`, zero from `dhat` on: C2 at
//! `dhat`, infinite at contact. As in IPC's toolkit, contact potentials apply it to
//! **squared** distances, `b(d^2, dhat^2)`, so every number here compares with the toolkit's
//! `BarrierPotential` (stiffness one, no minimum distance). Edge-edge stencils multiply it by
//! the mollifier `e_x` (see [`super::distance::mollifier`]).

use super::distance::{edge_edge_distance, edge_edge_mollifier};
use crate::energy::{Local, Want};

/// `b(d, dhat)`; zero for `d >= dhat`, infinite for `d <= 0`.
pub fn barrier(d: f64, dhat: f64) -> f64 {
    if d >= dhat {
        return 0.0;
    }
    if d <= 0.0 {
        return f64::INFINITY;
    }
    -(d - dhat) * (d - dhat) * (d / dhat).ln()
}

/// `b'(d) = (dhat - d) (2 ln(d / dhat) - dhat / d + 1)`; zero for `d >= dhat`, and zero at
/// contact (`d <= 0`), as in IPC's toolkit: there the value is infinite and no derivative
/// exists, and zero keeps every product with it (the contact force, the gradient and Hessian
/// of the potential, friction's normal force) a number instead of `0 * inf`.
pub fn barrier_first_derivative(d: f64, dhat: f64) -> f64 {
    if d >= dhat || d <= 0.0 {
        return 0.0;
    }
    (dhat - d) * (2.0 * (d / dhat).ln() - dhat / d + 1.0)
}

/// `b''(d) = (dhat / d + 3)(dhat / d - 1) - 2 ln(d / dhat)`; zero for `d >= dhat` and at
/// contact (`d <= 0`, as [`barrier_first_derivative`]).
pub fn barrier_second_derivative(d: f64, dhat: f64) -> f64 {
    if d >= dhat || d <= 0.0 {
        return 0.0;
    }
    let q = dhat / d;
    (q + 3.0) * (q - 1.0) - 2.0 * (d / dhat).ln()
}

/// Turns the derivatives of a squared distance `d2` held in `out` (first `n` gradient
/// entries, `n * n` Hessian entries, as `want` asks) into those of `b(d2, dhat^2)`, in place,
/// and returns the barrier's value. The Hessian is exact, or PSD-projected when
/// `want` asks so.
pub fn barrier_of_squared_distance(d2: f64, n: usize, dhat: f64, want: Want, out: &mut Local) -> f64 {
    let dhat2 = dhat * dhat;
    let (b, db, ddb) = (
        barrier(d2, dhat2),
        barrier_first_derivative(d2, dhat2),
        barrier_second_derivative(d2, dhat2),
    );
    if let Some(project) = want.hessian() {
        for i in 0..n {
            for j in 0..n {
                out.hess[i * n + j] = ddb * out.grad[i] * out.grad[j] + db * out.hess[i * n + j];
            }
        }
        if project {
            crate::energy::psd::project_psd(&mut out.hess, n);
        }
    }
    if want.gradient() {
        out.grad[..n].iter_mut().for_each(|g| *g *= db);
    }
    b
}

/// The mollified edge-edge barrier `e_x(c) b(d^2, dhat^2)` of `x = [ea0, ea1, eb0, eb1]`
/// with the rest-based threshold `eps_x`, and its derivatives over the 12 dofs.
pub fn edge_edge_barrier(x: &[f64], eps_x: f64, dhat: f64, want: Want, out: &mut Local) -> f64 {
    const N: usize = 12;
    let exact = match want {
        Want::Hessian { .. } => Want::Hessian { project: false },
        w => w,
    };
    let d2 = edge_edge_distance(x, exact, out);
    let b = barrier_of_squared_distance(d2, N, dhat, exact, out);
    if b == 0.0 {
        out.clear(N);
        return 0.0;
    }
    if b == f64::INFINITY {
        // At contact: infinite, with zero derivatives as the unmollified barrier's (the
        // mollifier's derivatives times an infinite barrier would be `0 * inf`).
        out.clear(N);
        return f64::INFINITY;
    }
    let mut mol = Local::default();
    let m = edge_edge_mollifier(x, eps_x, exact, &mut mol);
    if let Some(project) = want.hessian() {
        for i in 0..N {
            for j in 0..N {
                out.hess[i * N + j] = m * out.hess[i * N + j]
                    + b * mol.hess[i * N + j]
                    + mol.grad[i] * out.grad[j]
                    + out.grad[i] * mol.grad[j];
            }
        }
        if project {
            crate::energy::psd::project_psd(&mut out.hess, N);
        }
    }
    if want.gradient() {
        for i in 0..N {
            out.grad[i] = m * out.grad[i] + b * mol.grad[i];
        }
    }
    m * b
}

/// Magnitude of the contact force of a barrier with stiffness `kappa` at squared distance
/// `d2`: `-kappa db/dd = -2 kappa sqrt(d2) b'(d2, dhat^2)` (the lagged normal force of
/// friction).
pub fn barrier_force_magnitude(d2: f64, dhat: f64, kappa: f64) -> f64 {
    -kappa * 2.0 * d2.sqrt() * barrier_first_derivative(d2, dhat * dhat)
}
