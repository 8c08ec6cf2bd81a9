//! mochi codegen: freezes a trained artifact into Rust `const` arrays consumed by
//! `mochi-runtime`. Filled in by the codegen issue; the crate exists so the workspace
//! layout matches the design.

/// Version of the artifact format this code generator reads.
pub const ARTIFACT_VERSION: u32 = 1;
