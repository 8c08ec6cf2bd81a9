//! The wide `f32` kernel for layers stored column by column
//! ([`crate::model::WeightFormat::F32Columns`]): a decoder's narrow output layer (thousands
//! of rows of a few columns) and wider layers of [`crate::model::COLUMN_ROWS`] rows (an
//! integrator's and a decoder MLP's hidden layers).
//!
//! Stored row by row, each row's products must be summed across a vector at the end, which
//! costs shuffles ([`super::narrow`], [`super::x86`]). Stored column by column, one vector
//! holds the same column of sixteen (AVX-512) or eight (AVX2) consecutive rows, and each
//! column is one fused multiply-add into all of them; nothing is reduced, and a group of
//! blocks reads the weights once in memory order (a 128 x 128 layer streams at the speed the
//! cache delivers). Each row is one
//! chain over the columns in order, whichever vector or lane holds it, so a row computed
//! alone, or from any offset, gets the same bits, with either vector width:
//!
//! ```text
//! s = 0;  s = fma(w[r][c], x[c], s) for c = 0, 1, ..., cols - 1;  y[r] = b[r] + s
//! ```

use core::arch::x86_64::*;

use crate::model::{column_stride, wide_stores_columns, Layer};

/// Blocks of 16 (AVX-512) or 8 (AVX2) rows computed together, one pass over the columns:
/// eight independent chains hide each fused multiply-add's latency, and a layer of at most
/// 128 rows (an integrator's hidden layer) streams its weights once in memory order.
const GROUP: usize = 8;

/// Rows `first..first + out.len()` of a column-stored `f32` layer (weights `w`, `x.len()`
/// columns, biases in `params`) with AVX-512F; returns the rows written (0 when the shapes do
/// not match: the caller computes them). The first block ends where the loads become 64-byte
/// aligned (every column has the same alignment, see [`column_stride`]): a load across two
/// cache lines costs two. Then groups of [`GROUP`] blocks, then the blocks left.
///
/// # Safety
/// The CPU must have AVX-512F.
#[target_feature(enable = "avx512f")]
pub(super) unsafe fn rows512(
    params: &[f32],
    layer: &Layer,
    w: &[f32],
    x: &[f32],
    first: usize,
    out: &mut [f32],
) -> usize {
    let Some(bias) = checked(params, layer, w, x.len(), first, out.len()) else {
        return 0;
    };
    let stride = column_stride(layer.rows as usize);
    let (head, rest) = out.split_at_mut(lead(w, first, 16).min(out.len()));
    let mut r = first;
    let mut groups = rest.chunks_exact_mut(16 * GROUP);
    // SAFETY (every call below): `checked` made sure rows `first..first + out.len()` exist in
    // every column of `w` and in `bias`; each call gets the rows from `r` that its block holds.
    unsafe {
        if !head.is_empty() {
            block512(w, stride, x, bias, r, head);
            r += head.len();
        }
        for group in &mut groups {
            group512(w, stride, x, bias, r, group);
            r += group.len();
        }
        for block in groups.into_remainder().chunks_mut(16) {
            block512(w, stride, x, bias, r, block);
            r += block.len();
        }
    }
    out.len()
}

/// Rows `r..r + out.len()` (at most 16), masked.
///
/// # Safety
/// AVX-512F; the rows exist in every column of `w` (`stride` apart, `x.len()` columns) and in
/// `bias`.
#[target_feature(enable = "avx512f")]
#[inline]
unsafe fn block512(w: &[f32], stride: usize, x: &[f32], bias: &[f32], r: usize, out: &mut [f32]) {
    let keep = ((1u32 << out.len()) - 1) as u16;
    let mut s = _mm512_setzero_ps();
    for (c, &xc) in x.iter().enumerate() {
        // SAFETY: the caller's promise; the mask reads only the block's rows.
        let v = unsafe { _mm512_maskz_loadu_ps(keep, w.as_ptr().add(c * stride + r)) };
        s = _mm512_fmadd_ps(v, _mm512_set1_ps(xc), s);
    }
    // SAFETY: the caller's promise; the masks cover only the block's rows and `out`.
    unsafe {
        let b = _mm512_maskz_loadu_ps(keep, bias.as_ptr().add(r));
        _mm512_mask_storeu_ps(out.as_mut_ptr(), keep, _mm512_add_ps(b, s));
    }
}

/// Rows `r..r + 16 GROUP`.
///
/// # Safety
/// As [`block512`], and `out` holds `16 GROUP` floats.
#[target_feature(enable = "avx512f")]
#[inline]
unsafe fn group512(w: &[f32], stride: usize, x: &[f32], bias: &[f32], r: usize, out: &mut [f32]) {
    // SAFETY: the caller's promise.
    let s = unsafe { column_chains512::<GROUP>(w.as_ptr().add(r), stride, x) };
    for (b, s) in s.iter().enumerate() {
        // SAFETY: the caller's promise.
        unsafe {
            let v = _mm512_add_ps(_mm512_loadu_ps(bias.as_ptr().add(r + 16 * b)), *s);
            _mm512_storeu_ps(out.as_mut_ptr().add(16 * b), v);
        }
    }
}

/// The sums of `V` consecutive 16-row vectors of a column-stored layer, from `w` (row `r` of
/// column 0; column `c` is `c * stride` floats further): for each vector one chain of fused
/// multiply-adds over the columns in order, the module's formula without the bias. Also
/// what the decode's one-pass kernels of `crate::world_x86` sum.
///
/// # Safety
/// The CPU must have AVX-512F; `16 V` floats from `w + c * stride` must be readable for every
/// column `c < x.len()`.
#[target_feature(enable = "avx512f")]
#[inline]
pub(crate) unsafe fn column_chains512<const V: usize>(w: *const f32, stride: usize, x: &[f32]) -> [__m512; V] {
    let mut s = [_mm512_setzero_ps(); V];
    for (c, &xc) in x.iter().enumerate() {
        let xv = _mm512_set1_ps(xc);
        // SAFETY: the caller's promise.
        let column = unsafe { w.add(c * stride) };
        for (b, s) in s.iter_mut().enumerate() {
            // SAFETY: the caller's promise.
            *s = _mm512_fmadd_ps(unsafe { _mm512_loadu_ps(column.add(16 * b)) }, xv, *s);
        }
    }
    s
}

/// [`rows512`] with AVX2 and FMA, eight rows per vector, loads aligned to 32 bytes (the same
/// bits).
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn rows256(
    params: &[f32],
    layer: &Layer,
    w: &[f32],
    x: &[f32],
    first: usize,
    out: &mut [f32],
) -> usize {
    let Some(bias) = checked(params, layer, w, x.len(), first, out.len()) else {
        return 0;
    };
    let stride = column_stride(layer.rows as usize);
    let (head, rest) = out.split_at_mut(lead(w, first, 8).min(out.len()));
    let mut r = first;
    let mut groups = rest.chunks_exact_mut(8 * GROUP);
    // SAFETY (every call below): as in `rows512`.
    unsafe {
        if !head.is_empty() {
            block256(w, stride, x, bias, r, head);
            r += head.len();
        }
        for group in &mut groups {
            group256(w, stride, x, bias, r, group);
            r += group.len();
        }
        for block in groups.into_remainder().chunks_mut(8) {
            block256(w, stride, x, bias, r, block);
            r += block.len();
        }
    }
    out.len()
}

/// Rows `r..r + out.len()` (at most 8), masked.
///
/// # Safety
/// AVX2 and FMA; as [`block512`].
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn block256(w: &[f32], stride: usize, x: &[f32], bias: &[f32], r: usize, out: &mut [f32]) {
    let n = out.len() as i32;
    let mask = _mm256_cmpgt_epi32(_mm256_set1_epi32(n), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
    let mut s = _mm256_setzero_ps();
    for (c, &xc) in x.iter().enumerate() {
        // SAFETY: the caller's promise; the mask reads only the block's rows.
        let v = unsafe { _mm256_maskload_ps(w.as_ptr().add(c * stride + r), mask) };
        s = _mm256_fmadd_ps(v, _mm256_set1_ps(xc), s);
    }
    // SAFETY: as above.
    unsafe {
        let b = _mm256_maskload_ps(bias.as_ptr().add(r), mask);
        _mm256_maskstore_ps(out.as_mut_ptr(), mask, _mm256_add_ps(b, s));
    }
}

/// Rows `r..r + 8 GROUP`.
///
/// # Safety
/// AVX2 and FMA; as [`group512`] with `8 GROUP` floats.
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn group256(w: &[f32], stride: usize, x: &[f32], bias: &[f32], r: usize, out: &mut [f32]) {
    let mut s = [_mm256_setzero_ps(); GROUP];
    for (c, &xc) in x.iter().enumerate() {
        let xv = _mm256_set1_ps(xc);
        for (b, s) in s.iter_mut().enumerate() {
            // SAFETY: the caller's promise.
            *s = _mm256_fmadd_ps(
                unsafe { _mm256_loadu_ps(w.as_ptr().add(c * stride + r + 8 * b)) },
                xv,
                *s,
            );
        }
    }
    for (b, s) in s.iter().enumerate() {
        // SAFETY: the caller's promise.
        unsafe {
            let v = _mm256_add_ps(_mm256_loadu_ps(bias.as_ptr().add(r + 8 * b)), *s);
            _mm256_storeu_ps(out.as_mut_ptr().add(8 * b), v);
        }
    }
}

/// Rows from `first` until row `first + lead` of `w`'s columns starts on a multiple of
/// `lanes` floats in memory (0 when it already does).
#[inline(always)]
fn lead(w: &[f32], first: usize, lanes: usize) -> usize {
    let at = (w.as_ptr() as usize / 4).wrapping_add(first);
    (lanes - at % lanes) % lanes
}

/// The layer's biases when `n` rows from `first` of a `cols`-column layer stored in `w` can
/// be computed: the shapes agree, the layer is one the loader stores by columns and every
/// row exists.
#[inline(always)]
pub(super) fn checked<'p>(
    params: &'p [f32],
    layer: &Layer,
    w: &[f32],
    cols: usize,
    first: usize,
    n: usize,
) -> Option<&'p [f32]> {
    let rows = layer.rows as usize;
    let fits = cols > 0
        && wide_stores_columns(rows, cols)
        && cols == layer.cols as usize
        && w.len() == column_stride(rows) * cols
        && first.checked_add(n).is_some_and(|end| end <= rows);
    let start = layer.bias as usize;
    fits.then(|| params.get(start..start + rows)).flatten()
}

#[cfg(all(test, feature = "std"))]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::*;
    use crate::model::WeightFormat;
    use crate::network::test_support::{noise, Case};

    /// The module's formula for row `r`, written out with scalar fused multiply-adds.
    fn formula(row: &[f32], x: &[f32], b: f32) -> f32 {
        b + row.iter().zip(x).fold(0.0f32, |s, (w, x)| w.mul_add(*x, s))
    }

    /// Every row of every kernel this CPU has equals the formula bit for bit, computed with
    /// the whole layer or alone from any offset.
    #[test]
    fn every_row_is_the_formula_alone_or_in_a_block() {
        let avx512 = std::is_x86_feature_detected!("avx512f");
        let avx2 = std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma");
        for (rows, cols) in [
            (1, 1),
            (5, 3),
            (16, 8),
            (37, 6),
            (100, 24),
            (33, 64),
            (17, 13),
            (200, 8),
            (128, 128),
            (256, 100),
            (131, 70),
        ] {
            let case = Case::new(rows, cols);
            let params = case.columns();
            let layer = case.layer(WeightFormat::F32Columns);
            let w = &params[layer.weights as usize..][..column_stride(rows) * cols];
            let x: Vec<f32> = noise(7 + cols as u32, cols).collect();
            let want: Vec<u32> = (0..rows)
                .map(|r| formula(&case.row(WeightFormat::F32, r), &x, case.params[r]).to_bits())
                .collect();
            type Kernel = unsafe fn(&[f32], &Layer, &[f32], &[f32], usize, &mut [f32]) -> usize;
            let kernels: [(bool, Kernel); 2] = [(avx512, rows512), (avx2, rows256)];
            for (_, kernel) in kernels.into_iter().filter(|(has, _)| *has) {
                let mut all = std::vec![0.0f32; rows];
                // SAFETY: the CPU has the kernel's features (filtered above).
                assert_eq!(unsafe { kernel(&params, &layer, w, &x, 0, &mut all) }, rows);
                assert_eq!(
                    all.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                    want,
                    "{rows}x{cols}"
                );
                for first in 0..rows {
                    let mut one = [0.0f32];
                    // SAFETY: as above.
                    assert_eq!(unsafe { kernel(&params, &layer, w, &x, first, &mut one) }, 1);
                    assert_eq!(one[0].to_bits(), want[first], "{rows}x{cols}, row {first} alone");
                }
                // Rows past the layer are refused, not read.
                let mut past = [0.0f32; 2];
                // SAFETY: as above.
                assert_eq!(unsafe { kernel(&params, &layer, w, &x, rows - 1, &mut past) }, 0);
            }
        }
    }
}
