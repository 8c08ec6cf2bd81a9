//! Lipschitz-optimised subspaces (Lyu et al. 2024, Sec. 4): the second-order Lipschitz loss
//! of the subspace Hessian of the potential (Eq. 9), its gradient in the decoder's weights,
//! and the estimate of `Lip[d^2 P / dz^2]` reported for every subspace (Eq. 7).
//!
//! Files: `physics` (the potential's gradient, Hessian products and third derivative at a
//! decoded state, from the stencil kernels), `loss` (Eq. 9, its surrogate for candle, Eq. 7),
//! `cubature` (the element subset and weights that stand in for the elastic energy, fitted
//! on the vanilla subspace), `train` (Eq. 10 for a supervised subspace, on the trainer's
//! training loop).
pub mod cubature;
pub mod loss;
pub(crate) mod physics;
pub mod train;

#[cfg(test)]
mod tests;
