//! What selection measures of every candidate model: its rollouts over the validation
//! sequences and its time per frame in the runtime, in every weight storage.

use std::path::Path;

use crate::artifact::{Artifact, CandidateRow};
use crate::error::{TrainerError, TrainerResult};
use crate::eval::rollout::{carried_encoding, rollout, LoadedModel};
use crate::eval::runtime_bench::bench_artifact;
use crate::learn::recipe::Recipe;
use crate::pipeline::stages::{TrainingFrames, Workspace};
use mochi_runtime::WeightFormat;
use mochi_sim::dataset;
use mochi_sim::trajectory::Trajectory;
use mochi_sim::BuiltScene;

/// Frames of the runtime timing of each candidate.
const TIMING_FRAMES: usize = 200;

/// What stage 4 needs besides the decoders.
pub(crate) struct SelectionInputs<'a> {
    /// The recipe trained.
    pub(crate) recipe: &'a Recipe,
    /// Its scene, built.
    pub(crate) problem: &'a BuiltScene,
    /// The encoded training split.
    pub(crate) frames: &'a TrainingFrames,
    /// The validation split.
    pub(crate) validation: &'a [(dataset::SequencePlan, Trajectory)],
    /// Where training works.
    pub(crate) work: &'a Workspace,
    /// Where every candidate's artifact is written (`candidates/` of the output directory).
    pub(crate) candidates_dir: &'a Path,
}

/// Rolls `artifact` out over the validation sequences and times it in the runtime in every
/// weight storage, filling in `row`.
pub(crate) fn measure(artifact: &Artifact, inputs: &SelectionInputs<'_>, row: &mut CandidateRow) -> TrainerResult<()> {
    let problem = inputs.problem;
    let model = LoadedModel::new(artifact.clone())?;
    // A distilled candidate may decode in another encoding than the training's.
    let encoding = carried_encoding(artifact, problem)?;
    let mut errors = Vec::new();
    row.stable_frames = u64::MAX;
    for (plan, reference) in inputs.validation {
        let frames = reference.num_frames() - 1;
        let bc = problem.plan_sequence(plan, frames);
        // A sequence at another frame time is measured in the scene stepped at it.
        let at_rate = problem.at_frame_time(plan.dt)?;
        let metrics = rollout(
            &model,
            at_rate.as_ref().unwrap_or(problem),
            &encoding,
            &bc,
            frames,
            reference,
            frames,
        )?;
        errors.push(metrics.mean_error);
        row.stable_frames = row.stable_frames.min(metrics.stable_frames as u64);
        row.validation_frames = frames as u64;
    }
    if errors.is_empty() {
        return Err(TrainerError::invalid(
            "model selection needs validation sequences (dataset.validation is 0)",
        ));
    }
    row.validation_error = errors.iter().sum::<f64>() / errors.len() as f64;
    let bytes = artifact.to_bytes()?;
    let storages = [WeightFormat::F32, WeightFormat::F16, WeightFormat::Int8];
    let timings = bench_artifact(artifact, &bytes, Path::new(&artifact.scene), TIMING_FRAMES, &storages)?;
    for t in &timings {
        row.storages.push((
            mochi_codegen::format_name(t.weights).to_string(),
            t.weight_bytes as u64,
            1e6 * t.full,
        ));
        row.multiply_adds = t.multiply_adds as u64;
        row.candle_microseconds = 1e6 * t.candle;
    }
    Ok(())
}
