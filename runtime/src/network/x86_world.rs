//! The world transform `p = R q + o` of encoded 3D vertices, sixteen at a time on AVX-512F
//! ([`WorldTransform`], the seam of `super::world`), and the one-pass decode into it.
//!
//! Sixteen vertices are 48 interleaved floats, three vectors. Output lane `i` (coordinate
//! `c = i % 3` of its vertex) is `R[c][0] x + R[c][1] y + R[c][2] z + o[c]`; the vertex's
//! `x`, `y` and `z` for every lane are gathered from two of the three vectors by one
//! permutation each, and the rows of `R` and `o` are laid out once in the same lane pattern.
//! Every lane computes `((R[c][0] x + o[c]) + R[c][1] y) + R[c][2] z` with fused
//! multiply-adds: the scalar path (`crate::decode`) is free to round differently, within the
//! tolerance `f32` targets agree to.

use core::arch::x86_64::*;

use nalgebra::{Matrix3, Vector3};

use super::columns::{column_chains512, column_layer};
use super::world::{WorldTransform, BLOCK_FLOATS, BLOCK_VERTICES};
use super::Width;
use crate::model::{column_stride, Layer};

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

impl WorldTransform for WorldBlocks {
    const PRESENT: bool = true;

    /// The pattern for the rotation `r` and the origin `o`; `None` where the CPU lacks
    /// AVX-512F (the caller transforms vertex by vertex).
    fn new(r: &Matrix3<f32>, o: &Vector3<f32>) -> Option<Self> {
        if super::fast::width() != Width::Avx512 {
            return None;
        }
        // Lane `l` of output vector `b` holds coordinate `(16 b + l) % 3` of its vertex.
        let mut rows = [[[0.0f32; 16]; 3]; 3];
        for b in 0..3 {
            for l in 0..16 {
                let c = (16 * b + l) % 3;
                for k in 0..3 {
                    rows[b][k][l] = r[(c, k)];
                }
            }
        }
        // SAFETY: every array holds 16 values; AVX-512F is present (checked above).
        let (load, index) = unsafe {
            (
                |v: &[f32; 16]| _mm512_loadu_ps(v.as_ptr()),
                |v: &[i32; 16]| _mm512_loadu_si512(v.as_ptr().cast()),
            )
        };
        let mut blocks = WorldBlocks {
            gathers: GATHERS.map(|b| [index(&b[0]), index(&b[1]), index(&b[2])]),
            rows: rows.map(|b| [load(&b[0]), load(&b[1]), load(&b[2])]),
            origin: [load(&[0.0; 16]); 3],
        };
        blocks.set_origin(o);
        Some(blocks)
    }

    /// Moves the transform to the origin `o` (the rotation stays).
    fn set_origin(&mut self, o: &Vector3<f32>) {
        let mut origin = [[0.0f32; 16]; 3];
        for (b, lanes) in origin.iter_mut().enumerate() {
            for (l, lane) in lanes.iter_mut().enumerate() {
                *lane = o[(16 * b + l) % 3];
            }
        }
        // SAFETY: a `WorldBlocks` exists only where the CPU has AVX-512F; 16 floats each.
        self.origin = origin.map(|lanes| unsafe { _mm512_loadu_ps(lanes.as_ptr()) });
    }

    /// Transforms one block of sixteen vertices in place.
    fn apply(&self, block: &mut [f32; BLOCK_FLOATS]) {
        // SAFETY: a `WorldBlocks` exists only where the CPU has AVX-512F.
        unsafe { self.apply_avx512(block) }
    }

    /// See [`WorldTransform::placed_rows`]: the bits of the column kernel followed by
    /// [`WorldTransform::apply`], without storing and loading the block in between.
    fn placed_rows(&self, params: &[f32], layer: &Layer, x: &[f32], first: usize, out: &mut [f32]) -> usize {
        let n = out.len() / BLOCK_FLOATS * BLOCK_FLOATS;
        let Some((w, bias)) = column_layer(params, layer, x.len(), first, n).filter(|_| n > 0) else {
            return 0;
        };
        let stride = column_stride(layer.rows as usize);
        // SAFETY: a `WorldBlocks` exists only where the CPU has AVX-512F; `column_layer`
        // checked that rows `first..first + n` exist in every column of `w` and in `bias`.
        unsafe { self.placed_avx512(w, stride, bias, x, first, &mut out[..n]) };
        n
    }

    /// See [`WorldTransform::placed_vertices`]: contiguous blocks with three stores, blocks
    /// across a prescribed vertex vertex by vertex; the vertices of a block with several
    /// origins are moved from the first one's to their own. Blocks of one origin have the
    /// bits of [`WorldTransform::placed_rows`].
    #[allow(clippy::too_many_arguments)]
    fn placed_vertices(
        &mut self,
        params: &[f32],
        layer: &Layer,
        x: &[f32],
        free: &[u32],
        origin_of: &[u32],
        origin: &mut u32,
        origin_at: &mut dyn FnMut(u32) -> Vector3<f32>,
        out: &mut [f32],
    ) -> usize {
        let n = free.len().min(origin_of.len()) / BLOCK_VERTICES * BLOCK_VERTICES;
        let Some((w, bias)) = column_layer(params, layer, x.len(), 0, 3 * n).filter(|_| n > 0) else {
            return 0;
        };
        let stride = column_stride(layer.rows as usize);
        let (free, origin_of) = (&free[..n], &origin_of[..n]);
        // SAFETY: a `WorldBlocks` exists only where the CPU has AVX-512F; `column_layer`
        // checked that rows `0..3 n` exist in every column of `w` and in `bias`.
        unsafe { self.placed_vertices_avx512(w, stride, bias, x, free, origin_of, origin, origin_at, out) }
    }
}

impl WorldBlocks {
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

    /// # Safety
    /// Rows `first..first + out.len()` must exist in `bias` and in each of the `x.len()`
    /// columns of `w` (`stride` floats apart).
    #[target_feature(enable = "avx512f")]
    unsafe fn placed_avx512(&self, w: &[f32], stride: usize, bias: &[f32], x: &[f32], first: usize, out: &mut [f32]) {
        // Two blocks at a time where there are two: six independent chains hide the latency
        // of each block's chain and transform.
        let mut pairs = out.chunks_exact_mut(2 * BLOCK_FLOATS);
        let mut r = first;
        for pair in &mut pairs {
            // SAFETY: rows `r..r + 96` exist in every column and in `bias` (the caller's
            // promise); `pair` holds 96 floats.
            unsafe {
                let [a0, a1, a2, b0, b1, b2] = column_chains512::<6>(w.as_ptr().add(r), stride, x);
                let (a, b) = ([a0, a1, a2], [b0, b1, b2]);
                self.finish_block(bias.as_ptr().add(r), a, pair.as_mut_ptr());
                self.finish_block(
                    bias.as_ptr().add(r + BLOCK_FLOATS),
                    b,
                    pair.as_mut_ptr().add(BLOCK_FLOATS),
                );
            }
            r += 2 * BLOCK_FLOATS;
        }
        if let Some(block) = pairs.into_remainder().get_mut(..BLOCK_FLOATS) {
            // SAFETY: as above, for 48 rows.
            unsafe {
                let a = column_chains512::<3>(w.as_ptr().add(r), stride, x);
                self.finish_block(bias.as_ptr().add(r), a, block.as_mut_ptr());
            }
        }
    }

    /// The loop of [`WorldTransform::placed_vertices`], compiled for AVX-512F so that the column
    /// chains and the block's transform and stores inline into it.
    ///
    /// # Safety
    /// Rows `0..3 free.len()` must exist in `bias` and in each of the `x.len()` columns of
    /// `w`; `free.len()` a multiple of 16 and equal to `origin_of`'s. (Destinations are
    /// checked here: a block is stored whole only where its sixteen vertices are
    /// consecutive and inside `out`.)
    #[allow(clippy::too_many_arguments)]
    #[target_feature(enable = "avx512f")]
    unsafe fn placed_vertices_avx512(
        &mut self,
        w: &[f32],
        stride: usize,
        bias: &[f32],
        x: &[f32],
        free: &[u32],
        origin_of: &[u32],
        origin: &mut u32,
        origin_at: &mut dyn FnMut(u32) -> Vector3<f32>,
        out: &mut [f32],
    ) -> usize {
        let mut done = 0;
        for (vertices, origins) in free
            .chunks_exact(BLOCK_VERTICES)
            .zip(origin_of.chunks_exact(BLOCK_VERTICES))
        {
            if origins[0] != *origin {
                *origin = origins[0];
                self.set_origin(&origin_at(*origin));
            }
            let r = 3 * done;
            // SAFETY: rows `r..r + 48` exist in every column and in `bias` (the caller's
            // promise); `origins` holds 16 indices; AVX-512F is present.
            unsafe {
                let a = column_chains512::<3>(w.as_ptr().add(r), stride, x);
                match shares_origin(origins, _mm512_set1_epi32(*origin as i32)) {
                    true => self.store_block(bias.as_ptr().add(r), a, vertices, out),
                    false => self.mixed_block(bias.as_ptr().add(r), a, vertices, origins, origin_at, out),
                }
            }
            done += BLOCK_VERTICES;
        }
        done
    }

    /// [`WorldBlocks::scatter_block`] for a block whose vertices `vertices` have the origins
    /// `origins`, not all this transform's (the first's): each other vertex moved by the
    /// difference of its origin (`origin_at`) and the first's.
    ///
    /// # Safety
    /// `bias` must hold 48 floats.
    #[target_feature(enable = "avx512f")]
    #[cold]
    unsafe fn mixed_block(
        &self,
        bias: *const f32,
        s: [__m512; 3],
        vertices: &[u32],
        origins: &[u32],
        origin_at: &mut dyn FnMut(u32) -> Vector3<f32>,
        out: &mut [f32],
    ) {
        let mut block = [0.0f32; BLOCK_FLOATS];
        // SAFETY: the caller's promise; `block` holds 48 floats.
        unsafe { self.finish_block(bias, s, block.as_mut_ptr()) };
        let first = origins.first().map_or(Vector3::zeros(), |&o| origin_at(o));
        let mut shift = (origins.first().copied().unwrap_or(0), Vector3::zeros());
        for ((&v, &o), p) in vertices.iter().zip(origins).zip(block.chunks_exact(3)) {
            if o != shift.0 {
                shift = (o, origin_at(o) - first);
            }
            if let Some(x) = out.get_mut(3 * v as usize..3 * v as usize + 3) {
                for ((x, p), d) in x.iter_mut().zip(p).zip(shift.1.iter()) {
                    *x = p + d;
                }
            }
        }
    }

    /// One block's sums plus its biases at `bias`, transformed and stored as the vertices
    /// `vertices` (16) of `out`: with three stores where they are consecutive and inside
    /// `out`, else vertex by vertex ([`WorldBlocks::scatter_block`]).
    ///
    /// # Safety
    /// `bias` must hold 48 floats.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn store_block(&self, bias: *const f32, s: [__m512; 3], vertices: &[u32], out: &mut [f32]) {
        let (Some(&first), Some(&last)) = (vertices.first(), vertices.get(BLOCK_FLOATS / 3 - 1)) else {
            return;
        };
        let (v0, last) = (first as usize, last as usize);
        if last.wrapping_sub(v0) == BLOCK_FLOATS / 3 - 1 && 3 * last + 3 <= out.len() {
            // SAFETY: the caller's promise for `bias`; the block's vertices are `v0..=last`,
            // so floats `3 v0..3 last + 3` of `out` (checked).
            unsafe { self.finish_block(bias, s, out.as_mut_ptr().add(3 * v0)) };
        } else {
            // SAFETY: the caller's promise.
            unsafe { self.scatter_block(bias, s, vertices, out) };
        }
    }

    /// [`WorldBlocks::store_block`] vertex by vertex (those outside `out` are skipped): a
    /// block across a prescribed vertex.
    ///
    /// # Safety
    /// `bias` must hold 48 floats.
    #[target_feature(enable = "avx512f")]
    #[cold]
    unsafe fn scatter_block(&self, bias: *const f32, s: [__m512; 3], vertices: &[u32], out: &mut [f32]) {
        let mut block = [0.0f32; BLOCK_FLOATS];
        // SAFETY: the caller's promise; `block` holds 48 floats.
        unsafe { self.finish_block(bias, s, block.as_mut_ptr()) };
        for (&v, p) in vertices.iter().zip(block.chunks_exact(3)) {
            if let Some(o) = out.get_mut(3 * v as usize..3 * v as usize + 3) {
                o.copy_from_slice(p);
            }
        }
    }

    /// One block's sums plus its biases at `bias`, transformed and stored at `out`.
    ///
    /// # Safety
    /// `bias` and `out` must hold 48 floats.
    #[target_feature(enable = "avx512f")]
    #[inline]
    unsafe fn finish_block(&self, bias: *const f32, s: [__m512; 3], out: *mut f32) {
        // SAFETY: the caller's promise.
        unsafe {
            let [out0, out1, out2] = self.transform(
                _mm512_add_ps(_mm512_loadu_ps(bias), s[0]),
                _mm512_add_ps(_mm512_loadu_ps(bias.add(16)), s[1]),
                _mm512_add_ps(_mm512_loadu_ps(bias.add(32)), s[2]),
            );
            _mm512_storeu_ps(out, out0);
            _mm512_storeu_ps(out.add(16), out1);
            _mm512_storeu_ps(out.add(32), out2);
        }
    }
}

/// Whether all sixteen `origins` equal `wanted` (broadcast).
///
/// # Safety
/// The CPU must have AVX-512F; `origins` must hold 16 indices.
#[target_feature(enable = "avx512f")]
#[inline]
unsafe fn shares_origin(origins: &[u32], wanted: __m512i) -> bool {
    // SAFETY: the caller's promise.
    unsafe { _mm512_cmpeq_epi32_mask(_mm512_loadu_si512(origins.as_ptr().cast()), wanted) == u16::MAX }
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;

    /// The transform of a fixed rotation and origin; `None` (said) without AVX-512F.
    fn test_blocks() -> Option<WorldBlocks> {
        let r = Matrix3::new(0.36, 0.48, -0.8, -0.8, 0.6, 0.0, 0.48, 0.64, 0.6);
        let blocks = WorldBlocks::new(&r, &Vector3::new(1.5, -2.0, 0.25));
        if blocks.is_none() {
            std::println!("no AVX-512F: the vector transform is not run on this CPU");
        }
        blocks
    }

    /// Rows decoded and placed in one pass have the bits of the column kernel's rows placed
    /// block by block afterwards, from any first vertex; a layer stored by rows, or rows past
    /// the layer, are left to the caller.
    #[test]
    fn placed_rows_are_the_rows_then_the_transform() {
        use crate::model::{WeightFormat, Weights};
        use crate::network::test_support::{noise, Case};
        let Some(blocks) = test_blocks() else {
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

    /// Free vertices decoded and placed straight into a full buffer have the bits of the rows
    /// placed block by block, whole blocks or across prescribed vertices, at their origin:
    /// the transform moves to the origin of each block's first vertex, and a vertex of
    /// another origin inside a block is moved to its own (within rounding). Decoding stops
    /// before the last partial block and leaves prescribed vertices untouched.
    #[test]
    fn placed_vertices_are_the_placed_rows_at_their_vertices() {
        use crate::model::WeightFormat;
        use crate::network::test_support::{noise, Case};
        let (Some(mut blocks), Some(mut at_three)) = (test_blocks(), test_blocks()) else {
            return;
        };
        // Origin 2 is the test transform's; origin 3 another.
        let (two, three) = (Vector3::new(1.5f32, -2.0, 0.25), Vector3::new(-0.5f32, 4.0, 1.0));
        at_three.set_origin(&three);
        let mut origin_at = |o: u32| if o == 3 { three } else { two };
        // 120 vertices; prescribed: 0, 40 and 41 (inside a block of free vertices), 119.
        let prescribed = [0u32, 40, 41, 119];
        let free: std::vec::Vec<u32> = (0..120).filter(|v| !prescribed.contains(v)).collect();
        let (cols, n) = (8, free.len());
        let case = Case::new(3 * n, cols);
        let params = case.columns();
        let layer = case.layer(WeightFormat::F32Columns);
        let x: std::vec::Vec<f32> = noise(11, cols).collect();
        let placed = |blocks: &WorldBlocks| {
            let mut rows = std::vec![0.0f32; 3 * n];
            assert_eq!(blocks.placed_rows(&params, &layer, &x, 0, &mut rows), 3 * (n / 16 * 16));
            rows
        };
        let (rows_two, rows_three) = (placed(&blocks), placed(&at_three));
        let bits = |v: &[f32]| v.iter().map(|v| v.to_bits()).collect::<std::vec::Vec<_>>();
        let stop = n / 16 * 16;
        // All at origin 2; vertex 50 alone at 3 (inside a block); from the fifth block on at 3.
        for origin_of in [
            std::vec![2u32; n],
            (0..n).map(|j| if j == 50 { 3 } else { 2 }).collect(),
            (0..n)
                .map(|j| if j >= 64 { 3 } else { 2 })
                .collect::<std::vec::Vec<u32>>(),
        ] {
            let mut out = std::vec![7.0f32; 3 * 120];
            let mut origin = 2;
            let done = blocks.placed_vertices(
                &params,
                &layer,
                &x,
                &free,
                &origin_of,
                &mut origin,
                &mut origin_at,
                &mut out,
            );
            assert_eq!(done, stop);
            for (j, &v) in free.iter().enumerate() {
                let got = &out[3 * v as usize..3 * v as usize + 3];
                let (own, first) = (origin_of[j], origin_of[j / 16 * 16]);
                let rows = if first == 3 { &rows_three } else { &rows_two };
                match (j < stop, own == first) {
                    (true, true) => assert_eq!(bits(got), bits(&rows[3 * j..3 * j + 3]), "free vertex {j}"),
                    (true, false) => {
                        let want = Vector3::from_column_slice(&rows[3 * j..3 * j + 3]) + three - two;
                        for c in 0..3 {
                            assert!((got[c] - want[c]).abs() <= 1e-5, "free vertex {j}: {got:?} vs {want:?}");
                        }
                    }
                    (false, _) => assert_eq!(got, [7.0; 3], "free vertex {j} is past the stop"),
                }
            }
            for v in prescribed {
                assert_eq!(out[3 * v as usize..3 * v as usize + 3], [7.0; 3], "prescribed {v}");
            }
            // The transform is left at the last block's origin.
            assert_eq!(origin, origin_of[stop - 16]);
            blocks.set_origin(&two);
        }
        // A buffer too short for the last block's vertices is not written past its end.
        let mut short = std::vec![0.0f32; 3 * 60];
        let all_two = std::vec![2; n];
        let done = blocks.placed_vertices(&params, &layer, &x, &free, &all_two, &mut 2, &mut origin_at, &mut short);
        assert_eq!(done, stop);
        let rows_layer = Layer {
            format: WeightFormat::F32,
            ..layer
        };
        let mut out = std::vec![0.0f32; 3 * 120];
        let done = blocks.placed_vertices(
            &case.params,
            &rows_layer,
            &x,
            &free,
            &all_two,
            &mut 2,
            &mut origin_at,
            &mut out,
        );
        assert_eq!(done, 0);
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
