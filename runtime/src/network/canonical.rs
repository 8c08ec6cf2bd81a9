//! The canonical sum (see [`super`]): eight lanes over the columns, every product and sum
//! rounded to `f32`, no fused multiply-add, a fixed fold. `f16` layers always use it (the same
//! bits on every target); `f32` layers use it where the CPU has no [`super::fast`] kernel.
//! The loops are written so the compiler vectorises them; on x86-64 an AVX2 version of the
//! same arithmetic serves `f16` weights where the CPU has it (see [`super::dense_rows`]).

use super::finish;
use crate::model::Layer;

/// Lanes of the canonical sum.
pub const LANES: usize = 8;

/// A stored weight, converted exactly to `f32`.
pub trait Stored: Copy {
    /// The weight's value.
    fn value(self) -> f32;
}

impl Stored for f32 {
    #[inline(always)]
    fn value(self) -> f32 {
        self
    }
}

/// Half-precision bit pattern (an exact conversion: every `f16` is an `f32`), converted by the
/// FPU where it can (`network/armv7em.rs`), in software elsewhere.
impl Stored for u16 {
    #[inline(always)]
    fn value(self) -> f32 {
        super::isa_f16_to_f32(self)
    }
}

/// The canonical fold of the eight lanes.
#[inline(always)]
pub fn fold(l: &[f32; LANES]) -> f32 {
    ((l[0] + l[4]) + (l[1] + l[5])) + ((l[2] + l[6]) + (l[3] + l[7]))
}

/// Rows `first..first + out.len()` of `layer`, whose weights are `w`, for the input given as
/// consecutive `parts`.
pub fn rows<T: Stored>(params: &[f32], layer: &Layer, w: &[T], parts: &[&[f32]], first: usize, out: &mut [f32]) {
    let mut done = 0;
    if let [x] = parts {
        if x.len() == layer.cols as usize && x.len().is_multiple_of(LANES) {
            done = rows_blocked(params, layer, w, x, first, out);
        }
    }
    rows_general(params, layer, w, parts, first + done, &mut out[done..]);
}

/// Rows for the input given as consecutive `parts`, any `cols`.
fn rows_general<T: Stored>(params: &[f32], layer: &Layer, w: &[T], parts: &[&[f32]], first: usize, out: &mut [f32]) {
    let cols = layer.cols as usize;
    for (i, o) in out.iter_mut().enumerate() {
        let r = first + i;
        let mut row = w.get(r * cols..(r + 1) * cols).unwrap_or(&[]);
        let mut lanes = [0.0f32; LANES];
        // Column `c` goes to lane `c % 8`: each part is split into a head that completes the
        // lane cycle the previous part left open, whole cycles (vectorised), and a tail.
        let mut lane = 0;
        for part in parts {
            let n = part.len().min(row.len());
            let (x, rest) = (&part[..n], &row[n..]);
            let wx = &row[..n];
            let head = ((LANES - lane) % LANES).min(n);
            for (wv, &v) in wx[..head].iter().zip(&x[..head]) {
                lanes[lane] += wv.value() * v;
                lane += 1;
            }
            lane %= LANES;
            let (wc, wt) = wx[head..].as_chunks::<LANES>();
            let (xc, xt) = x[head..].as_chunks::<LANES>();
            for (a, b) in wc.iter().zip(xc) {
                for l in 0..LANES {
                    lanes[l] += a[l].value() * b[l];
                }
            }
            for (wv, &v) in wt.iter().zip(xt) {
                lanes[lane] += wv.value() * v;
                lane += 1;
            }
            row = rest;
        }
        *o = finish(params, layer, r, fold(&lanes));
    }
}

/// Rows [`rows_blocked`] computes together (four where vector registers hold their lanes,
/// two on the Cortex-M4: see [`super`]'s `ISA_ROW_BLOCK`).
const ROW_BLOCK: usize = super::ISA_ROW_BLOCK;

/// Rows [`ROW_BLOCK`] at a time, `x` loaded once for all of them (a matrix-vector product is
/// limited by loads; this divides them). `x.len() == cols`, a multiple of 8. Returns the
/// leading rows of `out` written (a multiple of the block).
#[inline(always)]
fn rows_blocked<T: Stored>(params: &[f32], layer: &Layer, w: &[T], x: &[f32], first: usize, out: &mut [f32]) -> usize {
    let cols = layer.cols as usize;
    let (xc, _) = x.as_chunks::<LANES>();
    let row = |r: usize| w.get(r * cols..(r + 1) * cols).unwrap_or(&[]).as_chunks::<LANES>().0;
    let mut done = 0;
    for (block, o) in out.chunks_exact_mut(ROW_BLOCK).enumerate() {
        let r = first + ROW_BLOCK * block;
        let rows: [&[[T; LANES]]; ROW_BLOCK] = core::array::from_fn(|k| row(r + k));
        // A row missing from `w` stops the whole block (its rows give their biases).
        let groups = rows.iter().fold(xc.len(), |n, w| n.min(w.len()));
        let (xc, rows) = (&xc[..groups], rows.map(|w| &w[..groups]));
        let mut acc = [[0.0f32; LANES]; ROW_BLOCK];
        for g in 0..groups {
            for (acc, w) in acc.iter_mut().zip(&rows) {
                for l in 0..LANES {
                    acc[l] += w[g][l].value() * xc[g][l];
                }
            }
        }
        for (k, (o, lanes)) in o.iter_mut().zip(&acc).enumerate() {
            *o = finish(params, layer, r + k, fold(lanes));
        }
        done += ROW_BLOCK;
    }
    done
}

/// Rows [`column_rows`] computes together: four, fewer instructions per frame than one, two,
/// eight or sixteen both on the Cortex-M4 (whose 32 single-precision registers hold four
/// rows' eight lanes) and in wasm with `simd128` (`scripts/run-cortex-m4.sh`,
/// `scripts/run-wasm.sh`).
const COLUMN_BLOCK: usize = 4;

/// [`rows`] for a layer stored column by column (`W[r][c]` at `w[c * column_stride(rows) +
/// r]`): the same sum, so the same bits as the layer stored row by row. [`COLUMN_BLOCK`] rows
/// at a time, each column read as that many consecutive values.
pub fn column_rows<T: Stored>(params: &[f32], layer: &Layer, w: &[T], parts: &[&[f32]], first: usize, out: &mut [f32]) {
    let (rows, cols) = (layer.rows as usize, layer.cols as usize);
    let stride = crate::model::column_stride(rows);
    let w = w.get(..stride * cols).unwrap_or(&[]);
    let done = match parts {
        [x] if x.len() == cols && !w.is_empty() => column_blocks::<T, COLUMN_BLOCK>(params, layer, w, x, first, out),
        _ => 0,
    };
    // The rest (an input in several parts, a block past the columns' padding): row by row, a
    // missing weight read as nothing.
    for (i, o) in out.iter_mut().enumerate().skip(done) {
        let r = first + i;
        let mut lanes = [0.0f32; LANES];
        let x = parts.iter().flat_map(|p| p.iter()).take(cols);
        for (c, &v) in x.enumerate() {
            if let Some(wv) = w.get(c * stride + r).filter(|_| r < rows) {
                lanes[c % LANES] += wv.value() * v;
            }
        }
        *o = finish(params, layer, r, fold(&lanes));
    }
}

/// The leading whole blocks of `ROWS` rows of [`column_rows`] for one input `x` (`w` the
/// layer's `stride * cols` weights); returns the rows written. The columns go eight at a
/// time, so that every lane index is a constant.
#[inline(always)]
fn column_blocks<T: Stored, const ROWS: usize>(
    params: &[f32],
    layer: &Layer,
    w: &[T],
    x: &[f32],
    first: usize,
    out: &mut [f32],
) -> usize {
    let stride = crate::model::column_stride(layer.rows as usize);
    let (xc, xt) = x.as_chunks::<LANES>();
    let mut done = 0;
    for (block, o) in out.chunks_exact_mut(ROWS).enumerate() {
        let r = first + ROWS * block;
        let column = |c: usize| {
            w.get(c * stride + r..c * stride + r + ROWS)
                .and_then(|s| <&[T; ROWS]>::try_from(s).ok())
        };
        if r + ROWS > stride {
            break;
        }
        // lanes[l][k]: lane `l` of the canonical sum of row `r + k`.
        let mut lanes = [[0.0f32; ROWS]; LANES];
        for (g, xg) in xc.iter().enumerate() {
            for l in 0..LANES {
                let Some(col) = column(g * LANES + l) else {
                    return done;
                };
                for k in 0..ROWS {
                    lanes[l][k] += col[k].value() * xg[l];
                }
            }
        }
        for (l, &v) in xt.iter().enumerate() {
            let Some(col) = column(xc.len() * LANES + l) else {
                return done;
            };
            for k in 0..ROWS {
                lanes[l][k] += col[k].value() * v;
            }
        }
        for (k, o) in o.iter_mut().enumerate() {
            let row: [f32; LANES] = core::array::from_fn(|l| lanes[l][k]);
            *o = finish(params, layer, r + k, fold(&row));
        }
        done += ROWS;
    }
    done
}

#[cfg(all(test, feature = "std"))]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::*;
    use crate::model::WeightFormat;
    use crate::network::test_support::{noise, Case};
    use crate::network::{dense_rows, matrix};

    /// The canonical sum written out plainly, for one row.
    fn reference(w: &[f32], x: &[f32], b: f32) -> f32 {
        let mut lanes = [0.0f32; LANES];
        for (c, (w, x)) in w.iter().zip(x).enumerate() {
            lanes[c % LANES] += w * x;
        }
        b + fold(&lanes)
    }

    /// `f16` layers through every path (blocked, general, multi-part, AVX2 where the CPU has
    /// it) and the portable `f32` kernel give the canonical sum bit for bit, for every row
    /// count and a few column counts.
    #[test]
    fn every_canonical_path_gives_the_canonical_sum_bit_for_bit() {
        for (rows_n, cols) in [(1, 8), (3, 16), (13, 24), (21, 40), (9, 7), (17, 44)] {
            let case = Case::new(rows_n, cols);
            let x: Vec<f32> = noise(cols as u32, cols).collect();
            let weights = case.weights();
            for format in [WeightFormat::F32, WeightFormat::F16] {
                let layer = case.layer(format);
                let want: Vec<f32> = (0..rows_n)
                    .map(|r| reference(&case.row(format, r), &x, case.params[r]))
                    .collect();
                let mut portable = std::vec![0.0; rows_n];
                match format {
                    WeightFormat::F32 => rows(
                        &case.params,
                        &layer,
                        matrix(&case.params, &layer),
                        &[&x],
                        0,
                        &mut portable,
                    ),
                    _ => rows(
                        &case.params,
                        &layer,
                        matrix(&case.halves, &layer),
                        &[&x],
                        0,
                        &mut portable,
                    ),
                }
                assert_eq!(portable, want, "{format:?} {rows_n}x{cols} portable");
                if format == WeightFormat::F32 {
                    // Stored column by column: the same sum, whole or in parts.
                    let columns = case.columns();
                    let layer = case.layer(WeightFormat::F32Columns);
                    let mut out = std::vec![0.0; rows_n];
                    column_rows(&columns, &layer, matrix(&columns, &layer), &[&x], 0, &mut out);
                    assert_eq!(out, want, "{rows_n}x{cols} by columns");
                    let (a, b) = x.split_at(cols / 3);
                    column_rows(&columns, &layer, matrix(&columns, &layer), &[a, b], 1, &mut out[1..]);
                    assert_eq!(out, want, "{rows_n}x{cols} by columns, in two parts, from row 1");
                    continue;
                }
                let mut out = std::vec![0.0; rows_n];
                dense_rows(&weights, &layer, &[&x], 0, &mut out);
                assert_eq!(out, want, "{format:?} {rows_n}x{cols}");
                let mut general = std::vec![0.0; rows_n];
                let (a, b) = x.split_at(cols / 3);
                dense_rows(&weights, &layer, &[a, b], 0, &mut general);
                assert_eq!(general, want, "{format:?} {rows_n}x{cols} in two parts");
                let (a, rest) = x.split_at(cols.min(3));
                let (b, c) = rest.split_at(rest.len().min(9));
                dense_rows(&weights, &layer, &[a, b, c], 0, &mut general);
                assert_eq!(general, want, "{format:?} {rows_n}x{cols} in three parts");
                let mut tail = std::vec![0.0; rows_n - 1];
                dense_rows(&weights, &layer, &[&x], 1, &mut tail);
                assert_eq!(tail[..], want[1..], "{format:?} {rows_n}x{cols} from row 1");
            }
        }
    }
}
