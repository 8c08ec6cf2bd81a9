//! The render mesh an artifact carries (`mochi_runtime::render`): the scene's render embedding
//! (`mesh.render`, written by `mochi mesh`) as the runtime's record, and the trainer's own
//! render positions and normals (in `f64`) that the runtime's and the generated code's are
//! compared with.

use mochi_runtime::payload::RenderData;
use mochi_sim::mesh::asset::render::RenderEmbedding;
use mochi_sim::{BuiltScene, InputError};

/// The render mesh of the scene `problem` was built from (empty when it names none).
pub fn render_data(problem: &BuiltScene) -> Result<RenderData, InputError> {
    Ok(match problem.scene.render_embedding(&problem.mesh)? {
        Some(render) => from_embedding(&render),
        None => RenderData::default(),
    })
}

/// The runtime's record of a render embedding: its anchors and weights (as `f32`), triangles
/// and texture coordinates.
pub fn from_embedding(render: &RenderEmbedding) -> RenderData {
    let anchors = &render.embedding.anchors;
    RenderData {
        anchors: anchors.iter().flat_map(|a| a.vertices.map(|v| v as u32)).collect(),
        weights: anchors.iter().flat_map(|a| a.weights.map(|w| w as f32)).collect(),
        triangles: render.surface.triangles.iter().flatten().map(|&v| v as u32).collect(),
        uvs: render
            .surface
            .uvs
            .iter()
            .flatten()
            .flatten()
            .map(|&v| v as f32)
            .collect(),
    }
}

/// The render vertices' positions (3 each) for simulation positions `x` (3 per vertex), in
/// `f64`: each the weighted sum of its anchors.
pub fn positions(render: &RenderData, x: &[f64]) -> Vec<f64> {
    let at = |v: u32, c: usize| x.get(3 * v as usize + c).copied().unwrap_or(0.0);
    render
        .anchors
        .chunks_exact(4)
        .zip(render.weights.chunks_exact(4))
        .flat_map(|(a, w)| {
            let p: [f64; 3] = std::array::from_fn(|c| (0..4).map(|i| w[i] as f64 * at(a[i], c)).sum());
            p
        })
        .collect()
}

/// Area-weighted vertex normals of the render triangles at `positions` (3 per render vertex),
/// in `f64`; zero for a vertex of no triangle of positive area.
pub fn normals(render: &RenderData, positions: &[f64]) -> Vec<f64> {
    let p = |v: u32| nalgebra::Vector3::from_fn(|c, _| positions[3 * v as usize + c]);
    let mut sums = vec![nalgebra::Vector3::<f64>::zeros(); positions.len() / 3];
    for t in render.triangles.chunks_exact(3) {
        let n = (p(t[1]) - p(t[0])).cross(&(p(t[2]) - p(t[0])));
        for &v in t {
            sums[v as usize] += n;
        }
    }
    sums.iter()
        .flat_map(|n| {
            let unit = n.try_normalize(0.0).unwrap_or_default();
            [unit.x, unit.y, unit.z]
        })
        .collect()
}

/// A box's surface as a render mesh: on each face a grid of `cells` quads per side, two
/// triangles each, outward, with the face's own texture coordinates (so the six faces do not
/// share vertices: seams, as an engine's mesh has them).
pub fn box_surface(min: [f64; 3], max: [f64; 3], cells: usize) -> mochi_sim::mesh::asset::Surface {
    let mut surface = mochi_sim::mesh::asset::Surface {
        uvs: Some(Vec::new()),
        ..Default::default()
    };
    for axis in 0..3 {
        for end in [0, 1] {
            // The face's two other axes, ordered so that u x v points outward.
            let (mut a, mut b) = ((axis + 1) % 3, (axis + 2) % 3);
            if end == 0 {
                std::mem::swap(&mut a, &mut b);
            }
            let first = surface.positions.len();
            for j in 0..=cells {
                for i in 0..=cells {
                    let (u, v) = (i as f64 / cells as f64, j as f64 / cells as f64);
                    let mut p = [0.0; 3];
                    p[axis] = if end == 0 { min[axis] } else { max[axis] };
                    p[a] = min[a] + u * (max[a] - min[a]);
                    p[b] = min[b] + v * (max[b] - min[b]);
                    surface.positions.push(p);
                    surface.uvs.get_or_insert_with(Vec::new).push([u, v]);
                }
            }
            let at = |i: usize, j: usize| first + j * (cells + 1) + i;
            for j in 0..cells {
                for i in 0..cells {
                    surface.triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                    surface.triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
                }
            }
        }
    }
    surface.parts = vec![mochi_sim::mesh::asset::Part {
        name: None,
        triangles: 0..surface.triangles.len(),
    }];
    surface
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::Artifact;
    use std::path::{Path, PathBuf};

    fn committed(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../tests/artifacts")
            .join(name)
    }

    /// `tests/artifacts/tiny.mochi` with a render mesh: its box's surface, 12 quads a side on
    /// every face (the simulation mesh has 8 x 2 x 2 cells), embedded in its tets.
    fn tiny_render() -> Artifact {
        let mut artifact = Artifact::read(&committed("tiny.mochi")).unwrap();
        let (problem, _) = crate::eval::rebuild_problem(&artifact).unwrap();
        let (lo, hi) = problem.mesh.bounding_box(&problem.mesh.rest);
        let surface = box_surface([lo[0], lo[1], lo[2]], [hi[0], hi[1], hi[2]], 12);
        let render = RenderEmbedding::new(&surface, &problem.mesh).unwrap();
        assert!(render.max_distance() < 1e-12 * artifact.diagonal);
        artifact.render = from_embedding(&render);
        artifact
    }

    /// Writes `tests/artifacts/tiny-render.mochi` (`cargo test -p mochi-trainer --lib -- --ignored
    /// write_tiny_render`).
    #[test]
    #[ignore]
    fn write_tiny_render() {
        tiny_render().write(&committed("tiny-render.mochi")).unwrap();
    }

    #[test]
    fn the_committed_tiny_render_is_tiny_with_its_box_surface() {
        let written = std::fs::read(committed("tiny-render.mochi")).unwrap();
        assert_eq!(tiny_render().to_bytes().unwrap(), written);
        let artifact = Artifact::parse(&written).unwrap();
        let r = &artifact.render;
        assert_eq!(
            (r.anchors.len(), r.triangles.len(), r.uvs.len()),
            (4 * 1014, 3 * 1728, 2 * 1014)
        );
    }

    #[test]
    fn render_normals_of_the_rest_box_point_out_of_its_faces() {
        let artifact = tiny_render();
        let x: Vec<f64> = artifact.rest.iter().map(|&v| v as f64).collect();
        let p = positions(&artifact.render, &x);
        let n = normals(&artifact.render, &p);
        let (lo, hi) = (0..3).fold(([f64::MAX; 3], [f64::MIN; 3]), |(mut lo, mut hi), c| {
            for q in p.chunks_exact(3) {
                lo[c] = lo[c].min(q[c]);
                hi[c] = hi[c].max(q[c]);
            }
            (lo, hi)
        });
        let mut checked = 0;
        for (q, n) in p.chunks_exact(3).zip(n.chunks_exact(3)) {
            // A vertex inside a face (not on an edge of the box) has that face's normal.
            let on: Vec<(usize, f64)> = (0..3)
                .filter_map(|c| match () {
                    _ if (q[c] - lo[c]).abs() < 1e-6 => Some((c, -1.0)),
                    _ if (q[c] - hi[c]).abs() < 1e-6 => Some((c, 1.0)),
                    _ => None,
                })
                .collect();
            if let [(c, sign)] = on[..] {
                assert!((n[c] - sign).abs() < 1e-9, "{q:?}: {n:?}");
                checked += 1;
            }
        }
        // 11 x 11 vertices inside each of the six faces.
        assert_eq!(checked, 6 * 121);
    }
}
