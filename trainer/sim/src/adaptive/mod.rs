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
//! - [`model`]: the active model and the bases it spans;
//! - [`solver`]: the model inside the full-space simulator's Newton loop: the oracle's
//!   update at each iterate, the model's system, downdating after each step
//!   ([`crate::solver::Simulator::with_adaptive`]);
//! - [`system`]: the model's Newton system and the timing of its three solvers;
//! - [`settings`]: the thresholds and sizes a scene's `[solver]` table sets.

pub mod bfgs;
pub mod candidates;
pub mod elastic_subspace;
pub mod full_space;
mod lower_csc;
pub mod model;
pub mod oracle;
pub mod partition;
pub mod pcg;
pub mod schur;
pub mod settings;
pub mod solve_error;
pub mod solver;
pub mod system;
mod vertex_blocks;

pub use model::ActiveModel;
pub use settings::{AdaptiveSettings, SubspaceHessian};
pub use solve_error::SolveError;
pub use solver::{AdaptiveSolver, AdaptiveStepStats};
pub use system::LinearSolverTimings;

#[cfg(test)]
mod tests;
