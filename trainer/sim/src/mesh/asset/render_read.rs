//! Reading a render embedding back from the archive [`RenderEmbedding::write_npz`] writes (the
//! layout is in [`super::render`]'s module docs), every array checked against the others; an
//! error names the file and the array.

use std::path::Path;

use super::render::{RenderEmbedding, WEIGHT_TOLERANCE};
use super::{Part, Surface};
use crate::error::InputError;
use crate::mesh::embedding::{Anchor, Embedding};
use crate::mesh::{Elements, Mesh};
use crate::npz::NpzFile;

impl RenderEmbedding {
    /// [`RenderEmbedding::read_npz`], checked against the tet mesh `mesh` it rides on: the same
    /// counts of vertices and tets, and each render vertex's anchors the vertices of its tet.
    pub fn read_for(path: &Path, mesh: &Mesh) -> Result<RenderEmbedding, InputError> {
        let render = RenderEmbedding::read_npz(path)?;
        let Elements::Tets(tets) = &mesh.elements else {
            return Err(InputError::file(
                path,
                "rides on a tet mesh; the scene's mesh has no tets",
            ));
        };
        let size = (mesh.num_vertices(), tets.len());
        if render.sim_size != size {
            return Err(InputError::field(
                path,
                "sim_vertices",
                format!(
                    "made for a mesh of {} vertices and {} tets; the scene's has {} and {}",
                    render.sim_size.0, render.sim_size.1, size.0, size.1
                ),
            ));
        }
        let sorted = |mut v: [usize; 4]| {
            v.sort_unstable();
            v
        };
        let anchors = render.embedding.anchors.iter().zip(&render.tets);
        if let Some(i) = anchors
            .map(|(a, &t)| sorted(a.vertices) == sorted(tets[t]))
            .position(|same| !same)
        {
            return Err(InputError::field(
                path,
                "tet_vertices",
                format!("render vertex {i}'s anchors are not the vertices of its tet in the scene's mesh"),
            ));
        }
        Ok(render)
    }

    /// Reads the archive at `path` (as [`RenderEmbedding::write_npz`] writes it). The render
    /// mesh comes back as one part.
    pub fn read_npz(path: &Path) -> Result<RenderEmbedding, InputError> {
        let mut npz = NpzFile::open(path)?;
        let positions = npz.array("positions")?;
        let [n, three] = positions.dims::<2>()?;
        if three != 3 {
            return Err(positions.error(format!("{three} coordinates per vertex, expected 3")));
        }
        let positions = triples(positions.into_vec::<f64>("f64")?);
        let triangles = npz.array("triangles")?;
        let [m, three] = triangles.dims::<2>()?;
        if three != 3 {
            return Err(triangles.error(format!("{three} vertices per triangle, expected 3")));
        }
        let flat = triangles.into_vec::<u32>("u32")?;
        if flat.iter().any(|&v| v as usize >= n) {
            return Err(InputError::field(
                path,
                "triangles",
                format!("a vertex index beyond the {n} vertices"),
            ));
        }
        let triangles: Vec<[usize; 3]> = flat
            .chunks_exact(3)
            .map(|t| [t[0] as usize, t[1] as usize, t[2] as usize])
            .collect();
        let normals = match npz.has("normals") {
            true => Some(triples(per_vertex(&mut npz, "normals", n, 3)?)),
            false => None,
        };
        let uvs = match npz.has("uvs") {
            true => Some(
                per_vertex(&mut npz, "uvs", n, 2)?
                    .chunks_exact(2)
                    .map(|c| [c[0], c[1]])
                    .collect(),
            ),
            false => None,
        };
        let scalar = |npz: &mut NpzFile, name: &'static str| -> Result<usize, InputError> {
            let a = npz.array(name)?;
            a.expect_shape(&[])?;
            let v = a.into_vec::<u64>("u64")?;
            Ok(v.first().copied().unwrap_or(0) as usize)
        };
        let sim_size = (scalar(&mut npz, "sim_vertices")?, scalar(&mut npz, "sim_tets")?);
        let tets = npz.array("tet")?;
        tets.expect_shape(&[n as u64])?;
        let tets: Vec<usize> = tets.into_vec::<u32>("u32")?.into_iter().map(|t| t as usize).collect();
        if tets.iter().any(|&t| t >= sim_size.1) {
            return Err(InputError::field(
                path,
                "tet",
                format!("a tet beyond the {} tets", sim_size.1),
            ));
        }
        let vertices = per_vertex_u32(&mut npz, "tet_vertices", n)?;
        if vertices.iter().any(|&v| v as usize >= sim_size.0) {
            return Err(InputError::field(
                path,
                "tet_vertices",
                format!("a vertex beyond the {} simulation vertices", sim_size.0),
            ));
        }
        let weights = per_vertex(&mut npz, "weights", n, 4)?;
        let inside = |w: &f64| (-WEIGHT_TOLERANCE..=1.0 + WEIGHT_TOLERANCE).contains(w);
        if !weights.iter().all(inside) {
            return Err(InputError::field(
                path,
                "weights",
                format!("a weight outside [-{WEIGHT_TOLERANCE}, 1 + {WEIGHT_TOLERANCE}] (or not finite)"),
            ));
        }
        let distance = npz.array("distance")?;
        distance.expect_shape(&[n as u64])?;
        let distance = distance.into_vec::<f64>("f64")?;
        let anchors = (0..n)
            .map(|i| Anchor {
                vertices: std::array::from_fn(|k| vertices[4 * i + k] as usize),
                weights: std::array::from_fn(|k| weights[4 * i + k]),
                distance: distance[i],
            })
            .collect();
        let surface = Surface {
            positions,
            triangles,
            normals,
            uvs,
            parts: vec![Part {
                name: None,
                triangles: 0..m,
            }],
        };
        Ok(RenderEmbedding {
            surface,
            tets,
            embedding: Embedding { dim: 3, anchors },
            sim_size,
        })
    }
}

fn triples(v: Vec<f64>) -> Vec<[f64; 3]> {
    v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

/// Array `name` of shape `(n, width)` as `f64`.
fn per_vertex(npz: &mut NpzFile, name: &'static str, n: usize, width: usize) -> Result<Vec<f64>, InputError> {
    let a = npz.array(name)?;
    a.expect_shape(&[n as u64, width as u64])?;
    a.into_vec::<f64>("f64")
}

/// Array `name` of shape `(n, 4)` as `u32`.
fn per_vertex_u32(npz: &mut NpzFile, name: &'static str, n: usize) -> Result<Vec<u32>, InputError> {
    let a = npz.array(name)?;
    a.expect_shape(&[n as u64, 4])?;
    a.into_vec::<u32>("u32")
}
