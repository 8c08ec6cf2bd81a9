//! Lipschitz optimisation of a supervised subspace (Eq. 10): from the vanilla autoencoder
//! (trained on Eq. 3 alone), minimise `L_C + lambda L_LS` with the reconstruction loss `L_C`
//! on minibatches of encoded frames and the Lipschitz loss `L_LS` (Eq. 9) on the latents of a
//! few frames of each minibatch (the pull-back samples: frames encoded by the current
//! encoder, held fixed within the step).
//!
//! `lambda` is given relative to the two losses at the vanilla start: `lambda = weight *
//! L_C(0) / L_LS(0)`, so `weight = 1` makes the Lipschitz term as large as the reconstruction
//! term there, whatever the scene's units. The run is the trainer's ordinary training loop
//! (AdamW, checkpoints, resume).

use super::loss::{LatentSample, LipschitzTerm};
use crate::learn::network::{forward_exported, Autoencoder};
use crate::learn::train::{self, BatchLoss, TrainConfig, TrainError, TrainReport, TrainResult};

/// How strongly, and on how many samples, the Lipschitz term acts.
#[derive(Clone, Debug, PartialEq)]
pub struct LipschitzSettings {
    /// `weight` of the module documentation (default 1).
    pub weight: f64,
    /// Lipschitz samples per minibatch (the first frames of each; default 8, at least 2).
    pub samples: usize,
}

impl Default for LipschitzSettings {
    fn default() -> Self {
        LipschitzSettings {
            weight: 1.0,
            samples: 8,
        }
    }
}

/// What a Lipschitz optimisation did.
#[derive(Clone, Debug)]
pub(crate) struct LipschitzReport {
    /// The training loop's report (total loss per epoch).
    pub train: TrainReport,
    /// `L_C` and `L_LS` at the start.
    pub start: (f64, f64),
    /// The absolute weight `lambda` used.
    pub lambda: f64,
}

/// Optimises `autoencoder` in place on encoded frames `data` whose handle targets are
/// `targets` (one per frame), with `term` (module documentation).
pub(crate) fn optimise_supervised(
    autoencoder: &Autoencoder,
    data: &[Vec<f32>],
    targets: &[Vec<f64>],
    term: &LipschitzTerm<'_>,
    settings: &LipschitzSettings,
    config: &TrainConfig,
    resume: bool,
) -> TrainResult<LipschitzReport> {
    if data.len() != targets.len() {
        return Err(TrainError::Invalid(format!(
            "{} frames with {} handle placements",
            data.len(),
            targets.len()
        )));
    }
    if settings.samples < 2 || config.batch_size < settings.samples {
        return Err(TrainError::Invalid(format!(
            "the Lipschitz term needs at least 2 samples per minibatch, within the batch size {} (got {})",
            config.batch_size, settings.samples
        )));
    }
    if !(settings.weight.is_finite() && settings.weight >= 0.0) {
        return Err(TrainError::Invalid(format!(
            "the Lipschitz weight must be finite and non-negative, got {}",
            settings.weight
        )));
    }
    let invalid = |e: crate::error::TrainerError| candle_core::Error::Msg(e.to_string());
    let samples_of = |indices: &[usize]| -> candle_core::Result<Vec<LatentSample>> {
        let exported = autoencoder.export().map_err(|e| candle_core::Error::Msg(e.to_string()))?;
        indices
            .iter()
            .take(settings.samples)
            .map(|&i| {
                let z = forward_exported(&exported.encoder, &data[i]).map_err(|e| candle_core::Error::Msg(e.to_string()))?;
                Ok(LatentSample {
                    z: z.iter().map(|&v| v as f64).collect(),
                    targets: targets[i].clone(),
                })
            })
            .collect()
    };
    // The two losses at the start, on the first minibatch's worth of frames.
    let first: Vec<usize> = (0..data.len().min(config.batch_size)).collect();
    let exported = autoencoder.export().map_err(|e| TrainError::Invalid(e.to_string()))?;
    let start_samples = samples_of(&first)?;
    let hessians = term
        .hessians(&exported.decoder, &start_samples)
        .map_err(|e| TrainError::Invalid(e.to_string()))?;
    let ls0 = super::loss::lipschitz_loss(&hessians, &start_samples);
    let lc0 = train::mean_reconstruction_error(autoencoder, data, 256)?;
    let lambda = if ls0 > 0.0 { settings.weight * lc0.max(1e-12) / ls0 } else { 0.0 };

    let report = train::train(&autoencoder.parameters(), data, config, resume, |batch, _| {
        let reconstruction = Autoencoder::reconstruction_loss_of(&autoencoder.reconstruct(&batch.inputs)?, &batch.inputs)?;
        let samples = samples_of(batch.indices)?;
        let exported = autoencoder.export().map_err(|e| candle_core::Error::Msg(e.to_string()))?;
        let lip = term
            .batch(autoencoder.decoder(), None, &exported.decoder, &samples)
            .map_err(invalid)?;
        let value = reconstruction.to_scalar::<f32>()? as f64 + lambda * lip.loss;
        let objective = (reconstruction + lip.surrogate.affine(lambda, 0.0)?)?;
        Ok(BatchLoss { objective, value })
    })?;
    Ok(LipschitzReport {
        train: report,
        start: (lc0, ls0),
        lambda,
    })
}
