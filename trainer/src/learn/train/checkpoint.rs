//! Checkpoint files of a training run (the layout is in the parent module's documentation):
//! written atomically at the end of an epoch, read back only when they belong to the run.

use std::collections::HashMap;
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use candle_core::{Device, Tensor};
use safetensors::tensor::{Dtype, TensorView};
use safetensors::SafeTensors;

use super::{AdamW, TrainConfig, TrainError, TrainResult};
use mochi_sim::error::{InputError, Location};

/// Magic of a checkpoint's envelope (`mochi_runtime::envelope`).
const CHECKPOINT_MAGIC: &[u8; 8] = b"MOCHICKP";
/// Checkpoint format version.
const CHECKPOINT_VERSION: u32 = 1;

/// What a checkpoint must agree on to be resumed by a run: everything that shapes the
/// trajectory except the total epoch count.
pub(super) struct RunIdentity {
    fields: Vec<(&'static str, String)>,
}

impl RunIdentity {
    pub(super) fn new(config: &TrainConfig, dataset_len: usize, input_dim: usize) -> Self {
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
        let mut fields = fields;
        if let Some(schedule) = config.warmup_step {
            fields.push(("warmup_step", format!("{schedule:?}")));
        }
        RunIdentity { fields }
    }
}

pub(super) fn save_checkpoint(
    path: &Path,
    run: &RunIdentity,
    optimizer: &AdamW,
    losses: &[f64],
    seconds: f64,
) -> TrainResult<()> {
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
pub(super) fn load_checkpoint(
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
