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

use super::matrix;
use super::x86_lanes::{wide_driver, Avx2, Avx512, Lanes};
use crate::model::{column_stride, wide_stores_columns, Layer, WeightFormat};

/// Blocks of 16 (AVX-512) or 8 (AVX2) rows computed together, one pass over the columns:
/// eight independent chains hide each fused multiply-add's latency, and a layer of at most
/// 128 rows (an integrator's hidden layer) streams its weights once in memory order.
const GROUP: usize = 8;

/// Rows `first..first + out.len()` of a column-stored `f32` layer (weights `w`, `x.len()`
/// columns, biases in `params`) with `L`'s vectors; returns the rows written (0 when the
/// shapes do not match: the caller computes them). The first block ends where the loads
/// become aligned to a whole vector (every column has the same alignment, see
/// [`column_stride`]): a load across two cache lines costs two. Then groups of [`GROUP`]
/// blocks, then the blocks left.
///
/// # Safety
/// Inside a wrapper compiled for `L`'s features ([`Lanes`]).
#[inline(always)]
unsafe fn rows_by_columns<L: Lanes>(
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
    let (head, rest) = out.split_at_mut(lead(w, first, L::N).min(out.len()));
    let mut r = first;
    let mut groups = rest.chunks_exact_mut(L::N * GROUP);
    // SAFETY (every call below): `checked` made sure rows `first..first + out.len()` exist in
    // every column of `w` and in `bias`; each call gets the rows from `r` that its block
    // holds; the caller's features.
    unsafe {
        if !head.is_empty() {
            block::<L>(w, stride, x, bias, r, head);
            r += head.len();
        }
        for group in &mut groups {
            group_of::<L>(w, stride, x, bias, r, group);
            r += group.len();
        }
        for rows in groups.into_remainder().chunks_mut(L::N) {
            block::<L>(w, stride, x, bias, r, rows);
            r += rows.len();
        }
    }
    out.len()
}

wide_driver!(
    /// [`rows_by_columns`] with AVX-512F, sixteen rows per vector.
    pub(super) rows512 = rows_by_columns::<Avx512>, "avx512f"
);
wide_driver!(
    /// [`rows_by_columns`] with AVX2 and FMA, eight rows per vector (the same bits).
    pub(super) rows256 = rows_by_columns::<Avx2>, "avx2,fma"
);

/// Rows `r..r + out.len()` (at most `L::N`), masked.
///
/// # Safety
/// `L`'s features; the rows exist in every column of `w` (`stride` apart, `x.len()` columns)
/// and in `bias`.
#[inline(always)]
unsafe fn block<L: Lanes>(w: &[f32], stride: usize, x: &[f32], bias: &[f32], r: usize, out: &mut [f32]) {
    // SAFETY: the caller's promise; the mask reads and writes only the block's rows.
    unsafe {
        let keep = L::mask(out.len());
        let mut s = L::zero();
        for (c, &xc) in x.iter().enumerate() {
            let v = L::load_masked(keep, w.as_ptr().add(c * stride + r));
            s = L::fmadd(v, L::splat(xc), s);
        }
        let b = L::load_masked(keep, bias.as_ptr().add(r));
        L::store_masked(keep, out.as_mut_ptr(), L::add(b, s));
    }
}

/// Rows `r..r + L::N GROUP`.
///
/// # Safety
/// As [`block`], and `out` holds `L::N GROUP` floats.
#[inline(always)]
unsafe fn group_of<L: Lanes>(w: &[f32], stride: usize, x: &[f32], bias: &[f32], r: usize, out: &mut [f32]) {
    // SAFETY: the caller's promise.
    unsafe {
        let s = column_chains::<L, GROUP>(w.as_ptr().add(r), stride, x);
        for (b, s) in s.iter().enumerate() {
            let v = L::add(L::load(bias.as_ptr().add(r + L::N * b)), *s);
            L::store(out.as_mut_ptr().add(L::N * b), v);
        }
    }
}

/// The sums of `V` consecutive `L::N`-row vectors of a column-stored layer, from `w` (row `r`
/// of column 0; column `c` is `c * stride` floats further): for each vector one chain of
/// fused multiply-adds over the columns in order, the module's formula without the bias.
///
/// # Safety
/// `L`'s features; `L::N V` floats from `w + c * stride` must be readable for every column
/// `c < x.len()`.
#[inline(always)]
unsafe fn column_chains<L: Lanes, const V: usize>(w: *const f32, stride: usize, x: &[f32]) -> [L::V; V] {
    // SAFETY: the caller's promise.
    unsafe {
        let mut s = [L::zero(); V];
        for (c, &xc) in x.iter().enumerate() {
            let xv = L::splat(xc);
            let column = w.add(c * stride);
            for (b, s) in s.iter_mut().enumerate() {
                *s = L::fmadd(L::load(column.add(L::N * b)), xv, *s);
            }
        }
        s
    }
}

/// [`column_chains`] with AVX-512F: what the decode's one-pass kernels of `super::x86_world`
/// sum.
///
/// # Safety
/// The CPU must have AVX-512F; `16 V` floats from `w + c * stride` must be readable for every
/// column `c < x.len()`.
#[target_feature(enable = "avx512f")]
#[inline]
pub(super) unsafe fn column_chains512<const V: usize>(w: *const f32, stride: usize, x: &[f32]) -> [__m512; V] {
    // SAFETY: compiled for AVX-512F; the caller's promise.
    unsafe { column_chains::<Avx512, V>(w, stride, x) }
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

/// The weights (column by column) and biases of a [`WeightFormat::F32Columns`] layer, when
/// rows `first..first + n` of it exist for an input of `cols` values.
pub(super) fn column_layer<'p>(
    params: &'p [f32],
    layer: &Layer,
    cols: usize,
    first: usize,
    n: usize,
) -> Option<(&'p [f32], &'p [f32])> {
    if layer.format != WeightFormat::F32Columns {
        return None;
    }
    let w = matrix(params, layer);
    checked(params, layer, w, cols, first, n).map(|bias| (w, bias))
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
