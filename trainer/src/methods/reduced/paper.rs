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
//! In emulated single precision ([`super::rounding`]) the objective rounds its own numbers;
//! here the Armijo bound and the decrease compared with [`PAPER_FTOL`] are rounded to `f32`
//! as an `f32` solver computes them.
//!
//! Two guards the paper's code does not have keep a stepped body finite: a non-finite
//! direction ends the solve as [`Exit::LineSearchCap`] without moving, and a non-finite E
//! or gradient at the new point returns to the last point and ends it as [`Exit::Saddle`].

use super::optimize::{dot, inf_norm, report, Exit, Objective, SolveReport, SolveSettings, ARMIJO_C1};
use super::rounding::Rounding;

/// The absolute decrease below which a step ends the solve (JAX's default `ftol`).
pub const PAPER_FTOL: f64 = 2.220446049250313e-9;

/// The factor each backtracking trial shrinks the step by.
pub const PAPER_SHRINK: f64 = 0.8;

/// The curvature pairs the paper's code keeps (JAX's `maxcor`).
pub const PAPER_MEMORY: usize = 10;

/// The buffers of a solve (allocated once per size).
#[derive(Debug, Clone)]
pub struct PaperWorkspace {
    r: usize,
    memory: usize,
    /// Pairs, oldest first: `len` of them in slots `0..len`.
    s: Vec<f64>,
    y: Vec<f64>,
    rho: Vec<f64>,
    alpha: Vec<f64>,
    len: usize,
    gamma: f64,
    g: Vec<f64>,
    g_new: Vec<f64>,
    d: Vec<f64>,
    trial: Vec<f64>,
}

impl PaperWorkspace {
    /// A workspace for `r` unknowns keeping `memory` pairs.
    pub fn new(r: usize, memory: usize) -> Self {
        PaperWorkspace {
            r,
            memory,
            s: vec![0.0; r * memory],
            y: vec![0.0; r * memory],
            rho: vec![0.0; memory],
            alpha: vec![0.0; memory],
            len: 0,
            gamma: 1.0,
            g: vec![0.0; r],
            g_new: vec![0.0; r],
            d: vec![0.0; r],
            trial: vec![0.0; r],
        }
    }

    fn start(&mut self, r: usize, memory: usize) {
        if self.r != r || self.memory != memory {
            *self = PaperWorkspace::new(r, memory);
        }
        self.len = 0;
        self.gamma = 1.0;
    }

    /// `d = -H g` by the two-loop recursion over the stored pairs.
    fn direction(&mut self) {
        let r = self.r;
        for (d, g) in self.d.iter_mut().zip(&self.g) {
            *d = -g;
        }
        for i in (0..self.len).rev() {
            let a = self.rho[i] * dot(&self.s[i * r..(i + 1) * r], &self.d);
            self.alpha[i] = a;
            for (q, y) in self.d.iter_mut().zip(&self.y[i * r..(i + 1) * r]) {
                *q -= a * y;
            }
        }
        for q in self.d.iter_mut() {
            *q *= self.gamma;
        }
        for i in 0..self.len {
            let b = self.rho[i] * dot(&self.y[i * r..(i + 1) * r], &self.d);
            let c = self.alpha[i] - b;
            for (q, s) in self.d.iter_mut().zip(&self.s[i * r..(i + 1) * r]) {
                *q += c * s;
            }
        }
    }

    /// Stores the pair `s = step * d`, `y = g_new - g`, dropping the oldest when full.
    fn push(&mut self, step: f64) {
        if self.memory == 0 {
            return;
        }
        let r = self.r;
        if self.len == self.memory {
            self.s.copy_within(r.., 0);
            self.y.copy_within(r.., 0);
            self.rho.copy_within(1.., 0);
            self.len -= 1;
        }
        let slot = self.len;
        let (mut sy, mut yy) = (0.0, 0.0);
        for i in 0..r {
            let (s, y) = (step * self.d[i], self.g_new[i] - self.g[i]);
            self.s[slot * r + i] = s;
            self.y[slot * r + i] = y;
            sy += s * y;
            yy += y * y;
        }
        self.rho[slot] = 1.0 / sy;
        self.gamma = sy / yy;
        self.len += 1;
    }
}

/// Minimises `obj` from `z` as the paper's code does (module documentation), leaving the
/// final iterate in `z`. Reads `tolerance`, `max_iterations`, `max_line_search`, `memory`
/// and `rounding` from `settings` (never `warm_start`: every solve is cold).
pub fn paper_lbfgs(
    obj: &mut dyn Objective,
    z: &mut [f64],
    settings: &SolveSettings,
    workspace: &mut PaperWorkspace,
    record_history: bool,
) -> SolveReport {
    let ws = workspace;
    ws.start(z.len(), settings.memory);
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
        ws.direction();
        if !ws.d.iter().all(|v| v.is_finite()) {
            return report(Exit::LineSearchCap, iterations, evaluations, f, &ws.g, history);
        }
        let slope = dot(&ws.g, &ws.d);
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
        ws.push(step);
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
