//! Armv7E-M (Cortex-M4, M7; the `armv7em` feature): the instructions the kernels use there.
//!
//! - int8 ([`super::integer`]): `SXTB16` unpacks bytes 0 and 2 of a weight word into two
//!   16-bit halves (rotated by 8: bytes 1 and 3), and `SMLAD` multiplies both halves with a
//!   pair of activations and adds the two products to the sum: four weights in two of each.
//!   The products are summed exactly in `i32` ([`super::integer`]'s bound), so the order is
//!   free and the bits are the other targets'.
//! - `f16` ([`super::canonical`], with the FPU of `eabihf` targets): `VCVTB` converts the low
//!   half of a register to `f32` in one instruction, where the software conversion takes a
//!   dozen and branches. The conversion is exact (every `f16` is an
//!   `f32`; subnormals included, as the flush-to-zero bit is clear), so the canonical sum's
//!   bits do not change. Rows of a layer whose columns are whole eights go two at a time
//!   through [`rows_f16`]: `VLDM` loads two weights per word straight into the FPU,
//!   `VCVTB`/`VCVTT` convert the low and the high half, then the canonical sum's `VMUL` and
//!   `VADD` per weight (`LDRH`, `VMOV` and `VCVTB` one weight at a time took two instructions
//!   more per weight).

use core::arch::asm;

/// Stores each group of four activations as (0, 2, 1, 3), the order [`dot_i8`] reads them:
/// `SXTB16` unpacks bytes 0 and 2 of a weight word into one register and bytes 1 and 3 into
/// another.
#[inline(always)]
pub fn arrange(q: &mut [i16]) {
    for g in q.chunks_exact_mut(4) {
        g.swap(1, 2);
    }
}

/// `sum w[c] * q[c]` in `i32` over the leading whole fours of columns (`q` as [`arrange`]
/// left it), and the columns after them, which the caller adds.
#[inline]
pub fn dot_i8<'a, 'b>(w: &'a [i8], q: &'b [i16]) -> (i32, &'a [i8], &'b [i16]) {
    let n = w.len().min(q.len());
    let groups = n / 4;
    // Two sums so that consecutive `SMLAD`s do not wait on each other.
    let (mut a, mut b) = (0i32, 0i32);
    for g in 0..groups {
        // SAFETY: 4 g + 4 <= n, so the four bytes of `w` and the four halves of `q` at 4 g are
        // inside both slices; Armv7E-M loads words at any address (`read_unaligned`).
        let (w4, q02, q13) = unsafe {
            (
                w.as_ptr().add(4 * g).cast::<u32>().read_unaligned(),
                q.as_ptr().add(4 * g).cast::<u32>().read_unaligned(),
                q.as_ptr().add(4 * g + 2).cast::<u32>().read_unaligned(),
            )
        };
        a = smlad(sxtb16(w4), q02, a);
        b = smlad(sxtb16_ror8(w4), q13, b);
    }
    (a.wrapping_add(b), &w[4 * groups..n], &q[4 * groups..n])
}

/// Bytes 0 and 2 of `x`, sign-extended to the two halves.
#[inline(always)]
fn sxtb16(x: u32) -> u32 {
    let y: u32;
    // SAFETY: a register-only instruction of Armv7E-M (the `armv7em` feature).
    unsafe { asm!("sxtb16 {0}, {1}", lateout(reg) y, in(reg) x, options(pure, nomem, nostack, preserves_flags)) };
    y
}

/// Bytes 1 and 3 of `x`, sign-extended to the two halves.
#[inline(always)]
fn sxtb16_ror8(x: u32) -> u32 {
    let y: u32;
    // SAFETY: as in `sxtb16`.
    unsafe {
        asm!("sxtb16 {0}, {1}, ror #8", lateout(reg) y, in(reg) x, options(pure, nomem, nostack, preserves_flags))
    };
    y
}

/// `acc + lo(x) * lo(y) + hi(x) * hi(y)`, the halves signed. `SMLAD` sets the Q flag on a
/// signed overflow and otherwise wraps, which the sums here never reach.
#[inline(always)]
fn smlad(x: u32, y: u32, acc: i32) -> i32 {
    let r: i32;
    // SAFETY: a register-only instruction of Armv7E-M; it may set the sticky Q flag (APSR),
    // which nothing reads.
    unsafe {
        asm!("smlad {0}, {1}, {2}, {3}", lateout(reg) r, in(reg) x, in(reg) y, in(reg) acc, options(pure, nomem, nostack))
    };
    r
}

/// The `f16` with bits `h` as `f32`: one `VCVTB.F32.F16` (the language's `f16`, which the
/// crate enables on these targets only).
#[cfg(target_abi = "eabihf")]
#[inline(always)]
pub fn f16_to_f32(h: u16) -> f32 {
    f16::from_bits(h) as f32
}

/// The canonical `f16` sum ([`super::canonical`]) of rows `first..first + out.len()` of a
/// layer whose weights are `w`, for the input given as consecutive `parts` (gathered on the
/// stack first), two rows at a time; returns the leading rows written (an even number: the
/// caller computes the rest). 0 unless the columns are a whole number of eights. Not inlined:
/// the stack buffer and the loop stay out of the callers' `f32` paths.
#[cfg(target_abi = "eabihf")]
#[inline(never)]
pub fn rows_f16(
    params: &[f32],
    layer: &crate::model::Layer,
    w: &[u16],
    parts: &[&[f32]],
    first: usize,
    out: &mut [f32],
) -> usize {
    super::joined(parts, |x| rows_f16_joined(params, layer, w, x, first, out))
}

/// [`rows_f16`] for the input `x`.
#[cfg(target_abi = "eabihf")]
#[inline(always)]
fn rows_f16_joined(
    params: &[f32],
    layer: &crate::model::Layer,
    w: &[u16],
    x: &[f32],
    first: usize,
    out: &mut [f32],
) -> usize {
    use super::canonical::{fold, LANES};
    let cols = x.len();
    if cols == 0 || !cols.is_multiple_of(LANES) || cols != layer.cols as usize {
        return 0;
    }
    let mut done = 0;
    for (pair, o) in out.chunks_exact_mut(2).enumerate() {
        let r = first + 2 * pair;
        let Some(rows) = w.get(r * cols..(r + 2) * cols) else {
            break;
        };
        let mut lanes = [0.0f32; 2 * LANES];
        // SAFETY: `rows` holds two rows of `cols` halves and `x` `cols` floats, `cols` a
        // positive multiple of 8; `lanes` holds 16 floats.
        unsafe {
            lanes_f16x2(
                rows.as_ptr(),
                rows.as_ptr().add(cols),
                x.as_ptr(),
                cols / LANES,
                &mut lanes,
            )
        };
        let (l0, l1) = lanes.split_at(LANES);
        for (k, (o, l)) in o.iter_mut().zip([l0, l1]).enumerate() {
            let l: &[f32; LANES] = l.try_into().unwrap_or(&[0.0; LANES]);
            *o = super::finish(params, layer, r + k, fold(l));
        }
        done += 2;
    }
    done
}

/// The eight canonical lanes of two rows of `f16` weights (`w0`, `w1`) with `x`, over `groups`
/// groups of eight columns, written to `lanes` (row 0's, then row 1's): lane `l` adds
/// `w[c] * x[c]` for `c = l, l + 8, ...` in order, the product and the sum each rounded
/// (`VMUL`, `VADD`), from +0.
///
/// The FPU registers cannot be operands here (Rust's single-precision register class on Arm
/// needs the `vfp2` feature, which implies the double precision the M4 lacks), so the block
/// names them itself and saves and restores all 32 around the loop: `x` in s0-s7, the loaded
/// weight words in s8-s11, the converted products in s12-s15, the sixteen lanes in s16-s31.
///
/// # Safety
/// `w0` and `w1` must hold `8 groups` halves, `x` `8 groups` floats; `groups > 0`.
#[cfg(target_abi = "eabihf")]
#[inline(never)]
unsafe fn lanes_f16x2(w0: *const u16, w1: *const u16, x: *const f32, groups: usize, lanes: &mut [f32; 16]) {
    // SAFETY: the caller's promise; the block reads `8 groups` halves from each row and
    // floats from `x`, and reads and writes the 16 floats of `lanes`; every FPU register it
    // writes is restored from the stack before it ends.
    unsafe {
        asm!(
            "vpush {{s0-s15}}",
            "vpush {{s16-s31}}",
            "vldmia {lanes}, {{s16-s31}}",
            "2:",
            "vldmia {x}!, {{s0-s7}}",
            // Columns 0-3 of the group: row 0 into lanes 0-3 (s16-s19), row 1 (s24-s27).
            "vldmia {w0}!, {{s8-s9}}",
            "vldmia {w1}!, {{s10-s11}}",
            "vcvtb.f32.f16 s12, s8",
            "vcvtt.f32.f16 s13, s8",
            "vcvtb.f32.f16 s14, s9",
            "vcvtt.f32.f16 s15, s9",
            "vmul.f32 s12, s12, s0",
            "vmul.f32 s13, s13, s1",
            "vmul.f32 s14, s14, s2",
            "vmul.f32 s15, s15, s3",
            "vadd.f32 s16, s16, s12",
            "vadd.f32 s17, s17, s13",
            "vadd.f32 s18, s18, s14",
            "vadd.f32 s19, s19, s15",
            "vcvtb.f32.f16 s12, s10",
            "vcvtt.f32.f16 s13, s10",
            "vcvtb.f32.f16 s14, s11",
            "vcvtt.f32.f16 s15, s11",
            "vmul.f32 s12, s12, s0",
            "vmul.f32 s13, s13, s1",
            "vmul.f32 s14, s14, s2",
            "vmul.f32 s15, s15, s3",
            "vadd.f32 s24, s24, s12",
            "vadd.f32 s25, s25, s13",
            "vadd.f32 s26, s26, s14",
            "vadd.f32 s27, s27, s15",
            // Columns 4-7: row 0 into lanes 4-7 (s20-s23), row 1 (s28-s31).
            "vldmia {w0}!, {{s8-s9}}",
            "vldmia {w1}!, {{s10-s11}}",
            "vcvtb.f32.f16 s12, s8",
            "vcvtt.f32.f16 s13, s8",
            "vcvtb.f32.f16 s14, s9",
            "vcvtt.f32.f16 s15, s9",
            "vmul.f32 s12, s12, s4",
            "vmul.f32 s13, s13, s5",
            "vmul.f32 s14, s14, s6",
            "vmul.f32 s15, s15, s7",
            "vadd.f32 s20, s20, s12",
            "vadd.f32 s21, s21, s13",
            "vadd.f32 s22, s22, s14",
            "vadd.f32 s23, s23, s15",
            "vcvtb.f32.f16 s12, s10",
            "vcvtt.f32.f16 s13, s10",
            "vcvtb.f32.f16 s14, s11",
            "vcvtt.f32.f16 s15, s11",
            "vmul.f32 s12, s12, s4",
            "vmul.f32 s13, s13, s5",
            "vmul.f32 s14, s14, s6",
            "vmul.f32 s15, s15, s7",
            "vadd.f32 s28, s28, s12",
            "vadd.f32 s29, s29, s13",
            "vadd.f32 s30, s30, s14",
            "vadd.f32 s31, s31, s15",
            "subs {n}, {n}, #1",
            "bne 2b",
            "vstmia {lanes}, {{s16-s31}}",
            "vpop {{s16-s31}}",
            "vpop {{s0-s15}}",
            w0 = inout(reg) w0 => _,
            w1 = inout(reg) w1 => _,
            x = inout(reg) x => _,
            n = inout(reg) groups => _,
            lanes = in(reg) lanes.as_mut_ptr(),
        );
    }
}
