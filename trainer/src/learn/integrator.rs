//! The self-supervised objective of the latent integrator (Li et al. 2025, Sec. 3.3): the
//! full-space incremental potential of the decoded prediction (Eq. 4) on clean, noisy (Eq. 5)
//! and rolled-out inputs, each sample weighted by data balancing (Eq. 6).
//!
//! The physics gradient meets candle at the decoded state (DESIGN.md, decision 2): the
//! simulator's energies give `g = dE/dx` in f64; the objective handed to backpropagation is
//! `sum(q * stopgrad(R^T g))` over the decoded encoded state `q = D(I(...))`, whose gradient
//! with respect to the integrator's weights is exactly `(dE/dx)^T dx/dtheta`.

use candle_core::{Device, Tensor};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::learn::encoding::decode_world;
use crate::learn::loss::{ColliderContact, PhysicsLoss};
use crate::learn::network::{tensor_to_rows, Autoencoder, LatentIntegrator};
use crate::learn::samples::{candle_err, perturbed, rolled_inputs, to_tensor, Augmentation, IntegratorData, SampleRef};
use crate::learn::train::{Batch, BatchLoss};
use mochi_sim::{BuiltScene, InputError};

/// The self-supervised objective (Eq. 4-6) on minibatches of [`IntegratorData`].
pub struct PhysicsObjective<'a> {
    data: &'a IntegratorData<'a>,
    ae: &'a Autoencoder,
    losses: Vec<PhysicsLoss>,
    augmentation: Augmentation,
    min_speed: f64,
    scene_dt: f64,
}

impl<'a> PhysicsObjective<'a> {
    /// The objective of `problem`'s body with penalty weight `bc_weight` (Eq. 4), input
    /// augmentation `augmentation` (Eq. 5) and balancing floor `min_speed` (Eq. 6).
    pub fn new(
        problem: &BuiltScene,
        data: &'a IntegratorData<'a>,
        ae: &'a Autoencoder,
        augmentation: Augmentation,
        bc_weight: f64,
        min_speed: f64,
    ) -> Result<Self, InputError> {
        let colliders = (data.colliders > 0).then(|| collider_contact(problem)).flatten();
        let losses = (0..rayon::current_num_threads().max(1))
            .map(|_| {
                let loss = PhysicsLoss::new(&problem.scene, &problem.mesh, &problem.handles, Some(bc_weight))?;
                Ok(match &colliders {
                    Some(c) => loss.with_colliders(c.clone()),
                    None => loss,
                })
            })
            .collect::<Result<Vec<_>, InputError>>()?;
        Ok(PhysicsObjective {
            data,
            ae,
            losses,
            augmentation,
            min_speed,
            scene_dt: problem.scene.dt,
        })
    }

    /// Decoded world-space `(x_{t-1}, x_{t-2})` of packed `rows` predicting `samples`.
    fn decoded_previous(
        &self,
        rows: &[Vec<f32>],
        samples: &[SampleRef],
    ) -> candle_core::Result<Vec<(Vec<f64>, Vec<f64>)>> {
        let (data, k) = (self.data, self.data.latent);
        let z1: Vec<&[f32]> = rows.iter().map(|r| &r[..k]).collect();
        let z2: Vec<&[f32]> = rows.iter().map(|r| &r[k..2 * k]).collect();
        let q1 = tensor_to_rows(&self.ae.decoder().forward_frozen(&to_tensor(&z1, k)?)?)?;
        let q2 = tensor_to_rows(&self.ae.decoder().forward_frozen(&to_tensor(&z2, k)?)?)?;
        samples
            .iter()
            .enumerate()
            .map(|(i, s)| {
                let seq = &data.sequences[s.sequence];
                let world = |q: &[f32], f: usize| decode_world(data.encoding, q, &seq.frames[f], &seq.targets[f]);
                let prev = world(&q1[i], s.frame - 1).map_err(candle_err)?;
                let prev2 = world(&q2[i], s.prev2()).map_err(candle_err)?;
                Ok((prev, prev2))
            })
            .collect()
    }

    /// The surrogate objective and the mean balanced loss of one minibatch (clean samples,
    /// then as many perturbed ones when noise is on, then rolled-out ones when rollout
    /// augmentation is on).
    pub fn batch_loss(
        &mut self,
        integrator: &LatentIntegrator,
        batch: &Batch<'_>,
        rng: &mut ChaCha8Rng,
    ) -> candle_core::Result<BatchLoss> {
        let data = self.data;
        let k = data.latent;
        let clean = tensor_to_rows(&batch.inputs)?;
        let samples: Vec<SampleRef> = batch.indices.iter().map(|&i| data.samples[i]).collect();
        // Previous states for the inertia term: the decoded inputs themselves (decoded per
        // batch, so no decoded frame is held between batches).
        let mut prevs = self.decoded_previous(&clean, &samples)?;
        let mut rows = clean.clone();
        let mut all_samples = samples.clone();
        let augmentation = self.augmentation;
        if augmentation.noise > 0.0 {
            let noisy = perturbed(&clean, k, augmentation.noise, rng);
            prevs.extend(self.decoded_previous(&noisy, &samples)?);
            rows.extend(noisy);
            all_samples.extend(samples.iter().copied());
        }
        let limit = augmentation.rollout_at(batch.epoch);
        if limit > 0 {
            let (kept, rolled) = rolled_inputs(data, integrator, &samples, limit, rng)?;
            prevs.extend(self.decoded_previous(&rolled, &kept)?);
            rows.extend(rolled);
            all_samples.extend(kept);
        }
        let refs: Vec<&[f32]> = rows.iter().map(Vec::as_slice).collect();
        let inputs = to_tensor(&refs, rows[0].len())?;
        let z = integrator.forward(&inputs)?;
        let q = self.ae.decoder().forward_frozen(&z)?;
        let q_rows = tensor_to_rows(&q)?;
        let (m, n) = (q_rows.len(), data.encoding.encoded_len());
        // One sample per thread: each worker has its own copy of the loss (its inertia and
        // penalty targets change per sample), and results are gathered in sample order.
        let per_worker = m.div_ceil(self.losses.len());
        let (min_speed, scene_dt) = (self.min_speed, self.scene_dt);
        let parts: Vec<Result<(f64, Vec<f32>), String>> = self
            .losses
            .par_iter_mut()
            .enumerate()
            .map(|(w, loss)| {
                let range = (w * per_worker).min(m)..((w + 1) * per_worker).min(m);
                let mut total = 0.0;
                let mut g = vec![0.0f32; range.len() * n];
                let mut grad = vec![0.0; data.encoding.state_len()];
                let mut x = vec![0.0; data.encoding.state_len()];
                let mut q = vec![0.0; n];
                let mut local = vec![0.0; n];
                for (row, i) in range.enumerate() {
                    let s = all_samples[i];
                    let (frame, targets) = data.step(s);
                    for (q, &v) in q.iter_mut().zip(&q_rows[i]) {
                        *q = v as f64;
                    }
                    data.encoding
                        .decode_into(&q, frame, targets, &mut x)
                        .map_err(|e| e.to_string())?;
                    let (prev, prev2) = &prevs[i];
                    let dt = data.sequences[s.sequence].trajectory.dt;
                    loss.set_dt(dt);
                    let (previous, current) = data.collider_poses(s);
                    loss.set_collider_poses(&previous, &current);
                    let value = loss.value_and_gradient(&x, prev, prev2, targets, &mut grad);
                    // A sample at another frame time is weighted by dt / scene dt. The loss
                    // times dt^2 is the solver's own objective, whose curvature (M + dt^2 K) is
                    // about the mass matrix at every rate; one factor of dt / scene dt more
                    // would make a position error cost the same at every rate, but a 120 Hz
                    // step's error recurs four times as often per second of motion as a 30 Hz
                    // one's. This weight lets it cost four times as much (docs/design.md,
                    // decision 10).
                    let balance = loss.balance(prev, prev2, min_speed) / (dt / scene_dt);
                    total += value / balance;
                    data.encoding
                        .encode_gradient(&q, &grad, frame, balance, &mut local)
                        .map_err(|e| e.to_string())?;
                    for (out, l) in g[row * n..(row + 1) * n].iter_mut().zip(&local) {
                        *out = *l as f32;
                    }
                }
                Ok((total, g))
            })
            .collect();
        let mut total = 0.0;
        let mut g = Vec::with_capacity(m * n);
        for part in parts {
            let (t, rows) = part.map_err(candle_core::Error::Msg)?;
            total += t;
            g.extend(rows);
        }
        let g = Tensor::from_vec(g, (m, n), &Device::Cpu)?;
        let objective = ((q * g)?.sum_all()? / m as f64)?;
        Ok(BatchLoss {
            objective,
            value: total / m as f64,
        })
    }
}

/// The colliders' part of the physics loss of `problem`'s body: the simulator's collider
/// barrier at the stiffest stiffness its solver uses, with the scene's friction; `None`
/// without colliders.
pub(crate) fn collider_contact(problem: &BuiltScene) -> Option<ColliderContact> {
    let barrier = problem.simulator.collider_barrier()?.clone();
    let (_, kappa) = problem.simulator.barrier_stiffness_range()?;
    let contact = problem.scene.contact.as_ref()?;
    let friction = (contact.friction > 0.0).then_some((contact.friction, contact.epsv));
    (!barrier.colliders().is_empty()).then(|| ColliderContact::new(barrier, kappa, friction))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::network::rows_to_tensor;
    use crate::learn::samples::fixtures::{tiny_beam, tiny_integrator};
    use rand::SeedableRng;

    /// The surrogate objective's gradient with respect to an integrator weight equals the
    /// derivative of the balanced physics loss itself (central finite difference).
    #[test]
    fn surrogate_gradient_matches_finite_difference_of_the_loss() {
        let beam = tiny_beam();
        let (problem, ae, data) = (&beam.problem, &beam.ae, beam.data());
        let integrator = tiny_integrator(&data);
        let mut objective = PhysicsObjective::new(problem, &data, ae, Augmentation::NONE, 1e5, 1e-3).unwrap();
        let indices: Vec<usize> = (2..10).collect();
        let rows: Vec<&[f32]> = indices.iter().map(|&i| data.inputs[i].as_slice()).collect();
        let batch = Batch {
            inputs: rows_to_tensor(&rows, data.inputs[0].len()).unwrap(),
            indices: &indices,
            epoch: 0,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let loss = objective.batch_loss(&integrator, &batch, &mut rng).unwrap();
        let grads = loss.objective.backward().unwrap();
        let params = integrator.parameters();
        let mut checked = 0;
        for (name, var) in &params {
            if !(name.ends_with("output.bias") || name.ends_with("input.weight")) {
                continue;
            }
            let g = grads.get(var.as_tensor()).unwrap().flatten_all().unwrap();
            let g = g.to_vec1::<f32>().unwrap();
            let original = var.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap();
            for idx in [0, original.len() / 2] {
                let h = 1e-2f32;
                let mut value_at = |delta: f32| {
                    let mut w = original.clone();
                    w[idx] += delta;
                    var.set(&Tensor::from_vec(w, var.as_tensor().shape(), &Device::Cpu).unwrap())
                        .unwrap();
                    objective.batch_loss(&integrator, &batch, &mut rng).unwrap().value
                };
                let fd = (value_at(h) - value_at(-h)) / (2.0 * h as f64);
                value_at(0.0);
                let analytic = g[idx] as f64;
                let scale = fd.abs().max(analytic.abs()).max(1e-3);
                assert!(
                    (fd - analytic).abs() <= 2e-2 * scale,
                    "{name}[{idx}]: surrogate {analytic:.6e}, finite difference {fd:.6e}"
                );
                checked += 1;
            }
        }
        assert_eq!(checked, 4);
    }
}
