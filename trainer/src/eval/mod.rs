//! `mochi eval`: latent rollouts of trained models on the held-out test sequences, against
//! the full-space reference (docs/design.md, "Measuring").
//!
//! For each model and test sequence: mean and max vertex error over the reference frames (at
//! most [`ACCURACY_FRAMES`]) as a fraction of the rest bounding-box diagonal, the ratio of
//! kinetic energy summed over those frames to the reference's, frames until divergence over a
//! [`STABILITY_FRAMES`]-frame rollout (the test sequence's boundary conditions continued with
//! the same speeds and seed), and the cost per frame (step and decode, single thread), next to
//! the full-space solver timed in the same process.
//!
//! A rollout counts as diverged at the first frame whose latent or state is not finite, whose
//! error exceeds half the diagonal (where a reference exists), whose vertices leave the
//! training envelope (farther from their encoding origin than any training frame, plus half
//! the diagonal), or whose kinetic energy exceeds 100 times the training maximum. The report
//! says which; a rollout that drifted off the reference rolls on, its errors are measured
//! to the end of the window, and the report also gives the frames it stayed bounded (the
//! other three tests): drift, not a blow-up.

use std::path::{Path, PathBuf};
use std::time::Instant;

use mochi_sim::bc::BcSequence;
use mochi_sim::dataset::{self, SequencePlan, Split};
use mochi_sim::trajectory::Trajectory;
use mochi_sim::{BuiltScene, InputError};

use crate::artifact::{Artifact, Method};
use crate::error::{fs, TrainerError, TrainerResult};
use crate::learn::encoding::Encoding;
use crate::progress::Reporter;
use crate::report::chart::{self, LabelledPoint, Series};

pub mod adaptive;
pub mod adaptive_bench;
pub mod compare;
pub mod network_export;
pub mod penetration;
pub mod rates;
pub mod reduced;
pub mod reduced_bench;
pub mod rollout;
pub mod runtime_bench;
pub mod sim_bench;
pub mod storage;

pub use rollout::{
    carried_encoding, rebuild_problem, roll, rollout, stable_rollout, Divergence, LoadedModel, RolloutMetrics,
    ACCURACY_FRAMES, OFF_REFERENCE, STABILITY_FRAMES,
};

/// Results of one model on every test sequence.
#[derive(Clone, Debug)]
pub struct ModelReport {
    /// Artifact file.
    pub path: PathBuf,
    /// How its integrator was trained.
    pub method: Method,
    /// Latent size.
    pub latent: usize,
    /// Per test sequence: its plan and the metrics.
    pub sequences: Vec<(SequencePlan, RolloutMetrics)>,
}

impl ModelReport {
    /// Mean of a metric over the sequences.
    pub(crate) fn mean_of(&self, f: impl Fn(&RolloutMetrics) -> f64) -> f64 {
        self.sequences.iter().map(|(_, m)| f(m)).sum::<f64>() / self.sequences.len().max(1) as f64
    }
}

/// Refuses a stored test sequence (`path`) whose prescribed vertices do not follow `bc`,
/// the scene's plan for it, over the frames both cover: a dataset made from another copy of
/// the scene (another `beyond`, seed or motion) would otherwise be measured against a
/// rollout driven by a different motion.
fn check_follows_plan(
    problem: &BuiltScene,
    encoding: &Encoding,
    bc: &BcSequence,
    reference: &Trajectory,
    path: &Path,
) -> TrainerResult<()> {
    let dim = problem.mesh.dim;
    let tolerance = 1e-9 * problem.mesh.rest_diagonal();
    let frames = (reference.num_frames() - 1).min(bc.frames());
    for t in 0..=frames {
        let planned = bc.targets(&problem.handles, t, dim);
        let stored = encoding.handle_targets(&reference.positions[t])?;
        let gap = planned
            .iter()
            .zip(&stored)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        if gap > tolerance || stored.iter().any(|v| !v.is_finite()) {
            return Err(InputError::file(
                path,
                format!(
                    "its prescribed vertices at frame {t} are {gap:.3e} from where the scene `{}` moves \
                     them (made from another copy of the scene?); regenerate it with `mochi dataset`",
                    problem.scene.name
                ),
            )
            .into());
        }
        // The run-time colliders' paths too.
        if let Some(stored) = &reference.colliders {
            let planned = bc.collider_states(t);
            let gap = planned
                .iter()
                .zip(&stored.states[t])
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            if gap > tolerance || planned.len() != stored.states[t].len() {
                return Err(InputError::file(
                    path,
                    format!(
                        "its colliders at frame {t} are {gap:.3e} from where the scene `{}` moves them \
                         (made from another copy of the scene?); regenerate it with `mochi dataset`",
                        problem.scene.name
                    ),
                )
                .into());
            }
        }
    }
    Ok(())
}

/// Options of `mochi eval`.
#[derive(Clone, Debug)]
pub struct EvalOptions {
    /// Where the report and charts go.
    pub out_dir: PathBuf,
    /// Frames of the stability rollout.
    pub stability_frames: usize,
    /// Frames of accuracy measurement.
    pub accuracy_frames: usize,
    /// Also step the test sequences with the adaptive subspace solver (always when the
    /// scene's `[solver]` is adaptive).
    pub adaptive: bool,
    /// Measure against the test split simulated in full space (`dataset-full-space/` beside
    /// the first artifact, made where missing) when the scene's own solver is another one
    /// (the adaptive solver made its dataset): the adaptive solver is then measured too.
    pub full_space_reference: bool,
}

/// The whole evaluation: every artifact (and its supervised sibling when present) on the
/// test split of its scene; writes `report.md` and the charts into `options.out_dir`. Each
/// model's result on each sequence goes to `report` as it is measured.
pub fn evaluate(
    paths: &[PathBuf],
    options: &EvalOptions,
    report: &dyn Reporter,
) -> TrainerResult<(Vec<ModelReport>, f64)> {
    let mut all = Vec::new();
    for path in expand_with_baselines(paths) {
        all.push((path.clone(), LoadedModel::new(Artifact::read(&path)?)?));
    }
    let first = &all
        .first()
        .ok_or_else(|| TrainerError::invalid("no artifact given"))?
        .1
        .artifact;
    if let Some((p, _)) = all.iter().find(|(_, m)| m.artifact.scene_toml != first.scene_toml) {
        return Err(TrainerError::invalid(format!(
            "{} is for a different scene than {}; evaluate one scene at a time",
            p.display(),
            paths[0].display()
        )));
    }
    let (mut problem, encoding) = rebuild_problem(first)?;
    let full_space = options.full_space_reference && problem.scene.solver != mochi_sim::SolverSpec::FullSpace;
    // The reference: the scene's own solver, or full space in a dataset directory of its own.
    let mut full_space_problem = if full_space {
        let mut scene = problem.scene.clone();
        scene.solver = mochi_sim::SolverSpec::FullSpace;
        Some(scene.build()?)
    } else {
        None
    };
    let data_dir = match full_space {
        true => rollout::dataset_dir(&paths[0]).with_file_name("dataset-full-space"),
        false => rollout::dataset_dir(&paths[0]),
    };
    let tests = rollout::test_split_in(full_space_problem.as_mut().unwrap_or(&mut problem), &data_dir, report)?;
    // The rollouts' boundary conditions come from the scene's plan, each sequence's errors
    // from its stored frames: the two must be the same motion.
    let plans: Vec<BcSequence> = tests
        .iter()
        .map(|(plan, _)| problem.sequence(&plan.speeds, options.stability_frames, plan.seed))
        .collect();
    for ((plan, reference), bc) in tests.iter().zip(&plans) {
        check_follows_plan(
            &problem,
            &encoding,
            bc,
            reference,
            &dataset::sequence_path(&data_dir, plan),
        )?;
    }

    // Full-space cost per frame, timed here (first 30 frames of the first test sequence).
    let timing_frames = 30.min(problem.scene.dataset.frames_of(Split::Test));
    let seq = problem.sequence(&tests[0].0.speeds, timing_frames, tests[0].0.seed);
    let clock = Instant::now();
    full_space_problem
        .as_mut()
        .unwrap_or(&mut problem)
        .run(&seq, &mochi_sim::Silent)?;
    let reference_seconds = clock.elapsed().as_secs_f64() / timing_frames as f64;

    let mut reports = Vec::new();
    for (path, model) in &all {
        let own = carried_encoding(&model.artifact, &problem)?;
        let mut sequences = Vec::new();
        for ((plan, reference), bc) in tests.iter().zip(&plans) {
            let metrics = rollout(
                model,
                &problem,
                &own,
                bc,
                options.stability_frames,
                reference,
                options.accuracy_frames,
            )?;
            report.message(&format!(
                "{} {} on {}: mean error {:.3}%, max {:.2}%, KE ratio {:.3}, stable {}",
                model.artifact.scene,
                model.artifact.method.label(),
                plan.name,
                100.0 * metrics.mean_error,
                100.0 * metrics.max_error,
                metrics.kinetic_energy_ratio,
                stability(&metrics)
            ));
            sequences.push((plan.clone(), metrics));
        }
        reports.push(ModelReport {
            path: path.clone(),
            method: model.artifact.method,
            latent: model.artifact.latent as usize,
            sequences,
        });
    }
    // The reduced-order solver, when the scene was trained with a `[reduced]` table.
    let reduced_file =
        crate::artifact::reduced::reduced_path(paths[0].parent().unwrap_or(Path::new(".")), &first.scene);
    let reduced_reports = if reduced_file.is_file() {
        let file = crate::artifact::reduced::ReducedArtifact::load(&reduced_file)?;
        reduced::evaluate_reduced(
            &file,
            &problem,
            &encoding,
            &tests,
            &plans,
            options.accuracy_frames,
            report,
        )?
    } else {
        Vec::new()
    };
    // The adaptive subspace solver, when asked or when the scene uses it.
    let adaptive_rows =
        if options.adaptive || full_space || matches!(problem.scene.solver, mochi_sim::SolverSpec::Adaptive(_)) {
            Some(adaptive::evaluate_adaptive(
                &problem,
                &tests,
                &plans,
                options.accuracy_frames,
                report,
            )?)
        } else {
            None
        };
    fs::create_dir_all(&options.out_dir)?;
    let adaptive_points: Vec<LabelledPoint> = adaptive_rows
        .iter()
        .map(|(_, rows)| {
            let n = rows.len().max(1) as f64;
            LabelledPoint {
                group: "adaptive solver".into(),
                label: String::new(),
                emphasis: false,
                x: 1e3 * rows.iter().map(|(_, m)| m.step_seconds).sum::<f64>() / n,
                y: 100.0 * rows.iter().map(|(_, m)| m.mean_error).sum::<f64>() / n,
            }
        })
        .collect();
    write_charts(
        &options.out_dir,
        &first.scene,
        &reports,
        &reduced_reports,
        &adaptive_points,
        reference_seconds,
    )?;
    let reference = match &problem.scene.solver {
        _ if full_space => format!(
            "Reference: the test split simulated in full space ({}; the scene's own dataset is its {} solver's). \
             Full-space solver",
            data_dir.display(),
            problem.scene.solver.label()
        ),
        mochi_sim::SolverSpec::FullSpace => "Full-space solver".to_string(),
        other => format!("Reference: the scene's {} solver", other.label()),
    };
    let mut text = report_markdown(&first.scene, &reports, reference_seconds, options, &reference);
    if !reduced_reports.is_empty() {
        reduced::write_convergence_chart(&options.out_dir, &first.scene, &reduced_reports)?;
        text += &reduced::markdown(&problem, &reduced_reports, reference_seconds, options.accuracy_frames);
    }
    if let Some((settings, rows)) = &adaptive_rows {
        text += &adaptive::markdown(settings, rows, options.accuracy_frames, reference_seconds);
    }
    // What each weight storage costs, for the first artifact (the runtime's own rollout).
    let first_path = &all[0].0;
    let bytes = fs::read(first_path)?;
    let storage = storage::evaluate(&bytes, first_path, &problem, &tests, options.accuracy_frames)?;
    storage::write_chart(&options.out_dir, &first.scene, &storage)?;
    text += &storage::markdown(&storage, options.accuracy_frames);
    // The model selection that chose the first artifact's networks (`mochi train`).
    let candidates = &first.summary.candidates;
    if !candidates.is_empty() {
        crate::report::candidates::pareto_charts(&options.out_dir, &first.scene, candidates)?;
        text += &format!(
            "\n## Model selection\n\nEvery model `mochi train` tried (`latent.selection`), with its cost measured \
             while training (runtime step + full decode, one thread) and its rollout error on the validation \
             sequences; the kept one is the cheapest within {:.0}% of the best stable candidate.\n\n{}\n\
             ![time against error](pareto-time.png)\n\n![bytes against error](pareto-bytes.png)\n",
            100.0 * slack_of(first),
            crate::report::candidates_table(candidates)
        );
    }
    fs::write(&options.out_dir.join("report.md"), &text)?;
    Ok((reports, reference_seconds))
}

/// The selection slack the artifact's scene was trained with.
fn slack_of(artifact: &Artifact) -> f64 {
    crate::learn::recipe::Recipe::parse(&artifact.scene_toml, Path::new(&artifact.scene_path))
        .map_or(crate::learn::recipe::SelectionSpec::default().slack, |r| {
            r.latent.selection.slack
        })
}

/// `paths`, each followed by its supervised sibling (`X.supervised.mochi` beside `X.mochi`)
/// when that exists and is not listed already.
pub(crate) fn expand_with_baselines(paths: &[PathBuf]) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = Vec::new();
    for p in paths {
        if !out.contains(p) {
            out.push(p.clone());
        }
        let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if let Some(stem) = name.strip_suffix(".mochi").filter(|s| !s.ends_with(".supervised")) {
            let sibling = p.with_file_name(format!("{stem}.supervised.mochi"));
            if sibling.is_file() && !out.contains(&sibling) && !paths.contains(&sibling) {
                out.push(sibling);
            }
        }
    }
    out
}

fn label(r: &ModelReport) -> String {
    format!("{} k={}", r.method.label(), r.latent)
}

fn write_charts(
    dir: &Path,
    scene: &str,
    reports: &[ModelReport],
    reduced: &[reduced::ReducedReport],
    adaptive: &[LabelledPoint],
    reference_seconds: f64,
) -> TrainerResult<()> {
    let count = reports.first().map_or(0, |r| r.sequences.len());
    for s in 0..count {
        let plan = &reports[0].sequences[s].0;
        let series: Vec<Series> = reports
            .iter()
            .map(|r| Series {
                name: label(r),
                points: r.sequences[s]
                    .1
                    .error_curve
                    .iter()
                    .enumerate()
                    .map(|(t, e)| ((t + 1) as f64, 100.0 * e))
                    .collect(),
            })
            .collect();
        chart::line_chart(
            &dir.join(format!("error-{}.png", plan.name)),
            &format!("{scene} {}: {}", plan.name, plan.description),
            "frame",
            "mean vertex error (% of diagonal)",
            &series,
            true,
        )?;
    }
    let mut points: Vec<LabelledPoint> = reports
        .iter()
        .map(|r| {
            // A rollout that diverged inside the measured window has an unbounded mean error;
            // the chart shows its error over the frames before divergence and says so.
            let diverged = r.sequences.iter().filter(|(_, m)| !m.mean_error.is_finite()).count();
            let note = if diverged > 0 {
                format!(" ({diverged} of {} diverged)", r.sequences.len())
            } else {
                String::new()
            };
            LabelledPoint {
                group: r.method.label().into(),
                label: format!("k={}{note}", r.latent),
                emphasis: false,
                x: 1e3 * r.mean_of(|m| m.step_seconds + m.decode_seconds),
                y: 100.0 * r.mean_of(|m| m.error_curve.iter().sum::<f64>() / m.error_curve.len().max(1) as f64),
            }
        })
        .collect();
    points.extend(reduced.iter().map(|r| LabelledPoint {
        group: format!("reduced, {}", r.name),
        label: format!("r={}", r.latent),
        emphasis: false,
        x: 1e3 * r.mean_of(|m| m.step_seconds),
        y: 100.0 * r.mean_of(|m| m.error_curve.iter().sum::<f64>() / m.error_curve.len().max(1) as f64),
    }));
    points.extend(adaptive.iter().cloned());
    points.push(LabelledPoint {
        group: "full space".into(),
        label: "reference".into(),
        emphasis: false,
        x: 1e3 * reference_seconds,
        y: 0.0,
    });
    chart::scatter_chart(
        &dir.join("speed-accuracy.png"),
        &format!("{scene}: cost per frame against accuracy (test mean)"),
        "ms per frame (step + full decode, one thread)",
        "mean vertex error (% of diagonal)",
        &points,
        true,
        false,
    )
}

/// Stable frames, with the reason where the rollout diverged and, where it drifted off the
/// reference, how long it stayed bounded: `154 (half a diagonal off the reference; bounded
/// 10000)`.
fn stability(m: &RolloutMetrics) -> String {
    match m.divergence {
        Some(Divergence::OffReference) => format!(
            "{} ({}; bounded {})",
            m.stable_frames,
            Divergence::OffReference.describe(),
            m.bounded_frames
        ),
        Some(d) => format!("{} ({})", m.stable_frames, d.describe()),
        None => m.stable_frames.to_string(),
    }
}

fn report_markdown(
    scene: &str,
    reports: &[ModelReport],
    reference_seconds: f64,
    options: &EvalOptions,
    reference: &str,
) -> String {
    let mut s = format!(
        "# {scene}: evaluation\n\nErrors are vertex distances as % of the rest bounding-box diagonal over the first {} \
         frames of each test sequence; stability over {} frames. {reference}: {:.2} ms/frame (timed in the \
         same process).\n\n| model | sequence | mean err % | max err % | KE ratio | stable frames | ms/frame | speed-up |\n\
         |---|---|---|---|---|---|---|---|\n",
        options.accuracy_frames,
        options.stability_frames,
        1e3 * reference_seconds
    );
    for r in reports {
        for (plan, m) in &r.sequences {
            let cost = m.step_seconds + m.decode_seconds;
            s += &format!(
                "| {} | {} ({}) | {:.3} | {:.3} | {:.3} | {} | {:.3} | {:.0}x |\n",
                label(r),
                plan.name,
                plan.description,
                100.0 * m.mean_error,
                100.0 * m.max_error,
                m.kinetic_energy_ratio,
                stability(m),
                1e3 * cost,
                reference_seconds / cost
            );
        }
    }
    s + &penetration_table(reports)
}

/// The colliders' table of the report (empty for a scene without run-time colliders): per
/// model and sequence, how deep the surface went into the colliders over the stable frames,
/// and the same with the runtime's push-out correction.
fn penetration_table(reports: &[ModelReport]) -> String {
    let rows: Vec<_> = reports
        .iter()
        .flat_map(|r| r.sequences.iter().map(move |(plan, m)| (r, plan, m)))
        .filter_map(|(r, plan, m)| m.penetration.as_ref().map(|p| (r, plan, p)))
        .collect();
    let Some((_, _, first)) = rows.first() else {
        return String::new();
    };
    let mut s = format!(
        "\n## Colliders\n\nPenetration of the surface vertices into the run-time colliders over each rollout's stable \
         frames (`dhat` = {:.1e} m), and with the runtime's push-out (`collider::push_out`) of the decoded surface; \
         its error is over the accuracy frames.\n\n| model | sequence | deepest | frames with a vertex inside | \
         deeper than dhat | deepest, pushed out | mean err % pushed out |\n|---|---|---|---|---|---|---|\n",
        first.dhat
    );
    for (r, plan, p) in rows {
        s += &format!(
            "| {} | {} | {:.2} mm ({:.1} dhat) | {:.1}% | {:.1}% | {:.2} mm | {:.3} |\n",
            label(r),
            plan.name,
            1e3 * p.max_depth,
            p.max_depth / p.dhat,
            100.0 * p.inside_share,
            100.0 * p.deep_share,
            1e3 * p.pushed_max_depth,
            100.0 * p.pushed_mean_error
        );
    }
    s
}
