//! The adaptive subspace simulator of Trusty, Fei, Levin and Kaufman: each time step is
//! solved in a running reduced model made of an adaptive set of subspace modes and enriched
//! vertices, on top of the full-space state.
//!
//! This module holds its linear algebra and its fixed decomposition: the mesh partition
//! into subdomains (`partition`), the per-subdomain BFGS approximations of the elastic
//! subspace Hessian (`bfgs`), the Schur-complement solver of the Newton-iterate system
//! (`schur`, on conjugate gradients in `pcg`), and the full-space baselines it is compared
//! with (`full_space`).

pub mod bfgs;
pub mod full_space;
mod lower_csc;
pub mod partition;
pub mod pcg;
pub mod schur;
pub mod solve_error;

pub use solve_error::SolveError;

#[cfg(test)]
mod tests;
