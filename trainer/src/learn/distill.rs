//! Decoder distillation: a cheap decoder (a small residual MLP before a linear basis of `m`
//! modes, [`DecoderShape::Basis`]) fitted to reproduce a trained decoder on the latents its
//! integrator visits. The integrator is kept as it is, so the model's latent trajectories do
//! not change; only the decoder's cost does (docs/design.md, decision 6).
//!
//! The basis is the PCA of the teacher's outputs on those latents (the `m` modes that hold
//! most of its variance); the MLP `g` learns the coefficients. With `f(z) = pad(z) + g(z)`
//! and the basis orthonormal, `|B f(z) + b - y|² = |f(z) - Bᵀ(y - b)|² + |residual of y|²`,
//! so the fit runs in the `m` coefficients instead of the full output.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::network::{
    forward_exported, Decoder, DecoderShape, DenseLayer, ExportedMlp, FrozenDecoder, MlpSpec, ResMlp,
};
use super::pca::Pca;
use super::train::{self, BatchLoss, TrainConfig, TrainError, TrainResult};

/// The shape of a distilled decoder.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DistillShape {
    /// Columns of the basis `m` (at least the latent size).
    pub modes: usize,
    /// Width of the MLP before the basis.
    pub hidden: usize,
    /// Its residual blocks.
    pub blocks: usize,
}

/// A distilled decoder and how closely it follows its teacher.
#[derive(Debug, Clone)]
pub struct Distilled {
    /// The decoder.
    pub decoder: FrozenDecoder,
    /// Mean loss of every epoch (mean squared coefficient error).
    pub losses: Vec<f64>,
    /// RMS over the held-out latents and output values of the teacher's output minus its
    /// projection onto the basis: what no MLP before this basis can recover.
    pub basis_rms: f64,
    /// RMS over the held-out latents and output values of the distilled decoder's output
    /// minus the teacher's.
    pub fit_rms: f64,
    /// The PCA of the outputs whose leading components are the basis.
    pub pca: Pca,
}

/// Distils `teacher` into a basis decoder of `shape`, fitted on the latents `train` and
/// checked on the latents `held_out` (each of the teacher's latent size), with the training
/// settings `config` (its batch rows are latents with their target coefficients).
pub fn distill_decoder(
    teacher: &FrozenDecoder,
    train: &[Vec<f32>],
    held_out: &[Vec<f32>],
    shape: DistillShape,
    config: &TrainConfig,
) -> TrainResult<Distilled> {
    let k = teacher.latent();
    if train.is_empty() || held_out.is_empty() {
        return Err(TrainError::Invalid(
            "distillation needs training and held-out latents".into(),
        ));
    }
    if let Some(z) = train.iter().chain(held_out).find(|z| z.len() != k) {
        return Err(TrainError::Invalid(format!(
            "a latent of {} values for a decoder of latent size {k}",
            z.len()
        )));
    }
    let outputs = teacher_outputs(teacher, train)?;
    let held_outputs = teacher_outputs(teacher, held_out)?;
    distill_outputs((train, &outputs), (held_out, &held_outputs), shape, config)
}

/// Fits a basis decoder of `shape` to the outputs `train.1` of the latents `train.0` and
/// checks it on `held_out` (latents and their outputs), with the training settings `config`:
/// [`distill_decoder`] with the outputs given instead of a teacher's (e.g. the teacher's
/// decoding in another encoding).
pub fn distill_outputs(
    train: (&[Vec<f32>], &[Vec<f64>]),
    held_out: (&[Vec<f32>], &[Vec<f64>]),
    shape: DistillShape,
    config: &TrainConfig,
) -> TrainResult<Distilled> {
    let ((train, outputs), (held_out, held_outputs)) = (train, held_out);
    let k = train.first().map_or(0, Vec::len);
    if train.is_empty() || held_out.is_empty() || outputs.len() != train.len() || held_outputs.len() != held_out.len() {
        return Err(TrainError::Invalid(
            "distillation needs training and held-out latents, each with its output".into(),
        ));
    }
    let pca = Pca::fit(outputs, shape.modes).map_err(invalid)?;
    let decoder_shape = DecoderShape::Basis {
        modes: shape.modes,
        hidden: shape.hidden,
        blocks: shape.blocks,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let decoder = Decoder::basis_from_pca(k, decoder_shape, &pca.mean, &pca.basis, &mut rng).map_err(invalid)?;
    let Decoder::Basis { mlp: Some(g), .. } = &decoder else {
        return Err(TrainError::Invalid(
            "a distilled decoder needs an MLP before its basis (hidden > 0)".into(),
        ));
    };
    // Each row: the latent, then the coefficients `g` must add to `pad(z)`.
    let rows: Vec<Vec<f32>> = train
        .iter()
        .zip(outputs)
        .map(|(z, y)| {
            let c = pca.project(y).map_err(invalid)?;
            let mut row = z.clone();
            row.extend(
                c.iter()
                    .enumerate()
                    .map(|(i, &c)| (c - z.get(i).map_or(0.0, |&z| z as f64)) as f32),
            );
            Ok(row)
        })
        .collect::<TrainResult<_>>()?;
    let m = shape.modes;
    let report = train::train(&g.parameters("g"), &rows, config, false, |batch, _| {
        let z = batch.inputs.narrow(1, 0, k)?;
        let target = batch.inputs.narrow(1, k, m)?;
        BatchLoss::new((g.forward(&z)? - target)?.sqr()?.mean_all()?)
    })?;
    let frozen = decoder.export().map_err(invalid)?;
    let (mut basis_sum, mut fit_sum, mut count) = (0.0, 0.0, 0usize);
    for (z, y) in held_out.iter().zip(held_outputs) {
        let projected = pca.project(y).and_then(|c| pca.reconstruct(&c)).map_err(invalid)?;
        let student = frozen
            .decode::<f64>(&z.iter().map(|&v| v as f64).collect::<Vec<_>>())
            .map_err(invalid)?;
        for ((&y, &p), &s) in y.iter().zip(&projected).zip(&student) {
            basis_sum += (y - p).powi(2);
            fit_sum += (y - s).powi(2);
        }
        count += y.len();
    }
    let rms = |sum: f64| (sum / count.max(1) as f64).sqrt();
    Ok(Distilled {
        decoder: frozen,
        losses: report.losses,
        basis_rms: rms(basis_sum),
        fit_rms: rms(fit_sum),
        pca,
    })
}

/// Fits an encoder (outputs -> latent) to the pairs `train` of a distillation whose basis
/// came from `pca`: a residual MLP of width `hidden` (one block) learns the latent from the
/// output's `m` basis coefficients, and the projection onto the basis is then folded into
/// its input layer, so the encoder reads the output itself. Returns it with the RMS latent
/// error on `held_out`.
pub fn distill_encoder(
    train: (&[Vec<f32>], &[Vec<f64>]),
    held_out: (&[Vec<f32>], &[Vec<f64>]),
    pca: &Pca,
    hidden: usize,
    config: &TrainConfig,
) -> TrainResult<(ExportedMlp, f64)> {
    let (m, n) = (pca.basis.len(), pca.mean.len());
    let k = train.0.first().map_or(0, Vec::len);
    if k == 0 || m == 0 || hidden == 0 {
        return Err(TrainError::Invalid(
            "an encoder fit needs latents, a basis and a hidden width".into(),
        ));
    }
    let coefficients = |y: &Vec<f64>| pca.project(y).map_err(invalid);
    // Each row: the coefficients, then the latent.
    let rows: Vec<Vec<f32>> = train
        .0
        .iter()
        .zip(train.1)
        .map(|(z, y)| {
            let mut row: Vec<f32> = coefficients(y)?.iter().map(|&c| c as f32).collect();
            row.extend_from_slice(z);
            Ok(row)
        })
        .collect::<TrainResult<_>>()?;
    let spec = MlpSpec {
        input: m,
        output: k,
        hidden,
        blocks: 1,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let mlp = ResMlp::new(spec, &mut rng).map_err(invalid)?;
    train::train(&mlp.parameters("e"), &rows, config, false, |batch, _| {
        let c = batch.inputs.narrow(1, 0, m)?;
        let z = batch.inputs.narrow(1, m, k)?;
        BatchLoss::new((mlp.forward(&c)? - z)?.sqr()?.mean_all()?)
    })?;
    let exported = mlp.export().map_err(invalid)?;
    // W (B^T (y - mean)) + b = (W B^T) y + (b - W B^T mean).
    let mut layers = exported.layers().into_iter().cloned().collect::<Vec<DenseLayer>>();
    let first = &layers[0];
    let mut weights = vec![0.0f32; first.rows * n];
    let mut bias = first.bias.clone();
    for r in 0..first.rows {
        let row = &mut weights[r * n..(r + 1) * n];
        for (j, component) in pca.basis.iter().enumerate() {
            let w = first.weights[r * m + j] as f64;
            for ((out, &b), &mean) in row.iter_mut().zip(component).zip(&pca.mean) {
                *out += (w * b) as f32;
                bias[r] -= (w * b * mean) as f32;
            }
        }
    }
    layers[0] = DenseLayer {
        rows: first.rows,
        cols: n,
        weights,
        bias,
    };
    let encoder = ExportedMlp::from_layers(layers).map_err(invalid)?;
    let (mut sum, mut count) = (0.0, 0usize);
    for (z, y) in held_out.0.iter().zip(held_out.1) {
        let e = forward_exported(&encoder, &y.iter().map(|&v| v as f32).collect::<Vec<_>>()).map_err(invalid)?;
        sum += e.iter().zip(z).map(|(a, b)| (a - b).powi(2) as f64).sum::<f64>();
        count += z.len();
    }
    Ok((encoder, (sum / count.max(1) as f64).sqrt()))
}

/// A network or PCA error as the training's own.
fn invalid(e: impl std::fmt::Display) -> TrainError {
    TrainError::Invalid(e.to_string())
}

/// The teacher's output (f64) for every latent.
fn teacher_outputs(teacher: &FrozenDecoder, latents: &[Vec<f32>]) -> TrainResult<Vec<Vec<f64>>> {
    latents
        .iter()
        .map(|z| {
            let z: Vec<f64> = z.iter().map(|&v| v as f64).collect();
            teacher.decode::<f64>(&z).map_err(invalid)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::train::AdamWConfig;

    /// A teacher whose outputs lie on a curved 2-D manifold in 12 values.
    fn teacher() -> FrozenDecoder {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let spec = crate::learn::network::MlpSpec {
            input: 2,
            output: 12,
            hidden: 16,
            blocks: 1,
        };
        let mlp = crate::learn::network::ResMlp::new(spec, &mut rng).unwrap();
        FrozenDecoder::Mlp(mlp.export().unwrap())
    }

    fn latents(n: usize, seed: u64) -> Vec<Vec<f32>> {
        use rand::Rng;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| vec![rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)])
            .collect()
    }

    fn config(epochs: usize) -> TrainConfig {
        TrainConfig {
            name: "distill-test".into(),
            epochs,
            batch_size: 32,
            seed: 1,
            optimizer: AdamWConfig {
                lr: 3e-3,
                ..AdamWConfig::default()
            },
            final_lr: Some(1e-4),
            warmup_step: None,
            checkpoint: None,
            progress: false,
        }
    }

    #[test]
    fn the_distilled_decoder_follows_its_teacher_on_held_out_latents() {
        let teacher = teacher();
        let (train, held) = (latents(512, 1), latents(64, 2));
        let shape = DistillShape {
            modes: 6,
            hidden: 16,
            blocks: 1,
        };
        // The spread of the teacher's outputs about their mean: the scale of the errors.
        let outputs = teacher_outputs(&teacher, &held).unwrap();
        let n = outputs.len() as f64 * 12.0;
        let mean: Vec<f64> = (0..12)
            .map(|j| outputs.iter().map(|y| y[j]).sum::<f64>() * 12.0 / n)
            .collect();
        let spread = (outputs
            .iter()
            .flat_map(|y| y.iter().zip(&mean).map(|(a, b)| (a - b).powi(2)))
            .sum::<f64>()
            / n)
            .sqrt();
        let untrained = distill_decoder(&teacher, &train, &held, shape, &config(0)).unwrap();
        let trained = distill_decoder(&teacher, &train, &held, shape, &config(150)).unwrap();
        assert!(
            trained.losses.last().unwrap() < &(0.05 * trained.losses[0]),
            "{:?}",
            trained.losses
        );
        assert!(
            trained.fit_rms < 0.1 * untrained.fit_rms,
            "{} vs {}",
            trained.fit_rms,
            untrained.fit_rms
        );
        assert!(
            trained.fit_rms < 0.05 * spread,
            "{} vs spread {spread}",
            trained.fit_rms
        );
        assert!(trained.basis_rms <= trained.fit_rms + 1e-12);
        assert_eq!(trained.decoder.latent(), 2);
        assert_eq!(trained.decoder.output(), 12);
        assert!(trained.decoder.is_basis());
    }

    #[test]
    fn latents_of_the_wrong_size_are_refused() {
        let teacher = teacher();
        let shape = DistillShape {
            modes: 4,
            hidden: 8,
            blocks: 0,
        };
        let err = distill_decoder(&teacher, &[vec![0.0; 3]], &latents(4, 2), shape, &config(1)).unwrap_err();
        assert!(err.to_string().contains("latent of 3 values"), "{err}");
        let linear = DistillShape { hidden: 0, ..shape };
        let err = distill_decoder(&teacher, &latents(8, 1), &latents(4, 2), linear, &config(1)).unwrap_err();
        assert!(err.to_string().contains("latent"), "{err}");
    }
}
