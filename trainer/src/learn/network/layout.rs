//! The residual MLP's layout (in the documentation of [`super`]): its sizes, its style (the
//! activation, and residual blocks or plain hidden layers), and the number types of the
//! plain-Rust forward pass.

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

/// The activation between a network's layers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Activation {
    /// `v * sigmoid(v)` (every network the runtime runs).
    #[default]
    Swish,
    /// `v` for `v > 0`, `e^v - 1` otherwise (the ELU of Lyu et al.'s code, `alpha = 1`).
    Elu,
}

impl Activation {
    /// The activation of `v`.
    pub(crate) fn apply<T: Real>(self, v: T) -> T {
        match self {
            Activation::Swish => swish(v),
            Activation::Elu => elu(v),
        }
    }

    /// `(a(u), a'(u), a''(u))` in `f64` (ELU's second derivative taken as 0 at `u = 0`, its
    /// one kink, like its first as 1 there).
    pub(crate) fn parts(self, u: f64) -> (f64, f64, f64) {
        match self {
            Activation::Swish => {
                let sig = 1.0 / (1.0 + (-u).exp());
                let first = sig + u * sig * (1.0 - sig);
                let second = sig * (1.0 - sig) * (2.0 + u * (1.0 - 2.0 * sig));
                (swish(u), first, second)
            }
            Activation::Elu if u > 0.0 => (u, 1.0, 0.0),
            Activation::Elu => {
                let e = u.exp();
                (e - 1.0, e, e)
            }
        }
    }
}

/// How a network's hidden layers are joined (the module documentation of [`super`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct MlpStyle {
    /// The activation (default Swish).
    #[serde(default)]
    pub activation: Activation,
    /// Residual blocks `h + W_out a(W_in h)` (default); `false`: plain hidden layers
    /// `h = W a(h)`, one layer a block.
    #[serde(default = "residual_default")]
    pub residual: bool,
    /// A fixed linear map before the input layer (default false): an encoder's PCA
    /// projection `B^T (x - mean)`, never trained.
    #[serde(default)]
    pub input_projection: bool,
    /// A fixed linear map after the output layer (default false): a decoder's PCA basis
    /// `mean + B y`, never trained.
    #[serde(default)]
    pub output_projection: bool,
}

fn residual_default() -> bool {
    true
}

impl Default for MlpStyle {
    fn default() -> Self {
        MlpStyle::DEFAULT
    }
}

impl MlpStyle {
    /// Residual Swish blocks, no projection: every network the runtime runs.
    pub const DEFAULT: MlpStyle = MlpStyle {
        activation: Activation::Swish,
        residual: true,
        input_projection: false,
        output_projection: false,
    };

    /// Plain hidden layers with ELU: the networks of Lyu et al.'s code.
    pub const PAPER: MlpStyle = MlpStyle {
        activation: Activation::Elu,
        residual: false,
        input_projection: false,
        output_projection: false,
    };

    /// Fixed projection layers around the trained ones (0, 1 or 2).
    pub fn projections(&self) -> usize {
        usize::from(self.input_projection) + usize::from(self.output_projection)
    }

    /// Dense layers per block: two in a residual block, one in a plain one.
    pub fn layers_per_block(&self) -> usize {
        if self.residual {
            2
        } else {
            1
        }
    }
}

/// `v` for `v > 0`, `e^v - 1` otherwise.
pub(crate) fn elu<T: Real>(v: T) -> T {
    if v > T::default() {
        v
    } else {
        v.exp() + T::from_f32(-1.0)
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
    + PartialOrd
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

    #[test]
    fn elu_matches_candle_and_its_parts_match_differences() {
        let values = [-30.0f32, -2.0, -0.5, -1e-3, 0.0, 1e-3, 0.7, 40.0];
        let t = Tensor::from_slice(&values, values.len(), &Device::Cpu).unwrap();
        let candle = t.elu(1.0).unwrap().to_vec1::<f32>().unwrap();
        for (v, c) in values.iter().zip(candle) {
            assert!((Activation::Elu.apply(*v) - c).abs() <= 1e-7 * (1.0 + c.abs()), "{v}");
        }
        for activation in [Activation::Swish, Activation::Elu] {
            for u in [-3.0, -0.4, 0.3, 2.5] {
                let h = 1e-5;
                let (value, first, second) = activation.parts(u);
                let at = |x: f64| activation.parts(x);
                assert_eq!(value, activation.apply(u));
                assert!((first - (at(u + h).0 - at(u - h).0) / (2.0 * h)).abs() < 1e-8);
                assert!((second - (at(u + h).1 - at(u - h).1) / (2.0 * h)).abs() < 1e-8);
            }
        }
    }

    #[test]
    fn styles_read_with_defaults() {
        let style: MlpStyle = toml::from_str("").unwrap();
        assert_eq!(style, MlpStyle::default());
        let style: MlpStyle = toml::from_str("activation = \"elu\"\nresidual = false").unwrap();
        assert_eq!(style, MlpStyle::PAPER);
        assert_eq!(
            (style.layers_per_block(), MlpStyle::default().layers_per_block()),
            (1, 2)
        );
    }
}
