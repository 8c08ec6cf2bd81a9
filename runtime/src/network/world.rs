//! The vector world transform `p = R q + o` of decoded 3D vertices, sixteen at a time, and the
//! one-pass decode that computes a column-stored output layer's rows and transforms them
//! while they are in registers: what an ISA module implements ([`WorldTransform`]) and what
//! a target without one has ([`NoWorldBlocks`]). `super::WorldBlocks` is this target's.
//!
//! Only behind an `f32` decoder: the transform rounds differently from the scalar one, within
//! the tolerance `f32` targets agree to.

use nalgebra::{Matrix3, Vector3};

use crate::model::Layer;

/// Floats in one block: sixteen vertices of three coordinates.
pub(crate) const BLOCK_FLOATS: usize = 48;

/// Vertices in one block.
pub(crate) const BLOCK_VERTICES: usize = BLOCK_FLOATS / 3;

/// A world transform for one rotation and origin, sixteen vertices at a time.
pub(crate) trait WorldTransform: Sized {
    /// Whether this target has one at all (`false`: [`WorldTransform::new`] is always
    /// `None`, and callers skip the work that would prepare it).
    const PRESENT: bool;

    /// The transform for the rotation `r` and the origin `o`; `None` where the CPU has none
    /// (the caller transforms vertex by vertex).
    fn new(r: &Matrix3<f32>, o: &Vector3<f32>) -> Option<Self>;

    /// Moves the transform to the origin `o` (the rotation stays).
    fn set_origin(&mut self, o: &Vector3<f32>);

    /// Transforms one block of sixteen vertices in place.
    fn apply(&self, block: &mut [f32; BLOCK_FLOATS]);

    /// Rows `first..` of a decoder's column-stored `f32` output layer on the input `x`, as
    /// many whole blocks as `out` holds, each transformed in the same pass: the bits of the
    /// layer's rows followed by [`WorldTransform::apply`]. Returns the rows written (0 where
    /// the layer is not stored by columns or lacks the rows: the caller computes them).
    fn placed_rows(&self, params: &[f32], layer: &Layer, x: &[f32], first: usize, out: &mut [f32]) -> usize;

    /// The encoded vertices `free` (the model's free vertices, ascending; `origin_of` their
    /// origins, `origin` the one this transform is at, `origin_at` the position of any)
    /// decoded from a column-stored `f32` output layer on the input `x` and placed, sixteen
    /// at a time, each block straight to its vertices in `out` (three floats per vertex). A
    /// block whose first vertex has another origin moves the transform there; vertices of
    /// another origin inside a block are moved to their own one by one. Stops before the
    /// last `free.len() % 16`; returns the free vertices placed (0 where the layer is not
    /// stored by columns or `out` is too short).
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
    ) -> usize;
}

/// The world transform of a target without one: no value exists, so every use compiles away.
/// (Unused on targets that have one.)
#[allow(dead_code)]
pub(crate) enum NoWorldBlocks {}

impl WorldTransform for NoWorldBlocks {
    const PRESENT: bool = false;

    #[inline(always)]
    fn new(_: &Matrix3<f32>, _: &Vector3<f32>) -> Option<Self> {
        None
    }

    fn set_origin(&mut self, _: &Vector3<f32>) {
        match *self {}
    }

    fn apply(&self, _: &mut [f32; BLOCK_FLOATS]) {
        match *self {}
    }

    fn placed_rows(&self, _: &[f32], _: &Layer, _: &[f32], _: usize, _: &mut [f32]) -> usize {
        match *self {}
    }

    fn placed_vertices(
        &mut self,
        _: &[f32],
        _: &Layer,
        _: &[f32],
        _: &[u32],
        _: &[u32],
        _: &mut u32,
        _: &mut dyn FnMut(u32) -> Vector3<f32>,
        _: &mut [f32],
    ) -> usize {
        match *self {}
    }
}
