//! Weights on cache-line boundaries. The wide `f32` kernels load sixteen floats (64 bytes, one
//! cache line) at a time; a load that straddles two lines costs two, and the 128-wide
//! integrator of a model ran 1.7 times slower from a pool 16 bytes off a line. So the loader
//! starts every layer's weights at a multiple of [`LINE`] floats of its pool, the desktop pool
//! ([`AlignedFloats`], feature `std`) starts on a line, and generated code puts its pool in an
//! [`Aligned`] static.

/// Floats per cache line (and per AVX-512 vector).
pub const LINE: usize = 16;

/// A value on a 64-byte boundary: generated code holds its `f32` pool in one.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(64))]
pub struct Aligned<T>(pub T);

#[cfg(feature = "std")]
pub use pool::AlignedFloats;

#[cfg(feature = "std")]
mod pool {
    extern crate std;
    use std::vec::Vec;

    use super::LINE;

    /// One cache line of floats.
    #[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
    #[repr(C, align(64))]
    struct Line([f32; LINE]);

    /// A growable `f32` pool whose first value sits on a 64-byte boundary (`Vec<f32>` only
    /// promises 4 bytes): the lines are allocated with the line's alignment and read as one
    /// slice of floats.
    #[derive(Clone, Debug, Default, PartialEq)]
    pub struct AlignedFloats {
        lines: Vec<Line>,
        len: usize,
    }

    impl AlignedFloats {
        /// Removes every value.
        pub fn clear(&mut self) {
            self.lines.clear();
            self.len = 0;
        }

        /// Appends `v`.
        pub fn push(&mut self, v: f32) {
            if self.len == self.lines.len() * LINE {
                self.lines.push(Line::default());
            }
            if let Some(line) = self.lines.get_mut(self.len / LINE) {
                line.0[self.len % LINE] = v;
            }
            self.len += 1;
        }

        /// The values.
        pub fn as_slice(&self) -> &[f32] {
            bytemuck::cast_slice::<Line, f32>(&self.lines)
                .get(..self.len)
                .unwrap_or(&[])
        }

        /// The values, to change in place.
        pub fn as_mut_slice(&mut self) -> &mut [f32] {
            let len = self.len;
            bytemuck::cast_slice_mut::<Line, f32>(&mut self.lines)
                .get_mut(..len)
                .unwrap_or(&mut [])
        }
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        #[test]
        fn the_pool_starts_on_a_line_and_holds_what_was_pushed() {
            let mut pool = AlignedFloats::default();
            assert!(pool.as_slice().is_empty());
            for i in 0..40 {
                pool.push(i as f32);
            }
            assert_eq!(pool.as_slice().as_ptr() as usize % 64, 0);
            assert_eq!(pool.as_slice(), (0..40).map(|i| i as f32).collect::<Vec<_>>());
            pool.as_mut_slice()[39] = -1.0;
            assert_eq!(pool.as_slice()[39], -1.0);
            pool.clear();
            assert!(pool.as_slice().is_empty());
        }
    }
}
