//! The supervised baseline's objective: the same integrator trained on ground-truth latents,
//! with the same input augmentation as the self-supervised one.

use candle_core::{Device, Tensor};
use rand_chacha::ChaCha8Rng;

use crate::learn::network::{tensor_to_rows, LatentIntegrator};
use crate::learn::samples::{perturbed, rolled_inputs, to_tensor, Augmentation, IntegratorData, SampleRef};
use crate::learn::train::{Batch, BatchLoss};

/// The supervised baseline's objective: squared error of the predicted latent against the
/// ground truth, per coordinate in units of the increment's standard deviation.
pub struct SupervisedObjective<'a> {
    data: &'a IntegratorData<'a>,
    augmentation: Augmentation,
    scale: Tensor,
}

impl<'a> SupervisedObjective<'a> {
    /// The objective on `data`, with the same input augmentation as the physics one.
    pub fn new(data: &'a IntegratorData<'a>, augmentation: Augmentation) -> candle_core::Result<Self> {
        let inv: Vec<f32> = data.increment_norm.std.iter().map(|s| 1.0 / s).collect();
        let scale = Tensor::from_vec(inv, (1, data.latent), &Device::Cpu)?;
        Ok(SupervisedObjective {
            data,
            augmentation,
            scale,
        })
    }

    /// Objective of one minibatch.
    pub fn batch_loss(
        &self,
        integrator: &LatentIntegrator,
        batch: &Batch<'_>,
        rng: &mut ChaCha8Rng,
    ) -> candle_core::Result<BatchLoss> {
        let k = self.data.latent;
        let clean = tensor_to_rows(&batch.inputs)?;
        let samples: Vec<SampleRef> = batch.indices.iter().map(|&i| self.data.samples[i]).collect();
        let truth_of = |s: &SampleRef| self.data.latents[s.sequence][s.frame].clone();
        let mut rows = clean.clone();
        let mut truth: Vec<Vec<f32>> = samples.iter().map(truth_of).collect();
        let augmentation = self.augmentation;
        if augmentation.noise > 0.0 {
            rows.extend(perturbed(&clean, k, augmentation.noise, rng));
            truth.extend(truth.clone());
        }
        let limit = augmentation.rollout_at(batch.epoch);
        if limit > 0 {
            let (kept, rolled) = rolled_inputs(self.data, integrator, &samples, limit, rng)?;
            rows.extend(rolled);
            truth.extend(kept.iter().map(truth_of));
        }
        let refs: Vec<&[f32]> = rows.iter().map(Vec::as_slice).collect();
        let truth_refs: Vec<&[f32]> = truth.iter().map(Vec::as_slice).collect();
        let z = integrator.forward(&to_tensor(&refs, rows[0].len())?)?;
        let target = to_tensor(&truth_refs, k)?;
        let objective = (z - target)?.broadcast_mul(&self.scale)?.sqr()?.mean_all()?;
        BatchLoss::new(objective)
    }
}
