//! mochi runtime: steps latent rollouts of a frozen model and decodes vertex positions.
//!
//! `#![no_std]` and allocation-free; every buffer is sized at compile time. A [`Model`] is
//! static and shared (generated `const` arrays from `mochi-codegen`, or an artifact loaded from
//! bytes into a [`LoadedModel`]); each simulated object is an [`Instance`] holding only its
//! state. Bad input gets an error value, never a panic and never a NaN in the caller's buffer.
//!
//! ```ignore
//! let model = ValidModel::new(generated::MODEL)?;      // once, at start-up
//! let mut body = generated::Instance::new(&model)?;    // one per object
//! body.step(&model, &[HandleMotion::from_poses(&before, &now, generated::DT)])?;
//! body.decode_into(&model, &mut positions)?;           // or decode_surface_into
//! ```
//!
//! Every target computes the same bits for the same input (see [`network`]). The `std`
//! feature only adds desktop conveniences (`std::error::Error`, `Vec`-backed storage, the
//! run-time choice of the AVX2 kernel); `capi` adds the C ABI (module `capi`, no_std too).
#![no_std]
// Armv7E-M with an FPU (`armv7em` feature, `eabihf`): half-precision weights are converted by
// the FPU through the language's `f16` (`network/armv7em.rs`), still unstable; such builds
// use a toolchain that builds `core` anyway (`-Zbuild-std`).
#![cfg_attr(all(target_arch = "arm", feature = "armv7em", target_abi = "eabihf"), feature(f16))]

#[cfg(feature = "std")]
extern crate std;

pub mod aligned;
pub mod artifact;
#[cfg(feature = "capi")]
pub mod capi;
pub mod collider;
mod decode;
pub mod envelope;
mod fields;
#[allow(unsafe_code)]
mod finite;
pub mod frame;
pub mod instance;
pub mod model;
pub mod network;
#[cfg(feature = "std")]
pub mod payload;
pub mod pool;
pub mod render;
#[allow(unsafe_code)]
mod strand_lanes;
mod validation;
mod vertex_lists;

pub use aligned::Aligned;
#[cfg(feature = "std")]
pub use artifact::OwnedModel;
pub use artifact::{LoadError, LoadedModel, Storage, FORMAT_VERSION as ARTIFACT_VERSION};
pub use collider::{push_out, Collider, ColliderError};
pub use envelope::EnvelopeError;
pub use fields::FieldValue;
pub use frame::{ChainWalk, HandleMotion, HandlePose};
pub use instance::{
    AnyInstance, DecodeError, Instance, SizeError, StepError, Stepped, ValidModel, MAX_HIDDEN, MAX_LATENT, MAX_SIGNAL,
    RANGE_MARGIN,
};
pub use model::{
    column_stride, stores_columns, wide_stores_columns, Chain, Chains, Handle, Layer, Model, ModelError, Problem, Span,
    WeightFormat, Weights, COLUMNS_MAX, COLUMN_ROWS, HANDLE_SOURCE, SIGNAL_PER_HANDLE,
};
