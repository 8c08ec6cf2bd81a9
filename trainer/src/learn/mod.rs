//! Learning a latent space and an integrator for a scene (Li et al. 2025): states encoded
//! relative to their boundary conditions, PCA, candle networks, the physics loss on the
//! simulator's own energies, the training loop, and `mochi train`'s recipe and stages.
//!
//! `mochi train` is [`pipeline::train_scene`]: the stages of `stages.rs` in order, on the
//! encoded training split ([`sequences`]) and the integrator's samples (`samples.rs`), with
//! the self-supervised objective of `integrator.rs` and the baseline's of `supervised.rs`;
//! `build.rs` assembles the artifact.

pub(crate) mod build;
pub mod encoding;
pub(crate) mod integrator;
pub mod loss;
pub mod network;
pub mod pca;
pub mod pipeline;
pub mod recipe;
pub(crate) mod samples;
pub mod sequences;
pub(crate) mod stages;
pub(crate) mod stretch;
pub(crate) mod supervised;
pub(crate) mod train;

pub use samples::pack;
