//! [`Dense64`]'s products compiled a second time for AVX2, chosen at run time: the trainer is
//! built for any x86-64 CPU (two `f64` per vector), and a decoder's output layer (thousands of
//! rows) is read two or three times in every evaluation of a reduced solve.
//!
//! Each product's portable body (`#[inline(always)]`) is inlined into a function compiled with
//! AVX2 enabled, where it vectorises four `f64` wide. The order of operations is the body's:
//! no fused multiply-add (Rust contracts none on its own) and no reassociation, so both
//! builds give the same bits (tested). The `multiversion` crate does this with a macro over
//! whole functions; three small wrappers do it here.

use super::Dense64;

/// [`Dense64::matvec`], with AVX2 where the CPU has it.
#[inline]
pub(super) fn matvec(layer: &Dense64, x: &[f64], sink: impl FnMut(usize, f64)) {
    #[cfg(target_arch = "x86_64")]
    if has_avx2() {
        // SAFETY: the CPU has AVX2.
        return unsafe { avx2::matvec(layer, x, sink) };
    }
    layer.matvec_portable(x, sink)
}

/// [`Dense64::with_tangents`], with AVX2 where the CPU has it.
#[inline]
pub(super) fn with_tangents(layer: &Dense64, a: &[f64], t: &[f64], value: &mut [f64], out: &mut [f64], add: bool) {
    #[cfg(target_arch = "x86_64")]
    if has_avx2() {
        // SAFETY: the CPU has AVX2.
        return unsafe { avx2::with_tangents(layer, a, t, value, out, add) };
    }
    layer.with_tangents_portable(a, t, value, out, add)
}

/// [`Dense64::add_transposed`], with AVX2 where the CPU has it.
#[inline]
pub(super) fn add_transposed(layer: &Dense64, v: &[f64], out: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if has_avx2() {
        // SAFETY: the CPU has AVX2.
        return unsafe { avx2::add_transposed(layer, v, out) };
    }
    layer.add_transposed_portable(v, out)
}

/// Whether the CPU has AVX2 (detected once, then a cached load).
#[cfg(target_arch = "x86_64")]
#[inline]
pub(super) fn has_avx2() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
}

/// The portable bodies compiled with AVX2 (callers must have checked [`has_avx2`]).
#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::Dense64;

    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn matvec(layer: &Dense64, x: &[f64], sink: impl FnMut(usize, f64)) {
        layer.matvec_portable(x, sink)
    }

    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn with_tangents(
        layer: &Dense64,
        a: &[f64],
        t: &[f64],
        value: &mut [f64],
        out: &mut [f64],
        add: bool,
    ) {
        layer.with_tangents_portable(a, t, value, out, add)
    }

    #[target_feature(enable = "avx2")]
    pub(super) unsafe fn add_transposed(layer: &Dense64, v: &[f64], out: &mut [f64]) {
        layer.add_transposed_portable(v, out)
    }
}
