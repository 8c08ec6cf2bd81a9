//! x86-64 vector kernels: the wide `f32` kernel ([`super::fast`]), the canonical `f16` sum on
//! AVX2 + F16C ([`super::canonical`]), and the int8 dot products ([`super::integer`]).
//!
//! Every kernel reads only inside the slices it is given (bounds are checked before each
//! block, tails use masked loads), so a corrupted layer table cannot make it read past a pool.

use core::arch::x86_64::*;

use super::canonical::{fold, Stored, LANES};
use super::x86_lanes::{wide_driver, Avx2, Avx512, Lanes};
use super::{finish, matrix, Width};
use crate::model::{Layer, WeightFormat, Weights};

/// Whether this CPU has a feature: detected at run time (once, then cached by std) under
/// `std`, the compiled target features without it.
macro_rules! has {
    ($feature:tt) => {{
        #[cfg(feature = "std")]
        let yes = std::is_x86_feature_detected!($feature);
        #[cfg(not(feature = "std"))]
        let yes = cfg!(target_feature = $feature);
        yes
    }};
}

/// The wide `f32` kernel this CPU runs.
pub(super) fn width() -> Width {
    if has!("avx512f") {
        Width::Avx512
    } else if has!("avx2") && has!("fma") {
        Width::Avx2
    } else {
        Width::Canonical
    }
}

/// Rows the wide `f32` kernels compute together (each row still gets exactly the arithmetic
/// it gets alone: its own chain of fused multiply-adds, then the same reduction).
const BLOCK: usize = 8;

/// Sums each of eight 8-lane vectors: lane `k` of the result is the sum of `s[k]`, by a tree
/// that reads no other vector (so a row's sum does not depend on its neighbours).
#[target_feature(enable = "avx2")]
#[inline]
fn reduce8(s: [__m256; BLOCK]) -> __m256 {
    let t0 = _mm256_hadd_ps(s[0], s[1]);
    let t1 = _mm256_hadd_ps(s[2], s[3]);
    let t2 = _mm256_hadd_ps(s[4], s[5]);
    let t3 = _mm256_hadd_ps(s[6], s[7]);
    let u0 = _mm256_hadd_ps(t0, t1);
    let u1 = _mm256_hadd_ps(t2, t3);
    _mm256_add_ps(
        _mm256_permute2f128_ps::<0x20>(u0, u1),
        _mm256_permute2f128_ps::<0x31>(u0, u1),
    )
}

/// Writes the reduced sums of `n` rows from `r` (bias added) into `out`.
#[inline(always)]
fn store_rows(params: &[f32], layer: &Layer, sums: __m256, r: usize, out: &mut [f32]) {
    let start = layer.bias as usize + r;
    if let (Some(bias), true) = (params.get(start..start + BLOCK), out.len() == BLOCK) {
        // `finish` of an `f32` layer (the only kind these kernels run), eight rows at once.
        // SAFETY: `bias` and `out` hold 8 floats; AVX, as above.
        unsafe { _mm256_storeu_ps(out.as_mut_ptr(), _mm256_add_ps(_mm256_loadu_ps(bias.as_ptr()), sums)) };
        return;
    }
    let mut lanes = [0.0f32; BLOCK];
    // SAFETY: `lanes` holds 8 floats; storing needs only AVX, which every caller has.
    unsafe { _mm256_storeu_ps(lanes.as_mut_ptr(), sums) };
    for (k, o) in out.iter_mut().enumerate() {
        *o = finish(params, layer, r + k, lanes[k]);
    }
}

/// The wide kernel for rows `first..first + out.len()` of an `f32` layer (weights `w` in the
/// layer's layout, input `x`); returns the rows written (0 where the CPU has no wide kernel).
pub(super) fn rows_f32(params: &[f32], layer: &Layer, w: &[f32], x: &[f32], first: usize, out: &mut [f32]) -> usize {
    let columns = layer.format == WeightFormat::F32Columns;
    // SAFETY: `width` reports only kernels whose features this CPU has; the kernels take
    // every bound from the slices (see their docs).
    unsafe {
        match width() {
            Width::Avx512 if columns => super::columns::rows512(params, layer, w, x, first, out),
            Width::Avx2 if columns => super::columns::rows256(params, layer, w, x, first, out),
            Width::Avx512 if x.len() <= super::narrow::MAX_COLS => super::narrow::rows(params, layer, w, x, first, out),
            Width::Avx512 => rows_f32_avx512(params, layer, w, x, first, out),
            Width::Avx2 => rows_f32_avx2(params, layer, w, x, first, out),
            Width::Canonical | Width::Neon => 0,
        }
    }
}

/// The accumulators of `N` consecutive rows starting at `base` (row stride `cols`): for each
/// row one chain of `L::N`-lane fused multiply-adds over the columns, the last block masked;
/// the rows past `N` stay zero. `N` is a constant so that the chains live in registers.
///
/// # Safety
/// Inside a wrapper compiled for `L`'s features (see [`Lanes`]); `base..base + N * cols` and
/// `x..x + cols` must be readable.
#[inline(always)]
unsafe fn chains<L: Lanes, const N: usize>(base: *const f32, x: *const f32, cols: usize) -> [L::V; BLOCK] {
    let (whole, rem) = (cols / L::N, cols % L::N);
    // SAFETY: for row k < N and column block i < whole, k * cols + N i + N <= N * cols and
    // N i + N <= cols; the masked tail reads only the `rem` columns that exist.
    unsafe {
        let mut acc = [L::zero(); BLOCK];
        for i in 0..whole {
            let xv = L::load(x.add(L::N * i));
            for (k, a) in acc.iter_mut().enumerate().take(N) {
                *a = L::fmadd(L::load(base.add(k * cols + L::N * i)), xv, *a);
            }
        }
        if rem > 0 {
            let mask = L::mask(rem);
            let xv = L::load_masked(mask, x.add(L::N * whole));
            for (k, a) in acc.iter_mut().enumerate().take(N) {
                *a = L::fmadd(L::load_masked(mask, base.add(k * cols + L::N * whole)), xv, *a);
            }
        }
        acc
    }
}

/// Rows `first..first + out.len()` of an `f32` layer with `L`'s vectors: eight rows at a
/// time ([`chains`]), the rest one at a time, then each accumulator summed into eight lanes
/// and [`reduce8`] (which gives a row the same bits whichever lane it sits in). Returns the
/// rows written.
///
/// # Safety
/// Inside a wrapper compiled for `L`'s features and AVX2. `x.len() == cols`; rows outside
/// `w` are not written.
#[inline(always)]
unsafe fn rows_wide<L: Lanes>(
    params: &[f32],
    layer: &Layer,
    w: &[f32],
    x: &[f32],
    first: usize,
    out: &mut [f32],
) -> usize {
    let cols = x.len();
    let mut r = first;
    for o in out.chunks_mut(BLOCK) {
        let n = o.len();
        let Some(block) = w.get(r * cols..(r + n) * cols) else {
            return r - first;
        };
        // SAFETY (both branches): `block` holds the `n` rows; `x` holds `cols` values; the
        // caller's features.
        unsafe {
            if n == BLOCK {
                let acc = chains::<L, BLOCK>(block.as_ptr(), x.as_ptr(), cols);
                let mut eight = [_mm256_setzero_ps(); BLOCK];
                for (e, a) in eight.iter_mut().zip(acc) {
                    *e = L::eight(a);
                }
                store_rows(params, layer, reduce8(eight), r, o);
            } else {
                for (k, o) in o.iter_mut().enumerate() {
                    let acc = chains::<L, 1>(block.as_ptr().add(k * cols), x.as_ptr(), cols);
                    let mut eight = [_mm256_setzero_ps(); BLOCK];
                    eight[0] = L::eight(acc[0]);
                    store_rows(params, layer, reduce8(eight), r + k, core::slice::from_mut(o));
                }
            }
        }
        r += n;
    }
    out.len()
}

wide_driver!(
    /// [`rows_wide`] with AVX-512F.
    rows_f32_avx512 = rows_wide::<Avx512>, "avx512f,avx2"
);
wide_driver!(
    /// [`rows_wide`] with AVX2 and FMA.
    rows_f32_avx2 = rows_wide::<Avx2>, "avx2,fma"
);

/// Eight consecutive weights converted to `f32`.
trait Load8: Stored {
    /// # Safety
    /// `p..p + 8` must be readable, and the CPU must have AVX2 and F16C.
    unsafe fn load8(p: *const Self) -> __m256;
}

impl Load8 for u16 {
    #[inline(always)]
    unsafe fn load8(p: *const u16) -> __m256 {
        // SAFETY: the caller guarantees 8 readable halves (16 bytes) and F16C.
        unsafe { _mm256_cvtph_ps(_mm_loadu_si128(p.cast())) }
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

/// The canonical sum with AVX2: rows eight at a time into eight accumulators (`x` loaded once
/// per eight rows), then one at a time (multiply, then add: no FMA). `x.len() == cols`,
/// `cols % 8 == 0`. Returns the leading rows of `out` written.
#[target_feature(enable = "avx2,f16c")]
fn rows_canonical_avx<T: Load8>(
    params: &[f32],
    layer: &Layer,
    w: &[T],
    x: &[f32],
    first: usize,
    out: &mut [f32],
) -> usize {
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

/// The canonical `f16` sum with AVX2 and F16C when this CPU has them; returns the leading
/// rows of `out` written.
pub(super) fn rows_f16(weights: &Weights, layer: &Layer, x: &[f32], first: usize, out: &mut [f32]) -> usize {
    if x.len() != layer.cols as usize || !x.len().is_multiple_of(LANES) || !has!("avx2") || !has!("f16c") {
        return 0;
    }
    // SAFETY: the CPU has the features `rows_canonical_avx` is compiled for (checked above).
    unsafe { rows_canonical_avx(weights.params, layer, matrix(weights.halves, layer), x, first, out) }
}

/// Whether every value is finite (no value with every exponent bit set: one pass of compares
/// and ORs, compiled for AVX-512F) where the `f32` kernel is AVX-512F; `None` otherwise.
pub(super) fn all_finite(values: &[f32]) -> Option<bool> {
    if super::fast::width() != Width::Avx512 {
        return None;
    }
    // SAFETY: the CPU has AVX-512F (`width` reports only what it has).
    Some(unsafe { all_finite_avx512(values) })
}

#[target_feature(enable = "avx512f")]
fn all_finite_avx512(values: &[f32]) -> bool {
    const EXPONENT: u32 = 0x7f80_0000;
    let any = values
        .iter()
        .fold(0u32, |any, v| any | u32::from(v.to_bits() & EXPONENT == EXPONENT));
    any == 0
}

/// Which integer dot product this CPU runs.
#[derive(Clone, Copy, PartialEq, Eq)]
enum IntKernel {
    Vnni,
    Avx512,
    Avx2,
    Plain,
}

fn int_kernel() -> IntKernel {
    if has!("avx512bw") && has!("avx512vl") {
        if has!("avx512vnni") {
            return IntKernel::Vnni;
        }
        return IntKernel::Avx512;
    }
    if has!("avx2") {
        return IntKernel::Avx2;
    }
    IntKernel::Plain
}

/// `sum w[c] * q[c]` in `i32` with the widest integer kernel this CPU has; `None` where it has
/// none (the caller runs the plain loop). Exact, so every kernel gives the same sum.
#[inline]
pub(super) fn dot_i8(w: &[i8], q: &[i16]) -> Option<i32> {
    let n = w.len().min(q.len());
    let (w, q) = (&w[..n], &q[..n]);
    // SAFETY: each kernel runs only where `int_kernel` found its features.
    unsafe {
        match int_kernel() {
            IntKernel::Vnni => Some(dot_vnni(w, q)),
            IntKernel::Avx512 => Some(dot_avx512(w, q)),
            IntKernel::Avx2 => Some(dot_avx2(w, q)),
            IntKernel::Plain => None,
        }
    }
}

/// A 32-weights-at-a-time dot product: weights widened to `i16`, `$step(acc, w, q)` adds the
/// pairwise products into 16 `i32` lanes, masked loads for the tail.
macro_rules! dot512 {
    ($(#[$doc:meta])* $name:ident, $features:literal, $step:expr) => {
        $(#[$doc])*
        ///
        /// # Safety
        /// The CPU must have the features the function is compiled for.
        #[target_feature(enable = $features)]
        unsafe fn $name(w: &[i8], q: &[i16]) -> i32 {
            let n = w.len().min(q.len());
            let mut acc = _mm512_setzero_si512();
            let mut c = 0;
            // SAFETY: c + 32 <= n: 32 bytes of `w` and 32 halves of `q` are readable; the
            // tail's masked loads read only the `n - c` that exist.
            unsafe {
                while c + 32 <= n {
                    let wv = _mm512_cvtepi8_epi16(_mm256_loadu_si256(w.as_ptr().add(c).cast()));
                    acc = $step(acc, wv, _mm512_loadu_si512(q.as_ptr().add(c).cast()));
                    c += 32;
                }
                if c < n {
                    let mask: __mmask32 = (1u32 << (n - c)) - 1;
                    let wv = _mm512_cvtepi8_epi16(_mm256_maskz_loadu_epi8(mask, w.as_ptr().add(c)));
                    acc = $step(acc, wv, _mm512_maskz_loadu_epi16(mask, q.as_ptr().add(c)));
                }
            }
            _mm512_reduce_add_epi32(acc)
        }
    };
}

dot512!(
    /// `vpmaddwd` and an add (AVX-512BW).
    dot_avx512,
    "avx512bw,avx512vl",
    |acc, w, q| _mm512_add_epi32(acc, _mm512_madd_epi16(w, q))
);
dot512!(
    /// `vpdpwssd`, the two in one instruction (AVX-512 VNNI).
    dot_vnni,
    "avx512bw,avx512vl,avx512vnni",
    |acc, w, q| _mm512_dpwssd_epi32(acc, w, q)
);

/// 16 weights at a time, widened to `i16`, `vpmaddwd`.
///
/// # Safety
/// The CPU must have AVX2. `w.len() == q.len()`.
#[target_feature(enable = "avx2")]
unsafe fn dot_avx2(w: &[i8], q: &[i16]) -> i32 {
    let n = w.len().min(q.len());
    let mut acc = _mm256_setzero_si256();
    let mut c = 0;
    // SAFETY: c + 16 <= n: 16 bytes of `w` and 16 halves of `q` are readable.
    unsafe {
        while c + 16 <= n {
            let wv = _mm256_cvtepi8_epi16(_mm_loadu_si128(w.as_ptr().add(c).cast()));
            let qv = _mm256_loadu_si256(q.as_ptr().add(c).cast());
            acc = _mm256_add_epi32(acc, _mm256_madd_epi16(wv, qv));
            c += 16;
        }
    }
    let mut lanes = [0i32; 8];
    // SAFETY: `lanes` holds 8 integers.
    unsafe { _mm256_storeu_si256(lanes.as_mut_ptr().cast(), acc) };
    let head = lanes.iter().fold(0i32, |a, &b| a.wrapping_add(b));
    let tail = w[c..].iter().zip(&q[c..]);
    tail.fold(head, |acc, (&w, &q)| acc.wrapping_add(i32::from(w) * i32::from(q)))
}

#[cfg(all(test, feature = "std"))]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::*;
    use crate::model::WeightFormat;
    use crate::network::test_support::{noise, Case};

    /// Every integer kernel this CPU has gives the plain loop's sum, for lengths around every
    /// block size and the extreme values.
    #[test]
    fn every_integer_kernel_this_cpu_has_gives_the_exact_sum() {
        for n in [0, 1, 7, 15, 16, 17, 31, 32, 33, 63, 64, 100, 128, 1000] {
            let mut w: Vec<i8> = noise(n as u32, n).map(|v| (v * 127.0) as i8).collect();
            let mut q: Vec<i16> = noise(n as u32 + 1, n).map(|v| (v * 32767.0) as i16).collect();
            if n > 2 {
                (w[0], q[0], w[n - 1], q[n - 1]) = (-128, -32767, 127, 32767);
            }
            let want = w
                .iter()
                .zip(&q)
                .fold(0i32, |a, (&w, &q)| a.wrapping_add(i32::from(w) * i32::from(q)));
            // SAFETY: each kernel runs only where the CPU has its features.
            unsafe {
                if has!("avx2") {
                    assert_eq!(dot_avx2(&w, &q), want, "avx2 {n}");
                }
                if has!("avx512bw") && has!("avx512vl") {
                    assert_eq!(dot_avx512(&w, &q), want, "avx512 {n}");
                }
                if has!("avx512bw") && has!("avx512vl") && has!("avx512vnni") {
                    assert_eq!(dot_vnni(&w, &q), want, "vnni {n}");
                }
            }
        }
    }

    /// A wide `f32` kernel's signature.
    type WideKernel = unsafe fn(&[f32], &Layer, &[f32], &[f32], usize, &mut [f32]) -> usize;

    /// Both wide `f32` kernels this CPU may have: each row is within rounding of the exact
    /// sum and gets the same bits alone as in a block of eight.
    #[test]
    fn both_wide_kernels_are_within_rounding_and_blockwise_consistent() {
        for (rows_n, cols) in [(9, 7), (17, 44), (16, 128), (3, 1)] {
            let case = Case::new(rows_n, cols);
            let x: Vec<f32> = noise(cols as u32, cols).collect();
            let layer = case.layer(WeightFormat::F32);
            let w = &case.params[2 * rows_n..];
            let kernels: [(&str, bool, WideKernel); 2] = [
                ("avx512", has!("avx512f"), rows_f32_avx512),
                ("avx2", has!("avx2") && has!("fma"), rows_f32_avx2),
            ];
            for (name, present, kernel) in kernels {
                if !present {
                    continue;
                }
                let mut all = std::vec![0.0f32; rows_n];
                // SAFETY: the CPU has the kernel's features; the slices fit the layer.
                assert_eq!(unsafe { kernel(&case.params, &layer, w, &x, 0, &mut all) }, rows_n);
                for r in 0..rows_n {
                    let mut one = [0.0f32];
                    // SAFETY: as above.
                    unsafe { kernel(&case.params, &layer, w, &x, r, &mut one) };
                    assert_eq!(one[0], all[r], "{name} {rows_n}x{cols} row {r}");
                    let row = case.row(WeightFormat::F32, r);
                    let exact: f64 =
                        case.params[r] as f64 + row.iter().zip(&x).map(|(a, b)| *a as f64 * *b as f64).sum::<f64>();
                    let size: f64 = case.params[r].abs() as f64
                        + row.iter().zip(&x).map(|(a, b)| (a * b).abs() as f64).sum::<f64>();
                    assert!(
                        (all[r] as f64 - exact).abs() <= 4.0 * f32::EPSILON as f64 * size,
                        "{name} row {r}"
                    );
                }
            }
        }
    }
}
