//! Dense-layer kernels: the residual MLP forward pass of [`crate::model`], with scratch on the
//! stack (`H` floats per buffer, fixed at compile time).
//!
//! Every target computes every output with the same arithmetic, so a model gives bit-identical
//! positions on x86-64, wasm and Cortex-M4: row `r` of a layer is
//!
//! ```text
//! lane[l] = sum over columns c = l, l + 8, l + 16, ... (ascending) of  w[r][c] * x[c]
//! y[r]    = b[r] + s[r] * (((lane0 + lane4) + (lane1 + lane5)) + ((lane2 + lane6) + (lane3 + lane7)))
//! ```
//!
//! with every product and sum rounded to `f32` (no fused multiply-add), `w` converted exactly
//! from its storage format, and `s[r] = 1` unless the layer is stored as int8. The portable
//! loops are written so the compiler vectorises them; on x86-64 with `std` an AVX2 version of
//! the same arithmetic is chosen at run time when the CPU has it.

use crate::model::{Layer, WeightFormat, Weights};

/// `x * sigmoid(x)`.
#[inline]
pub fn swish(x: f32) -> f32 {
    x / (1.0 + libm::expf(-x))
}

/// Lanes of the canonical sum (see the module docs).
const LANES: usize = 8;

/// A stored weight, converted exactly to `f32`.
trait Stored: Copy {
    fn value(self) -> f32;
}

impl Stored for f32 {
    #[inline(always)]
    fn value(self) -> f32 {
        self
    }
}

/// Half-precision bit pattern.
impl Stored for u16 {
    #[inline(always)]
    fn value(self) -> f32 {
        half::f16::from_bits(self).to_f32()
    }
}

impl Stored for i8 {
    #[inline(always)]
    fn value(self) -> f32 {
        f32::from(self)
    }
}

/// The canonical fold of the eight lanes.
#[inline(always)]
fn fold(l: &[f32; LANES]) -> f32 {
    ((l[0] + l[4]) + (l[1] + l[5])) + ((l[2] + l[6]) + (l[3] + l[7]))
}

/// `b[r] + s[r] * sum` for row `r` of `layer`.
#[inline(always)]
fn finish(params: &[f32], layer: &Layer, r: usize, sum: f32) -> f32 {
    let b = params.get(layer.bias as usize + r).copied().unwrap_or(0.0);
    match layer.format {
        WeightFormat::Int8 => b + params.get(layer.scales as usize + r).copied().unwrap_or(0.0) * sum,
        WeightFormat::F32 | WeightFormat::F16 => b + sum,
    }
}

/// The weights of `layer` in its pool.
#[inline(always)]
fn matrix<'p, T>(pool: &'p [T], layer: &Layer) -> &'p [T] {
    let start = layer.weights as usize;
    pool.get(start..start + layer.rows as usize * layer.cols as usize)
        .unwrap_or(&[])
}

/// Rows `first..first + out.len()` of `w` (`cols` per row) for the input given as consecutive
/// `parts`, any `cols`.
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

/// Rows four at a time, `x` loaded once for all four (a matrix-vector product is limited by
/// loads; this halves them). `x.len() == cols`, a multiple of 8. Returns the leading rows of
/// `out` written (a multiple of 4).
#[inline(always)]
fn rows_blocked<T: Stored>(params: &[f32], layer: &Layer, w: &[T], x: &[f32], first: usize, out: &mut [f32]) -> usize {
    let cols = layer.cols as usize;
    let (xc, _) = x.as_chunks::<LANES>();
    let row = |r: usize| w.get(r * cols..(r + 1) * cols).unwrap_or(&[]).as_chunks::<LANES>().0;
    let mut done = 0;
    for (block, o) in out.chunks_exact_mut(4).enumerate() {
        let r = first + 4 * block;
        let [w0, w1, w2, w3] = [r, r + 1, r + 2, r + 3].map(row);
        let mut acc = [[0.0f32; LANES]; 4];
        for ((((xv, a), b), c), d) in xc.iter().zip(w0).zip(w1).zip(w2).zip(w3) {
            for l in 0..LANES {
                acc[0][l] += a[l].value() * xv[l];
                acc[1][l] += b[l].value() * xv[l];
                acc[2][l] += c[l].value() * xv[l];
                acc[3][l] += d[l].value() * xv[l];
            }
        }
        for (k, (o, lanes)) in o.iter_mut().zip(&acc).enumerate() {
            *o = finish(params, layer, r + k, fold(lanes));
        }
        done += 4;
    }
    done
}

/// The portable kernel for one storage pool.
fn rows_portable<T: Stored>(params: &[f32], layer: &Layer, w: &[T], parts: &[&[f32]], first: usize, out: &mut [f32]) {
    let mut done = 0;
    if let [x] = parts {
        if x.len() == layer.cols as usize && x.len().is_multiple_of(LANES) {
            done = rows_blocked(params, layer, w, x, first, out);
        }
    }
    rows_general(params, layer, w, parts, first + done, &mut out[done..]);
}

#[cfg(all(feature = "std", target_arch = "x86_64"))]
#[allow(unsafe_code)]
mod x86 {
    use super::*;
    use core::arch::x86_64::*;

    /// Eight consecutive weights converted to `f32`.
    trait Load8: Stored {
        /// # Safety
        /// `p..p + 8` must be readable, and the CPU must have AVX2 and F16C.
        unsafe fn load8(p: *const Self) -> __m256;
    }

    impl Load8 for f32 {
        #[inline(always)]
        unsafe fn load8(p: *const f32) -> __m256 {
            // SAFETY: the caller guarantees 8 readable floats.
            unsafe { _mm256_loadu_ps(p) }
        }
    }

    impl Load8 for u16 {
        #[inline(always)]
        unsafe fn load8(p: *const u16) -> __m256 {
            // SAFETY: the caller guarantees 8 readable halves (16 bytes) and F16C.
            unsafe { _mm256_cvtph_ps(_mm_loadu_si128(p.cast())) }
        }
    }

    impl Load8 for i8 {
        #[inline(always)]
        unsafe fn load8(p: *const i8) -> __m256 {
            // SAFETY: the caller guarantees 8 readable bytes; the conversions are exact.
            unsafe { _mm256_cvtepi32_ps(_mm256_cvtepi8_epi32(_mm_loadl_epi64(p.cast()))) }
        }
    }

    /// The lanes of an accumulator in memory order (lane `l` holds columns `c % 8 == l`).
    #[inline(always)]
    fn lanes(v: __m256) -> [f32; LANES] {
        let mut l = [0.0f32; LANES];
        // SAFETY: `l` holds 8 floats.
        unsafe { _mm256_storeu_ps(l.as_mut_ptr(), v) };
        l
    }

    /// Rows eight at a time into eight accumulators (`x` loaded once per eight rows), then one
    /// at a time, with the module's canonical arithmetic (multiply, then add: no FMA).
    /// `x.len() == cols`, `cols % 8 == 0`. Returns the leading rows of `out` written.
    #[target_feature(enable = "avx2,f16c")]
    fn rows_avx<T: Load8>(params: &[f32], layer: &Layer, w: &[T], x: &[f32], first: usize, out: &mut [f32]) -> usize {
        let cols = layer.cols as usize;
        let mut done = 0;
        for (block, o) in out.chunks_exact_mut(8).enumerate() {
            let r = first + 8 * block;
            let Some(w) = w.get(r * cols..(r + 8) * cols) else {
                break;
            };
            let mut acc = [_mm256_setzero_ps(); 8];
            let mut c = 0;
            while c + LANES <= cols {
                // SAFETY: c + 8 <= cols = x.len(), and k * cols + c + 8 <= 8 * cols = w.len()
                // for every row k < 8, so every 8-element load is in bounds.
                unsafe {
                    let xv = _mm256_loadu_ps(x.as_ptr().add(c));
                    for (k, a) in acc.iter_mut().enumerate() {
                        *a = _mm256_add_ps(*a, _mm256_mul_ps(T::load8(w.as_ptr().add(k * cols + c)), xv));
                    }
                }
                c += LANES;
            }
            for (k, (o, a)) in o.iter_mut().zip(acc).enumerate() {
                *o = finish(params, layer, r + k, fold(&lanes(a)));
            }
            done += 8;
        }
        for (i, o) in out.iter_mut().enumerate().skip(done) {
            let r = first + i;
            let Some(w) = w.get(r * cols..(r + 1) * cols) else {
                break;
            };
            let mut acc = _mm256_setzero_ps();
            let mut c = 0;
            while c + LANES <= cols {
                // SAFETY: c + 8 <= cols = x.len() = w.len().
                unsafe {
                    let prod = _mm256_mul_ps(T::load8(w.as_ptr().add(c)), _mm256_loadu_ps(x.as_ptr().add(c)));
                    acc = _mm256_add_ps(acc, prod);
                }
                c += LANES;
            }
            *o = finish(params, layer, r, fold(&lanes(acc)));
            done = i + 1;
        }
        done
    }

    /// Computes what it can with AVX2 (and F16C) when this CPU has them (detected once by
    /// std, then cached); returns the leading rows of `out` written.
    pub(super) fn rows(weights: &Weights, layer: &Layer, x: &[f32], first: usize, out: &mut [f32]) -> usize {
        if x.len() != layer.cols as usize
            || !x.len().is_multiple_of(LANES)
            || !std::is_x86_feature_detected!("avx2")
            || !std::is_x86_feature_detected!("f16c")
        {
            return 0;
        }
        let p = weights.params;
        // SAFETY: the CPU has the features `rows_avx` is compiled for (checked above).
        unsafe {
            match layer.format {
                WeightFormat::F32 => rows_avx(p, layer, matrix(p, layer), x, first, out),
                WeightFormat::F16 => rows_avx(p, layer, matrix(weights.halves, layer), x, first, out),
                WeightFormat::Int8 => rows_avx(p, layer, matrix(weights.bytes, layer), x, first, out),
            }
        }
    }
}

/// Rows `first..first + out.len()` of `layer` applied to the concatenation of `parts`.
pub fn dense_rows(weights: &Weights, layer: &Layer, parts: &[&[f32]], first: usize, out: &mut [f32]) {
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    let done = match parts {
        [x] => x86::rows(weights, layer, x, first, out),
        _ => 0,
    };
    #[cfg(not(all(feature = "std", target_arch = "x86_64")))]
    let done = 0;
    let (first, out) = (first + done, &mut out[done..]);
    let p = weights.params;
    match layer.format {
        WeightFormat::F32 => rows_portable(p, layer, matrix(p, layer), parts, first, out),
        WeightFormat::F16 => rows_portable(p, layer, matrix(weights.halves, layer), parts, first, out),
        WeightFormat::Int8 => rows_portable(p, layer, matrix(weights.bytes, layer), parts, first, out),
    }
}

/// The last hidden activation `swish(h)` of a network for the input `parts`, written into
/// `h`; `scratch` holds two more buffers. All three must hold the hidden width. The output
/// layer is then applied with [`dense_rows`], so a caller can compute only the rows it needs.
pub fn hidden(weights: &Weights, layers: &[Layer], parts: &[&[f32]], h: &mut [f32], scratch: [&mut [f32]; 2]) {
    let Some((input, rest)) = layers.split_first() else {
        return;
    };
    let blocks = rest.split_last().map_or(&[][..], |(_, b)| b);
    let [a, r] = scratch;
    let width = (input.rows as usize).min(h.len()).min(a.len()).min(r.len());
    let (h, a, r) = (&mut h[..width], &mut a[..width], &mut r[..width]);
    dense_rows(weights, input, parts, 0, h);
    for pair in blocks.chunks_exact(2) {
        dense_rows(weights, &pair[0], &[h], 0, a);
        a.iter_mut().for_each(|v| *v = swish(*v));
        dense_rows(weights, &pair[1], &[a], 0, r);
        h.iter_mut().zip(r.iter()).for_each(|(h, r)| *h += r);
    }
    h.iter_mut().for_each(|v| *v = swish(*v));
}

/// Multiply-adds of one forward pass of `layers` (for GFLOP/s reports).
pub fn multiply_adds(layers: &[Layer]) -> usize {
    layers.iter().map(|l| l.rows as usize * l.cols as usize).sum()
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;

    /// The canonical sum written out plainly, for one row.
    fn reference(w: &[f32], x: &[f32], b: f32, s: f32) -> f32 {
        let mut lanes = [0.0f32; LANES];
        for (c, (w, x)) in w.iter().zip(x).enumerate() {
            lanes[c % LANES] += w * x;
        }
        b + s * fold(&lanes)
    }

    /// A pseudo-random sequence (no dependency for a test).
    fn noise(seed: u32, n: usize) -> impl Iterator<Item = f32> {
        let mut state = seed.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
        (0..n).map(move |_| {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state as f32 / u32::MAX as f32) * 2.0 - 1.0
        })
    }

    /// Every path (blocked, general, multi-part, AVX2 where the CPU has it) and every format
    /// gives the canonical sum bit for bit, for every row count and a few column counts.
    #[test]
    fn every_path_gives_the_canonical_sum_bit_for_bit() {
        for (rows, cols) in [(1, 8), (3, 16), (13, 24), (21, 40), (9, 7), (17, 44)] {
            let x: std::vec::Vec<f32> = noise(cols as u32, cols).collect();
            let w32: std::vec::Vec<f32> = noise(rows as u32 * 7, rows * cols).collect();
            let halves: std::vec::Vec<u16> = w32.iter().map(|&v| half::f16::from_f32(v).to_bits()).collect();
            let bytes: std::vec::Vec<i8> = w32.iter().map(|&v| (v * 127.0) as i8).collect();
            let mut params: std::vec::Vec<f32> = noise(99, 2 * rows).collect();
            params.extend(&w32);
            let weights = Weights {
                params: &params,
                halves: &halves,
                bytes: &bytes,
            };
            for format in [WeightFormat::F32, WeightFormat::F16, WeightFormat::Int8] {
                let layer = Layer {
                    rows: rows as u32,
                    cols: cols as u32,
                    format,
                    weights: if format == WeightFormat::F32 {
                        2 * rows as u32
                    } else {
                        0
                    },
                    bias: 0,
                    scales: rows as u32,
                };
                let want: std::vec::Vec<f32> = (0..rows)
                    .map(|r| {
                        let w: std::vec::Vec<f32> = (0..cols)
                            .map(|c| match format {
                                WeightFormat::F32 => w32[r * cols + c],
                                WeightFormat::F16 => half::f16::from_bits(halves[r * cols + c]).to_f32(),
                                WeightFormat::Int8 => f32::from(bytes[r * cols + c]),
                            })
                            .collect();
                        let s = if format == WeightFormat::Int8 {
                            params[rows + r]
                        } else {
                            1.0
                        };
                        reference(&w, &x, params[r], s)
                    })
                    .collect();
                let mut out = std::vec![0.0; rows];
                dense_rows(&weights, &layer, &[&x], 0, &mut out);
                assert_eq!(out, want, "{format:?} {rows}x{cols}");
                let mut general = std::vec![0.0; rows];
                let (a, b) = x.split_at(cols / 3);
                dense_rows(&weights, &layer, &[a, b], 0, &mut general);
                assert_eq!(general, want, "{format:?} {rows}x{cols} in two parts");
                let (a, rest) = x.split_at(cols.min(3));
                let (b, c) = rest.split_at(rest.len().min(9));
                dense_rows(&weights, &layer, &[a, b, c], 0, &mut general);
                assert_eq!(general, want, "{format:?} {rows}x{cols} in three parts");
                let mut portable = std::vec![0.0; rows];
                match format {
                    WeightFormat::F32 => {
                        rows_portable(&params, &layer, matrix(&params, &layer), &[&x], 0, &mut portable)
                    }
                    WeightFormat::F16 => {
                        rows_portable(&params, &layer, matrix(&halves, &layer), &[&x], 0, &mut portable)
                    }
                    WeightFormat::Int8 => {
                        rows_portable(&params, &layer, matrix(&bytes, &layer), &[&x], 0, &mut portable)
                    }
                }
                assert_eq!(portable, want, "{format:?} {rows}x{cols} portable");
                let mut tail = std::vec![0.0; rows - 1];
                dense_rows(&weights, &layer, &[&x], 1, &mut tail);
                assert_eq!(tail[..], want[1..], "{format:?} {rows}x{cols} from row 1");
            }
        }
    }
}
