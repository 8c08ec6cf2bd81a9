//! Edge-edge squared distance (3D) and its closest-feature classification.

use super::kernels;
use super::point_edge::{point_edge_type, PointEdgeType};
use super::reduced::{cross, dot, sub, vertex};
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

/// Edges whose squared cross-product norm is below this fraction of
/// `max(1, |a|^2 |b|^2)` are treated as parallel.
const PARALLEL_THRESHOLD: f64 = 1e-20;

/// Classifies `x = [ea0, ea1, eb0, eb1]`. The closest points of the two lines, at parameters
/// `s` on `a` and `t` on `b`, are clamped to the segments in turn (the classic
/// segment-segment algorithm): `s` first, then `t` for that `s`, then `s` again if `t` had to
/// be clamped. Degenerate (zero-length) edges fall back to their first endpoint; parallel
/// edges to [`parallel_type`].
pub fn edge_edge_type(x: &[f64]) -> EdgeEdgeType {
    use EdgeEdgeType::*;
    let v = [0, 1, 2, 3].map(|a| vertex(x, 3, a));
    let u = sub(v[1], v[0]);
    let w = sub(v[3], v[2]);
    let r = sub(v[0], v[2]);
    let (a, b, c, d, e) = (dot(u, u), dot(u, w), dot(w, w), dot(u, r), dot(w, r));
    let den = a * c - b * b;
    match (a == 0.0, c == 0.0) {
        (true, true) => return A0B0,
        (true, false) => return A0B,
        (false, true) => return AB0,
        _ => {}
    }
    let n = cross(u, w);
    if dot(n, n) < PARALLEL_THRESHOLD * (a * c).max(1.0) {
        return parallel_type(x);
    }
    // s = s_num / den on a; t = t_num / t_den on b.
    let s_num = b * e - c * d;
    let (t_num, t_den, interior) = if s_num <= 0.0 {
        (e, c, A0B)
    } else if s_num >= den {
        (e + b, c, A1B)
    } else {
        (a * e - b * d, den, AB)
    };
    if t_num <= 0.0 {
        // t = 0: closest point of a to eb0, at s = -d / a.
        if -d <= 0.0 {
            A0B0
        } else if -d >= a {
            A1B0
        } else {
            AB0
        }
    } else if t_num >= t_den {
        // t = 1: closest point of a to eb1, at s = (b - d) / a.
        if b - d <= 0.0 {
            A0B1
        } else if b - d >= a {
            A1B1
        } else {
            AB1
        }
    } else {
        interior
    }
}

/// Classification of parallel edges: the closest of the four endpoint-to-other-edge
/// distances (an endpoint always attains the minimum for parallel segments).
pub fn parallel_type(x: &[f64]) -> EdgeEdgeType {
    use EdgeEdgeType::*;
    let v = [0, 1, 2, 3].map(|a| vertex(x, 3, a));
    // (point, edge start, edge end, type if interior, type at edge start, type at edge end)
    let cases = [
        (2, 0, 1, AB0, A0B0, A1B0),
        (3, 0, 1, AB1, A0B1, A1B1),
        (0, 2, 3, A0B, A0B0, A0B1),
        (1, 2, 3, A1B, A1B0, A1B1),
    ];
    let mut best = (f64::INFINITY, AB);
    let mut out = Local::default();
    for (p, s, t, interior, at_s, at_t) in cases {
        let mut local = [0.0; 9];
        for (k, a) in [p, s, t].into_iter().enumerate() {
            local[3 * k..3 * k + 3].copy_from_slice(&v[a]);
        }
        let ty = point_edge_type(&local, 3);
        let d = super::point_edge_distance_typed(&local, 3, ty, Want::Value, &mut out);
        let ee = match ty {
            PointEdgeType::E0 => at_s,
            PointEdgeType::E1 => at_t,
            PointEdgeType::Interior => interior,
        };
        if d < best.0 {
            best = (d, ee);
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
    let diff = |a: usize, b: usize| {
        let mut c = [0.0; 4];
        c[a] = 1.0;
        c[b] = -1.0;
        c
    };
    let point_point = |a: usize, b: usize, out: &mut Local| {
        kernels::point_point(sub(v[a], v[b]), hess).scatter(&[diff(a, b)], 4, 3, want, out)
    };
    // Point `p` against the line of the edge `[s, t]`.
    let point_line = |p: usize, s: usize, t: usize, out: &mut Local| {
        kernels::point_line(sub(v[p], v[s]), sub(v[t], v[s]), hess).scatter(&[diff(p, s), diff(t, s)], 4, 3, want, out)
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
