//! x86-64 with AVX-512F: the step of sixteen strand lanes in vectors
//! (`crate::strand_lanes::ChainWalks`).

use core::arch::x86_64::*;

use crate::frame::TINY;

/// Every sixteen lanes by [`step16`] where the `f32` kernel is AVX-512F and `N` is a multiple
/// of sixteen; `false`, and nothing done, otherwise.
pub(super) fn step<const N: usize>(
    position: &mut [[f32; N]; 3],
    axes: &mut [[[f32; N]; 3]; 3],
    q0: &[f32; N],
    q1: &[f32; N],
    length: &[f32; N],
) -> bool {
    if !N.is_multiple_of(16) || super::fast::width() != super::Width::Avx512 {
        return false;
    }
    for first in (0..N).step_by(16) {
        // SAFETY: the CPU has AVX-512F (`width` reports only what it has); lanes
        // `first..first + 16` exist in every array.
        unsafe { step16(position, axes, q0, q1, length, first) };
    }
    true
}

/// [`crate::frame::flush_tiny`] in every lane: `+0` where `|v| < 2^-50` (NaN stays NaN).
#[target_feature(enable = "avx512f")]
#[inline]
fn flush(v: __m512) -> __m512 {
    let tiny = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(_mm512_abs_ps(v), _mm512_set1_ps(TINY));
    _mm512_mask_mov_ps(v, tiny, _mm512_setzero_ps())
}

/// `g x y` in the order of the scalar `cross`.
#[target_feature(enable = "avx512f")]
#[inline]
fn cross(g: &[__m512; 3], y: &[__m512; 3]) -> [__m512; 3] {
    let term = |a: __m512, b: __m512, c: __m512, d: __m512| _mm512_sub_ps(_mm512_mul_ps(a, b), _mm512_mul_ps(c, d));
    [
        term(g[1], y[2], g[2], y[1]),
        term(g[2], y[0], g[0], y[2]),
        term(g[0], y[1], g[1], y[0]),
    ]
}

/// [`crate::strand_lanes::ChainWalks::step`] for lanes `first..first + 16`: each operation of the lane
/// loops, in their order, on one vector (separate multiplies and adds, as there).
///
/// # Safety
/// The CPU must have AVX-512F, and `first + 16 <= N`.
#[target_feature(enable = "avx512f")]
unsafe fn step16<const N: usize>(
    position: &mut [[f32; N]; 3],
    axes: &mut [[[f32; N]; 3]; 3],
    q0: &[f32; N],
    q1: &[f32; N],
    length: &[f32; N],
    first: usize,
) {
    // SAFETY: every array holds lanes `first..first + 16` (the caller's promise).
    let load = |v: &[f32; N]| unsafe { _mm512_loadu_ps(v.as_ptr().add(first)) };
    let (q0, q1, length) = (flush(load(q0)), flush(load(q1)), load(length));
    let mut y: [[__m512; 3]; 3] = [[_mm512_setzero_ps(); 3]; 3];
    for (y, axis) in y.iter_mut().zip(axes.iter()) {
        for (y, a) in y.iter_mut().zip(axis) {
            *y = load(a);
        }
    }
    let (u, w) = (y[1], y[2]);
    let mut g = [_mm512_setzero_ps(); 3];
    for (i, g) in g.iter_mut().enumerate() {
        let along = _mm512_add_ps(_mm512_mul_ps(u[i], q0), _mm512_mul_ps(w[i], q1));
        *g = flush(_mm512_div_ps(along, length));
    }
    let gg = _mm512_add_ps(
        _mm512_add_ps(_mm512_mul_ps(g[0], g[0]), _mm512_mul_ps(g[1], g[1])),
        _mm512_mul_ps(g[2], g[2]),
    );
    let c = _mm512_div_ps(_mm512_set1_ps(2.0), _mm512_add_ps(_mm512_set1_ps(1.0), gg));
    for axis in y.iter_mut() {
        let [h0, h1, h2] = cross(&g, axis);
        let h = [flush(h0), flush(h1), flush(h2)];
        let k = cross(&g, &h);
        for i in 0..3 {
            let turn = _mm512_mul_ps(_mm512_add_ps(h[i], k[i]), c);
            axis[i] = flush(_mm512_add_ps(axis[i], turn));
        }
    }
    for (i, p) in position.iter_mut().enumerate() {
        // SAFETY: as above.
        unsafe {
            let moved = _mm512_add_ps(_mm512_loadu_ps(p.as_ptr().add(first)), _mm512_mul_ps(y[0][i], length));
            _mm512_storeu_ps(p.as_mut_ptr().add(first), moved);
        }
    }
    for (axis, y) in axes.iter_mut().zip(&y) {
        for (a, y) in axis.iter_mut().zip(y) {
            // SAFETY: as above.
            unsafe { _mm512_storeu_ps(a.as_mut_ptr().add(first), *y) };
        }
    }
}
