//! IPC's mollifier for nearly parallel edges.
//!
//! The edge-edge distance is not smooth where the edges turn parallel (the closest-feature
//! type jumps). IPC multiplies the edge-edge barrier by `e_x(c)`, a C1 ramp in the squared
//! cross-product norm `c = |(ea1 - ea0) x (eb1 - eb0)|^2` that is zero for parallel edges and
//! one from `eps_x` on:
//! `e_x(c) = -c^2 / eps_x^2 + 2c / eps_x` for `c < eps_x`, `1` otherwise, with
//! `eps_x = 1e-3 |ea0 - ea1|^2 |eb0 - eb1|^2` at rest.

use super::kernels;
use super::reduced::{dot, sub, vertex};
use crate::energy::{Local, Want};

/// Fraction of the rest edges' squared lengths' product below which the mollifier acts.
pub const MOLLIFIER_FRACTION: f64 = 1e-3;

/// `eps_x` of the edges of `rest = [ea0, ea1, eb0, eb1]` (rest positions, 3D).
pub fn edge_edge_mollifier_threshold(rest: &[f64]) -> f64 {
    let v = [0, 1, 2, 3].map(|a| vertex(rest, 3, a));
    let (a, b) = (sub(v[0], v[1]), sub(v[2], v[3]));
    MOLLIFIER_FRACTION * dot(a, a) * dot(b, b)
}

/// `e_x(c)` for the squared cross norm `c`.
pub fn mollifier(c: f64, eps_x: f64) -> f64 {
    mollifier_derivatives(c, eps_x).0
}

/// `(e_x(c), e_x'(c), e_x''(c))`.
pub fn mollifier_derivatives(c: f64, eps_x: f64) -> (f64, f64, f64) {
    if c < eps_x {
        let t = c / eps_x;
        ((2.0 - t) * t, 2.0 * (1.0 - t) / eps_x, -2.0 / (eps_x * eps_x))
    } else {
        (1.0, 0.0, 0.0)
    }
}

/// `e_x` of the edges of `x = [ea0, ea1, eb0, eb1]` with its gradient and Hessian over the 12
/// dofs written into `out` as `want` asks.
pub fn edge_edge_mollifier(x: &[f64], eps_x: f64, want: Want, out: &mut Local) -> f64 {
    let v = [0, 1, 2, 3].map(|a| vertex(x, 3, a));
    let c = kernels::cross_squared_norm(sub(v[1], v[0]), sub(v[3], v[2]), want.hessian().is_some());
    let (m, dm, ddm) = mollifier_derivatives(c.value, eps_x);
    if want.gradient() {
        c.scatter(&[[-1.0, 1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 1.0]], 4, 3, want, out);
        if want.hessian().is_some() {
            for i in 0..12 {
                for j in 0..12 {
                    out.hess[i * 12 + j] = ddm * out.grad[i] * out.grad[j] + dm * out.hess[i * 12 + j];
                }
            }
        }
        out.grad[..12].iter_mut().for_each(|g| *g *= dm);
    }
    m
}
