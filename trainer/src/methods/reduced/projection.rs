//! Projection of a world state onto a subspace: the latent whose decoded state is closest
//! to it in the mass norm, `z* = argmin_z 1/2 |f(z) - x|_M^2 / (M L^2)` (`M` the total mass,
//! `L` the rest diagonal, so the value is half the mass-weighted mean squared distance in
//! diagonals). It measures how well a subspace can represent a state at all, apart from
//! where the solver's steps take it: the paper's Fig. 7 compares two subspaces by the
//! distance between their projections of the same full-space frames.
//!
//! Minimised by the solver's own L-BFGS ([`super::lbfgs`]) with the exact Jacobian of
//! [`DecoderSubspace`]; Newton's Hessian is the Gauss-Newton `J^T M J`.

use super::lbfgs::{lbfgs, LbfgsWorkspace};
use super::optimize::{Objective, SolveReport, SolveSettings};
use super::subspace::DecoderSubspace;
use crate::error::{TrainerError, TrainerResult};

/// Gradient tolerance of a projection (the scaled objective's units: a remaining pull of
/// 1e-9 diagonals per unit latent).
pub const PROJECTION_TOLERANCE: f64 = 1e-9;

/// Most L-BFGS iterations of one projection.
pub const PROJECTION_ITERATIONS: usize = 500;

/// `1/2 |f(z) - x|_M^2 / (M L^2)` over the latent of `subspace` (module documentation).
pub struct ProjectionObjective<'a> {
    subspace: &'a mut DecoderSubspace,
    /// Per world value (`dim` per vertex), the vertex mass over `M L^2`.
    weights: Vec<f64>,
    target: &'a [f64],
    x: Vec<f64>,
    jac: Vec<f64>,
    residual: Vec<f64>,
}

impl<'a> ProjectionObjective<'a> {
    /// The projection of `target` (a world state) onto `subspace`, with lumped vertex
    /// `masses` and rest diagonal `diagonal`.
    pub fn new(
        subspace: &'a mut DecoderSubspace,
        masses: &[f64],
        diagonal: f64,
        target: &'a [f64],
    ) -> TrainerResult<Self> {
        let (n, r, dim) = (subspace.state_len(), subspace.latent_len(), subspace.dim());
        let total: f64 = masses.iter().sum();
        if masses.len() * dim != n || target.len() != n {
            return Err(TrainerError::invalid(format!(
                "projection: {} masses and a state of {} values for a subspace of {n} values",
                masses.len(),
                target.len()
            )));
        }
        if !(total > 0.0 && diagonal > 0.0) {
            return Err(TrainerError::invalid(format!(
                "projection: needs a positive total mass ({total}) and diagonal ({diagonal})"
            )));
        }
        let scale = 1.0 / (total * diagonal * diagonal);
        Ok(ProjectionObjective {
            weights: masses
                .iter()
                .flat_map(|&m| std::iter::repeat_n(m * scale, dim))
                .collect(),
            subspace,
            target,
            x: vec![0.0; n],
            jac: vec![0.0; n * r],
            residual: vec![0.0; n],
        })
    }

    /// Fills the weighted residual `W (f(z) - x)` from `self.x`; returns the value.
    fn residual(&mut self) -> f64 {
        let mut value = 0.0;
        for (((r, x), t), w) in self
            .residual
            .iter_mut()
            .zip(&self.x)
            .zip(self.target)
            .zip(&self.weights)
        {
            let d = x - t;
            *r = w * d;
            value += 0.5 * w * d * d;
        }
        value
    }
}

impl Objective for ProjectionObjective<'_> {
    fn dim(&self) -> usize {
        self.subspace.latent_len()
    }

    fn value(&mut self, z: &[f64]) -> f64 {
        if self.subspace.positions(z, &mut self.x).is_err() {
            return f64::NAN;
        }
        self.residual()
    }

    fn gradient(&mut self, z: &[f64], grad: &mut [f64]) -> f64 {
        if self
            .subspace
            .positions_and_jacobian(z, &mut self.x, &mut self.jac)
            .is_err()
        {
            grad.fill(f64::NAN);
            return f64::NAN;
        }
        let value = self.residual();
        let r = grad.len();
        grad.fill(0.0);
        for (row, &res) in self.jac.chunks_exact(r).zip(&self.residual) {
            if res != 0.0 {
                grad.iter_mut().zip(row).for_each(|(g, j)| *g += res * j);
            }
        }
        value
    }

    fn hessian(&mut self, z: &[f64], grad: &mut [f64], hess: &mut [f64]) -> f64 {
        let value = self.gradient(z, grad);
        let r = grad.len();
        hess.fill(0.0);
        for (row, &w) in self.jac.chunks_exact(r).zip(&self.weights) {
            for (a, &ja) in row.iter().enumerate() {
                if ja != 0.0 {
                    hess[a * r..(a + 1) * r]
                        .iter_mut()
                        .zip(row)
                        .for_each(|(h, jb)| *h += w * ja * jb);
                }
            }
        }
        value
    }
}

/// Projects `target` onto `subspace` from the latent `z` (overwritten with the projection),
/// leaving the projected state in `x`; the report says how the minimisation ended.
pub fn project(
    subspace: &mut DecoderSubspace,
    masses: &[f64],
    diagonal: f64,
    target: &[f64],
    z: &mut [f64],
    x: &mut [f64],
) -> TrainerResult<SolveReport> {
    let settings = SolveSettings {
        tolerance: PROJECTION_TOLERANCE,
        max_iterations: PROJECTION_ITERATIONS,
        warm_start: false,
        ..SolveSettings::default()
    };
    let mut workspace = LbfgsWorkspace::new(z.len(), settings.memory);
    let report = {
        let mut objective = ProjectionObjective::new(subspace, masses, diagonal, target)?;
        lbfgs(&mut objective, z, &settings, &mut workspace, false)
    };
    subspace.positions(z, x)?;
    Ok(report)
}
