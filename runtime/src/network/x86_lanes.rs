//! The vector widths of the x86-64 wide `f32` kernels ([`Lanes`]): AVX-512F and AVX2 with
//! FMA, so that each driver of `super::x86` and `super::columns` is one generic body.

use core::arch::x86_64::*;

/// A driver of `f32` rows, `$generic::<$lanes>` (see [`Lanes`]), compiled for `$features`:
/// `fn(params, layer, w, x, first, out) -> rows written`, unsafe because the CPU must have
/// the features (the slices are checked by the driver).
macro_rules! wide_driver {
    ($(#[$doc:meta])* $vis:vis $name:ident = $generic:ident::<$lanes:ty>, $features:literal) => {
        $(#[$doc])*
        ///
        /// # Safety
        /// The CPU must have the features the function is compiled for.
        #[target_feature(enable = $features)]
        $vis unsafe fn $name(params: &[f32], layer: &Layer, w: &[f32], x: &[f32], first: usize, out: &mut [f32]) -> usize {
            // SAFETY: compiled for the features the generic body's width needs.
            unsafe { $generic::<$lanes>(params, layer, w, x, first, out) }
        }
    };
}
pub(super) use wide_driver;

/// One vector width of the wide `f32` kernels, so that the AVX-512F and the AVX2 drivers
/// (`super::x86` and `super::columns`) are one generic body each.
///
/// `#[target_feature]` does not go with `#[inline(always)]`, and a function without the
/// features cannot inline the intrinsics it calls. So the methods, and the generic drivers
/// written with them, are `#[inline(always)]` without features, and each driver is
/// instantiated only inside a `#[target_feature]` wrapper of its width (`x86::rows_f32_avx512`,
/// `x86::rows_f32_avx2`, `columns::rows512`, ...): inlined there, the whole body is compiled for
/// the wrapper's features. No closures in the generic bodies: a closure is a function of its
/// own, compiled without the features.
///
/// # Safety
/// Every method may run only where the CPU has the width's features; the pointer methods
/// read or write the lanes they name.
pub(super) trait Lanes {
    /// Floats per vector.
    const N: usize;
    /// A vector of `N` floats.
    type V: Copy;
    /// Which lanes a masked load or store touches.
    type Mask: Copy;
    unsafe fn zero() -> Self::V;
    unsafe fn splat(x: f32) -> Self::V;
    unsafe fn load(p: *const f32) -> Self::V;
    unsafe fn store(p: *mut f32, v: Self::V);
    unsafe fn add(a: Self::V, b: Self::V) -> Self::V;
    /// `a * b + c`, rounded once.
    unsafe fn fmadd(a: Self::V, b: Self::V, c: Self::V) -> Self::V;
    /// The first `n` lanes (`n <= N`).
    unsafe fn mask(n: usize) -> Self::Mask;
    /// The lanes of `m` from `p`, zeros elsewhere (the others are not read).
    unsafe fn load_masked(m: Self::Mask, p: *const f32) -> Self::V;
    /// The lanes of `m` stored at `p` (the others are not written).
    unsafe fn store_masked(m: Self::Mask, p: *mut f32, v: Self::V);
    /// The vector's lanes summed into eight, by a tree that reads no other vector.
    unsafe fn eight(v: Self::V) -> __m256;
}

/// Sixteen lanes, AVX-512F.
pub(super) struct Avx512;

/// Eight lanes, AVX2 with FMA.
pub(super) struct Avx2;

#[allow(clippy::missing_safety_doc)]
impl Lanes for Avx512 {
    const N: usize = 16;
    type V = __m512;
    type Mask = __mmask16;
    #[inline(always)]
    unsafe fn zero() -> __m512 {
        _mm512_setzero_ps()
    }
    #[inline(always)]
    unsafe fn splat(x: f32) -> __m512 {
        _mm512_set1_ps(x)
    }
    #[inline(always)]
    unsafe fn load(p: *const f32) -> __m512 {
        // SAFETY: the trait's contract.
        unsafe { _mm512_loadu_ps(p) }
    }
    #[inline(always)]
    unsafe fn store(p: *mut f32, v: __m512) {
        // SAFETY: the trait's contract.
        unsafe { _mm512_storeu_ps(p, v) }
    }
    #[inline(always)]
    unsafe fn add(a: __m512, b: __m512) -> __m512 {
        _mm512_add_ps(a, b)
    }
    #[inline(always)]
    unsafe fn fmadd(a: __m512, b: __m512, c: __m512) -> __m512 {
        _mm512_fmadd_ps(a, b, c)
    }
    #[inline(always)]
    unsafe fn mask(n: usize) -> __mmask16 {
        ((1u32 << n) - 1) as u16
    }
    #[inline(always)]
    unsafe fn load_masked(m: __mmask16, p: *const f32) -> __m512 {
        // SAFETY: the trait's contract.
        unsafe { _mm512_maskz_loadu_ps(m, p) }
    }
    #[inline(always)]
    unsafe fn store_masked(m: __mmask16, p: *mut f32, v: __m512) {
        // SAFETY: the trait's contract.
        unsafe { _mm512_mask_storeu_ps(p, m, v) }
    }
    #[inline(always)]
    unsafe fn eight(v: __m512) -> __m256 {
        _mm256_add_ps(
            _mm512_castps512_ps256(v),
            _mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(_mm512_castps_pd(v))),
        )
    }
}

#[allow(clippy::missing_safety_doc)]
impl Lanes for Avx2 {
    const N: usize = 8;
    type V = __m256;
    type Mask = __m256i;
    #[inline(always)]
    unsafe fn zero() -> __m256 {
        _mm256_setzero_ps()
    }
    #[inline(always)]
    unsafe fn splat(x: f32) -> __m256 {
        _mm256_set1_ps(x)
    }
    #[inline(always)]
    unsafe fn load(p: *const f32) -> __m256 {
        // SAFETY: the trait's contract.
        unsafe { _mm256_loadu_ps(p) }
    }
    #[inline(always)]
    unsafe fn store(p: *mut f32, v: __m256) {
        // SAFETY: the trait's contract.
        unsafe { _mm256_storeu_ps(p, v) }
    }
    #[inline(always)]
    unsafe fn add(a: __m256, b: __m256) -> __m256 {
        _mm256_add_ps(a, b)
    }
    #[inline(always)]
    unsafe fn fmadd(a: __m256, b: __m256, c: __m256) -> __m256 {
        _mm256_fmadd_ps(a, b, c)
    }
    #[inline(always)]
    unsafe fn mask(n: usize) -> __m256i {
        _mm256_cmpgt_epi32(_mm256_set1_epi32(n as i32), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7))
    }
    #[inline(always)]
    unsafe fn load_masked(m: __m256i, p: *const f32) -> __m256 {
        // SAFETY: the trait's contract; `maskload` reads only the lanes its mask enables.
        unsafe { _mm256_maskload_ps(p, m) }
    }
    #[inline(always)]
    unsafe fn store_masked(m: __m256i, p: *mut f32, v: __m256) {
        // SAFETY: the trait's contract.
        unsafe { _mm256_maskstore_ps(p, m, v) }
    }
    #[inline(always)]
    unsafe fn eight(v: __m256) -> __m256 {
        v
    }
}
