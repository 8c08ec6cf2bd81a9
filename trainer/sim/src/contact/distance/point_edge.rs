//! Point-edge squared distance (2D and 3D) and its closest-feature classification.

use super::kernels;
use super::reduced::{difference, dot, sub, vertex, Reduced};
use crate::energy::{Local, Want};

/// Which features of the edge `[e0, e1]` are closest to the point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PointEdgeType {
    /// The endpoint `e0`.
    E0,
    /// The endpoint `e1`.
    E1,
    /// The edge's interior (distance to its line).
    Interior,
}

/// Classifies `x = [p, e0, e1]` by the projection parameter `t = (p - e0).e / e.e` of the
/// point on the edge's line: `t < 0` is `E0`, `t > 1` is `E1`, otherwise the interior. A
/// zero-length edge is its one point, `E0`.
pub fn point_edge_type(x: &[f64], dim: usize) -> PointEdgeType {
    let (p, e0, e1) = (vertex(x, dim, 0), vertex(x, dim, 1), vertex(x, dim, 2));
    let e = sub(e1, e0);
    let c = dot(e, e);
    if c == 0.0 {
        return PointEdgeType::E0;
    }
    let t = dot(sub(p, e0), e) / c;
    if t < 0.0 {
        PointEdgeType::E0
    } else if t > 1.0 {
        PointEdgeType::E1
    } else {
        PointEdgeType::Interior
    }
}

/// Squared distance from `p` to the edge of `x = [p, e0, e1]`, classified by
/// [`point_edge_type`].
pub fn point_edge_distance(x: &[f64], dim: usize, want: Want, out: &mut Local) -> f64 {
    point_edge_distance_typed(x, dim, point_edge_type(x, dim), want, out)
}

/// As [`point_edge_distance`] with the closest features given.
pub fn point_edge_distance_typed(x: &[f64], dim: usize, ty: PointEdgeType, want: Want, out: &mut Local) -> f64 {
    let (p, e0, e1) = (vertex(x, dim, 0), vertex(x, dim, 1), vertex(x, dim, 2));
    let hess = want.hessian().is_some();
    match ty {
        PointEdgeType::E0 => {
            kernels::point_point(sub(p, e0), hess).scatter(&[[1.0, -1.0, 0.0, 0.0]], 3, dim, want, out)
        }
        PointEdgeType::E1 => {
            kernels::point_point(sub(p, e1), hess).scatter(&[[1.0, 0.0, -1.0, 0.0]], 3, dim, want, out)
        }
        PointEdgeType::Interior => {
            let (kernel, coef) = point_line(&[p, e0, e1], 0, 1, 2, hess);
            kernel.scatter(&coef, 3, dim, want, out)
        }
    }
}

/// The squared distance from vertex `p` of a stencil (vertices `v`) to the line of its edge
/// `[s, t]`, as [`kernels::point_line`] with `r` taken from the endpoint nearer `p` (from
/// the farther one, `r x e` would cancel near the nearer end), and the coefficients of its
/// reduced vectors `r` and `e` over the stencil's vertices.
pub(super) fn point_line(v: &[[f64; 3]], p: usize, s: usize, t: usize, hessian: bool) -> (Reduced, [[f64; 4]; 2]) {
    let (rs, rt) = (sub(v[p], v[s]), sub(v[p], v[t]));
    let near = if dot(rt, rt) < dot(rs, rs) { t } else { s };
    let kernel = kernels::point_line(sub(v[p], v[near]), sub(v[t], v[s]), hessian);
    (kernel, [difference(p, near), difference(t, s)])
}

/// Vertex `p` of the 3D stencil `x` against the stencil's edge `[s, t]`: the squared
/// distance and the closest feature, named from `names` as `[at s, at t, in the interior]`
/// (how edge-edge and degenerate point-triangle pairs reduce to their sub-primitives).
pub(super) fn sub_point_edge<T: Copy>(x: &[f64], [p, s, t]: [usize; 3], names: [T; 3]) -> (f64, T) {
    let mut local = [0.0; 9];
    for (k, a) in [p, s, t].into_iter().enumerate() {
        local[3 * k..3 * k + 3].copy_from_slice(&x[3 * a..3 * a + 3]);
    }
    let ty = point_edge_type(&local, 3);
    let d = point_edge_distance_typed(&local, 3, ty, Want::Value, &mut Local::default());
    let name = match ty {
        PointEdgeType::E0 => names[0],
        PointEdgeType::E1 => names[1],
        PointEdgeType::Interior => names[2],
    };
    (d, name)
}
