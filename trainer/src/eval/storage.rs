//! What each weight storage costs in accuracy (`mochi eval`, "Weight storage"): the runtime's
//! rollout of one artifact with its weights stored as `f32`, `f16` and int8 (per-row scales,
//! as `mochi codegen --weights` would generate them), against the full-space reference on the
//! test sequences, and against the `f32` runtime. The int8 kernel also quantises each layer's
//! input (see `mochi_runtime::network::integer`); the same int8 weights widened back to `f32`
//! show what that costs apart from the weights' own rounding.

use std::path::Path;

use mochi_codegen::{format_name, Options, Quantized};
use mochi_runtime::{OwnedModel, ValidModel, WeightFormat};

use crate::error::{Context, TrainerResult as Result};
use crate::eval::rollout::OFF_REFERENCE;
use crate::methods::learned::LearnedRuntime;
use crate::methods::method::run_sequence;
use crate::report::chart::{self, LabelledPoint};
use mochi_sim::dataset::SequencePlan;
use mochi_sim::measure::{mean_and_max_error, vertex_errors};
use mochi_sim::trajectory::Trajectory;
use mochi_sim::BuiltScene;

/// One storage compared: the networks' weight formats, and whether int8 weights are widened
/// back to `f32` (exactly `scale * q`) so that the `f32` kernel runs on unquantised inputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Storage {
    /// The weight formats.
    pub options: Options,
    /// Int8 weights widened to `f32`.
    pub widened: bool,
}

impl Storage {
    fn stored(options: Options) -> Self {
        Storage {
            options,
            widened: false,
        }
    }
}

/// The storages compared: `--weights f32`, `f16` and `int8` (which keeps the integrator in
/// `f16`), int8 for both networks (the reason it does), and `--weights int8` widened to `f32`
/// (what the int8 kernel's input quantisation costs).
pub fn storages() -> [Storage; 5] {
    [
        Storage::stored(Options::weights(WeightFormat::F32)),
        Storage::stored(Options::weights(WeightFormat::F16)),
        Storage::stored(Options::weights(WeightFormat::Int8)),
        Storage::stored(Options {
            decoder: WeightFormat::Int8,
            integrator: WeightFormat::Int8,
        }),
        Storage {
            options: Options::weights(WeightFormat::Int8),
            widened: true,
        },
    ]
}

/// How a storage is called in reports.
pub(crate) fn storage_name(storage: &Storage) -> String {
    let options = &storage.options;
    if storage.widened {
        format!(
            "{}, widened to f32 (no input quantisation)",
            storage_name(&Storage::stored(*options))
        )
    } else if options == &Options::weights(options.decoder) {
        format_name(options.decoder).into()
    } else {
        format!(
            "{} decoder, {} integrator",
            format_name(options.decoder),
            format_name(options.integrator)
        )
    }
}

/// One format's results over the test sequences.
#[derive(Clone, Debug, PartialEq)]
pub struct StorageReport {
    /// The weight storage.
    pub storage: Storage,
    /// Bytes of weights, biases and scales.
    pub weight_bytes: usize,
    /// Mean over sequences of the mean vertex error / diagonal over every measured frame
    /// (infinite if the runtime refused a step inside the window on one of them).
    pub mean_error: f64,
    /// Largest vertex error / diagonal.
    pub max_error: f64,
    /// Largest vertex distance / diagonal from the `f32` runtime's positions.
    pub max_deviation: f64,
    /// Fewest frames any sequence ran before a vertex was half a diagonal off the reference
    /// (capped at the frames measured).
    pub stable_frames: usize,
    /// Fewest frames any sequence ran before the runtime refused a step or a decode (capped
    /// at the frames measured): a rollout that only drifted off the reference rolls on, as
    /// in `mochi eval`.
    pub bounded_frames: usize,
}

/// Rolls the runtime out over the first `frames` frames of every test sequence with the
/// artifact's weights stored in each of [`storages`] (the first, `f32`, is the one the others
/// are compared with).
pub fn evaluate(
    bytes: &[u8],
    source: &Path,
    problem: &BuiltScene,
    tests: &[(SequencePlan, Trajectory)],
    frames: usize,
) -> Result<Vec<StorageReport>> {
    let mut storage = OwnedModel::default();
    let base = *storage
        .load(bytes)
        .with_context(|| format!("{}: runtime refused the artifact", source.display()))?
        .model();
    let mut f32_positions: Vec<Vec<Vec<f64>>> = Vec::new();
    let mut reports = Vec::new();
    for storage in storages() {
        let options = storage.options;
        let quantized = Quantized::split(&base, options.decoder, options.integrator);
        let widened;
        let model = if storage.widened {
            widened = Quantized::split(&quantized.model(&base), WeightFormat::F32, WeightFormat::F32);
            widened.model(&base)
        } else {
            quantized.model(&base)
        };
        let model = ValidModel::new(model)
            .with_context(|| format!("{}: with {} weights", source.display(), storage_name(&storage)))?;
        let mut report = StorageReport {
            storage,
            weight_bytes: model.model().weight_bytes(),
            mean_error: 0.0,
            max_error: 0.0,
            max_deviation: 0.0,
            stable_frames: usize::MAX,
            bounded_frames: usize::MAX,
        };
        for (s, (plan, reference)) in tests.iter().enumerate() {
            let measured = frames.min(reference.num_frames() - 1);
            let bc = problem.sequence(&plan.speeds, measured, plan.seed);
            let diagonal = base.diagonal as f64;
            let dim = base.dim();
            // Frames `1..` up to the first step or decode the runtime refused or a blow-up (a
            // rollout that only drifted off the reference rolls on).
            let mut runtime = LearnedRuntime::new(&model, "learned (runtime)", storage_name(&storage))?;
            let mut rolled = Vec::new();
            run_sequence(
                &mut runtime,
                &bc,
                measured,
                &[],
                dim,
                diagonal,
                Some((&mut rolled, measured + 1)),
            )?;
            rolled.remove(0);
            let (mut mean_sum, mut stable) = (0.0, rolled.len());
            for (t, x) in rolled.iter().enumerate() {
                let (mean, worst) = mean_and_max_error(x, &reference.positions[t + 1], dim, diagonal);
                if worst > OFF_REFERENCE {
                    stable = stable.min(t);
                }
                mean_sum += mean;
                report.max_error = report.max_error.max(worst);
                if let Some(ours) = f32_positions.get(s).and_then(|p| p.get(t)) {
                    report.max_deviation = vertex_errors(x, ours, dim, diagonal).fold(report.max_deviation, f64::max);
                }
            }
            report.stable_frames = report.stable_frames.min(stable);
            report.bounded_frames = report.bounded_frames.min(rolled.len());
            report.mean_error += if rolled.len() < measured {
                f64::INFINITY
            } else {
                mean_sum / measured.max(1) as f64 / tests.len() as f64
            };
            if f32_positions.len() < tests.len() {
                f32_positions.push(rolled);
            }
        }
        reports.push(report);
    }
    Ok(reports)
}

/// Writes `storage.png`: mean error against model size, one point per format.
pub(crate) fn write_chart(dir: &Path, scene: &str, reports: &[StorageReport]) -> Result<()> {
    let points: Vec<LabelledPoint> = reports
        .iter()
        .map(|r| LabelledPoint {
            group: storage_name(&r.storage),
            label: format!("{:.0} KiB", r.weight_bytes as f64 / 1024.0),
            emphasis: false,
            x: r.weight_bytes as f64 / 1024.0,
            y: 100.0 * r.mean_error,
        })
        .collect();
    chart::scatter_chart(
        &dir.join("storage.png"),
        &format!("{scene}: weight storage, size against accuracy (runtime, test mean)"),
        "weights (KiB)",
        "mean vertex error (% of diagonal)",
        &points,
        true,
        false,
    )
}

/// The report section (markdown).
pub fn markdown(reports: &[StorageReport], frames: usize) -> String {
    let mut s = format!(
        "\n## Weight storage\n\nThe runtime's rollout with the weights stored each way (`mochi codegen --weights`), over \
         the first {frames} frames of each test sequence: error against the full-space reference, and the largest \
         distance from the `f32` runtime's positions (% of the diagonal).\n\n| weights | bytes | mean err % | max err % \
         | max distance from f32 % | fewest stable frames (bounded) |\n|---|---|---|---|---|---|\n"
    );
    for r in reports {
        s += &format!(
            "| {} | {} | {:.3} | {:.3} | {:.4} | {} ({}) |\n",
            storage_name(&r.storage),
            r.weight_bytes,
            100.0 * r.mean_error,
            100.0 * r.max_error,
            100.0 * r.max_deviation,
            r.stable_frames,
            r.bounded_frames
        );
    }
    s
}
