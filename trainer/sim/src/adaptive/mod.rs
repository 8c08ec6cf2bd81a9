//! Adaptive subspace simulation (Trusty, Fei, Levin and Kaufman): each time-step solve runs
//! in a small reduced model that adapts inside the step, made of subspace modes drawn from
//! a larger candidate set and of enriched vertices, updated and downdated by error and
//! progress measures, while the full positions stay the primary state.
//!
//! Built so far:
//! - [`candidates`]: the candidate bases of a body (rigid, affine and linear modes of the
//!   rest shape) grouped into the blocks the adaptivity queries one at a time;
//! - [`partition`]: the fixed decomposition of the mesh into subdomains (nodal groups and
//!   BFGS integration domains);
//! - [`oracle`]: the error and progress measures of vertices, modes and mode blocks, and
//!   the decision which candidates to activate;
//! - [`bfgs`]: the per-subdomain BFGS approximations of the elastic subspace Hessian;
//! - [`schur`]: the Schur-complement solver of the Newton-iterate system (on conjugate
//!   gradients in [`pcg`]), and [`full_space`], the baselines it is compared with;
//! - [`step`]: one implicit-Euler step in a given active model (Newton with the exact
//!   subspace Hessian, no BFGS, no contact, no activation inside the step).

pub mod bfgs;
pub mod candidates;
pub mod full_space;
mod lower_csc;
pub mod oracle;
pub mod partition;
pub mod pcg;
pub mod schur;
pub mod solve_error;
pub mod step;

pub use solve_error::SolveError;

#[cfg(test)]
mod tests;
