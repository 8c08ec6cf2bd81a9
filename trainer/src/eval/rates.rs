//! `mochi eval --rates`: models of one body stepped at several frame rates on the same motions,
//! against full space at each rate (docs/design.md, "The frame time as an input").
//!
//! The motions are the first model's test sequences (its scene's held-out speeds inside the
//! training range first), each seen at every rate ([`BuiltScene::plan_sequence`]: the motion
//! sampled at the scene's `dt`, resampled). At each rate the reference is the scene simulated
//! in full space with a time step of one frame over the first `seconds`; every model is rolled
//! out for `stability_frames` frames and measured over the reference's frames. A model that
//! takes the frame time as an input steps at every rate (outside its trained range the motion
//! is an extrapolation, reported as measured); a model of one frame time steps only at its own
//! and says so at the others. Models of different scenes may be compared when their bodies,
//! handles and encodings are the same (e.g. a model trained over 30-120 frames per second
//! against models trained at one rate each).

use std::path::PathBuf;

use mochi_sim::bc::BcSequence;
use mochi_sim::dataset::{self, SequencePlan, Split};
use mochi_sim::BuiltScene;

use super::rollout::{carried_encoding, rebuild_problem, rollout, LoadedModel, RolloutMetrics};
use crate::artifact::Artifact;
use crate::error::{fs, TrainerError, TrainerResult};
use crate::progress::Reporter;
use crate::report::chart::{self, Series};

/// Relative difference of frame times taken as the same (a model of one frame time at a rate
/// given as a rounded number of frames per second).
const SAME_FRAME_TIME: f64 = 1e-3;

/// Options of the frame-rate evaluation.
#[derive(Clone, Debug)]
pub struct RatesOptions {
    /// Frame rates (frames per second) to step at.
    pub rates: Vec<f64>,
    /// Seconds of motion measured against full space at each rate.
    pub seconds: f64,
    /// Frames of each stability rollout (at every rate).
    pub stability_frames: usize,
    /// Test sequences used (the held-out speeds inside the training range first).
    pub sequences: usize,
    /// Where `rates.md` and `rates.png` go.
    pub out_dir: PathBuf,
}

/// One model at one rate: its metrics, one per sequence, or why it cannot step there.
#[derive(Clone, Debug)]
pub enum RateCell {
    /// Rolled out on every sequence.
    Measured(Vec<RolloutMetrics>),
    /// Cannot step at this rate.
    Cannot(String),
}

/// Every model at every rate.
#[derive(Clone, Debug)]
pub struct RatesReport {
    /// Model labels (file stem and training method), in the order given.
    pub models: Vec<String>,
    /// The sequences measured.
    pub sequences: Vec<SequencePlan>,
    /// Per rate: the rate and one cell per model.
    pub rows: Vec<(f64, Vec<RateCell>)>,
}

impl RateCell {
    /// Mean over the sequences of a metric (NaN when the model cannot step at the rate).
    pub fn mean_of(&self, f: impl Fn(&RolloutMetrics) -> f64) -> f64 {
        match self {
            RateCell::Measured(m) => m.iter().map(f).sum::<f64>() / m.len().max(1) as f64,
            RateCell::Cannot(_) => f64::NAN,
        }
    }
}

/// Evaluates `paths` (with their supervised twins) at every rate of `options`, writes the page
/// and chart into `options.out_dir`, and returns what it measured.
pub fn evaluate_rates(paths: &[PathBuf], options: &RatesOptions, report: &dyn Reporter) -> TrainerResult<RatesReport> {
    if options.rates.is_empty() || options.rates.iter().any(|r| !(r.is_finite() && *r > 0.0)) {
        return Err(TrainerError::invalid(
            "--rates needs positive frame rates, e.g. 30,60,90,120",
        ));
    }
    if !(options.seconds.is_finite() && options.seconds > 0.0) {
        return Err(TrainerError::invalid("--seconds must be positive"));
    }
    let mut models = Vec::new();
    for path in super::expand_with_baselines(paths) {
        models.push((path.clone(), LoadedModel::new(Artifact::read(&path)?)?));
    }
    let first = &models
        .first()
        .ok_or_else(|| TrainerError::invalid("no artifact given"))?
        .1;
    let (mut problem, _) = rebuild_problem(&first.artifact)?;
    let mut encodings = Vec::new();
    for (path, model) in &models {
        let same_body = model.artifact.rest == first.artifact.rest && model.artifact.handles == first.artifact.handles;
        let encoding = carried_encoding(&model.artifact, &problem).ok().filter(|_| same_body);
        encodings.push(encoding.ok_or_else(|| {
            TrainerError::invalid(format!(
                "{} is a model of another body than {}; compare models of one body",
                path.display(),
                paths[0].display()
            ))
        })?);
    }
    let plans = test_plans(&problem, options.sequences);
    let mut rows = Vec::new();
    for &rate in &options.rates {
        let dt = 1.0 / rate;
        let measured = ((options.seconds * rate).round() as usize).max(1);
        let frames = options.stability_frames.max(measured);
        // The motions seen at this rate, then the scene stepped at it.
        let motions: Vec<BcSequence> = plans
            .iter()
            .map(|plan| {
                let seen = SequencePlan {
                    dt: Some(dt),
                    ..plan.clone()
                };
                problem.plan_sequence(&seen, frames)
            })
            .collect();
        let mut rebuilt = problem.at_frame_time(Some(dt))?;
        let at_rate = rebuilt.as_mut().unwrap_or(&mut problem);
        let mut cells: Vec<Vec<RolloutMetrics>> = vec![Vec::new(); models.len()];
        for (plan, bc) in plans.iter().zip(&motions) {
            let reference = at_rate.run(&bc.first(measured), &report.frames(&format!("{rate} Hz {}", plan.name)))?;
            for (((_, model), encoding), cell) in models.iter().zip(&encodings).zip(&mut cells) {
                if !steps_at(&model.artifact, dt) {
                    continue;
                }
                let metrics = rollout(model, at_rate, encoding, bc, frames, &reference, measured)?;
                report.message(&format!(
                    "{rate} Hz {} {}: mean error {:.3}%, stable {} / {frames}",
                    label(&model.artifact),
                    plan.name,
                    100.0 * metrics.mean_error,
                    stable_text(&metrics)
                ));
                cell.push(metrics);
            }
        }
        let row = models
            .iter()
            .zip(cells)
            .map(|((_, model), metrics)| {
                if steps_at(&model.artifact, dt) {
                    RateCell::Measured(metrics)
                } else {
                    RateCell::Cannot(format!(
                        "trained at {:.0} Hz only: needs retraining",
                        1.0 / model.artifact.dt
                    ))
                }
            })
            .collect();
        rows.push((rate, row));
    }
    let result = RatesReport {
        models: models.iter().map(|(_, m)| label(&m.artifact)).collect(),
        sequences: plans,
        rows,
    };
    write_page(&result, options, paths)?;
    Ok(result)
}

/// Whether `artifact` steps at frame time `dt`: any, when it takes the frame time as an input;
/// otherwise its own only.
fn steps_at(artifact: &Artifact, dt: f64) -> bool {
    artifact.timed() || (artifact.dt - dt).abs() <= SAME_FRAME_TIME * dt
}

/// A model's label: its scene and training method, the frame rates it was trained at, and
/// whether its timed integrator reads the latent's rate (format 8) or the latent before the
/// last (format 7).
fn label(a: &Artifact) -> String {
    let rates = match a.dt_range {
        [lo, hi] if hi > 0.0 && (hi - lo).abs() <= SAME_FRAME_TIME * hi => format!("{:.0} Hz", 1.0 / lo),
        [lo, hi] if hi > 0.0 => format!("{:.0}-{:.0} Hz", 1.0 / hi, 1.0 / lo),
        _ => format!("{:.0} Hz", 1.0 / a.dt),
    };
    let reads = match (a.timed(), a.rate_input) {
        (true, true) => ", reads the rate",
        (true, false) => ", reads z_{t-2}",
        (false, _) => "",
    };
    format!("{} {} ({rates}{reads})", a.scene, a.method.label())
}

/// The first `count` test sequences of `problem`'s dataset, the held-out speeds inside the
/// training range (after the sudden drop and the speed beyond the range) first.
fn test_plans(problem: &BuiltScene, count: usize) -> Vec<SequencePlan> {
    let tests: Vec<SequencePlan> = dataset::plan(&problem.scene.dataset)
        .into_iter()
        .filter(|p| p.split == Split::Test)
        .collect();
    let inside = tests.len().min(2);
    tests[inside..]
        .iter()
        .chain(&tests[..inside])
        .take(count.max(1))
        .cloned()
        .collect()
}

/// `rates.md` (a table per metric) and `rates.png` (mean error against the rate, one line per
/// model) in `options.out_dir`.
fn write_page(result: &RatesReport, options: &RatesOptions, paths: &[PathBuf]) -> TrainerResult<()> {
    let dir = &options.out_dir;
    fs::create_dir_all(dir)?;
    let series: Vec<Series> = result
        .models
        .iter()
        .enumerate()
        .map(|(m, name)| Series {
            name: name.clone(),
            points: result
                .rows
                .iter()
                .map(|(rate, cells)| (*rate, 100.0 * cells[m].mean_of(|x| x.mean_error)))
                .collect(),
        })
        .collect();
    chart::line_chart(
        &dir.join("rates.png"),
        "Mean vertex error against full space at each frame rate",
        "frames per second",
        "mean vertex error (% of the diagonal)",
        &series,
        true,
    )?;
    let mut md = String::from("# Frame rates\n\n");
    let files: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
    md += &format!(
        "`mochi eval {} --rates {} --seconds {} --frames {} --sequences {}`\n\n",
        files.join(" "),
        result
            .rows
            .iter()
            .map(|(r, _)| format!("{r}"))
            .collect::<Vec<_>>()
            .join(","),
        options.seconds,
        options.stability_frames,
        result.sequences.len()
    );
    md += &format!(
        "Sequences: {} (each the scene's test motion seen at every rate). Each cell: mean vertex \
         error over the first {} s against full space stepped at that rate (% of the diagonal), \
         then frames stable of each sequence's {}-frame rollout (and why a rollout diverged where it did).\n\n![error against frame rate](rates.png)\n\n",
        result
            .sequences
            .iter()
            .map(|p| format!("{} ({})", p.name, p.description))
            .collect::<Vec<_>>()
            .join(", "),
        options.seconds,
        options.stability_frames
    );
    md += &format!(
        "| frames per second | {} |\n|---|{}\n",
        result.models.join(" | "),
        "---|".repeat(result.models.len())
    );
    for (rate, cells) in &result.rows {
        let texts: Vec<String> = cells.iter().map(cell_text).collect();
        md += &format!("| {rate} | {} |\n", texts.join(" | "));
    }
    fs::write(&dir.join("rates.md"), md)?;
    Ok(())
}

fn cell_text(cell: &RateCell) -> String {
    match cell {
        RateCell::Cannot(why) => why.clone(),
        RateCell::Measured(m) => {
            let stable: Vec<String> = m.iter().map(stable_text).collect();
            let error = cell.mean_of(|x| x.mean_error);
            // A rollout that blew up inside the measured seconds has no finite mean error.
            let error = match error.is_finite() {
                true => format!("{:.3}%", 100.0 * error),
                false => "blew up".into(),
            };
            format!("{error}, stable {}", stable.join(" / "))
        }
    }
}

/// A rollout's stable frames, and why it diverged where it did.
fn stable_text(m: &RolloutMetrics) -> String {
    match m.divergence {
        Some(why) => format!("{} ({})", m.stable_frames, why.describe()),
        None => m.stable_frames.to_string(),
    }
}
