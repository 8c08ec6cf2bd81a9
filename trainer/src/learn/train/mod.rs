//! The training loop shared by the autoencoder and the latent integrator: seeded minibatches,
//! AdamW, a loss closure, a progress bar, periodic checkpoints and `--resume` that ends with
//! exactly the weights of an uninterrupted run.
//!
//! Determinism: epoch `e` shuffles the dataset with a ChaCha8 generator seeded by the run's seed
//! on stream `2e`, and hands the loss closure a generator on stream `2e + 1` (for noise
//! augmentation), so an epoch depends only on the seed, its number and the state at its start.
//! A checkpoint, written at the end of an epoch, holds that state completely: the parameters,
//! AdamW's moments and step count, and the loss history. Resuming from it therefore repeats the
//! uninterrupted run bit for bit (candle's CPU kernels are deterministic for a fixed thread
//! count).
//!
//! # Checkpoint file
//!
//! `DIR/NAME.ckpt`, replaced atomically (written beside it, then renamed):
//!
//! ```text
//! b"MOCHICKP" | format version: u32 LE | payload length: u64 LE | CRC-32 of payload: u32 LE
//! payload: safetensors with tensors "param/NAME", "adam.m/NAME", "adam.v/NAME" (f32),
//!          "history.loss" (f64, mean loss per finished epoch) and string metadata
//!          (epoch, adam_step, seed, batch_size, dataset_len, input_dim, optimiser settings)
//! ```

mod adamw;
mod checkpoint;
#[cfg(test)]
mod tests;

use std::path::PathBuf;

use candle_core::{Tensor, Var};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::learn::frame_rows::Rows;
use crate::learn::network::Autoencoder;
use crate::learn::stretch::EdgeStretch;
use crate::progress::EpochsBar;
use mochi_sim::error::InputError;

pub use adamw::{AdamW, AdamWConfig};
pub(crate) use checkpoint::write_atomically;
use checkpoint::{load_checkpoint, save_checkpoint, RunIdentity};

/// Errors of a training run.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// A checkpoint could not be used (corrupt, truncated, or from a different run).
    #[error(transparent)]
    Checkpoint(#[from] InputError),
    /// A checkpoint could not be written.
    #[error("writing checkpoint {path}: {source}")]
    Write {
        /// The file being written.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The dataset or configuration cannot be trained on.
    #[error("{0}")]
    Invalid(String),
    /// The loss became NaN or infinite.
    #[error("loss is not finite ({value}) in epoch {epoch}, batch {batch}")]
    NonFinite {
        /// The loss value.
        value: f64,
        /// 0-based epoch.
        epoch: usize,
        /// 0-based batch within the epoch.
        batch: usize,
    },
    /// candle failed (including errors raised by the loss closure).
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
    /// The training frames could not be read back from their file.
    #[error("reading the training frames: {0}")]
    Read(#[from] std::io::Error),
}

/// Result of this module's functions.
pub type TrainResult<T> = Result<T, TrainError>;

/// Where and how often to checkpoint.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckpointConfig {
    /// Directory of the checkpoint file (created if missing).
    pub dir: PathBuf,
    /// Write after every this many epochs (and always after the last one); at least 1.
    pub every: usize,
}

/// Settings of one training run.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainConfig {
    /// Name of the run: checkpoint file stem and progress-bar label.
    pub name: String,
    /// Total epochs (a resumed run continues up to this count).
    pub epochs: usize,
    /// Samples per minibatch (the last batch of an epoch may be smaller).
    pub batch_size: usize,
    /// Seed of the shuffling and of the loss closure's generator.
    pub seed: u64,
    /// Optimiser settings.
    pub optimizer: AdamWConfig,
    /// Cosine decay of the learning rate from `optimizer.lr` at epoch 0 to this at the last
    /// epoch; `None` keeps it constant.
    pub final_lr: Option<f64>,
    /// A linear warm-up and step decay instead (Lyu et al.'s schedule); `final_lr` is then
    /// ignored.
    pub warmup_step: Option<WarmupStep>,
    /// Periodic checkpoints; `None` writes none (and `resume` then has nothing to resume).
    pub checkpoint: Option<CheckpointConfig>,
    /// Show a progress bar on the terminal.
    pub progress: bool,
}

/// A learning-rate schedule: `lr * min(1, (e + 1) / (warmup + 1)) * factor^(e / every)` at
/// epoch `e`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WarmupStep {
    /// Epochs of linear warm-up.
    pub warmup: usize,
    /// The factor of each decay step.
    pub factor: f64,
    /// Epochs between decay steps (at least 1).
    pub every: usize,
}

impl TrainConfig {
    /// The learning rate of `epoch`.
    pub fn lr_at(&self, epoch: usize) -> f64 {
        let start = self.optimizer.lr;
        if let Some(WarmupStep { warmup, factor, every }) = self.warmup_step {
            let ramp = ((epoch + 1) as f64 / (warmup + 1) as f64).min(1.0);
            return start * ramp * factor.powi((epoch / every.max(1)) as i32);
        }
        match self.final_lr {
            Some(end) if self.epochs > 1 => {
                let t = epoch.min(self.epochs - 1) as f64 / (self.epochs - 1) as f64;
                end + 0.5 * (start - end) * (1.0 + (std::f64::consts::PI * t).cos())
            }
            _ => start,
        }
    }

    /// The checkpoint file of this run, if it checkpoints.
    pub fn checkpoint_path(&self) -> Option<PathBuf> {
        let c = self.checkpoint.as_ref()?;
        Some(c.dir.join(format!("{}.ckpt", self.name)))
    }
}

/// One minibatch handed to the loss closure.
#[derive(Debug)]
pub struct Batch<'a> {
    /// The samples, `(batch, dim)`.
    pub inputs: Tensor,
    /// The dataset rows of the samples, in the order of `inputs`.
    pub indices: &'a [usize],
    /// 0-based epoch.
    pub epoch: usize,
}

/// What the loss closure returns for one batch.
#[derive(Debug)]
pub struct BatchLoss {
    /// Scalar tensor whose gradient w.r.t. the parameters is the training gradient (for the
    /// physics loss this is the surrogate `sum(x * stopgrad(dE/dx))`, docs/design.md, decision 2).
    pub objective: Tensor,
    /// The loss value reported and recorded (the objective's value unless it is a surrogate).
    pub value: f64,
}

impl BatchLoss {
    /// A loss whose reported value is the objective itself.
    pub fn new(objective: Tensor) -> candle_core::Result<Self> {
        let value = objective.to_dtype(candle_core::DType::F64)?.to_scalar::<f64>()?;
        Ok(BatchLoss { objective, value })
    }

    /// This loss plus `weight` times `other` (objectives and reported values alike).
    pub fn plus(self, other: BatchLoss, weight: f64) -> candle_core::Result<Self> {
        Ok(BatchLoss {
            objective: (self.objective + (other.objective * weight)?)?,
            value: self.value + weight * other.value,
        })
    }
}

/// Outcome of [`train`].
#[derive(Debug, Clone, PartialEq)]
pub struct TrainReport {
    /// The epoch training started from: 0, or the checkpoint's epoch when resumed.
    pub start_epoch: usize,
    /// Mean loss (weighted by batch size) of every finished epoch, including those before a
    /// resumed checkpoint.
    pub losses: Vec<f64>,
    /// Training seconds spent before this call, as recorded in the checkpoint it resumed
    /// from (0 for a fresh run), so that a resumed stage reports its whole cost.
    pub earlier_seconds: f64,
}

/// Trains `params` on `data` (equal-length rows, gathered a minibatch at a time: in memory or
/// read from a file) for `config.epochs` epochs with AdamW,
/// minimising `loss(batch, rng)`. With `resume`, continues from the checkpoint if there is
/// one (checking that it belongs to this run) and ends with the same weights as an
/// uninterrupted run; without, starts afresh and overwrites old checkpoints.
pub fn train<R, F>(
    params: &[(String, Var)],
    data: &R,
    config: &TrainConfig,
    resume: bool,
    mut loss: F,
) -> TrainResult<TrainReport>
where
    R: Rows + ?Sized,
    F: FnMut(&Batch<'_>, &mut ChaCha8Rng) -> candle_core::Result<BatchLoss>,
{
    let dim = check_dataset(data)?;
    if config.batch_size == 0 {
        return Err(TrainError::Invalid("batch size must be positive".into()));
    }
    if config.checkpoint.as_ref().is_some_and(|c| c.every == 0) {
        return Err(TrainError::Invalid(
            "checkpoint interval must be at least 1 epoch".into(),
        ));
    }
    let mut optimizer = AdamW::new(params, config.optimizer)?;
    let run = RunIdentity::new(config, data.count(), dim);
    let clock = std::time::Instant::now();
    let (mut losses, mut earlier_seconds) = (Vec::new(), 0.0);
    if resume {
        if let Some(path) = config.checkpoint_path().filter(|p| p.exists()) {
            (losses, earlier_seconds) = load_checkpoint(&path, &run, config.epochs, &mut optimizer)?;
        }
    }
    let start_epoch = losses.len();

    let bar = EpochsBar::new(&config.name, config.epochs, start_epoch, config.progress);
    for epoch in start_epoch..config.epochs {
        optimizer.set_lr(config.lr_at(epoch));
        let mut order: Vec<usize> = (0..data.count()).collect();
        order.shuffle(&mut epoch_rng(config.seed, 2 * epoch as u64));
        let mut rng = epoch_rng(config.seed, 2 * epoch as u64 + 1);
        let mut total = 0.0;
        for (batch, indices) in order.chunks(config.batch_size).enumerate() {
            let inputs = gathered(data, indices, dim)?;
            let step = loss(&Batch { inputs, indices, epoch }, &mut rng)?;
            if !step.value.is_finite() {
                return Err(TrainError::NonFinite {
                    value: step.value,
                    epoch,
                    batch,
                });
            }
            optimizer.step(&step.objective.backward()?)?;
            total += step.value * indices.len() as f64;
        }
        losses.push(total / data.count() as f64);
        bar.epoch(total / data.count() as f64);
        if let (Some(path), Some(c)) = (config.checkpoint_path(), &config.checkpoint) {
            let done = epoch + 1;
            if done.is_multiple_of(c.every) || done == config.epochs {
                let seconds = earlier_seconds + clock.elapsed().as_secs_f64();
                save_checkpoint(&path, &run, &optimizer, &losses, seconds)?;
            }
        }
    }
    bar.finish();
    Ok(TrainReport {
        start_epoch,
        losses,
        earlier_seconds,
    })
}

/// Trains the autoencoder on states `data` with the reconstruction loss of Eq. 2, plus
/// `weight` times the edge-stretch penalty ([`EdgeStretch::penalty`]) when `stretch` is given.
pub fn train_autoencoder(
    autoencoder: &Autoencoder,
    data: &(impl Rows + ?Sized),
    config: &TrainConfig,
    resume: bool,
    stretch: Option<(&EdgeStretch, f64)>,
) -> TrainResult<TrainReport> {
    let dim = check_dataset(data)?;
    if dim != autoencoder.spec().input {
        return Err(TrainError::Invalid(format!(
            "states have {dim} values, the autoencoder takes {}",
            autoencoder.spec().input
        )));
    }
    train(&autoencoder.parameters(), data, config, resume, |batch, _| {
        BatchLoss::new(autoencoder_loss(autoencoder, &batch.inputs, stretch)?)
    })
}

/// The autoencoder's objective on states `x`: the reconstruction loss of Eq. 2, plus `weight`
/// times the edge-stretch penalty when `stretch` is given.
pub fn autoencoder_loss(
    autoencoder: &Autoencoder,
    x: &Tensor,
    stretch: Option<(&EdgeStretch, f64)>,
) -> candle_core::Result<Tensor> {
    let decoded = autoencoder.reconstruct(x)?;
    let loss = Autoencoder::reconstruction_loss_of(&decoded, x)?;
    match stretch {
        Some((stretch, weight)) => loss + (stretch.penalty(&decoded, x)? * weight)?,
        None => Ok(loss),
    }
}

/// [`autoencoder_loss`] over all of `data`, evaluated in chunks of `chunk` samples.
pub fn mean_autoencoder_loss(
    autoencoder: &Autoencoder,
    data: &(impl Rows + ?Sized),
    chunk: usize,
    stretch: Option<(&EdgeStretch, f64)>,
) -> TrainResult<f64> {
    let dim = check_dataset(data)?;
    let mut total = 0.0;
    let all: Vec<usize> = (0..data.count()).collect();
    for indices in all.chunks(chunk.max(1)) {
        let x = gathered(data, indices, dim)?;
        let loss = autoencoder_loss(autoencoder, &x, stretch)?.to_scalar::<f32>()?;
        total += loss as f64 * indices.len() as f64;
    }
    Ok(total / data.count() as f64)
}

/// Mean squared reconstruction error of the autoencoder over all of `data` (Eq. 2 divided by
/// the number of values), evaluated in chunks of `chunk` samples.
pub fn mean_reconstruction_error(
    autoencoder: &Autoencoder,
    data: &(impl Rows + ?Sized),
    chunk: usize,
) -> TrainResult<f64> {
    mean_autoencoder_loss(autoencoder, data, chunk, None)
}

/// The rows' width; an error for no rows or rows of different widths.
fn check_dataset(data: &(impl Rows + ?Sized)) -> TrainResult<usize> {
    if data.count() == 0 {
        return Err(TrainError::Invalid("the training set is empty".into()));
    }
    if let Some(i) = data.ragged_row() {
        return Err(TrainError::Invalid(format!(
            "sample {i} has another number of values than sample 0 ({})",
            data.width()
        )));
    }
    Ok(data.width())
}

/// Rows `indices` of `data` as a `(rows, dim)` tensor.
fn gathered(data: &(impl Rows + ?Sized), indices: &[usize], dim: usize) -> TrainResult<Tensor> {
    let mut flat = Vec::with_capacity(indices.len() * dim);
    data.gather_f32(indices, &mut flat)?;
    Ok(Tensor::from_vec(flat, (indices.len(), dim), &candle_core::Device::Cpu)?)
}

fn epoch_rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    rng
}
