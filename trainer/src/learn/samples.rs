//! The integrator's training set (one sample per predicted frame, packed from ground-truth
//! latents) and the augmentation of its inputs shared by both objectives: noise on the input
//! latents (Eq. 5) and rollouts of the integrator's own predictions.

use candle_core::Tensor;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use crate::learn::encoding::{collider_inputs, pack_signals, Encoding, Frame};
use crate::learn::frame_rows::Rows;
use crate::learn::network::{
    network_inputs, rows_to_tensor, tensor_to_rows, Autoencoder, LatentIntegrator, Normalisation,
};
use crate::learn::sequences::EncodedSequence;
use mochi_sim::bc::SIGNAL_PER_HANDLE;
use mochi_sim::contact::ColliderPose;
use mochi_sim::BuiltScene;

/// Where a training sample of the integrator comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SampleRef {
    /// Sequence.
    pub sequence: usize,
    /// Predicted frame `t` (at least 1; frame `t - 2` is clamped to 0 at the start, where
    /// the body is at rest).
    pub frame: usize,
}

impl SampleRef {
    pub(crate) fn prev2(&self) -> usize {
        self.frame.saturating_sub(2)
    }
}

/// The integrator's training set: packed inputs from ground-truth latents, the targets and
/// frames of every predicted step, and the decoded previous states the inertia term needs.
pub struct IntegratorData<'a> {
    /// Encoded sequences.
    pub sequences: &'a [EncodedSequence],
    /// Latent size.
    pub latent: usize,
    /// Boundary-condition numbers per frame.
    pub bc_len: usize,
    /// Ground-truth latents `E(q)` per sequence and frame.
    pub latents: Vec<Vec<Vec<f32>>>,
    /// One sample per predicted frame.
    pub samples: Vec<SampleRef>,
    /// Run-time collider slots the integrator reads (0: none, or a model trained without
    /// collider inputs).
    pub colliders: usize,
    /// The collider slots' inputs per sequence and frame (empty rows without slots).
    pub collider_inputs: Vec<Vec<Vec<f32>>>,
    /// Packed inputs `[z_{t-1}, z_{t-2}, p_t, p_{t-1}, p_{t-2}]` (then collider inputs and
    /// the frame time, as the integrator takes them), one per sample.
    pub inputs: Vec<Vec<f32>>,
    /// Normalisation of the packed inputs.
    pub input_norm: Normalisation,
    /// Normalisation of the ground-truth increments `z_t - z_{t-1}`.
    pub increment_norm: Normalisation,
    /// Per latent coordinate, smallest and largest training value.
    pub latent_range: (Vec<f32>, Vec<f32>),
    /// Whether the integrator takes the frame time as an input (the scene's dataset spans a
    /// range of frame rates, `dataset.frame_rates`).
    pub timed: bool,
    /// The scene's frame time, to which a timed integrator's increments are scaled.
    pub reference_dt: f64,
    pub(crate) encoding: &'a Encoding,
}

/// Why the integrator's samples could not be made.
#[derive(Debug, thiserror::Error)]
pub enum SamplesError {
    /// candle failed encoding or decoding the frames.
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
    /// The network refused the frames.
    #[error(transparent)]
    Network(#[from] crate::learn::network::NetworkError),
    /// A decoded frame could not be placed in the world.
    #[error(transparent)]
    Encoding(#[from] crate::learn::encoding::EncodingError),
    /// The training frames could not be read back from their file.
    #[error("reading the training frames back: {0}")]
    Read(#[from] std::io::Error),
    /// A sequence's boundary-condition signal does not fit the scene's handles.
    #[error("training sequence {sequence} has {got} boundary-condition numbers per frame, the scene has {expected}")]
    SignalLength {
        /// The sequence's index.
        sequence: usize,
        /// Numbers per frame in the sequence.
        got: usize,
        /// Numbers per frame the scene's handles give.
        expected: usize,
    },
}

impl<'a> IntegratorData<'a> {
    /// Encodes every frame with `ae` and packs one sample per predicted frame, with the
    /// states of `colliders` collider slots (the scene's colliders, or 0 for a model without
    /// collider inputs). `rows` are the encoded frames of `sequences`, sequence after
    /// sequence, read a block at a time.
    pub fn new(
        problem: &BuiltScene,
        encoding: &'a Encoding,
        ae: &Autoencoder,
        sequences: &'a [EncodedSequence],
        rows: &dyn Rows,
        colliders: usize,
    ) -> Result<Self, SamplesError> {
        let k = ae.spec().latent;
        let bc_len = SIGNAL_PER_HANDLE * problem.handles.len();
        let timed = problem.scene.dataset.frame_rates.is_some();
        let reference_dt = problem.scene.dt;
        let mut latents = Vec::new();
        let mut first = 0;
        let width = encoding.encoded_len();
        for seq in sequences {
            let indices: Vec<usize> = (first..first + seq.frames.len()).collect();
            first += seq.frames.len();
            let mut z_seq = Vec::new();
            for chunk in indices.chunks(256) {
                let mut flat = Vec::with_capacity(chunk.len() * width);
                rows.gather_f32(chunk, &mut flat)?;
                let x = Tensor::from_vec(flat, (chunk.len(), width), &candle_core::Device::Cpu)?;
                z_seq.extend(tensor_to_rows(&ae.encode(&x)?)?);
            }
            latents.push(z_seq);
        }
        let diagonal = problem.mesh.rest_diagonal();
        let dim = encoding.dim();
        let touch: Vec<Vec<Vec<f32>>> = sequences
            .iter()
            .map(|seq| {
                (0..seq.frames.len())
                    .map(|t| {
                        let states = seq.trajectory.colliders.as_ref().map_or(&[][..], |c| &c.states[t][..]);
                        collider_inputs(colliders, &seq.frames[t], &seq.targets[t], dim, diagonal, states)
                    })
                    .collect()
            })
            .collect();
        let mut samples = Vec::new();
        let mut inputs = Vec::new();
        let mut increments = Vec::new();
        for (s, seq) in sequences.iter().enumerate() {
            if seq.trajectory.bc_signal.first().map_or(0, Vec::len) != bc_len {
                return Err(SamplesError::SignalLength {
                    sequence: s,
                    got: seq.trajectory.bc_signal.first().map_or(0, Vec::len),
                    expected: bc_len,
                });
            }
            for t in 1..seq.frames.len() {
                let sample = SampleRef { sequence: s, frame: t };
                inputs.push(pack(
                    &latents[s][t - 1],
                    &latents[s][sample.prev2()],
                    &seq.trajectory.bc_signal,
                    &touch[s][t],
                    t,
                    timed.then_some(seq.trajectory.dt),
                ));
                // A timed integrator's increments scale with the frame time: its network
                // predicts them at the scene's.
                let scale = if timed {
                    (seq.trajectory.dt / reference_dt) as f32
                } else {
                    1.0
                };
                increments.push(
                    latents[s][t]
                        .iter()
                        .zip(&latents[s][t - 1])
                        .map(|(a, b)| (a - b) / scale)
                        .collect(),
                );
                samples.push(sample);
            }
        }
        let mut lo = vec![f32::INFINITY; k];
        let mut hi = vec![f32::NEG_INFINITY; k];
        for z in latents.iter().flatten() {
            for i in 0..k {
                lo[i] = lo[i].min(z[i]);
                hi[i] = hi[i].max(z[i]);
            }
        }
        Ok(IntegratorData {
            sequences,
            latent: k,
            bc_len,
            // A timed integrator reads the latent's change per reference frame (`rate_input`).
            input_norm: Normalisation::fit(&network_inputs(&inputs, k, timed.then_some(reference_dt)))?,
            increment_norm: Normalisation::fit(&increments)?,
            latents,
            samples,
            inputs,
            colliders,
            collider_inputs: touch,
            latent_range: (lo, hi),
            timed,
            reference_dt,
            encoding,
        })
    }

    /// The integrator's time input for samples of `sequence`: its frame time when
    /// [`IntegratorData::timed`].
    pub(crate) fn input_time(&self, sequence: usize) -> Option<f64> {
        self.timed.then(|| self.sequences[sequence].trajectory.dt)
    }

    /// The colliders' poses at the frame before `sample`'s predicted frame and at it (empty
    /// without collider inputs).
    pub(crate) fn collider_poses(&self, sample: SampleRef) -> (Vec<ColliderPose>, Vec<ColliderPose>) {
        let tracks = self.sequences[sample.sequence].trajectory.colliders.as_ref();
        let poses = |frame: usize| -> Vec<ColliderPose> {
            tracks
                .filter(|_| self.colliders > 0)
                .map(|c| c.colliders_at(frame).iter().map(|c| c.pose).collect())
                .unwrap_or_default()
        };
        (poses(sample.frame - 1), poses(sample.frame))
    }

    /// Target of the predicted frame of `sample`.
    pub(crate) fn step(&self, sample: SampleRef) -> (&Frame, &[f64]) {
        let seq = &self.sequences[sample.sequence];
        (&seq.frames[sample.frame], &seq.targets[sample.frame])
    }
}

/// `[z_{t-1}, z_{t-2}, p_t, p_{t-1}, p_{t-2}]`, then the collider inputs `colliders` of frame
/// `t` (and `dt`, for an integrator that takes the frame time) for predicting frame `t` from
/// the signal of every frame (frame indices below 0 clamp to 0, the body at rest).
pub fn pack(
    z_prev: &[f32],
    z_prev2: &[f32],
    signal: &[Vec<f64>],
    colliders: &[f32],
    t: usize,
    dt: Option<f64>,
) -> Vec<f32> {
    pack_signals(
        z_prev,
        z_prev2,
        [&signal[t], &signal[t.saturating_sub(1)], &signal[t.saturating_sub(2)]],
        colliders,
        dt,
    )
}

/// Uniform noise in `±scale * std` per latent coordinate, `std` over the batch's `z_{t-1}`
/// (Eq. 5), added to both input latents of a copy of every packed row.
pub(crate) fn perturbed(rows: &[Vec<f32>], k: usize, scale: f64, rng: &mut ChaCha8Rng) -> Vec<Vec<f32>> {
    let n = rows.len().max(1) as f64;
    let std: Vec<f64> = (0..k)
        .map(|i| {
            let mean = rows.iter().map(|r| r[i] as f64).sum::<f64>() / n;
            (rows.iter().map(|r| (r[i] as f64 - mean).powi(2)).sum::<f64>() / n).sqrt()
        })
        .collect();
    rows.iter()
        .map(|r| {
            let mut r = r.clone();
            for i in 0..2 * k {
                let u: f64 = rng.random_range(-1.0..1.0);
                r[i] += (u * scale * std[i % k]) as f32;
            }
            r
        })
        .collect()
}

/// How the integrator's inputs are augmented beyond the ground-truth latents; both the
/// self-supervised objective and the supervised baseline use the same.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Augmentation {
    /// Noise on the input latents as a fraction of the batch standard deviation (Eq. 5); 0
    /// turns it off.
    pub noise: f64,
    /// Longest rollout of the integrator's own predictions (see [`rolled_inputs`]); 0 turns
    /// it off.
    pub rollout: usize,
    /// Training epochs, over which the rollout limit grows from 1 to `rollout`.
    pub epochs: usize,
}

impl Augmentation {
    /// Ground-truth inputs only.
    #[cfg(test)]
    pub const NONE: Augmentation = Augmentation {
        noise: 0.0,
        rollout: 0,
        epochs: 1,
    };

    /// The rollout limit at 0-based `epoch`: 1 at the start, `rollout` at the last epoch.
    pub(crate) fn rollout_at(&self, epoch: usize) -> usize {
        if self.rollout == 0 {
            return 0;
        }
        let progress = epoch.min(self.epochs) as f64 / self.epochs.saturating_sub(1).max(1) as f64;
        1 + ((self.rollout - 1) as f64 * progress.min(1.0)).round() as usize
    }
}

/// Packed inputs for the predicted frame of each of `samples` whose latents `z_{t-1}`
/// (and `z_{t-2}` after two or more steps) are `integrator`'s own predictions: a rollout of
/// between 1 and `limit` steps (fewer near a sequence's start) from the ground-truth latents
/// before it, without gradient. Samples at frame 1 have nothing to roll and are left out;
/// returns the samples kept and their inputs.
pub fn rolled_inputs(
    data: &IntegratorData<'_>,
    integrator: &LatentIntegrator,
    samples: &[SampleRef],
    limit: usize,
    rng: &mut ChaCha8Rng,
) -> candle_core::Result<(Vec<SampleRef>, Vec<Vec<f32>>)> {
    struct Roll {
        sample: SampleRef,
        next: usize,
        z_prev: Vec<f32>,
        z_prev2: Vec<f32>,
    }
    let mut rolls: Vec<Roll> = samples
        .iter()
        .filter(|s| s.frame >= 2 && limit > 0)
        .map(|&sample| {
            let steps = rng.random_range(1..=limit.min(sample.frame - 1));
            let next = sample.frame - steps;
            let latents = &data.latents[sample.sequence];
            Roll {
                sample,
                next,
                z_prev: latents[next - 1].clone(),
                z_prev2: latents[next.saturating_sub(2)].clone(),
            }
        })
        .collect();
    loop {
        let active: Vec<usize> = (0..rolls.len())
            .filter(|&i| rolls[i].next < rolls[i].sample.frame)
            .collect();
        if active.is_empty() {
            break;
        }
        let rows: Vec<Vec<f32>> = active
            .iter()
            .map(|&i| {
                let r = &rolls[i];
                let signal = &data.sequences[r.sample.sequence].trajectory.bc_signal;
                pack(
                    &r.z_prev,
                    &r.z_prev2,
                    signal,
                    &data.collider_inputs[r.sample.sequence][r.next],
                    r.next,
                    data.input_time(r.sample.sequence),
                )
            })
            .collect();
        let refs: Vec<&[f32]> = rows.iter().map(Vec::as_slice).collect();
        let predicted = tensor_to_rows(&integrator.forward(&to_tensor(&refs, rows[0].len())?)?)?;
        for (&i, z) in active.iter().zip(predicted) {
            let r = &mut rolls[i];
            r.z_prev2 = std::mem::replace(&mut r.z_prev, z);
            r.next += 1;
        }
    }
    Ok(rolls
        .into_iter()
        .map(|r| {
            let signal = &data.sequences[r.sample.sequence].trajectory.bc_signal;
            let dt = data.input_time(r.sample.sequence);
            let touch = &data.collider_inputs[r.sample.sequence][r.sample.frame];
            (r.sample, pack(&r.z_prev, &r.z_prev2, signal, touch, r.sample.frame, dt))
        })
        .unzip())
}

pub(crate) fn to_tensor(rows: &[&[f32]], dim: usize) -> candle_core::Result<Tensor> {
    rows_to_tensor(rows, dim).map_err(candle_err)
}

pub(crate) fn candle_err(e: impl std::fmt::Display) -> candle_core::Error {
    candle_core::Error::Msg(e.to_string())
}

/// A tiny scene, trajectory and autoencoder for the tests of the training stages.
#[cfg(test)]
pub(crate) mod fixtures {
    use super::*;
    use crate::learn::frame_rows::FrameRows;
    use crate::learn::network::AutoencoderSpec;
    use crate::learn::network::IntegratorSpec;
    use crate::learn::pca::Pca;
    use crate::learn::recipe::{Recipe, RodEncoding};
    use crate::learn::sequences::encode_sequences;
    use mochi_sim::dataset::SpeedPlan;
    use mochi_sim::scene::MeshSpec;

    /// A 6-cell beam, one short trajectory, its encoding and a PCA-initialised autoencoder.
    pub(crate) struct TinyBeam {
        pub(crate) problem: BuiltScene,
        pub(crate) encoding: Encoding,
        pub(crate) sequences: Vec<EncodedSequence>,
        pub(crate) ae: Autoencoder,
    }

    /// The beam, its trajectory simulated.
    pub(crate) fn tiny_beam() -> TinyBeam {
        let mut scene = Recipe::load("beam").unwrap().scene;
        scene.mesh = MeshSpec::Box {
            min: [0.0, -0.05, -0.05],
            max: [0.6, 0.05, 0.05],
            cells: [6, 1, 1],
        };
        let mut problem = scene.build().unwrap();
        let seq = problem.sequence(&SpeedPlan::constant(1.0), 12, 4);
        let traj = problem.run(&seq, &mochi_sim::Silent).unwrap();
        let encoding = Encoding::new(&problem, RodEncoding::Positions).unwrap();
        let sequences = encode_sequences(&encoding, vec![traj]).unwrap();
        let frames: Vec<Vec<f64>> = sequences[0].encoded.clone();
        let pca = Pca::fit(&frames, 3).unwrap();
        let spec = AutoencoderSpec {
            input: encoding.encoded_len(),
            latent: 3,
            hidden: 16,
            blocks: 1,
            shape: crate::learn::network::DecoderShape::Mlp,
        };
        let ae = Autoencoder::new_pca_init(spec, &pca.mean, &pca.basis, 1).unwrap();
        TinyBeam {
            problem,
            encoding,
            sequences,
            ae,
        }
    }

    impl TinyBeam {
        /// The integrator's training set of the beam.
        pub(crate) fn data(&self) -> IntegratorData<'_> {
            IntegratorData::new(
                &self.problem,
                &self.encoding,
                &self.ae,
                &self.sequences,
                &self.rows(),
                0,
            )
            .unwrap()
        }

        /// The encoded frames of the beam's sequences, in memory.
        pub(crate) fn rows(&self) -> FrameRows {
            FrameRows::Memory(self.sequences.iter().flat_map(|s| s.encoded.iter().cloned()).collect())
        }
    }

    /// An integrator of 16 hidden units for `data`.
    pub(crate) fn tiny_integrator(data: &IntegratorData<'_>) -> LatentIntegrator {
        let int_spec = IntegratorSpec {
            latent: data.latent,
            bc: data.bc_len,
            hidden: 16,
            blocks: 1,
            colliders: data.colliders,
            timed: data.timed,
            reference_dt: data.reference_dt,
            rate_input: data.timed,
        };
        LatentIntegrator::new(int_spec, data.input_norm.clone(), data.increment_norm.clone(), 2).unwrap()
    }
}

#[cfg(test)]
mod tests {
    use super::fixtures::{tiny_beam, tiny_integrator};
    use super::*;
    use rand::SeedableRng;

    /// Rolled inputs are the integrator's own rollout from ground truth: each equals a
    /// rollout of between 1 and `limit` steps computed one step at a time here, frame-1
    /// samples are dropped, and the limit grows from 1 to `rollout` over training.
    #[test]
    fn rolled_inputs_are_the_integrators_own_rollout() {
        let beam = tiny_beam();
        let data = beam.data();
        let integrator = tiny_integrator(&data);
        let signal = &beam.sequences[0].trajectory.bc_signal;
        let k = data.latent;
        let step = |z1: &[f32], z2: &[f32], t: usize| -> Vec<f32> {
            let row = pack(z1, z2, signal, &[], t, None);
            tensor_to_rows(&integrator.forward(&to_tensor(&[&row], row.len()).unwrap()).unwrap()).unwrap()[0].clone()
        };
        // Packed input of frame `t` after `steps` own steps from ground truth.
        let by_hand = |t: usize, steps: usize| -> Vec<f32> {
            let z = &data.latents[0];
            let first = t - steps;
            let (mut z1, mut z2) = (z[first - 1].clone(), z[first.saturating_sub(2)].clone());
            for f in first..t {
                let next = step(&z1, &z2, f);
                z2 = std::mem::replace(&mut z1, next);
            }
            pack(&z1, &z2, signal, &[], t, None)
        };
        let samples: Vec<SampleRef> = (1..data.samples.len() + 1)
            .map(|frame| SampleRef { sequence: 0, frame })
            .collect();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut steps_seen = std::collections::BTreeSet::new();
        for limit in [1, 3] {
            let (kept, rows) = rolled_inputs(&data, &integrator, &samples, limit, &mut rng).unwrap();
            assert_eq!(kept, samples[1..].to_vec(), "frame 1 has nothing to roll");
            for (s, row) in kept.iter().zip(&rows) {
                let close = |steps: usize| {
                    let want = by_hand(s.frame, steps);
                    row.iter()
                        .zip(&want)
                        .all(|(a, b)| (a - b).abs() <= 1e-5 * (1.0 + b.abs()))
                };
                let steps = (1..=limit.min(s.frame - 1)).find(|&n| close(n));
                let steps =
                    steps.unwrap_or_else(|| panic!("frame {}: no rollout of 1..={limit} steps gives {row:?}", s.frame));
                steps_seen.insert((limit, steps));
                assert_ne!(
                    &row[..2 * k],
                    &data.inputs[s.frame - 1][..2 * k],
                    "frame {}: not rolled",
                    s.frame
                );
            }
        }
        assert!(
            steps_seen.contains(&(3, 3)) && steps_seen.contains(&(3, 1)),
            "{steps_seen:?}"
        );
        let ramp = Augmentation {
            noise: 0.0,
            rollout: 8,
            epochs: 100,
        };
        assert_eq!(
            (ramp.rollout_at(0), ramp.rollout_at(50), ramp.rollout_at(99)),
            (1, 5, 8)
        );
        assert_eq!(Augmentation::NONE.rollout_at(10), 0);
    }
}
