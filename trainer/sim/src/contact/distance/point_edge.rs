//! Point-edge squared distance (2D and 3D) and its closest-feature classification.

use super::kernels;
use super::reduced::{dot, sub, vertex};
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
/// point on the edge's line: `t < 0` is `E0`, `t > 1` is `E1`, otherwise the interior.
pub fn point_edge_type(x: &[f64], dim: usize) -> PointEdgeType {
    let (p, e0, e1) = (vertex(x, dim, 0), vertex(x, dim, 1), vertex(x, dim, 2));
    let e = sub(e1, e0);
    let t = dot(sub(p, e0), e) / dot(e, e);
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
        PointEdgeType::Interior => kernels::point_line(sub(p, e0), sub(e1, e0), hess).scatter(
            &[[1.0, -1.0, 0.0, 0.0], [0.0, -1.0, 1.0, 0.0]],
            3,
            dim,
            want,
            out,
        ),
    }
}
