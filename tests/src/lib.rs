//! Shared helpers of the workspace integration tests: models generated from the committed
//! artifacts by `build.rs`, and the runtime rollout the agreement tests compare with the
//! trainer's.

use mochi_runtime::{Instance, Stepped, ValidModel};
use mochi_trainer::bc::BcSequence;
pub use mochi_trainer::runtime_bench::motions;

/// Generated from `artifacts/tiny.mochi`.
pub mod tiny {
    include!(concat!(env!("OUT_DIR"), "/tiny.rs"));
}

/// Generated from `artifacts/beam.mochi` (the shipped beam scene's self-supervised model).
pub mod beam {
    include!(concat!(env!("OUT_DIR"), "/beam.rs"));
}

/// Rolls `model` out over `bc` in the runtime for `frames` frames, calling
/// `visit(t, status, z_t, x_t)` with what the step did, the latent and the decoded world state.
pub fn runtime_rollout<const K: usize, const S: usize, const H: usize>(
    model: &ValidModel,
    bc: &BcSequence,
    frames: usize,
    mut visit: impl FnMut(usize, Stepped, &[f32], &[f32]),
) -> anyhow::Result<()> {
    let mut body = Instance::<K, S, H>::new(model)?;
    let mut x = vec![0.0f32; model.model().state_len()];
    for t in 1..=frames {
        let status = body.step(model, &motions(bc, t))?;
        body.decode_into(model, &mut x)?;
        visit(t, status, body.latent(), &x);
    }
    Ok(())
}
