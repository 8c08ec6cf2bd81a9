//! The render mesh riding on the simulation mesh (docs/design.md, decision 12): an engine
//! draws a finer mesh, with its own UVs, than the tets the model moves. Each render vertex is
//! tied to one simulation tet by four anchors and four barycentric weights
//! ([`Model::render_anchors`], [`Model::render_weights`]), so its position is
//! `sum_i w_i x(anchor_i)` of the decoded simulation positions `x`; its normal is recomputed
//! every frame from the render triangles ([`Model::render_triangles`]), area-weighted.
//!
//! Both run in one pass each over fixed buffers the caller provides (`3` floats per render
//! vertex), without allocating: `O(render vertices + render triangles)`.

use nalgebra::Vector3;

use crate::instance::{check_len, DecodeError, Instance, ValidModel};
use crate::model::{Model, ModelError, Problem};

/// Largest amount by which a render vertex's weight may lie outside `[0, 1]`, and their sum
/// differ from 1, in a valid model: the trainer's weights are within `1e-9` of `[0, 1]` and sum
/// to one in `f64`; this leaves room for their rounding to `f32`. A render vertex then never
/// leaves its tet's convex hull by more than this much, in barycentric units.
pub const RENDER_WEIGHT_TOLERANCE: f32 = 1e-6;

fn fail<T>(field: &'static str, problem: Problem) -> Result<T, ModelError> {
    Err(ModelError { field, problem })
}

impl<'a> Model<'a> {
    /// Vertices of the render mesh (0 without one).
    pub fn render_vertices(&self) -> usize {
        self.render_anchors.len as usize / 4
    }
    /// Length of the render decode's positions and normals (3 per render vertex).
    pub fn render_len(&self) -> usize {
        3 * self.render_vertices()
    }
    /// Whether the model carries a render mesh.
    pub fn has_render(&self) -> bool {
        self.render_anchors.len > 0
    }
    /// Per render vertex, the four simulation vertices of its tet.
    pub fn render_anchors(&self) -> &'a [u32] {
        self.render_anchors.of(self.indices).unwrap_or(&[])
    }
    /// Per render vertex, the barycentric weights of its anchors.
    pub fn render_weights(&self) -> &'a [f32] {
        self.render_weights.of(self.floats).unwrap_or(&[])
    }
    /// Render triangles, three render-vertex indices each.
    pub fn render_triangles(&self) -> &'a [u32] {
        self.render_triangles.of(self.indices).unwrap_or(&[])
    }
    /// Per render vertex, its texture coordinates (empty when the asset has none).
    pub fn render_uvs(&self) -> &'a [f32] {
        self.render_uvs.of(self.floats).unwrap_or(&[])
    }

    /// The render mesh: spans inside their pools; none at all, or a 3D model with four anchors
    /// (simulation vertices) and four finite weights per render vertex, each weight within
    /// [`RENDER_WEIGHT_TOLERANCE`] of `[0, 1]` and their sum within it of 1; whole triangles over
    /// the render vertices; two finite texture coordinates per render vertex, or none.
    pub(crate) fn validate_render(&self) -> Result<(), ModelError> {
        let spans = [
            ("render.anchors", self.render_anchors.of(self.indices).is_some()),
            ("render.weights", self.render_weights.of(self.floats).is_some()),
            ("render.triangles", self.render_triangles.of(self.indices).is_some()),
            ("render.uvs", self.render_uvs.of(self.floats).is_some()),
        ];
        for (field, fits) in spans {
            if !fits {
                return fail(field, Problem::OutOfRange);
            }
        }
        let (anchors, weights) = (self.render_anchors(), self.render_weights());
        let (triangles, uvs) = (self.render_triangles(), self.render_uvs());
        if !anchors.len().is_multiple_of(4) {
            let expected = anchors.len() - anchors.len() % 4;
            return fail("render.anchors", length(expected, anchors.len()));
        }
        let n = anchors.len() / 4;
        if n > 0 && self.dim != 3 {
            return fail("render.anchors", Problem::Unsupported);
        }
        if anchors.iter().any(|&v| v >= self.num_vertices) {
            return fail("render.anchors", Problem::OutOfRange);
        }
        if weights.len() != 4 * n {
            return fail("render.weights", length(4 * n, weights.len()));
        }
        if !weights.iter().all(|w| w.is_finite()) {
            return fail("render.weights", Problem::NotFinite);
        }
        let inside = |w: &f32| (-RENDER_WEIGHT_TOLERANCE..=1.0 + RENDER_WEIGHT_TOLERANCE).contains(w);
        let sums_to_one = |w: &[f32]| (w.iter().sum::<f32>() - 1.0).abs() <= RENDER_WEIGHT_TOLERANCE;
        if !weights.chunks_exact(4).all(|w| w.iter().all(inside) && sums_to_one(w)) {
            return fail("render.weights", Problem::Domain);
        }
        if !triangles.len().is_multiple_of(3) || (n == 0 && !triangles.is_empty()) {
            let expected = if n == 0 {
                0
            } else {
                triangles.len() - triangles.len() % 3
            };
            return fail("render.triangles", length(expected, triangles.len()));
        }
        if triangles.iter().any(|&i| i as usize >= n) {
            return fail("render.triangles", Problem::OutOfRange);
        }
        if !(uvs.is_empty() || uvs.len() == 2 * n) {
            return fail("render.uvs", length(2 * n, uvs.len()));
        }
        if !uvs.iter().all(|v| v.is_finite()) {
            return fail("render.uvs", Problem::NotFinite);
        }
        Ok(())
    }
}

fn length(expected: usize, found: usize) -> Problem {
    Problem::Length { expected, found }
}

/// The render vertices' positions (3 each, [`Model::render_len`]) for the decoded simulation
/// positions `sim` ([`Model::state_len`], as [`Instance::decode_into`] writes them).
pub fn render_positions(model: &ValidModel, sim: &[f32], out: &mut [f32]) -> Result<(), DecodeError> {
    let m = model.model();
    check_len(sim, m.state_len())?;
    check_len(out, m.render_len())?;
    let vertex = |v: u32| {
        let i = 3 * v as usize;
        match sim.get(i..i + 3) {
            Some(p) => Vector3::new(p[0], p[1], p[2]),
            None => Vector3::zeros(),
        }
    };
    let tets = m
        .render_anchors()
        .chunks_exact(4)
        .zip(m.render_weights().chunks_exact(4));
    for ((anchors, weights), o) in tets.zip(out.chunks_exact_mut(3)) {
        let mut p = Vector3::zeros();
        for (&v, &w) in anchors.iter().zip(weights) {
            p += vertex(v) * w;
        }
        o.copy_from_slice(p.as_slice());
    }
    Ok(())
}

/// Area-weighted vertex normals of the render triangles at `positions` (3 floats per render
/// vertex each), as [`triangle_normals`] computes them.
pub fn render_normals(model: &ValidModel, positions: &[f32], normals: &mut [f32]) -> Result<(), DecodeError> {
    let m = model.model();
    check_len(positions, m.render_len())?;
    check_len(normals, m.render_len())?;
    triangle_normals(m.render_triangles(), positions, normals);
    Ok(())
}

/// Area-weighted vertex normals of `triangles` (three indices into `positions` each) at
/// `positions` (3 floats per vertex), written into `normals` (as long as `positions`): the
/// sum of the cross products of each vertex's triangles' edges (twice their areas along their
/// normals), normalised; zero for a vertex of no triangle or of triangles of no area. An
/// index past `positions` reads as the origin and writes nowhere.
pub fn triangle_normals(triangles: &[u32], positions: &[f32], normals: &mut [f32]) {
    let at = |s: &[f32], v: u32| {
        let i = 3 * v as usize;
        match s.get(i..i + 3) {
            Some(p) => Vector3::new(p[0], p[1], p[2]),
            None => Vector3::zeros(),
        }
    };
    normals.fill(0.0);
    for t in triangles.chunks_exact(3) {
        let (a, b, c) = (at(positions, t[0]), at(positions, t[1]), at(positions, t[2]));
        let n = (b - a).cross(&(c - a));
        for &v in t {
            let sum = at(normals, v) + n;
            let i = 3 * v as usize;
            if let Some(o) = normals.get_mut(i..i + 3) {
                o.copy_from_slice(sum.as_slice());
            }
        }
    }
    for o in normals.chunks_exact_mut(3) {
        let n = Vector3::new(o[0], o[1], o[2]);
        let length = n.norm();
        let unit = if length > 0.0 && length.is_finite() {
            n / length
        } else {
            Vector3::zeros()
        };
        o.copy_from_slice(unit.as_slice());
    }
}

impl<const K: usize, const S: usize, const H: usize> Instance<K, S, H> {
    /// The render mesh's positions and normals ([`Model::render_len`] floats each) for the
    /// current state, through the decoded simulation positions written into `sim`
    /// ([`Model::state_len`] floats, the caller's scratch). A state that decodes to a
    /// non-finite value gives the render mesh at the rest positions and
    /// [`DecodeError::NotFinite`], as [`Instance::decode_into`] does.
    pub fn decode_render_into(
        &self,
        model: &ValidModel,
        sim: &mut [f32],
        positions: &mut [f32],
        normals: &mut [f32],
    ) -> Result<(), DecodeError> {
        let m = model.model();
        check_len(positions, m.render_len())?;
        check_len(normals, m.render_len())?;
        let decoded = match self.decode_into(model, sim) {
            Err(DecodeError::NotFinite) => Err(DecodeError::NotFinite),
            Err(e) => return Err(e),
            Ok(()) => Ok(()),
        };
        render_positions(model, sim, positions)?;
        render_normals(model, positions, normals)?;
        decoded
    }
}

#[cfg(all(test, feature = "std"))]
#[path = "render_tests.rs"]
mod tests;
