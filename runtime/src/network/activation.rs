//! The activation, `swish(x) = x * sigmoid(x) = x / (1 + exp(-x))`.
//!
//! Layers stored in `f16` or int8 compute the same bits on every target, so their activations
//! use the one scalar definition ([`swish`], `libm`'s `expf`). An `f32` layer's targets agree
//! within rounding only (see [`super`]), so on a CPU with AVX-512F its activations are computed
//! sixteen at a time ([`swish_all`], `network/swish_avx512.rs`) with an exponential accurate to
//! a few units in the last place: the scalar `expf` was a call per value.

use crate::model::Layer;

/// `x * sigmoid(x)`.
#[inline]
pub fn swish(x: f32) -> f32 {
    x / (1.0 + libm::expf(-x))
}

/// [`swish`] of every value of `v`, the output of `layer`: vectorised where `layer` is `f32`
/// and the CPU has AVX-512F, the scalar definition otherwise.
pub fn swish_all(layer: &Layer, v: &mut [f32]) {
    if layer.format.is_f32() && super::isa_swish_all(v) {
        return;
    }
    v.iter_mut().for_each(|x| *x = swish(*x));
}

#[cfg(all(test, feature = "std"))]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::*;
    use crate::model::WeightFormat;
    use crate::network::test_support::noise;

    fn layer(format: WeightFormat) -> Layer {
        Layer {
            rows: 0,
            cols: 0,
            format,
            weights: 0,
            bias: 0,
            scales: 0,
        }
    }

    /// The vectorised activation is within 4 units in the last place (relative 5e-7) of the
    /// scalar definition over the whole range, including values whose exponential overflows
    /// or underflows; NaN stays NaN; other storages get the scalar definition bit for bit.
    #[test]
    fn vectorised_swish_is_within_rounding_of_the_definition() {
        let mut x: Vec<f32> = noise(5, 4000).map(|v| 12.0 * v).collect();
        x.extend(noise(6, 997).map(|v| 120.0 * v));
        x.extend([
            0.0, -0.0, 1e-30, -1e-30, 88.0, 89.5, -88.0, -89.5, 103.0, -103.0, 110.0, -110.0,
        ]);
        x.extend([f32::MAX, f32::MIN, f32::INFINITY, f32::NEG_INFINITY, f32::NAN]);
        let mut fast = x.clone();
        swish_all(&layer(WeightFormat::F32), &mut fast);
        for (&x, &y) in x.iter().zip(&fast) {
            let want = swish(x);
            if want.is_nan() {
                assert!(y.is_nan(), "swish({x}) = {y}, want NaN");
                continue;
            }
            let close = (y - want).abs() <= 5e-7 * want.abs() || (y - want).abs() <= 1e-37;
            assert!(close || y == want, "swish({x}) = {y}, want {want}");
        }
        let mut exact = x.clone();
        swish_all(&layer(WeightFormat::F16), &mut exact);
        for (&x, &y) in x.iter().zip(&exact) {
            assert!(y.to_bits() == swish(x).to_bits() || y.is_nan(), "swish({x})");
        }
    }
}
