//! Distilled candidates of the selection over cost (`latent.selection.distill`, docs/design.md
//! decision 6): a trained candidate with an `mlp` decoder gives one more candidate per
//! number of modes listed, its decoder distilled into a basis ([`crate::pipeline::distill`])
//! and its integrator kept, each measured like every candidate.

use crate::artifact::{Artifact, CandidateRow};
use crate::error::{TrainerError, TrainerResult};
use crate::eval::rollout::carried_encoding;
use crate::learn::distill::DistillShape;
use crate::learn::frame_rows::Rows;
use crate::learn::network::forward_exported;
use crate::pipeline::distill::{distill_artifact, DistillOptions};
use crate::pipeline::measure::{measure, SelectionInputs};
use crate::pipeline::stages::{StageTimes, TrainingFrames, BLOCK};
use crate::progress::Reporter;
use crate::report::candidates::candidate_name;
use mochi_sim::BuiltScene;

/// The distilled models of `teacher` (a measured candidate, `teacher_row` its row) for every
/// number of modes of `latent.selection.distill` between its latent size and its encoded
/// length, each with its measured row; a fit that fails is reported and skipped.
pub(crate) fn distilled_candidates(
    teacher: &Artifact,
    teacher_row: &CandidateRow,
    inputs: &SelectionInputs<'_>,
    times: &mut StageTimes,
    report: &dyn Reporter,
) -> TrainerResult<Vec<(Artifact, CandidateRow)>> {
    let spec = &inputs.recipe.latent.selection.distill;
    let (latent, encoded) = (teacher.latent as usize, teacher.encoded_len());
    let mut out = Vec::new();
    for &modes in spec.modes.iter().filter(|&&m| m >= latent && m <= encoded) {
        let stage = format!("distilled decoder ({modes} modes) of {}", candidate_name(teacher_row));
        report.stage(&stage);
        let clock = std::time::Instant::now();
        let options = DistillOptions {
            shape: DistillShape {
                modes,
                hidden: spec.hidden,
                blocks: 1,
            },
            epochs: spec.epochs,
            strand_positions: spec.strand_positions,
            ..DistillOptions::default()
        };
        let fitted = distill_artifact(teacher, &options);
        times.record(stage, clock);
        let outcome = match fitted {
            Ok(outcome) => outcome,
            Err(e) => {
                report.message(&format!("distilled decoder of {modes} modes not fitted: {e}"));
                continue;
            }
        };
        let artifact = outcome.artifact;
        let mut row = CandidateRow {
            decoder: "distilled".into(),
            modes: modes as u32,
            decoder_width: spec.hidden as u32,
            reconstruction: reconstruction(&artifact, inputs.problem, inputs.frames)?,
            validation_error: f64::INFINITY,
            stable_frames: 0,
            storages: Vec::new(),
            multiply_adds: 0,
            candle_microseconds: f64::NAN,
            kept: false,
            ..teacher_row.clone()
        };
        measure(&artifact, inputs, &mut row)?;
        report.message(&format!(
            "distilled({modes}) of {}: validation error {:.3}% (stable {} of {} frames), {} multiply-adds",
            candidate_name(teacher_row),
            100.0 * row.validation_error,
            row.stable_frames,
            row.validation_frames,
            row.multiply_adds,
        ));
        out.push((artifact, row));
    }
    Ok(out)
}

/// RMS vertex error / diagonal of the training frames encoded by `artifact`'s encoder and
/// decoded by its decoder, both in the encoding it carries, against the frames' positions:
/// the reconstruction column of the candidates table (strands encoded by their bends compared
/// as decoded positions, as the autoencoders' are).
fn reconstruction(artifact: &Artifact, problem: &BuiltScene, frames: &TrainingFrames) -> TrainerResult<f64> {
    let encoding = carried_encoding(artifact, problem)?;
    let (encoder, decoder) = (artifact.encoder()?, artifact.decoder()?);
    let (mut sum, mut count) = (0.0, 0usize);
    let steps = frames.steps();
    let width = frames.rows.width();
    let mut x = vec![0.0; frames.encoding.state_len()];
    // The positions are the training frames' own, decoded from the training encoding.
    frames.rows.for_each_block(BLOCK, |first, block| {
        for (i, exact) in block.chunks_exact(width).enumerate() {
            let (frame, targets) = steps[first + i];
            frames.encoding.decode_into(exact, frame, targets, &mut x)?;
            let q = encoding.encode(&x, &encoding.frame(targets)?)?;
            let rebuilt = decoder.decode::<f64>(&forward_exported(&encoder, &q)?)?;
            let approx = encoding.decode(&rebuilt, targets)?;
            sum += approx.iter().zip(&x).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
            count += encoding.free_vertices().len();
        }
        Ok::<(), TrainerError>(())
    })?;
    Ok((sum / count.max(1) as f64).sqrt() / artifact.diagonal)
}
