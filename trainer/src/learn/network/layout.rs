//! The residual MLP's layout (in the documentation of [`super`]): its sizes, and the number
//! types and activation of the plain-Rust forward pass.

use serde::{Deserialize, Serialize};

use super::error::{invalid, ModelResult};

/// Sizes of a residual MLP (layout in the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct MlpSpec {
    /// Input features.
    pub input: usize,
    /// Output features.
    pub output: usize,
    /// Width of the residual stream and of every block.
    pub hidden: usize,
    /// Number of residual blocks (0 gives a one-hidden-layer MLP).
    pub blocks: usize,
}

impl MlpSpec {
    pub(super) fn check(&self) -> ModelResult<()> {
        if self.input == 0 || self.output == 0 || self.hidden == 0 {
            return invalid(format!("network sizes must be positive: {self:?}"));
        }
        Ok(())
    }
}

/// `v * sigmoid(v)`, written as candle writes its `silu` (`v / (1 + exp(-v))`).
pub(crate) fn swish<T: Real>(v: T) -> T {
    v / (T::from_f32(1.0) + (-v).exp())
}

/// The number types the plain-Rust forward pass ([`forward_exported`](super::forward_exported)) runs in: `f32`, the
/// reference for the runtime's kernels, and `f64`, for diagnostics that differentiate a
/// frozen decoder by finite differences.
pub trait Real:
    Copy
    + Default
    + std::ops::Add<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
    + std::ops::Neg<Output = Self>
    + std::ops::AddAssign
    + std::iter::Sum
{
    /// A weight or bias in this type.
    fn from_f32(v: f32) -> Self;
    /// `e^self`.
    fn exp(self) -> Self;
}

impl Real for f32 {
    fn from_f32(v: f32) -> Self {
        v
    }
    fn exp(self) -> Self {
        f32::exp(self)
    }
}

impl Real for f64 {
    fn from_f32(v: f32) -> Self {
        v as f64
    }
    fn exp(self) -> Self {
        f64::exp(self)
    }
}

#[cfg(test)]
mod tests {
    use candle_core::{Device, Tensor};

    use super::*;

    #[test]
    fn swish_matches_candle_silu() {
        let values = [-90.0f32, -5.0, -0.5, 0.0, 1e-3, 0.7, 4.0, 60.0];
        let t = Tensor::from_slice(&values, values.len(), &Device::Cpu).unwrap();
        let candle = t.silu().unwrap().to_vec1::<f32>().unwrap();
        for (v, c) in values.iter().zip(candle) {
            assert_eq!(swish(*v), c);
        }
    }
}
