//! A contact scene as people look at it: the body's surface and the obstacle meshes as one
//! triangle mesh, frame by frame, for OBJ files and previews.

use mochi_sim::trajectory::ObstacleFrames;
use mochi_sim::{Elements, Mesh};

/// Obstacle triangles are split until no edge is longer than this share of the body's rest
/// diagonal, so that depth sorting (previews draw far triangles first) places a large ground
/// behind the body and not over it.
const LONGEST_EDGE_SHARE: f64 = 0.25;
/// The most obstacle triangles the splitting makes.
const MOST_TRIANGLES: usize = 20_000;

/// The body's surface triangles followed by the obstacles' (3D bodies with triangle
/// surfaces), and every frame's positions in the same order; `None` when the body has no
/// surface triangles (rods) or is 2D.
pub fn with_obstacles(mesh: &Mesh, frames: &[Vec<f64>], obstacles: &ObstacleFrames) -> Option<(Mesh, Vec<Vec<f64>>)> {
    let mut triangles = mesh.surface_triangles();
    if mesh.dim != 3 || triangles.is_empty() || obstacles.positions.len() != frames.len() {
        return None;
    }
    let n = mesh.num_vertices();
    let longest = LONGEST_EDGE_SHARE * mesh.rest_diagonal();
    let (faces, midpoints) = split_long_edges(&obstacles.faces, &obstacles.positions[0], longest);
    triangles.extend(faces.iter().map(|f| f.map(|v| v + n)));
    let joined: Vec<Vec<f64>> = frames
        .iter()
        .zip(&obstacles.positions)
        .map(|(x, o)| {
            let mut all: Vec<f64> = x.iter().chain(o).copied().collect();
            let base = x.len();
            for &(a, b) in &midpoints {
                for i in 0..3 {
                    all.push(0.5 * (all[base + 3 * a + i] + all[base + 3 * b + i]));
                }
            }
            all
        })
        .collect();
    let view = Mesh {
        dim: 3,
        rest: joined[0].clone(),
        elements: Elements::Shell(triangles),
        attributes: None,
    };
    Some((view, joined))
}

/// Splits triangles at the midpoint of their longest edge until every edge is at most
/// `longest` at positions `x` (or the count reaches [`MOST_TRIANGLES`]). Returns the
/// triangles and, per new vertex (numbered after the old ones), the two vertices it is the
/// midpoint of, so any frame's positions give its own.
fn split_long_edges(faces: &[[u32; 3]], x: &[f64], longest: f64) -> (Vec<[usize; 3]>, Vec<(usize, usize)>) {
    let mut points: Vec<[f64; 3]> = x.chunks(3).map(|p| [p[0], p[1], p[2]]).collect();
    let mut midpoints = Vec::new();
    let mut edge_midpoint = std::collections::HashMap::new();
    let mut pending: Vec<[usize; 3]> = faces.iter().map(|f| f.map(|v| v as usize)).collect();
    let mut done = Vec::new();
    let length = |p: &[[f64; 3]], a: usize, b: usize| (0..3).map(|i| (p[a][i] - p[b][i]).powi(2)).sum::<f64>().sqrt();
    while let Some(t) = pending.pop() {
        let (k, edge) = (0..3)
            .map(|k| (k, length(&points, t[k], t[(k + 1) % 3])))
            .fold((0, 0.0), |m, e| if e.1 > m.1 { e } else { m });
        if edge <= longest || done.len() + pending.len() + 2 > MOST_TRIANGLES {
            done.push(t);
            continue;
        }
        let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
        let m = *edge_midpoint.entry((a.min(b), a.max(b))).or_insert_with(|| {
            points.push([0, 1, 2].map(|i| 0.5 * (points[a][i] + points[b][i])));
            midpoints.push((a, b));
            points.len() - 1
        });
        pending.push([a, m, c]);
        pending.push([m, b, c]);
    }
    (done, midpoints)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn obstacles_follow_the_body_in_vertices_and_triangles() {
        let mesh = mochi_sim::mesh::procedural::box_tets([0.0; 3], [1.0; 3], [1, 1, 1]).unwrap();
        let n = mesh.num_vertices();
        let surface = mesh.surface_triangles().len();
        let frames = vec![mesh.rest.clone(), mesh.rest.iter().map(|c| c + 1.0).collect()];
        let obstacles = ObstacleFrames {
            faces: vec![[0, 1, 2]],
            positions: vec![vec![0.0, -1.0, 0.0, 1.0, -1.0, 0.0, 0.0, -1.0, 1.0]; 2],
        };
        let (view, joined) = with_obstacles(&mesh, &frames, &obstacles).unwrap();
        let Elements::Shell(t) = &view.elements else {
            panic!("triangles")
        };
        // The unit obstacle triangle is split to edges of at most a quarter of the body's
        // diagonal (sqrt 3): the body's triangles come first, unchanged.
        assert_eq!(&t[..surface], &mesh.surface_triangles()[..]);
        assert!(t.len() > surface + 4, "{} triangles", t.len());
        assert!(t[surface..]
            .iter()
            .flatten()
            .all(|&v| v >= n && 3 * v < joined[1].len()));
        let limit = 0.25 * 3f64.sqrt() + 1e-12;
        for x in &joined {
            for tri in &t[surface..] {
                for k in 0..3 {
                    let (a, b) = (tri[k], tri[(k + 1) % 3]);
                    let d = (0..3)
                        .map(|i| (x[3 * a + i] - x[3 * b + i]).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    assert!(d <= limit, "edge {a}-{b} of length {d}");
                }
            }
        }
        // Split triangles cover the original one: their areas add up to its area (0.5).
        let area = |x: &[f64], tri: &[usize; 3]| {
            let p = tri.map(|v| [x[3 * v], x[3 * v + 1], x[3 * v + 2]]);
            let (u, w) = (
                [0, 1, 2].map(|i| p[1][i] - p[0][i]),
                [0, 1, 2].map(|i| p[2][i] - p[0][i]),
            );
            let c = [
                u[1] * w[2] - u[2] * w[1],
                u[2] * w[0] - u[0] * w[2],
                u[0] * w[1] - u[1] * w[0],
            ];
            0.5 * (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
        };
        let total: f64 = t[surface..].iter().map(|tri| area(&joined[1], tri)).sum();
        assert!((total - 0.5).abs() < 1e-12, "{total}");
        assert_eq!(&joined[1][..3 * n], &frames[1][..]);
        assert_eq!(&joined[1][3 * n..3 * (n + 3)], &obstacles.positions[1][..]);
        // Frame counts that disagree give nothing rather than a wrong picture.
        assert!(with_obstacles(&mesh, &frames[..1], &obstacles).is_none());
    }
}
