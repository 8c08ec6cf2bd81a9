//! Point-triangle squared distance (3D) and its closest-feature classification.

use super::kernels;
use super::point_edge::{point_line, sub_point_edge};
use super::reduced::{cross, cross_accurate, difference, dot, sub, vertex};
use crate::energy::{Local, Want};

/// Which features of the triangle `[t0, t1, t2]` are closest to the point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PointTriangleType {
    /// Vertex `t0`.
    T0,
    /// Vertex `t1`.
    T1,
    /// Vertex `t2`.
    T2,
    /// Edge `[t0, t1]`.
    E0,
    /// Edge `[t1, t2]`.
    E1,
    /// Edge `[t2, t0]`.
    E2,
    /// The triangle's interior (distance to its plane).
    Interior,
}

/// Coordinates of `p` in the frame of the triangle's edge `i` (from `t_i` to `t_{i+1}`):
/// `[along the edge, as a fraction of its length; outward from the edge, in the plane]`.
fn edge_frame(t: [[f64; 3]; 3], normal: [f64; 3], i: usize, p: [f64; 3]) -> [f64; 2] {
    let along = sub(t[(i + 1) % 3], t[i]);
    let outward = cross(along, normal);
    let r = sub(p, t[i]);
    [
        dot(along, r) / dot(along, along),
        dot(outward, r) / dot(outward, outward),
    ]
}

/// Triangles whose squared double area is at most this fraction of their longest edge's
/// length to the fourth (heights up to `1e-10` of that edge) are degenerate: they have no
/// interior, and the point's closest feature is found among their edges.
pub const DEGENERATE_TRIANGLE: f64 = 1e-20;

/// Classifies `x = [p, t0, t1, t2]`: the point's projection onto the triangle's plane is
/// compared with each edge (the fraction along it and the side of it). An edge is closest
/// when the projection lies outside it and strictly between its endpoints; a vertex when
/// the projection is past the ends of both its edges; otherwise the interior. A degenerate
/// triangle (see [`DEGENERATE_TRIANGLE`]: collinear or coincident vertices) is the union of
/// its edges, so the closest of them, classified by [`point_edge_type`], decides.
pub fn point_triangle_type(x: &[f64]) -> PointTriangleType {
    let p = vertex(x, 3, 0);
    let t = [1, 2, 3].map(|a| vertex(x, 3, a));
    let normal = cross_accurate(sub(t[1], t[0]), sub(t[2], t[0]));
    let longest = (0..3)
        .map(|i| dot(sub(t[(i + 1) % 3], t[i]), sub(t[(i + 1) % 3], t[i])))
        .fold(0.0, f64::max);
    let area2 = dot(normal, normal);
    if area2.is_nan() || area2 <= DEGENERATE_TRIANGLE * longest * longest {
        return closest_edge_type(x);
    }
    let mut frame = [[0.0; 2]; 3];
    const EDGES: [PointTriangleType; 3] = [PointTriangleType::E0, PointTriangleType::E1, PointTriangleType::E2];
    for i in 0..3 {
        frame[i] = edge_frame(t, normal, i, p);
        if frame[i][0] > 0.0 && frame[i][0] < 1.0 && frame[i][1] >= 0.0 {
            return EDGES[i];
        }
    }
    // Vertex i closes edge i - 1 and opens edge i.
    if frame[0][0] <= 0.0 && frame[2][0] >= 1.0 {
        PointTriangleType::T0
    } else if frame[1][0] <= 0.0 && frame[0][0] >= 1.0 {
        PointTriangleType::T1
    } else if frame[2][0] <= 0.0 && frame[1][0] >= 1.0 {
        PointTriangleType::T2
    } else {
        PointTriangleType::Interior
    }
}

/// The type of the closest of the three edges of `x = [p, t0, t1, t2]` to `p`, each
/// classified by [`point_edge_type`] (a zero-length edge as its one point).
fn closest_edge_type(x: &[f64]) -> PointTriangleType {
    use PointTriangleType::*;
    const EDGES: [([usize; 3], [PointTriangleType; 3]); 3] = [
        ([0, 1, 2], [T0, T1, E0]),
        ([0, 2, 3], [T1, T2, E1]),
        ([0, 3, 1], [T2, T0, E2]),
    ];
    let mut best = (f64::INFINITY, Interior);
    for (stencil, types) in EDGES {
        let (d, ty) = sub_point_edge(x, stencil, types);
        // The first edge always names a type, so non-finite input still gets one.
        if d < best.0 || best.1 == Interior {
            best = (d, ty);
        }
    }
    best.1
}

/// Squared distance from `p` to the triangle of `x = [p, t0, t1, t2]`, classified by
/// [`point_triangle_type`].
pub fn point_triangle_distance(x: &[f64], want: Want, out: &mut Local) -> f64 {
    point_triangle_distance_typed(x, point_triangle_type(x), want, out)
}

/// As [`point_triangle_distance`] with the closest features given.
pub fn point_triangle_distance_typed(x: &[f64], ty: PointTriangleType, want: Want, out: &mut Local) -> f64 {
    let v = [0, 1, 2, 3].map(|a| vertex(x, 3, a));
    let hess = want.hessian().is_some();
    let diff = difference;
    let (vertex_of, edge_of) = match ty {
        PointTriangleType::T0 => (Some(1), None),
        PointTriangleType::T1 => (Some(2), None),
        PointTriangleType::T2 => (Some(3), None),
        PointTriangleType::E0 => (None, Some((1, 2))),
        PointTriangleType::E1 => (None, Some((2, 3))),
        PointTriangleType::E2 => (None, Some((3, 1))),
        PointTriangleType::Interior => (None, None),
    };
    if let Some(a) = vertex_of {
        return kernels::point_point(sub(v[0], v[a]), hess).scatter(&[diff(0, a)], 4, 3, want, out);
    }
    if let Some((a, b)) = edge_of {
        let (kernel, coef) = point_line(&v, 0, a, b, hess);
        return kernel.scatter(&coef, 4, 3, want, out);
    }
    kernels::plane(sub(v[0], v[1]), sub(v[2], v[1]), sub(v[3], v[1]), hess).scatter(
        &[diff(0, 1), diff(2, 1), diff(3, 1)],
        4,
        3,
        want,
        out,
    )
}
