//! Barycentric embedding of points in a mesh: each point is tied to one element of a
//! (coarser) mesh by its barycentric weights at rest, so that wherever the mesh's vertices go
//! the point follows as the same weighted sum of them. This is how a coarse simulation mesh
//! drives a finer one (the coarse-mesh method of `mochi compare`) and how a cage drives a
//! render mesh.
//!
//! A point inside an element (or on its boundary) gets weights in `[0, 1]` that sum to one.
//! A point outside every element goes to the element whose closest point is nearest, with
//! the weights of that closest point (clamped to the element), so it moves with the nearest
//! part of the surface instead of extrapolating. For cloth (triangles in 3D) and rods the
//! closest point is measured in 3D, so points off the sheet's plane or off a strand are
//! projected onto it.
//!
//! The search tests every element whose bounding box, grown by the distance to the nearest
//! element found so far, can hold a closer point: fine for meshes of up to some ten thousand
//! elements per thousand points (the procedural scenes and their coarse versions).

use nalgebra::{Matrix3, Vector3};

use super::{Elements, Mesh};

type V3 = Vector3<f64>;

/// A point's element (up to four vertices; unused slots have weight 0 and vertex 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Anchor {
    /// Vertices of the element in the embedding mesh.
    pub vertices: [usize; 4],
    /// Their weights (sum one).
    pub weights: [f64; 4],
    /// Distance from the point to the element at rest (0 inside).
    pub distance: f64,
}

/// Points embedded in a mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct Embedding {
    /// Coordinates per vertex of both meshes.
    pub dim: usize,
    /// One anchor per embedded point.
    pub anchors: Vec<Anchor>,
}

impl Embedding {
    /// Embeds `points` (flat, `mesh.dim` per point, in the mesh's rest frame) in `mesh`.
    /// Errors when the mesh has no elements or a point is not finite.
    pub fn new(mesh: &Mesh, points: &[f64]) -> Result<Embedding, String> {
        let dim = mesh.dim;
        let cells = element_vertices(mesh);
        if cells.is_empty() {
            return Err("the embedding mesh has no elements".into());
        }
        let rest = |v: usize| padded(&mesh.rest[dim * v..dim * v + dim]);
        let boxes: Vec<(V3, V3)> = cells
            .iter()
            .map(|c| {
                let mut lo = V3::repeat(f64::INFINITY);
                let mut hi = V3::repeat(f64::NEG_INFINITY);
                for &v in c {
                    lo = lo.inf(&rest(v));
                    hi = hi.sup(&rest(v));
                }
                (lo, hi)
            })
            .collect();
        let mut anchors = Vec::with_capacity(points.len() / dim);
        for (i, p) in points.chunks_exact(dim).enumerate() {
            if !p.iter().all(|c| c.is_finite()) {
                return Err(format!("point {i} is not finite"));
            }
            let p = padded(p);
            let mut best: Option<Anchor> = None;
            for (c, (lo, hi)) in cells.iter().zip(&boxes) {
                let reach = best.map_or(f64::INFINITY, |b| b.distance);
                let outside = (lo - p).sup(&(p - hi)).sup(&V3::zeros()).norm();
                if outside > reach {
                    continue;
                }
                let corners: Vec<V3> = c.iter().map(|&v| rest(v)).collect();
                let (weights, distance) = closest_weights(&corners, &p);
                if best.is_none_or(|b| distance < b.distance) {
                    let mut anchor = Anchor {
                        vertices: [0; 4],
                        weights: [0.0; 4],
                        distance,
                    };
                    anchor.vertices[..c.len()].copy_from_slice(c);
                    anchor.weights[..c.len()].copy_from_slice(&weights[..c.len()]);
                    best = Some(anchor);
                }
            }
            anchors.push(best.expect("at least one element"));
        }
        Ok(Embedding { dim, anchors })
    }

    /// Number of embedded points.
    pub fn len(&self) -> usize {
        self.anchors.len()
    }

    /// Whether no point is embedded.
    pub fn is_empty(&self) -> bool {
        self.anchors.is_empty()
    }

    /// Largest distance from a point to its element at rest (0 when every point lies in the
    /// mesh).
    pub fn max_distance(&self) -> f64 {
        self.anchors.iter().map(|a| a.distance).fold(0.0, f64::max)
    }

    /// The embedded points' positions (flat, `dim` each, written into `out`) for mesh vertex
    /// positions `x`.
    pub fn apply(&self, x: &[f64], out: &mut [f64]) {
        let dim = self.dim;
        for (a, o) in self.anchors.iter().zip(out.chunks_exact_mut(dim)) {
            o.fill(0.0);
            for (&v, &w) in a.vertices.iter().zip(&a.weights) {
                if w != 0.0 {
                    for (o, x) in o.iter_mut().zip(&x[dim * v..dim * v + dim]) {
                        *o += w * x;
                    }
                }
            }
        }
    }
}

/// Each element's vertices: tets, triangles, or a rod's segments.
fn element_vertices(mesh: &Mesh) -> Vec<Vec<usize>> {
    match &mesh.elements {
        Elements::Tets(t) => t.iter().map(|c| c.to_vec()).collect(),
        Elements::Triangles(t) | Elements::Shell(t) => t.iter().map(|c| c.to_vec()).collect(),
        Elements::Rods(rods) => rods.iter().flat_map(|r| r.windows(2).map(|w| w.to_vec())).collect(),
    }
}

fn padded(p: &[f64]) -> V3 {
    V3::new(p[0], p[1], p.get(2).copied().unwrap_or(0.0))
}

/// Barycentric weights of the point of the simplex `corners` (2, 3 or 4 of them) closest to
/// `p`, and the distance to it.
fn closest_weights(corners: &[V3], p: &V3) -> ([f64; 4], f64) {
    let inside = match corners.len() {
        4 => tet_weights(corners, p),
        3 => triangle_weights(corners, p),
        _ => segment_weights(corners[0], corners[1], p),
    };
    if let Some(w) = inside.filter(|w| w.iter().all(|&c| c >= -1e-12)) {
        let q = point_of(corners, &w);
        return (w, (q - p).norm());
    }
    // Outside (or degenerate): the closest point lies on a face of lower dimension.
    let mut best = ([0.0; 4], f64::INFINITY);
    let faces: &[&[usize]] = match corners.len() {
        4 => &[&[0, 1, 2], &[0, 1, 3], &[0, 2, 3], &[1, 2, 3]],
        3 => &[&[0, 1], &[1, 2], &[0, 2]],
        _ => &[&[0], &[1]],
    };
    for face in faces {
        let sub: Vec<V3> = face.iter().map(|&k| corners[k]).collect();
        let (w, d) = if sub.len() == 1 {
            ([1.0, 0.0, 0.0, 0.0], (sub[0] - p).norm())
        } else {
            closest_weights(&sub, p)
        };
        if d < best.1 {
            let mut full = [0.0; 4];
            for (slot, &k) in face.iter().enumerate() {
                full[k] = w[slot];
            }
            best = (full, d);
        }
    }
    best
}

fn point_of(corners: &[V3], w: &[f64; 4]) -> V3 {
    corners.iter().zip(w).map(|(c, &w)| c * w).sum()
}

/// Barycentric weights of `p` in a tet (none when it is degenerate).
fn tet_weights(c: &[V3], p: &V3) -> Option<[f64; 4]> {
    let m = Matrix3::from_columns(&[c[1] - c[0], c[2] - c[0], c[3] - c[0]]);
    let l = m.try_inverse()? * (p - c[0]);
    Some([1.0 - l.x - l.y - l.z, l.x, l.y, l.z])
}

/// Barycentric weights of `p`'s projection onto a triangle's plane (none when degenerate).
fn triangle_weights(c: &[V3], p: &V3) -> Option<[f64; 4]> {
    let (e1, e2, d) = (c[1] - c[0], c[2] - c[0], p - c[0]);
    let (a, b, cc) = (e1.dot(&e1), e1.dot(&e2), e2.dot(&e2));
    let det = a * cc - b * b;
    if det.abs() <= 1e-14 * a * cc {
        return None;
    }
    let (r1, r2) = (e1.dot(&d), e2.dot(&d));
    let u = (cc * r1 - b * r2) / det;
    let v = (a * r2 - b * r1) / det;
    Some([1.0 - u - v, u, v, 0.0])
}

/// Weights of `p`'s projection onto the line through a segment (none when it has no length).
fn segment_weights(a: V3, b: V3, p: &V3) -> Option<[f64; 4]> {
    let e = b - a;
    let l = e.dot(&e);
    (l > 0.0).then(|| {
        let t = e.dot(&(p - a)) / l;
        [1.0 - t, t, 0.0, 0.0]
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::procedural::{box_tets, cloth_grid};

    /// A finer box's vertices embedded in a coarse box move with it exactly under any affine
    /// map (barycentric interpolation reproduces affine functions).
    #[test]
    fn fine_box_follows_an_affine_map_of_the_coarse_box() {
        let coarse = box_tets([0.0, 0.0, 0.0], [1.0, 0.3, 0.2], [4, 2, 2]).unwrap();
        let fine = box_tets([0.0, 0.0, 0.0], [1.0, 0.3, 0.2], [8, 3, 5]).unwrap();
        let e = Embedding::new(&coarse, &fine.rest).unwrap();
        assert!(e.max_distance() < 1e-12, "{}", e.max_distance());
        for a in &e.anchors {
            assert!((a.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            assert!(a.weights.iter().all(|w| (-1e-9..=1.0 + 1e-9).contains(w)), "{a:?}");
        }
        let map = |p: &[f64]| {
            [
                0.3 + 1.1 * p[0] - 0.4 * p[1] + 0.2 * p[2],
                -0.2 + 0.5 * p[0] + 0.9 * p[1],
                0.1 * p[0] - 0.3 * p[2] + 0.7,
            ]
        };
        let moved: Vec<f64> = coarse.rest.chunks(3).flat_map(map).collect();
        let mut out = vec![0.0; fine.rest.len()];
        e.apply(&moved, &mut out);
        for (p, o) in fine.rest.chunks(3).zip(out.chunks(3)) {
            let want = map(p);
            for k in 0..3 {
                assert!((want[k] - o[k]).abs() < 1e-12, "{p:?}: {o:?} vs {want:?}");
            }
        }
    }

    /// A point outside the mesh follows the nearest point of the surface (clamped weights).
    #[test]
    fn outside_points_go_to_the_nearest_element() {
        let coarse = box_tets([0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [1, 1, 1]).unwrap();
        let e = Embedding::new(&coarse, &[2.0, 0.5, 0.5, 0.5, 0.5, -0.25]).unwrap();
        assert!((e.anchors[0].distance - 1.0).abs() < 1e-12);
        assert!((e.anchors[1].distance - 0.25).abs() < 1e-12);
        let mut out = vec![0.0; 6];
        e.apply(&coarse.rest, &mut out);
        let want = [1.0, 0.5, 0.5, 0.5, 0.5, 0.0];
        for (o, w) in out.iter().zip(want) {
            assert!((o - w).abs() < 1e-12, "{out:?}");
        }
        assert!(Embedding::new(&coarse, &[f64::NAN, 0.0, 0.0]).is_err());
    }

    /// A finer cloth grid's vertices lie on the coarse sheet and follow its triangles.
    #[test]
    fn fine_cloth_lies_on_the_coarse_sheet() {
        let axes = ([1.0, 0.0, 0.0], [0.0, -1.0, 0.0]);
        let coarse = cloth_grid([1.0, 1.0], [5, 5], [-0.5, 0.0, 0.0], axes).unwrap();
        let fine = cloth_grid([1.0, 1.0], [9, 9], [-0.5, 0.0, 0.0], axes).unwrap();
        let e = Embedding::new(&coarse, &fine.rest).unwrap();
        assert!(e.max_distance() < 1e-12);
        let mut out = vec![0.0; fine.rest.len()];
        e.apply(&coarse.rest, &mut out);
        for (a, b) in out.iter().zip(&fine.rest) {
            assert!((a - b).abs() < 1e-12);
        }
    }
}
