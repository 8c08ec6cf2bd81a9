//! L-BFGS as Lyu et al. 2024's code runs it (a vendored copy of JAX's L-BFGS with an
//! Armijo-only backtracking line search), for measuring subspaces in the paper's own regime.
//! The product's solver is [`super::lbfgs`]; this one is selected with
//! [`super::stepper::ReducedSolver::PaperLbfgs`].
//!
//! What it does differently from [`super::lbfgs`]:
//!
//! - Every solve starts cold: no curvature pairs, initial inverse Hessian `I` (so the first
//!   trial step is `-g` at full length, whatever the scale of the objective).
//! - The line search tries steps `1, 0.8, 0.8^2, ...` (at most `max_line_search` trials) and
//!   takes the first with `E(z + a d) < E(z) + c1 a g.d` (strict, `c1 = 1e-4`), evaluating
//!   E alone at each trial and E with its gradient at the accepted point: no curvature
//!   condition, no interpolation. When no trial passes, the last (smallest) step is taken
//!   anyway and the solve stops.
//! - Every pair is stored (`rho = 1 / s.y` without a curvature check), the newest `memory`
//!   of them (the paper's code keeps 10).
//! - No convergence check before the first step: a solve takes at least one line search.
//! - Exits, checked after each step in this order: [`Exit::Converged`] when the new
//!   gradient's infinity norm is below the tolerance (strictly), else
//!   [`Exit::LineSearchCap`] when no trial passed, else [`Exit::IterationCap`] when the
//!   step was the one after `max_iterations`, else [`Exit::Saddle`] when the step lowered E
//!   by less than [`PAPER_FTOL`] (absolute; JAX's "insufficient progress", which the
//!   paper's code reports as a saddle point).
//!
//! The pairs and the two-loop recursion are [`super::lbfgs`]'s ([`LbfgsWorkspace`]), stored
//! without its curvature check and with `s = a d` as JAX computes it.
//!
//! In emulated single precision ([`super::rounding`]) the objective rounds its own numbers;
//! here the Armijo bound and the decrease compared with [`PAPER_FTOL`] are rounded to `f32`
//! as an `f32` solver computes them.
//!
//! Two guards the paper's code does not have keep a stepped body finite: a non-finite
//! direction ends the solve as [`Exit::LineSearchCap`] without moving, and a non-finite E
//! or gradient at the new point returns to the last point and ends it as [`Exit::Saddle`].

use super::lbfgs::{LbfgsWorkspace, PairStep};
use super::optimize::{inf_norm, report, Exit, Objective, SolveReport, SolveSettings, ARMIJO_C1};
use super::rounding::Rounding;

/// The absolute decrease below which a step ends the solve (JAX's default `ftol`).
pub const PAPER_FTOL: f64 = 2.220446049250313e-9;

/// The factor each backtracking trial shrinks the step by.
pub const PAPER_SHRINK: f64 = 0.8;

/// The curvature pairs the paper's code keeps (JAX's `maxcor`).
pub const PAPER_MEMORY: usize = 10;

/// Minimises `obj` from `z` as the paper's code does (module documentation), leaving the
/// final iterate in `z`. Reads `tolerance`, `max_iterations`, `max_line_search`, `memory`
/// and `rounding` from `settings` (never `warm_start`: every solve is cold).
pub fn paper_lbfgs(
    obj: &mut dyn Objective,
    z: &mut [f64],
    settings: &SolveSettings,
    workspace: &mut LbfgsWorkspace,
    record_history: bool,
) -> SolveReport {
    let ws = workspace;
    ws.fit(z.len(), settings.memory, false);
    if obj.dim() != z.len() {
        return report(Exit::Saddle, 0, 0, f64::NAN, &[f64::NAN], Vec::new());
    }
    let rounding = settings.rounding;
    let mut f = obj.gradient(z, &mut ws.g);
    let mut evaluations = 1;
    let mut history = Vec::new();
    if record_history {
        history.push(f);
    }
    if !f.is_finite() || !inf_norm(&ws.g).is_finite() {
        return report(Exit::Saddle, 0, evaluations, f, &ws.g, history);
    }
    let mut iterations = 0;
    loop {
        let slope = ws.direction();
        if !ws.d.iter().all(|v| v.is_finite()) {
            return report(Exit::LineSearchCap, iterations, evaluations, f, &ws.g, history);
        }
        // Backtracking on Armijo alone.
        let mut step = 1.0;
        let mut passed = false;
        for trial in 0..settings.max_line_search.max(1) {
            if trial > 0 {
                step *= PAPER_SHRINK;
            }
            place(&mut ws.trial, z, &ws.d, step);
            let value = obj.value(&ws.trial);
            evaluations += 1;
            if value < rounding.round(f + ARMIJO_C1 * step * slope) {
                passed = true;
                break;
            }
        }
        place(&mut ws.trial, z, &ws.d, step);
        let value = obj.gradient(&ws.trial, &mut ws.g_new);
        evaluations += 1;
        if !value.is_finite() || !inf_norm(&ws.g_new).is_finite() {
            return report(Exit::Saddle, iterations, evaluations, f, &ws.g, history);
        }
        ws.store_pair(PairStep::Along(step), false);
        let decrease = rounding.round(f - value);
        let before = iterations;
        z.copy_from_slice(&ws.trial);
        std::mem::swap(&mut ws.g, &mut ws.g_new);
        f = value;
        iterations += 1;
        if record_history {
            history.push(f);
        }
        let exit = if inf_norm(&ws.g) < settings.tolerance {
            Some(Exit::Converged)
        } else if !passed {
            Some(Exit::LineSearchCap)
        } else if before >= settings.max_iterations {
            Some(Exit::IterationCap)
        } else if decrease < PAPER_FTOL {
            Some(Exit::Saddle)
        } else {
            None
        };
        if let Some(exit) = exit {
            return report(exit, iterations, evaluations, f, &ws.g, history);
        }
    }
}

/// Writes `z + step * d` into `trial`.
fn place(trial: &mut [f64], z: &[f64], d: &[f64], step: f64) {
    for ((t, &zi), &di) in trial.iter_mut().zip(z).zip(d) {
        *t = zi + step * di;
    }
}

/// The settings of the paper's solver: its memory, line-search cap and tolerance on the
/// objective as the stepper scales it in this mode (see
/// [`super::stepper::ReducedSolver::PaperLbfgs`]); `rounding` as given.
pub fn paper_settings(tolerance: f64, max_iterations: usize, rounding: Rounding) -> SolveSettings {
    SolveSettings {
        tolerance,
        max_iterations,
        max_line_search: 128,
        memory: PAPER_MEMORY,
        warm_start: false,
        rounding,
    }
}

#[cfg(test)]
mod tests;
