//! Learning a latent space and an integrator for a scene (Li et al. 2025): states encoded
//! relative to their boundary conditions, PCA, candle networks, the physics loss on the
//! simulator's own energies, the training loop, and `mochi train`'s recipe and stages.

pub mod encoding;
pub mod latent;
pub mod loss;
pub mod network;
pub mod pca;
pub mod recipe;
pub mod stretch;
pub mod train;
