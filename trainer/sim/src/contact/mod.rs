//! IPC-style contact primitives (Li et al. 2020; `docs/design.md`, decision 8): squared
//! distances between points, edges and triangles with their exact derivatives and
//! closest-feature classification, the edge-edge mollifier, the log barrier on squared
//! distances with its adaptive stiffness, the building blocks of lagged smoothed friction,
//! the contact surface of a mesh, the broad phase that finds candidate pairs, continuous
//! collision detection that bounds every step, an exact intersection check, and analytic
//! kinematic colliders (spheres, capsules, boxes) with their barrier and step bound.
//!
//! Conventions follow IPC's toolkit (squared distances, `b(d^2, dhat^2)`, tangent bases and
//! closest-point coordinates) so every quantity compares with it one to one
//! (`scripts/check-ipctk.sh`). Local vectors are vertex-major as in [`crate::energy`].

pub mod barrier;
pub mod barrier_potential;
pub mod broad_phase;
pub mod ccd;
pub mod collider;
pub mod collider_barrier;
pub mod collider_ccd;
pub mod collider_friction;
pub mod distance;
pub mod friction;
pub mod friction_potential;
pub mod intersection;
pub mod stiffness;
pub mod surface;

#[cfg(test)]
mod tests;

pub use barrier::{barrier, barrier_first_derivative, barrier_second_derivative};
pub use collider::{Collider, ColliderPose, ColliderShape};
pub use collider_barrier::ColliderBarrier;
pub use surface::ContactSurface;
