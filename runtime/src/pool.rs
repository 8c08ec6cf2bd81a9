//! The fixed-capacity lists the artifact loader fills ([`crate::artifact::Storage::load`]):
//! `heapless::Vec` on targets, `Vec` and the cache-line-aligned weight pool with the `std`
//! feature. A full pool is an error for the loader, never a panic.

/// A growable-up-to-capacity list the loader fills: `heapless::Vec` on targets, `Vec` with
/// the `std` feature.
pub trait Pool<T> {
    /// Removes every element.
    fn clear(&mut self);
    /// Appends `v`; `false` when full.
    fn push(&mut self, v: T) -> bool;
    /// The elements.
    fn as_slice(&self) -> &[T];
    /// The elements, to change in place.
    fn as_mut_slice(&mut self) -> &mut [T];
}

impl<T, const N: usize> Pool<T> for heapless::Vec<T, N> {
    fn clear(&mut self) {
        heapless::Vec::clear(self)
    }
    fn push(&mut self, v: T) -> bool {
        heapless::Vec::push(self, v).is_ok()
    }
    fn as_slice(&self) -> &[T] {
        self
    }
    fn as_mut_slice(&mut self) -> &mut [T] {
        self
    }
}

#[cfg(feature = "std")]
impl<T> Pool<T> for std::vec::Vec<T> {
    fn clear(&mut self) {
        std::vec::Vec::clear(self)
    }
    fn push(&mut self, v: T) -> bool {
        std::vec::Vec::push(self, v);
        true
    }
    fn as_slice(&self) -> &[T] {
        self
    }
    fn as_mut_slice(&mut self) -> &mut [T] {
        self
    }
}

/// The desktop weight pool, on cache lines (see [`crate::aligned`]).
#[cfg(feature = "std")]
impl Pool<f32> for crate::aligned::AlignedFloats {
    fn clear(&mut self) {
        crate::aligned::AlignedFloats::clear(self);
    }
    fn push(&mut self, v: f32) -> bool {
        crate::aligned::AlignedFloats::push(self, v);
        true
    }
    fn as_slice(&self) -> &[f32] {
        crate::aligned::AlignedFloats::as_slice(self)
    }
    fn as_mut_slice(&mut self) -> &mut [f32] {
        crate::aligned::AlignedFloats::as_mut_slice(self)
    }
}
