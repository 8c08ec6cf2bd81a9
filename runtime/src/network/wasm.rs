//! wasm with `simd128`: the int8 dot product ([`super::integer`]).

use core::arch::wasm32::*;

/// Eight weights at a time: widened to `i16`, `i32x4.dot_i16x8_s` with the activations; the
/// sum over the leading whole eights, and the columns after them (which the caller adds).
#[inline]
pub fn dot_i8<'a, 'b>(w: &'a [i8], q: &'b [i16]) -> (i32, &'a [i8], &'b [i16]) {
    let n = w.len().min(q.len());
    let mut acc = i32x4_splat(0);
    let mut c = 0;
    while c + 8 <= n {
        // SAFETY: c + 8 <= n, so 8 bytes of `w` and 8 halves of `q` are readable; wasm loads
        // need no alignment.
        unsafe {
            let wv = i16x8_load_extend_i8x8(w.as_ptr().add(c).cast());
            let qv = v128_load(q.as_ptr().add(c).cast());
            acc = i32x4_add(acc, i32x4_dot_i16x8(wv, qv));
        }
        c += 8;
    }
    let lanes = i32x4_extract_lane::<0>(acc)
        .wrapping_add(i32x4_extract_lane::<1>(acc))
        .wrapping_add(i32x4_extract_lane::<2>(acc))
        .wrapping_add(i32x4_extract_lane::<3>(acc));
    (lanes, &w[c..n], &q[c..n])
}
