//! The paper's vanilla subspace for `[reduced] vanilla = "plain-mlp"` (Lyu et al. 2024,
//! Eq. 3): an autoencoder of plain MLPs (one hidden layer, or `plain_blocks` residual blocks
//! more), randomly initialised and trained on the reconstruction loss alone, independent of
//! the latent model's PCA-initialised autoencoder (whose latent size it takes). With
//! `plain_schedule = "paper"` it trains as the paper's configs say (minibatches of 256, a
//! warm-up of 2,000 iterations, a factor 0.8 every 30,000); with `plain_activation = "elu"` and
//! `plain_residual = false` its MLPs are the paper code's (plain hidden layers, ELU), and with
//! `plain_pca` they work between the fixed maps of a PCA of the frames, as the paper code's
//! with a PCA basis.

use crate::learn::frame_rows::Rows;
use std::time::Instant;

use super::stages::Workspace;
use crate::error::TrainerResult;
use crate::learn::network::{Autoencoder, AutoencoderSpec, DecoderShape, MlpStyle};
use crate::learn::pca;
use crate::learn::reduced_spec::{PlainSchedule, ReducedSpec};
use crate::learn::train::{self, AdamWConfig, CheckpointConfig, TrainConfig, WarmupStep};

/// Minibatch size of the paper's schedule.
pub(crate) const PAPER_BATCH: usize = 256;
/// Warm-up iterations of the paper's schedule.
const PAPER_WARMUP_ITERATIONS: usize = 2000;
/// Iterations between the paper's learning-rate decay steps.
const PAPER_DECAY_EVERY: usize = 30000;
/// The paper's decay factor.
const PAPER_DECAY: f64 = 0.8;

/// A trained plain vanilla autoencoder.
pub(crate) struct PlainVanilla {
    /// The autoencoder.
    pub(crate) autoencoder: Autoencoder,
    /// Mean loss of every epoch.
    pub(crate) losses: Vec<f64>,
    /// Training seconds (including those before a resumed checkpoint).
    pub(crate) seconds: f64,
    /// With `plain_pca`: the PCA's components and its RMS vertex error / diagonal.
    pub(crate) projection: Option<(usize, f64)>,
}

/// The sizes of the plain autoencoder of `spec` for states of `input` values and latent `k`.
pub(crate) fn plain_spec(spec: &ReducedSpec, input: usize, k: usize) -> AutoencoderSpec {
    AutoencoderSpec {
        input,
        latent: k,
        hidden: spec.plain_hidden,
        blocks: spec.plain_blocks,
        shape: DecoderShape::Mlp,
    }
}

/// The style of the plain autoencoder's MLPs.
pub(crate) fn plain_style(spec: &ReducedSpec) -> MlpStyle {
    MlpStyle {
        activation: spec.plain_activation,
        residual: spec.plain_residual,
        ..MlpStyle::default()
    }
}

/// What tells plain autoencoders of other settings apart (in checkpoint names).
pub(crate) fn plain_tag(spec: &ReducedSpec) -> String {
    let mut tag = format!(
        "h{}-e{}-lr{:?}-{:?}",
        spec.plain_hidden, spec.plain_epochs, spec.plain_learning_rate, spec.plain_final_learning_rate
    );
    if spec.plain_blocks > 0 {
        tag += &format!("-b{}", spec.plain_blocks);
    }
    if spec.plain_schedule == PlainSchedule::Paper {
        tag += "-paper";
    }
    let style = plain_style(spec);
    if let Some(tolerance) = spec.plain_pca {
        tag += &format!("-pca{tolerance:?}");
    }
    if style != MlpStyle::default() {
        tag += &format!("-{:?}", style.activation).to_lowercase();
        if !style.residual {
            tag += "-layers";
        }
    }
    tag
}

/// The training settings of the plain autoencoder on `frames` frames (minibatches of `batch`
/// frames, or the paper's with its schedule).
pub(crate) fn plain_config(
    spec: &ReducedSpec,
    k: usize,
    frames: usize,
    batch: usize,
    seed: u64,
    work: &Workspace,
) -> TrainConfig {
    let (batch, warmup_step) = match spec.plain_schedule {
        PlainSchedule::Cosine => (batch, None),
        PlainSchedule::Paper => {
            let per_epoch = frames.div_ceil(PAPER_BATCH).max(1);
            let schedule = WarmupStep {
                warmup: PAPER_WARMUP_ITERATIONS.div_ceil(per_epoch),
                factor: PAPER_DECAY,
                every: (PAPER_DECAY_EVERY / per_epoch).max(1),
            };
            (PAPER_BATCH, Some(schedule))
        }
    };
    TrainConfig {
        name: format!("plain-vanilla-k{k}-{}", plain_tag(spec)),
        epochs: spec.plain_epochs,
        batch_size: batch,
        seed,
        optimizer: AdamWConfig {
            lr: spec.plain_learning_rate,
            ..AdamWConfig::default()
        },
        final_lr: Some(spec.plain_final_learning_rate),
        warmup_step,
        checkpoint: Some(CheckpointConfig {
            dir: work.checkpoints.clone(),
            every: 25,
        }),
        progress: work.bars,
    }
}

/// Trains the plain autoencoder of `spec` (latent `k`) on the encoded frames `data`, whose
/// vertices have `scale.0` values and whose rest diagonal is `scale.1` (the units of
/// `plain_pca`).
pub(crate) fn train_plain_vanilla(
    spec: &ReducedSpec,
    data: &(impl Rows + ?Sized),
    k: usize,
    batch: usize,
    seed: u64,
    work: &Workspace,
    scale: (usize, f64),
) -> TrainerResult<PlainVanilla> {
    let input = data.width();
    let sizes = plain_spec(spec, input, k);
    let mut projection = None;
    let autoencoder = match spec.plain_pca {
        None => Autoencoder::new_styled(sizes, plain_style(spec), seed)?,
        Some(tolerance) => {
            let frames = (0..data.count())
                .map(|i| data.row_f64(i))
                .collect::<std::io::Result<Vec<_>>>()?;
            let sized = pca::smallest_k_for(tolerance, &frames, scale.0, scale.1)?;
            let modes = sized.pca.num_components();
            projection = Some((modes, sized.errors.get(modes).copied().unwrap_or(0.0)));
            Autoencoder::new_projected(sizes, plain_style(spec), &sized.pca.mean, &sized.pca.basis, seed)?
        }
    };
    let clock = Instant::now();
    let config = plain_config(spec, k, data.count(), batch, seed, work);
    let report = train::train_autoencoder(&autoencoder, data, &config, work.resume, None)?;
    Ok(PlainVanilla {
        autoencoder,
        losses: report.losses,
        seconds: clock.elapsed().as_secs_f64() + report.earlier_seconds,
        projection,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::samples::fixtures::tiny_beam;

    /// The plain autoencoder learns the tiny beam's frames from a random start: its
    /// reconstruction error falls far below the start's, with one hidden layer (no block) and
    /// with the paper code's two plain ELU layers.
    #[test]
    fn the_plain_autoencoder_learns_the_frames() {
        let one_layer = ReducedSpec {
            plain_hidden: 16,
            plain_epochs: 150,
            plain_learning_rate: 3e-3,
            ..ReducedSpec::default()
        };
        let paper_layers = ReducedSpec {
            plain_blocks: 1,
            plain_activation: crate::learn::network::Activation::Elu,
            plain_residual: false,
            ..one_layer.clone()
        };
        let projected = ReducedSpec {
            plain_pca: Some(1e-3),
            ..paper_layers.clone()
        };
        for spec in [one_layer, paper_layers, projected] {
            learns_the_frames(spec);
        }
    }

    fn learns_the_frames(spec: ReducedSpec) {
        let beam = tiny_beam();
        let data: Vec<Vec<f32>> = beam.sequences[0]
            .encoded
            .iter()
            .map(|q| q.iter().map(|&v| v as f32).collect())
            .collect();
        let dir = tempfile::tempdir().unwrap();
        let work = Workspace {
            dataset: dir.path().to_path_buf(),
            frames: dir.path().join("frames.f64"),
            frame_memory: crate::pipeline::FRAME_MEMORY,
            checkpoints: dir.path().to_path_buf(),
            resume: false,
            bars: false,
        };
        let start = Autoencoder::new_styled(plain_spec(&spec, data[0].len(), 3), plain_style(&spec), 1).unwrap();
        let before = train::mean_reconstruction_error(&start, &data, 64).unwrap();
        let trained = train_plain_vanilla(&spec, &data, 3, 4, 1, &work, (3, 1.0)).unwrap();
        let after = train::mean_reconstruction_error(&trained.autoencoder, &data, 64).unwrap();
        assert_eq!(trained.losses.len(), 150);
        assert!(after < 1e-2 * before, "reconstruction {before:.3e} -> {after:.3e}");
        let exported = trained.autoencoder.export().unwrap();
        let decoder = exported.decoder.as_mlp().unwrap();
        assert_eq!(decoder.spec().blocks, spec.plain_blocks);
        assert_eq!(decoder.spec().output, data[0].len());
        match trained.projection {
            // The PCA meets its tolerance with fewer components than values, and the decoder
            // writes through its basis.
            Some((modes, error)) => {
                assert!(modes < data[0].len() && error <= 1e-3, "{modes} components, {error:e}");
                assert_eq!(decoder.output_projection().unwrap().cols, modes);
                assert_eq!(exported.encoder.input_projection().unwrap().rows, modes);
            }
            None => assert_eq!(decoder.style(), plain_style(&spec)),
        }
    }

    #[test]
    fn the_paper_schedule_warms_up_and_steps_down_by_iterations() {
        let dir = tempfile::tempdir().unwrap();
        let work = Workspace {
            dataset: dir.path().to_path_buf(),
            frames: dir.path().join("frames.f64"),
            frame_memory: crate::pipeline::FRAME_MEMORY,
            checkpoints: dir.path().to_path_buf(),
            resume: false,
            bars: false,
        };
        let spec = ReducedSpec {
            plain_schedule: PlainSchedule::Paper,
            plain_blocks: 1,
            plain_hidden: 200,
            plain_epochs: 20000,
            ..ReducedSpec::default()
        };
        // 900 frames: 4 minibatches of 256 per epoch, so 500 epochs of warm-up and a decay
        // step every 7,500 epochs.
        let config = plain_config(&spec, 10, 900, 32, 1, &work);
        assert_eq!(config.batch_size, 256);
        assert_eq!(
            config.warmup_step,
            Some(WarmupStep {
                warmup: 500,
                factor: 0.8,
                every: 7500
            })
        );
        assert!((config.lr_at(0) - 1e-3 / 501.0).abs() < 1e-15);
        assert!(config.lr_at(499) < 1e-3);
        assert_eq!(config.lr_at(500), 1e-3);
        assert_eq!(config.lr_at(7499), 1e-3);
        assert!((config.lr_at(7500) - 8e-4).abs() < 1e-15);
        assert!(plain_tag(&spec).ends_with("-b1-paper"));
        let paper_layers = ReducedSpec {
            plain_activation: crate::learn::network::Activation::Elu,
            plain_residual: false,
            ..spec.clone()
        };
        assert!(plain_tag(&paper_layers).ends_with("-b1-paper-elu-layers"));
        assert_eq!(plain_style(&paper_layers), MlpStyle::PAPER);
        assert_eq!(plain_spec(&spec, 30, 10).blocks, 1);
        // The default keeps the cosine schedule and the names of earlier checkpoints.
        let plain = ReducedSpec::default();
        assert_eq!(plain_config(&plain, 10, 900, 32, 1, &work).warmup_step, None);
        assert_eq!(plain_tag(&plain), "h128-e2000-lr0.001-1e-5");
    }
}
