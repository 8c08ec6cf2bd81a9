//! The stages of `mochi train` (Li et al. 2025, Sec. 3.2-3.3), each a function from the
//! values the stages before it made to the values the stages after it need; the pipeline
//! ([`crate::pipeline`]) calls them in order and times them.
//!
//! 1. [`generate_dataset`]: the scene's training split, simulated if missing;
//!    [`encode_training_split`] encodes every frame relative to its boundary conditions
//!    (in memory, or into a file read back in batches: [`super::training_frames`]).
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

pub(crate) use super::training_frames::{encode_training_split, fit_pca, PcaFit, TrainingFrames, BLOCK};
use crate::artifact::{Method, SizeTrial};
use crate::error::{TrainerError, TrainerResult};
use crate::learn::integrator::PhysicsObjective;
use crate::learn::network::{
    tensor_to_rows, Autoencoder, AutoencoderSpec, DecoderShape, IntegratorSpec, LatentIntegrator,
};
use crate::learn::pca::Pca;
use crate::learn::recipe::{LatentSpec, NetworkSpec};
use crate::learn::samples::{Augmentation, IntegratorData};
use crate::learn::stretch::EdgeStretch;
use crate::learn::supervised::SupervisedObjective;
use crate::learn::train::{self, AdamWConfig, Batch, BatchLoss, CheckpointConfig, TrainConfig};
use crate::progress::Reporter;
use mochi_sim::dataset::{self, Split};
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
    /// The file the encoded training frames are written to when they are read from disk.
    pub(crate) frames: PathBuf,
    /// Bytes of training frames held in memory at most (`mochi train --frame-memory`).
    pub(crate) frame_memory: u64,
    /// Training checkpoints.
    pub(crate) checkpoints: PathBuf,
    /// Continue from checkpoints left by an interrupted run.
    pub(crate) resume: bool,
    /// Progress bars for training epochs.
    pub(crate) bars: bool,
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
                let width = encoding.encoded_len();
                return frames.decoded_rms_error(diagonal, |block| {
                    let rows: Vec<f32> = block.iter().map(|&v| v as f32).collect();
                    let x =
                        candle_core::Tensor::from_vec(rows, (block.len() / width, width), &candle_core::Device::Cpu)?;
                    let rebuilt = tensor_to_rows(&ae.reconstruct(&x)?)?;
                    Ok(rebuilt.iter().map(|r| r.iter().map(|&v| v as f64).collect()).collect())
                });
            }
            let mse = train::mean_reconstruction_error(ae, &frames.rows, BLOCK)?;
            Ok((mse * per_vertex as f64).sqrt() / diagonal)
        };
        let trained = train::train_autoencoder(
            &ae,
            &frames.rows,
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
                    &frames.rows,
                    BLOCK,
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
        rate_input: data.timed,
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
    // Runs with rollout augmentation or a data term get their own checkpoints.
    let rolled = if spec.rollout > 0 {
        format!("-rollout{}", spec.rollout)
    } else {
        String::new()
    };
    let anchored = method == Method::SelfSupervised && spec.data_weight > 0.0;
    let weighted = if anchored {
        format!("-data{}", spec.data_weight)
    } else {
        String::new()
    };
    let config = train_config(
        &format!("integrator-{}{}-k{k}{rolled}{weighted}", method.label(), shape.tag),
        &spec.integrator,
        spec.seed + 1,
        work,
    );
    let mut physics;
    let supervised;
    // The data term of an anchored self-supervised run: the supervised objective.
    let data_term = if anchored {
        Some(SupervisedObjective::new(data, augmentation)?)
    } else {
        None
    };
    type Loss<'l> = Box<dyn FnMut(&Batch<'_>, &mut ChaCha8Rng) -> candle_core::Result<BatchLoss> + 'l>;
    let loss: Loss<'_> = match method {
        Method::SelfSupervised => {
            physics = PhysicsObjective::new(problem, data, ae, augmentation, spec.bc_weight, spec.min_speed)?;
            Box::new(|batch, rng| {
                let loss = physics.batch_loss(&integrator, batch, rng)?;
                match &data_term {
                    Some(term) => loss.plus(term.batch_loss(&integrator, batch, rng)?, spec.data_weight),
                    None => Ok(loss),
                }
            })
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
