//! The wide `f32` kernel for narrow layers on AVX-512F: few columns (a basis decoder's
//! `m` modes, a small MLP's inputs), many rows (one per decoded coordinate).
//!
//! The row kernel of [`super::x86`] spends a 16-lane vector on each row and folds it down to
//! one value, which for an 8-column row wastes half the lanes and costs more shuffles than
//! multiply-adds. Here a vector holds **two rows** (eight columns of each), so sixteen rows
//! are eight vectors, and one shuffle tree reduces all sixteen at once.
//!
//! Each row's arithmetic depends on nothing but its own weights and the input, so a row gets
//! the same bits whichever block, position or call computes it:
//!
//! ```text
//! p[l] = fma chain over column groups g = 0, 1, ... of  w[r][8 g + l] * x[8 g + l]   (l < 8)
//! y[r] = b[r] + (((p0 + p4) + (p2 + p6)) + ((p1 + p5) + (p3 + p7)))
//! ```

use core::arch::x86_64::*;

use crate::model::Layer;

/// Rows reduced together: eight vectors of two rows each.
const ROWS: usize = 16;

/// Widest layer this kernel takes (eight groups of eight columns); wider ones go through the
/// row kernel, whose reduction is then a small share of the work.
pub(super) const MAX_COLS: usize = 64;

/// Rows `first..first + out.len()` of an `f32` layer with `x.len() <= MAX_COLS` columns
/// (weights `w`, biases in `params`); returns the rows written (rows outside `w` are not).
///
/// # Safety
/// The CPU must have AVX-512F.
#[target_feature(enable = "avx512f")]
pub(super) unsafe fn rows(params: &[f32], layer: &Layer, w: &[f32], x: &[f32], first: usize, out: &mut [f32]) -> usize {
    let cols = x.len();
    if cols == 0 || cols > MAX_COLS {
        return 0;
    }
    let groups = cols.div_ceil(8);
    // Each column group of the input, in both halves of a vector, the missing columns zero.
    let mut xs = [_mm512_setzero_ps(); MAX_COLS / 8];
    for (g, v) in xs.iter_mut().enumerate().take(groups) {
        let mask = group_mask(cols, g);
        // SAFETY: the mask enables only columns 8 g + l < cols of `x`.
        let half = unsafe { _mm512_maskz_loadu_ps(mask, x.as_ptr().add(8 * g)) };
        *v = _mm512_shuffle_f32x4::<0x44>(half, half);
    }
    let bias = params.get(layer.bias as usize..).unwrap_or(&[]);
    let mut r = first;
    for o in out.chunks_mut(ROWS) {
        let n = o.len();
        let Some(block) = w.get(r * cols..(r + n) * cols) else {
            return r - first;
        };
        // SAFETY: `block` holds the `n` rows the masks enable; `xs` the input groups.
        let sums = unsafe {
            match n {
                ROWS => block_sums::<true>(block.as_ptr(), n, cols, &xs[..groups]),
                _ => block_sums::<false>(block.as_ptr(), n, cols, &xs[..groups]),
            }
        };
        let keep: __mmask16 = ((1u32 << n) - 1) as u16;
        let b = match bias.get(r..r + n) {
            // SAFETY: the mask enables only the `n` biases that exist.
            Some(b) => unsafe { _mm512_maskz_loadu_ps(keep, b.as_ptr()) },
            None => _mm512_setzero_ps(),
        };
        // SAFETY: the mask enables only the `n` values of `o`.
        unsafe { _mm512_mask_storeu_ps(o.as_mut_ptr(), keep, _mm512_add_ps(b, sums)) };
        r += n;
    }
    out.len()
}

/// The lanes of column group `g` that exist in a row of `cols` columns (low eight bits).
#[inline(always)]
fn group_mask(cols: usize, g: usize) -> __mmask16 {
    let have = cols.saturating_sub(8 * g).min(8);
    ((1u32 << have) - 1) as u16
}

/// The sums of the `n <= 16` rows at `base` (row stride `cols`) against the input groups
/// `xs`, lane `k` for row `k` (rows past `n` give zero). `FULL` when `n` is [`ROWS`], so
/// that the row masks are constants.
///
/// # Safety
/// The CPU must have AVX-512F; `base..base + n * cols` must be readable.
#[target_feature(enable = "avx512f")]
#[inline]
unsafe fn block_sums<const FULL: bool>(base: *const f32, n: usize, cols: usize, xs: &[__m512]) -> __m512 {
    let mut acc = [_mm512_setzero_ps(); ROWS / 2];
    for (g, xv) in xs.iter().enumerate() {
        let mask = group_mask(cols, g);
        for (i, a) in acc.iter_mut().enumerate() {
            let (even, odd) = (2 * i, 2 * i + 1);
            let lo = if FULL || even < n { mask } else { 0 };
            let hi = if FULL || odd < n { mask << 8 } else { 0 };
            // Row `even` into lanes 0-7, row `odd` into lanes 8-15: the second load starts
            // 8 floats before the odd row's group so that its columns land in lanes 8-15.
            // SAFETY: each load reads only the lanes its mask enables, which are columns
            // 8 g + l < cols of a row < n, all inside the block; a load whose mask is zero
            // reads nothing (the pointers are formed with wrapping arithmetic).
            let v = unsafe {
                if cols == 8 {
                    // The two rows are adjacent: one load.
                    _mm512_maskz_loadu_ps(lo | hi, base.wrapping_add(even * 8))
                } else {
                    let v = _mm512_maskz_loadu_ps(lo, base.wrapping_add(even * cols + 8 * g));
                    _mm512_mask_loadu_ps(v, hi, base.wrapping_add(odd * cols + 8 * g).wrapping_sub(8))
                }
            };
            *a = _mm512_fmadd_ps(v, *xv, *a);
        }
    }
    reduce(acc)
}

/// Sixteen row sums from eight vectors of two rows' eight partial sums each (vector `i`:
/// row `2 i` in lanes 0-7, row `2 i + 1` in lanes 8-15), lane `k` for row `k`. Only a row's
/// own partials are ever added, in the order of the module's formula.
#[target_feature(enable = "avx512f")]
#[inline]
fn reduce(acc: [__m512; ROWS / 2]) -> __m512 {
    // 128-bit lanes: (p0..p3) + (p4..p7) for four rows per vector: rows 4 j .. 4 j + 3 in
    // lanes 0..3 of vector j.
    let quad =
        |a: __m512, b: __m512| _mm512_add_ps(_mm512_shuffle_f32x4::<0x88>(a, b), _mm512_shuffle_f32x4::<0xDD>(a, b));
    let s = [
        quad(acc[0], acc[1]),
        quad(acc[2], acc[3]),
        quad(acc[4], acc[5]),
        quad(acc[6], acc[7]),
    ];
    // (q0 + q2), (q1 + q3) for the rows of two vectors, interleaved: lane L of vector j holds
    // rows 8 j + L and 8 j + 4 + L.
    let pair = |a: __m512, b: __m512| _mm512_add_ps(_mm512_unpacklo_ps(a, b), _mm512_unpackhi_ps(a, b));
    let t = [pair(s[0], s[1]), pair(s[2], s[3])];
    // The last addition: 128-bit lane L, position m holds row L + 4 m.
    let lo = _mm512_castpd_ps(_mm512_unpacklo_pd(_mm512_castps_pd(t[0]), _mm512_castps_pd(t[1])));
    let hi = _mm512_castpd_ps(_mm512_unpackhi_pd(_mm512_castps_pd(t[0]), _mm512_castps_pd(t[1])));
    let u = _mm512_add_ps(lo, hi);
    // Row k sits at lane 4 (k % 4) + k / 4.
    let order = _mm512_setr_epi32(0, 4, 8, 12, 1, 5, 9, 13, 2, 6, 10, 14, 3, 7, 11, 15);
    _mm512_permutexvar_ps(order, u)
}

#[cfg(all(test, feature = "std"))]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::*;
    use crate::model::WeightFormat;
    use crate::network::test_support::{noise, Case};

    /// The module's formula, written out.
    fn formula(w: &[f32], x: &[f32], b: f32) -> f32 {
        let mut p = [0.0f32; 8];
        for (c, (w, x)) in w.iter().zip(x).enumerate() {
            p[c % 8] = w.mul_add(*x, p[c % 8]);
        }
        b + (((p[0] + p[4]) + (p[2] + p[6])) + ((p[1] + p[5]) + (p[3] + p[7])))
    }

    /// Every row equals the formula bit for bit, alone or in any block, for column counts
    /// around every group size and row counts around the block size.
    #[test]
    fn every_row_is_the_formula_alone_or_in_a_block() {
        if !std::is_x86_feature_detected!("avx512f") {
            std::println!("no AVX-512F: the narrow kernel is not run on this CPU");
            return;
        }
        for cols in [1, 3, 6, 8, 9, 16, 24, 31, 64] {
            for rows_n in [1, 5, 15, 16, 17, 40] {
                let case = Case::new(rows_n, cols);
                let x: Vec<f32> = noise(cols as u32 + 3, cols).collect();
                let layer = case.layer(WeightFormat::F32);
                let w = &case.params[2 * rows_n..];
                let mut all = std::vec![0.0f32; rows_n];
                // SAFETY: the CPU has AVX-512F.
                assert_eq!(unsafe { rows(&case.params, &layer, w, &x, 0, &mut all) }, rows_n);
                for r in 0..rows_n {
                    let want = formula(&case.row(WeightFormat::F32, r), &x, case.params[r]);
                    assert_eq!(all[r].to_bits(), want.to_bits(), "{rows_n}x{cols} row {r}");
                    let mut from_r = std::vec![0.0f32; rows_n - r];
                    // SAFETY: as above.
                    unsafe { rows(&case.params, &layer, w, &x, r, &mut from_r) };
                    assert_eq!(from_r[0].to_bits(), want.to_bits(), "{rows_n}x{cols} from row {r}");
                }
            }
        }
    }

    /// Rows past the weights are not written, wider layers are left to the row kernel.
    #[test]
    fn rows_outside_the_weights_and_wide_layers_are_left_alone() {
        if !std::is_x86_feature_detected!("avx512f") {
            return;
        }
        let case = Case::new(20, 8);
        let layer = case.layer(WeightFormat::F32);
        let w = &case.params[2 * 20..];
        let x = [0.5f32; 8];
        let mut out = [7.0f32; 20];
        // SAFETY: the CPU has AVX-512F.
        assert_eq!(unsafe { rows(&case.params, &layer, &w[..16 * 8], &x, 0, &mut out) }, 16);
        assert!(out[16..].iter().all(|&v| v == 7.0));
        let wide = [0.5f32; MAX_COLS + 1];
        // SAFETY: as above.
        assert_eq!(unsafe { rows(&case.params, &layer, w, &wide, 0, &mut out) }, 0);
    }
}
