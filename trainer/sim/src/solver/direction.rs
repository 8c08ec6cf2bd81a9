//! Newton's direction of each iterate: the full-space system by sparse Cholesky, or, with an
//! [`AdaptiveSolver`] attached, the adaptive model's system (the oracle first updates the
//! model, then the Schur complement solves it; see [`crate::adaptive::solver`]).

use std::time::Instant;

use super::{HessianMode, Simulator, StepReport, NOT_FREE};
use crate::adaptive::oracle::WeightedTerm;
use crate::adaptive::solver::{AdaptiveSolver, Iterate};
use crate::adaptive::SolveError;
use crate::energy::inertia::Inertia;
use crate::energy::StencilEnergy;
use crate::error::{Quantity, StepError};
use crate::hessian::Unfactorised;

/// Halvings the oracle's line search tries before it takes no step.
const ORACLE_HALVINGS: usize = 30;

impl Simulator {
    /// Makes every Newton iterate's direction come from `solver`'s adaptive model; the
    /// time integration, energies, contact, line search and convergence test stay.
    pub fn with_adaptive(mut self, solver: AdaptiveSolver) -> Self {
        self.adaptive_initial = Some(Box::new(solver.clone()));
        self.adaptive = Some(solver);
        self
    }

    /// The attached adaptive model, if any.
    pub fn adaptive(&self) -> Option<&AdaptiveSolver> {
        self.adaptive.as_ref()
    }

    /// The attached adaptive model, if any, to change its model.
    pub fn adaptive_mut(&mut self) -> Option<&mut AdaptiveSolver> {
        self.adaptive.as_mut()
    }

    /// Replaces `rhs` (the free dofs' `-g`, and a moving obstacle's push) by Newton's
    /// direction at `x`, whose full gradient is `grad`, at Newton iteration `iteration` of
    /// the step to `frame` (which errors name). A Hessian with a NaN or infinite entry is
    /// an error, and so is one no diagonal shift makes factorisable.
    pub(super) fn newton_direction(
        &mut self,
        x: &[f64],
        grad: &[f64],
        rhs: &mut [f64],
        weights: (f64, f64),
        (frame, iteration): (usize, usize),
        report: &mut StepReport,
    ) -> Result<(), StepError> {
        let (w_inertia, w_potential) = weights;
        // Exact Newton where the exact Hessian is positive definite (quadratic
        // convergence); otherwise per-stencil PSD projection (always a descent direction).
        let exact_first = self.settings.hessian == HessianMode::ExactIfDefinite;
        let clock = Instant::now();
        self.assemble(x, w_inertia, w_potential, !exact_first);
        report.phases.assembly += clock.elapsed().as_secs_f64();
        let non_finite = StepError::NonFinite {
            frame,
            iteration,
            quantity: Quantity::Hessian,
        };
        if !self.hessian.is_finite() {
            return Err(non_finite);
        }
        if self.adaptive.is_some() {
            return self.adaptive_direction(x, grad, rhs, weights, exact_first, iteration, report);
        }
        let clock = Instant::now();
        let solved = exact_first && self.hessian.try_solve(rhs);
        report.phases.linear_solve += clock.elapsed().as_secs_f64();
        if !solved {
            if exact_first {
                let clock = Instant::now();
                self.assemble(x, w_inertia, w_potential, true);
                report.phases.assembly += clock.elapsed().as_secs_f64();
                report.projected_iterations += 1;
            }
            let clock = Instant::now();
            let solved = self.hessian.solve(rhs);
            report.phases.linear_solve += clock.elapsed().as_secs_f64();
            solved.map_err(|e| match e {
                Unfactorised::NonFinite => non_finite,
                Unfactorised::Indefinite { shift } => StepError::Unfactorisable {
                    frame,
                    iteration,
                    shift,
                },
            })?;
        }
        Ok(())
    }

    /// The adaptive model's direction (the Hessian is assembled, exact or projected as
    /// `exact_first` says).
    #[allow(clippy::too_many_arguments)]
    fn adaptive_direction(
        &mut self,
        x: &[f64],
        grad: &[f64],
        rhs: &mut [f64],
        weights: (f64, f64),
        exact_first: bool,
        iteration: usize,
        report: &mut StepReport,
    ) -> Result<(), StepError> {
        let mut solver = self
            .adaptive
            .take()
            .unwrap_or_else(|| unreachable!("checked by the caller"));
        let negative_gradient = rhs.to_vec();
        let objective = Some(report.objective);
        let found = self.adaptive_solve(
            &mut solver,
            x,
            grad,
            &negative_gradient,
            weights,
            !exact_first,
            objective,
        );
        let found = match found {
            Err(Failure::Solve(
                SolveError::NotPositiveDefinite(_)
                | SolveError::PreconditionerBlock { .. }
                | SolveError::Indefinite { .. },
            )) if exact_first => {
                let clock = Instant::now();
                // The assembly asks the model which elastic stencils it evaluates exactly.
                self.adaptive = Some(solver);
                self.assemble(x, weights.0, weights.1, true);
                solver = self.adaptive.take().unwrap_or_else(|| unreachable!("put back above"));
                report.phases.assembly += clock.elapsed().as_secs_f64();
                report.projected_iterations += 1;
                self.adaptive_solve(&mut solver, x, grad, &negative_gradient, weights, true, None)
            }
            other => other,
        };
        self.adaptive = Some(solver);
        let dir = found.map_err(|f| StepError::Adaptive {
            iteration,
            message: f.to_string(),
        })?;
        rhs.copy_from_slice(&dir);
        Ok(())
    }

    /// Updates the model when given the objective at `x` (`update`), then solves its system
    /// with the assembled Hessian (per-stencil PSD projections when `projected`), to which
    /// the elastic Hessians of the subdomains the update made exact are added first.
    #[allow(clippy::too_many_arguments)]
    fn adaptive_solve(
        &mut self,
        solver: &mut AdaptiveSolver,
        x: &[f64],
        grad: &[f64],
        rhs: &[f64],
        (w_inertia, w_potential): (f64, f64),
        projected: bool,
        update: Option<f64>,
    ) -> Result<Vec<f64>, Failure> {
        if let Some(objective) = update {
            let terms = weighted_terms(&self.inertia, &self.potentials, w_inertia, w_potential);
            let it = self.adaptive_iterate(x, grad, rhs, &terms);
            self.update_adaptive_model(solver, &it, objective, (w_inertia, w_potential))?;
            // The update may have made subdomains exact: their stencils join the Hessian
            // the solve reads.
            self.assemble_newly_exact(solver, x, w_potential, projected);
        }
        let terms = weighted_terms(&self.inertia, &self.potentials, w_inertia, w_potential);
        let it = self.adaptive_iterate(x, grad, rhs, &terms);
        solver.solve(&it).map_err(Failure::Solve)
    }

    /// The iterate at `x` as the adaptive model sees it, with the assembled Hessian.
    fn adaptive_iterate<'a>(
        &'a self,
        x: &'a [f64],
        gradient: &'a [f64],
        rhs: &'a [f64],
        terms: &'a [WeightedTerm<'a>],
    ) -> Iterate<'a> {
        Iterate {
            hessian: self.hessian.lower(),
            x,
            gradient,
            rhs,
            terms,
            dt: self.dt,
        }
    }

    /// Adds the elastic Hessians of the subdomains `solver` (taken out of the simulator for
    /// its solve) made exact since the last assembly.
    fn assemble_newly_exact(&mut self, solver: &mut AdaptiveSolver, x: &[f64], w_potential: f64, project: bool) {
        let Some(e) = solver.elastic_subspace_mut() else {
            return;
        };
        let added: Vec<Vec<usize>> = (0..e.num_terms()).map(|t| e.newly_exact_stencils(t)).collect();
        e.take_newly_exact();
        for (i, stencils) in added.iter().enumerate().filter(|(_, s)| !s.is_empty()) {
            let term = self.potentials[i].as_ref();
            self.hessian
                .add_stencils(1 + i, term, w_potential, Some(stencils), x, project);
        }
    }

    /// The oracle's update of the model at the iterate `it`, where the objective is
    /// `objective` (its step measured by a line search bounded by half the smallest contact
    /// distance).
    fn update_adaptive_model(
        &self,
        solver: &mut AdaptiveSolver,
        it: &Iterate<'_>,
        objective: f64,
        (w_inertia, w_potential): (f64, f64),
    ) -> Result<(), Failure> {
        let (x, grad) = (it.x, it.gradient);
        let (inertia, potentials, contact) = (&self.inertia, &self.potentials, &self.contact);
        let free_index = &self.free_index;
        let mut along = |step: &[f64]| {
            let objective_at = |y: &[f64], contact: &Option<super::Contact>| {
                let e = super::incremental_potential(inertia, potentials, w_inertia, w_potential, y, None);
                e + contact.as_ref().map_or(0.0, |c| c.value(y))
            };
            // The oracle's step is only measured, never taken: instead of CCD (a broad
            // phase over the swept surface), it is bounded so that no vertex moves more
            // than half the smallest primitive distance, which no pair can close.
            let largest = step.iter().fold(0.0f64, |m, s| m.abs().max(s.abs()));
            let mut alpha = match contact.as_ref() {
                Some(c) if largest > 0.0 => (0.5 * c.min_distance() / largest).min(1.0),
                _ => 1.0,
            };
            let e0 = objective;
            let slope: f64 = free_index
                .iter()
                .enumerate()
                .filter(|(_, &f)| f != NOT_FREE)
                .map(|(k, _)| grad[k] * step[k])
                .sum();
            for _ in 0..ORACLE_HALVINGS {
                let y: Vec<f64> = x.iter().zip(step).map(|(a, s)| a + alpha * s).collect();
                let e = objective_at(&y, contact);
                if e.is_finite() && e <= e0 + 1e-4 * alpha * slope.min(0.0) {
                    return alpha;
                }
                alpha *= 0.5;
            }
            0.0
        };
        solver.update_model(it, &mut along).map_err(Failure::Oracle)
    }
}

/// The objective's stencil terms with their weights, inertia first.
fn weighted_terms<'a>(
    inertia: &'a Inertia,
    potentials: &'a [Box<dyn StencilEnergy>],
    w_inertia: f64,
    w_potential: f64,
) -> Vec<WeightedTerm<'a>> {
    std::iter::once(WeightedTerm {
        energy: inertia as &dyn StencilEnergy,
        weight: w_inertia,
    })
    .chain(potentials.iter().map(|p| WeightedTerm {
        energy: p.as_ref(),
        weight: w_potential,
    }))
    .collect()
}

/// Why the adaptive model gave no direction.
#[derive(Debug, thiserror::Error)]
enum Failure {
    #[error("oracle: {0}")]
    Oracle(String),
    #[error(transparent)]
    Solve(SolveError),
}
