//! The adaptive subspace solver on the test sequences (`mochi eval --adaptive`): each
//! sequence stepped by the adaptive solver from the scene's start (the scene's own
//! `[solver]` settings when it is adaptive, the defaults otherwise), against the reference
//! frames, through the one interface of every method ([`crate::methods::method`]). Measured
//! per sequence: mean and max vertex error (fraction of the rest diagonal), seconds per step
//! (the process's CPU time), and the enriched share of the free vertices.

use mochi_sim::bc::BcSequence;
use mochi_sim::dataset::SequencePlan;
use mochi_sim::trajectory::Trajectory;
use mochi_sim::{AdaptiveSettings, BuiltScene, SolverSpec};

use crate::error::{TrainerError, TrainerResult};
use crate::methods::method::run_sequence;
use crate::methods::simulated::Simulated;
use crate::progress::Reporter;

/// The adaptive solver on one test sequence.
#[derive(Clone, Debug, Default)]
pub struct AdaptiveMetrics {
    /// Mean over frames of the mean vertex error / diagonal.
    pub mean_error: f64,
    /// Max over frames of the max vertex error / diagonal.
    pub max_error: f64,
    /// Mean seconds per step.
    pub step_seconds: f64,
    /// Mean enriched share of the free vertices.
    pub enriched: f64,
    /// Mean Newton iterations per step.
    pub iterations: f64,
}

/// The adaptive solver on every test sequence, over at most `frames` frames of each.
pub fn evaluate_adaptive(
    problem: &BuiltScene,
    tests: &[(SequencePlan, Trajectory)],
    plans: &[BcSequence],
    frames: usize,
    report: &dyn Reporter,
) -> TrainerResult<(AdaptiveSettings, Vec<(SequencePlan, AdaptiveMetrics)>)> {
    let settings = match &problem.scene.solver {
        SolverSpec::Adaptive(s) => s.clone(),
        SolverSpec::FullSpace | SolverSpec::Vbd(_) => AdaptiveSettings::default(),
    };
    let mut scene = problem.scene.clone();
    scene.solver = SolverSpec::Adaptive(settings.clone());
    let mut adaptive = Simulated::new(&scene, 1, "")?;
    let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
    let mut out = Vec::new();
    for ((plan, reference), bc) in tests.iter().zip(plans) {
        let count = frames.min(reference.positions.len().saturating_sub(1)).min(bc.frames());
        let run = run_sequence(&mut adaptive, bc, count, &[&reference.positions], dim, diagonal, None)?;
        if let Some(failure) = &run.failure {
            return Err(TrainerError::invalid(format!(
                "{} adaptive solver on {}: {failure}",
                scene.name, plan.name
            )));
        }
        let metrics = AdaptiveMetrics {
            mean_error: run.mean_error(0),
            max_error: run.max_errors[0],
            step_seconds: run.seconds,
            enriched: adaptive.enriched_share(),
            iterations: run.iterations,
        };
        report.message(&format!(
            "{} adaptive solver on {}: mean error {:.3}%, max {:.2}%, {:.2} ms/step, {:.1}% enriched",
            scene.name,
            plan.name,
            100.0 * metrics.mean_error,
            100.0 * metrics.max_error,
            1e3 * metrics.step_seconds,
            100.0 * metrics.enriched
        ));
        out.push((plan.clone(), metrics));
    }
    Ok((settings, out))
}

/// The report's section.
pub fn markdown(
    settings: &AdaptiveSettings,
    rows: &[(SequencePlan, AdaptiveMetrics)],
    frames: usize,
    reference_seconds: f64,
) -> String {
    let mut s = format!(
        "\n## Adaptive subspace solver\n\nThe adaptive solver (error thresholds {} modal, {} nodal, progress {}, \
         downdating {}) over the first {frames} frames of each test sequence, against the reference frames; full \
         space takes {:.2} ms per step here.\n\n| sequence | mean err % | max err % | ms/step | Newton it./step | \
         enriched % |\n|---|---|---|---|---|---|\n",
        settings.modal_error,
        settings.nodal_error,
        settings.progress,
        settings.downdate,
        1e3 * reference_seconds
    );
    for (plan, m) in rows {
        s += &format!(
            "| {} | {:.3} | {:.3} | {:.3} | {:.2} | {:.1} |\n",
            plan.name,
            100.0 * m.mean_error,
            100.0 * m.max_error,
            1e3 * m.step_seconds,
            m.iterations,
            100.0 * m.enriched
        );
    }
    s
}
