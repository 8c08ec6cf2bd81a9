//! Rows of f32 values to and from candle tensors.

use candle_core::{DType, Device, Tensor};

use super::error::{invalid, ModelResult};

/// A `(rows.len(), dim)` f32 tensor from equal-length rows (`dim` when `rows` is empty).
pub(crate) fn rows_to_tensor(rows: &[&[f32]], dim: usize) -> ModelResult<Tensor> {
    let mut flat = Vec::with_capacity(rows.len() * dim);
    for (i, row) in rows.iter().enumerate() {
        if row.len() != dim {
            return invalid(format!("row {i} has {} values, expected {dim}", row.len()));
        }
        flat.extend_from_slice(row);
    }
    Ok(Tensor::from_vec(flat, (rows.len(), dim), &Device::Cpu)?)
}

/// The rows of a `(batch, n)` f32 tensor.
pub(crate) fn tensor_to_rows(t: &Tensor) -> candle_core::Result<Vec<Vec<f32>>> {
    t.to_dtype(DType::F32)?.to_vec2::<f32>()
}
