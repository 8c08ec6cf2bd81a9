//! Limited-memory BFGS (Nocedal & Wright, Alg. 7.4): the two-loop recursion over the last
//! `memory` pairs `s = z_{k+1} - z_k`, `y = g_{k+1} - g_k`, with the initial inverse Hessian
//! `gamma I`, `gamma = s^T y / y^T y` of the newest pair (1 while none is stored), and the
//! shared line search of [`super::optimize`] in its weak-Wolfe form: Armijo sufficient
//! decrease (c1 = 1e-4, halving from step 1, non-finite values rejected) plus the curvature
//! condition (c2 = 0.9). Armijo alone lets steps along a curved valley (Rosenbrock's) give
//! `s^T y <= 0` again and again, freezing the memory on a stale model; the curvature
//! condition makes every accepted pair usable.
//!
//! With [`SolveSettings::warm_start`] a solve starts from the pairs the previous solve on the
//! same workspace left (a time step's curvature is close to the last one's): the first
//! direction is already scaled and curved, where a cold start takes halvings to find the
//! scale of `-g`. Pairs stay valid quasi-Newton data whatever the new objective is, since
//! a non-descent direction or a failed line search resets them and retries along `-g`.
//!
//! Each line-search trial evaluates the gradient as well as E, so an accepted step (almost
//! always the first trial) costs one objective call. A pair is stored only when
//! `s^T y > eps |s| |y|` holds, which keeps the implied inverse Hessian positive definite;
//! otherwise the step is taken and the pair dropped.
//!
//! Exits ([`Exit`]): `Converged` once `|g|_inf <= tolerance` (checked on entry too, so a
//! solve started at a minimiser takes zero iterations). When the quasi-Newton direction is
//! not a descent direction (`g . d` not finite and negative) or its line search fails, the
//! memory is reset and the step retried along steepest descent `-g`. `Saddle` is reported
//! when E or the gradient is not finite at the iterate, when even `-g` gives no finite
//! negative slope, when the steepest-descent line search shrinks the step until
//! `z + step * d == z`, when `obj.dim() != z.len()` (then nothing is evaluated and the
//! objective is NaN), or, in emulated single precision ([`super::rounding`]), after an
//! accepted step that left E unchanged short of the tolerance. `LineSearchCap` when the
//! steepest-descent line search needs more than `max_line_search` halvings; `IterationCap`
//! after `max_iterations` accepted steps.

use super::optimize::{
    dot, inf_norm, is_descent, line_search, report, rounding_stalled, Exit, Objective, Search, SolveReport,
    SolveSettings,
};

/// Every buffer an L-BFGS solve uses, so that a solve on a sized workspace allocates nothing
/// (apart from the history, when it is recorded).
#[derive(Debug, Clone)]
pub struct LbfgsWorkspace {
    r: usize,
    memory: usize,
    /// `memory` steps s, r values each, as a ring.
    s: Vec<f64>,
    /// `memory` gradient changes y, r values each, as a ring.
    y: Vec<f64>,
    /// `1 / s^T y` of each stored pair.
    rho: Vec<f64>,
    /// The first loop's coefficients.
    alpha: Vec<f64>,
    /// Stored pairs (at most `memory`).
    len: usize,
    /// The ring slot the next pair goes to.
    head: usize,
    /// Scaling of the initial inverse Hessian.
    gamma: f64,
    pub(super) g: Vec<f64>,
    pub(super) g_new: Vec<f64>,
    pub(super) d: Vec<f64>,
    pub(super) trial: Vec<f64>,
}

impl LbfgsWorkspace {
    /// A workspace for `r` unknowns keeping `memory` pairs.
    pub fn new(r: usize, memory: usize) -> Self {
        LbfgsWorkspace {
            r,
            memory,
            s: vec![0.0; r * memory],
            y: vec![0.0; r * memory],
            rho: vec![0.0; memory],
            alpha: vec![0.0; memory],
            len: 0,
            head: 0,
            gamma: 1.0,
            g: vec![0.0; r],
            g_new: vec![0.0; r],
            d: vec![0.0; r],
            trial: vec![0.0; r],
        }
    }

    /// Sizes the buffers for `r` unknowns and `memory` pairs (allocating only when these
    /// changed, which forgets every pair) and, unless `warm`, forgets every pair.
    pub(super) fn fit(&mut self, r: usize, memory: usize, warm: bool) {
        if self.r != r || self.memory != memory {
            *self = LbfgsWorkspace::new(r, memory);
        } else if !warm {
            self.reset();
        }
    }

    /// Forgets every pair, so the next solve starts from steepest descent whatever the
    /// settings say (a new sequence).
    pub fn forget(&mut self) {
        self.reset();
    }

    /// Forgets every pair: the next direction is steepest descent.
    fn reset(&mut self) {
        self.len = 0;
        self.head = 0;
        self.gamma = 1.0;
    }

    /// `d = -g`.
    fn steepest(&mut self) -> f64 {
        for (d, g) in self.d.iter_mut().zip(&self.g) {
            *d = -g;
        }
        dot(&self.g, &self.d)
    }

    /// `d = -H g` by the two-loop recursion; returns the slope `g . d`.
    pub(super) fn direction(&mut self) -> f64 {
        let (r, m) = (self.r, self.memory);
        self.d.copy_from_slice(&self.g);
        for k in 0..self.len {
            let i = (self.head + m - 1 - k) % m;
            let a = self.rho[i] * dot(&self.s[i * r..(i + 1) * r], &self.d);
            self.alpha[i] = a;
            for (q, y) in self.d.iter_mut().zip(&self.y[i * r..(i + 1) * r]) {
                *q -= a * y;
            }
        }
        for q in self.d.iter_mut() {
            *q *= self.gamma;
        }
        for k in (0..self.len).rev() {
            let i = (self.head + m - 1 - k) % m;
            let beta = self.rho[i] * dot(&self.y[i * r..(i + 1) * r], &self.d);
            let c = self.alpha[i] - beta;
            for (q, s) in self.d.iter_mut().zip(&self.s[i * r..(i + 1) * r]) {
                *q += c * s;
            }
        }
        for q in self.d.iter_mut() {
            *q = -*q;
        }
        dot(&self.g, &self.d)
    }

    /// Stores the pair from `z` to `trial` (gradients `g` to `g_new`) when it satisfies the
    /// curvature condition.
    fn push(&mut self, z: &[f64]) {
        self.store_pair(PairStep::Between(z), true);
    }

    /// Stores the pair of the step `s` (`PairStep`) and `y = g_new - g` in place of the oldest
    /// one when memory is full; with `check_curvature`, only when `s.y > eps |s| |y|` (and
    /// finite), which keeps the implied inverse Hessian positive definite.
    pub(super) fn store_pair(&mut self, step: PairStep, check_curvature: bool) {
        if self.memory == 0 {
            return;
        }
        let s_at = |ws: &Self, i: usize| match step {
            PairStep::Between(z) => ws.trial[i] - z[i],
            PairStep::Along(a) => a * ws.d[i],
        };
        let (mut sy, mut ss, mut yy) = (0.0, 0.0, 0.0);
        for i in 0..self.r {
            let (s, y) = (s_at(self, i), self.g_new[i] - self.g[i]);
            sy += s * y;
            ss += s * s;
            yy += y * y;
        }
        let curved = sy > f64::EPSILON * (ss * yy).sqrt();
        if check_curvature && !(curved && sy.is_finite() && yy.is_finite() && yy > 0.0) {
            return;
        }
        let (r, slot) = (self.r, self.head);
        for i in 0..r {
            self.s[slot * r + i] = s_at(self, i);
            self.y[slot * r + i] = self.g_new[i] - self.g[i];
        }
        self.rho[slot] = 1.0 / sy;
        self.gamma = sy / yy;
        self.head = (slot + 1) % self.memory;
        self.len = (self.len + 1).min(self.memory);
    }
}

/// The step of a curvature pair.
#[derive(Clone, Copy)]
pub(super) enum PairStep<'a> {
    /// From `z` to the workspace's trial point: `s = trial - z`.
    Between(&'a [f64]),
    /// Along the workspace's direction: `s = a d` (as JAX's L-BFGS computes it).
    Along(f64),
}

/// Minimises `obj` from `z` by L-BFGS, leaving the final iterate in `z`. The exits are listed
/// in the module documentation; `record_history` fills [`SolveReport::history`].
pub fn lbfgs(
    obj: &mut dyn Objective,
    z: &mut [f64],
    settings: &SolveSettings,
    workspace: &mut LbfgsWorkspace,
    record_history: bool,
) -> SolveReport {
    let ws = workspace;
    ws.fit(z.len(), settings.memory, settings.warm_start);
    if obj.dim() != z.len() {
        return report(Exit::Saddle, 0, 0, f64::NAN, &[f64::NAN], Vec::new());
    }
    let mut f = obj.gradient(z, &mut ws.g);
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

        let mut slope = ws.direction();
        let mut steepest = ws.len == 0;
        if !is_descent(slope) && !steepest {
            ws.reset();
            slope = ws.steepest();
            steepest = true;
        }
        let value = loop {
            if !is_descent(slope) {
                return report(Exit::Saddle, iterations, evaluations, f, &ws.g, history);
            }
            let (outcome, calls) = line_search(z, &ws.d, f, slope, settings.into(), &mut ws.trial, |t| {
                let value = obj.gradient(t, &mut ws.g_new);
                (value, Some(dot(&ws.g_new, &ws.d)))
            });
            evaluations += calls;
            let exit = match outcome {
                Search::Accepted(value) => break value,
                _ if !steepest => {
                    ws.reset();
                    slope = ws.steepest();
                    steepest = true;
                    continue;
                }
                Search::Stalled => Exit::Saddle,
                Search::Capped => Exit::LineSearchCap,
            };
            return report(exit, iterations, evaluations, f, &ws.g, history);
        };

        let before = f;
        ws.push(z);
        z.copy_from_slice(&ws.trial);
        std::mem::swap(&mut ws.g, &mut ws.g_new);
        f = value;
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
    use super::super::optimize::problems::{
        ill_conditioned, lifted, quadratic, rosenbrock, slope, uphill, walled, Problem,
    };
    use super::super::rounding::Rounding;
    use super::*;

    fn solve(obj: &mut dyn Objective, z: &mut [f64], settings: &SolveSettings) -> SolveReport {
        let mut ws = LbfgsWorkspace::new(z.len(), settings.memory);
        lbfgs(obj, z, settings, &mut ws, true)
    }

    fn assert_near(z: &[f64], expected: &[f64], tol: f64) {
        for (a, b) in z.iter().zip(expected) {
            assert!((a - b).abs() <= tol, "{z:?} vs {expected:?}");
        }
    }

    #[test]
    fn reaches_the_minimiser_of_a_convex_quadratic() {
        let mut obj = quadratic(&[1.0, 3.0, 0.5], &[2.0, -1.0, 0.5], None);
        let mut z = [0.0; 3];
        let report = solve(&mut obj, &mut z, &SolveSettings::default());
        assert_eq!(report.exit, Exit::Converged, "{report:?}");
        assert!(report.gradient_norm <= 1e-5);
        assert_near(&z, &[2.0, -1.0, 0.5], 1e-4);
    }

    #[test]
    fn reaches_the_minimiser_of_rosenbrock() {
        let mut z = [-1.2, 1.0];
        let report = solve(&mut rosenbrock(), &mut z, &SolveSettings::default());
        assert_eq!(report.exit, Exit::Converged, "{report:?}");
        assert!(report.iterations < 100, "{report:?}");
        assert_near(&z, &[1.0, 1.0], 1e-4);
        assert!(report.history.windows(2).all(|w| w[1] <= w[0]));
    }

    #[test]
    fn single_precision_stops_where_rounding_hides_the_decrease() {
        // Rosenbrock's function lifted by 1000: along the valley's flat end its decrease
        // rounds away in f32. Single precision ends where E stops changing, as a saddle
        // above the tolerance, each such step accepted at once (not after 128 halvings);
        // double precision converges on the same function unrounded.
        let single = SolveSettings {
            rounding: Rounding::Single,
            ..SolveSettings::default()
        };
        let mut z = [-1.2, 1.0];
        let report = solve(&mut lifted(rosenbrock(), true), &mut z, &single);
        assert_eq!(report.exit, Exit::Saddle, "{report:?}");
        assert!(report.gradient_norm > 1e-5, "{report:?}");
        assert!(report.evaluations < 4 * report.iterations + 10, "{report:?}");
        let mut z = [-1.2, 1.0];
        let report = solve(&mut lifted(rosenbrock(), false), &mut z, &SolveSettings::default());
        assert_eq!(report.exit, Exit::Converged, "{report:?}");
        assert_near(&z, &[1.0, 1.0], 1e-4);
    }

    #[test]
    fn longer_memory_helps_on_an_ill_conditioned_quadratic() {
        let run = |memory| {
            let (mut obj, minimiser) = ill_conditioned();
            let mut z = [0.0; 8];
            let settings = SolveSettings {
                memory,
                ..SolveSettings::default()
            };
            let report = solve(&mut obj, &mut z, &settings);
            assert_eq!(report.exit, Exit::Converged, "memory {memory}: {report:?}");
            assert_near(&z, &minimiser, 1.01e-5);
            report.iterations
        };
        let (long, short) = (run(8), run(1));
        assert!(long < short, "memory 8: {long} iterations, memory 1: {short}");
    }

    #[test]
    fn a_warm_start_reuses_the_last_solves_curvature() {
        // A sequence of stiff quadratics whose minimiser moves a little each time, as a
        // time step's objective does: the warm solves need fewer evaluations, reach the
        // same minimisers, and forgetting the pairs restores the cold behaviour.
        let a = [1.0, 40.0, 900.0, 3.0];
        let run = |warm_start: bool, forget_at: Option<usize>| {
            let settings = SolveSettings {
                warm_start,
                ..SolveSettings::default()
            };
            let mut ws = LbfgsWorkspace::new(4, settings.memory);
            let mut z = [0.0; 4];
            let mut evaluations = Vec::new();
            for k in 0..6 {
                let m: Vec<f64> = (0..4).map(|i| 0.1 * (k * (i + 1)) as f64).collect();
                if forget_at == Some(k) {
                    ws.forget();
                }
                let report = lbfgs(&mut quadratic(&a, &m, None), &mut z, &settings, &mut ws, false);
                assert_eq!(report.exit, Exit::Converged, "{report:?}");
                assert_near(&z, &m, 1e-5);
                evaluations.push(report.evaluations);
            }
            evaluations
        };
        let (cold, warm) = (run(false, None), run(true, None));
        let later = |e: &[usize]| e[1..].iter().sum::<usize>();
        assert!(later(&warm) < later(&cold), "warm {warm:?} against cold {cold:?}");
        assert_eq!(warm[0], cold[0]);
        assert_eq!(run(true, Some(3))[3], cold[3]);
    }

    #[test]
    fn stops_at_the_iteration_cap() {
        let mut z = [-1.2, 1.0];
        let settings = SolveSettings {
            max_iterations: 3,
            ..SolveSettings::default()
        };
        let report = solve(&mut rosenbrock(), &mut z, &settings);
        assert_eq!(report.exit, Exit::IterationCap);
        assert_eq!(report.iterations, 3);
        assert_eq!(report.history.len(), 4);
        assert_eq!(report.objective, report.history[3]);
    }

    #[test]
    fn converges_without_iterating_at_the_minimiser() {
        let mut z = [1.0, 1.0];
        let report = solve(&mut rosenbrock(), &mut z, &SolveSettings::default());
        assert_eq!(report.exit, Exit::Converged);
        assert_eq!((report.iterations, report.evaluations), (0, 1));
        assert_eq!(report.history, vec![0.0]);
        assert_eq!(z, [1.0, 1.0]);
    }

    #[test]
    fn history_is_recorded_only_when_asked() {
        let mut ws = LbfgsWorkspace::new(2, 8);
        let settings = SolveSettings::default();
        let mut z = [-1.2, 1.0];
        let recorded = lbfgs(&mut rosenbrock(), &mut z, &settings, &mut ws, true);
        assert_eq!(recorded.history.len(), recorded.iterations + 1);
        assert_eq!(recorded.history[0], rosenbrock().value(&[-1.2, 1.0]));
        let mut z = [-1.2, 1.0];
        ws.forget();
        let plain = lbfgs(&mut rosenbrock(), &mut z, &settings, &mut ws, false);
        assert!(plain.history.is_empty());
        assert_eq!(plain.iterations, recorded.iterations);
        assert_eq!(plain.evaluations, recorded.evaluations);
    }

    #[test]
    fn backtracks_from_non_finite_values() {
        let mut obj = walled(10.0, 10.0);
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
        // Steepest descent along the reported gradient raises E: with 128 halvings the step
        // vanishes next to z first (Saddle), with 10 the halvings run out first.
        let mut z = [1.0, 1.0];
        let report = solve(&mut uphill(), &mut z, &SolveSettings::default());
        assert_eq!(report.exit, Exit::Saddle);
        assert_eq!((report.iterations, z), (0, [1.0, 1.0]));
        let settings = SolveSettings {
            max_line_search: 10,
            ..SolveSettings::default()
        };
        let report = solve(&mut uphill(), &mut z, &settings);
        assert_eq!((report.exit, report.evaluations), (Exit::LineSearchCap, 12));
        assert_eq!(z, [1.0, 1.0]);
    }

    #[test]
    fn unbounded_objectives_end_without_converging() {
        let mut z = [0.0, 0.0];
        // -sum z: the curvature condition never holds, so the first line search doubles the
        // step 128 times and takes it; from there a unit step no longer moves z.
        let report = solve(&mut slope(), &mut z, &SolveSettings::default());
        assert_eq!((report.exit, report.iterations), (Exit::Saddle, 1));
        assert_eq!(z, [2f64.powi(128); 2]);
        let settings = SolveSettings {
            max_iterations: 5,
            max_line_search: 3,
            ..SolveSettings::default()
        };
        let report = solve(&mut slope(), &mut [0.0, 0.0], &settings);
        assert_eq!((report.exit, report.iterations), (Exit::IterationCap, 5));

        // -|z|^2: each step triples z until the slope overflows.
        let mut concave = Problem::new(
            2,
            |z| -(z[0] * z[0] + z[1] * z[1]),
            |z, g| g.copy_from_slice(&[-2.0 * z[0], -2.0 * z[1]]),
            |_, h| h.fill(0.0),
        );
        let mut z = [1.0, 0.5];
        let report = solve(&mut concave, &mut z, &SolveSettings::default());
        assert_eq!(report.exit, Exit::Saddle, "{report:?}");
        assert!(report.objective.is_finite());
    }

    #[test]
    fn nan_input_and_mismatched_objectives_do_not_converge() {
        let mut z = [f64::NAN, 0.0];
        let report = solve(&mut rosenbrock(), &mut z, &SolveSettings::default());
        assert_eq!(report.exit, Exit::Saddle);
        assert!(report.gradient_norm.is_nan());
        let mut z = [0.0; 3];
        let report = solve(&mut rosenbrock(), &mut z, &SolveSettings::default());
        assert_eq!((report.exit, report.evaluations), (Exit::Saddle, 0));
    }

    #[test]
    fn the_two_loop_recursion_satisfies_the_newest_secant_equation() {
        // After pairs (s_i, y_i), H y_newest = s_newest, so the direction for g = y_newest is
        // -s_newest; with memory 2 the oldest of three pairs is dropped from the ring.
        let mut ws = LbfgsWorkspace::new(3, 2);
        let pairs = [
            ([1.0, 0.0, 0.5], [2.0, 0.1, 0.4]),
            ([0.0, 1.0, -1.0], [0.3, 3.0, -2.0]),
            ([0.5, -0.5, 1.0], [1.0, -2.0, 4.0]),
        ];
        for (s, y) in pairs {
            ws.trial.copy_from_slice(&s);
            ws.g.fill(0.0);
            ws.g_new.copy_from_slice(&y);
            ws.push(&[0.0; 3]);
        }
        assert_eq!((ws.len, ws.head), (2, 1));
        let (s, y) = pairs[2];
        ws.g.copy_from_slice(&y);
        let slope = ws.direction();
        assert_near(&ws.d, &[-s[0], -s[1], -s[2]], 1e-12);
        assert!((slope + dot(&s, &y)).abs() < 1e-12);
        assert_eq!(ws.gamma, dot(&s, &y) / dot(&y, &y));
    }

    #[test]
    fn a_sized_workspace_is_reused_and_resized() {
        let mut ws = LbfgsWorkspace::new(2, 8);
        let settings = SolveSettings {
            memory: 3,
            ..SolveSettings::default()
        };
        let (mut obj, _) = ill_conditioned();
        let mut z = [0.0; 8];
        let report = lbfgs(&mut obj, &mut z, &settings, &mut ws, false);
        assert_eq!(report.exit, Exit::Converged);
        assert_eq!((ws.r, ws.memory, ws.s.len()), (8, 3, 24));
    }
}
