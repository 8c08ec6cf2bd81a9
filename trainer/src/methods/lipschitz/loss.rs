//! The second-order Lipschitz loss of Lyu et al. 2024 (Eq. 9) and its gradient with respect
//! to the decoder's weights.
//!
//! For latent samples `z_1..z_B` (held fixed: they are draws from the pull-back
//! distribution), with `H_i = s d^2/dz^2 P~(f(z_i))` the subspace Hessian of the
//! (cubature-approximated) potential at sample `i`,
//!
//! ```text
//! L = 1/(B (B-1)) sum_{i != j} |H_i - H_j|_F^2 / |z_i - z_j|^2
//! ```
//!
//! # The gradient
//!
//! candle differentiates once, so the second derivatives inside `H_i` are written out:
//! `G_i = dL/dH_i = 4/(B (B-1)) sum_{j != i} (H_i - H_j) / |z_i - z_j|^2` is symmetric, with
//! eigenpairs `(l_k, v_k)`, and `<G_i, H_i> = sum_k l_k v_k^T H_i v_k`, where
//! `v^T H v / s = xd^T H_x xd + g^T xdd` for the tangent `xd = J v` and the curvature
//! `xdd = d^2/dt^2 f(z + t v)` of the decoded state `x = f(z)`, `g = dP/dx`, `H_x = d^2P/dx^2`.
//! Differentiating in the weights `theta` (through `x`, `xd` and `xdd`):
//!
//! ```text
//! d(v^T H v)/dtheta / s = 2 (H_x xd)^T dxd/dtheta + g^T dxdd/dtheta
//!                       + (D^3P[xd, xd, .] + H_x xdd)^T dx/dtheta
//! ```
//!
//! so the gradient of `L` is that of the surrogate
//! `S = sum_i sum_k l_k s [<xd_ik, c1> + <xdd_ik, c2> + <x_i, c3>]` with the bracketed
//! physics vectors `c1 = 2 H_x xd`, `c2 = g`, `c3 = D^3P[xd, xd, .] + H_x xdd` held constant.
//! `x`, `xd` and `xdd` come from a candle jet of the decoder (forward mode written as candle
//! ops, differentiable in the weights); the physics vectors from the scene's stencil kernels
//! ([`super::physics`]), pulled back to the encoded layout by the frame's rotation.

use candle_core::{Device, Tensor};
use mochi_sim::energy::StencilEnergy;
use nalgebra::DMatrix;
use rayon::prelude::*;

use super::physics::PotentialAt;
use crate::error::{TrainerError, TrainerResult};
use crate::learn::encoding::Encoding;
use crate::learn::network::jet::jet;
use crate::learn::network::{ExportedMlp, ResMlp};
use crate::methods::reduced::objective::{ObjectiveBuffers, ReducedObjective};
use crate::methods::reduced::subspace::DecoderSubspace;

/// One latent sample and the handle placement it is decoded with.
#[derive(Clone, Debug, PartialEq)]
pub struct LatentSample {
    /// The latent.
    pub z: Vec<f64>,
    /// The handle targets (`dim` per prescribed vertex).
    pub targets: Vec<f64>,
}

/// The Lipschitz term of one scene: its encoding, the potential whose subspace Hessian is
/// regularised, and the objective's scale.
pub struct LipschitzTerm<'a> {
    /// The scene's encoding (the decoders' output layout).
    pub encoding: &'a Encoding,
    /// The potential `P~` (usually cubature approximations of the elastic terms).
    pub potentials: &'a [&'a dyn StencilEnergy],
    /// The scale `s` of the reduced objective (see [`crate::methods::reduced::stepper`]).
    pub scale: f64,
    /// The rest diagonal: sets the step of the third-derivative difference.
    pub diagonal: f64,
}

/// The loss's value and the surrogate whose weight gradient is the loss's.
pub struct LipschitzBatch {
    /// `L` (Eq. 9).
    pub loss: f64,
    /// The surrogate `S` (module documentation): a candle scalar.
    pub surrogate: Tensor,
}

/// One sample's share of the surrogate's constants: the eigenvectors of `G_i` (`r x r`, one
/// per row) and the physics vectors `c1`, `c2` (`r x q_len`, one row per eigenvector) and
/// `c3` (`q_len`), each already weighted by its eigenvalue.
struct SampleConstants {
    directions: Vec<f32>,
    c1: Vec<f32>,
    c2: Vec<f32>,
    c3: Vec<f32>,
}

/// A subspace Hessian with the decoded state `x = f(z)` and the Jacobian `df/dz`
/// (`n x r`, row-major) at its sample.
struct HessianAt {
    hessian: DMatrix<f64>,
    positions: Vec<f64>,
    jacobian: Vec<f64>,
}

impl LipschitzTerm<'_> {
    /// The subspace Hessians `H_i` (`r x r`) of the frozen `decoder` at `samples`.
    ///
    /// Samples are independent: they are split into one chunk per worker thread (rayon), each
    /// with its own copy of the subspace, and come back in order.
    pub fn hessians(&self, decoder: &ExportedMlp, samples: &[LatentSample]) -> TrainerResult<Vec<DMatrix<f64>>> {
        self.hessians_with(decoder, samples, |hessian, _| hessian)
    }

    /// [`LipschitzTerm::hessians`], each with the decoded state and the decoder Jacobian it
    /// was computed from (the surrogate's constants need them again).
    fn hessians_at(&self, decoder: &ExportedMlp, samples: &[LatentSample]) -> TrainerResult<Vec<HessianAt>> {
        self.hessians_with(decoder, samples, |hessian, objective| HessianAt {
            hessian,
            positions: objective.positions().to_vec(),
            jacobian: objective.jacobian().to_vec(),
        })
    }

    /// What `keep` makes of each sample's subspace Hessian and the objective it was computed
    /// in, in sample order.
    fn hessians_with<T: Send>(
        &self,
        decoder: &ExportedMlp,
        samples: &[LatentSample],
        keep: impl Fn(DMatrix<f64>, &ReducedObjective) -> T + Sync,
    ) -> TrainerResult<Vec<T>> {
        let Some(first) = samples.first() else {
            return Ok(Vec::new());
        };
        let subspace = DecoderSubspace::new(decoder, self.encoding, &first.targets)?;
        per_sample(&subspace, samples, |subspace, s| {
            let r = subspace.latent_len();
            let mut buffers = ObjectiveBuffers::new(subspace.state_len(), r);
            subspace.set_frame(&self.encoding.frame(&s.targets)?, &s.targets);
            let mut objective = ReducedObjective::new(subspace, self.potentials, None, self.scale, &mut buffers);
            let (mut grad, mut hess) = (vec![0.0; r], vec![0.0; r * r]);
            objective.exact_hessian(&s.z, &mut grad, &mut hess)?;
            Ok(keep(DMatrix::from_row_slice(r, r, &hess), &objective))
        })
    }

    /// The loss and its surrogate for the trainable decoder `mlp` (plus a constant output
    /// `offset`, if any), whose frozen form (offset folded in) is `exported`.
    pub(crate) fn batch(
        &self,
        mlp: &ResMlp,
        offset: Option<&Tensor>,
        exported: &ExportedMlp,
        samples: &[LatentSample],
    ) -> TrainerResult<LipschitzBatch> {
        if samples.len() < 2 {
            return Err(TrainerError::invalid("the Lipschitz loss needs at least two samples"));
        }
        let at_samples = self.hessians_at(exported, samples)?;
        let hessians: Vec<DMatrix<f64>> = at_samples.iter().map(|h| h.hessian.clone()).collect();
        let loss = lipschitz_loss(&hessians, samples);
        let weights = loss_gradients(&hessians, samples);
        let subspace = DecoderSubspace::new(exported, self.encoding, &samples[0].targets)?;
        let (b, r, q_len) = (samples.len(), subspace.latent_len(), self.encoding.encoded_len());
        let items: Vec<_> = samples.iter().zip(&weights).zip(&at_samples).collect();
        let constants = per_sample(&subspace, &items, |subspace, &((s, weight), state)| {
            self.sample_constants(subspace, s, weight, state)
        })?;
        let mut directions = Vec::with_capacity(b * r * r);
        let (mut c1, mut c2, mut c3) = (
            Vec::with_capacity(b * r * q_len),
            Vec::with_capacity(b * r * q_len),
            Vec::with_capacity(b * q_len),
        );
        for c in constants {
            directions.extend(c.directions);
            c1.extend(c.c1);
            c2.extend(c.c2);
            c3.extend(c.c3);
        }
        let dev = Device::Cpu;
        let z: Vec<f32> = samples.iter().flat_map(|s| s.z.iter().map(|&v| v as f32)).collect();
        let jet = jet(
            mlp,
            &Tensor::from_vec(z, (b, r), &dev)?,
            &Tensor::from_vec(directions, (b, r, r), &dev)?,
        )?;
        let value = match offset {
            Some(o) => jet.value.broadcast_add(o)?,
            None => jet.value,
        };
        let surrogate = ((jet.tangent * Tensor::from_vec(c1, (b, r, q_len), &dev)?)?.sum_all()?
            + (jet.curvature * Tensor::from_vec(c2, (b, r, q_len), &dev)?)?.sum_all()?)?
        .add(&(value * Tensor::from_vec(c3, (b, q_len), &dev)?)?.sum_all()?)?;
        Ok(LipschitzBatch { loss, surrogate })
    }

    /// The surrogate's constants at sample `s` whose loss gradient `dL/dH` is `weight`, with
    /// the state and Jacobian there (`state`).
    fn sample_constants(
        &self,
        subspace: &mut DecoderSubspace,
        s: &LatentSample,
        weight: &DMatrix<f64>,
        state: &HessianAt,
    ) -> TrainerResult<SampleConstants> {
        let (r, n, q_len) = (subspace.latent_len(), subspace.state_len(), self.encoding.encoded_len());
        let mut out = SampleConstants {
            directions: Vec::with_capacity(r * r),
            c1: vec![0f32; r * q_len],
            c2: vec![0f32; r * q_len],
            c3: vec![0f32; q_len],
        };
        let (x, jac) = (&state.positions, &state.jacobian);
        let (mut xd, mut xdd) = (vec![0.0; n], vec![0.0; n]);
        let (mut hxd, mut hxdd, mut third) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let mut pulled = vec![0.0; q_len];
        subspace.set_frame(&self.encoding.frame(&s.targets)?, &s.targets);
        let at = PotentialAt::new(self.potentials, subspace.dim(), x);
        let eig = weight.clone().symmetric_eigen();
        for k in 0..r {
            let v: Vec<f64> = eig.eigenvectors.column(k).iter().copied().collect();
            let l = eig.eigenvalues[k] * self.scale;
            out.directions.extend(v.iter().map(|&c| c as f32));
            for (row, out) in jac.chunks_exact(r).zip(xd.iter_mut()) {
                *out = row.iter().zip(&v).map(|(a, b)| a * b).sum();
            }
            subspace.second_directional(&s.z, &v, &mut xdd)?;
            at.hessian_times(&xd, &mut hxd);
            at.hessian_times(&xdd, &mut hxdd);
            let top = xd.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let h = if top > 0.0 { 1e-4 * self.diagonal / top } else { 1.0 };
            at.third_times(&xd, h, &mut third);
            let row = k * q_len..(k + 1) * q_len;
            subspace.pull_back(&hxd, &mut pulled)?;
            fill(&mut out.c1[row.clone()], &pulled, 2.0 * l);
            subspace.pull_back(&at.grad, &mut pulled)?;
            fill(&mut out.c2[row], &pulled, l);
            third.iter_mut().zip(&hxdd).for_each(|(t, h)| *t += h);
            subspace.pull_back(&third, &mut pulled)?;
            add(&mut out.c3, &pulled, l);
        }
        Ok(out)
    }
}

/// `work` on every item, in order, split into one chunk per rayon worker, each chunk with its
/// own copy of `subspace` (the per-sample work of the loss is independent and the subspace
/// holds the only mutable state, so results do not depend on the thread count).
fn per_sample<T: Sync, R: Send>(
    subspace: &DecoderSubspace,
    items: &[T],
    work: impl Fn(&mut DecoderSubspace, &T) -> TrainerResult<R> + Sync,
) -> TrainerResult<Vec<R>> {
    let chunk = items.len().div_ceil(rayon::current_num_threads().max(1)).max(1);
    let chunks: Vec<TrainerResult<Vec<R>>> = items
        .par_chunks(chunk)
        .map(|chunk| {
            let mut own = subspace.clone();
            chunk.iter().map(|item| work(&mut own, item)).collect()
        })
        .collect();
    let mut out = Vec::with_capacity(items.len());
    for c in chunks {
        out.extend(c?);
    }
    Ok(out)
}

fn fill(out: &mut [f32], v: &[f64], scale: f64) {
    out.iter_mut().zip(v).for_each(|(o, v)| *o = (scale * v) as f32);
}

fn add(out: &mut [f32], v: &[f64], scale: f64) {
    out.iter_mut().zip(v).for_each(|(o, v)| *o += (scale * v) as f32);
}

fn squared_distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum()
}

/// Eq. 9: the mean over ordered pairs of distinct samples of `|H_i - H_j|_F^2 / |z_i - z_j|^2`
/// (pairs of coincident latents are skipped).
pub fn lipschitz_loss(hessians: &[DMatrix<f64>], samples: &[LatentSample]) -> f64 {
    let b = samples.len();
    if b < 2 {
        return 0.0;
    }
    let mut sum = 0.0;
    for i in 0..b {
        for j in 0..b {
            let d2 = squared_distance(&samples[i].z, &samples[j].z);
            if i != j && d2 > 0.0 {
                sum += (&hessians[i] - &hessians[j]).norm_squared() / d2;
            }
        }
    }
    sum / (b * (b - 1)) as f64
}

/// `dL/dH_i` for every sample (module documentation).
fn loss_gradients(hessians: &[DMatrix<f64>], samples: &[LatentSample]) -> Vec<DMatrix<f64>> {
    let b = samples.len();
    let norm = 4.0 / (b * (b - 1)) as f64;
    (0..b)
        .map(|i| {
            let mut g = DMatrix::zeros(hessians[i].nrows(), hessians[i].ncols());
            for j in 0..b {
                let d2 = squared_distance(&samples[i].z, &samples[j].z);
                if i != j && d2 > 0.0 {
                    g += (&hessians[i] - &hessians[j]) * (norm / d2);
                }
            }
            g
        })
        .collect()
}

/// Eq. 7: the largest `|H_i - H_j|_F / |z_i - z_j|` over pairs of distinct samples, the
/// estimate of `Lip[d^2 P / dz^2]` reported for every subspace.
pub fn lipschitz_estimate(hessians: &[DMatrix<f64>], samples: &[LatentSample]) -> f64 {
    let mut best = 0.0f64;
    for i in 0..samples.len() {
        for j in i + 1..samples.len() {
            let d2 = squared_distance(&samples[i].z, &samples[j].z);
            if d2 > 0.0 {
                best = best.max((&hessians[i] - &hessians[j]).norm() / d2.sqrt());
            }
        }
    }
    best
}

/// The RMS distance of the samples' latents from their mean: the subspace's latent scale.
///
/// Eq. 7 depends on that scale: a decoder stretched along its latent, `f(z / a)` (with the
/// encoder `a g(x)`), has the same image and the same solves, `a` times the spread and `a^3`
/// times less `Lip`. `Lip * spread^3` compares subspaces whatever their latent scale.
pub fn latent_spread(samples: &[LatentSample]) -> f64 {
    let Some(first) = samples.first() else {
        return 0.0;
    };
    let count = samples.len() as f64;
    let mean: Vec<f64> = (0..first.z.len())
        .map(|k| samples.iter().map(|s| s.z[k]).sum::<f64>() / count)
        .collect();
    (samples.iter().map(|s| squared_distance(&s.z, &mean)).sum::<f64>() / count).sqrt()
}

/// The median over `hessians` of the condition number `max |l| / min |l|` of each (infinite
/// where an eigenvalue is zero; NaN without Hessians): how far the subspace objective is from
/// a round bowl, which L-BFGS iterations grow with. It does not depend on the latent scale.
pub fn median_condition(hessians: &[DMatrix<f64>]) -> f64 {
    let mut conditions: Vec<f64> = hessians
        .iter()
        .map(|h| {
            let magnitudes = h.symmetric_eigenvalues().map(f64::abs);
            magnitudes.max() / magnitudes.min()
        })
        .collect();
    conditions.sort_by(f64::total_cmp);
    conditions.get(conditions.len() / 2).copied().unwrap_or(f64::NAN)
}
