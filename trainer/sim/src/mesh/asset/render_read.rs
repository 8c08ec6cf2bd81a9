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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::procedural::box_tets;
    use crate::scene::Scene;

    /// `mesh` as a MEDIT file (1-based indices).
    fn medit(mesh: &Mesh) -> String {
        let Elements::Tets(tets) = &mesh.elements else {
            unreachable!()
        };
        let mut s = format!(
            "MeshVersionFormatted 1\nDimension 3\nVertices\n{}\n",
            mesh.num_vertices()
        );
        for p in mesh.rest.chunks_exact(3) {
            s += &format!("{} {} {} 0\n", p[0], p[1], p[2]);
        }
        s += &format!("Tetrahedra\n{}\n", tets.len());
        for t in tets {
            s += &format!("{} {} {} {} 0\n", t[0] + 1, t[1] + 1, t[2] + 1, t[3] + 1);
        }
        s + "End\n"
    }

    #[test]
    fn a_scene_names_its_render_mesh_and_a_mismatched_one_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mesh = box_tets([0.0, 0.0, 0.0], [2.0, 1.0, 1.0], [2, 1, 1]).unwrap();
        std::fs::write(dir.path().join("body.mesh"), medit(&mesh)).unwrap();
        let surface = Surface {
            positions: vec![[0.5, 0.5, 0.5], [1.5, 0.2, 0.9], [1.9, 0.9, 0.1]],
            triangles: vec![[0, 1, 2]],
            ..Surface::default()
        };
        let render = RenderEmbedding::new(&surface, &mesh).unwrap();
        render.write_npz(&dir.path().join("body.render.npz")).unwrap();
        let scene = |render: &str| {
            format!(
                "name = \"body\"\n[mesh]\ntype = \"file\"\npath = \"body.mesh\"\nnormalize = true\n{render}\n\
                 [material]\nyoungs = 1e5\npoisson = 0.4\ndensity = 1000.0\n"
            )
        };
        let file = dir.path().join("body.toml");
        let with = Scene::parse(&scene("render = \"body.render.npz\""), &file).unwrap();
        let built = with.build_mesh().unwrap();
        let read = with.render_embedding(&built).unwrap().unwrap();
        assert_eq!(read.embedding, render.embedding);
        assert_eq!(read.tets, render.tets);
        let without = Scene::parse(&scene(""), &file).unwrap();
        assert_eq!(without.render_embedding(&built).unwrap(), None);
        // The archive of another mesh is refused, naming it.
        let other = box_tets([0.0, 0.0, 0.0], [2.0, 1.0, 1.0], [3, 1, 1]).unwrap();
        RenderEmbedding::new(&surface, &other)
            .unwrap()
            .write_npz(&dir.path().join("other.render.npz"))
            .unwrap();
        let wrong = Scene::parse(&scene("render = \"other.render.npz\""), &file).unwrap();
        let e = wrong.render_embedding(&built).unwrap_err().to_string();
        assert!(e.contains("other.render.npz") && e.contains("made for a mesh"), "{e}");
        let missing = Scene::parse(&scene("render = \"none.render.npz\""), &file).unwrap();
        let e = missing.render_embedding(&built).unwrap_err().to_string();
        assert!(e.contains("none.render.npz"), "{e}");
    }
}
