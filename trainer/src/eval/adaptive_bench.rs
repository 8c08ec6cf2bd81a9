//! The adaptive subspace solver against full space on one scene (`mochi bench sim` for a
//! scene whose `[solver]` is adaptive): both run the same boundary-condition sequence in
//! one process, one thread.
//!
//! - **Trajectory difference**: the adaptive run against an independent full-space run,
//!   per frame the mean vertex distance as a fraction of the rest diagonal; the table gives
//!   its mean and maximum over the frames.
//! - **Per-step difference** (`per_step`): before each adaptive step, a full-space
//!   simulator is set to the same state and takes the same step; the difference of the two
//!   results, `max |x_a - x_f| / (h L)`, is in the units of the Newton tolerance.
//! - Cost: milliseconds per step of each (the full-space figure from the independent run),
//!   and the adaptive model's size: enriched share of the free vertices, active modes.
//!
//! A sweep runs the comparison for several values of one setting (the error thresholds,
//! Young's modulus, downdating) and charts error and cost against it.

use std::path::Path;

use mochi_sim::adaptive::{LinearSolverTimings, SubspaceHessian};
use mochi_sim::bc::BcSequence;
use mochi_sim::dataset::SpeedPlan;
use mochi_sim::measure::mean_and_max_error;
use mochi_sim::solver::StepReport;
use mochi_sim::{AdaptiveSettings, Scene, SolverSpec};

use crate::error::{TrainerError, TrainerResult};
use crate::report::chart::{line_chart, Series};

/// A setting a sweep varies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SweepKey {
    /// Both error thresholds `ε_G` (modal and nodal).
    Error,
    /// The material's Young's modulus (Pa).
    Youngs,
    /// The downdating threshold `ε_d` (0: off).
    Downdate,
}

impl SweepKey {
    /// Parses `error`, `youngs` or `downdate`.
    pub fn parse(s: &str) -> Result<Self, String> {
        match s {
            "error" => Ok(SweepKey::Error),
            "youngs" => Ok(SweepKey::Youngs),
            "downdate" => Ok(SweepKey::Downdate),
            _ => Err(format!("unknown sweep `{s}`; expected error, youngs or downdate")),
        }
    }

    /// The name in file names.
    pub fn slug(self) -> &'static str {
        match self {
            SweepKey::Error => "error",
            SweepKey::Youngs => "youngs",
            SweepKey::Downdate => "downdate",
        }
    }

    fn name(self) -> &'static str {
        match self {
            SweepKey::Error => "error threshold",
            SweepKey::Youngs => "Young's modulus (Pa)",
            SweepKey::Downdate => "downdating threshold",
        }
    }

    /// `scene` with this setting at `value` (its solver adaptive).
    fn apply(self, scene: &Scene, value: f64) -> TrainerResult<Scene> {
        let mut scene = scene.clone();
        let SolverSpec::Adaptive(settings) = &mut scene.solver else {
            return Err(not_adaptive(&scene));
        };
        match self {
            SweepKey::Error => {
                settings.modal_error = value;
                settings.nodal_error = value;
            }
            SweepKey::Downdate => settings.downdate = value,
            SweepKey::Youngs => scene.material.youngs = value,
        }
        scene.validate()?;
        Ok(scene)
    }
}

fn not_adaptive(scene: &Scene) -> TrainerError {
    TrainerError::Input(mochi_sim::InputError::field(
        &scene.source,
        "solver",
        "the adaptive comparison needs `[solver] kind = \"adaptive\"`",
    ))
}

/// One comparison of the adaptive solver with full space.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Comparison {
    /// The swept value (NaN when not a sweep).
    pub value: f64,
    /// Free degrees of freedom.
    pub dofs: usize,
    /// Elements (tets, triangles, segments).
    pub elements: usize,
    /// Mean ms per step, adaptive.
    pub adaptive_ms: f64,
    /// Mean ms per step, full space.
    pub full_ms: f64,
    /// Mean and maximum over the frames of the mean vertex distance between the two
    /// trajectories, as a fraction of the rest diagonal.
    pub trajectory_mean: f64,
    /// See `trajectory_mean`.
    pub trajectory_max: f64,
    /// Mean and maximum over the frames of `max |x_a - x_f| / (h L)` after one step from the
    /// same state (NaN unless asked for).
    pub step_mean: f64,
    /// See `step_mean`.
    pub step_max: f64,
    /// Mean and maximum enriched share of the free vertices.
    pub enriched_mean: f64,
    /// See `enriched_mean`.
    pub enriched_max: f64,
    /// Mean active modes.
    pub modes_mean: f64,
    /// Mean Newton iterations per step, adaptive and full space.
    pub adaptive_iterations: f64,
    /// See `adaptive_iterations`.
    pub full_iterations: f64,
    /// Steps whose Newton solve did not converge, adaptive.
    pub unconverged: usize,
    /// Shares of the adaptive solves' time: Hessian assembly, the oracle, the model's
    /// systems (the rest: energies, gradients, line search, contact).
    pub shares: [f64; 3],
    /// The three linear solvers timed on the system of the iterate with the most enriched
    /// coordinates (the paper's Table 3), or why they could not be.
    pub linear_solvers: Option<Result<LinearSolverTimings, String>>,
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn max(v: &[f64]) -> f64 {
    v.iter().fold(0.0f64, |m, &x| m.max(x))
}

/// Runs `scene` (its solver adaptive) and its full-space twin over `frames` frames of the
/// sequence `mochi bench sim` uses, and compares them; `log` gets one line per 10% done.
///
/// With `linear_solvers`, the solver evaluates the whole elastic Hessian exactly
/// (`subspace_hessian = "exact"`, so the full system exists to be timed), keeps the largest
/// system whose full Hessian factors (checking costs a factorisation whenever the enrichment
/// grows, inside the timed steps) and the three linear solvers are timed on it afterwards.
pub fn compare(
    scene: &Scene,
    frames: usize,
    per_step: bool,
    linear_solvers: bool,
    log: &mut dyn FnMut(String),
) -> TrainerResult<Comparison> {
    if !matches!(scene.solver, SolverSpec::Adaptive(_)) {
        return Err(not_adaptive(scene));
    }
    let mut full_scene = scene.clone();
    full_scene.solver = SolverSpec::FullSpace;
    let mut adaptive_scene = scene.clone();
    if let (SolverSpec::Adaptive(settings), true) = (&mut adaptive_scene.solver, linear_solvers) {
        settings.subspace_hessian = SubspaceHessian::Exact;
    }
    let mut adaptive = adaptive_scene.build()?;
    let mut full = full_scene.build()?;
    let mut shadow = if per_step { Some(full_scene.build()?) } else { None };
    let seq: BcSequence = adaptive.sequence(&SpeedPlan::constant(0.5), frames, scene.dataset.seed);
    let (dim, diagonal) = (adaptive.mesh.dim, adaptive.mesh.rest_diagonal());
    let scale = scene.dt * diagonal;
    let reference = full.run(&seq, &mochi_sim::Silent)?;
    let full_ms = 1e3 * mean(&reference.step_seconds[1..]);
    let full_iterations = mean(
        &reference.newton_iterations[1..]
            .iter()
            .map(|&i| i as f64)
            .collect::<Vec<_>>(),
    );
    if let Some(a) = adaptive.simulator.adaptive_mut().filter(|_| linear_solvers) {
        a.keep_largest_system();
    }
    let mut reports: Vec<StepReport> = Vec::new();
    let mut step_gaps = Vec::new();
    let mut trajectory = adaptive.start(&seq)?;
    for frame in 1..=frames {
        let before = adaptive.simulator.state();
        reports.push(adaptive.advance(&seq, frame, &mut trajectory)?);
        if let Some(s) = shadow.as_mut() {
            s.simulator.set_state(&before);
            s.step_to(&seq, frame)?;
            let after = adaptive.simulator.positions();
            let gap = after
                .iter()
                .zip(s.simulator.positions())
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            step_gaps.push(gap / scale);
        }
        if frames >= 10 && frame % (frames / 10) == 0 {
            log(format!("  {frame}/{frames} frames"));
        }
    }
    let gaps: Vec<f64> = trajectory
        .positions
        .iter()
        .zip(&reference.positions)
        .skip(1)
        .map(|(a, b)| mean_and_max_error(a.as_slice(), b, dim, diagonal).0)
        .collect();
    let stats: Vec<_> = reports.iter().filter_map(|r| r.adaptive.clone()).collect();
    let share: Vec<f64> = stats
        .iter()
        .map(|s| s.enriched_vertices as f64 / s.free_vertices.max(1) as f64)
        .collect();
    Ok(Comparison {
        value: f64::NAN,
        dofs: adaptive.simulator.num_free_dofs(),
        elements: adaptive.mesh.num_elements(),
        adaptive_ms: 1e3 * mean(&trajectory.step_seconds[1..]),
        full_ms,
        trajectory_mean: mean(&gaps),
        trajectory_max: max(&gaps),
        step_mean: if per_step { mean(&step_gaps) } else { f64::NAN },
        step_max: if per_step { max(&step_gaps) } else { f64::NAN },
        enriched_mean: mean(&share),
        enriched_max: max(&share),
        modes_mean: mean(&stats.iter().map(|s| s.active_modes as f64).collect::<Vec<_>>()),
        adaptive_iterations: mean(&reports.iter().map(|r| r.iterations as f64).collect::<Vec<_>>()),
        full_iterations,
        unconverged: reports.iter().filter(|r| !r.converged).count(),
        linear_solvers: adaptive
            .simulator
            .adaptive()
            .and_then(|a| a.time_linear_solvers())
            .map(|r| r.map_err(|e| e.to_string())),
        shares: {
            let total = reports.iter().map(|r| r.seconds).sum::<f64>().max(f64::MIN_POSITIVE);
            [
                reports.iter().map(|r| r.phases.assembly).sum::<f64>() / total,
                stats.iter().map(|s| s.oracle_seconds).sum::<f64>() / total,
                stats.iter().map(|s| s.system_seconds).sum::<f64>() / total,
            ]
        },
    })
}

/// The comparison for each of `values` of `key`.
pub fn sweep(
    scene: &Scene,
    key: SweepKey,
    values: &[f64],
    frames: usize,
    per_step: bool,
    log: &mut dyn FnMut(String),
) -> TrainerResult<Vec<Comparison>> {
    let mut rows = Vec::new();
    for &value in values {
        log(format!("{} = {value:e}", key.name()));
        let mut row = compare(&key.apply(scene, value)?, frames, per_step, false, log)?;
        row.value = value;
        rows.push(row);
    }
    Ok(rows)
}

/// The comparison table, markdown (a sweep's first column is its value).
pub fn table(scene: &str, key: Option<SweepKey>, rows: &[Comparison]) -> String {
    let mut out = String::new();
    let first = key.map_or("scene".to_string(), |k| k.name().to_string());
    out.push_str(&format!(
        "| {first} | DOF | elements | adaptive ms/step | full ms/step | speedup | trajectory diff. mean / max (% diag.) | per-step diff. mean / max (h L) | enriched mean / max % | modes | Newton it. adaptive / full | unconverged | assembly / oracle / system % |\n"
    ));
    out.push_str("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for r in rows {
        let label = if key.is_some() {
            format!("{:e}", r.value)
        } else {
            scene.to_string()
        };
        out.push_str(&format!(
            "| {label} | {} | {} | {:.2} | {:.2} | {:.2}x | {:.4} / {:.4} | {:.2e} / {:.2e} | {:.1} / {:.1} | {:.1} | {:.2} / {:.2} | {} | {:.0} / {:.0} / {:.0} |\n",
            r.dofs,
            r.elements,
            r.adaptive_ms,
            r.full_ms,
            r.full_ms / r.adaptive_ms,
            100.0 * r.trajectory_mean,
            100.0 * r.trajectory_max,
            r.step_mean,
            r.step_max,
            100.0 * r.enriched_mean,
            100.0 * r.enriched_max,
            r.modes_mean,
            r.adaptive_iterations,
            r.full_iterations,
            r.unconverged,
            100.0 * r.shares[0],
            100.0 * r.shares[1],
            100.0 * r.shares[2],
        ));
    }
    out
}

/// Charts a sweep into `dir`: error (trajectory and per-step) and cost (ms per step of
/// each solver, enriched share) against the swept value.
pub fn charts(dir: &Path, scene: &str, key: SweepKey, rows: &[Comparison]) -> TrainerResult<()> {
    crate::error::fs::create_dir_all(dir)?;
    let points = |f: &dyn Fn(&Comparison) -> f64| rows.iter().map(|r| (r.value.log10(), f(r))).collect();
    let x_label = format!("log10 {}", key.name());
    line_chart(
        &dir.join("error.png"),
        &format!("{scene}: adaptive against full space"),
        &x_label,
        "difference",
        &[
            Series {
                name: "trajectory, mean vertex distance / diagonal".into(),
                points: points(&|r| r.trajectory_mean),
            },
            Series {
                name: "one step from the same state, max |dx| / (h L)".into(),
                points: points(&|r| r.step_mean),
            },
        ],
        true,
    )?;
    line_chart(
        &dir.join("cost.png"),
        &format!("{scene}: cost per step"),
        &x_label,
        "ms per step / enriched %",
        &[
            Series {
                name: "adaptive ms/step".into(),
                points: points(&|r| r.adaptive_ms),
            },
            Series {
                name: "full space ms/step".into(),
                points: points(&|r| r.full_ms),
            },
            Series {
                name: "enriched vertices, mean %".into(),
                points: points(&|r| 100.0 * r.enriched_mean),
            },
        ],
        true,
    )
}

/// The adaptive settings of a scene, if it uses the adaptive solver.
pub fn adaptive_settings(scene: &Scene) -> Option<&AdaptiveSettings> {
    match &scene.solver {
        SolverSpec::Adaptive(s) => Some(s),
        SolverSpec::FullSpace | SolverSpec::Vbd(_) => None,
    }
}

/// The linear-solver table of one comparison (the paper's Table 3), markdown.
pub fn linear_solver_table(scene: &str, comparison: &Comparison) -> String {
    match &comparison.linear_solvers {
        None => format!("{scene}: no system was kept for the linear-solver table\n"),
        Some(Err(e)) => format!("{scene}: the linear solvers could not be timed: {e}\n"),
        Some(Ok(t)) => format!(
            "| {scene}: one Newton system, {} free coordinates, {} enriched, {} modes | ms | iterations | relative residual |\n\
             |---|---|---|---|\n\
             | adaptive model, Schur-complement PCG | {:.2} | {} | (its own system) |\n\
             | full system, faer sparse Cholesky | {:.2} | - | {:.1e} |\n\
             | full system, block-Jacobi PCG | {:.2} | {} | {:.1e} |\n",
            t.free_dofs,
            t.enriched_dofs,
            t.modes,
            1e3 * t.schur_seconds,
            t.schur_iterations,
            1e3 * t.cholesky_seconds,
            t.full_residuals[0],
            1e3 * t.pcg_seconds,
            t.pcg_iterations,
            t.full_residuals[1],
        ),
    }
}
