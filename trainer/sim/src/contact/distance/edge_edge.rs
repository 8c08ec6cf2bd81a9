//! Edge-edge squared distance (3D) and its closest-feature classification.

use super::kernels;
use super::point_edge::{point_line, sub_point_edge};
use super::reduced::{cross_accurate, difference, dot, sub, vertex};
use crate::energy::{Local, Want};

/// Which features of the edges `a = [ea0, ea1]` and `b = [eb0, eb1]` are closest.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EdgeEdgeType {
    /// `ea0` and `eb0`.
    A0B0,
    /// `ea0` and `eb1`.
    A0B1,
    /// `ea1` and `eb0`.
    A1B0,
    /// `ea1` and `eb1`.
    A1B1,
    /// The interior of `a` and `eb0`.
    AB0,
    /// The interior of `a` and `eb1`.
    AB1,
    /// `ea0` and the interior of `b`.
    A0B,
    /// `ea1` and the interior of `b`.
    A1B,
    /// Both interiors (distance between the two lines).
    AB,
}

/// Edges whose squared cross-product norm is below this fraction of `|a|^2 |b|^2` (the
/// squared sine of their angle: under `1e-10` rad) are treated as parallel. Relative to the
/// edges' lengths, so short edges are classified as long ones of the same shape; treating
/// such edges as parallel moves their distance by at most `1e-10` times the shorter edge.
pub const PARALLEL_THRESHOLD: f64 = 1e-20;

/// Classifies `x = [ea0, ea1, eb0, eb1]`. The closest points of the two lines, at parameters
/// `s` on `a` and `t` on `b`, are clamped to the segments in turn (the classic
/// segment-segment algorithm): `s` first, then `t` for that `s`, then `s` again if `t` had to
/// be clamped. A zero-length edge is its one point, classified against the other edge; parallel
/// edges to [`parallel_type`]. The lines' parameters are ratios of cross products, each
/// component computed with one rounding ([`cross_accurate`]), instead of the Gram
/// determinant `|a|^2 |b|^2 - (a.b)^2`, which cancels for nearly parallel edges.
pub fn edge_edge_type(x: &[f64]) -> EdgeEdgeType {
    use EdgeEdgeType::*;
    let v = [0, 1, 2, 3].map(|a| vertex(x, 3, a));
    let u = sub(v[1], v[0]);
    let w = sub(v[3], v[2]);
    let r = sub(v[0], v[2]);
    let (a, c) = (dot(u, u), dot(w, w));
    match (a == 0.0, c == 0.0) {
        (true, true) => return A0B0,
        (true, false) => return point_type(x, 0, [A0B0, A0B1, A0B]),
        (false, true) => return point_type(x, 2, [A0B0, A1B0, AB0]),
        _ => {}
    }
    let n = cross_accurate(u, w);
    let den = dot(n, n);
    if den.is_nan() || den < PARALLEL_THRESHOLD * a * c {
        return parallel_type(x);
    }
    // By Lagrange's identity, s = n.(w x r) / |n|^2 on a; t = t_num / t_den on b.
    let s_num = dot(n, cross_accurate(w, r));
    let (t_num, t_den, interior) = if s_num <= 0.0 {
        (dot(w, r), c, A0B)
    } else if s_num >= den {
        (dot(w, sub(v[1], v[2])), c, A1B)
    } else {
        (dot(n, cross_accurate(u, r)), den, AB)
    };
    if t_num <= 0.0 {
        // t = 0: closest point of a to eb0, at s = (eb0 - ea0).u / a.
        let s = dot(u, sub(v[2], v[0]));
        if s <= 0.0 {
            A0B0
        } else if s >= a {
            A1B0
        } else {
            AB0
        }
    } else if t_num >= t_den {
        // t = 1: closest point of a to eb1, at s = (eb1 - ea0).u / a.
        let s = dot(u, sub(v[3], v[0]));
        if s <= 0.0 {
            A0B1
        } else if s >= a {
            A1B1
        } else {
            AB1
        }
    } else {
        interior
    }
}

/// The type of the endpoint `x[p]` of a zero-length edge against the other edge, as
/// `[at its first end, at its second end, in its interior]`.
fn point_type(x: &[f64], p: usize, types: [EdgeEdgeType; 3]) -> EdgeEdgeType {
    let [s, t] = if p == 0 { [2, 3] } else { [0, 1] };
    sub_point_edge(x, [p, s, t], types).1
}

/// Classification of parallel edges: the closest of the four endpoint-to-other-edge
/// distances (an endpoint always attains the minimum for parallel segments).
pub fn parallel_type(x: &[f64]) -> EdgeEdgeType {
    use EdgeEdgeType::*;
    // (point, edge start, edge end) and the types at the edge's start, end and interior.
    let cases = [
        ([2, 0, 1], [A0B0, A1B0, AB0]),
        ([3, 0, 1], [A0B1, A1B1, AB1]),
        ([0, 2, 3], [A0B0, A0B1, A0B]),
        ([1, 2, 3], [A1B0, A1B1, A1B]),
    ];
    let mut best = (f64::INFINITY, AB);
    for (stencil, types) in cases {
        let (d, ty) = sub_point_edge(x, stencil, types);
        if d < best.0 {
            best = (d, ty);
        }
    }
    best.1
}

/// Squared distance between the edges of `x = [ea0, ea1, eb0, eb1]`, classified by
/// [`edge_edge_type`] (not mollified: see [`super::mollifier`]).
pub fn edge_edge_distance(x: &[f64], want: Want, out: &mut Local) -> f64 {
    edge_edge_distance_typed(x, edge_edge_type(x), want, out)
}

/// As [`edge_edge_distance`] with the closest features given.
pub fn edge_edge_distance_typed(x: &[f64], ty: EdgeEdgeType, want: Want, out: &mut Local) -> f64 {
    use EdgeEdgeType::*;
    let v = [0, 1, 2, 3].map(|a| vertex(x, 3, a));
    let hess = want.hessian().is_some();
    let diff = difference;
    let point_point = |a: usize, b: usize, out: &mut Local| {
        kernels::point_point(sub(v[a], v[b]), hess).scatter(&[diff(a, b)], 4, 3, want, out)
    };
    // Point `p` against the line of the edge `[s, t]`.
    let point_line = |p: usize, s: usize, t: usize, out: &mut Local| {
        let (kernel, coef) = point_line(&v, p, s, t, hess);
        kernel.scatter(&coef, 4, 3, want, out)
    };
    match ty {
        A0B0 => point_point(0, 2, out),
        A0B1 => point_point(0, 3, out),
        A1B0 => point_point(1, 2, out),
        A1B1 => point_point(1, 3, out),
        AB0 => point_line(2, 0, 1, out),
        AB1 => point_line(3, 0, 1, out),
        A0B => point_line(0, 2, 3, out),
        A1B => point_line(1, 2, 3, out),
        AB => kernels::plane(sub(v[2], v[0]), sub(v[1], v[0]), sub(v[3], v[2]), hess).scatter(
            &[diff(2, 0), diff(1, 0), diff(3, 2)],
            4,
            3,
            want,
            out,
        ),
    }
}
