//! The activation, `swish(x) = x * sigmoid(x) = x / (1 + exp(-x))`.
//!
//! Layers stored in `f16` or int8 compute the same bits on every target, so their activations
//! use the one scalar definition ([`swish`], `libm`'s `expf`). An `f32` layer's targets agree
//! within rounding only (see [`super`]), so on a CPU with AVX-512F its activations are computed
//! sixteen at a time ([`swish_all`]) with an exponential accurate to a few units in the last
//! place: the scalar `expf` was a call per value.

use crate::model::Layer;

/// `x * sigmoid(x)`.
#[inline]
pub fn swish(x: f32) -> f32 {
    x / (1.0 + libm::expf(-x))
}

/// [`swish`] of every value of `v`, the output of `layer`: vectorised where `layer` is `f32`
/// and the CPU has AVX-512F, the scalar definition otherwise.
pub fn swish_all(layer: &Layer, v: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if layer.format.is_f32() && x86::swish_all(v) {
        return;
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = layer;
    v.iter_mut().for_each(|x| *x = swish(*x));
}

#[cfg(target_arch = "x86_64")]
#[allow(unsafe_code)]
mod x86 {
    use core::arch::x86_64::*;

    use crate::network::{fast, Width};

    /// [`super::swish`] of every value with AVX-512F ([`swish16`]); `false`, and nothing
    /// computed, where the CPU lacks it (the `f32` kernel's own choice, [`fast::width`]).
    pub(super) fn swish_all(v: &mut [f32]) -> bool {
        let present = fast::width() == Width::Avx512;
        if present {
            // SAFETY: the CPU has AVX-512F.
            unsafe { swish16(v) };
        }
        present
    }

    /// `exp(t)` in 16 lanes: `t = n ln 2 + r` with `|r| <= ln 2 / 2` (`ln 2` in two parts), a
    /// degree-6 polynomial for `exp(r)` (Cephes' `expf` coefficients), `2^n` by `vscalefps`.
    /// (`0.693_359_4` is `355 / 512` exactly, so `n` times it is exact.)
    /// `t` is clamped to `[-104, 89]` first: below, `exp` underflows to zero; above, to
    /// infinity, as the scalar definition does. NaN stays NaN.
    #[target_feature(enable = "avx512f")]
    #[inline]
    fn exp16(t: __m512) -> __m512 {
        let t = _mm512_min_ps(_mm512_set1_ps(89.0), _mm512_max_ps(_mm512_set1_ps(-104.0), t));
        let n = _mm512_roundscale_ps::<{ _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC }>(_mm512_mul_ps(
            t,
            _mm512_set1_ps(core::f32::consts::LOG2_E),
        ));
        let r = _mm512_fnmadd_ps(n, _mm512_set1_ps(0.693_359_4), t);
        let r = _mm512_fnmadd_ps(n, _mm512_set1_ps(-2.121_944_4e-4), r);
        let mut p = _mm512_set1_ps(1.987_569_1e-4);
        for c in [1.398_199_9e-3, 8.333_452e-3, 4.166_579_6e-2, 0.166_666_65, 0.5] {
            p = _mm512_fmadd_ps(p, r, _mm512_set1_ps(c));
        }
        let e = _mm512_fmadd_ps(_mm512_mul_ps(p, r), r, _mm512_add_ps(r, _mm512_set1_ps(1.0)));
        _mm512_scalef_ps(e, n)
    }

    /// [`super::swish`] of every value, sixteen at a time (the tail masked).
    ///
    /// # Safety
    /// The CPU must have AVX-512F.
    #[target_feature(enable = "avx512f")]
    unsafe fn swish16(v: &mut [f32]) {
        let one = _mm512_set1_ps(1.0);
        for chunk in v.chunks_mut(16) {
            let mask: __mmask16 = ((1u32 << chunk.len()) - 1) as u16;
            // SAFETY: the mask enables only the `chunk.len()` values of `chunk`.
            unsafe {
                let x = _mm512_maskz_loadu_ps(mask, chunk.as_ptr());
                let e = exp16(_mm512_sub_ps(_mm512_setzero_ps(), x));
                let y = _mm512_div_ps(x, _mm512_add_ps(one, e));
                _mm512_mask_storeu_ps(chunk.as_mut_ptr(), mask, y);
            }
        }
    }
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
