//! Distilled candidates of the selection over cost (`latent.selection.distill`, docs/design.md
//! decision 6): a trained candidate with an `mlp` decoder gives one more candidate per
//! number of modes listed, its decoder distilled into a basis ([`crate::pipeline::distill`])
//! and its integrator kept, each measured like every candidate.

use crate::artifact::{Artifact, CandidateRow};
use crate::error::TrainerResult;
use crate::learn::distill::DistillShape;
use crate::learn::network::forward_exported;
use crate::learn::sequences::decoded_rms_error;
use crate::pipeline::distill::{distill_artifact, DistillOptions};
use crate::pipeline::measure::{measure, SelectionInputs};
use crate::pipeline::stages::{StageTimes, TrainingFrames};
use crate::progress::Reporter;

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
        let stage = format!(
            "distilled decoder ({modes} modes) of mlp({}) k={latent}, integrator {}",
            teacher_row.decoder_width, teacher_row.integrator_width
        );
        report.stage(&stage);
        let clock = std::time::Instant::now();
        let options = DistillOptions {
            shape: DistillShape {
                modes,
                hidden: spec.hidden,
                blocks: 1,
            },
            epochs: spec.epochs,
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
            reconstruction: reconstruction(&artifact, inputs.frames)?,
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
            "distilled({modes}) of mlp({}) k={latent}: validation error {:.3}% (stable {} of {} frames), {} multiply-adds",
            teacher_row.decoder_width,
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
/// decoded by its decoder: the reconstruction column of the candidates table (strands
/// encoded by their bends compared as decoded positions, as the autoencoders' are).
fn reconstruction(artifact: &Artifact, frames: &TrainingFrames) -> TrainerResult<f64> {
    let (encoder, decoder) = (artifact.encoder()?, artifact.decoder()?);
    let rebuilt = frames
        .f64s
        .iter()
        .map(|q| Ok(decoder.decode::<f64>(&forward_exported(&encoder, q)?)?))
        .collect::<TrainerResult<Vec<Vec<f64>>>>()?;
    let encoding = &frames.encoding;
    if encoding.strand_bends() {
        return Ok(decoded_rms_error(
            encoding,
            &frames.sequences,
            &rebuilt,
            artifact.diagonal,
        )?);
    }
    let (mut sum, mut values) = (0.0, 0usize);
    for (q, r) in frames.f64s.iter().zip(&rebuilt) {
        sum += q.iter().zip(r).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        values += q.len();
    }
    let vertices = (values / encoding.values_per_vertex().max(1)).max(1) as f64;
    Ok((sum / vertices).sqrt() / artifact.diagonal)
}
