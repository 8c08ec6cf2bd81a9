//! Lipschitz optimisation of a subspace (Eq. 10), supervised or data-free.
//!
//! A supervised subspace continues from the vanilla autoencoder (trained on Eq. 3 alone) and
//! minimises `L_C + lambda L_LS`: the reconstruction loss `L_C` on minibatches of encoded
//! frames, the Lipschitz loss `L_LS` (Eq. 9) on the latents of a few frames of each minibatch
//! (the pull-back samples: frames encoded by the current encoder, held fixed within the step),
//! on the trainer's ordinary training loop (AdamW, checkpoints, resume). A data-free subspace
//! continues from its vanilla decoder with Eq. 4 as `L_C` and Gaussian latent samples.
//!
//! `lambda` is given relative to the two losses at the vanilla start: `lambda = weight *
//! max(L_C(0), floor) / L_LS(0)`, so `weight = 1` makes the Lipschitz term as large as the
//! construction term there, whatever the scene's units. For a supervised subspace the floor
//! is the reconstruction loss at the recipe's tolerance (`(tolerance * diagonal)^2 / dim`): a
//! vanilla autoencoder that reconstructs its data almost exactly would otherwise leave the
//! Lipschitz term no weight at all.

use crate::learn::frame_rows::Rows;
use candle_core::Tensor;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use mochi_sim::energy::StencilEnergy;

use super::cubature::sampled_cubature;
use super::loss::{LatentSample, LipschitzTerm};
use crate::error::{TrainerError, TrainerResult};
use crate::learn::datafree::{normal_latents, DataFreeModel, DataFreeObjective, DataFreeSettings};
use crate::learn::network::{forward_exported, tensor_to_rows, Autoencoder, ExportedMlp};
use crate::learn::samples::candle_err;
use crate::learn::train::{self, AdamW, AdamWConfig, BatchLoss, TrainConfig, TrainError, TrainReport, TrainResult};
use crate::progress::{EpochsBar, Reporter};

/// How strongly, and on how many samples, the Lipschitz term acts.
#[derive(Clone, Debug, PartialEq)]
pub struct LipschitzSettings {
    /// `weight` of the module documentation (default 1).
    pub weight: f64,
    /// Lipschitz samples per minibatch (the first frames of each; default 8, at least 2).
    pub samples: usize,
    /// The construction loss below which `lambda` stops growing (module documentation;
    /// default 0).
    pub floor: f64,
    /// An absolute `lambda` in place of the one derived from `weight` (a supervised
    /// optimisation continued in rounds keeps its first round's; default none).
    pub lambda: Option<f64>,
    /// Supervised only: when positive, half of each minibatch's samples are encoded frames
    /// and the other half those latents moved by `local` times the samples' RMS spread in a
    /// random direction, so Eq. 9 also sees pairs of nearby latents (the local roughness a
    /// step's solve meets); default 0, every sample an encoded frame (the paper's).
    pub local: f64,
    /// When positive, each minibatch's Lipschitz term differentiates a fresh Monte Carlo
    /// cubature of this many elements of each potential of the term
    /// ([`super::cubature::sampled_cubature`], one draw for the whole minibatch) instead of
    /// the term's potentials themselves; default 0.
    pub resample: usize,
}

impl Default for LipschitzSettings {
    fn default() -> Self {
        LipschitzSettings {
            weight: 1.0,
            samples: 8,
            floor: 0.0,
            lambda: None,
            local: 0.0,
            resample: 0,
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
    data: &(impl Rows + ?Sized),
    targets: &[Vec<f64>],
    term: &LipschitzTerm<'_>,
    settings: &LipschitzSettings,
    config: &TrainConfig,
    resume: bool,
) -> TrainResult<LipschitzReport> {
    if data.count() != targets.len() {
        return Err(TrainError::Invalid(format!(
            "{} frames with {} handle placements",
            data.count(),
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
    // The latents of the first `settings.samples` frames of `indices` under `encoder`.
    let frames_per_batch = if settings.local > 0.0 {
        settings.samples.div_ceil(2)
    } else {
        settings.samples
    };
    let encoded_of = |encoder: &ExportedMlp, indices: &[usize]| -> candle_core::Result<Vec<LatentSample>> {
        indices
            .iter()
            .take(frames_per_batch)
            .map(|&i| {
                let mut row = Vec::with_capacity(data.width());
                data.gather_f32(&[i], &mut row).map_err(candle_err)?;
                let z = forward_exported(encoder, &row).map_err(candle_err)?;
                Ok(LatentSample {
                    z: z.iter().map(|&v| v as f64).collect(),
                    targets: targets[i].clone(),
                })
            })
            .collect()
    };
    let samples_of = |encoder: &ExportedMlp, indices: &[usize]| -> candle_core::Result<Vec<LatentSample>> {
        let mut samples = encoded_of(encoder, indices)?;
        if settings.local > 0.0 {
            let mut rng = ChaCha8Rng::seed_from_u64(indices.first().map_or(0, |&i| i as u64));
            let nearby = local_neighbours(&samples, settings.local, settings.samples - samples.len(), &mut rng);
            samples.extend(nearby);
        }
        Ok(samples)
    };
    // The two losses at the start, on the first minibatch's worth of frames.
    let first: Vec<usize> = (0..data.count().min(config.batch_size)).collect();
    let exported = autoencoder.export().map_err(|e| TrainError::Invalid(e.to_string()))?;
    let start_samples = samples_of(&exported.encoder, &first)?;
    let invalid = |e: crate::learn::network::NetworkError| TrainError::Invalid(e.to_string());
    let (decoder, frozen) = (
        autoencoder.decoder().as_mlp().map_err(invalid)?,
        exported.decoder.as_mlp().map_err(invalid)?,
    );
    let hessians = term
        .hessians(frozen, &start_samples)
        .map_err(|e| TrainError::Invalid(e.to_string()))?;
    let ls0 = super::loss::lipschitz_loss(&hessians, &start_samples);
    let lc0 = train::mean_reconstruction_error(autoencoder, data, 256)?;
    let lambda = match settings.lambda {
        Some(lambda) => lambda,
        None if ls0 > 0.0 => settings.weight * lc0.max(settings.floor).max(1e-30) / ls0,
        None => 0.0,
    };

    let report = train::train(&autoencoder.parameters(), data, config, resume, |batch, _| {
        let reconstruction =
            Autoencoder::reconstruction_loss_of(&autoencoder.reconstruct(&batch.inputs)?, &batch.inputs)?;
        let exported = autoencoder.export().map_err(candle_err)?;
        let samples = samples_of(&exported.encoder, batch.indices)?;
        let frozen = exported.decoder.as_mlp().map_err(candle_err)?;
        let lip = if settings.resample > 0 {
            // One draw per minibatch, reproducible on a resumed run.
            let first = batch.indices.first().map_or(0, |&i| i as u64);
            let mut rng = ChaCha8Rng::seed_from_u64(((batch.epoch as u64) << 32) ^ first);
            rng.set_stream(11);
            let drawn = sampled_cubature(term.potentials, settings.resample, &mut rng).map_err(candle_err)?;
            let potentials: Vec<&dyn StencilEnergy> = drawn.iter().map(|e| e as &dyn StencilEnergy).collect();
            LipschitzTerm {
                potentials: &potentials,
                ..*term
            }
            .batch(decoder, None, frozen, &samples)
        } else {
            term.batch(decoder, None, frozen, &samples)
        }
        .map_err(candle_err)?;
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

/// `count` samples near the first of `samples` (cycling): each latent moved by `local`
/// times the samples' RMS spread about their mean, in a uniformly random direction.
fn local_neighbours(samples: &[LatentSample], local: f64, count: usize, rng: &mut ChaCha8Rng) -> Vec<LatentSample> {
    use rand::Rng;
    let Some(first) = samples.first() else {
        return Vec::new();
    };
    let r = first.z.len();
    let mean: Vec<f64> = (0..r)
        .map(|c| samples.iter().map(|s| s.z[c]).sum::<f64>() / samples.len() as f64)
        .collect();
    let spread = (samples
        .iter()
        .map(|s| s.z.iter().zip(&mean).map(|(z, m)| (z - m).powi(2)).sum::<f64>())
        .sum::<f64>()
        / samples.len() as f64)
        .sqrt()
        .max(1e-12);
    (0..count)
        .map(|i| {
            let base = &samples[i % samples.len()];
            // Box-Muller normals: their direction is uniform on the sphere.
            let dir: Vec<f64> = (0..r)
                .map(|_| {
                    let (u, v): (f64, f64) = (rng.random(), rng.random());
                    (-2.0 * (1.0 - u).ln()).sqrt() * (std::f64::consts::TAU * v).cos()
                })
                .collect();
            let norm = dir.iter().map(|v| v * v).sum::<f64>().sqrt().max(1e-12);
            LatentSample {
                z: base
                    .z
                    .iter()
                    .zip(&dir)
                    .map(|(z, d)| z + local * spread * d / norm)
                    .collect(),
                targets: base.targets.clone(),
            }
        })
        .collect()
}

/// Lipschitz optimisation of a data-free subspace (Eq. 10 with the construction loss of
/// Eq. 4): continues `model` in place for `iterations` Adam steps on the data-free objective
/// plus `lambda L_LS`, the Lipschitz samples being the first `settings.samples` latents of
/// each step's Gaussian batch (the pull-back distribution of a data-free subspace), decoded
/// with the handles at the start. `lambda` follows the module documentation, with `L_C`
/// the data-free loss of the first batch. Returns the total loss of every step and the
/// absolute `lambda`.
pub(crate) fn optimise_data_free(
    objective: &DataFreeObjective<'_>,
    model: &DataFreeModel,
    data_free: &DataFreeSettings,
    term: &LipschitzTerm<'_>,
    settings: &LipschitzSettings,
    iterations: usize,
    reporter: &dyn Reporter,
) -> TrainerResult<(Vec<f64>, f64)> {
    if settings.samples < 2 || settings.samples > data_free.batch {
        return Err(TrainerError::invalid(format!(
            "the Lipschitz term needs 2 to {} samples per step (the data-free batch), got {}",
            data_free.batch, settings.samples
        )));
    }
    let config = AdamWConfig {
        lr: data_free.learning_rate,
        ..AdamWConfig::default()
    };
    let mut optimizer = AdamW::new(&model.parameters(), config)?;
    let mut rng = ChaCha8Rng::seed_from_u64(data_free.seed);
    rng.set_stream(2);
    let samples_of = |z: &Tensor| -> TrainerResult<Vec<LatentSample>> {
        let rows = tensor_to_rows(z)?;
        Ok(rows
            .iter()
            .take(settings.samples)
            .map(|row| LatentSample {
                z: row.iter().map(|&v| v as f64).collect(),
                targets: objective.targets().to_vec(),
            })
            .collect())
    };
    let mut lambda = None;
    let mut losses = Vec::with_capacity(iterations);
    let bar = EpochsBar::new("lipschitz", iterations, 0, reporter.bars());
    for iteration in 0..iterations {
        let z = normal_latents(data_free.batch, data_free.latent, &mut rng)?;
        let terms = objective.batch(model, &z)?;
        let construction = terms.energy + data_free.lambda * terms.repulsion;
        let exported = model.export()?;
        let lip = term.batch(&model.mlp, Some(model.offset_row()), &exported, &samples_of(&z)?)?;
        let lambda = *lambda.get_or_insert_with(|| {
            if lip.loss > 0.0 {
                settings.weight * construction.abs().max(settings.floor).max(1e-30) / lip.loss
            } else {
                0.0
            }
        });
        let total = construction + lambda * lip.loss;
        if !total.is_finite() {
            return Err(TrainerError::invalid(format!(
                "Lipschitz optimisation: the loss is not finite at iteration {iteration}"
            )));
        }
        let objective_tensor = (terms.objective(data_free.lambda)? + lip.surrogate.affine(lambda, 0.0)?)?;
        optimizer.step(&objective_tensor.backward()?)?;
        losses.push(total);
        bar.epoch(total);
    }
    bar.finish();
    Ok((losses, lambda.unwrap_or(0.0)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each neighbour sits `local` times the samples' RMS spread from the sample it was
    /// moved from, with that sample's handle targets.
    #[test]
    fn local_neighbours_sit_at_the_asked_distance() {
        let samples: Vec<LatentSample> = (0..3)
            .map(|i| LatentSample {
                z: vec![i as f64, 2.0 * i as f64, -1.0],
                targets: vec![i as f64],
            })
            .collect();
        // Mean (1, 2, -1); squared distances 5, 0, 5: RMS spread sqrt(10 / 3).
        let spread = (10.0f64 / 3.0).sqrt();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let near = local_neighbours(&samples, 0.1, 5, &mut rng);
        assert_eq!(near.len(), 5);
        for (i, n) in near.iter().enumerate() {
            let base = &samples[i % 3];
            let d = squared(&n.z, &base.z).sqrt();
            assert!((d - 0.1 * spread).abs() < 1e-12, "neighbour {i} at {d}");
            assert_eq!(n.targets, base.targets);
        }
        assert_ne!(near[0].z, near[3].z, "two neighbours of one sample share a direction");
    }

    fn squared(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum()
    }
}
