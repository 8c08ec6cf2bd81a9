//! x86-64 with AVX-512F: the activation of `f32` layers sixteen values at a time
//! ([`super::activation`]).

use core::arch::x86_64::*;

use super::{fast, Width};

/// [`super::activation::swish`] of every value with AVX-512F ([`swish16`]); `false`, and nothing
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

/// [`super::activation::swish`] of every value, sixteen at a time (the tail masked).
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
