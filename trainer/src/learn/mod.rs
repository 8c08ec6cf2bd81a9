//! Learning a latent space and an integrator for a scene (Li et al. 2025): the recipe
//! (`[latent]`), states encoded relative to their boundary conditions, PCA, candle networks,
//! the physics loss on the simulator's own energies, the encoded training split
//! ([`sequences`]), the integrator's samples (`samples.rs`), the self-supervised objective
//! (`integrator.rs`), the baseline's (`supervised.rs`) and the training loop (`train/`).
//! `mochi train` runs them as stages in [`crate::pipeline`].

pub mod datafree;
pub mod distill;
pub mod distill_integrator;
pub mod encoding;
pub mod frame_rows;
pub(crate) mod integrator;
pub mod loss;
pub mod network;
pub mod pca;
pub mod pca_streamed;
pub mod recipe;
pub mod reduced_spec;
pub(crate) mod samples;
pub mod sequences;
pub(crate) mod stretch;
pub(crate) mod supervised;
pub(crate) mod train;

pub use samples::pack;
