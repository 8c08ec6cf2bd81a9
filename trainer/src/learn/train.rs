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

use std::collections::HashMap;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use candle_core::backprop::GradStore;
use candle_core::{Device, Tensor, Var};
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use safetensors::tensor::{Dtype, TensorView};
use safetensors::SafeTensors;

use crate::learn::network::{rows_to_tensor, Autoencoder};
use crate::learn::stretch::EdgeStretch;
use crate::progress::EpochsBar;
use mochi_sim::error::{InputError, Location};

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
}

/// Result of this module's functions.
pub type TrainResult<T> = Result<T, TrainError>;

// ---------------------------------------------------------------------------------------------
// AdamW
// ---------------------------------------------------------------------------------------------

/// AdamW settings (Loshchilov & Hutter: Adam with decoupled weight decay).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdamWConfig {
    /// Learning rate (the paper uses 1e-4 for both networks).
    pub lr: f64,
    /// Decay of the first-moment average.
    pub beta1: f64,
    /// Decay of the second-moment average.
    pub beta2: f64,
    /// Added to the root of the second moment.
    pub eps: f64,
    /// Decoupled weight decay per unit learning rate (0 makes this plain Adam).
    pub weight_decay: f64,
}

impl Default for AdamWConfig {
    /// lr 1e-4 (paper), betas (0.9, 0.999), eps 1e-8, no weight decay.
    fn default() -> Self {
        AdamWConfig {
            lr: 1e-4,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            weight_decay: 0.0,
        }
    }
}

/// One parameter and its AdamW moments. The moments are plain vectors and the update is one
/// fused loop over them: about four times faster than composing it from candle tensor ops,
/// each of which allocates a parameter-sized tensor.
#[derive(Debug)]
struct Slot {
    name: String,
    param: Var,
    m: Vec<f32>,
    v: Vec<f32>,
}

/// AdamW over named candle variables, with its state open to checkpoints.
#[derive(Debug)]
pub struct AdamW {
    config: AdamWConfig,
    step: u64,
    slots: Vec<Slot>,
}

impl AdamW {
    /// An optimiser for `params` (unique names, f32 variables), with zero moments.
    pub fn new(params: &[(String, Var)], config: AdamWConfig) -> TrainResult<Self> {
        let mut slots: Vec<Slot> = Vec::with_capacity(params.len());
        for (name, var) in params {
            if slots.iter().any(|s| &s.name == name) {
                return Err(TrainError::Invalid(format!("parameter `{name}` is listed twice")));
            }
            if var.dtype() != candle_core::DType::F32 {
                return Err(TrainError::Invalid(format!("parameter `{name}` is not f32")));
            }
            slots.push(Slot {
                name: name.clone(),
                param: var.clone(),
                m: vec![0.0; var.elem_count()],
                v: vec![0.0; var.elem_count()],
            });
        }
        Ok(AdamW { config, step: 0, slots })
    }

    /// Changes the learning rate of the following steps.
    pub fn set_lr(&mut self, lr: f64) {
        self.config.lr = lr;
    }

    /// One update from the gradients of a backward pass (variables without a gradient are left
    /// alone, their moments too):
    /// `m = b1 m + (1-b1) g`, `v = b2 v + (1-b2) g^2`,
    /// `p = p (1 - lr wd) - lr (m / (1-b1^t)) / (sqrt(v / (1-b2^t)) + eps)`.
    pub fn step(&mut self, grads: &GradStore) -> candle_core::Result<()> {
        self.step += 1;
        let AdamWConfig {
            lr,
            beta1,
            beta2,
            eps,
            weight_decay,
        } = self.config;
        let t = i32::try_from(self.step).unwrap_or(i32::MAX);
        let m_scale = (1.0 / (1.0 - beta1.powi(t))) as f32;
        let v_scale = (1.0 / (1.0 - beta2.powi(t))) as f32;
        let decay = (1.0 - lr * weight_decay) as f32;
        let (b1, b2, eps, lr) = (beta1 as f32, beta2 as f32, eps as f32, lr as f32);
        for slot in &mut self.slots {
            let Some(g) = grads.get(slot.param.as_tensor()) else {
                continue;
            };
            let g = g.flatten_all()?.to_vec1::<f32>()?;
            let param = slot.param.as_tensor();
            let mut p = param.flatten_all()?.to_vec1::<f32>()?;
            for (((p, m), v), g) in p.iter_mut().zip(&mut slot.m).zip(&mut slot.v).zip(&g) {
                *m = b1 * *m + (1.0 - b1) * g;
                *v = b2 * *v + (1.0 - b2) * g * g;
                *p = *p * decay - lr * (*m * m_scale) / ((*v * v_scale).sqrt() + eps);
            }
            slot.param.set(&Tensor::from_vec(p, param.shape(), param.device())?)?;
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// The loop
// ---------------------------------------------------------------------------------------------

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
    /// Periodic checkpoints; `None` writes none (and `resume` then has nothing to resume).
    pub checkpoint: Option<CheckpointConfig>,
    /// Show a progress bar on the terminal.
    pub progress: bool,
}

impl TrainConfig {
    /// The learning rate of `epoch`.
    pub fn lr_at(&self, epoch: usize) -> f64 {
        let start = self.optimizer.lr;
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

/// Trains `params` on `data` (equal-length rows) for `config.epochs` epochs with AdamW,
/// minimising `loss(batch, rng)`. With `resume`, continues from the checkpoint if there is
/// one (checking that it belongs to this run) and ends with the same weights as an
/// uninterrupted run; without, starts afresh and overwrites old checkpoints.
pub fn train<F>(
    params: &[(String, Var)],
    data: &[Vec<f32>],
    config: &TrainConfig,
    resume: bool,
    mut loss: F,
) -> TrainResult<TrainReport>
where
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
    let run = RunIdentity::new(config, data.len(), dim);
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
        let mut order: Vec<usize> = (0..data.len()).collect();
        order.shuffle(&mut epoch_rng(config.seed, 2 * epoch as u64));
        let mut rng = epoch_rng(config.seed, 2 * epoch as u64 + 1);
        let mut total = 0.0;
        for (batch, indices) in order.chunks(config.batch_size).enumerate() {
            let rows: Vec<&[f32]> = indices.iter().map(|&i| data[i].as_slice()).collect();
            let inputs = rows_to_tensor(&rows, dim).map_err(|e| TrainError::Invalid(e.to_string()))?;
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
        losses.push(total / data.len() as f64);
        bar.epoch(total / data.len() as f64);
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
    data: &[Vec<f32>],
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
    data: &[Vec<f32>],
    chunk: usize,
    stretch: Option<(&EdgeStretch, f64)>,
) -> TrainResult<f64> {
    let dim = check_dataset(data)?;
    let mut total = 0.0;
    for rows in data.chunks(chunk.max(1)) {
        let refs: Vec<&[f32]> = rows.iter().map(Vec::as_slice).collect();
        let x = rows_to_tensor(&refs, dim).map_err(|e| TrainError::Invalid(e.to_string()))?;
        let loss = autoencoder_loss(autoencoder, &x, stretch)?.to_scalar::<f32>()?;
        total += loss as f64 * rows.len() as f64;
    }
    Ok(total / data.len() as f64)
}

/// Mean squared reconstruction error of the autoencoder over all of `data` (Eq. 2 divided by
/// the number of values), evaluated in chunks of `chunk` samples.
pub fn mean_reconstruction_error(autoencoder: &Autoencoder, data: &[Vec<f32>], chunk: usize) -> TrainResult<f64> {
    mean_autoencoder_loss(autoencoder, data, chunk, None)
}

fn check_dataset(data: &[Vec<f32>]) -> TrainResult<usize> {
    let Some(first) = data.first() else {
        return Err(TrainError::Invalid("the training set is empty".into()));
    };
    let dim = first.len();
    if let Some(i) = data.iter().position(|row| row.len() != dim) {
        return Err(TrainError::Invalid(format!(
            "sample {i} has {} values, sample 0 has {dim}",
            data[i].len()
        )));
    }
    Ok(dim)
}

fn epoch_rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    rng
}

// ---------------------------------------------------------------------------------------------
// Checkpoints
// ---------------------------------------------------------------------------------------------

/// Magic of a checkpoint's envelope (`mochi_runtime::envelope`).
const CHECKPOINT_MAGIC: &[u8; 8] = b"MOCHICKP";
/// Checkpoint format version.
const CHECKPOINT_VERSION: u32 = 1;

/// What a checkpoint must agree on to be resumed by a run: everything that shapes the
/// trajectory except the total epoch count.
struct RunIdentity {
    fields: Vec<(&'static str, String)>,
}

impl RunIdentity {
    fn new(config: &TrainConfig, dataset_len: usize, input_dim: usize) -> Self {
        let o = &config.optimizer;
        // `{:?}` of an f64 round-trips exactly, so equal strings mean equal settings.
        let fields = vec![
            ("name", config.name.clone()),
            ("seed", config.seed.to_string()),
            ("batch_size", config.batch_size.to_string()),
            ("dataset_len", dataset_len.to_string()),
            ("input_dim", input_dim.to_string()),
            ("lr", format!("{:?}", o.lr)),
            ("beta1", format!("{:?}", o.beta1)),
            ("beta2", format!("{:?}", o.beta2)),
            ("eps", format!("{:?}", o.eps)),
            ("weight_decay", format!("{:?}", o.weight_decay)),
            ("final_lr", format!("{:?}", config.final_lr)),
        ];
        RunIdentity { fields }
    }
}

fn save_checkpoint(path: &Path, run: &RunIdentity, optimizer: &AdamW, losses: &[f64], seconds: f64) -> TrainResult<()> {
    let mut tensors: Vec<(String, Vec<usize>, Dtype, Vec<u8>)> = Vec::new();
    for slot in &optimizer.slots {
        let shape = slot.param.as_tensor().dims().to_vec();
        let param = slot.param.as_tensor().flatten_all()?.to_vec1::<f32>()?;
        for (prefix, values) in [("param", &param), ("adam.m", &slot.m), ("adam.v", &slot.v)] {
            let name = format!("{prefix}/{}", slot.name);
            let bytes = values.iter().flat_map(|v| v.to_le_bytes()).collect();
            tensors.push((name, shape.clone(), Dtype::F32, bytes));
        }
    }
    let history = losses.iter().flat_map(|v| v.to_le_bytes()).collect();
    tensors.push(("history.loss".into(), vec![losses.len()], Dtype::F64, history));
    let views = tensors
        .iter()
        .map(|(name, shape, dtype, bytes)| Ok((name.as_str(), TensorView::new(*dtype, shape.clone(), bytes)?)))
        .collect::<Result<Vec<_>, safetensors::SafeTensorError>>()
        .map_err(|e| TrainError::Invalid(format!("building checkpoint: {e}")))?;
    let mut metadata: HashMap<String, String> = run.fields.iter().map(|(k, v)| (k.to_string(), v.clone())).collect();
    metadata.insert("epoch".into(), losses.len().to_string());
    metadata.insert("adam_step".into(), optimizer.step.to_string());
    metadata.insert("seconds".into(), format!("{seconds:?}"));
    let payload = safetensors::serialize(views, Some(metadata))
        .map_err(|e| TrainError::Invalid(format!("building checkpoint: {e}")))?;

    let file = mochi_runtime::envelope::wrap(CHECKPOINT_MAGIC, CHECKPOINT_VERSION, &payload);
    write_atomically(path, &file).map_err(|source| TrainError::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes `bytes` to `path` through a temporary file beside it, so a crash leaves either the
/// old file or the new one.
pub(crate) fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    if let Some(dir) = path.parent() {
        fs::create_dir_all(dir)?;
    }
    let mut partial = path.as_os_str().to_owned();
    partial.push(".partial");
    let partial = PathBuf::from(partial);
    let mut file = fs::File::create(&partial)?;
    file.write_all(bytes)?;
    file.sync_all()?;
    fs::rename(&partial, path)
}

/// Reads a checkpoint, checks it against this run, and loads parameters and optimiser state.
/// Returns the loss history (its length is the epoch to continue from) and the training
/// seconds it records (0 when it records none). On any error nothing has been modified.
fn load_checkpoint(
    path: &Path,
    run: &RunIdentity,
    max_epochs: usize,
    optimizer: &mut AdamW,
) -> TrainResult<(Vec<f64>, f64)> {
    let whole = |message: String| InputError::file(path, message);
    let bytes = fs::read(path).map_err(|e| whole(format!("cannot read checkpoint: {e}")))?;
    let payload = match mochi_runtime::envelope::open(&bytes, CHECKPOINT_MAGIC, CHECKPOINT_VERSION) {
        Ok(payload) => payload,
        Err(mochi_runtime::EnvelopeError::BadMagic) => {
            return Err(whole("not a mochi checkpoint (bad magic bytes)".into()).into())
        }
        Err(e) => return Err(whole(format!("checkpoint {e}")).into()),
    };
    let tensors =
        SafeTensors::deserialize(payload).map_err(|e| whole(format!("checkpoint payload is unreadable: {e}")))?;
    let (_, header) =
        SafeTensors::read_metadata(payload).map_err(|e| whole(format!("checkpoint payload is unreadable: {e}")))?;
    let empty = HashMap::new();
    let metadata = header.metadata().as_ref().unwrap_or(&empty);
    let field = |key: &str| -> TrainResult<&String> {
        metadata
            .get(key)
            .ok_or_else(|| InputError::new(path, Location::Field(format!("metadata.{key}")), "missing").into())
    };
    for (key, expected) in &run.fields {
        let found = field(key)?;
        if found != expected {
            let msg = format!("checkpoint has {found}, this run has {expected}: it belongs to a different run");
            return Err(InputError::field(path, format!("metadata.{key}"), msg).into());
        }
    }
    let number = |key: &str| -> TrainResult<u64> {
        field(key)?
            .parse::<u64>()
            .map_err(|_| InputError::field(path, format!("metadata.{key}"), "not a whole number").into())
    };
    let epoch = number("epoch")? as usize;
    let adam_step = number("adam_step")?;
    let seconds = match metadata.get("seconds") {
        None => 0.0,
        Some(text) => text
            .parse::<f64>()
            .ok()
            .filter(|s| s.is_finite() && *s >= 0.0)
            .ok_or_else(|| InputError::field(path, "metadata.seconds", "not a non-negative number of seconds"))?,
    };
    if epoch > max_epochs {
        let msg = format!("checkpoint is at epoch {epoch}, beyond the {max_epochs} epochs asked for");
        return Err(InputError::field(path, "metadata.epoch", msg).into());
    }

    let read = |name: &str, dtype: Dtype, shape: &[usize]| -> TrainResult<Vec<u8>> {
        let view = tensors
            .tensor(name)
            .map_err(|_| InputError::field(path, name, "missing: the checkpoint is for a different network"))?;
        if view.dtype() != dtype || view.shape() != shape {
            let msg = format!(
                "{:?} of shape {:?}, expected {dtype:?} of shape {shape:?} (a different network)",
                view.dtype(),
                view.shape()
            );
            return Err(InputError::field(path, name, msg).into());
        }
        Ok(view.data().to_vec())
    };
    let history_bytes = read("history.loss", Dtype::F64, &[epoch])?;
    let history: Vec<f64> = history_bytes
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().expect("chunks of 8")))
        .collect();
    let expected_tensors = 3 * optimizer.slots.len() + 1;
    if tensors.len() != expected_tensors {
        let msg = format!(
            "checkpoint holds {} tensors, this network needs {expected_tensors}: it is for a different network",
            tensors.len()
        );
        return Err(whole(msg).into());
    }
    // Read everything before touching any variable.
    let mut values: Vec<[Vec<f32>; 3]> = Vec::with_capacity(optimizer.slots.len());
    for slot in &optimizer.slots {
        let shape = slot.param.as_tensor().dims().to_vec();
        let load = |prefix: &str| -> TrainResult<Vec<f32>> {
            let bytes = read(&format!("{prefix}/{}", slot.name), Dtype::F32, &shape)?;
            Ok(bytes
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().expect("chunks of 4")))
                .collect())
        };
        values.push([load("param")?, load("adam.m")?, load("adam.v")?]);
    }
    for (slot, [param, m, v]) in optimizer.slots.iter_mut().zip(values) {
        let shape = slot.param.as_tensor().shape().clone();
        slot.param.set(&Tensor::from_vec(param, shape, &Device::Cpu)?)?;
        slot.m = m;
        slot.v = v;
    }
    optimizer.step = adam_step;
    Ok((history, seconds))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::network::test_support::{manifold_data, pca, pca_reconstruction_error};
    use crate::learn::network::AutoencoderSpec;

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
            train_autoencoder(&ae, &[], &cfg, false, None),
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
        assert!(train_autoencoder(&ae, &[vec![0.0; 6]], &zero_batch, false, None).is_err());
        let nan = vec![vec![f32::NAN; 6]; 3];
        assert!(matches!(
            train_autoencoder(&ae, &nan, &cfg, false, None),
            Err(TrainError::NonFinite { .. })
        ));
        let mut params = ae.parameters();
        params.push(params[0].clone());
        assert!(AdamW::new(&params, AdamWConfig::default()).is_err());
    }
}
