//! The lagged friction potential of one contact stencil,
//! `D(v) = mu N f0(|tau|)` with `tau = T^T Gamma v`, and its gradient and Hessian.
//!
//! With `P = T^T Gamma` (`(dim - 1) x n`):
//! `grad D = mu N f1(|tau|) / |tau| P^T tau`,
//! `hess D = mu N P^T M P`, `M = f1(|tau|)/|tau| I + (f2(|tau|)|tau| - f1(|tau|)) / |tau|^3 tau tau^T`
//! (`M = 2 / eps_v I` at `tau = 0`). `M` is positive semi-definite in exact arithmetic (its
//! eigenvalues are `f1/|tau|` across and `f2` along `tau`); the projected Hessian clamps
//! `M`'s eigenvalues, which removes round-off and keeps `P^T M P` PSD.

use super::closest_point::RelativeVelocity;
use super::smoothing::{f0, f1_over_x, f2_x_minus_f1_over_x3};
use super::tangent_basis::TangentBasis;
use crate::energy::{Local, Want};

/// The lagged data of one friction stencil.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrictionStencil {
    /// Lagged tangent basis.
    pub basis: TangentBasis,
    /// Lagged relative-velocity weights (from the lagged closest point).
    pub relative: RelativeVelocity,
    /// Lagged normal force magnitude `N`.
    pub normal_force: f64,
    /// Friction coefficient `mu`.
    pub mu: f64,
}

impl FrictionStencil {
    /// Number of local dofs.
    pub fn dofs(&self) -> usize {
        self.relative.verts * self.basis.dim
    }

    /// Row `k` of `P = T^T Gamma` (`n` entries used).
    fn projection_row(&self, k: usize) -> [f64; 12] {
        let dim = self.basis.dim;
        let mut row = [0.0; 12];
        for a in 0..self.relative.verts {
            for i in 0..dim {
                row[a * dim + i] = self.relative.weights[a] * self.basis.columns[k][i];
            }
        }
        row
    }

    /// The tangential relative velocity `tau = T^T Gamma v` (`dim - 1` entries used).
    pub fn tangential_velocity(&self, v: &[f64]) -> [f64; 2] {
        let n = self.dofs();
        let mut tau = [0.0; 2];
        for k in 0..self.basis.len() {
            let row = self.projection_row(k);
            tau[k] = (0..n).map(|j| row[j] * v[j]).sum();
        }
        tau
    }

    /// `D(v)` for the stencil velocities `v` (vertex-major, `dofs()` entries) and threshold
    /// `eps_v`; writes the gradient / Hessian into `out` as `want` asks.
    pub fn eval(&self, v: &[f64], eps_v: f64, want: Want, out: &mut Local) -> f64 {
        let n = self.dofs();
        let m = self.basis.len();
        let tau = self.tangential_velocity(v);
        let norm = tau[..m].iter().map(|t| t * t).sum::<f64>().sqrt();
        let scale = self.mu * self.normal_force;
        let rows = [self.projection_row(0), self.projection_row(1)];
        if want.gradient() {
            let s = scale * f1_over_x(norm, eps_v);
            for j in 0..n {
                out.grad[j] = s * (0..m).map(|k| rows[k][j] * tau[k]).sum::<f64>();
            }
        }
        if let Some(project) = want.hessian() {
            let mut inner = [[0.0; 2]; 2];
            let diag = f1_over_x(norm, eps_v);
            let outer = if norm > 0.0 {
                f2_x_minus_f1_over_x3(norm, eps_v)
            } else {
                0.0
            };
            for k in 0..m {
                for l in 0..m {
                    inner[k][l] = outer * tau[k] * tau[l];
                }
                inner[k][k] += diag;
            }
            if project {
                clamp_2x2(&mut inner, m);
            }
            for i in 0..n {
                for j in 0..n {
                    let mut h = 0.0;
                    for k in 0..m {
                        for l in 0..m {
                            h += rows[k][i] * inner[k][l] * rows[l][j];
                        }
                    }
                    out.hess[i * n + j] = scale * h;
                }
            }
        }
        scale * f0(norm, eps_v)
    }
}

/// Clamps the eigenvalues of the symmetric `m x m` (`m` 1 or 2) matrix `a` at zero.
fn clamp_2x2(a: &mut [[f64; 2]; 2], m: usize) {
    if m == 1 {
        a[0][0] = a[0][0].max(0.0);
        return;
    }
    let mut flat = [a[0][0], a[0][1], a[1][0], a[1][1]];
    crate::energy::psd::project_psd(&mut flat, 2);
    *a = [[flat[0], flat[1]], [flat[2], flat[3]]];
}
