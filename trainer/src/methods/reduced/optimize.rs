//! The contract between the reduced solvers and the objective they minimise: the
//! [`Objective`] trait, the [`SolveSettings`] every solver reads, the [`SolveReport`] and its
//! [`Exit`] (the four exit conditions of Lyu et al. 2024), an [`ExitCounts`] tally for the
//! per-step convergence tables, and the backtracking line search both solvers share.

use super::rounding::Rounding;

/// A smooth objective of a small dense vector, as the reduced solvers see it.
pub trait Objective {
    /// Number of unknowns r.
    fn dim(&self) -> usize;
    /// E(z). May return a non-finite value for z outside the domain (the line search must
    /// then backtrack).
    fn value(&mut self, z: &[f64]) -> f64;
    /// E(z), writing grad E(z) into `grad` (r values).
    fn gradient(&mut self, z: &[f64], grad: &mut [f64]) -> f64;
    /// E(z), its gradient and a positive semi-definite approximation of its Hessian (r x r,
    /// row-major) into `hess`.
    fn hessian(&mut self, z: &[f64], grad: &mut [f64], hess: &mut [f64]) -> f64;
}

/// Why a solve stopped, in the order of the paper's exit conditions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Exit {
    /// The gradient's infinity norm is at most [`SolveSettings::tolerance`].
    Converged,
    /// No step can lower E: even steepest descent is not a descent direction (the gradient
    /// or E is non-finite at the iterate, or the objective does not fit the unknowns), or
    /// its line search shrank the step until the trial point equalled the iterate.
    Saddle,
    /// The line search along steepest descent needed more than
    /// [`SolveSettings::max_line_search`] halvings without finding a step of sufficient
    /// decrease.
    LineSearchCap,
    /// [`SolveSettings::max_iterations`] iterations ran without convergence.
    IterationCap,
}

impl Exit {
    /// Every exit, in the paper's order (the order of [`ExitCounts`]).
    pub const ALL: [Exit; 4] = [Exit::Converged, Exit::Saddle, Exit::LineSearchCap, Exit::IterationCap];

    /// A short phrase for reports and tables.
    pub fn describe(self) -> &'static str {
        match self {
            Exit::Converged => "converged (gradient below tolerance)",
            Exit::Saddle => "saddle (no descent direction)",
            Exit::LineSearchCap => "line search cap (too many halvings)",
            Exit::IterationCap => "iteration cap (too many iterations)",
        }
    }
}

/// The knobs every reduced solver reads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveSettings {
    /// Converged once the gradient's infinity norm is at most this. Default `1e-5`.
    pub tolerance: f64,
    /// The most iterations (accepted steps) a solve takes. Default `1024`.
    pub max_iterations: usize,
    /// The most halvings (trials after the first) one line search takes. Default `128`.
    pub max_line_search: usize,
    /// How many (s, y) pairs L-BFGS keeps; 0 gives steepest descent. Default `8`.
    pub memory: usize,
    /// L-BFGS starts from the pairs of the previous solve on the same workspace instead of
    /// steepest descent (see [`super::lbfgs`]). Default `true`.
    pub warm_start: bool,
    /// The arithmetic of the line search's bound and of L-BFGS's no-progress exit (see
    /// [`super::rounding`]; the objective rounds its own numbers). Default double.
    pub rounding: Rounding,
}

impl Default for SolveSettings {
    fn default() -> Self {
        SolveSettings {
            tolerance: 1e-5,
            max_iterations: 1024,
            max_line_search: 128,
            memory: 8,
            warm_start: true,
            rounding: Rounding::Double,
        }
    }
}

/// What a solve did and where it stopped.
#[derive(Debug, Clone, PartialEq)]
pub struct SolveReport {
    /// Why it stopped.
    pub exit: Exit,
    /// Accepted steps.
    pub iterations: usize,
    /// Calls to the objective (value, gradient and Hessian calls alike).
    pub evaluations: usize,
    /// E at the final iterate.
    pub objective: f64,
    /// Infinity norm of the gradient at the final iterate (NaN when any entry is NaN).
    pub gradient_norm: f64,
    /// E before the first step and after each accepted step (`iterations + 1` entries) when
    /// the solve was asked to record it; empty otherwise.
    pub history: Vec<f64>,
}

impl SolveReport {
    /// Whether the solve ended with [`Exit::Converged`].
    pub fn converged(&self) -> bool {
        self.exit == Exit::Converged
    }
}

/// How many solves ended in each [`Exit`], for per-step convergence tables.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ExitCounts {
    counts: [usize; 4],
    /// Objective evaluations of the solves that ended in each exit, summed.
    evaluations: [usize; 4],
}

impl ExitCounts {
    /// Counts the exit of one solve and its evaluations.
    pub fn add(&mut self, report: &SolveReport) {
        self.counts[report.exit as usize] += 1;
        self.evaluations[report.exit as usize] += report.evaluations;
    }

    /// Adds another tally's solves to this one.
    pub fn merge(&mut self, other: &ExitCounts) {
        for k in 0..4 {
            self.counts[k] += other.counts[k];
            self.evaluations[k] += other.evaluations[k];
        }
    }

    /// Mean objective evaluations of a solve that ended in `exit` (line-search trials
    /// included); NaN when none did.
    pub fn mean_evaluations(&self, exit: Exit) -> f64 {
        match self.count(exit) {
            0 => f64::NAN,
            n => self.evaluations[exit as usize] as f64 / n as f64,
        }
    }

    /// Solves that ended in `exit`.
    pub fn count(&self, exit: Exit) -> usize {
        self.counts[exit as usize]
    }

    /// Solves counted.
    pub fn total(&self) -> usize {
        self.counts.iter().sum()
    }

    /// The share of solves that ended in `exit`, in [0, 1]; 0 when nothing was counted.
    pub fn fraction(&self, exit: Exit) -> f64 {
        match self.total() {
            0 => 0.0,
            total => self.count(exit) as f64 / total as f64,
        }
    }
}

/// The Armijo sufficient-decrease constant c1.
pub(crate) const ARMIJO_C1: f64 = 1e-4;

/// The Wolfe curvature constant c2, checked when the line search is given slopes.
pub(crate) const WOLFE_C2: f64 = 0.9;

/// `a . b`.
pub(crate) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// The infinity norm, NaN when any entry is NaN (`f64::max` would drop it).
pub(crate) fn inf_norm(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |acc: f64, &x| {
        if acc.is_nan() || x.is_nan() {
            f64::NAN
        } else {
            acc.max(x.abs())
        }
    })
}

/// The limits of one line search: its halvings and the arithmetic of its bound.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SearchLimits {
    /// The most trials after the first.
    pub max_halvings: usize,
    /// The Armijo bound `f0 + c1 * step * slope` is rounded to this (in single precision a
    /// step whose decrease rounds away passes with E unchanged, as in an `f32` solver).
    pub rounding: Rounding,
}

impl SearchLimits {
    /// `max_halvings` in double precision.
    #[cfg(test)]
    pub fn halvings(max_halvings: usize) -> Self {
        SearchLimits {
            max_halvings,
            rounding: Rounding::Double,
        }
    }
}

impl From<&SolveSettings> for SearchLimits {
    fn from(settings: &SolveSettings) -> Self {
        SearchLimits {
            max_halvings: settings.max_line_search,
            rounding: settings.rounding,
        }
    }
}

/// How a line search ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Search {
    /// `trial` holds the accepted point; E there.
    Accepted(f64),
    /// The step shrank until `z + step * d` equalled `z`: no representable step lowers E.
    Stalled,
    /// More than the allowed halvings were needed.
    Capped,
}

/// Line search along `d` from `z`, where E(z) = `f0` (finite) and the slope `g . d` is
/// finite and negative. Each trial writes `z + step * d` into `trial` and evaluates it with
/// `eval`, which returns E there and, optionally, the slope `grad E(trial) . d`.
///
/// The first trial is step 1. A trial whose value is non-finite or fails the Armijo
/// condition `E <= f0 + c1 * step * slope` (the bound rounded as `limits` says) bounds the
/// step from above. Without slopes the first trial that passes is accepted: backtracking,
/// halving the step. With slopes the accepted trial must also meet the weak Wolfe curvature
/// condition `slope(trial) >= c2 * slope`; a trial that passes Armijo but not it bounds the
/// step from below. With slopes the next step is interpolated rather than halved or doubled: inside a
/// bracket, the minimiser of the cubic through both ends' values and slopes (Nocedal &
/// Wright, Eq. 3.59), kept at least a tenth of the bracket from either end; beyond the
/// last step that was too short, where the slope extrapolates linearly to zero, between
/// 2 and 10 times that step. Where the cubic is undefined (a non-finite end, no real
/// minimiser) the bracket is bisected, and without an upper bound the step doubles. Every
/// trial after the first counts as one halving against `limits.max_halvings`; when they run out
/// after some step passed Armijo, the largest such step is re-evaluated and accepted.
///
/// Returns the outcome and the number of `eval` calls. `eval` may compute more than E (the
/// L-BFGS solver evaluates the gradient with it, so the accepted point needs no second
/// call).
pub(crate) fn line_search(
    z: &[f64],
    d: &[f64],
    f0: f64,
    slope: f64,
    limits: SearchLimits,
    trial: &mut [f64],
    mut eval: impl FnMut(&[f64]) -> (f64, Option<f64>),
) -> (Search, usize) {
    let SearchLimits { max_halvings, rounding } = limits;
    let armijo = |step: f64| rounding.round(f0 + ARMIJO_C1 * step * slope);
    // The bracket's ends: step, value and slope (NaN where unknown).
    let mut lo = Probe {
        step: 0.0,
        value: f0,
        slope,
    };
    let mut hi = Probe {
        step: f64::INFINITY,
        value: f64::NAN,
        slope: f64::NAN,
    };
    let mut step = 1.0;
    let mut evaluations = 0;
    for _ in 0..=max_halvings {
        if !place(trial, z, d, step) {
            return (Search::Stalled, evaluations);
        }
        let (value, trial_slope) = eval(trial);
        evaluations += 1;
        let probe = Probe {
            step,
            value,
            slope: trial_slope.unwrap_or(f64::NAN),
        };
        if !(value.is_finite() && value <= armijo(step)) {
            hi = probe;
        } else if trial_slope.is_some_and(|s| s < WOLFE_C2 * slope) {
            lo = probe;
        } else {
            return (Search::Accepted(value), evaluations);
        }
        step = next_step(&lo, &hi, slope);
    }
    let lo = lo.step;
    if lo > 0.0 && place(trial, z, d, lo) {
        let (value, _) = eval(trial);
        evaluations += 1;
        if value.is_finite() && value <= armijo(lo) {
            return (Search::Accepted(value), evaluations);
        }
    }
    (Search::Capped, evaluations)
}

/// One evaluated point of a line search: `step`, E there and the slope `grad E . d` (NaN
/// where unknown).
struct Probe {
    step: f64,
    value: f64,
    slope: f64,
}

/// The next trial step of [`line_search`] for the bracket `lo` (passed Armijo, too short;
/// step 0 at first) .. `hi` (failed Armijo; infinite while none has), `slope0` the slope at
/// step 0 (see its documentation).
fn next_step(lo: &Probe, hi: &Probe, slope0: f64) -> f64 {
    if !hi.step.is_finite() {
        // Extrapolate: where the slope, linear in the step through 0 and `lo`, reaches zero.
        let rise = lo.slope - slope0;
        let zero = if rise > 0.0 {
            lo.step * -slope0 / rise
        } else {
            f64::INFINITY
        };
        return if zero.is_finite() {
            zero.clamp(2.0 * lo.step, 10.0 * lo.step)
        } else {
            2.0 * lo.step
        };
    }
    let width = hi.step - lo.step;
    let bisect = lo.step + 0.5 * width;
    let known = [lo.value, lo.slope, hi.value, hi.slope].iter().all(|v| v.is_finite());
    if !known {
        return bisect;
    }
    // Minimiser of the cubic through (lo, hi) with both values and slopes (N&W Eq. 3.59).
    let d1 = lo.slope + hi.slope - 3.0 * (lo.value - hi.value) / (lo.step - hi.step);
    let disc = d1 * d1 - lo.slope * hi.slope;
    if disc.is_nan() || disc < 0.0 {
        return bisect;
    }
    let d2 = disc.sqrt();
    let cubic = hi.step - width * (hi.slope + d2 - d1) / (hi.slope - lo.slope + 2.0 * d2);
    if !cubic.is_finite() {
        return bisect;
    }
    cubic.clamp(lo.step + 0.1 * width, hi.step - 0.1 * width)
}

/// Writes `z + step * d` into `trial`; false when that equals `z`.
fn place(trial: &mut [f64], z: &[f64], d: &[f64], step: f64) -> bool {
    let mut moved = false;
    for ((t, &zi), &di) in trial.iter_mut().zip(z).zip(d) {
        *t = zi + step * di;
        moved |= *t != zi;
    }
    moved
}

/// Whether a solve in single precision should stop after an accepted step from E = `before`
/// to E = `after` with gradient `g` there: rounding hid the step's decrease (E did not fall)
/// and the gradient is still above the tolerance (JAX's L-BFGS stops there too, on
/// insufficient progress). Never in double precision.
pub(crate) fn rounding_stalled(settings: &SolveSettings, before: f64, after: f64, g: &[f64]) -> bool {
    settings.rounding == Rounding::Single && after >= before && inf_norm(g) > settings.tolerance
}

/// Whether `slope = g . d` makes `d` a usable descent direction.
pub(crate) fn is_descent(slope: f64) -> bool {
    slope.is_finite() && slope < 0.0
}

/// The report of a solve that stopped at `z` with objective `f` and gradient `g`.
pub(crate) fn report(
    exit: Exit,
    iterations: usize,
    evaluations: usize,
    f: f64,
    g: &[f64],
    history: Vec<f64>,
) -> SolveReport {
    SolveReport {
        exit,
        iterations,
        evaluations,
        objective: f,
        gradient_norm: inf_norm(g),
        history,
    }
}

/// Test problems both solvers are checked on.
#[cfg(test)]
pub(crate) mod problems;

#[cfg(test)]
mod tests {
    use super::*;

    fn report_with(exit: Exit) -> SolveReport {
        report(exit, 0, 0, 0.0, &[], Vec::new())
    }

    #[test]
    fn exit_counts_tally_and_fractions() {
        let mut counts = ExitCounts::default();
        assert_eq!(counts.fraction(Exit::Converged), 0.0);
        for exit in [Exit::Converged, Exit::Converged, Exit::Saddle, Exit::IterationCap] {
            counts.add(&report_with(exit));
        }
        assert_eq!(counts.total(), 4);
        assert_eq!(counts.count(Exit::Converged), 2);
        assert_eq!(counts.count(Exit::LineSearchCap), 0);
        assert_eq!(counts.fraction(Exit::Converged), 0.5);
        let sum: f64 = Exit::ALL.iter().map(|&e| counts.fraction(e)).sum();
        assert_eq!(sum, 1.0);
    }

    #[test]
    fn exit_counts_keep_each_exits_evaluations() {
        let with = |exit, evaluations| report(exit, 1, evaluations, 0.0, &[], Vec::new());
        let mut counts = ExitCounts::default();
        counts.add(&with(Exit::Converged, 3));
        counts.add(&with(Exit::Converged, 5));
        counts.add(&with(Exit::LineSearchCap, 258));
        assert_eq!(counts.mean_evaluations(Exit::Converged), 4.0);
        assert_eq!(counts.mean_evaluations(Exit::LineSearchCap), 258.0);
        assert!(counts.mean_evaluations(Exit::Saddle).is_nan());
        let mut merged = ExitCounts::default();
        merged.merge(&counts);
        merged.add(&with(Exit::Converged, 1));
        assert_eq!(merged.count(Exit::Converged), 3);
        assert_eq!(merged.mean_evaluations(Exit::Converged), 3.0);
        assert_eq!(merged.count(Exit::LineSearchCap), 1);
    }

    #[test]
    fn inf_norm_propagates_nan() {
        assert_eq!(inf_norm(&[1.0, -3.0, 2.0]), 3.0);
        assert!(inf_norm(&[1.0, f64::NAN, 2.0]).is_nan());
        assert!(inf_norm(&[f64::NAN, 1.0]).is_nan());
        assert_eq!(inf_norm(&[]), 0.0);
    }

    /// [`line_search`] from 0 along +1 in double precision.
    fn from_zero(
        f0: f64,
        slope: f64,
        halvings: usize,
        trial: &mut [f64],
        eval: impl FnMut(&[f64]) -> (f64, Option<f64>),
    ) -> (Search, usize) {
        line_search(&[0.0], &[1.0], f0, slope, SearchLimits::halvings(halvings), trial, eval)
    }

    #[test]
    fn line_search_rejects_non_finite_values_and_halves() {
        // E(x) = x^2 on |x| <= 1, NaN beyond; from 0.9 along -3.6 the full step leaves the
        // domain, the half step does not decrease E and the quarter step reaches 0.
        let mut seen = Vec::new();
        let mut trial = [0.0];
        let (outcome, evaluations) = line_search(
            &[0.9],
            &[-3.6],
            0.81,
            -6.48,
            SearchLimits::halvings(10),
            &mut trial,
            |t| {
                seen.push(t[0]);
                let value = if t[0].abs() > 1.0 { f64::NAN } else { t[0] * t[0] };
                (value, None)
            },
        );
        assert_eq!(evaluations, 3);
        assert_eq!(seen, vec![0.9 - 3.6, -0.9, 0.0]);
        assert_eq!(outcome, Search::Accepted(0.0));
        assert_eq!(trial[0], 0.0);
    }

    #[test]
    fn line_search_stalls_or_caps_when_nothing_decreases() {
        let mut trial = [0.0];
        let (outcome, evaluations) = line_search(
            &[1.0],
            &[1.0],
            1.0,
            -1.0,
            SearchLimits::halvings(128),
            &mut trial,
            |t| (t[0], None),
        );
        assert_eq!(outcome, Search::Stalled);
        assert!(evaluations <= 60, "{evaluations}");
        let (outcome, evaluations) = from_zero(0.0, -1.0, 5, &mut trial, |t| (t[0], None));
        assert_eq!(outcome, Search::Capped);
        assert_eq!(evaluations, 6);
    }

    #[test]
    fn line_search_with_slopes_extrapolates_until_the_curvature_condition_holds() {
        // E(x) = (x - 100)^2 from 0 along +1: step 1 decreases E enough but the slope is
        // still steep; the slope, extrapolated linearly, vanishes at 100, and the next trial
        // is clamped to 10 times the last: there the slope is c2 times the initial one.
        let mut seen = Vec::new();
        let mut trial = [0.0];
        let (outcome, evaluations) = from_zero(1e4, -200.0, 128, &mut trial, |t| {
            seen.push(t[0]);
            ((t[0] - 100.0).powi(2), Some(2.0 * (t[0] - 100.0)))
        });
        assert_eq!(seen, vec![1.0, 10.0]);
        assert_eq!((outcome, evaluations), (Search::Accepted(8100.0), 2));
        // With no trials left the largest Armijo step is re-evaluated and taken.
        let (outcome, evaluations) = from_zero(1e4, -200.0, 0, &mut trial, |t| {
            ((t[0] - 100.0).powi(2), Some(2.0 * (t[0] - 100.0)))
        });
        assert_eq!((outcome, evaluations), (Search::Accepted(9801.0), 2));
        assert_eq!(trial, [1.0]);
    }

    #[test]
    fn line_search_with_slopes_interpolates_inside_a_bracket() {
        // E(x) = (x - 0.3)^2: step 1 overshoots, and the cubic through both ends' values
        // and slopes is the quadratic itself, so the second trial is its minimiser.
        let mut seen = Vec::new();
        let mut trial = [0.0];
        let (outcome, evaluations) = from_zero(0.09, -0.6, 128, &mut trial, |t| {
            seen.push(t[0]);
            ((t[0] - 0.3).powi(2), Some(2.0 * (t[0] - 0.3)))
        });
        assert_eq!(evaluations, 2, "{seen:?}");
        assert!((seen[1] - 0.3).abs() < 1e-12, "{seen:?}");
        assert!(matches!(outcome, Search::Accepted(v) if v < 1e-20));
        // A non-finite end cannot be interpolated: the bracket is bisected instead.
        let mut seen = Vec::new();
        let (outcome, _) = from_zero(0.09, -0.6, 128, &mut trial, |t| {
            seen.push(t[0]);
            let e = if t[0] > 0.6 { f64::NAN } else { (t[0] - 0.3).powi(2) };
            (e, Some(2.0 * (t[0] - 0.3)))
        });
        assert_eq!(seen[1], 0.5, "{seen:?}");
        assert!(matches!(outcome, Search::Accepted(_)));
    }

    #[test]
    fn a_rounded_bound_accepts_a_step_whose_decrease_rounds_away() {
        // E is flat at 1000 and the predicted decrease tiny: in double precision no step
        // passes Armijo; with the bound rounded to f32 the first one does, E unchanged.
        let mut trial = [0.0];
        let flat = |_: &[f64]| (1000.0, None);
        let (outcome, _) = from_zero(1000.0, -1e-6, 5, &mut trial, flat);
        assert_eq!(outcome, Search::Capped);
        let single = SearchLimits {
            max_halvings: 5,
            rounding: Rounding::Single,
        };
        let (outcome, evaluations) = line_search(&[0.0], &[1.0], 1000.0, -1e-6, single, &mut trial, flat);
        assert_eq!((outcome, evaluations), (Search::Accepted(1000.0), 1));
    }

    #[test]
    fn every_exit_has_a_distinct_description() {
        for (i, a) in Exit::ALL.iter().enumerate() {
            assert_eq!(*a as usize, i);
            for b in &Exit::ALL[i + 1..] {
                assert_ne!(a.describe(), b.describe());
            }
        }
    }
}
