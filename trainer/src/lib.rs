//! mochi trainer: full-space finite-element simulation, datasets, training and evaluation.

pub mod bc;
pub mod dataset;
pub mod energy;
pub mod error;
pub mod material;
pub mod scene;
pub mod mesh;
pub mod solver;

pub use error::{InputError, Location};
