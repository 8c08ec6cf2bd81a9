//! `mochi train`: from a scene's training trajectories to a latent model (Li et al. 2025,
//! Sec. 3.2-3.3).
//!
//! 1. Encode every training frame relative to its boundary conditions ([`Encoding`]).
//! 2. PCA of the encoded frames; its error for every size is reported.
//! 3. Autoencoders for the candidate latent sizes in ascending order, each initialised with
//!    the PCA (Fulton et al. 2019); the first whose RMS reconstruction error meets the
//!    scene's tolerance is kept (sizes whose PCA error is far above it are skipped untrained).
//! 4. The latent integrator, trained self-supervised on the full-space incremental potential
//!    of the decoded prediction (Eq. 4), with noise augmentation (Eq. 5) and data balancing
//!    (Eq. 6); and the same network trained supervised on ground-truth latents as a baseline.
//!
//! The physics gradient meets candle at the decoded state (DESIGN.md, decision 2): the
//! simulator's energies give `g = dE/dx` in f64; the objective handed to backpropagation is
//! `sum(q * stopgrad(R^T g))` over the decoded encoded state `q = D(I(...))`, whose gradient
//! with respect to the integrator's weights is exactly `(dE/dx)^T dx/dtheta`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use candle_core::{Device, Tensor};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::artifact::{Artifact, EncodingData, HandleData, Method, SizeTrial, TrainingSummary};
use crate::learn::encoding::{decode_world, pack_signals, Encoding, Frame};
use crate::learn::loss::PhysicsLoss;
use crate::learn::network::{
    rows_to_tensor, tensor_to_rows, Autoencoder, AutoencoderSpec, IntegratorSpec, LatentIntegrator, Normalisation,
};
use crate::learn::pca::{self, Pca};
use crate::learn::recipe::{NetworkSpec, Recipe};
use crate::learn::stretch::EdgeStretch;
use crate::learn::train::{self, AdamWConfig, Batch, BatchLoss, CheckpointConfig, TrainConfig};
use crate::report::progress::FramesBar;
use mochi_sim::bc::SIGNAL_PER_HANDLE;
use mochi_sim::dataset::{self, Split};
use mochi_sim::mesh::Elements;
use mochi_sim::trajectory::Trajectory;
use mochi_sim::BuiltScene;

/// Where `mochi train` works and how it reports.
#[derive(Clone, Debug)]
pub struct TrainOptions {
    /// Output directory: `dataset/`, `checkpoints/` and the artifacts go here.
    pub out_dir: PathBuf,
    /// Continue from checkpoints left by an interrupted run.
    pub resume: bool,
    /// Progress bars on the terminal.
    pub progress: bool,
    /// Only try this latent size (instead of the scene's candidates).
    pub latent: Option<usize>,
}

/// The two artifacts of a training run.
#[derive(Clone, Debug)]
pub struct TrainOutcome {
    /// Self-supervised model.
    pub model: Artifact,
    /// Supervised baseline (same autoencoder).
    pub baseline: Artifact,
    /// Loss per epoch of the self-supervised and the supervised integrator.
    pub losses: (Vec<f64>, Vec<f64>),
    /// Loss per epoch of the kept autoencoder.
    pub autoencoder_losses: Vec<f64>,
}

/// The artifact paths of a scene in `out_dir`: the model and its supervised baseline.
pub fn artifact_paths(out_dir: &Path, scene: &str) -> (PathBuf, PathBuf) {
    (
        out_dir.join(format!("{scene}.mochi")),
        out_dir.join(format!("{scene}.supervised.mochi")),
    )
}

/// One training sequence, encoded.
#[derive(Clone, Debug)]
pub struct EncodedSequence {
    /// The full-space trajectory.
    pub trajectory: Trajectory,
    /// Handle targets of every frame.
    pub targets: Vec<Vec<f64>>,
    /// Boundary-condition frame of every frame.
    pub frames: Vec<Frame>,
    /// Encoded state of every frame.
    pub encoded: Vec<Vec<f64>>,
}

/// Encodes trajectories of `problem`'s body.
pub fn encode_sequences(encoding: &Encoding, trajectories: Vec<Trajectory>) -> anyhow::Result<Vec<EncodedSequence>> {
    trajectories
        .into_iter()
        .map(|trajectory| {
            let targets = trajectory
                .positions
                .iter()
                .map(|x| encoding.handle_targets(x))
                .collect::<Result<Vec<_>, _>>()?;
            let frames = targets
                .iter()
                .map(|t| encoding.frame(t))
                .collect::<Result<Vec<_>, _>>()?;
            let encoded = trajectory
                .positions
                .iter()
                .zip(&frames)
                .map(|(x, f)| encoding.encode(x, f))
                .collect::<Result<Vec<_>, _>>()?;
            Ok(EncodedSequence {
                trajectory,
                targets,
                frames,
                encoded,
            })
        })
        .collect()
}

/// RMS vertex error over all frames of `sequences`, as a fraction of `diagonal`, of the
/// positions decoded from `rebuilt` (one encoded vector per frame, in sequence order) against
/// the positions decoded from the frames' own encodings.
fn decoded_rms_error(
    encoding: &Encoding,
    sequences: &[EncodedSequence],
    rebuilt: &[Vec<f64>],
    diagonal: f64,
) -> anyhow::Result<f64> {
    let frames = sequences
        .iter()
        .flat_map(|s| s.encoded.iter().zip(&s.frames).zip(&s.targets));
    let (mut sum, mut count) = (0.0, 0usize);
    let mut exact = vec![0.0; encoding.state_len()];
    let mut approx = vec![0.0; encoding.state_len()];
    for (((q, frame), targets), r) in frames.zip(rebuilt) {
        encoding.decode_into(q, frame, targets, &mut exact)?;
        encoding.decode_into(r, frame, targets, &mut approx)?;
        sum += exact.iter().zip(&approx).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        count += encoding.free_vertices().len();
    }
    Ok((sum / count.max(1) as f64).sqrt() / diagonal)
}

/// Runs the whole of `mochi train` for `problem`: dataset (train split, if missing),
/// latent-size selection, autoencoder, both integrators; writes both artifacts.
pub fn train_scene(recipe: &Recipe, options: &TrainOptions) -> anyhow::Result<TrainOutcome> {
    let problem = &mut recipe.build()?;
    let spec = recipe.latent.clone();
    let diagonal = problem.mesh.rest_diagonal();
    let dim = problem.mesh.dim;
    let mut stages: Vec<(String, f64)> = Vec::new();
    let checkpoints = options.out_dir.join("checkpoints");

    // Dataset.
    let clock = Instant::now();
    let data_dir = options.out_dir.join("dataset");
    let made = dataset::generate(
        problem,
        &data_dir,
        Some(Split::Train),
        false,
        &FramesBar::new("dataset", options.progress),
    )?;
    if made.sequences > 0 {
        stages.push(("dataset (train split)".into(), clock.elapsed().as_secs_f64()));
    }
    let trajectories: Vec<Trajectory> = dataset::load(problem, &data_dir, Split::Train)?
        .into_iter()
        .map(|(_, t)| t)
        .collect();
    let encoding = Encoding::new(problem, spec.rods)?;
    let sequences = encode_sequences(&encoding, trajectories)?;
    let frames_f64: Vec<Vec<f64>> = sequences.iter().flat_map(|s| s.encoded.iter().cloned()).collect();
    let frames_f32: Vec<Vec<f32>> = frames_f64
        .iter()
        .map(|f| f.iter().map(|&v| v as f32).collect())
        .collect();

    // PCA and latent-size selection.
    let clock = Instant::now();
    let sizes: Vec<usize> = options.latent.map_or(spec.sizes.clone(), |k| vec![k]);
    let largest = *sizes.iter().max().unwrap_or(&1);
    let per_vertex = encoding.values_per_vertex();
    let full_pca = Pca::fit(&frames_f64, largest.min(frames_f64.len()))?;
    // Encoded positions: the PCA error follows from the singular values. Strand bends: the
    // error is measured on the decoded positions, where it counts.
    let pca_errors = if encoding.strand_bends() {
        (0..=largest)
            .map(|k| {
                let pca_k = full_pca.clone().truncated(k.min(full_pca.num_components()))?;
                let rebuilt = frames_f64
                    .iter()
                    .map(|q| pca_k.reconstruct(&pca_k.project(q)?))
                    .collect::<Result<Vec<_>, _>>()?;
                decoded_rms_error(&encoding, &sequences, &rebuilt, diagonal)
            })
            .collect::<anyhow::Result<Vec<f64>>>()?
    } else {
        pca::smallest_k_for(spec.tolerance, &frames_f64, per_vertex, diagonal)?.errors
    };
    stages.push(("pca".into(), clock.elapsed().as_secs_f64()));
    let pca_error = |k: usize| pca_errors.get(k).copied().unwrap_or(0.0);
    if options.progress {
        let listed: Vec<String> = (1..=largest).map(|k| format!("{k}: {:.2e}", pca_error(k))).collect();
        println!("PCA RMS vertex error / diagonal by size: {}", listed.join(", "));
    }

    let stretch = if spec.stretch > 0.0 {
        Some(
            EdgeStretch::new(&problem.mesh, &encoding)
                .map_err(|e| anyhow::anyhow!("scene `{}`, latent.stretch: {e}", problem.scene.name))?,
        )
    } else {
        None
    };
    let mut trials = Vec::new();
    let mut kept: Option<(usize, Autoencoder, Vec<f64>, Pca)> = None;
    for (i, &k) in sizes.iter().enumerate() {
        let last = i + 1 == sizes.len();
        if pca_error(k) > 10.0 * spec.tolerance && !last {
            trials.push(SizeTrial {
                size: k as u32,
                pca_error: pca_error(k),
                autoencoder_error: None,
            });
            if options.progress {
                println!(
                    "latent {k}: PCA error {:.2e} is over 10x the tolerance {:.1e}; not trained",
                    pca_error(k),
                    spec.tolerance
                );
            }
            continue;
        }
        let clock = Instant::now();
        let pca_k = full_pca.clone().truncated(k.min(full_pca.num_components()))?;
        let ae_spec = AutoencoderSpec {
            input: encoding.encoded_len(),
            latent: k,
            hidden: spec.autoencoder.hidden,
            blocks: spec.autoencoder.blocks,
        };
        let mut basis = pca_k.basis.clone();
        // Fewer frames than components: pad with zero directions (never used by the data).
        basis.resize(k, vec![0.0; encoding.encoded_len()]);
        let ae = Autoencoder::new_pca_init(ae_spec, &pca_k.mean, &basis, spec.seed)?;
        // Runs with the edge-stretch term get their own checkpoints.
        let stretched = if stretch.is_some() {
            format!("-stretch{:?}", spec.stretch)
        } else {
            String::new()
        };
        let config = train_config(
            &format!("autoencoder-k{k}{stretched}"),
            &spec.autoencoder,
            spec.seed,
            &checkpoints,
            options.progress,
        );
        let rms = |ae: &Autoencoder| -> anyhow::Result<f64> {
            if encoding.strand_bends() {
                let refs: Vec<&[f32]> = frames_f32.iter().map(Vec::as_slice).collect();
                let rebuilt = tensor_to_rows(&ae.reconstruct(&rows_to_tensor(&refs, encoding.encoded_len())?)?)?;
                let rebuilt: Vec<Vec<f64>> = rebuilt.iter().map(|r| r.iter().map(|&v| v as f64).collect()).collect();
                return decoded_rms_error(&encoding, &sequences, &rebuilt, diagonal);
            }
            let mse = train::mean_reconstruction_error(ae, &frames_f32, 256)?;
            Ok((mse * per_vertex as f64).sqrt() / diagonal)
        };
        let report = train::train_autoencoder(
            &ae,
            &frames_f32,
            &config,
            options.resume,
            stretch.as_ref().map(|s| (s, spec.stretch)),
        )?;
        let mut ae = ae;
        // Training starts from the exact PCA; should it end worse (it can, on data PCA
        // already fits well), the PCA-initialised network is kept instead. With the
        // edge-stretch term, worse means a higher training objective, not a higher error.
        let initial = Autoencoder::new_pca_init(ae_spec, &pca_k.mean, &basis, spec.seed)?;
        let objective = |ae: &Autoencoder| -> anyhow::Result<f64> {
            match &stretch {
                Some(s) => Ok(train::mean_autoencoder_loss(
                    ae,
                    &frames_f32,
                    256,
                    Some((s, spec.stretch)),
                )?),
                None => rms(ae),
            }
        };
        let (trained_objective, initial_objective) = (objective(&ae)?, objective(&initial)?);
        if initial_objective < trained_objective {
            if options.progress {
                println!("latent {k}: training ended above the PCA initialisation ({trained_objective:.2e} > {initial_objective:.2e}); keeping the initialisation");
            }
            ae = initial;
        }
        let error = rms(&ae)?;
        stages.push((format!("autoencoder k={k}"), clock.elapsed().as_secs_f64()));
        trials.push(SizeTrial {
            size: k as u32,
            pca_error: pca_error(k),
            autoencoder_error: Some(error),
        });
        if options.progress {
            println!(
                "latent {k}: autoencoder RMS vertex error / diagonal {error:.2e} (PCA {:.2e}, tolerance {:.1e})",
                pca_error(k),
                spec.tolerance
            );
        }
        let meets = error <= spec.tolerance;
        kept = Some((k, ae, report.losses, pca_k));
        if meets {
            break;
        }
        if last && options.progress {
            println!("no candidate size meets the tolerance; keeping the largest, {k}");
        }
    }
    let (k, ae, autoencoder_losses, pca) = kept.ok_or_else(|| anyhow::anyhow!("no latent size was trained"))?;

    // Integrators.
    let set = IntegratorData::new(problem, &encoding, &ae, &sequences)?;
    let int_spec = IntegratorSpec {
        latent: k,
        bc: set.bc_len,
        hidden: spec.integrator.hidden,
        blocks: spec.integrator.blocks,
    };
    let augmentation = Augmentation {
        noise: spec.noise,
        rollout: spec.rollout,
        epochs: spec.integrator.epochs,
    };
    let mut outcomes = Vec::new();
    for method in [Method::SelfSupervised, Method::Supervised] {
        let clock = Instant::now();
        let integrator = LatentIntegrator::new(
            int_spec,
            set.input_norm.clone(),
            set.increment_norm.clone(),
            spec.seed + 1,
        )?;
        // Runs with rollout augmentation get their own checkpoints.
        let rolled = if spec.rollout > 0 {
            format!("-rollout{}", spec.rollout)
        } else {
            String::new()
        };
        let config = train_config(
            &format!("integrator-{}-k{k}{rolled}", method.label()),
            &spec.integrator,
            spec.seed + 1,
            &checkpoints,
            options.progress,
        );
        let mut physics;
        let supervised;
        type Loss<'l> = Box<dyn FnMut(&Batch<'_>, &mut ChaCha8Rng) -> candle_core::Result<BatchLoss> + 'l>;
        let loss: Loss<'_> = match method {
            Method::SelfSupervised => {
                physics = PhysicsObjective::new(problem, &set, &ae, augmentation, spec.bc_weight, spec.min_speed)?;
                Box::new(|batch, rng| physics.batch_loss(&integrator, batch, rng))
            }
            Method::Supervised => {
                supervised = SupervisedObjective::new(&set, augmentation)?;
                Box::new(|batch, rng| supervised.batch_loss(&integrator, batch, rng))
            }
        };
        let report = train::train(&integrator.parameters(), &set.inputs, &config, options.resume, loss)?;
        stages.push((
            format!("integrator ({})", method.label()),
            clock.elapsed().as_secs_f64(),
        ));
        outcomes.push((method, integrator, report.losses));
    }

    let max_radius = frames_f64
        .iter()
        .flat_map(|q| {
            q.chunks_exact(per_vertex)
                .map(|c| c.iter().map(|v| v * v).sum::<f64>().sqrt())
        })
        .fold(0.0, f64::max);
    let masses = problem.simulator.masses().to_vec();
    let max_kinetic_energy = sequences
        .iter()
        .flat_map(|s| {
            s.trajectory
                .positions
                .windows(2)
                .map(|w| mochi_sim::measure::kinetic_energy(&masses, &w[1], &w[0], problem.scene.dt, dim))
        })
        .fold(0.0, f64::max);
    let mut artifacts = Vec::new();
    let mut losses = Vec::new();
    for (method, integrator, history) in outcomes {
        let summary = TrainingSummary {
            tolerance: spec.tolerance,
            trials: trials.clone(),
            stage_seconds: stages.clone(),
            final_loss: history.last().copied().unwrap_or(f64::NAN),
            samples: set.inputs.len() as u64,
            max_radius,
            max_kinetic_energy,
        };
        artifacts.push(build_artifact(
            recipe,
            problem,
            &encoding,
            &ae,
            &integrator,
            &set,
            &pca,
            method,
            summary,
        )?);
        losses.push(history);
    }
    let baseline = artifacts.pop().expect("two artifacts");
    let model = artifacts.pop().expect("two artifacts");
    let (model_path, baseline_path) = artifact_paths(&options.out_dir, &problem.scene.name);
    model.write(&model_path)?;
    baseline.write(&baseline_path)?;
    let supervised_losses = losses.pop().unwrap_or_default();
    let physics_losses = losses.pop().unwrap_or_default();
    Ok(TrainOutcome {
        model,
        baseline,
        losses: (physics_losses, supervised_losses),
        autoencoder_losses,
    })
}

fn train_config(name: &str, net: &NetworkSpec, seed: u64, checkpoints: &Path, progress: bool) -> TrainConfig {
    TrainConfig {
        name: name.into(),
        epochs: net.epochs,
        batch_size: net.batch,
        seed,
        optimizer: AdamWConfig {
            lr: net.learning_rate,
            ..AdamWConfig::default()
        },
        final_lr: Some(net.final_learning_rate),
        checkpoint: Some(CheckpointConfig {
            dir: checkpoints.to_path_buf(),
            every: 5,
        }),
        progress,
    }
}

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
    fn prev2(&self) -> usize {
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
    /// Decoded ground-truth latents in world space, per sequence and frame (f64).
    pub decoded: Vec<Vec<Vec<f64>>>,
    /// One sample per predicted frame.
    pub samples: Vec<SampleRef>,
    /// Packed inputs `[z_{t-1}, z_{t-2}, p_t, p_{t-1}, p_{t-2}]`, one per sample.
    pub inputs: Vec<Vec<f32>>,
    /// Normalisation of the packed inputs.
    pub input_norm: Normalisation,
    /// Normalisation of the ground-truth increments `z_t - z_{t-1}`.
    pub increment_norm: Normalisation,
    /// Per latent coordinate, smallest and largest training value.
    pub latent_range: (Vec<f32>, Vec<f32>),
    encoding: &'a Encoding,
}

impl<'a> IntegratorData<'a> {
    /// Encodes every frame with `ae` and packs one sample per predicted frame.
    pub fn new(
        problem: &BuiltScene,
        encoding: &'a Encoding,
        ae: &Autoencoder,
        sequences: &'a [EncodedSequence],
    ) -> anyhow::Result<Self> {
        let k = ae.spec().latent;
        let bc_len = SIGNAL_PER_HANDLE * problem.handles.len();
        let mut latents = Vec::new();
        let mut decoded = Vec::new();
        for seq in sequences {
            let rows: Vec<Vec<f32>> = seq
                .encoded
                .iter()
                .map(|q| q.iter().map(|&v| v as f32).collect())
                .collect();
            let mut z_seq = Vec::new();
            let mut x_seq = Vec::new();
            for chunk in rows.chunks(256) {
                let refs: Vec<&[f32]> = chunk.iter().map(Vec::as_slice).collect();
                let x = rows_to_tensor(&refs, encoding.encoded_len())?;
                let z = ae.encode(&x)?;
                let back = tensor_to_rows(&ae.decode(&z)?)?;
                z_seq.extend(tensor_to_rows(&z)?);
                x_seq.extend(back);
            }
            let world = x_seq
                .iter()
                .enumerate()
                .map(|(t, q)| decode_world(encoding, q, &seq.frames[t], &seq.targets[t]))
                .collect::<anyhow::Result<Vec<_>>>()?;
            latents.push(z_seq);
            decoded.push(world);
        }
        let mut samples = Vec::new();
        let mut inputs = Vec::new();
        let mut increments = Vec::new();
        for (s, seq) in sequences.iter().enumerate() {
            if seq.trajectory.bc_signal.first().map_or(0, Vec::len) != bc_len {
                anyhow::bail!(
                    "training sequence {s} has {} boundary-condition numbers per frame, the scene has {bc_len}",
                    seq.trajectory.bc_signal.first().map_or(0, Vec::len)
                );
            }
            for t in 1..seq.encoded.len() {
                let sample = SampleRef { sequence: s, frame: t };
                inputs.push(pack(
                    &latents[s][t - 1],
                    &latents[s][sample.prev2()],
                    &seq.trajectory.bc_signal,
                    t,
                ));
                increments.push(
                    latents[s][t]
                        .iter()
                        .zip(&latents[s][t - 1])
                        .map(|(a, b)| a - b)
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
            input_norm: Normalisation::fit(&inputs)?,
            increment_norm: Normalisation::fit(&increments)?,
            latents,
            decoded,
            samples,
            inputs,
            latent_range: (lo, hi),
            encoding,
        })
    }

    /// Target of the predicted frame of `sample`.
    fn step(&self, sample: SampleRef) -> (&Frame, &[f64]) {
        let seq = &self.sequences[sample.sequence];
        (&seq.frames[sample.frame], &seq.targets[sample.frame])
    }
}

/// `[z_{t-1}, z_{t-2}, p_t, p_{t-1}, p_{t-2}]` for predicting frame `t` from the signal of
/// every frame (frame indices below 0 clamp to 0, the body at rest).
pub fn pack(z_prev: &[f32], z_prev2: &[f32], signal: &[Vec<f64>], t: usize) -> Vec<f32> {
    pack_signals(
        z_prev,
        z_prev2,
        [&signal[t], &signal[t.saturating_sub(1)], &signal[t.saturating_sub(2)]],
    )
}

/// Uniform noise in `±scale * std` per latent coordinate, `std` over the batch's `z_{t-1}`
/// (Eq. 5), added to both input latents of a copy of every packed row.
fn perturbed(rows: &[Vec<f32>], k: usize, scale: f64, rng: &mut ChaCha8Rng) -> Vec<Vec<f32>> {
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
    pub const NONE: Augmentation = Augmentation {
        noise: 0.0,
        rollout: 0,
        epochs: 1,
    };

    /// The rollout limit at 0-based `epoch`: 1 at the start, `rollout` at the last epoch.
    fn rollout_at(&self, epoch: usize) -> usize {
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
                pack(&r.z_prev, &r.z_prev2, signal, r.next)
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
            (r.sample, pack(&r.z_prev, &r.z_prev2, signal, r.sample.frame))
        })
        .unzip())
}

/// The self-supervised objective (Eq. 4-6) on minibatches of [`IntegratorData`].
pub struct PhysicsObjective<'a> {
    data: &'a IntegratorData<'a>,
    ae: &'a Autoencoder,
    losses: Vec<PhysicsLoss>,
    augmentation: Augmentation,
    min_speed: f64,
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
    ) -> anyhow::Result<Self> {
        let losses = (0..rayon::current_num_threads().max(1))
            .map(|_| PhysicsLoss::new(&problem.scene, &problem.mesh, &problem.handles, Some(bc_weight)))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(PhysicsObjective {
            data,
            ae,
            losses,
            augmentation,
            min_speed,
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
        // Previous states for the inertia term: the decoded inputs themselves.
        let mut prevs: Vec<(Vec<f64>, Vec<f64>)> = samples
            .iter()
            .map(|s| {
                let d = &data.decoded[s.sequence];
                (d[s.frame - 1].clone(), d[s.prev2()].clone())
            })
            .collect();
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
        let min_speed = self.min_speed;
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
                    let value = loss.value_and_gradient(&x, prev, prev2, targets, &mut grad);
                    let balance = loss.balance(prev, prev2, min_speed);
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

fn to_tensor(rows: &[&[f32]], dim: usize) -> candle_core::Result<Tensor> {
    rows_to_tensor(rows, dim).map_err(candle_err)
}

fn candle_err(e: impl std::fmt::Display) -> candle_core::Error {
    candle_core::Error::Msg(e.to_string())
}

/// Assembles the artifact of a trained model; `pca` is the PCA of the encoded training
/// frames the autoencoder was initialised with.
pub fn build_artifact(
    recipe: &Recipe,
    problem: &BuiltScene,
    encoding: &Encoding,
    ae: &Autoencoder,
    integrator: &LatentIntegrator,
    data: &IntegratorData<'_>,
    pca: &Pca,
    method: Method,
    summary: TrainingSummary,
) -> anyhow::Result<Artifact> {
    let exported = ae.export()?;
    let k = data.latent;
    let f32s = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let u32s = |v: &[usize]| v.iter().map(|&x| x as u32).collect::<Vec<u32>>();
    let x0 = &data.sequences[0].trajectory.positions[0];
    let q0: Vec<f32> = encoding.encode_state(x0)?.iter().map(|&v| v as f32).collect();
    let initial_latent = crate::learn::network::forward_exported(&exported.encoder, &q0)?;
    let mut pca_basis: Vec<f32> = pca.basis.iter().flat_map(|b| f32s(b)).collect();
    pca_basis.resize(k * encoding.encoded_len(), 0.0);
    let polylines = match &problem.mesh.elements {
        Elements::Rods(rods) => rods.iter().map(|r| u32s(r)).collect(),
        _ => Vec::new(),
    };
    let handles = problem
        .handles
        .iter()
        .map(|h| HandleData {
            name: h.name.clone(),
            vertices: u32s(&h.vertices),
            reference: h.reference.iter().flatten().map(|&v| v as f32).collect(),
            pivot: h.pivot.map(|v| v as f32),
        })
        .collect();
    let artifact = Artifact {
        scene: problem.scene.name.clone(),
        scene_path: problem.scene.source.display().to_string(),
        scene_toml: recipe.to_toml()?,
        method,
        dt: problem.scene.dt,
        dim: problem.mesh.dim as u32,
        num_vertices: problem.mesh.num_vertices() as u32,
        rest: f32s(&problem.mesh.rest),
        diagonal: problem.mesh.rest_diagonal(),
        encoding: EncodingData::new(encoding),
        handles,
        bc_len: data.bc_len as u32,
        surface_vertices: u32s(&problem.mesh.surface_vertices()),
        surface_triangles: problem
            .mesh
            .surface_triangles()
            .iter()
            .map(|t| t.map(|v| v as u32))
            .collect(),
        polylines,
        latent: k as u32,
        initial_latent,
        latent_min: data.latent_range.0.clone(),
        latent_max: data.latent_range.1.clone(),
        pca_mean: f32s(&pca.mean),
        pca_basis,
        encoder: exported.encoder.layers().into_iter().cloned().collect(),
        decoder: exported.decoder.layers().into_iter().cloned().collect(),
        integrator: integrator.export()?.mlp().layers().into_iter().cloned().collect(),
        summary,
    };
    artifact
        .validate()
        .map_err(|(field, msg)| anyhow::anyhow!("built an invalid artifact: {field}: {msg}"))?;
    Ok(artifact)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::recipe::{Recipe, RodEncoding};
    use mochi_sim::dataset::SpeedPlan;
    use mochi_sim::scene::MeshSpec;
    use rand::SeedableRng;

    /// A 6-cell beam, one short trajectory, its encoding and a PCA-initialised autoencoder.
    struct TinyBeam {
        problem: BuiltScene,
        encoding: Encoding,
        sequences: Vec<EncodedSequence>,
        ae: Autoencoder,
    }

    fn tiny_beam() -> TinyBeam {
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
        fn data(&self) -> IntegratorData<'_> {
            IntegratorData::new(&self.problem, &self.encoding, &self.ae, &self.sequences).unwrap()
        }
    }

    fn tiny_integrator(data: &IntegratorData<'_>) -> LatentIntegrator {
        let int_spec = IntegratorSpec {
            latent: data.latent,
            bc: data.bc_len,
            hidden: 16,
            blocks: 1,
        };
        LatentIntegrator::new(int_spec, data.input_norm.clone(), data.increment_norm.clone(), 2).unwrap()
    }

    /// The surrogate objective's gradient with respect to an integrator weight equals the
    /// derivative of the balanced physics loss itself (central finite difference).
    #[test]
    fn the_stretch_term_lowers_the_stretch_of_decoded_states() {
        let beam = tiny_beam();
        let frames: Vec<Vec<f32>> = beam.sequences[0]
            .encoded
            .iter()
            .map(|q| q.iter().map(|&v| v as f32).collect())
            .collect();
        let pca = Pca::fit(&beam.sequences[0].encoded, 1).unwrap();
        let spec = AutoencoderSpec {
            input: beam.encoding.encoded_len(),
            latent: 1,
            hidden: 16,
            blocks: 1,
        };
        let stretch = EdgeStretch::new(&beam.problem.mesh, &beam.encoding).unwrap();
        let trained = |weight: f64| {
            let ae = Autoencoder::new_pca_init(spec, &pca.mean, &pca.basis, 1).unwrap();
            let config = TrainConfig {
                name: "stretch".into(),
                epochs: 40,
                batch_size: 4,
                seed: 1,
                optimizer: AdamWConfig {
                    lr: 1e-3,
                    ..AdamWConfig::default()
                },
                final_lr: None,
                checkpoint: None,
                progress: false,
            };
            let term = (weight > 0.0).then_some((&stretch, weight));
            train::train_autoencoder(&ae, &frames, &config, false, term).unwrap();
            // The penalty alone: the weighted objective less the reconstruction error.
            train::mean_autoencoder_loss(&ae, &frames, 64, Some((&stretch, 1.0))).unwrap()
                - train::mean_reconstruction_error(&ae, &frames, 64).unwrap()
        };
        // Measured: 2.8e-9 against 5.4e-8.
        let (plain, stretched) = (trained(0.0), trained(100.0));
        assert!(stretched < 0.5 * plain, "stretch {stretched:e} vs {plain:e}");
    }

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
            batch: 0,
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
            let row = pack(z1, z2, signal, t);
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
            pack(&z1, &z2, signal, t)
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
