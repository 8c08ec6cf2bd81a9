//! Newton's method on the positive semi-definite Hessian the objective reports: each
//! iteration solves `(H + mu I) d = -g` by a dense Cholesky factorisation of the r x r
//! matrix, with `mu = 0` first and, while the factorisation fails (a pivot not above
//! `eps * s`, `s` the largest diagonal entry, or 1 when that is not positive), `mu` growing
//! tenfold from `1e-8 * s` (Levenberg-style). The step is then taken by the shared
//! backtracking Armijo line search of [`super::optimize`] (c1 = 1e-4, halving from step 1,
//! non-finite values rejected), evaluating E alone; the accepted point is evaluated once
//! more for its gradient and Hessian.
//!
//! The factorisation is hand-written rather than taken from nalgebra: it works in place in
//! a buffer of the workspace, so retrying with larger shifts allocates nothing, and for
//! r <= 64 the textbook r^3/6 loop is all the speed there is to have.
//!
//! Exits ([`Exit`]): `Converged` once `|g|_inf <= tolerance` (checked on entry too). When no
//! shift up to `1e31 s` factors the Hessian (it holds non-finite entries), the Newton
//! direction is not a descent direction, or its line search fails, the step is retried
//! along steepest descent `-g`. `Saddle` is reported when E or the gradient is not finite at
//! the iterate, when `-g` gives no finite negative slope, when the steepest-descent line
//! search shrinks the step until `z + step * d == z`, when `obj.dim() != z.len()` (nothing
//! is evaluated; the objective is NaN), or, in emulated single precision
//! ([`super::rounding`]), after an accepted step that left E unchanged short of the
//! tolerance. `LineSearchCap` when the steepest-descent line search needs more than
//! `max_line_search` halvings; `IterationCap` after `max_iterations` accepted steps.

use super::optimize::{
    dot, inf_norm, is_descent, line_search, report, rounding_stalled, Exit, Objective, Search, SolveReport,
    SolveSettings,
};

/// How many shifts are tried: `1e-8 s` times 10^0 ..= 10^39.
const MAX_SHIFTS: usize = 40;

/// Every buffer a Newton solve uses, so that a solve on a sized workspace allocates nothing
/// (apart from the history, when it is recorded).
#[derive(Debug, Clone)]
pub struct NewtonWorkspace {
    r: usize,
    /// The objective's Hessian, row-major.
    hess: Vec<f64>,
    /// The Cholesky factor L of the shifted Hessian (lower triangle, row-major).
    factor: Vec<f64>,
    g: Vec<f64>,
    d: Vec<f64>,
    trial: Vec<f64>,
}

impl NewtonWorkspace {
    /// A workspace for `r` unknowns.
    pub fn new(r: usize) -> Self {
        NewtonWorkspace {
            r,
            hess: vec![0.0; r * r],
            factor: vec![0.0; r * r],
            g: vec![0.0; r],
            d: vec![0.0; r],
            trial: vec![0.0; r],
        }
    }

    /// Sizes the buffers for `r` unknowns, allocating only when `r` changed.
    fn fit(&mut self, r: usize) {
        if self.r != r {
            *self = NewtonWorkspace::new(r);
        }
    }

    /// `d = -g`; returns the slope `g . d`.
    fn steepest(&mut self) -> f64 {
        for (d, g) in self.d.iter_mut().zip(&self.g) {
            *d = -g;
        }
        dot(&self.g, &self.d)
    }

    /// `d = -(H + mu I)^-1 g` with the smallest shift `mu` that factors; false when none does.
    fn direction(&mut self) -> bool {
        let r = self.r;
        let largest = (0..r).map(|i| self.hess[i * r + i]).fold(0.0, f64::max);
        let scale = if largest > 0.0 && largest.is_finite() {
            largest
        } else {
            1.0
        };
        let mut shift = 0.0;
        for attempt in 0..=MAX_SHIFTS {
            if cholesky(&self.hess, shift, f64::EPSILON * scale, &mut self.factor, r) {
                for (d, g) in self.d.iter_mut().zip(&self.g) {
                    *d = -g;
                }
                cholesky_solve(&self.factor, &mut self.d, r);
                return true;
            }
            shift = 1e-8 * scale * 10f64.powi(attempt as i32);
        }
        false
    }
}

/// Factors `H + shift I = L L^T` from the lower triangle of `h` (r x r, row-major) into the
/// lower triangle of `l`; false when a pivot is not finite or not above `min_pivot`.
fn cholesky(h: &[f64], shift: f64, min_pivot: f64, l: &mut [f64], r: usize) -> bool {
    for i in 0..r {
        for j in 0..=i {
            let mut sum = h[i * r + j];
            for k in 0..j {
                sum -= l[i * r + k] * l[j * r + k];
            }
            if i == j {
                sum += shift;
                if !(sum.is_finite() && sum > min_pivot) {
                    return false;
                }
                l[i * r + i] = sum.sqrt();
            } else {
                l[i * r + j] = sum / l[j * r + j];
            }
        }
    }
    true
}

/// Solves `L L^T x = b` in place (`b` becomes `x`).
fn cholesky_solve(l: &[f64], b: &mut [f64], r: usize) {
    for i in 0..r {
        let mut sum = b[i];
        for k in 0..i {
            sum -= l[i * r + k] * b[k];
        }
        b[i] = sum / l[i * r + i];
    }
    for i in (0..r).rev() {
        let mut sum = b[i];
        for k in i + 1..r {
            sum -= l[k * r + i] * b[k];
        }
        b[i] = sum / l[i * r + i];
    }
}

/// Minimises `obj` from `z` by Newton's method, leaving the final iterate in `z`. The exits
/// are listed in the module documentation; `record_history` fills
/// [`SolveReport::history`].
pub fn newton(
    obj: &mut dyn Objective,
    z: &mut [f64],
    settings: &SolveSettings,
    workspace: &mut NewtonWorkspace,
    record_history: bool,
) -> SolveReport {
    let ws = workspace;
    ws.fit(z.len());
    if obj.dim() != z.len() {
        return report(Exit::Saddle, 0, 0, f64::NAN, &[f64::NAN], Vec::new());
    }
    let mut f = obj.hessian(z, &mut ws.g, &mut ws.hess);
    let mut evaluations = 1;
    let mut iterations = 0;
    let mut history = Vec::new();
    if record_history {
        history.push(f);
    }
    loop {
        let gnorm = inf_norm(&ws.g);
        let exit = if gnorm <= settings.tolerance {
            Some(Exit::Converged)
        } else if !f.is_finite() || !gnorm.is_finite() {
            Some(Exit::Saddle)
        } else if iterations >= settings.max_iterations {
            Some(Exit::IterationCap)
        } else {
            None
        };
        if let Some(exit) = exit {
            return report(exit, iterations, evaluations, f, &ws.g, history);
        }

        let mut steepest = !ws.direction();
        let mut slope = if steepest { ws.steepest() } else { dot(&ws.g, &ws.d) };
        if !is_descent(slope) && !steepest {
            slope = ws.steepest();
            steepest = true;
        }
        let before = f;
        loop {
            if !is_descent(slope) {
                return report(Exit::Saddle, iterations, evaluations, f, &ws.g, history);
            }
            let (outcome, calls) = line_search(z, &ws.d, f, slope, settings.into(), &mut ws.trial, |t| {
                (obj.value(t), None)
            });
            evaluations += calls;
            let exit = match outcome {
                Search::Accepted(_) => break,
                _ if !steepest => {
                    slope = ws.steepest();
                    steepest = true;
                    continue;
                }
                Search::Stalled => Exit::Saddle,
                Search::Capped => Exit::LineSearchCap,
            };
            return report(exit, iterations, evaluations, f, &ws.g, history);
        }

        z.copy_from_slice(&ws.trial);
        f = obj.hessian(z, &mut ws.g, &mut ws.hess);
        evaluations += 1;
        iterations += 1;
        if record_history {
            history.push(f);
        }
        if rounding_stalled(settings, before, f, &ws.g) {
            return report(Exit::Saddle, iterations, evaluations, f, &ws.g, history);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::optimize::problems::{ill_conditioned, lifted, quadratic, rosenbrock, slope, uphill, walled};
    use super::super::rounding::Rounding;
    use super::*;

    fn solve(obj: &mut dyn Objective, z: &mut [f64], settings: &SolveSettings) -> SolveReport {
        newton(obj, z, settings, &mut NewtonWorkspace::new(z.len()), true)
    }

    fn assert_near(z: &[f64], expected: &[f64], tol: f64) {
        for (a, b) in z.iter().zip(expected) {
            assert!((a - b).abs() <= tol, "{z:?} vs {expected:?}");
        }
    }

    #[test]
    fn cholesky_solves_a_dense_spd_system() {
        let h = [4.0, 2.0, -2.0, 2.0, 5.0, 1.0, -2.0, 1.0, 6.0];
        let x = [1.0, -2.0, 0.5];
        let mut b: Vec<f64> = (0..3).map(|i| dot(&h[i * 3..i * 3 + 3], &x)).collect();
        let mut l = [0.0; 9];
        assert!(cholesky(&h, 0.0, 1e-15, &mut l, 3));
        cholesky_solve(&l, &mut b, 3);
        assert_near(&b, &x, 1e-12);
        assert!(!cholesky(&[1.0, 0.0, 0.0, -1.0], 0.0, 1e-15, &mut l, 2));
        assert!(!cholesky(&[f64::NAN, 0.0, 0.0, 1.0], 1e3, 1e-15, &mut l, 2));
    }

    #[test]
    fn solves_a_convex_quadratic_in_one_iteration() {
        let mut obj = quadratic(&[1.0, 3.0, 0.5], &[2.0, -1.0, 0.5], None);
        let mut z = [0.0; 3];
        let report = solve(&mut obj, &mut z, &SolveSettings::default());
        assert_eq!((report.exit, report.iterations), (Exit::Converged, 1));
        assert_near(&z, &[2.0, -1.0, 0.5], 1e-12);

        let (mut obj, minimiser) = ill_conditioned();
        let mut z = [0.0; 8];
        let report = solve(&mut obj, &mut z, &SolveSettings::default());
        assert_eq!((report.exit, report.iterations), (Exit::Converged, 1));
        assert_near(&z, &minimiser, 1e-10);
    }

    #[test]
    fn single_precision_stops_where_rounding_hides_the_decrease() {
        // A quadratic lifted by 1000 whose Hessian is reported ten times too large: each
        // Newton step goes a tenth of the way, so its decrease soon rounds away in f32 while
        // the gradient is still far above the tolerance. Single precision ends there as a
        // saddle; double precision converges on the same function unrounded.
        let problem = |round: bool| {
            let reported = vec![10.0, 0.0, 0.0, 10.0];
            lifted(quadratic(&[1.0, 1.0], &[1.0, -2.0], Some(reported)), round)
        };
        let single = SolveSettings {
            rounding: Rounding::Single,
            ..SolveSettings::default()
        };
        let mut z = [0.0, 0.0];
        let report = solve(&mut problem(true), &mut z, &single);
        assert_eq!(report.exit, Exit::Saddle, "{report:?}");
        assert!(report.gradient_norm > 1e-5, "{report:?}");
        let mut z = [0.0, 0.0];
        let report = solve(&mut problem(false), &mut z, &SolveSettings::default());
        assert_eq!(report.exit, Exit::Converged, "{report:?}");
        assert_near(&z, &[1.0, -2.0], 1e-4);
    }

    #[test]
    fn reaches_the_minimiser_of_rosenbrock() {
        let mut z = [-1.2, 1.0];
        let report = solve(&mut rosenbrock(), &mut z, &SolveSettings::default());
        assert_eq!(report.exit, Exit::Converged, "{report:?}");
        assert!(report.iterations < 50, "{report:?}");
        assert_near(&z, &[1.0, 1.0], 1e-5);
        assert!(report.history.windows(2).all(|w| w[1] <= w[0]));
    }

    #[test]
    fn singular_and_indefinite_hessians_are_shifted() {
        for hessian in [vec![0.0; 4], vec![1.0, 0.0, 0.0, -1.0], vec![1.0, 1.0, 1.0, 1.0]] {
            let mut obj = quadratic(&[1.0, 2.0], &[1.0, -1.0], Some(hessian.clone()));
            let mut z = [0.0, 0.0];
            let report = solve(&mut obj, &mut z, &SolveSettings::default());
            assert_eq!(report.exit, Exit::Converged, "{hessian:?}: {report:?}");
            assert_near(&z, &[1.0, -1.0], 1e-5);
        }
    }

    #[test]
    fn stops_at_the_iteration_cap() {
        let mut z = [-1.2, 1.0];
        let settings = SolveSettings {
            max_iterations: 2,
            ..SolveSettings::default()
        };
        let report = solve(&mut rosenbrock(), &mut z, &settings);
        assert_eq!((report.exit, report.iterations), (Exit::IterationCap, 2));
        assert_eq!(report.history.len(), 3);
        assert_eq!(report.history[0], rosenbrock().value(&[-1.2, 1.0]));
        assert_eq!(report.objective, report.history[2]);
    }

    #[test]
    fn converges_without_iterating_at_the_minimiser() {
        let (mut obj, minimiser) = ill_conditioned();
        let mut z = minimiser.clone();
        let report = solve(&mut obj, &mut z, &SolveSettings::default());
        assert_eq!(
            (report.exit, report.iterations, report.evaluations),
            (Exit::Converged, 0, 1)
        );
        assert_eq!(report.history.len(), 1);
    }

    #[test]
    fn history_is_recorded_only_when_asked() {
        let mut ws = NewtonWorkspace::new(2);
        let settings = SolveSettings::default();
        let mut z = [-1.2, 1.0];
        let recorded = newton(&mut rosenbrock(), &mut z, &settings, &mut ws, true);
        assert_eq!(recorded.history.len(), recorded.iterations + 1);
        let mut z = [-1.2, 1.0];
        let plain = newton(&mut rosenbrock(), &mut z, &settings, &mut ws, false);
        assert!(plain.history.is_empty());
        assert_eq!((plain.iterations, plain.exit), (recorded.iterations, recorded.exit));
    }

    #[test]
    fn backtracks_from_non_finite_values() {
        // The reported Hessian is ten times too small: the full step leaves the domain.
        let mut obj = walled(10.0, 1.0);
        let mut z = [0.0, 0.0];
        let report = solve(&mut obj, &mut z, &SolveSettings::default());
        assert!(
            obj.values.iter().any(|v| v.is_nan()),
            "the first step should leave the domain"
        );
        assert_eq!(report.exit, Exit::Converged, "{report:?}");
        assert!(report.history.iter().all(|f| f.is_finite()));
        assert_near(&z, &[0.6, -0.8], 1e-5);
    }

    #[test]
    fn an_uphill_gradient_is_a_saddle_or_a_line_search_cap() {
        let mut z = [1.0, 1.0];
        let report = solve(&mut uphill(), &mut z, &SolveSettings::default());
        assert_eq!((report.exit, report.iterations), (Exit::Saddle, 0));
        let settings = SolveSettings {
            max_line_search: 10,
            ..SolveSettings::default()
        };
        let report = solve(&mut uphill(), &mut z, &settings);
        assert_eq!(report.exit, Exit::LineSearchCap);
        assert_eq!(z, [1.0, 1.0]);
    }

    #[test]
    fn an_unbounded_objective_runs_to_the_iteration_cap() {
        let mut z = [0.0, 0.0];
        let settings = SolveSettings {
            max_iterations: 20,
            ..SolveSettings::default()
        };
        let report = solve(&mut slope(), &mut z, &settings);
        assert_eq!((report.exit, report.iterations), (Exit::IterationCap, 20));
        assert!(report.objective < -1e8);
    }

    #[test]
    fn nan_input_and_mismatched_objectives_do_not_converge() {
        let mut z = [0.0, f64::NAN];
        let report = solve(&mut rosenbrock(), &mut z, &SolveSettings::default());
        assert_eq!(report.exit, Exit::Saddle);
        let mut z = [0.0];
        let report = solve(&mut rosenbrock(), &mut z, &SolveSettings::default());
        assert_eq!((report.exit, report.evaluations), (Exit::Saddle, 0));
    }
}
