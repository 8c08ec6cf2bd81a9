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

use crate::model::{column_stride, Layer};
use crate::network;

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

/// [`gather`]'s lane indices for every output vector and coordinate, computed at compile time.
const GATHERS: [[[i32; 16]; 3]; 3] = {
    let mut all = [[[0i32; 16]; 3]; 3];
    let mut b = 0;
    while b < 3 {
        let mut k = 0;
        while k < 3 {
            all[b][k] = gather(b, k).1;
            k += 1;
        }
        b += 1;
    }
    all
};

/// The lane pattern of the transform: for each output vector, the three permutations and the
/// coefficients of each lane's coordinate.
pub(crate) struct WorldBlocks {
    gathers: [[__m512i; 3]; 3],
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
        // Lane `l` of output vector `b` holds coordinate `(16 b + l) % 3` of its vertex.
        let (mut rows, mut origin) = ([[[0.0f32; 16]; 3]; 3], [[0.0f32; 16]; 3]);
        for b in 0..3 {
            for l in 0..16 {
                let c = (16 * b + l) % 3;
                for k in 0..3 {
                    rows[b][k][l] = r[(c, k)];
                }
                origin[b][l] = o[c];
            }
        }
        // SAFETY: every array holds 16 values; AVX-512F is present (checked above).
        let (load, index) = unsafe {
            (
                |v: &[f32; 16]| _mm512_loadu_ps(v.as_ptr()),
                |v: &[i32; 16]| _mm512_loadu_si512(v.as_ptr().cast()),
            )
        };
        Some(WorldBlocks {
            gathers: GATHERS.map(|b| [index(&b[0]), index(&b[1]), index(&b[2])]),
            rows: rows.map(|b| [load(&b[0]), load(&b[1]), load(&b[2])]),
            origin: [load(&origin[0]), load(&origin[1]), load(&origin[2])],
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
        let [out0, out1, out2] = self.transform(v[0], v[1], v[2]);
        // SAFETY: as above.
        unsafe {
            _mm512_storeu_ps(p, out0);
            _mm512_storeu_ps(p.add(16), out1);
            _mm512_storeu_ps(p.add(32), out2);
        }
    }

    /// The transform of one block held in three vectors.
    #[target_feature(enable = "avx512f")]
    #[inline]
    fn transform(&self, v0: __m512, v1: __m512, v2: __m512) -> [__m512; 3] {
        // Written out (no closures, no indexing by a variable): the block stays in registers
        // only when this is inlined into its callers. Which pair of vectors each
        // permutation reads is fixed by [`gather`] (checked by a test).
        let (g, r) = (&self.gathers, &self.rows);
        let lane = |b: usize, k: usize| g[b][k];
        let mut out0 = _mm512_fmadd_ps(r[0][0], _mm512_permutex2var_ps(v0, lane(0, 0), v1), self.origin[0]);
        out0 = _mm512_fmadd_ps(r[0][1], _mm512_permutex2var_ps(v0, lane(0, 1), v1), out0);
        out0 = _mm512_fmadd_ps(r[0][2], _mm512_permutex2var_ps(v0, lane(0, 2), v1), out0);
        let mut out1 = _mm512_fmadd_ps(r[1][0], _mm512_permutex2var_ps(v0, lane(1, 0), v1), self.origin[1]);
        out1 = _mm512_fmadd_ps(r[1][1], _mm512_permutex2var_ps(v1, lane(1, 1), v2), out1);
        out1 = _mm512_fmadd_ps(r[1][2], _mm512_permutex2var_ps(v1, lane(1, 2), v2), out1);
        let mut out2 = _mm512_fmadd_ps(r[2][0], _mm512_permutex2var_ps(v1, lane(2, 0), v2), self.origin[2]);
        out2 = _mm512_fmadd_ps(r[2][1], _mm512_permutex2var_ps(v1, lane(2, 1), v2), out2);
        out2 = _mm512_fmadd_ps(r[2][2], _mm512_permutex2var_ps(v1, lane(2, 2), v2), out2);
        [out0, out1, out2]
    }

    /// Rows `first..` of a decoder's column-stored `f32` output layer on the input `x`, as
    /// many whole blocks as `out` holds, each transformed while still in registers: the bits
    /// of the column kernel followed by [`WorldBlocks::apply`], without storing and loading
    /// the block in between. Returns the rows written (0 where the layer is not stored by
    /// columns or lacks the rows: the caller computes them).
    pub(crate) fn placed_rows(&self, params: &[f32], layer: &Layer, x: &[f32], first: usize, out: &mut [f32]) -> usize {
        let n = out.len() / BLOCK_FLOATS * BLOCK_FLOATS;
        let Some((w, bias)) = network::column_layer(params, layer, x.len(), first, n).filter(|_| n > 0) else {
            return 0;
        };
        let stride = column_stride(layer.rows as usize);
        // SAFETY: a `WorldBlocks` exists only where the CPU has AVX-512F; `column_layer`
        // checked that rows `first..first + n` exist in every column of `w` and in `bias`.
        unsafe { self.placed_avx512(w, stride, bias, x, first, &mut out[..n]) };
        n
    }

    /// # Safety
    /// Rows `first..first + out.len()` must exist in `bias` and in each of the `x.len()`
    /// columns of `w` (`stride` floats apart).
    #[target_feature(enable = "avx512f")]
    unsafe fn placed_avx512(&self, w: &[f32], stride: usize, bias: &[f32], x: &[f32], first: usize, out: &mut [f32]) {
        for (g, block) in out.chunks_exact_mut(BLOCK_FLOATS).enumerate() {
            let r = first + BLOCK_FLOATS * g;
            // Three chains, one per vector of the block, as the column kernel computes each.
            let (mut s0, mut s1, mut s2) = (_mm512_setzero_ps(), _mm512_setzero_ps(), _mm512_setzero_ps());
            for (c, &xc) in x.iter().enumerate() {
                let xv = _mm512_set1_ps(xc);
                // SAFETY: column `c` holds rows `r..r + 48` (the caller's promise).
                unsafe {
                    let column = w.as_ptr().add(c * stride + r);
                    s0 = _mm512_fmadd_ps(_mm512_loadu_ps(column), xv, s0);
                    s1 = _mm512_fmadd_ps(_mm512_loadu_ps(column.add(16)), xv, s1);
                    s2 = _mm512_fmadd_ps(_mm512_loadu_ps(column.add(32)), xv, s2);
                }
            }
            // SAFETY: `bias` holds rows `r..r + 48` (the caller's promise); the block holds 48
            // floats.
            unsafe {
                let b = bias.as_ptr().add(r);
                let [out0, out1, out2] = self.transform(
                    _mm512_add_ps(_mm512_loadu_ps(b), s0),
                    _mm512_add_ps(_mm512_loadu_ps(b.add(16)), s1),
                    _mm512_add_ps(_mm512_loadu_ps(b.add(32)), s2),
                );
                let p = block.as_mut_ptr();
                _mm512_storeu_ps(p, out0);
                _mm512_storeu_ps(p.add(16), out1);
                _mm512_storeu_ps(p.add(32), out2);
            }
        }
    }
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;

    /// Rows decoded and placed in one pass have the bits of the column kernel's rows placed
    /// block by block afterwards, from any first vertex; a layer stored by rows, or rows past
    /// the layer, are left to the caller.
    #[test]
    fn placed_rows_are_the_rows_then_the_transform() {
        use crate::model::{WeightFormat, Weights};
        use crate::network::test_support::{noise, Case};
        let r = Matrix3::new(0.36, 0.48, -0.8, -0.8, 0.6, 0.0, 0.48, 0.64, 0.6);
        let Some(blocks) = WorldBlocks::new(&r, &Vector3::new(1.5, -2.0, 0.25)) else {
            std::println!("no AVX-512F: the vector transform is not run on this CPU");
            return;
        };
        for (vertices, cols) in [(40, 8), (77, 24), (16, 1), (50, 64)] {
            let case = Case::new(3 * vertices, cols);
            let params = case.columns();
            let layer = case.layer(WeightFormat::F32Columns);
            let weights = Weights {
                params: &params,
                halves: &[],
                bytes: &[],
            };
            let x: std::vec::Vec<f32> = noise(3 + cols as u32, cols).collect();
            for first in [0, 1, 5, vertices.saturating_sub(32)] {
                let n = (vertices - first) / 16 * 16;
                let mut want = std::vec![0.0f32; 3 * n];
                crate::network::dense_rows(&weights, &layer, &[&x], 3 * first, &mut want);
                for block in want.chunks_exact_mut(BLOCK_FLOATS) {
                    blocks.apply(block.try_into().unwrap());
                }
                let mut got = std::vec![0.0f32; 3 * n + 5];
                assert_eq!(blocks.placed_rows(&params, &layer, &x, 3 * first, &mut got), 3 * n);
                let bits = |v: &[f32]| v.iter().map(|v| v.to_bits()).collect::<std::vec::Vec<_>>();
                assert_eq!(
                    bits(&got[..3 * n]),
                    bits(&want),
                    "{vertices} vertices x {cols}, from {first}"
                );
                assert!(got[3 * n..].iter().all(|&v| v == 0.0), "only whole blocks are written");
            }
            let rows_layer = Layer {
                format: WeightFormat::F32,
                ..layer
            };
            let mut out = [0.0f32; BLOCK_FLOATS];
            assert_eq!(blocks.placed_rows(&case.params, &rows_layer, &x, 0, &mut out), 0);
            assert_eq!(blocks.placed_rows(&params, &layer, &x, 3 * vertices - 47, &mut out), 0);
        }
    }

    /// The pairs of vectors [`WorldBlocks::transform`] permutes are the ones [`gather`] names.
    #[test]
    fn the_written_out_transform_reads_the_gathered_pairs() {
        let pairs = [[0, 0, 0], [0, 1, 1], [1, 1, 1]];
        for (b, pair) in pairs.iter().enumerate() {
            for (k, &first) in pair.iter().enumerate() {
                assert_eq!(gather(b, k).0, first, "vector {b}, coordinate {k}");
            }
        }
    }

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
