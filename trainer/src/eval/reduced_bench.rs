//! `mochi bench reduced`: the reduced-order solver's cost per step in each subspace of a
//! scene's `.reduced` file, as a ratio against the vanilla subspace stepped in the same
//! process over the same test motions.
//!
//! No full-space reference is simulated (`mochi eval` does that): each subspace steps the
//! scene's test sequences (their boundary conditions, regenerated from the scene's plan) for
//! the given number of frames, one thread, timed by the process's CPU time
//! ([`crate::methods::clock`]). Where the `.reduced` file's directory holds the scene's dataset
//! (`dataset/`, as `mochi train` leaves it), its error is measured against the test frames
//! stored there (simulated first if missing, as `mochi eval` does; the first `frames` of
//! each, at most as many as are stored).

use std::path::Path;

use mochi_sim::dataset::{self, Split};
use mochi_sim::StencilEnergy;

use super::reduced::{step_sequence, stepper_settings, subspace_runs, with_runtime_cubature, ReducedMetrics};
use crate::artifact::reduced::ReducedArtifact;
use crate::error::{TrainerError, TrainerResult};
use crate::learn::encoding::Encoding;
use crate::learn::recipe::Recipe;
use crate::learn::reduced_spec::SolverChoice;
use crate::methods::lipschitz::cubature::{cubature_energies, elastic_terms};
use crate::methods::lipschitz::loss::{
    latent_spread, lipschitz_estimate, median_condition, LatentSample, LipschitzTerm,
};
use crate::methods::reduced::optimize::{Exit, ExitCounts};
use crate::methods::reduced::rounding::Rounding;
use crate::methods::reduced::stepper::{scene_objective_scale, ReducedSolver};
use crate::progress::Reporter;

/// One subspace over every test sequence.
#[derive(Clone, Debug)]
pub struct ReducedTiming {
    /// "vanilla" or "Lipschitz", with or without runtime cubature.
    pub name: &'static str,
    /// Mean milliseconds per step.
    pub ms_per_step: f64,
    /// Mean iterations per step.
    pub iterations: f64,
    /// Mean objective evaluations per step.
    pub evaluations: f64,
    /// Share of steps that ended in each exit, in [`Exit::ALL`]'s order (the paper's I-IV).
    pub exit_shares: [f64; 4],
    /// Mean objective evaluations of a step that ended in each exit, over every sequence's
    /// steps, in the same order (NaN where no step did).
    pub exit_evaluations: [f64; 4],
    /// Mean gradient infinity norm where the steps stopped (of the objective the solver
    /// minimises: unscaled for the paper's solver).
    pub exit_gradient: f64,
    /// Mean vertex error / diagonal against the stored test frames (NaN without a dataset).
    pub mean_error: f64,
    /// The solver that stepped.
    pub solver: ReducedSolver,
    /// Its arithmetic.
    pub rounding: Rounding,
    /// Its gradient tolerance.
    pub tolerance: f64,
    /// `Lip[d^2 P/dz^2]` (Eq. 7) on every tenth visited latent.
    pub lipschitz: f64,
    /// The RMS spread of those latents about their mean
    /// ([`latent_spread`]: `lipschitz * spread^3` does not depend on the latent scale).
    pub spread: f64,
    /// The median condition number of the subspace Hessians there ([`median_condition`]).
    pub condition: f64,
    /// How many visited latents those three figures come from (none below 10 frames).
    pub visited: usize,
}

/// What [`bench`] steps, and how.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReducedBenchOptions {
    /// Steps taken on each test motion (default 300).
    pub frames: usize,
    /// Start every L-BFGS solve from steepest descent, whatever the scene's
    /// `reduced.warm_start` says (the paper's solver; default off).
    pub cold: bool,
    /// Step every this many frames of the test motions
    /// ([`mochi_sim::bc::BcSequence::every`]): the same motions in `stride` times larger
    /// steps (default 1).
    pub stride: usize,
    /// The solves' arithmetic: as the scene says (`Double`, the default), or single precision
    /// emulated ([`crate::methods::reduced::rounding`]): what each subspace costs a solver
    /// whose numbers are `f32`.
    pub rounding: Rounding,
    /// Step with the paper's solver ([`crate::methods::reduced::paper`]) whatever the
    /// scene's `reduced.solver` says (default off).
    pub paper: bool,
    /// The gradient tolerance instead of the scene's `reduced.tolerance`.
    pub tolerance: Option<f64>,
}

impl Default for ReducedBenchOptions {
    fn default() -> Self {
        ReducedBenchOptions {
            frames: 300,
            cold: false,
            stride: 1,
            rounding: Rounding::Double,
            paper: false,
            tolerance: None,
        }
    }
}

impl ReducedTiming {
    /// Share of steps that converged (exit I).
    pub fn converged(&self) -> f64 {
        self.exit_shares[Exit::Converged as usize]
    }
}

/// Steps every subspace of the `.reduced` file at `path` over the scene's test motions as
/// `options` say.
pub fn bench(path: &Path, options: &ReducedBenchOptions, report: &dyn Reporter) -> TrainerResult<Vec<ReducedTiming>> {
    let ReducedBenchOptions {
        frames, cold, stride, ..
    } = *options;
    if frames == 0 || stride == 0 {
        return Err(TrainerError::invalid(
            "bench reduced: --frames and --stride must be at least 1",
        ));
    }
    let reduced = ReducedArtifact::load(path)?;
    let recipe = Recipe::parse(&reduced.scene_toml, Path::new(&reduced.scene_path))?;
    let mut spec = recipe.reduced.clone().unwrap_or_default();
    spec.warm_start &= !cold;
    if options.paper {
        spec.solver = SolverChoice::LbfgsPaper;
    }
    if let Some(tolerance) = options.tolerance {
        spec.tolerance = tolerance;
    }
    let mut problem = recipe.build()?;
    let encoding = Encoding::new(&problem, recipe.latent.rods)?;
    let mut settings = stepper_settings(&spec, problem.scene.integrator);
    if options.rounding == Rounding::Single {
        settings.solve.rounding = Rounding::Single;
    }
    let data_dir = super::rollout::dataset_dir(path);
    let references = if data_dir.is_dir() && stride == 1 {
        Some(super::rollout::test_split(&mut problem, path, report)?)
    } else {
        None
    };
    let potentials: Vec<&dyn StencilEnergy> = problem.simulator.potentials().iter().map(|p| p.as_ref()).collect();
    let elastic = elastic_terms(&potentials);
    let cubatures = cubature_energies(&problem, &reduced.cubature)?;
    let with_cubature = with_runtime_cubature(&potentials, &cubatures);
    let motions: Vec<_> = dataset::plan(&problem.scene.dataset)
        .into_iter()
        .filter(|p| p.split == Split::Test)
        .map(|p| problem.sequence(&p.speeds, frames * stride, p.seed).every(stride))
        .collect();
    let mut out = Vec::new();
    for (name, data, terms) in subspace_runs(&reduced, &potentials, &with_cubature) {
        let mut visited: Vec<LatentSample> = Vec::new();
        let mut runs: Vec<ReducedMetrics> = Vec::new();
        for (k, bc) in motions.iter().enumerate() {
            let reference = references.as_ref().and_then(|r| r.get(k)).map(|(_, t)| t);
            runs.push(step_sequence(
                data,
                &problem,
                &encoding,
                &settings,
                terms,
                bc,
                reference,
                frames,
                &mut visited,
            )?);
        }
        let mean = |f: &dyn Fn(&ReducedMetrics) -> f64| runs.iter().map(f).sum::<f64>() / runs.len().max(1) as f64;
        let term = LipschitzTerm {
            encoding: &encoding,
            potentials: &elastic,
            scale: scene_objective_scale(&problem),
            diagonal: problem.mesh.rest_diagonal(),
        };
        let hessians = term.hessians(&data.decoder()?, &visited)?;
        let timing = ReducedTiming {
            name,
            ms_per_step: mean(&|m| 1e3 * m.step_seconds),
            iterations: mean(&|m| m.iterations),
            evaluations: mean(&|m| m.evaluations),
            exit_shares: Exit::ALL.map(|exit| mean(&|m| m.exits.fraction(exit))),
            exit_evaluations: {
                let mut all = ExitCounts::default();
                runs.iter().for_each(|m| all.merge(&m.exits));
                Exit::ALL.map(|exit| all.mean_evaluations(exit))
            },
            exit_gradient: mean(&|m| m.exit_gradient),
            mean_error: match &references {
                Some(_) => mean(&|m| m.mean_error),
                None => f64::NAN,
            },
            solver: settings.solver,
            rounding: settings.solve.rounding,
            tolerance: settings.solve.tolerance,
            lipschitz: lipschitz_estimate(&hessians, &visited),
            spread: latent_spread(&visited),
            condition: median_condition(&hessians),
            visited: visited.len(),
        };
        report.message(&format!(
            "{}: {name}: {:.3} ms/step, {:.2} iterations, {:.2} evaluations",
            reduced.scene, timing.ms_per_step, timing.iterations, timing.evaluations
        ));
        out.push(timing);
    }
    Ok(out)
}

/// A markdown table of `timings` (made with `options`), each step time also as the vanilla
/// run's (the first row, or the first cubature row for cubature rows) divided by it.
pub fn table(scene: &str, options: &ReducedBenchOptions, timings: &[ReducedTiming]) -> String {
    let ReducedBenchOptions { frames, stride, .. } = *options;
    let start = if options.cold { "cold" } else { "as the scene says" };
    let steps = if stride == 1 {
        format!("{frames} frames of each test motion")
    } else {
        format!("{frames} steps of {stride} frames each along each test motion")
    };
    let (solver, rounding, tolerance) = timings
        .first()
        .map_or((ReducedSolver::Lbfgs, options.rounding, f64::NAN), |t| {
            (t.solver, t.rounding, t.tolerance)
        });
    let how = match solver {
        ReducedSolver::PaperLbfgs => format!(
            "the paper's L-BFGS (cold, Armijo backtracking by 0.8, gradient tolerance {tolerance:e} on the unscaled objective)"
        ),
        ReducedSolver::Lbfgs => format!("L-BFGS starts {start}, gradient tolerance {tolerance:e} on the scaled objective"),
        other => format!("{}, gradient tolerance {tolerance:e}", other.name()),
    };
    let mut s = format!(
        "{scene}: reduced-order solver in {}, {steps}, {how}\n\n| subspace | ms/step | speedup vs vanilla \
         | iterations/step | evaluations/step | converged % | exits I / II / III / IV % | evaluations per step by exit \
         | mean exit gradient | mean error % | Lip | latent spread | Lip x spread^3 | condition |\n\
         |---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
        rounding.name()
    );
    for (k, t) in timings.iter().enumerate() {
        let baseline = &timings[k - k % 2];
        // Lip needs two visited latents (every tenth frame is kept).
        let landscape = if t.visited >= 2 {
            format!(
                "{:.3e} | {:.3} | {:.3e} | {:.3e}",
                t.lipschitz,
                t.spread,
                t.lipschitz * t.spread.powi(3),
                t.condition
            )
        } else {
            "- | - | - | -".to_string()
        };
        s += &format!(
            "| {} | {:.3} | {:.2}x | {:.2} | {:.2} | {:.1} | {} | {} | {:.1e} | {:.3} | {landscape} |\n",
            t.name,
            t.ms_per_step,
            baseline.ms_per_step / t.ms_per_step.max(1e-12),
            t.iterations,
            t.evaluations,
            100.0 * t.converged(),
            t.exit_shares.map(|f| format!("{:.1}", 100.0 * f)).join(" / "),
            t.exit_evaluations
                .map(|e| if e.is_nan() { "-".to_string() } else { format!("{e:.1}") })
                .join(" / "),
            t.exit_gradient,
            100.0 * t.mean_error,
        );
    }
    if timings.iter().any(|t| t.visited < 2) {
        s += "\nLip, latent spread and condition are taken on every tenth frame's latent: '-' where fewer than two \
              were visited (run 10 frames or more).\n";
    }
    s
}
