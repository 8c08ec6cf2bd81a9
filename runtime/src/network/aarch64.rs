//! AArch64 NEON kernels (every AArch64 CPU has NEON; the dot-product extension is detected):
//!
//! - `f32` rows ([`super::fast`]): fused multiply-add on 128-bit vectors, two chains of four
//!   lanes per row, four rows at a time; a layer stored by columns adds each column into
//!   sixteen rows per step. Any order is allowed for `f32`; each row's arithmetic does not
//!   depend on which call or block computes it.
//! - `f16` rows ([`super::canonical`]'s sum, bit for bit): `FCVTL`/`FCVTL2` widen eight
//!   weights to `f32`, the eight canonical lanes are two vectors, products and sums rounded
//!   separately (no fused multiply-add), and the fold is the canonical one. The conversion
//!   intrinsics take the `float16x4_t` type, stable only from Rust 1.94 (the workspace builds
//!   with 1.89), so the two instructions are written as inline assembly.
//! - int8 ([`super::integer`]): with the dot-product extension (`SDOT`, four `i8` products per
//!   `i32` lane), each `i16` activation `q` is split into two bytes, `a = q >> 8` and
//!   `b = (q & 255) - 128`, so that `q = 256 a + b + 128` and
//!   `w . q = 256 (w . a) + w . b + 128 (w . 1)`: three `SDOT`s per sixteen weights. The
//!   split is made once per input ([`arrange`]: sixteen `b` then sixteen `a` bytes in the room
//!   of sixteen `i16`), columns past the last whole sixteen stay `i16`. Without the extension,
//!   `SMLAL` on weights widened to `i16`. The integer sums wrap in `i32`, and the true sum
//!   fits ([`super::integer`]'s bound), so every order gives the same, exact, sum.
//!   `SDOT` is written as inline assembly: its intrinsic is not stable.
//!
//! Every kernel reads only inside the slices it is given (bounds are checked before each
//! block; tails are copied into zero-padded registers).

use core::arch::aarch64::*;
use core::arch::asm;

use super::canonical::LANES;
use super::finish;
use crate::model::{column_stride, Layer, WeightFormat};

/// Rows the row-major kernels compute together.
const BLOCK: usize = 4;

/// `n <= 4` floats from `p`, zero-padded to a vector.
///
/// # Safety
/// `p..p + n` must be readable.
#[inline(always)]
unsafe fn load_partial(p: *const f32, n: usize) -> float32x4_t {
    let mut v = [0.0f32; 4];
    // SAFETY: the caller's bound; `v` holds 4 floats.
    unsafe {
        core::ptr::copy_nonoverlapping(p, v.as_mut_ptr(), n.min(4));
        vld1q_f32(v.as_ptr())
    }
}

/// The sums of `N` rows from `base` (row stride `cols`) with `x`: per row two chains of fused
/// multiply-adds over eight columns at a time (columns 4..8 of each eight into the second),
/// a last four into the first, the rest zero-padded into the second, then the two added and
/// reduced pairwise.
///
/// # Safety
/// `base..base + N * cols` and `x..x + cols` must be readable.
#[inline(always)]
unsafe fn chains<const N: usize>(base: *const f32, x: *const f32, cols: usize) -> [f32; N] {
    let zero = vdupq_n_f32(0.0);
    let (mut a, mut b) = ([zero; N], [zero; N]);
    let mut c = 0;
    // SAFETY: every load is inside row k (`k * cols + c + 8 <= (k + 1) * cols`) or `x`.
    unsafe {
        while c + 8 <= cols {
            let (x0, x1) = (vld1q_f32(x.add(c)), vld1q_f32(x.add(c + 4)));
            for k in 0..N {
                let row = base.add(k * cols + c);
                a[k] = vfmaq_f32(a[k], vld1q_f32(row), x0);
                b[k] = vfmaq_f32(b[k], vld1q_f32(row.add(4)), x1);
            }
            c += 8;
        }
        if c + 4 <= cols {
            let x0 = vld1q_f32(x.add(c));
            for k in 0..N {
                a[k] = vfmaq_f32(a[k], vld1q_f32(base.add(k * cols + c)), x0);
            }
            c += 4;
        }
        if c < cols {
            let x0 = load_partial(x.add(c), cols - c);
            for k in 0..N {
                b[k] = vfmaq_f32(b[k], load_partial(base.add(k * cols + c), cols - c), x0);
            }
        }
    }
    core::array::from_fn(|k| vaddvq_f32(vaddq_f32(a[k], b[k])))
}

/// Rows `first..first + out.len()` of an `f32` layer (weights `w` in the layer's layout, input
/// `x` of `cols` values); returns the rows written (the leading ones: a row missing from `w`
/// stops the kernel).
pub(super) fn rows_f32(params: &[f32], layer: &Layer, w: &[f32], x: &[f32], first: usize, out: &mut [f32]) -> usize {
    if layer.format == WeightFormat::F32Columns {
        return column_rows(params, layer, w, x, first, out);
    }
    let cols = x.len();
    let mut r = first;
    for o in out.chunks_mut(BLOCK) {
        let n = o.len();
        let Some(block) = w.get(r * cols..(r + n) * cols) else {
            return r - first;
        };
        if n == BLOCK {
            // SAFETY: `block` holds the 4 rows; `x` holds `cols` values.
            let sums = unsafe { chains::<BLOCK>(block.as_ptr(), x.as_ptr(), cols) };
            for (k, (o, sum)) in o.iter_mut().zip(sums).enumerate() {
                *o = finish(params, layer, r + k, sum);
            }
        } else {
            for (k, o) in o.iter_mut().enumerate() {
                // SAFETY: row k of `block` holds `cols` values.
                let [sum] = unsafe { chains::<1>(block.as_ptr().add(k * cols), x.as_ptr(), cols) };
                *o = finish(params, layer, r + k, sum);
            }
        }
        r += n;
    }
    out.len()
}

/// Rows `r..r + 4 V` of a layer stored by columns (`W[r][c]` at `w[c * stride + r]`): one
/// chain of fused multiply-adds per row over the columns in order, four rows per vector, the
/// input read four columns per load (each column's value taken from its lane).
///
/// # Safety
/// `r + 4 V <= stride` and `w.len() >= stride * x.len()`.
#[inline(always)]
unsafe fn column_block<const V: usize>(w: &[f32], stride: usize, x: &[f32], r: usize) -> [float32x4_t; V] {
    let mut acc = [vdupq_n_f32(0.0); V];
    // SAFETY (every load below): c * stride + r + 4 V <= (c + 1) * stride <= w.len() for
    // every column c < x.len(), and the input loads are inside `x`.
    unsafe {
        let col = |c: usize| w.as_ptr().add(c * stride + r);
        let (groups, tail) = x.as_chunks::<4>();
        for (g, xg) in groups.iter().enumerate() {
            let xv = vld1q_f32(xg.as_ptr());
            let c = 4 * g;
            for (v, a) in acc.iter_mut().enumerate() {
                *a = vfmaq_laneq_f32::<0>(*a, vld1q_f32(col(c).add(4 * v)), xv);
                *a = vfmaq_laneq_f32::<1>(*a, vld1q_f32(col(c + 1).add(4 * v)), xv);
                *a = vfmaq_laneq_f32::<2>(*a, vld1q_f32(col(c + 2).add(4 * v)), xv);
                *a = vfmaq_laneq_f32::<3>(*a, vld1q_f32(col(c + 3).add(4 * v)), xv);
            }
        }
        for (t, &xc) in tail.iter().enumerate() {
            let c = 4 * groups.len() + t;
            for (v, a) in acc.iter_mut().enumerate() {
                *a = vfmaq_n_f32(*a, vld1q_f32(col(c).add(4 * v)), xc);
            }
        }
    }
    acc
}

/// [`rows_f32`] for a layer stored by columns: sixteen rows at a time (biases added four
/// rows per instruction), the rest four at a time (a block that would pass the columns'
/// padding starts earlier; each row's chain is the same in any block).
fn column_rows(params: &[f32], layer: &Layer, w: &[f32], x: &[f32], first: usize, out: &mut [f32]) -> usize {
    let rows = layer.rows as usize;
    let stride = column_stride(rows);
    let n = out.len();
    let start = layer.bias as usize + first;
    let (Some(bias), false, true) = (
        params.get(start..start + n),
        x.is_empty() || stride < 4,
        w.len() == stride * x.len() && first + n <= rows,
    ) else {
        return 0;
    };
    let mut i = 0;
    for (o, b) in out.chunks_exact_mut(16).zip(bias.chunks_exact(16)) {
        // SAFETY: first + i + 16 <= rows <= stride; `w` holds every column.
        let acc = unsafe { column_block::<4>(w, stride, x, first + i) };
        for (v, a) in acc.iter().enumerate() {
            // SAFETY: `o` and `b` hold sixteen floats (`finish` of an `f32` layer: b + sum).
            unsafe {
                vst1q_f32(
                    o.as_mut_ptr().add(4 * v),
                    vaddq_f32(vld1q_f32(b.as_ptr().add(4 * v)), *a),
                )
            };
        }
        i += 16;
    }
    while i < n {
        let at = (first + i).min(stride - 4);
        // SAFETY: at + 4 <= stride; `w` holds every column.
        let [acc] = unsafe { column_block::<1>(w, stride, x, at) };
        let mut sums = [0.0f32; 4];
        // SAFETY: `sums` holds 4 floats.
        unsafe { vst1q_f32(sums.as_mut_ptr(), acc) };
        let skip = first + i - at;
        let take = (4 - skip).min(n - i);
        for k in 0..take {
            out[i + k] = bias[i + k] + sums[skip + k];
        }
        i += take;
    }
    n
}

/// Eight `f16` bit patterns widened to `f32` (`FCVTL`, `FCVTL2`): exact.
#[inline(always)]
fn widen(h: uint16x8_t) -> (float32x4_t, float32x4_t) {
    let (lo, hi): (float32x4_t, float32x4_t);
    // SAFETY: register-only instructions of the base AArch64 floating point; the outputs are
    // not `lateout`, so neither shares a register with the input.
    unsafe {
        asm!(
            "fcvtl {lo:v}.4s, {h:v}.4h",
            "fcvtl2 {hi:v}.4s, {h:v}.8h",
            h = in(vreg) h,
            lo = out(vreg) lo,
            hi = out(vreg) hi,
            options(pure, nomem, nostack, preserves_flags)
        );
    }
    (lo, hi)
}

/// `lanes + w * x` for the eight canonical lanes (two vectors), product and sum rounded
/// separately.
#[target_feature(enable = "neon")]
#[inline]
fn accumulate(lanes: [float32x4_t; 2], w: uint16x8_t, x: [float32x4_t; 2]) -> [float32x4_t; 2] {
    let (w0, w1) = widen(w);
    [
        vaddq_f32(lanes[0], vmulq_f32(w0, x[0])),
        vaddq_f32(lanes[1], vmulq_f32(w1, x[1])),
    ]
}

/// The canonical sum of one row of `f16` weights `w` with `x` (`w.len() == x.len()`): lanes
/// 0..4 and 4..8 of each eight columns in two vectors, the tail zero-padded (a product of two
/// zeros adds nothing: a lane that starts at +0 is never -0), then the canonical fold.
#[target_feature(enable = "neon")]
#[inline]
fn canonical_f16(w: &[u16], x: &[f32]) -> f32 {
    let n = w.len().min(x.len());
    let mut lanes = [vdupq_n_f32(0.0); 2];
    let mut c = 0;
    while c + LANES <= n {
        // SAFETY: c + 8 <= n: eight halves of `w` and eight floats of `x` are readable.
        let (wv, xv) = unsafe {
            let x = x.as_ptr().add(c);
            (vld1q_u16(w.as_ptr().add(c)), [vld1q_f32(x), vld1q_f32(x.add(4))])
        };
        lanes = accumulate(lanes, wv, xv);
        c += LANES;
    }
    if c < n {
        let (mut wt, mut xt) = ([0u16; LANES], [0.0f32; LANES]);
        wt[..n - c].copy_from_slice(&w[c..n]);
        xt[..n - c].copy_from_slice(&x[c..n]);
        // SAFETY: the padded copies hold eight values each.
        let (wv, xv) = unsafe {
            (
                vld1q_u16(wt.as_ptr()),
                [vld1q_f32(xt.as_ptr()), vld1q_f32(xt.as_ptr().add(4))],
            )
        };
        lanes = accumulate(lanes, wv, xv);
    }
    // ((l0 + l4) + (l1 + l5)) + ((l2 + l6) + (l3 + l7)): the pairs, then pairwise twice.
    let s = vaddq_f32(lanes[0], lanes[1]);
    let p = vpaddq_f32(s, s);
    vpadds_f32(vget_low_f32(p))
}

/// The canonical `f16` sum for rows `first..first + out.len()` (weights `w`, input `x` of
/// `cols` values); returns the leading rows written.
pub(super) fn rows_f16(params: &[f32], layer: &Layer, w: &[u16], x: &[f32], first: usize, out: &mut [f32]) -> usize {
    let cols = x.len();
    for (i, o) in out.iter_mut().enumerate() {
        let r = first + i;
        let Some(row) = w.get(r * cols..(r + 1) * cols) else {
            return i;
        };
        // SAFETY: every AArch64 target has NEON (a base feature of the architecture's targets).
        *o = finish(params, layer, r, unsafe { canonical_f16(row, x) });
    }
    out.len()
}

/// Whether this CPU has the dot-product extension: detected at run time (once, then cached by
/// std) under `std`, the compiled target features without it.
#[inline(always)]
fn has_dotprod() -> bool {
    #[cfg(feature = "std")]
    let yes = std::arch::is_aarch64_feature_detected!("dotprod");
    #[cfg(not(feature = "std"))]
    let yes = cfg!(target_feature = "dotprod");
    yes
}

/// Columns the `SDOT` kernel takes at a time.
const DOT_BLOCK: usize = 16;

/// Rows the int8 kernels compute together.
const INT_BLOCK: usize = 4;

/// Puts the quantised activations in the order [`dot_i8`] and [`rows_i8`] read them: with
/// `SDOT`, each whole sixteen `i16` become sixteen bytes `b` then sixteen bytes `a` (see the
/// module docs); the rest, and everything without `SDOT`, stays as it is.
pub(super) fn arrange(q: &mut [i16]) {
    if !has_dotprod() || !super::vector_kernels() {
        return;
    }
    for block in q.chunks_exact_mut(DOT_BLOCK) {
        let mut bytes = [0u8; 2 * DOT_BLOCK];
        for (c, &v) in block.iter().enumerate() {
            bytes[c] = ((v & 0xff) - 128) as i8 as u8;
            bytes[DOT_BLOCK + c] = (v >> 8) as i8 as u8;
        }
        for (v, pair) in block.iter_mut().zip(bytes.chunks_exact(2)) {
            *v = i16::from_ne_bytes([pair[0], pair[1]]);
        }
    }
}

/// `sum w[c] * q[c]` in `i32` (`q` as [`arrange`] left it), and the columns left to the
/// caller (none; all of them while the vector kernels are off).
#[inline]
pub(super) fn dot_i8<'a, 'b>(w: &'a [i8], q: &'b [i16]) -> (i32, &'a [i8], &'b [i16]) {
    if !super::vector_kernels() {
        return (0, w, q);
    }
    let n = w.len().min(q.len());
    let [sum] = sums::<1>(&w[..n], &q[..n]);
    (sum, &[], &[])
}

/// Rows of an int8 layer: `out[k] = bias[k] + scale[k] * (sum_k * scale_x)` with `sum_k` the
/// sum of row `k` of `w` (`cols` weights per row) with `q` (as [`arrange`] left it): four rows
/// at a time, the sums turned to `f32` and scaled four rows per instruction, each operation
/// rounded as the plain code rounds it. Returns the rows written (0 while the vector kernels
/// are off).
pub(super) fn rows_i8(w: &[i8], q: &[i16], scale_x: f32, bias: &[f32], scale: &[f32], out: &mut [f32]) -> usize {
    let cols = q.len();
    let n = out.len().min(bias.len()).min(scale.len());
    if !super::vector_kernels() || cols == 0 || w.len() < n * cols {
        return 0;
    }
    let mut r = 0;
    while r + INT_BLOCK <= n {
        let sums = sums::<INT_BLOCK>(&w[r * cols..(r + INT_BLOCK) * cols], q);
        // SAFETY: every AArch64 target has NEON; the slices hold rows r..r + 4.
        unsafe {
            let acc = vcvtq_f32_s32(vld1q_s32(sums.as_ptr()));
            let scaled = vmulq_f32(vld1q_f32(scale.as_ptr().add(r)), vmulq_n_f32(acc, scale_x));
            vst1q_f32(
                out.as_mut_ptr().add(r),
                vaddq_f32(vld1q_f32(bias.as_ptr().add(r)), scaled),
            );
        }
        r += INT_BLOCK;
    }
    while r < n {
        let [sum] = sums::<1>(&w[r * cols..(r + 1) * cols], q);
        out[r] = bias[r] + scale[r] * (sum as f32 * scale_x);
        r += 1;
    }
    n
}

/// The sums of the `N` rows of `w` (`q.len()` weights each) with `q`, by the kernel this CPU
/// has.
#[inline(always)]
fn sums<const N: usize>(w: &[i8], q: &[i16]) -> [i32; N] {
    let cols = q.len();
    if w.len() < N * cols {
        return [0; N];
    }
    // SAFETY: `w` holds N rows of `cols`; NEON is a base feature of every AArch64 target, and
    // the dot-product kernel runs only where the CPU has the extension.
    unsafe {
        if cols >= DOT_BLOCK && has_dotprod() {
            sums_sdot::<N>(w.as_ptr(), q)
        } else {
            sums_smlal::<N>(w.as_ptr(), q, 0)
        }
    }
}

/// The sums of `N` rows from `w` with the plain `i16` activations `q` over columns `from..`:
/// eight at a time through `SMLAL` (weights widened to `i16`), the rest one at a time.
///
/// # Safety
/// `w..w + N * q.len()` must be readable.
#[target_feature(enable = "neon")]
#[inline]
unsafe fn sums_smlal<const N: usize>(w: *const i8, q: &[i16], from: usize) -> [i32; N] {
    let cols = q.len();
    let mut acc = [vdupq_n_s32(0); N];
    let mut c = from;
    // SAFETY: c + 8 <= cols: eight bytes of each row and eight activations are readable.
    unsafe {
        while c + 8 <= cols {
            let qv = vld1q_s16(q.as_ptr().add(c));
            for (k, a) in acc.iter_mut().enumerate() {
                let wv = vmovl_s8(vld1_s8(w.add(k * cols + c)));
                *a = vmlal_high_s16(vmlal_s16(*a, vget_low_s16(wv), vget_low_s16(qv)), wv, qv);
            }
            c += 8;
        }
    }
    let mut sums: [i32; N] = core::array::from_fn(|k| vaddvq_s32(acc[k]));
    for (k, s) in sums.iter_mut().enumerate() {
        for (i, &qc) in q.iter().enumerate().skip(c) {
            // SAFETY: column i < cols of row k.
            let wc = unsafe { *w.add(k * cols + i) };
            *s = s.wrapping_add(i32::from(wc) * i32::from(qc));
        }
    }
    sums
}

/// `acc + ` the four products of each `i32` lane's four bytes of `w` and `x` (`SDOT`).
///
/// # Safety
/// The CPU must have the dot-product extension.
#[target_feature(enable = "neon,dotprod")]
#[inline]
unsafe fn sdot(acc: int32x4_t, w: int8x16_t, x: int8x16_t) -> int32x4_t {
    let mut acc = acc;
    // SAFETY: a register-only instruction of the dot-product extension, which the caller
    // guarantees.
    unsafe {
        asm!(
            "sdot {acc:v}.4s, {w:v}.16b, {x:v}.16b",
            acc = inout(vreg) acc,
            w = in(vreg) w,
            x = in(vreg) x,
            options(pure, nomem, nostack, preserves_flags)
        );
    }
    acc
}

/// The sums of `N` rows from `w` with `q` split by [`arrange`]: the whole sixteens through
/// `SDOT` (`256 (w . a) + w . b + 128 (w . 1)`), the rest through [`sums_smlal`].
///
/// # Safety
/// The CPU must have the dot-product extension; `w..w + N * q.len()` must be readable.
#[target_feature(enable = "neon,dotprod")]
#[inline]
unsafe fn sums_sdot<const N: usize>(w: *const i8, q: &[i16]) -> [i32; N] {
    let cols = q.len();
    let blocks = cols / DOT_BLOCK;
    let zero = vdupq_n_s32(0);
    let ones = vdupq_n_s8(1);
    let (mut high, mut low, mut sum) = ([zero; N], [zero; N], [zero; N]);
    for b in 0..blocks {
        let c = DOT_BLOCK * b;
        // SAFETY: c + 16 <= cols: sixteen bytes of each row, and sixteen `i16` (32 bytes: `b`
        // then `a`) of `q`, are readable; the extension as the caller guarantees.
        unsafe {
            let split = q.as_ptr().add(c).cast::<i8>();
            let (bv, av) = (vld1q_s8(split), vld1q_s8(split.add(DOT_BLOCK)));
            for k in 0..N {
                let wv = vld1q_s8(w.add(k * cols + c));
                low[k] = sdot(low[k], wv, bv);
                high[k] = sdot(high[k], wv, av);
                sum[k] = sdot(sum[k], wv, ones);
            }
        }
    }
    let total = |k: usize| {
        vaddvq_s32(high[k])
            .wrapping_mul(256)
            .wrapping_add(vaddvq_s32(low[k]))
            .wrapping_add(vaddvq_s32(sum[k]).wrapping_mul(128))
    };
    let mut sums: [i32; N] = core::array::from_fn(total);
    if blocks * DOT_BLOCK < cols {
        // SAFETY: as the caller guarantees.
        let rest = unsafe { sums_smlal::<N>(w, q, blocks * DOT_BLOCK) };
        for (s, r) in sums.iter_mut().zip(rest) {
            *s = s.wrapping_add(r);
        }
    }
    sums
}

/// Places the 3D vertices of `run` (three floats each) in the world: `frame * v + origin`,
/// four vertices per vector (`LD3` splits the coordinates), the last group zero-padded, so
/// that every vertex gets the same arithmetic whichever group it falls in. `FUSED`: one chain
/// of fused multiply-adds per coordinate from the origin (behind an `f32` decoder, whose
/// targets agree within rounding); otherwise the scalar transform's own operations in its
/// order, `((m0 x + m1 y) + m2 z) + o` with every product and sum rounded, so the same bits
/// as every other target (behind `f16` and int8 decoders). `origin(o)` gives origin `o` of
/// each vertex's entry in `origin_of`; vertices without one are left as they are. Returns the
/// vertices placed.
pub(crate) fn place<const FUSED: bool>(
    frame: &nalgebra::Matrix3<f32>,
    run: &mut [f32],
    origin_of: &[u32],
    mut origin: impl FnMut(u32) -> nalgebra::Vector3<f32>,
) -> usize {
    let n = (run.len() / 3).min(origin_of.len());
    let m: [f32; 9] = core::array::from_fn(|i| frame[(i / 3, i % 3)]);
    let mut lanes = |of: &[u32]| -> [[f32; 4]; 3] {
        let mut o = [[0.0f32; 4]; 3];
        let shared = of.iter().all(|&x| x == of[0]);
        let first = origin(of[0]);
        for (k, &at) in of.iter().enumerate() {
            let p = if shared { first } else { origin(at) };
            for c in 0..3 {
                o[c][k] = p[c];
            }
        }
        o
    };
    let (groups, _) = run[..3 * n].as_chunks_mut::<12>();
    for (g, block) in groups.iter_mut().enumerate() {
        let o = lanes(&origin_of[4 * g..4 * g + 4]);
        // SAFETY: every AArch64 target has NEON.
        unsafe { transform::<FUSED>(&m, block, &o) };
    }
    let v = 4 * (n / 4);
    if v < n {
        let mut block = [0.0f32; 12];
        block[..3 * (n - v)].copy_from_slice(&run[3 * v..3 * n]);
        let o = lanes(&origin_of[v..n]);
        // SAFETY: every AArch64 target has NEON.
        unsafe { transform::<FUSED>(&m, &mut block, &o) };
        run[3 * v..3 * n].copy_from_slice(&block[..3 * (n - v)]);
    }
    n
}

/// Four vertices of `block` (interleaved x, y, z) to `m * v + o` (`m` row by row, `o` by
/// coordinate), fused or not (see [`place`]).
#[target_feature(enable = "neon")]
#[inline]
fn transform<const FUSED: bool>(m: &[f32; 9], block: &mut [f32; 12], o: &[[f32; 4]; 3]) {
    // SAFETY: `block` holds twelve floats and each `o[c]` four.
    let (xyz, origin) = unsafe {
        (
            vld3q_f32(block.as_ptr()),
            [
                vld1q_f32(o[0].as_ptr()),
                vld1q_f32(o[1].as_ptr()),
                vld1q_f32(o[2].as_ptr()),
            ],
        )
    };
    let row = |c: usize| {
        let (m0, m1, m2) = (m[3 * c], m[3 * c + 1], m[3 * c + 2]);
        if FUSED {
            let t = vfmaq_n_f32(origin[c], xyz.0, m0);
            let t = vfmaq_n_f32(t, xyz.1, m1);
            vfmaq_n_f32(t, xyz.2, m2)
        } else {
            let t = vmulq_n_f32(xyz.0, m0);
            let t = vaddq_f32(t, vmulq_n_f32(xyz.1, m1));
            let t = vaddq_f32(t, vmulq_n_f32(xyz.2, m2));
            vaddq_f32(t, origin[c])
        }
    };
    let world = float32x4x3_t(row(0), row(1), row(2));
    // SAFETY: `block` holds twelve floats.
    unsafe { vst3q_f32(block.as_mut_ptr(), world) };
}
