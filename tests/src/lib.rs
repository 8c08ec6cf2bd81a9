//! Shared helpers of the workspace integration tests: models generated from the committed
//! artifacts by `build.rs`.

pub use mochi_trainer::runtime_bench::motions;

/// Generated from `artifacts/tiny.mochi`.
pub mod tiny {
    include!(concat!(env!("OUT_DIR"), "/tiny.rs"));
}

/// Generated from `artifacts/beam.mochi` (the shipped beam scene's self-supervised model).
pub mod beam {
    include!(concat!(env!("OUT_DIR"), "/beam.rs"));
}
