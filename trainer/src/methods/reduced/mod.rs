//! The reduced-order solver (Lyu et al. 2024, Eq. 2): every step minimises
//! `E(z) = 1/(2 dt^2) |f(z) - xhat|_M^2 + P(f(z))` over the latent `z`, `f` a subspace map
//! (a decoder in the scene's boundary-condition frame) and `P` the scene's own energies.
//!
//! Files: `optimize` (the objective contract and the exits every solver reports), `lbfgs`
//! (L-BFGS with line search), `newton` (Newton on the PSD-projected reduced Hessian).
pub mod lbfgs;
pub mod newton;
pub mod optimize;
