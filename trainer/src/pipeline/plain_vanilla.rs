//! The paper's vanilla subspace for `[reduced] vanilla = "plain-mlp"` (Lyu et al. 2024,
//! Eq. 3): an autoencoder of plain one-hidden-layer MLPs, randomly initialised and trained
//! on the reconstruction loss alone, independent of the latent model's PCA-initialised
//! autoencoder (whose latent size it takes).

use std::time::Instant;

use super::stages::Workspace;
use crate::error::TrainerResult;
use crate::learn::network::{Autoencoder, AutoencoderSpec, DecoderShape};
use crate::learn::reduced_spec::ReducedSpec;
use crate::learn::train::{self, AdamWConfig, CheckpointConfig, TrainConfig};

/// A trained plain vanilla autoencoder.
pub(crate) struct PlainVanilla {
    /// The autoencoder.
    pub(crate) autoencoder: Autoencoder,
    /// Mean loss of every epoch.
    pub(crate) losses: Vec<f64>,
    /// Training seconds (including those before a resumed checkpoint).
    pub(crate) seconds: f64,
}

/// The sizes of the plain autoencoder of `spec` for states of `input` values and latent `k`.
pub(crate) fn plain_spec(spec: &ReducedSpec, input: usize, k: usize) -> AutoencoderSpec {
    AutoencoderSpec {
        input,
        latent: k,
        hidden: spec.plain_hidden,
        blocks: 0,
        shape: DecoderShape::Mlp,
    }
}

/// What tells plain autoencoders of other settings apart (in checkpoint names).
pub(crate) fn plain_tag(spec: &ReducedSpec) -> String {
    format!(
        "h{}-e{}-lr{:?}-{:?}",
        spec.plain_hidden, spec.plain_epochs, spec.plain_learning_rate, spec.plain_final_learning_rate
    )
}

/// The training settings of the plain autoencoder (minibatches of `batch` frames).
pub(crate) fn plain_config(spec: &ReducedSpec, k: usize, batch: usize, seed: u64, work: &Workspace) -> TrainConfig {
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
        checkpoint: Some(CheckpointConfig {
            dir: work.checkpoints.clone(),
            every: 25,
        }),
        progress: work.bars,
    }
}

/// Trains the plain autoencoder of `spec` (latent `k`) on the encoded frames `data`.
pub(crate) fn train_plain_vanilla(
    spec: &ReducedSpec,
    data: &[Vec<f32>],
    k: usize,
    batch: usize,
    seed: u64,
    work: &Workspace,
) -> TrainerResult<PlainVanilla> {
    let input = data.first().map_or(0, Vec::len);
    let autoencoder = Autoencoder::new(plain_spec(spec, input, k), seed)?;
    let clock = Instant::now();
    let config = plain_config(spec, k, batch, seed, work);
    let report = train::train_autoencoder(&autoencoder, data, &config, work.resume, None)?;
    Ok(PlainVanilla {
        autoencoder,
        losses: report.losses,
        seconds: clock.elapsed().as_secs_f64() + report.earlier_seconds,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::samples::fixtures::tiny_beam;

    /// The plain autoencoder learns the tiny beam's frames from a random start: its
    /// reconstruction error falls far below the start's, and its decoder has no residual
    /// block.
    #[test]
    fn the_plain_autoencoder_learns_the_frames() {
        let beam = tiny_beam();
        let data: Vec<Vec<f32>> = beam.sequences[0]
            .encoded
            .iter()
            .map(|q| q.iter().map(|&v| v as f32).collect())
            .collect();
        let spec = ReducedSpec {
            plain_hidden: 16,
            plain_epochs: 150,
            plain_learning_rate: 3e-3,
            ..ReducedSpec::default()
        };
        let dir = tempfile::tempdir().unwrap();
        let work = Workspace {
            dataset: dir.path().to_path_buf(),
            checkpoints: dir.path().to_path_buf(),
            resume: false,
            bars: false,
        };
        let start = Autoencoder::new(plain_spec(&spec, data[0].len(), 3), 1).unwrap();
        let before = train::mean_reconstruction_error(&start, &data, 64).unwrap();
        let trained = train_plain_vanilla(&spec, &data, 3, 4, 1, &work).unwrap();
        let after = train::mean_reconstruction_error(&trained.autoencoder, &data, 64).unwrap();
        assert_eq!(trained.losses.len(), 150);
        assert!(after < 1e-2 * before, "reconstruction {before:.3e} -> {after:.3e}");
        let exported = trained.autoencoder.export().unwrap();
        assert_eq!(exported.decoder.as_mlp().unwrap().spec().blocks, 0);
    }
}
