//! Exact intersection checks: does any edge of a contact surface pass through one of its
//! triangles (3D), or cross another of its edges (2D)?
//!
//! The tests are built on exact orientation predicates (`robust`'s adaptive-precision
//! `orient2d` / `orient3d`, Shewchuk's), so the answer is exact for the f64 positions given:
//! touching counts as intersecting. Pairs sharing a vertex are not tested (they touch by
//! construction; an edge through a vertex of a triangle can only meet the triangle again if
//! it lies in the triangle's plane, a flattened element that element checks catch). A body
//! entirely inside another without crossing surfaces is not an intersection here.

use robust::{orient2d, orient3d, Coord, Coord3D};

use super::broad_phase::aabb::Aabb;
use super::broad_phase::spatial_hash::overlapping_pairs;
use super::broad_phase::spatial_hash::overlapping_self_pairs;
use super::ContactSurface;

fn o3(a: [f64; 3], b: [f64; 3], c: [f64; 3], d: [f64; 3]) -> f64 {
    let p = |v: [f64; 3]| Coord3D {
        x: v[0],
        y: v[1],
        z: v[2],
    };
    orient3d(p(a), p(b), p(c), p(d))
}

fn o2(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    let p = |v: [f64; 2]| Coord { x: v[0], y: v[1] };
    orient2d(p(a), p(b), p(c))
}

/// The sign of an orientation: `1`, `-1` or `0` (products of signs cannot underflow).
fn sign(v: f64) -> i32 {
    if v > 0.0 {
        1
    } else if v < 0.0 {
        -1
    } else {
        0
    }
}

/// Whether the closed segments `[a, b]` and `[c, d]` of the plane share a point.
pub fn segments_intersect_2d(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let (s1, s2) = (sign(o2(a, b, c)), sign(o2(a, b, d)));
    if s1 == 0 && s2 == 0 {
        // `c` and `d` on the line of `[a, b]` (or `[a, b]` a single point): for points on
        // one line, the segments meet iff their extents overlap on both axes.
        let degenerate = a == b;
        if !degenerate || sign(o2(c, d, a)) == 0 {
            return (0..2).all(|k| a[k].min(b[k]) <= c[k].max(d[k]) && c[k].min(d[k]) <= a[k].max(b[k]));
        }
        return false;
    }
    let (s3, s4) = (sign(o2(c, d, a)), sign(o2(c, d, b)));
    s1 * s2 <= 0 && s3 * s4 <= 0
}

/// Whether the closed segment `[a, b]` and the closed triangle `t` share a point (3D).
pub fn segment_triangle_intersect(a: [f64; 3], b: [f64; 3], t: [[f64; 3]; 3]) -> bool {
    let (sa, sb) = (o3(t[0], t[1], t[2], a), o3(t[0], t[1], t[2], b));
    let (sa, sb) = (sign(sa), sign(sb));
    if sa == 0 && sb == 0 {
        return coplanar_segment_triangle(a, b, t);
    }
    if sa * sb > 0 {
        return false;
    }
    // The segment meets the plane; its line passes through the triangle iff it turns the
    // same way around all three edges.
    let s = [0, 1, 2].map(|i| sign(o3(a, b, t[i], t[(i + 1) % 3])));
    s.iter().all(|&v| v >= 0) || s.iter().all(|&v| v <= 0)
}

/// A segment in the plane of the triangle: projected onto the coordinate plane that keeps
/// the triangle widest (dropping one coordinate keeps orientations exact up to one common
/// sign), it meets the triangle iff an endpoint is inside or it crosses an edge.
fn coplanar_segment_triangle(a: [f64; 3], b: [f64; 3], t: [[f64; 3]; 3]) -> bool {
    let u = [0, 1, 2].map(|k| t[1][k] - t[0][k]);
    let v = [0, 1, 2].map(|k| t[2][k] - t[0][k]);
    let n = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    let axis = (0..3).max_by(|&i, &j| n[i].abs().total_cmp(&n[j].abs())).unwrap_or(2);
    let keep = match axis {
        0 => [1, 2],
        1 => [2, 0],
        _ => [0, 1],
    };
    let p = |q: [f64; 3]| [q[keep[0]], q[keep[1]]];
    let (a2, b2, t2) = (p(a), p(b), t.map(p));
    let inside = |q: [f64; 2]| {
        let s = [0, 1, 2].map(|i| sign(o2(t2[i], t2[(i + 1) % 3], q)));
        s.iter().all(|&v| v >= 0) || s.iter().all(|&v| v <= 0)
    };
    inside(a2) || inside(b2) || (0..3).any(|i| segments_intersect_2d(a2, b2, t2[i], t2[(i + 1) % 3]))
}

/// The intersecting pairs of `surface` at positions `x`: `[edge, face]` (indices into
/// `surface.edges` and `surface.faces`) in 3D, `[edge, edge]` (`a < b`) in 2D; sorted.
pub fn intersecting_pairs(surface: &ContactSurface, x: &[f64]) -> Vec<[usize; 2]> {
    let dim = surface.dim;
    let (edges, faces) = (&surface.edges, &surface.faces);
    let edge_boxes: Vec<Aabb> = edges.iter().map(|e| Aabb::of_vertices(x, dim, e)).collect();
    if dim == 2 {
        let p = |v: usize| [x[2 * v], x[2 * v + 1]];
        return overlapping_self_pairs(&edge_boxes, |i, j| {
            let (a, b) = (edges[i], edges[j]);
            !a.iter().any(|v| b.contains(v)) && segments_intersect_2d(p(a[0]), p(a[1]), p(b[0]), p(b[1]))
        });
    }
    let p = |v: usize| [x[3 * v], x[3 * v + 1], x[3 * v + 2]];
    let face_boxes: Vec<Aabb> = faces.iter().map(|f| Aabb::of_vertices(x, dim, f)).collect();
    overlapping_pairs(&edge_boxes, &face_boxes, |i, j| {
        let (e, f) = (edges[i], faces[j]);
        !e.iter().any(|v| f.contains(v)) && segment_triangle_intersect(p(e[0]), p(e[1]), f.map(p))
    })
}

/// Whether any edge of `surface` at positions `x` meets a triangle of it (3D) or another
/// edge (2D).
pub fn has_intersections(surface: &ContactSurface, x: &[f64]) -> bool {
    !intersecting_pairs(surface, x).is_empty()
}
