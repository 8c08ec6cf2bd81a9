//! Squared unsigned distances between contact primitives, their exact gradients and
//! Hessians, and the closest-feature classification that picks the formula.
//!
//! As in IPC, every distance here is the **squared** Euclidean distance (it is smooth where
//! the distance itself is not, and the barrier takes squared distances, see
//! [`crate::contact::barrier`]). Stencils are vertex-major local vectors as in
//! [`crate::energy`]: point-point `[p0, p1]`, point-edge `[p, e0, e1]` (2D or 3D),
//! point-triangle `[p, t0, t1, t2]` and edge-edge `[ea0, ea1, eb0, eb1]` (3D). Each
//! `*_distance` function classifies the closest features and evaluates the matching formula;
//! the `*_distance_typed` variants take the type (for a lagged or known classification).
//! Distance Hessians are always exact: a `Want::Hessian { project: true }` request is served
//! unprojected, as projection belongs to the energy built on the distance.

pub mod edge_edge;
pub mod kernels;
pub mod mollifier;
pub mod point_edge;
pub mod point_triangle;
pub mod reduced;

pub use edge_edge::{edge_edge_distance, edge_edge_distance_typed, edge_edge_type, EdgeEdgeType};
pub use mollifier::{edge_edge_mollifier, edge_edge_mollifier_threshold, mollifier, mollifier_derivatives};
pub use point_edge::{point_edge_distance, point_edge_distance_typed, point_edge_type, PointEdgeType};
pub use point_triangle::{
    point_triangle_distance, point_triangle_distance_typed, point_triangle_type, PointTriangleType,
};

use crate::energy::{Local, Want};
use reduced::{sub, vertex};

/// Squared distance between the points of `x = [p0, p1]` (`dim` 2 or 3), with gradient and
/// Hessian written into `out` as `want` asks.
pub fn point_point_distance(x: &[f64], dim: usize, want: Want, out: &mut Local) -> f64 {
    let r = sub(vertex(x, dim, 0), vertex(x, dim, 1));
    kernels::point_point(r, want.hessian().is_some()).scatter(&[[1.0, -1.0, 0.0, 0.0]], 2, dim, want, out)
}
