//! The render mesh riding on the simulation mesh: each vertex of the asset as an engine draws
//! it (split at UV and normal seams) tied to one tet by barycentric weights
//! ([`crate::mesh::embedding`]), written with the render mesh to an `.npz` archive.
//!
//! A render vertex inside the tet mesh gets its tet and weights in `[0, 1]` summing to one, so
//! its rest position comes back within rounding. A vertex outside (the tet mesh's surface
//! lies within the mesher's envelope of the asset's, not on it) goes to the nearest tet with
//! the weights of that tet's closest point: it then rides on the tet mesh's surface, never
//! outside its tet's convex hull, and its rest position comes back within its `distance`,
//! which the archive stores and [`RenderEmbedding::max_distance`] reports.
//!
//! Archive (`numpy.load`): `positions` (n, 3) f64 rest positions; `triangles` (m, 3) u32;
//! `normals` (n, 3) f64 and `uvs` (n, 2) f64 where the asset has them; `tet` (n,) u32 the
//! tet of each vertex in the simulation mesh; `tet_vertices` (n, 4) u32 its vertices (0-based,
//! the simulation mesh's numbering); `weights` (n, 4) f64; `distance` (n,) f64 from the rest
//! position to the tet; `sim_vertices`, `sim_tets` 0-d u64 (the mesh it was made for).

use std::collections::HashMap;
use std::path::Path;

use super::Surface;
use crate::error::InputError;
use crate::mesh::embedding::Embedding;
use crate::mesh::{Elements, Mesh};
use crate::npz::NpzOut;

/// Weights of an embedded vertex lie in `[-WEIGHT_TOLERANCE, 1 + WEIGHT_TOLERANCE]` (rounding
/// of the 3x3 solve that gives them): how far outside its tet's convex hull a render vertex can
/// be, in barycentric units.
pub const WEIGHT_TOLERANCE: f64 = 1e-9;

/// The render mesh and each of its vertices' tet.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderEmbedding {
    /// The render mesh (the asset's own vertices, normals, UVs and triangles).
    pub surface: Surface,
    /// Per render vertex: its tet in the simulation mesh.
    pub tets: Vec<usize>,
    /// Per render vertex: the tet's vertices, weights and rest distance.
    pub embedding: Embedding,
    /// Vertices and tets of the simulation mesh.
    pub sim_size: (usize, usize),
}

impl RenderEmbedding {
    /// Embeds `surface`'s vertices in the tet mesh `mesh` (same frame and units).
    pub fn new(surface: &Surface, mesh: &Mesh) -> Result<RenderEmbedding, String> {
        let Elements::Tets(tets) = &mesh.elements else {
            return Err("the simulation mesh is not a tet mesh".into());
        };
        if mesh.dim != 3 {
            return Err("the simulation mesh is not 3D".into());
        }
        let points: Vec<f64> = surface.positions.iter().flatten().copied().collect();
        let embedding = Embedding::new(mesh, &points)?;
        let tet_of: HashMap<[usize; 4], usize> = tets.iter().enumerate().map(|(i, t)| (sorted(*t), i)).collect();
        let tets_of_anchors = embedding
            .anchors
            .iter()
            .map(|a| {
                tet_of
                    .get(&sorted(a.vertices))
                    .copied()
                    .ok_or_else(|| "an anchor's vertices are not a tet of the mesh".to_string())
            })
            .collect::<Result<Vec<usize>, String>>()?;
        Ok(RenderEmbedding {
            surface: surface.clone(),
            tets: tets_of_anchors,
            embedding,
            sim_size: (mesh.num_vertices(), tets.len()),
        })
    }

    /// Largest distance from a render vertex's rest position to its tet.
    pub fn max_distance(&self) -> f64 {
        self.embedding.max_distance()
    }

    /// The render vertices' positions for simulation-mesh positions `x` (flat, 3 per vertex).
    pub fn positions(&self, x: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; 3 * self.embedding.len()];
        self.embedding.apply(x, &mut out);
        out
    }

    /// Writes the archive (layout in the module docs) to `path` whole or not at all.
    pub fn write_npz(&self, path: &Path) -> Result<(), InputError> {
        let temporary = super::temporary_beside(path);
        let result = self
            .write_npz_to(&temporary)
            .and_then(|()| std::fs::rename(&temporary, path));
        if let Err(e) = result {
            let _ = std::fs::remove_file(&temporary);
            return Err(InputError::file(path, format!("cannot write: {e}")));
        }
        Ok(())
    }

    fn write_npz_to(&self, path: &Path) -> std::io::Result<()> {
        let s = &self.surface;
        let n = s.positions.len() as u64;
        let mut npz = NpzOut::create(path)?;
        npz.array("positions", &[n, 3], s.positions.iter().flatten().copied())?;
        npz.array(
            "triangles",
            &[s.triangles.len() as u64, 3],
            s.triangles.iter().flatten().map(|&v| v as u32),
        )?;
        if let Some(normals) = &s.normals {
            npz.array("normals", &[n, 3], normals.iter().flatten().copied())?;
        }
        if let Some(uvs) = &s.uvs {
            npz.array("uvs", &[n, 2], uvs.iter().flatten().copied())?;
        }
        let anchors = &self.embedding.anchors;
        npz.array("tet", &[n], self.tets.iter().map(|&t| t as u32))?;
        npz.array(
            "tet_vertices",
            &[n, 4],
            anchors.iter().flat_map(|a| a.vertices.map(|v| v as u32)),
        )?;
        npz.array("weights", &[n, 4], anchors.iter().flat_map(|a| a.weights))?;
        npz.array("distance", &[n], anchors.iter().map(|a| a.distance))?;
        npz.array("sim_vertices", &[], [self.sim_size.0 as u64])?;
        npz.array("sim_tets", &[], [self.sim_size.1 as u64])?;
        npz.finish()
    }
}

fn sorted(mut v: [usize; 4]) -> [usize; 4] {
    v.sort_unstable();
    v
}
