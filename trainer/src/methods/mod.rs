//! Ways of stepping a body in a learned subspace other than the latent integrator of
//! [`crate::learn`]: the reduced-order solver of Lyu et al. 2024 ([`reduced`]), which solves
//! the implicit-Euler problem (or the quasi-static one) inside a subspace every step, and the
//! Lipschitz optimisation of its subspaces ([`lipschitz`]).
pub mod lipschitz;
pub mod reduced;
