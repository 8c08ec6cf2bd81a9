//! The reduced-order solver (Lyu et al. 2024, Eq. 2): every step minimises
//! `E(z) = 1/(2 dt^2) |f(z) - xhat|_M^2 + P(f(z))` over the latent `z`, `f` a subspace map
//! (a decoder in the scene's boundary-condition frame) and `P` the scene's own energies.
//!
//! Files, in the order data flows: `decoder_map` (a trained decoder or a PCA's linear map, with
//! its derivatives), `subspace` (the decoder in the boundary-condition frame, with its exact
//! Jacobian), `objective` (Eq. 2 on the scene's energies), `optimize` (the
//! contract every optimiser solves, the exits it reports and the shared line search),
//! `lbfgs` (L-BFGS with a weak-Wolfe line search), `paper` (L-BFGS as the paper's code runs
//! it: cold, Armijo-only backtracking, in the paper's units), `newton` (Newton on the
//! PSD-projected reduced Hessian, Armijo backtracking), `stepper` (one solve per frame over a
//! boundary-condition script), `projection` (the closest state of a subspace to a given one,
//! for comparing subspaces), `rounding` (double precision, or single precision emulated).
pub mod decoder_map;
pub mod lbfgs;
pub mod method;
pub mod newton;
pub mod objective;
pub mod optimize;
pub mod paper;
pub mod projection;
pub mod rounding;
pub mod stepper;
pub mod subspace;

#[cfg(test)]
mod tests;
