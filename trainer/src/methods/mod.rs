//! Every way of stepping a scene behind one interface ([`method::Method`]), and the methods
//! that are not the latent integrator of [`crate::learn`]: the reduced-order solver of Lyu et
//! al. 2024 ([`reduced`]), which solves the implicit-Euler problem (or the quasi-static one)
//! inside a subspace every step, the Lipschitz optimisation of its subspaces
//! ([`lipschitz`]), the simulator's own solvers and a coarser mesh ([`simulated`]), the
//! learned integrator as the runtime steps it ([`learned`]), and peers' recorded runs
//! ([`peer`]); [`clock`] is what they are all timed with.
pub mod clock;
pub mod learned;
pub mod lipschitz;
pub mod method;
pub mod peer;
pub mod reduced;
pub mod simulated;
