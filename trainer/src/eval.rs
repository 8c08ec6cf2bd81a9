//! `mochi eval`: latent rollouts of trained models on the held-out test sequences, against
//! the full-space reference (DESIGN.md, "Measuring").
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

use anyhow::Context;

use crate::artifact::{Artifact, Method};
use crate::bc::BcSequence;
use crate::chart::{self, LabelledPoint, Series};
use crate::dataset::{self, SequencePlan, Split};
use crate::encoding::Encoding;
use crate::error::InputError;
use crate::latent::{decode_world, pack_signals};
use crate::model::{forward_exported, ExportedIntegrator, ExportedMlp};
use crate::scene::{Problem, Scene};
use crate::storage;
use crate::trajectory::Trajectory;

/// Frames over which accuracy is measured (from the start of each test sequence).
pub const ACCURACY_FRAMES: usize = 1000;
/// Length of the stability rollout.
pub const STABILITY_FRAMES: usize = 10_000;

/// A loaded model ready to roll out.
pub struct LoadedModel {
    /// The artifact.
    pub artifact: Artifact,
    /// Its decoder.
    pub decoder: ExportedMlp,
    /// Its integrator.
    pub integrator: ExportedIntegrator,
}

impl LoadedModel {
    /// Builds the runnable networks of `artifact`.
    pub fn new(artifact: Artifact) -> anyhow::Result<Self> {
        let decoder = artifact.decoder().map_err(anyhow::Error::msg)?;
        let integrator = artifact.integrator().map_err(anyhow::Error::msg)?;
        Ok(LoadedModel {
            artifact,
            decoder,
            integrator,
        })
    }
}

/// Rebuilds the scene an artifact was trained on and checks that its encoding is the same.
pub fn rebuild_problem(artifact: &Artifact) -> anyhow::Result<(Problem, Encoding)> {
    let scene = Scene::parse(&artifact.scene_toml, Path::new(&artifact.scene_path))?;
    let problem = scene.build()?;
    let encoding = Encoding::new(&problem)?;
    if crate::artifact::EncodingData::new(&encoding) != artifact.encoding {
        anyhow::bail!(
            "the artifact's boundary-condition encoding does not match scene `{}` as rebuilt from it",
            artifact.scene
        );
    }
    Ok((problem, encoding))
}

/// A vertex farther than this from the reference (fraction of the rest diagonal) has drifted
/// off it: the one threshold of [`Divergence::OffReference`], the weight-storage table and
/// the subspace diagnostics.
pub const OFF_REFERENCE: f64 = 0.5;

/// Why a rollout counts as diverged (the tests of the module documentation, in the order
/// they are made).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Divergence {
    /// A latent or a position is not finite.
    NotFinite,
    /// A vertex left the training envelope: the state blew up.
    LeftEnvelope,
    /// The kinetic energy passed 100 times the training maximum.
    KineticEnergy,
    /// A vertex is more than half the diagonal from the reference: the state is finite
    /// and bounded but has drifted from the motion it should follow.
    OffReference,
}

impl Divergence {
    /// A few words for reports.
    pub fn describe(self) -> &'static str {
        match self {
            Divergence::NotFinite => "not finite",
            Divergence::LeftEnvelope => "left the envelope",
            Divergence::KineticEnergy => "kinetic energy over 100x",
            Divergence::OffReference => "half a diagonal off the reference",
        }
    }
}

/// What one rollout measured.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RolloutMetrics {
    /// Mean over frames of the mean vertex error / diagonal.
    pub mean_error: f64,
    /// Max over frames of the max vertex error / diagonal.
    pub max_error: f64,
    /// Kinetic energy summed over the measured frames, ours over the reference's.
    pub kinetic_energy_ratio: f64,
    /// Frames completed before divergence, capped at the rollout length.
    pub stable_frames: usize,
    /// Why the rollout diverged; `None` when it ran its length.
    pub divergence: Option<Divergence>,
    /// Frames before the state blew up (not finite, out of the envelope, or the kinetic
    /// energy cap), capped at the rollout length: a rollout that drifted off the reference
    /// rolls on to measure this.
    pub bounded_frames: usize,
    /// Mean vertex error / diagonal of every measured frame.
    pub error_curve: Vec<f64>,
    /// Seconds per latent step.
    pub step_seconds: f64,
    /// Seconds per full decode (network and world frame).
    pub decode_seconds: f64,
}

/// Per vertex, the distance between `x` and `reference` (`dim` numbers per vertex, f32 or f64)
/// as a fraction of `diagonal`.
pub fn vertex_errors<'a, T: Copy + Into<f64>>(
    x: &'a [T],
    reference: &'a [f64],
    dim: usize,
    diagonal: f64,
) -> impl Iterator<Item = f64> + 'a {
    x.chunks_exact(dim).zip(reference.chunks_exact(dim)).map(move |(p, r)| {
        let squared: f64 = p.iter().zip(r).map(|(&a, &b)| (a.into() - b).powi(2)).sum();
        squared.sqrt() / diagonal
    })
}

/// The mean and the largest of [`vertex_errors`]: one frame's error in the units every report
/// uses.
pub fn mean_and_max_error<T: Copy + Into<f64>>(x: &[T], reference: &[f64], dim: usize, diagonal: f64) -> (f64, f64) {
    let (sum, max, count) = vertex_errors(x, reference, dim, diagonal)
        .fold((0.0, 0.0, 0usize), |(sum, max, count): (f64, f64, usize), e| {
            (sum + e, max.max(e), count + 1)
        });
    (sum / count.max(1) as f64, max)
}

/// Largest norm of an encoded vertex's values (`per_vertex` each): its distance from its
/// origin for positions, its edge's bend for strand bends.
fn max_radius(q: &[f32], per_vertex: usize) -> f64 {
    q.chunks_exact(per_vertex)
        .map(|c| c.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt())
        .fold(0.0, f64::max)
}

/// Kinetic energy of the step from `prev` to `x`.
pub fn kinetic_energy(masses: &[f64], x: &[f64], prev: &[f64], dt: f64, dim: usize) -> f64 {
    masses
        .iter()
        .enumerate()
        .map(|(v, m)| {
            let s: f64 = (0..dim).map(|c| (x[v * dim + c] - prev[v * dim + c]).powi(2)).sum();
            0.5 * m * s / (dt * dt)
        })
        .sum()
}

/// The trainer's own rollout of `model` over `bc` (the reference the runtime is checked
/// against): from the initial latent, calls `visit(t, z_t, q_t, x_t)` for `t = 1..=frames` with
/// the latent, the decoded encoded state and the world state, until `visit` returns `false`.
/// Returns the seconds spent stepping and decoding.
pub fn roll(
    model: &LoadedModel,
    problem: &Problem,
    encoding: &Encoding,
    bc: &BcSequence,
    frames: usize,
    mut visit: impl FnMut(usize, &[f32], &[f32], &[f64]) -> bool,
) -> anyhow::Result<(f64, f64)> {
    let a = &model.artifact;
    let dim = problem.mesh.dim;
    let mut z_prev = a.initial_latent.clone();
    let mut z_prev2 = a.initial_latent.clone();
    let mut signals = [bc.signal(0), bc.signal(0), bc.signal(0)];
    let (mut step_time, mut decode_time) = (0.0, 0.0);
    for t in 1..=frames {
        signals.rotate_right(1);
        signals[0] = bc.signal(t);
        let clock = Instant::now();
        let q_in = pack_signals(&z_prev, &z_prev2, [&signals[0], &signals[1], &signals[2]]);
        let z = model.integrator.step(&q_in)?;
        let mid = Instant::now();
        let targets = bc.targets(&problem.handles, t, dim);
        let frame = encoding.frame(&targets)?;
        let q = forward_exported(&model.decoder, &z)?;
        let x = decode_world(encoding, &q, &frame, &targets)?;
        step_time += (mid - clock).as_secs_f64();
        decode_time += mid.elapsed().as_secs_f64();
        if !visit(t, &z, &q, &x) {
            break;
        }
        z_prev2 = std::mem::replace(&mut z_prev, z);
    }
    Ok((step_time, decode_time))
}

/// The limits a rollout of `model` must stay inside: the training envelope (a vertex farther
/// from its encoding origin than in any training frame plus half the diagonal) and 100 times
/// the training maximum of the kinetic energy.
struct BlowUpLimits {
    envelope: f64,
    kinetic_energy: f64,
    values_per_vertex: usize,
}

impl BlowUpLimits {
    fn new(model: &LoadedModel, encoding: &Encoding) -> Self {
        let a = &model.artifact;
        BlowUpLimits {
            envelope: a.summary.max_radius + 0.5 * a.diagonal,
            kinetic_energy: 100.0 * a.summary.max_kinetic_energy.max(1e-12),
            values_per_vertex: encoding.values_per_vertex(),
        }
    }

    /// Why the state with latent `z`, decoded encoded state `q`, world state `x` and kinetic
    /// energy `ke` (`None`: not checked) has blown up, if it has.
    fn check(&self, z: &[f32], q: &[f32], x: &[f64], ke: Option<f64>) -> Option<Divergence> {
        if !(z.iter().all(|v| v.is_finite()) && x.iter().all(|v| v.is_finite())) {
            Some(Divergence::NotFinite)
        } else if max_radius(q, self.values_per_vertex) > self.envelope {
            Some(Divergence::LeftEnvelope)
        } else if ke.is_some_and(|ke| ke > self.kinetic_energy) {
            Some(Divergence::KineticEnergy)
        } else {
            None
        }
    }
}

/// The trainer's rollout of `model` over `bc` (world states of frames `1..`) up to the first
/// frame that is not finite or leaves the training envelope (see [`BlowUpLimits`]): the
/// frames on which another implementation of the same model can be expected to agree with it.
pub fn stable_rollout(
    model: &LoadedModel,
    problem: &Problem,
    encoding: &Encoding,
    bc: &BcSequence,
    frames: usize,
) -> anyhow::Result<Vec<Vec<f64>>> {
    let limits = BlowUpLimits::new(model, encoding);
    let mut states = Vec::new();
    roll(model, problem, encoding, bc, frames, |_, z, q, x| {
        let stable = limits.check(z, q, x, None).is_none();
        if stable {
            states.push(x.to_vec());
        }
        stable
    })?;
    Ok(states)
}

/// Rolls `model` out over `bc` for `frames` frames from its initial latent, comparing with
/// `reference` where it has frames (at most `accuracy_frames` of them).
pub fn rollout(
    model: &LoadedModel,
    problem: &Problem,
    encoding: &Encoding,
    bc: &BcSequence,
    frames: usize,
    reference: &Trajectory,
    accuracy_frames: usize,
) -> anyhow::Result<RolloutMetrics> {
    let a = &model.artifact;
    let dim = problem.mesh.dim;
    let masses = problem.simulator.masses();
    let measured = accuracy_frames.min(reference.num_frames() - 1).min(frames);
    let limits = BlowUpLimits::new(model, encoding);
    let mut x_prev = reference.positions[0].clone();
    let mut metrics = RolloutMetrics {
        stable_frames: frames,
        bounded_frames: frames,
        ..Default::default()
    };
    let (mut ke_ours, mut ke_ref) = (0.0, 0.0);
    let mut rolled = 0;
    // A rollout that drifts off the reference is diverged, but rolls on to measure how long
    // it stays bounded.
    let (step_time, decode_time) = roll(model, problem, encoding, bc, frames, |t, z, q, x| {
        rolled = t;
        let ke = kinetic_energy(masses, x, &x_prev, a.dt, dim);
        if let Some(reason) = limits.check(z, q, x, Some(ke)) {
            metrics.bounded_frames = t - 1;
            if metrics.divergence.is_none() {
                metrics.stable_frames = t - 1;
                metrics.divergence = Some(reason);
            }
            return false;
        }
        if t <= measured {
            let xr = &reference.positions[t];
            let (mean, max) = mean_and_max_error(x, xr, dim, a.diagonal);
            metrics.error_curve.push(mean);
            metrics.max_error = metrics.max_error.max(max);
            ke_ours += ke;
            ke_ref += kinetic_energy(masses, xr, &reference.positions[t - 1], a.dt, dim);
            if (max > OFF_REFERENCE || !mean.is_finite()) && metrics.divergence.is_none() {
                metrics.stable_frames = t - 1;
                metrics.divergence = Some(Divergence::OffReference);
            }
        }
        x_prev.copy_from_slice(x);
        true
    })?;
    let done = rolled.max(1) as f64;
    metrics.step_seconds = step_time / done;
    metrics.decode_seconds = decode_time / done;
    if metrics.error_curve.len() < measured {
        // Blew up inside the measured window: the error there counts as unbounded. (A
        // rollout that only drifted off the reference was measured to the end.)
        metrics.mean_error = f64::INFINITY;
        metrics.max_error = f64::INFINITY;
        metrics.kinetic_energy_ratio = f64::NAN;
    } else {
        metrics.mean_error = metrics.error_curve.iter().sum::<f64>() / measured.max(1) as f64;
        metrics.kinetic_energy_ratio = if ke_ref > 0.0 { ke_ours / ke_ref } else { f64::NAN };
    }
    Ok(metrics)
}

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
    pub fn mean_of(&self, f: impl Fn(&RolloutMetrics) -> f64) -> f64 {
        self.sequences.iter().map(|(_, m)| f(m)).sum::<f64>() / self.sequences.len().max(1) as f64
    }
}

/// Refuses a stored test sequence (`path`) whose prescribed vertices do not follow `bc`,
/// the scene's plan for it, over the frames both cover: a dataset made from another copy of
/// the scene (another `beyond`, seed or motion) would otherwise be measured against a
/// rollout driven by a different motion.
fn check_follows_plan(
    problem: &Problem,
    encoding: &Encoding,
    bc: &BcSequence,
    reference: &Trajectory,
    path: &Path,
) -> anyhow::Result<()> {
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
    /// Progress output.
    pub progress: bool,
}

/// The whole evaluation: every artifact (and its supervised sibling when present) on the
/// test split of its scene; writes `report.md` and the charts into `options.out_dir`.
pub fn evaluate(paths: &[PathBuf], options: &EvalOptions) -> anyhow::Result<(Vec<ModelReport>, f64)> {
    let mut all = Vec::new();
    for path in expand_with_baselines(paths) {
        all.push((path.clone(), LoadedModel::new(Artifact::read(&path)?)?));
    }
    let first = &all
        .first()
        .ok_or_else(|| anyhow::anyhow!("no artifact given"))?
        .1
        .artifact;
    if let Some((p, _)) = all.iter().find(|(_, m)| m.artifact.scene_toml != first.scene_toml) {
        anyhow::bail!(
            "{} is for a different scene than {}; evaluate one scene at a time",
            p.display(),
            paths[0].display()
        );
    }
    let (mut problem, encoding) = rebuild_problem(first)?;
    let data_dir = paths[0].parent().unwrap_or(Path::new(".")).join("dataset");
    dataset::generate(&mut problem, &data_dir, Some(Split::Test), false, options.progress)?;
    let tests = dataset::load(&problem, &data_dir, Split::Test)?;
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
    problem.run(&seq, None)?;
    let reference_seconds = clock.elapsed().as_secs_f64() / timing_frames as f64;

    let mut reports = Vec::new();
    for (path, model) in &all {
        let mut sequences = Vec::new();
        for ((plan, reference), bc) in tests.iter().zip(&plans) {
            let metrics = rollout(
                model,
                &problem,
                &encoding,
                bc,
                options.stability_frames,
                reference,
                options.accuracy_frames,
            )?;
            if options.progress {
                println!(
                    "{} {} on {}: mean error {:.3}%, max {:.2}%, KE ratio {:.3}, stable {}",
                    model.artifact.scene,
                    model.artifact.method.label(),
                    plan.name,
                    100.0 * metrics.mean_error,
                    100.0 * metrics.max_error,
                    metrics.kinetic_energy_ratio,
                    stability(&metrics)
                );
            }
            sequences.push((plan.clone(), metrics));
        }
        reports.push(ModelReport {
            path: path.clone(),
            method: model.artifact.method,
            latent: model.artifact.latent as usize,
            sequences,
        });
    }
    std::fs::create_dir_all(&options.out_dir)?;
    write_charts(&options.out_dir, &first.scene, &reports, reference_seconds)?;
    let mut text = report_markdown(&first.scene, &reports, reference_seconds, options);
    // What each weight storage costs, for the first artifact (the runtime's own rollout).
    let first_path = &all[0].0;
    let bytes = std::fs::read(first_path).with_context(|| format!("reading {}", first_path.display()))?;
    let storage = storage::evaluate(&bytes, first_path, &problem, &tests, options.accuracy_frames)?;
    storage::write_chart(&options.out_dir, &first.scene, &storage)?;
    text += &storage::markdown(&storage, options.accuracy_frames);
    std::fs::write(options.out_dir.join("report.md"), &text)?;
    Ok((reports, reference_seconds))
}

/// `paths`, each followed by its supervised sibling (`X.supervised.mochi` beside `X.mochi`)
/// when that exists and is not listed already.
fn expand_with_baselines(paths: &[PathBuf]) -> Vec<PathBuf> {
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

fn write_charts(dir: &Path, scene: &str, reports: &[ModelReport], reference_seconds: f64) -> anyhow::Result<()> {
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
                x: 1e3 * r.mean_of(|m| m.step_seconds + m.decode_seconds),
                y: 100.0 * r.mean_of(|m| m.error_curve.iter().sum::<f64>() / m.error_curve.len().max(1) as f64),
            }
        })
        .collect();
    points.push(LabelledPoint {
        group: "full space".into(),
        label: "reference".into(),
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

fn report_markdown(scene: &str, reports: &[ModelReport], reference_seconds: f64, options: &EvalOptions) -> String {
    let mut s = format!(
        "# {scene}: evaluation\n\nErrors are vertex distances as % of the rest bounding-box diagonal over the first {} \
         frames of each test sequence; stability over {} frames. Full-space solver: {:.2} ms/frame (timed in the \
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
    s
}
