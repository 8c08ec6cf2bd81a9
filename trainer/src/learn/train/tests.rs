//! Tests of the training loop, AdamW and checkpoints.

use super::*;
use crate::learn::network::test_support::{manifold_data, pca, pca_reconstruction_error};
use crate::learn::network::AutoencoderSpec;
use candle_core::Device;
use std::fs;
use std::path::Path;

fn config(name: &str, epochs: usize, batch_size: usize, lr: f64) -> TrainConfig {
    TrainConfig {
        name: name.into(),
        epochs,
        batch_size,
        seed: 42,
        optimizer: AdamWConfig {
            lr,
            ..AdamWConfig::default()
        },
        final_lr: None,
        warmup_step: None,
        checkpoint: None,
        progress: false,
    }
}

fn with_checkpoints(mut config: TrainConfig, dir: &Path, every: usize) -> TrainConfig {
    config.checkpoint = Some(CheckpointConfig {
        dir: dir.to_path_buf(),
        every,
    });
    config
}

/// Every parameter's f32 bit patterns, for exact comparison.
fn weight_bits(params: &[(String, Var)]) -> Vec<(String, Vec<u32>)> {
    params
        .iter()
        .map(|(name, var)| {
            let values = var.as_tensor().flatten_all().unwrap().to_vec1::<f32>().unwrap();
            (name.clone(), values.iter().map(|v| v.to_bits()).collect())
        })
        .collect()
}

#[test]
fn autoencoder_learns_a_nonlinear_manifold() {
    let data = manifold_data(256, 30, 1);
    let spec = AutoencoderSpec {
        input: 30,
        latent: 2,
        hidden: 32,
        blocks: 2,
        shape: crate::learn::network::DecoderShape::Mlp,
    };
    let ae = Autoencoder::new(spec, 7).unwrap();
    let initial = mean_reconstruction_error(&ae, &data, 64).unwrap();
    let report = train_autoencoder(&ae, &data, &config("ae", 150, 32, 3e-3), false, None).unwrap();
    let trained = mean_reconstruction_error(&ae, &data, 64).unwrap();
    assert_eq!(report.start_epoch, 0);
    assert_eq!(report.losses.len(), 150);
    assert!(trained * 10.0 < initial, "error fell only from {initial} to {trained}");
    // A 2D linear subspace cannot do that: the autoencoder beats PCA with 2 components.
    let (mean, basis) = pca(&data, 2);
    let linear = pca_reconstruction_error(&data, &mean, &basis);
    assert!(trained < linear, "autoencoder {trained} vs PCA {linear}");
}

#[test]
fn pca_initialised_autoencoder_starts_at_the_pca_error() {
    let data = manifold_data(256, 30, 2);
    let (mean, basis) = pca(&data, 3);
    let spec = AutoencoderSpec {
        input: 30,
        latent: 3,
        hidden: 24,
        blocks: 2,
        shape: crate::learn::network::DecoderShape::Mlp,
    };
    let ae = Autoencoder::new_pca_init(spec, &mean, &basis, 3).unwrap();
    let linear = pca_reconstruction_error(&data, &mean, &basis);
    let initial = mean_reconstruction_error(&ae, &data, 64).unwrap();
    assert!(
        (initial - linear).abs() < 1e-3 * linear,
        "initial error {initial}, PCA error {linear}"
    );
    let report = train_autoencoder(&ae, &data, &config("pca", 40, 32, 1e-3), false, None).unwrap();
    let trained = mean_reconstruction_error(&ae, &data, 64).unwrap();
    // Training starts from the PCA and only improves on it.
    assert!((report.losses[0] - linear).abs() < 0.5 * linear);
    assert!(trained < 0.8 * linear, "trained {trained}, PCA {linear}");
}

/// A denoising reconstruction loss that draws from the batch generator, so resuming must
/// also reproduce the generator streams.
fn noisy_loss(ae: &Autoencoder, batch: &Batch<'_>, rng: &mut ChaCha8Rng) -> candle_core::Result<BatchLoss> {
    use rand::Rng;
    let (n, d) = batch.inputs.dims2()?;
    let noise: Vec<f32> = (0..n * d).map(|_| rng.random_range(-0.01..0.01)).collect();
    let noisy = (&batch.inputs + Tensor::from_vec(noise, (n, d), &Device::Cpu)?)?;
    let error = (ae.reconstruct(&noisy)? - &batch.inputs)?;
    BatchLoss::new(error.sqr()?.mean_all()?)
}

const TINY: AutoencoderSpec = AutoencoderSpec {
    input: 6,
    latent: 2,
    hidden: 8,
    blocks: 1,
    shape: crate::learn::network::DecoderShape::Mlp,
};

#[test]
fn resume_is_bit_exact() {
    let data = manifold_data(40, 6, 3);
    let dir = tempfile::tempdir().unwrap();
    let full = with_checkpoints(config("full", 6, 8, 1e-2), &dir.path().join("a"), 2);
    let reference = Autoencoder::new(TINY, 11).unwrap();
    let uninterrupted = train(&reference.parameters(), &data, &full, false, |b, r| {
        noisy_loss(&reference, b, r)
    })
    .unwrap();

    // N epochs, then resume to 2N.
    let split = with_checkpoints(config("full", 3, 8, 1e-2), &dir.path().join("b"), 2);
    let ae = Autoencoder::new(TINY, 11).unwrap();
    let first = train(&ae.parameters(), &data, &split, true, |b, r| noisy_loss(&ae, b, r)).unwrap();
    assert_eq!(first.earlier_seconds, 0.0, "nothing to resume");
    let rest = TrainConfig { epochs: 6, ..split };
    let resumed = train(&ae.parameters(), &data, &rest, true, |b, r| noisy_loss(&ae, b, r)).unwrap();
    assert_eq!(resumed.start_epoch, 3);
    assert_eq!(resumed.losses, uninterrupted.losses);
    // The resumed run knows what the first three epochs cost.
    assert!(resumed.earlier_seconds > 0.0, "{resumed:?}");
    assert!(
        weight_bits(&ae.parameters()) == weight_bits(&reference.parameters()),
        "weights differ"
    );

    // Interrupted mid-epoch 5: the epoch-4 checkpoint is resumed in a fresh process state.
    let crashing = with_checkpoints(config("full", 6, 8, 1e-2), &dir.path().join("c"), 2);
    let ae = Autoencoder::new(TINY, 11).unwrap();
    // (epoch, batch within the epoch) of the latest call.
    let mut at = (usize::MAX, 0);
    let crash = train(&ae.parameters(), &data, &crashing, false, |b, r| {
        at = if at.0 == b.epoch {
            (b.epoch, at.1 + 1)
        } else {
            (b.epoch, 0)
        };
        if at == (4, 2) {
            return Err(candle_core::Error::Msg("interrupted".into()));
        }
        noisy_loss(&ae, b, r)
    });
    assert!(crash.unwrap_err().to_string().contains("interrupted"));
    let ae = Autoencoder::new(TINY, 11).unwrap();
    let resumed = train(&ae.parameters(), &data, &crashing, true, |b, r| noisy_loss(&ae, b, r)).unwrap();
    assert_eq!(resumed.start_epoch, 4);
    assert_eq!(resumed.losses, uninterrupted.losses);
    assert!(
        weight_bits(&ae.parameters()) == weight_bits(&reference.parameters()),
        "weights differ"
    );

    // Resuming a finished run changes nothing.
    let again = train(&ae.parameters(), &data, &crashing, true, |b, r| noisy_loss(&ae, b, r)).unwrap();
    assert_eq!(again.start_epoch, 6);
    assert!(
        weight_bits(&ae.parameters()) == weight_bits(&reference.parameters()),
        "weights differ"
    );
}

#[test]
fn bad_checkpoints_are_refused_without_touching_the_weights() {
    let data = manifold_data(24, 6, 4);
    let dir = tempfile::tempdir().unwrap();
    let cfg = with_checkpoints(config("run", 2, 8, 1e-2), dir.path(), 1);
    let ae = Autoencoder::new(TINY, 1).unwrap();
    train_autoencoder(&ae, &data, &cfg, false, None).unwrap();
    let path = cfg.checkpoint_path().unwrap();
    let good = fs::read(&path).unwrap();

    let fresh = Autoencoder::new(TINY, 1).unwrap();
    let before = weight_bits(&fresh.parameters());
    let more = TrainConfig {
        epochs: 3,
        ..cfg.clone()
    };
    let refused = |bytes: &[u8], cfg: &TrainConfig, ae: &Autoencoder| -> String {
        fs::write(&path, bytes).unwrap();
        let err = train_autoencoder(ae, &data, cfg, true, None).unwrap_err();
        assert!(matches!(err, TrainError::Checkpoint(_)), "{err:?}");
        err.to_string()
    };

    let mut flipped = good.clone();
    let middle = flipped.len() / 2;
    flipped[middle] ^= 0x10;
    assert!(refused(&flipped, &more, &fresh).contains("CRC-32"));
    assert!(refused(&good[..good.len() - 7], &more, &fresh).contains("truncated"));
    assert!(refused(&good[..10], &more, &fresh).contains("truncated"));
    assert!(refused(b"{\"not\": \"a checkpoint\"}", &more, &fresh).contains("not a mochi checkpoint"));
    let other_seed = TrainConfig {
        seed: 43,
        ..more.clone()
    };
    assert!(refused(&good, &other_seed, &fresh).contains("different run"));
    let wider = Autoencoder::new(AutoencoderSpec { hidden: 9, ..TINY }, 1).unwrap();
    assert!(refused(&good, &more, &wider).contains("different network"));
    let shorter = TrainConfig {
        epochs: 1,
        ..cfg.clone()
    };
    assert!(refused(&good, &shorter, &fresh).contains("beyond"));
    assert!(
        weight_bits(&fresh.parameters()) == before,
        "a refused checkpoint changed the weights"
    );

    // The intact file still resumes.
    fs::write(&path, &good).unwrap();
    let report = train_autoencoder(&fresh, &data, &more, true, None).unwrap();
    assert_eq!(report.start_epoch, 2);
}

#[test]
fn invalid_runs_are_errors() {
    let ae = Autoencoder::new(TINY, 1).unwrap();
    let cfg = config("x", 1, 4, 1e-3);
    assert!(matches!(
        train_autoencoder(&ae, &Vec::<Vec<f32>>::new(), &cfg, false, None),
        Err(TrainError::Invalid(_))
    ));
    let ragged = vec![vec![0.0; 6], vec![0.0; 5]];
    assert!(matches!(
        train_autoencoder(&ae, &ragged, &cfg, false, None),
        Err(TrainError::Invalid(_))
    ));
    let wrong_dim = vec![vec![0.0; 7]; 3];
    assert!(matches!(
        train_autoencoder(&ae, &wrong_dim, &cfg, false, None),
        Err(TrainError::Invalid(_))
    ));
    let zero_batch = TrainConfig {
        batch_size: 0,
        ..cfg.clone()
    };
    assert!(train_autoencoder(&ae, &vec![vec![0.0; 6]], &zero_batch, false, None).is_err());
    let nan = vec![vec![f32::NAN; 6]; 3];
    assert!(matches!(
        train_autoencoder(&ae, &nan, &cfg, false, None),
        Err(TrainError::NonFinite { .. })
    ));
    let mut params = ae.parameters();
    params.push(params[0].clone());
    assert!(AdamW::new(&params, AdamWConfig::default()).is_err());
}

/// A sum of losses (the physics loss with a data term) has the summed value and, through its
/// objective, the weighted sum of both gradients.
#[test]
fn a_weighted_sum_of_losses_adds_values_and_gradients() {
    let x = Var::from_vec(vec![1.0f32, -2.0, 0.5], 3, &Device::Cpu).unwrap();
    let first = BatchLoss::new(x.as_tensor().sqr().unwrap().sum_all().unwrap()).unwrap();
    let second = BatchLoss::new((x.as_tensor() * 3.0).unwrap().sum_all().unwrap()).unwrap();
    let (a, b) = (first.value, second.value);
    let sum = first.plus(second, 0.25).unwrap();
    assert!(
        (sum.value - (a + 0.25 * b)).abs() < 1e-9,
        "{} against {}",
        sum.value,
        a + 0.25 * b
    );
    let grads = sum.objective.backward().unwrap();
    let g = grads.get(x.as_tensor()).unwrap().to_vec1::<f32>().unwrap();
    // d/dx (x^2 + 0.25 * 3x) = 2x + 0.75.
    for (g, x) in g.iter().zip([1.0f32, -2.0, 0.5]) {
        assert!((g - (2.0 * x + 0.75)).abs() < 1e-6, "{g} at {x}");
    }
}
