//! The world transform `p = R q + o` of encoded 3D vertices, sixteen at a time on AVX-512F.
//!
//! Sixteen vertices are 48 interleaved floats, three vectors. Output lane `i` (coordinate
//! `c = i % 3` of its vertex) is `R[c][0] x + R[c][1] y + R[c][2] z + o[c]`; the vertex's
//! `x`, `y` and `z` for every lane are gathered from two of the three vectors by one
//! permutation each, and the rows of `R` and `o` are laid out once in the same lane pattern.
//! Every lane computes `((R[c][0] x + o[c]) + R[c][1] y) + R[c][2] z` with fused
//! multiply-adds: the scalar path ([`crate::decode`]) is free to round differently, within the
//! tolerance `f32` targets agree to.

use core::arch::x86_64::*;

use nalgebra::{Matrix3, Vector3};

/// Floats in one block: sixteen vertices of three coordinates.
pub(crate) const BLOCK_FLOATS: usize = 48;

/// For output vector `b` and coordinate `k` of the source vertex: which pair of input vectors
/// the permutation reads (`first`, `first + 1`), and the index of each lane in that pair.
const fn gather(b: usize, k: usize) -> (usize, [i32; 16]) {
    let first = if b == 0 || (b == 1 && k == 0) { 0 } else { 1 };
    let mut idx = [0i32; 16];
    let mut l = 0;
    while l < 16 {
        let i = 16 * b + l;
        idx[l] = (i - i % 3 + k - 16 * first) as i32;
        l += 1;
    }
    (first, idx)
}

/// The lane pattern of the transform: for each output vector, the three permutations and the
/// coefficients of each lane's coordinate.
pub(crate) struct WorldBlocks {
    gathers: [[(usize, __m512i); 3]; 3],
    rows: [[__m512; 3]; 3],
    origin: [__m512; 3],
}

impl WorldBlocks {
    /// The pattern for the rotation `r` and the origin `o`; `None` where the CPU lacks
    /// AVX-512F (the caller transforms vertex by vertex).
    pub(crate) fn new(r: &Matrix3<f32>, o: &Vector3<f32>) -> Option<Self> {
        if crate::network::fast::width() != crate::network::Width::Avx512 {
            return None;
        }
        let lanes = |b: usize, f: &dyn Fn(usize) -> f32| -> [f32; 16] { core::array::from_fn(|l| f((16 * b + l) % 3)) };
        let load = |v: [f32; 16]| -> __m512 {
            // SAFETY: `v` holds 16 floats; AVX-512F is present (checked above).
            unsafe { _mm512_loadu_ps(v.as_ptr()) }
        };
        let index = |v: [i32; 16]| -> __m512i {
            // SAFETY: `v` holds 16 integers; AVX-512F is present.
            unsafe { _mm512_loadu_si512(v.as_ptr().cast()) }
        };
        Some(WorldBlocks {
            gathers: core::array::from_fn(|b| {
                core::array::from_fn(|k| {
                    let (first, idx) = gather(b, k);
                    (first, index(idx))
                })
            }),
            rows: core::array::from_fn(|b| core::array::from_fn(|k| load(lanes(b, &|c| r[(c, k)])))),
            origin: core::array::from_fn(|b| load(lanes(b, &|c| o[c]))),
        })
    }

    /// Transforms one block of sixteen vertices in place.
    pub(crate) fn apply(&self, block: &mut [f32; BLOCK_FLOATS]) {
        // SAFETY: a `WorldBlocks` exists only where the CPU has AVX-512F.
        unsafe { self.apply_avx512(block) }
    }

    #[target_feature(enable = "avx512f")]
    fn apply_avx512(&self, block: &mut [f32; BLOCK_FLOATS]) {
        let p = block.as_mut_ptr();
        // SAFETY: the block holds 48 floats: three loads and three stores of 16.
        let v = unsafe {
            [
                _mm512_loadu_ps(p),
                _mm512_loadu_ps(p.add(16)),
                _mm512_loadu_ps(p.add(32)),
            ]
        };
        for b in 0..3 {
            let coord = |k: usize| {
                let (first, idx) = self.gathers[b][k];
                _mm512_permutex2var_ps(v[first], idx, v[first + 1])
            };
            let mut out = _mm512_fmadd_ps(self.rows[b][0], coord(0), self.origin[b]);
            out = _mm512_fmadd_ps(self.rows[b][1], coord(1), out);
            out = _mm512_fmadd_ps(self.rows[b][2], coord(2), out);
            // SAFETY: as above.
            unsafe { _mm512_storeu_ps(p.add(16 * b), out) };
        }
    }
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;

    /// A block transformed by the vectors equals `R q + o` vertex by vertex within rounding.
    #[test]
    fn a_block_is_rotated_and_offset_vertex_by_vertex() {
        let r = Matrix3::new(0.36, 0.48, -0.8, -0.8, 0.6, 0.0, 0.48, 0.64, 0.6);
        let o = Vector3::new(1.5, -2.0, 0.25);
        let Some(blocks) = WorldBlocks::new(&r, &o) else {
            std::println!("no AVX-512F: the vector transform is not run on this CPU");
            return;
        };
        let mut block: [f32; BLOCK_FLOATS] = core::array::from_fn(|i| (i as f32 * 0.37).sin() * 3.0);
        let before = block;
        blocks.apply(&mut block);
        for (q, p) in before.chunks_exact(3).zip(block.chunks_exact(3)) {
            let want = r * Vector3::new(q[0], q[1], q[2]) + o;
            for c in 0..3 {
                assert!(
                    (p[c] - want[c]).abs() <= 1e-6 * (1.0 + want[c].abs()),
                    "{p:?} vs {want:?}"
                );
            }
        }
    }
}
