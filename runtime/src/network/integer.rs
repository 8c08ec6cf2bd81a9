//! The int8 kernel: integer products summed exactly, so every target computes the same bits.
//!
//! The input `x` of a layer is quantised once per call with one scale for the whole vector:
//! `m = max |x_c|`, `L = levels(cols)`, `q_c = round(x_c * (L / m))` (an `i16` in `[-L, L]`),
//! `scale_x = m / L`. A row is `acc = sum_c w[r][c] * q_c` in `i32`, then
//! `y[r] = b[r] + s[r] * (acc * scale_x)` in `f32` (multiply, then add, in that order).
//! `L` keeps `acc` inside `i32` for any weights (-128 included): `128 * L * cols <= i32::MAX`,
//! so the sum is exact and its order free. Each target adds in its own way:
//!
//! - x86-64: `vpmaddwd` on 16 (AVX2) or 32 (AVX-512BW) weights at a time, or `vpdpwssd`
//!   where the CPU has AVX-512 VNNI; chosen at run time under `std`, by target features
//!   without it;
//! - wasm with `simd128`: `i32x4.dot_i16x8_s` on 8 weights at a time (`network/wasm.rs`);
//! - Armv7E-M (Cortex-M4, the `armv7em` feature): `SMLAD`, two 16-bit multiply-accumulates per
//!   instruction, on weight pairs unpacked by `SXTB16` (the activations are stored
//!   pair-interleaved to match; `network/armv7em.rs`);
//! - AArch64: `SDOT` on the activations split into bytes where the CPU has the dot-product
//!   extension, `SMLAL` without it (`network/aarch64.rs`);
//! - anywhere else: a plain loop.
//!
//! Each target's kernel sums the leading columns it takes; the plain loop adds the rest.
//! Which kernel runs is chosen in one place ([`super`]'s `isa_` functions).
//!
//! An input with a NaN or infinity gives NaN rows (the instance then reports a non-finite
//! state, as the float kernels' NaN would).

use super::finish;
use crate::model::Layer;

/// Largest layer input the integer path quantises (the quantised copy lives on the stack:
/// 2 KiB). Larger inputs give NaN rows.
pub const MAX_COLS: usize = 1024;

/// Quantisation levels for a layer of `cols` inputs: the most that keeps `128 * L * cols`
/// inside `i32`, at most `i16::MAX`.
pub const fn levels(cols: usize) -> i32 {
    let bound = i32::MAX as usize / (128 * if cols == 0 { 1 } else { cols });
    if bound > i16::MAX as usize {
        i16::MAX as i32
    } else {
        bound as i32
    }
}

/// An input vector quantised for the integer kernels.
pub struct Quantized {
    q: [i16; MAX_COLS],
    cols: usize,
    scale: f32,
}

impl Quantized {
    /// Quantises the concatenation of `parts` (the first `cols` values; missing values are
    /// zeros). `None` when `cols` exceeds [`MAX_COLS`] or the input is not finite.
    pub fn new(parts: &[&[f32]], cols: usize) -> Option<Quantized> {
        if cols > MAX_COLS {
            return None;
        }
        let values = || parts.iter().flat_map(|p| p.iter()).take(cols);
        // The largest magnitude, NaN kept (`f32::max` would drop it).
        let m = values().fold(0.0f32, |m, &v| if v.abs() > m || v.is_nan() { v.abs() } else { m });
        if !m.is_finite() {
            return None;
        }
        let mut quantized = Quantized {
            q: [0; MAX_COLS],
            cols,
            scale: 0.0,
        };
        if m > 0.0 {
            let levels = levels(cols) as f32;
            let inv = levels / m;
            for (q, &v) in quantized.q.iter_mut().zip(values()) {
                *q = libm::roundf(v * inv).clamp(-levels, levels) as i16;
            }
            quantized.scale = m / levels;
        }
        arrange(&mut quantized.q[..cols]);
        Some(quantized)
    }

    /// The quantisation step `scale_x`.
    pub fn scale(&self) -> f32 {
        self.scale
    }

    /// `sum_c w[c] * q_c` for a row `w` of `cols` weights (a shorter row reads as zeros).
    pub fn dot(&self, w: &[i8]) -> i32 {
        if w.len() != self.cols {
            return 0;
        }
        dot(w, &self.q[..self.cols])
    }
}

/// Rows `first..first + out.len()` of the int8 layer `layer` (scales and biases in `params`,
/// weights `w`) for the input `parts`.
pub fn rows(params: &[f32], layer: &Layer, w: &[i8], parts: &[&[f32]], first: usize, out: &mut [f32]) {
    match Quantized::new(parts, layer.cols as usize) {
        Some(x) => quantized_rows(params, layer, w, &x, first, out),
        None => out.fill(f32::NAN),
    }
}

/// [`rows`] for an input already quantised for this layer (`x` from [`Quantized::new`] with
/// the layer's column count): a caller that computes a layer's rows in several calls
/// quantises once.
pub fn quantized_rows(params: &[f32], layer: &Layer, w: &[i8], x: &Quantized, first: usize, out: &mut [f32]) {
    let cols = layer.cols as usize;
    let n = out.len();
    let span = |start: u32| params.get(start as usize + first..start as usize + first + n);
    // Every row, bias and scale present (a valid model): one pass without per-row lookups.
    if let (Some(w), Some(bias), Some(scale), true) = (
        w.get(first * cols..(first + n) * cols),
        span(layer.bias),
        span(layer.scales),
        cols > 0 && x.cols == cols,
    ) {
        let q = &x.q[..cols];
        let done = super::isa_rows_i8(w, q, x.scale, bias, scale, out);
        let rows = out.iter_mut().zip(w.chunks_exact(cols)).zip(bias).zip(scale);
        for (((o, row), &b), &s) in rows.skip(done) {
            *o = b + s * (dot(row, q) as f32 * x.scale);
        }
        return;
    }
    for (i, o) in out.iter_mut().enumerate() {
        let r = first + i;
        let acc = w.get(r * cols..(r + 1) * cols).map_or(0, |row| x.dot(row));
        *o = finish(params, layer, r, acc as f32 * x.scale);
    }
}

/// Puts the quantised activations in the order this target's [`dot`] reads them.
#[inline(always)]
fn arrange(q: &mut [i16]) {
    super::isa_arrange_i8(q);
}

/// `sum w[c] * q[c]` in `i32` (`w.len() == q.len()`, `q` as [`arrange`] left it): the
/// target's vector kernel over the leading columns it takes, the plain loop over the rest.
#[inline]
fn dot(w: &[i8], q: &[i16]) -> i32 {
    let (head, w, q) = super::isa_dot_i8(w, q);
    head.wrapping_add(dot_portable(w, q))
}

/// The plain loop (any `q` order that matches `w`).
#[inline]
pub fn dot_portable(w: &[i8], q: &[i16]) -> i32 {
    w.iter()
        .zip(q)
        .fold(0i32, |acc, (&w, &q)| acc.wrapping_add(i32::from(w) * i32::from(q)))
}

#[cfg(all(test, feature = "std"))]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::*;
    use crate::model::WeightFormat;
    use crate::network::dense_rows;
    use crate::network::test_support::{noise, Case};

    /// The definition in the module docs, written out plainly in `i64` (no overflow to hide).
    fn reference(case: &Case, x: &[f32], r: usize) -> f32 {
        let cols = case.cols;
        let m = x.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let levels = levels(cols) as f32;
        let q: Vec<i64> = x.iter().map(|v| libm::roundf(v * (levels / m)) as i64).collect();
        let acc: i64 = (0..cols).map(|c| i64::from(case.bytes[r * cols + c]) * q[c]).sum();
        let scale = case.params[case.rows + r];
        case.params[r] + scale * (acc as i32 as f32 * (m / levels))
    }

    /// Every row count and column count, whole or split into parts or from a row offset,
    /// gives the definition's bits; the result is within the quantisation's error of the
    /// float product.
    #[test]
    fn integer_kernel_gives_the_definition_bit_for_bit() {
        for (rows_n, cols) in [
            (1, 8),
            (3, 16),
            (13, 24),
            (21, 40),
            (9, 7),
            (17, 44),
            (40, 128),
            (5, 3),
            (6, 1000),
        ] {
            let case = Case::new(rows_n, cols);
            let x: Vec<f32> = noise(cols as u32 + 5, cols).map(|v| 3.0 * v).collect();
            let layer = case.layer(WeightFormat::Int8);
            let want: Vec<f32> = (0..rows_n).map(|r| reference(&case, &x, r)).collect();
            let mut out = std::vec![0.0; rows_n];
            dense_rows(&case.weights(), &layer, &[&x], 0, &mut out);
            assert_eq!(out, want, "{rows_n}x{cols}");
            let (a, b) = x.split_at(cols / 3);
            dense_rows(&case.weights(), &layer, &[a, b], 0, &mut out);
            assert_eq!(out, want, "{rows_n}x{cols} in two parts");
            let mut tail = std::vec![0.0; rows_n - 1];
            dense_rows(&case.weights(), &layer, &[&x], 1, &mut tail);
            assert_eq!(tail[..], want[1..], "{rows_n}x{cols} from row 1");
            for (r, y) in want.iter().enumerate() {
                let w = case.row(WeightFormat::Int8, r);
                let s = case.params[rows_n + r];
                let float: f32 = case.params[r] + s * w.iter().zip(&x).map(|(w, x)| w * x).sum::<f32>();
                let step = 3.0 / levels(cols) as f32;
                let bound = s * 127.0 * step * cols as f32 * 0.5 + 1e-4;
                assert!((y - float).abs() <= bound, "{rows_n}x{cols} row {r}: {y} vs {float}");
            }
        }
    }

    /// The largest sums stay exact: every weight at -128 or 127 and every input at the
    /// largest magnitude, for the widest input.
    #[test]
    fn extreme_weights_and_inputs_do_not_overflow() {
        let cols = MAX_COLS;
        let x = std::vec![-1.0f32; cols];
        let q = Quantized::new(&[&x], cols).unwrap();
        let w = std::vec![-128i8; cols];
        let want = 128i64 * i64::from(levels(cols)) * cols as i64;
        assert!(want <= i64::from(i32::MAX));
        assert_eq!(i64::from(q.dot(&w)), want);
        assert_eq!(dot_portable(&w, &q.q[..cols]), q.dot(&w));
    }

    /// Zero input gives the biases; NaN or infinite input and inputs wider than the room give
    /// NaN rows, never a panic.
    #[test]
    fn degenerate_inputs() {
        let case = Case::new(3, 16);
        let layer = case.layer(WeightFormat::Int8);
        let mut out = [0.0f32; 3];
        dense_rows(&case.weights(), &layer, &[&[0.0; 16]], 0, &mut out);
        assert_eq!(out[..], case.params[..3]);
        let mut bad = [0.5f32; 16];
        for v in [f32::NAN, f32::INFINITY] {
            bad[7] = v;
            dense_rows(&case.weights(), &layer, &[&bad], 0, &mut out);
            assert!(out.iter().all(|y| y.is_nan()), "{v}");
        }
        assert!(Quantized::new(&[&[1.0; 4]], MAX_COLS + 1).is_none());
        assert_eq!(levels(0), i16::MAX as i32);
        assert_eq!(levels(1000), 16_777);
    }
}
