//! mochi trainer: full-space finite-element simulation, datasets, training and evaluation.

pub mod artifact;
pub mod bc;
pub mod chart;
pub mod dataset;
pub mod demo;
pub mod encoding;
pub mod energy;
pub mod error;
pub mod eval;
pub mod framing;
pub mod latent;
pub mod loss;
pub mod material;
pub mod mesh;
pub mod model;
pub mod pca;
pub mod render;
pub mod runtime_bench;
pub mod scene;
pub mod solver;
pub mod storage;
pub mod stretch;
pub mod train;
pub mod trajectory;

pub use error::{InputError, Location};
