//! The stages of `mochi train` (Li et al. 2025, Sec. 3.2-3.3), each a function from the
//! values the stages before it made to the values the stages after it need; the pipeline
//! ([`crate::pipeline`]) calls them in order and times them.
//!
//! 1. [`generate_dataset`]: the scene's training split, simulated if missing;
//!    [`encode_training_split`] encodes every frame relative to its boundary conditions.
//! 2. [`fit_pca`]: PCA of the encoded frames and its error for every size.
//! 3. [`select_autoencoder`]: autoencoders of one decoder family for the candidate latent
//!    sizes in ascending order, each initialised with the PCA (Fulton et al. 2019); the first
//!    whose RMS reconstruction error meets the scene's tolerance is kept (sizes whose PCA
//!    error is far above it are skipped untrained); [`pca_autoencoder`] for the linear
//!    family. [`super::selection`] runs them for every family.
//! 4. [`train_integrator`]: the latent integrator, self-supervised on the full-space incremental
//!    potential ([`crate::learn::integrator`]) or supervised on ground-truth latents as a
//!    baseline ([`crate::learn::supervised`]).
//! 5. [`super::assemble::write_artifacts`]: both artifacts, with the training summary.

use std::path::PathBuf;
use std::time::Instant;

use rand_chacha::ChaCha8Rng;

use crate::artifact::{Method, SizeTrial};
use crate::error::{TrainerError, TrainerResult};
use crate::learn::encoding::Encoding;
use crate::learn::integrator::PhysicsObjective;
use crate::learn::network::{
    rows_to_tensor, tensor_to_rows, Autoencoder, AutoencoderSpec, DecoderShape, IntegratorSpec, LatentIntegrator,
};
use crate::learn::pca::{self, Pca};
use crate::learn::recipe::{LatentSpec, NetworkSpec};
use crate::learn::samples::{Augmentation, IntegratorData};
use crate::learn::sequences::{decoded_rms_error, encode_sequences, EncodedSequence};
use crate::learn::stretch::EdgeStretch;
use crate::learn::supervised::SupervisedObjective;
use crate::learn::train::{self, AdamWConfig, Batch, BatchLoss, CheckpointConfig, TrainConfig};
use crate::progress::Reporter;
use mochi_sim::dataset::{self, Split};
use mochi_sim::trajectory::Trajectory;
use mochi_sim::BuiltScene;

/// Seconds of every stage that ran, in order (the training summary's `stage_seconds`).
#[derive(Clone, Debug, Default)]
pub(crate) struct StageTimes(pub(crate) Vec<(String, f64)>);

impl StageTimes {
    /// Records stage `name`, started at `clock`.
    pub(crate) fn record(&mut self, name: impl Into<String>, clock: Instant) {
        self.record_resumed(name, clock, 0.0);
    }

    /// Records stage `name`, started at `clock`, which resumed training that had already
    /// taken `earlier` seconds (from its checkpoint).
    pub(crate) fn record_resumed(&mut self, name: impl Into<String>, clock: Instant, earlier: f64) {
        self.0.push((name.into(), clock.elapsed().as_secs_f64() + earlier));
    }
}

/// Where the stages work and whether they draw bars.
#[derive(Clone, Debug)]
pub(crate) struct Workspace {
    /// The simulated dataset.
    pub(crate) dataset: PathBuf,
    /// Training checkpoints.
    pub(crate) checkpoints: PathBuf,
    /// Continue from checkpoints left by an interrupted run.
    pub(crate) resume: bool,
    /// Progress bars for training epochs.
    pub(crate) bars: bool,
}

/// The training split, encoded.
pub(crate) struct TrainingFrames {
    /// The encoding of the scene's body.
    pub(crate) encoding: Encoding,
    /// Every training sequence, encoded.
    pub(crate) sequences: Vec<EncodedSequence>,
    /// Every encoded frame, sequence after sequence.
    pub(crate) f64s: Vec<Vec<f64>>,
    /// The same in f32, as the networks take them.
    pub(crate) f32s: Vec<Vec<f32>>,
}

/// Stage 1: simulates the training split into `work.dataset` unless it is there; returns
/// how many sequences it simulated.
pub(crate) fn generate_dataset(
    problem: &mut BuiltScene,
    work: &Workspace,
    report: &dyn Reporter,
) -> TrainerResult<usize> {
    let made = dataset::generate(
        problem,
        &work.dataset,
        Some(Split::Train),
        false,
        &report.frames("dataset"),
    )?;
    Ok(made.sequences)
}

/// Loads the training split and encodes every frame relative to its boundary conditions.
pub(crate) fn encode_training_split(
    problem: &BuiltScene,
    spec: &LatentSpec,
    work: &Workspace,
) -> TrainerResult<TrainingFrames> {
    let trajectories: Vec<Trajectory> = dataset::load(problem, &work.dataset, Split::Train)?
        .into_iter()
        .map(|(_, t)| t)
        .collect();
    let encoding = Encoding::new(problem, spec.rods)?;
    let sequences = encode_sequences(&encoding, trajectories)?;
    let f64s: Vec<Vec<f64>> = sequences.iter().flat_map(|s| s.encoded.iter().cloned()).collect();
    let f32s: Vec<Vec<f32>> = f64s.iter().map(|f| f.iter().map(|&v| v as f32).collect()).collect();
    Ok(TrainingFrames {
        encoding,
        sequences,
        f64s,
        f32s,
    })
}

/// The PCA of the encoded training frames and its error at every size.
pub(crate) struct PcaFit {
    /// Components up to the largest candidate size (fewer if there are fewer frames).
    pub(crate) full: Pca,
    /// RMS vertex error / diagonal with `k` components, `k` from 0 to the largest size.
    pub(crate) errors: Vec<f64>,
}

impl PcaFit {
    /// The error with `k` components (0 past the fitted sizes).
    pub(crate) fn error(&self, k: usize) -> f64 {
        self.errors.get(k).copied().unwrap_or(0.0)
    }

    /// The PCA truncated to `k` components (all of them if there are fewer).
    pub(crate) fn truncated(&self, k: usize) -> TrainerResult<Pca> {
        Ok(self.full.clone().truncated(k.min(self.full.num_components()))?)
    }
}

/// Stage 2: the PCA of `frames` up to the largest of `sizes` and its error at every size.
/// Encoded positions: the error follows from the singular values. Strand bends: the error
/// is measured on the decoded positions, where it counts.
pub(crate) fn fit_pca(
    frames: &TrainingFrames,
    sizes: &[usize],
    tolerance: f64,
    diagonal: f64,
    report: &dyn Reporter,
) -> TrainerResult<PcaFit> {
    let largest = *sizes.iter().max().unwrap_or(&1);
    let encoding = &frames.encoding;
    let full = Pca::fit(&frames.f64s, largest.min(frames.f64s.len()))?;
    let mut fit = PcaFit {
        full,
        errors: Vec::new(),
    };
    fit.errors = if encoding.strand_bends() {
        (0..=largest)
            .map(|k| {
                let pca_k = fit.truncated(k)?;
                let rebuilt = frames
                    .f64s
                    .iter()
                    .map(|q| pca_k.reconstruct(&pca_k.project(q)?))
                    .collect::<Result<Vec<_>, _>>()?;
                Ok(decoded_rms_error(encoding, &frames.sequences, &rebuilt, diagonal)?)
            })
            .collect::<TrainerResult<Vec<f64>>>()?
    } else {
        pca::smallest_k_for(tolerance, &frames.f64s, encoding.values_per_vertex(), diagonal)?.errors
    };
    let listed: Vec<String> = (1..=largest).map(|k| format!("{k}: {:.2e}", fit.error(k))).collect();
    report.message(&format!(
        "PCA RMS vertex error / diagonal by size: {}",
        listed.join(", ")
    ));
    Ok(fit)
}

/// The autoencoder kept by size selection.
pub(crate) struct SelectedAutoencoder {
    /// The network.
    pub(crate) autoencoder: Autoencoder,
    /// Its training loss per epoch.
    pub(crate) losses: Vec<f64>,
    /// The PCA it was initialised with.
    pub(crate) pca: Pca,
    /// Every size tried, in order.
    pub(crate) trials: Vec<SizeTrial>,
}

/// The decoder family an autoencoder stage trains: its shape for each latent size, and the
/// tag of its stage names and checkpoints (empty for the residual MLP of `latent.autoencoder`).
pub(crate) struct DecoderFamily {
    /// Shape of the decoder for a latent size.
    pub(crate) shape: Box<dyn Fn(usize) -> DecoderShape>,
    /// Tag in stage and checkpoint names (`basis32-m6`), empty for the MLP.
    pub(crate) tag: String,
}

impl DecoderFamily {
    /// The residual MLP of `latent.autoencoder`.
    pub(crate) fn mlp() -> Self {
        DecoderFamily {
            shape: Box::new(|_| DecoderShape::Mlp),
            tag: String::new(),
        }
    }

    /// Name of the autoencoder stage for latent `k` (`autoencoder k=6`,
    /// `autoencoder basis32-m6 k=4`).
    pub(crate) fn stage(&self, k: usize) -> String {
        if self.tag.is_empty() {
            format!("autoencoder k={k}")
        } else {
            format!("autoencoder {} k={k}", self.tag)
        }
    }
}

/// Stage 3: autoencoders of `family` for `sizes` in ascending order until one meets the
/// tolerance (the last one tried is kept if none does); records each one's seconds in `times`.
pub(crate) fn select_autoencoder(
    problem: &BuiltScene,
    spec: &LatentSpec,
    frames: &TrainingFrames,
    pca: &PcaFit,
    sizes: &[usize],
    family: &DecoderFamily,
    work: &Workspace,
    times: &mut StageTimes,
    report: &dyn Reporter,
) -> TrainerResult<SelectedAutoencoder> {
    let encoding = &frames.encoding;
    let diagonal = problem.mesh.rest_diagonal();
    let per_vertex = encoding.values_per_vertex();
    let stretch = if spec.stretch > 0.0 {
        Some(
            EdgeStretch::new(&problem.mesh, encoding)
                .map_err(|e| TrainerError::invalid(format!("scene `{}`, latent.stretch: {e}", problem.scene.name)))?,
        )
    } else {
        None
    };
    let mut trials = Vec::new();
    let mut kept: Option<(usize, Autoencoder, Vec<f64>, Pca)> = None;
    for (i, &k) in sizes.iter().enumerate() {
        let last = i + 1 == sizes.len();
        if pca.error(k) > 10.0 * spec.tolerance && !last {
            trials.push(SizeTrial {
                size: k as u32,
                pca_error: pca.error(k),
                autoencoder_error: None,
            });
            report.message(&format!(
                "latent {k}: PCA error {:.2e} is over 10x the tolerance {:.1e}; not trained",
                pca.error(k),
                spec.tolerance
            ));
            continue;
        }
        report.stage(&family.stage(k));
        let clock = Instant::now();
        let shape = (family.shape)(k);
        let components = match shape {
            DecoderShape::Basis { modes, .. } => modes.max(k),
            DecoderShape::Mlp => k,
        };
        let pca_k = pca.truncated(components)?;
        let ae_spec = AutoencoderSpec {
            input: encoding.encoded_len(),
            latent: k,
            hidden: spec.autoencoder.hidden,
            blocks: spec.autoencoder.blocks,
            shape,
        };
        let mut basis = pca_k.basis.clone();
        // Fewer frames than components: pad with zero directions (never used by the data).
        basis.resize(components, vec![0.0; encoding.encoded_len()]);
        let ae = Autoencoder::new_pca_init(ae_spec, &pca_k.mean, &basis, spec.seed)?;
        // Runs with the edge-stretch term get their own checkpoints.
        let stretched = if stretch.is_some() {
            format!("-stretch{:?}", spec.stretch)
        } else {
            String::new()
        };
        let tag = if family.tag.is_empty() {
            String::new()
        } else {
            format!("-{}", family.tag)
        };
        let config = train_config(
            &format!("autoencoder{tag}-k{k}{stretched}"),
            &spec.autoencoder,
            spec.seed,
            work,
        );
        let rms = |ae: &Autoencoder| -> TrainerResult<f64> {
            if encoding.strand_bends() {
                let refs: Vec<&[f32]> = frames.f32s.iter().map(Vec::as_slice).collect();
                let rebuilt = tensor_to_rows(&ae.reconstruct(&rows_to_tensor(&refs, encoding.encoded_len())?)?)?;
                let rebuilt: Vec<Vec<f64>> = rebuilt.iter().map(|r| r.iter().map(|&v| v as f64).collect()).collect();
                return Ok(decoded_rms_error(encoding, &frames.sequences, &rebuilt, diagonal)?);
            }
            let mse = train::mean_reconstruction_error(ae, &frames.f32s, 256)?;
            Ok((mse * per_vertex as f64).sqrt() / diagonal)
        };
        let trained = train::train_autoencoder(
            &ae,
            &frames.f32s,
            &config,
            work.resume,
            stretch.as_ref().map(|s| (s, spec.stretch)),
        )?;
        let mut ae = ae;
        // Training starts from the exact PCA; should it end worse (it can, on data PCA
        // already fits well), the PCA-initialised network is kept instead. With the
        // edge-stretch term, worse means a higher training objective, not a higher error.
        let initial = Autoencoder::new_pca_init(ae_spec, &pca_k.mean, &basis, spec.seed)?;
        let objective = |ae: &Autoencoder| -> TrainerResult<f64> {
            match &stretch {
                Some(s) => Ok(train::mean_autoencoder_loss(
                    ae,
                    &frames.f32s,
                    256,
                    Some((s, spec.stretch)),
                )?),
                None => rms(ae),
            }
        };
        let (trained_objective, initial_objective) = (objective(&ae)?, objective(&initial)?);
        if initial_objective < trained_objective {
            report.message(&format!(
                "latent {k}: training ended above the PCA initialisation ({trained_objective:.2e} > \
                 {initial_objective:.2e}); keeping the initialisation"
            ));
            ae = initial;
        }
        let error = rms(&ae)?;
        times.record_resumed(family.stage(k), clock, trained.earlier_seconds);
        trials.push(SizeTrial {
            size: k as u32,
            pca_error: pca.error(k),
            autoencoder_error: Some(error),
        });
        report.message(&format!(
            "latent {k}: autoencoder RMS vertex error / diagonal {error:.2e} (PCA {:.2e}, tolerance {:.1e})",
            pca.error(k),
            spec.tolerance
        ));
        let meets = error <= spec.tolerance;
        kept = Some((k, ae, trained.losses, pca_k));
        if meets {
            break;
        }
        if last {
            report.message(&format!(
                "no candidate size meets the tolerance; keeping the largest, {k}"
            ));
        }
    }
    let (_, autoencoder, losses, pca) = kept.ok_or_else(|| TrainerError::invalid("no latent size was trained"))?;
    Ok(SelectedAutoencoder {
        autoencoder,
        losses,
        pca,
        trials,
    })
}

/// Stage 3 for the linear family: the PCA with `m` components as a basis decoder, not trained
/// (among linear decoders PCA is the least-squares optimum).
pub(crate) fn pca_autoencoder(
    spec: &LatentSpec,
    frames: &TrainingFrames,
    pca: &PcaFit,
    m: usize,
    family: &DecoderFamily,
) -> TrainerResult<SelectedAutoencoder> {
    let encoded = frames.encoding.encoded_len();
    let pca_m = pca.truncated(m)?;
    let mut basis = pca_m.basis.clone();
    basis.resize(m, vec![0.0; encoded]);
    let ae_spec = AutoencoderSpec {
        input: encoded,
        latent: m,
        hidden: spec.autoencoder.hidden,
        blocks: spec.autoencoder.blocks,
        shape: (family.shape)(m),
    };
    Ok(SelectedAutoencoder {
        autoencoder: Autoencoder::new_pca_init(ae_spec, &pca_m.mean, &basis, spec.seed)?,
        losses: Vec::new(),
        pca: pca_m,
        trials: vec![SizeTrial {
            size: m as u32,
            pca_error: pca.error(m),
            autoencoder_error: Some(pca.error(m)),
        }],
    })
}

/// A trained integrator.
#[derive(Clone)]
pub(crate) struct TrainedIntegrator {
    /// How it was trained.
    pub(crate) method: Method,
    /// The network.
    pub(crate) integrator: LatentIntegrator,
    /// Its training loss per epoch.
    pub(crate) losses: Vec<f64>,
    /// Training seconds before a resume (see [`train::TrainReport::earlier_seconds`]).
    pub(crate) earlier_seconds: f64,
}

/// The width of an integrator and the tag of its checkpoints (empty for the scene's own
/// `latent.integrator` on the MLP decoder; `-w64-linear` and the like for other candidates).
#[derive(Clone)]
pub(crate) struct IntegratorShape {
    /// Hidden width.
    pub(crate) width: usize,
    /// Added to the checkpoint name.
    pub(crate) tag: String,
}

/// Stage 4: the latent integrator on `data`, trained by `method`: self-supervised on the
/// physics objective or supervised on ground-truth latents.
pub(crate) fn train_integrator(
    problem: &BuiltScene,
    spec: &LatentSpec,
    data: &IntegratorData<'_>,
    ae: &Autoencoder,
    method: Method,
    shape: &IntegratorShape,
    work: &Workspace,
) -> TrainerResult<TrainedIntegrator> {
    let k = data.latent;
    let int_spec = IntegratorSpec {
        latent: k,
        bc: data.bc_len,
        hidden: shape.width,
        blocks: spec.integrator.blocks,
        colliders: data.colliders,
        timed: data.timed,
        reference_dt: data.reference_dt,
    };
    let augmentation = Augmentation {
        noise: spec.noise,
        rollout: spec.rollout,
        epochs: spec.integrator.epochs,
    };
    let integrator = LatentIntegrator::new(
        int_spec,
        data.input_norm.clone(),
        data.increment_norm.clone(),
        spec.seed + 1,
    )?;
    // Runs with rollout augmentation get their own checkpoints.
    let rolled = if spec.rollout > 0 {
        format!("-rollout{}", spec.rollout)
    } else {
        String::new()
    };
    let config = train_config(
        &format!("integrator-{}{}-k{k}{rolled}", method.label(), shape.tag),
        &spec.integrator,
        spec.seed + 1,
        work,
    );
    let mut physics;
    let supervised;
    type Loss<'l> = Box<dyn FnMut(&Batch<'_>, &mut ChaCha8Rng) -> candle_core::Result<BatchLoss> + 'l>;
    let loss: Loss<'_> = match method {
        Method::SelfSupervised => {
            physics = PhysicsObjective::new(problem, data, ae, augmentation, spec.bc_weight, spec.min_speed)?;
            Box::new(|batch, rng| physics.batch_loss(&integrator, batch, rng))
        }
        Method::Supervised => {
            supervised = SupervisedObjective::new(data, augmentation)?;
            Box::new(|batch, rng| supervised.batch_loss(&integrator, batch, rng))
        }
    };
    let trained = train::train(&integrator.parameters(), &data.inputs, &config, work.resume, loss)?;
    Ok(TrainedIntegrator {
        method,
        integrator,
        losses: trained.losses,
        earlier_seconds: trained.earlier_seconds,
    })
}

fn train_config(name: &str, net: &NetworkSpec, seed: u64, work: &Workspace) -> TrainConfig {
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
        warmup_step: None,
        checkpoint: Some(CheckpointConfig {
            dir: work.checkpoints.clone(),
            every: 5,
        }),
        progress: work.bars,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::samples::fixtures::tiny_beam;

    /// Training with the edge-stretch term lowers the stretch of the decoded states.
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
            shape: DecoderShape::Mlp,
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
                warmup_step: None,
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
}
