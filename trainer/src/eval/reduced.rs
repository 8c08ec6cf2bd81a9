//! The reduced-order solver on the test sequences (Lyu et al. 2024): each subspace of a
//! scene's `.reduced` file steps every test sequence with one solve of Eq. 2 per frame, from
//! the scene's start, against the full-space reference.
//!
//! Measured per subspace and sequence: mean and max vertex error (fraction of the rest
//! diagonal) over the reference frames, seconds per step (the solve, whose last evaluation
//! decodes the state; one thread), iterations per step and how each step ended (the paper's
//! four exits), and frames before a step failed (a non-finite latent). `Lip[d^2 P/dz^2]`
//! (Eq. 7) is estimated on the latents the rollouts visited (every tenth frame), with the
//! scene's exact elastic energy, for the vanilla and the optimised subspace alike. Each
//! subspace runs twice: with the scene's energies, and with runtime cubature (the elastic
//! terms through the cubature fitted for the Lipschitz loss, the other terms exact).

use mochi_sim::bc::BcSequence;
use mochi_sim::cubature::CubatureEnergy;
use mochi_sim::dataset::SequencePlan;
use mochi_sim::measure::mean_and_max_error;
use mochi_sim::trajectory::Trajectory;
use mochi_sim::{BuiltScene, StencilEnergy, TimeScheme};

use crate::artifact::reduced::{ReducedArtifact, SubspaceData};
use crate::error::TrainerResult;
use crate::learn::encoding::Encoding;
use crate::learn::recipe::Recipe;
use crate::learn::reduced_spec::{ReducedSpec, SolverChoice, SolverPrecision};
use crate::methods::lipschitz::cubature::cubature_energies;
use crate::methods::lipschitz::cubature::{elastic_terms, ELASTIC_TERMS};
use crate::methods::lipschitz::loss::{lipschitz_estimate, LatentSample, LipschitzTerm};
use crate::methods::method::run_sequence;
use crate::methods::reduced::method::ReducedMethod;
use crate::methods::reduced::optimize::{Exit, ExitCounts, SolveSettings};
use crate::methods::reduced::paper::paper_settings;
use crate::methods::reduced::projection::project;
use crate::methods::reduced::rounding::Rounding;
use crate::methods::reduced::stepper::scene_objective_scale;
use crate::methods::reduced::stepper::{ReducedSolver, StepperSettings};
use crate::methods::reduced::subspace::DecoderSubspace;
use crate::progress::Reporter;
use crate::report::chart::{self, Series};

/// One subspace on one test sequence.
#[derive(Clone, Debug, Default)]
pub struct ReducedMetrics {
    /// Mean over frames of the mean vertex error / diagonal.
    pub mean_error: f64,
    /// Max over frames of the max vertex error / diagonal.
    pub max_error: f64,
    /// Mean vertex error / diagonal of every measured frame.
    pub error_curve: Vec<f64>,
    /// Mean seconds per step.
    pub step_seconds: f64,
    /// Mean solver iterations per step.
    pub iterations: f64,
    /// Mean objective evaluations per step (line-search trials included).
    pub evaluations: f64,
    /// How the steps ended.
    pub exits: ExitCounts,
    /// Mean over steps of the gradient's infinity norm where each solve stopped (the
    /// paper's mean exit gradient norm).
    pub exit_gradient: f64,
    /// Frames stepped before a step failed (all of them when none did).
    pub stable_frames: usize,
    /// Objective after each iteration of the tenth step (the convergence chart).
    pub convergence: Vec<f64>,
    /// Mean vertex error / diagonal of the subspace's projections of every tenth reference
    /// frame (the closest the subspace comes to them; NaN where not measured).
    pub projection_error: f64,
    /// Those projected states, in order.
    pub projections: Vec<Vec<f64>>,
}

/// One subspace on every test sequence.
#[derive(Clone, Debug)]
pub struct ReducedReport {
    /// "vanilla" or "Lipschitz", with or without runtime cubature.
    pub name: &'static str,
    /// Latent size.
    pub latent: usize,
    /// Per sequence: its plan and the metrics.
    pub sequences: Vec<(SequencePlan, ReducedMetrics)>,
    /// `Lip[d^2 P/dz^2]` on the visited latents.
    pub lipschitz: f64,
    /// Training seconds (from the file).
    pub training_seconds: f64,
    /// Mean vertex distance / diagonal between this subspace's projections of the reference
    /// frames and the vanilla subspace's (the paper's Fig. 7 check; NaN for the vanilla
    /// subspace itself and the runtime-cubature runs).
    pub manifold_gap: f64,
}

impl ReducedReport {
    /// Mean of a metric over the sequences.
    pub fn mean_of(&self, f: impl Fn(&ReducedMetrics) -> f64) -> f64 {
        self.sequences.iter().map(|(_, m)| f(m)).sum::<f64>() / self.sequences.len().max(1) as f64
    }
}

/// The step settings of a `[reduced]` table.
pub fn stepper_settings(spec: &ReducedSpec, scheme: TimeScheme) -> StepperSettings {
    let rounding = match spec.precision {
        SolverPrecision::Double => Rounding::Double,
        SolverPrecision::Single => Rounding::Single,
    };
    let (solver, solve) = match spec.solver {
        SolverChoice::LbfgsPaper => (
            ReducedSolver::PaperLbfgs,
            paper_settings(spec.tolerance, spec.max_iterations, rounding),
        ),
        choice => (
            match choice {
                SolverChoice::Newton => ReducedSolver::Newton,
                _ => ReducedSolver::Lbfgs,
            },
            SolveSettings {
                tolerance: spec.tolerance,
                max_iterations: spec.max_iterations,
                warm_start: spec.warm_start,
                memory: spec.memory,
                rounding,
                ..SolveSettings::default()
            },
        ),
    };
    StepperSettings {
        solver,
        solve,
        quasi_static: scheme == TimeScheme::QuasiStatic,
        record_history: false,
    }
}

/// Steps both subspaces of `reduced` over the test sequences (`tests` with their boundary
/// conditions `plans`) for `frames` frames each.
pub fn evaluate_reduced(
    reduced: &ReducedArtifact,
    problem: &BuiltScene,
    encoding: &Encoding,
    tests: &[(SequencePlan, Trajectory)],
    plans: &[BcSequence],
    frames: usize,
    report: &dyn Reporter,
) -> TrainerResult<Vec<ReducedReport>> {
    let recipe = Recipe::parse(&reduced.scene_toml, std::path::Path::new(&reduced.scene_path))?;
    let spec = recipe.reduced.clone().unwrap_or_default();
    let settings = stepper_settings(&spec, problem.scene.integrator);
    let potentials: Vec<&dyn StencilEnergy> = problem.simulator.potentials().iter().map(|p| p.as_ref()).collect();
    let elastic = elastic_terms(&potentials);
    let cubatures = cubature_energies(problem, &reduced.cubature)?;
    let with_cubature = with_runtime_cubature(&potentials, &cubatures);
    let runs = subspace_runs(reduced, &potentials, &with_cubature);
    let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
    let mut out: Vec<ReducedReport> = Vec::new();
    for (run, (name, data, terms)) in runs.into_iter().enumerate() {
        let mut sequences = Vec::new();
        let mut visited = Vec::new();
        for ((plan, reference), bc) in tests.iter().zip(plans) {
            let mut metrics = step_sequence(
                data,
                problem,
                encoding,
                &settings,
                terms,
                bc,
                Some(reference),
                frames,
                &mut visited,
            )?;
            report.message(&format!(
                "{} reduced ({name}) on {}: mean error {:.3}%, {:.2} ms/step, {:.1} iterations/step ({:.1} evaluations), {:.0}% converged",
                problem.scene.name,
                plan.name,
                100.0 * metrics.mean_error,
                1e3 * metrics.step_seconds,
                metrics.iterations,
                metrics.evaluations,
                100.0 * metrics.exits.fraction(Exit::Converged)
            ));
            // The exact-energy runs also project the reference frames onto their subspace.
            metrics.projection_error = f64::NAN;
            if run < 2 {
                metrics.projections = project_reference(data, problem, encoding, bc, reference, frames)?;
                let errors: Vec<f64> = metrics
                    .projections
                    .iter()
                    .enumerate()
                    .map(|(k, x)| {
                        let t = PROJECTION_EVERY * (k + 1);
                        mean_and_max_error(x, &reference.positions[t], dim, diagonal).0
                    })
                    .collect();
                metrics.projection_error = errors.iter().sum::<f64>() / errors.len().max(1) as f64;
            }
            sequences.push((plan.clone(), metrics));
        }
        let manifold_gap = match (run, out.first()) {
            (1, Some(vanilla)) => mean_gap(&vanilla.sequences, &sequences, dim, diagonal),
            _ => f64::NAN,
        };
        let decoder = data.decoder()?;
        let term = LipschitzTerm {
            encoding,
            potentials: &elastic,
            scale: scene_objective_scale(problem),
            diagonal: problem.mesh.rest_diagonal(),
        };
        let lipschitz = lipschitz_estimate(&term.hessians(&decoder, &visited)?, &visited);
        out.push(ReducedReport {
            name,
            latent: data.initial_latent.len(),
            sequences,
            lipschitz,
            training_seconds: data.training_seconds,
            manifold_gap,
        });
    }
    Ok(out)
}

/// Every how many frames the reference is projected onto a subspace.
pub const PROJECTION_EVERY: usize = 10;

/// The projections of reference frames `PROJECTION_EVERY`, `2 PROJECTION_EVERY`, ... (up to
/// `frames`) onto `data`'s subspace with the handles of `bc`, each started from the last.
fn project_reference(
    data: &SubspaceData,
    problem: &BuiltScene,
    encoding: &Encoding,
    bc: &BcSequence,
    reference: &Trajectory,
    frames: usize,
) -> TrainerResult<Vec<Vec<f64>>> {
    let dim = problem.mesh.dim;
    let masses = problem.simulator.masses();
    let diagonal = problem.mesh.rest_diagonal();
    let targets0 = bc.targets(&problem.handles, 0, dim);
    let mut subspace = DecoderSubspace::new(&data.decoder()?, encoding, &targets0)?;
    let mut z = data.initial_latent.clone();
    let last = frames.min(reference.num_frames().saturating_sub(1)).min(bc.frames());
    let mut out = Vec::new();
    for t in (PROJECTION_EVERY..=last).step_by(PROJECTION_EVERY) {
        let targets = bc.targets(&problem.handles, t, dim);
        subspace.set_frame(&encoding.frame(&targets)?, &targets);
        let mut x = vec![0.0; reference.positions[t].len()];
        project(&mut subspace, masses, diagonal, &reference.positions[t], &mut z, &mut x)?;
        out.push(x);
    }
    Ok(out)
}

/// Mean over sequences and projected frames of the mean vertex distance / diagonal between
/// the projections of `a` and `b`.
fn mean_gap(
    a: &[(SequencePlan, ReducedMetrics)],
    b: &[(SequencePlan, ReducedMetrics)],
    dim: usize,
    diagonal: f64,
) -> f64 {
    let gaps: Vec<f64> = a
        .iter()
        .zip(b)
        .flat_map(|((_, ma), (_, mb))| ma.projections.iter().zip(&mb.projections))
        .map(|(xa, xb)| mean_and_max_error(xa, xb, dim, diagonal).0)
        .collect();
    if gaps.is_empty() {
        return f64::NAN;
    }
    gaps.iter().sum::<f64>() / gaps.len() as f64
}

/// Runtime cubature: the elastic terms through `cubatures` (fitted for the Lipschitz loss),
/// the other terms of `potentials` exact.
pub fn with_runtime_cubature<'a>(
    potentials: &[&'a dyn StencilEnergy],
    cubatures: &'a [CubatureEnergy<'a>],
) -> Vec<&'a dyn StencilEnergy> {
    cubatures
        .iter()
        .map(|c| c as &dyn StencilEnergy)
        .chain(
            potentials
                .iter()
                .copied()
                .filter(|p| !ELASTIC_TERMS.contains(&p.name())),
        )
        .collect()
}

/// The four runs of a `.reduced` file: each subspace with the scene's energies (`exact`),
/// then each with runtime cubature (`cubature`).
pub fn subspace_runs<'a>(
    reduced: &'a ReducedArtifact,
    exact: &'a Vec<&'a dyn StencilEnergy>,
    cubature: &'a Vec<&'a dyn StencilEnergy>,
) -> [(&'static str, &'a SubspaceData, &'a Vec<&'a dyn StencilEnergy>); 4] {
    [
        ("vanilla", &reduced.vanilla, exact),
        ("Lipschitz", &reduced.lipschitz, exact),
        ("vanilla, runtime cubature", &reduced.vanilla, cubature),
        ("Lipschitz, runtime cubature", &reduced.lipschitz, cubature),
    ]
}

/// One rollout of `data`'s subspace over `bc`, measured against `reference` when given;
/// pushes every tenth frame's latent into `visited`.
#[allow(clippy::too_many_arguments)]
pub fn step_sequence(
    data: &SubspaceData,
    problem: &BuiltScene,
    encoding: &Encoding,
    settings: &StepperSettings,
    potentials: &[&dyn StencilEnergy],
    bc: &BcSequence,
    reference: Option<&Trajectory>,
    frames: usize,
    visited: &mut Vec<LatentSample>,
) -> TrainerResult<ReducedMetrics> {
    let decoder = data.decoder()?;
    let mut method = ReducedMethod::new(
        String::new(),
        String::new(),
        problem,
        &decoder,
        &data.initial_latent,
        encoding,
        potentials.to_vec(),
        settings.clone(),
        problem.scene.dt,
    );
    let references: Vec<&[Vec<f64>]> = reference.map(|r| &r.positions[..]).into_iter().collect();
    let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
    let run = run_sequence(&mut method, bc, frames, &references, dim, diagonal, None)?;
    let log = method.log();
    let done = run.stable_frames.max(1) as f64;
    visited.extend(log.visited.iter().cloned());
    Ok(ReducedMetrics {
        mean_error: match reference {
            Some(_) => run.mean_error(0),
            None => 0.0,
        },
        max_error: run.max_errors.first().copied().unwrap_or(0.0),
        error_curve: run.error_curves.first().cloned().unwrap_or_default(),
        step_seconds: run.seconds,
        iterations: run.iterations,
        evaluations: log.evaluations as f64 / done,
        exits: log.exits,
        exit_gradient: log.exit_gradients / done,
        stable_frames: run.stable_frames,
        convergence: log.convergence.clone(),
        ..Default::default()
    })
}

/// `convergence.png`: the objective above its final value against the iteration, for the
/// tenth step of the first test sequence in each subspace (the paper's Fig. 4c).
pub fn write_convergence_chart(dir: &std::path::Path, scene: &str, reports: &[ReducedReport]) -> TrainerResult<()> {
    let series: Vec<Series> = reports
        .iter()
        .take(2)
        .filter_map(|r| {
            let history = &r.sequences.first()?.1.convergence;
            let last = *history.last()?;
            Some(Series {
                name: format!("reduced, {}", r.name),
                points: history
                    .iter()
                    .enumerate()
                    .map(|(k, e)| (k as f64, (e - last).max(1e-16)))
                    .collect(),
            })
        })
        .collect();
    chart::line_chart(
        &dir.join("convergence.png"),
        &format!("{scene}: one reduced step (frame 10 of the first test sequence)"),
        "iteration",
        "objective minus its final value (scaled units)",
        &series,
        true,
    )
}

/// The report's reduced-solver section: a row per subspace and sequence, the exits, and the
/// paper's Table 1 for this scene.
pub fn markdown(problem: &BuiltScene, reports: &[ReducedReport], reference_seconds: f64, frames: usize) -> String {
    let mut s = format!(
        "\n## Reduced-order solver\n\nOne solve of Eq. 2 per frame in each subspace, over the first {frames} frames of \
         each test sequence (errors against the full-space reference frames). Exits: I converged, II saddle, III \
         line-search cap, IV iteration cap. Projection: the mean error of the subspace's closest states to every \
         tenth reference frame.\n\n| subspace | sequence | mean err % | max err % | projection err % | ms/step | \
         iterations/step | I / II / III / IV % | stable frames |\n|---|---|---|---|---|---|---|---|---|\n"
    );
    for r in reports {
        for (plan, m) in &r.sequences {
            let pct = |e| 100.0 * m.exits.fraction(e);
            s += &format!(
                "| {} r={} | {} | {:.3} | {:.3} | {} | {:.3} | {:.1} | {:.0} / {:.0} / {:.0} / {:.0} | {} |\n",
                r.name,
                r.latent,
                plan.name,
                100.0 * m.mean_error,
                100.0 * m.max_error,
                percent_or_dash(m.projection_error),
                1e3 * m.step_seconds,
                m.iterations,
                pct(Exit::Converged),
                pct(Exit::Saddle),
                pct(Exit::LineSearchCap),
                pct(Exit::IterationCap),
                m.stable_frames
            );
        }
    }
    let elements: usize = problem
        .simulator
        .potentials()
        .iter()
        .filter(|p| ELASTIC_TERMS.contains(&p.name()))
        .map(|p| p.len())
        .max()
        .unwrap_or(0);
    if let [vanilla, ours, ..] = reports {
        let step = |r: &ReducedReport| r.mean_of(|m| m.step_seconds);
        s += &format!(
            "\n| n | elements | r | training s (ours / vanilla) | Lip (ours / vanilla) | ms/step ours | vanilla | full |\n\
             |---|---|---|---|---|---|---|---|\n| {} | {} | {} | {:.0} / {:.0} ({:.1}x) | {:.3e} / {:.3e} ({:.2}x) | \
             {:.2} | {:.2} ({:.2}x) | {:.1} ({:.1}x) |\n",
            problem.mesh.rest.len(),
            elements,
            ours.latent,
            ours.training_seconds,
            vanilla.training_seconds,
            ours.training_seconds / vanilla.training_seconds.max(1e-9),
            ours.lipschitz,
            vanilla.lipschitz,
            vanilla.lipschitz / ours.lipschitz.max(1e-300),
            1e3 * step(ours),
            1e3 * step(vanilla),
            step(vanilla) / step(ours).max(1e-12),
            1e3 * reference_seconds,
            reference_seconds / step(ours).max(1e-12)
        );
    }
    if let [_, ours, ..] = reports {
        s += &format!(
            "\nProjection check (the paper's Fig. 7): the two subspaces' closest states to the same reference frames \
             lie {}% of the diagonal apart on average.\n",
            percent_or_dash(ours.manifold_gap)
        );
    }
    s
}

/// `100 v` with three decimals, or a dash for NaN.
fn percent_or_dash(v: f64) -> String {
    if v.is_nan() {
        "-".into()
    } else {
        format!("{:.3}", 100.0 * v)
    }
}
