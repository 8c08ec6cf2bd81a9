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
//!   bits do not change.

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
