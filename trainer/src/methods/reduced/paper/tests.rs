use super::super::lbfgs::{lbfgs, LbfgsWorkspace};
use super::super::optimize::problems::{lifted, quadratic, rosenbrock, uphill};
use super::*;

fn solve(obj: &mut dyn Objective, z: &mut [f64], settings: &SolveSettings) -> SolveReport {
    let mut ws = LbfgsWorkspace::new(z.len(), settings.memory);
    paper_lbfgs(obj, z, settings, &mut ws, true)
}

fn paper() -> SolveSettings {
    paper_settings(1e-5, 1024, Rounding::Double)
}

#[test]
fn converges_on_a_convex_quadratic_after_at_least_one_step() {
    let mut z = [0.0; 3];
    let report = solve(
        &mut quadratic(&[1.0, 3.0, 0.5], &[2.0, -1.0, 0.5], None),
        &mut z,
        &paper(),
    );
    assert_eq!(report.exit, Exit::Converged, "{report:?}");
    assert!(report.gradient_norm < 1e-5);
    // Started at the minimiser, the paper's code still takes one line search, and no trial
    // is strictly below E there: all 128 fail before the (zero) step is taken and found
    // converged.
    let mut z = [2.0, -1.0, 0.5];
    let report = solve(
        &mut quadratic(&[1.0, 3.0, 0.5], &[2.0, -1.0, 0.5], None),
        &mut z,
        &paper(),
    );
    assert_eq!(
        (report.exit, report.iterations, report.evaluations),
        (Exit::Converged, 1, 130)
    );
}

#[test]
fn a_decrease_below_ftol_is_a_saddle_where_the_product_solver_converges() {
    // 0.25 |z|^2 from (5e-5, 0): the first step (-g, taken at full length) halves z and
    // lowers E by 4.7e-10 < ftol, leaving a gradient of 1.25e-5 above the tolerance.
    let objective = || quadratic(&[0.5, 0.5], &[0.0, 0.0], None);
    let mut z = [5e-5, 0.0];
    let report = solve(&mut objective(), &mut z, &paper());
    assert_eq!((report.exit, report.iterations), (Exit::Saddle, 1), "{report:?}");
    assert!((report.gradient_norm - 1.25e-5).abs() < 1e-12, "{report:?}");
    assert_eq!(z, [2.5e-5, 0.0]);
    let mut z = [5e-5, 0.0];
    let mut ws = LbfgsWorkspace::new(2, 8);
    let ours = lbfgs(&mut objective(), &mut z, &SolveSettings::default(), &mut ws, false);
    assert_eq!(ours.exit, Exit::Converged, "{ours:?}");
}

#[test]
fn backtracks_by_four_fifths_and_caps_at_the_line_search_limit() {
    // E = |z|^2 with a gradient reported upside down: no step passes Armijo. The 128 trials
    // (steps 0.8^0 .. 0.8^127) all fail, the smallest is taken anyway, and the solve ends.
    let mut z = [1.0, 1.0];
    let report = solve(&mut uphill(), &mut z, &paper());
    assert_eq!((report.exit, report.iterations), (Exit::LineSearchCap, 1), "{report:?}");
    assert_eq!(report.evaluations, 1 + 128 + 1);
    let last = PAPER_SHRINK.powi(127);
    assert!((z[0] - (1.0 + 2.0 * last)).abs() < 1e-15, "{z:?}");
    let settings = SolveSettings {
        max_line_search: 5,
        ..paper()
    };
    let report = solve(&mut uphill(), &mut [1.0, 1.0], &settings);
    assert_eq!((report.exit, report.evaluations), (Exit::LineSearchCap, 7));
}

#[test]
fn every_solve_starts_cold() {
    // Two solves on one workspace do the same work: no pairs are carried over.
    let mut ws = LbfgsWorkspace::new(2, PAPER_MEMORY);
    let settings = SolveSettings {
        warm_start: true,
        ..paper()
    };
    let first = paper_lbfgs(&mut rosenbrock(), &mut [-1.2, 1.0], &settings, &mut ws, false);
    let second = paper_lbfgs(&mut rosenbrock(), &mut [-1.2, 1.0], &settings, &mut ws, false);
    assert_eq!(first, second);
    assert!(first.iterations > 1, "{first:?}");
}

#[test]
fn the_iteration_cap_counts_as_the_paper_code_does() {
    // The cap is checked against the iterations before the step: max_iterations = 2 stops
    // after the third step.
    let settings = SolveSettings {
        max_iterations: 2,
        ..paper()
    };
    let mut z = [-1.2, 1.0];
    let report = solve(&mut rosenbrock(), &mut z, &settings);
    assert_eq!((report.exit, report.iterations), (Exit::IterationCap, 3), "{report:?}");
    assert_eq!(report.history.len(), 4);
}

#[test]
fn where_rounding_hides_every_decrease_the_strict_armijo_test_caps_the_line_search() {
    // Lifted by 1e3 and rounded to f32, the quadratic's decreases soon fall below E's
    // spacing: no trial is strictly below the (rounded) Armijo bound, so a line search runs
    // its 128 trials and ends the solve above the tolerance, as an f32 run of the paper's
    // code does. Unrounded, the same solver converges.
    let objective = |round| lifted(quadratic(&[1.0, 2.0], &[1e-2, -1e-2], None), round);
    let mut z = [0.0, 0.0];
    let report = solve(
        &mut objective(true),
        &mut z,
        &paper_settings(1e-6, 1024, Rounding::Single),
    );
    assert_eq!(report.exit, Exit::LineSearchCap, "{report:?}");
    assert!(report.gradient_norm > 1e-6 && report.evaluations > 128, "{report:?}");
    let mut z = [0.0, 0.0];
    let report = solve(
        &mut objective(false),
        &mut z,
        &paper_settings(1e-6, 1024, Rounding::Double),
    );
    assert_eq!(report.exit, Exit::Converged, "{report:?}");
}
