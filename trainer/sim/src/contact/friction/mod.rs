//! Building blocks of IPC's lagged, smoothed Coulomb friction (Li et al. 2020, Sec. 5).
//!
//! Per contact stencil, friction is lagged over one Newton solve: the tangent basis `T`, the
//! closest-point coordinates (which weight the vertices' velocities into the relative
//! velocity, `Gamma`) and the normal force `N` are computed once from the lagged positions;
//! the potential `D = mu N f0(|T^T Gamma v|)` is then a smooth function of the stencil's
//! velocities (or displacements) `v`, with `f0` the smoothed magnitude of
//! [`smoothing`].

pub mod closest_point;
pub mod potential;
pub mod smoothing;
pub mod tangent_basis;

pub use closest_point::{
    edge_edge_closest_point, point_edge_closest_point, point_triangle_closest_point, RelativeVelocity,
};
pub use potential::FrictionStencil;
pub use smoothing::{f0, f1, f1_over_x, f2, f2_x_minus_f1_over_x3};
pub use tangent_basis::{
    edge_edge_tangent_basis, point_edge_tangent_basis, point_point_tangent_basis, point_triangle_tangent_basis,
    TangentBasis,
};
