//! Shared helpers of the workspace integration tests: models generated from the committed
//! artifacts by `build.rs`.

pub use mochi_trainer::eval::rollout::{collider_states, motions};

/// Generated from `artifacts/tiny.mochi`.
pub mod tiny {
    include!(concat!(env!("OUT_DIR"), "/tiny.rs"));
}

/// Generated from `artifacts/tiny-render.mochi` (`tiny` with a render mesh: its box's surface,
/// 12 quads a side on every face, riding on its tets).
pub mod tiny_render {
    include!(concat!(env!("OUT_DIR"), "/tiny_render.rs"));
}

/// Generated from `artifacts/tiny-render.mochi` with int8 weights (the integrator in `f16`).
pub mod tiny_render_int8 {
    include!(concat!(env!("OUT_DIR"), "/tiny_render_int8.rs"));
}

/// Generated from `artifacts/beam.mochi` (the shipped beam scene's self-supervised model).
pub mod beam {
    include!(concat!(env!("OUT_DIR"), "/beam.rs"));
}

/// Generated from `artifacts/beam-m8.mochi` (the right-sized beam: beam's integrator with its
/// decoder distilled into 8 modes).
pub mod beam_m8 {
    include!(concat!(env!("OUT_DIR"), "/beam_m8.rs"));
}

/// Generated from `artifacts/beam-m8.mochi` with int8 weights (the integrator in `f16`).
pub mod beam_m8_int8 {
    include!(concat!(env!("OUT_DIR"), "/beam_m8_int8.rs"));
}

/// Generated from `artifacts/rods.mochi` (the `rods` scene's model as `mochi train` selects
/// it: 16 strands of 30 vertices encoded by their bends, a linear decoder).
pub mod rods {
    include!(concat!(env!("OUT_DIR"), "/rods.rs"));
}

/// Generated from `artifacts/rods-m8.mochi` (the right-sized rods: `rods.mochi`'s integrator
/// with its strands decoded as positions by a basis of 8 modes).
pub mod rods_m8 {
    include!(concat!(env!("OUT_DIR"), "/rods_m8.rs"));
}

/// Generated from `artifacts/strands.mochi` (four rods encoded by their bends).
pub mod strands {
    include!(concat!(env!("OUT_DIR"), "/strands.rs"));
}

/// Generated from `artifacts/tiny.mochi` with `f16` weights.
pub mod tiny_f16 {
    include!(concat!(env!("OUT_DIR"), "/tiny_f16.rs"));
}

/// Generated from `artifacts/tiny.mochi` with int8 weights (the integrator in `f16`).
pub mod tiny_int8 {
    include!(concat!(env!("OUT_DIR"), "/tiny_int8.rs"));
}

/// Generated from `artifacts/beam.mochi` with int8 weights (the integrator in `f16`).
pub mod beam_int8 {
    include!(concat!(env!("OUT_DIR"), "/beam_int8.rs"));
}

/// Generated from `artifacts/tiny-poke.mochi` (a small block pressed by a moving ball: one
/// run-time collider slot).
pub mod tiny_poke {
    include!(concat!(env!("OUT_DIR"), "/tiny_poke.rs"));
}

/// Generated from `artifacts/tiny-poke.mochi` with int8 weights (the integrator in `f16`).
pub mod tiny_poke_int8 {
    include!(concat!(env!("OUT_DIR"), "/tiny_poke_int8.rs"));
}
