//! mochi runtime: steps latent rollouts of a frozen model and decodes vertex positions.
//!
//! `#![no_std]` and allocation-free; every buffer is sized at compile time. The `std`
//! feature only adds desktop conveniences for tests.
#![no_std]

#[cfg(feature = "std")]
extern crate std;

/// Version of the artifact format this runtime understands.
pub const ARTIFACT_VERSION: u32 = 1;
