//! The integrator's collider inputs on the trainer's side: each collider slot's state at a
//! frame, seen from the body's encoding frame (rotation `R`, origin the centroid of the
//! handle targets). The numbers come from the runtime's `collider::features`, the one
//! definition of the layout (docs/design.md, decision 11), so a model trained here reads the
//! same inputs on every target.

use mochi_runtime::collider::{features, ColliderState, FEATURES_PER_COLLIDER};
use mochi_sim::bc::colliders::STATE_PER_COLLIDER;
use nalgebra::{Matrix3, Vector3};

use super::frame::{centroid, Frame};

/// The collider inputs of one frame: [`FEATURES_PER_COLLIDER`] numbers for each of `slots`
/// slots, from `states` (a trajectory's `collider_states` row: [`STATE_PER_COLLIDER`]
/// numbers per collider, the scene's order) in the encoding frame `frame` of the handle
/// targets `targets` (`dim` numbers per handle vertex). A slot without a state reads as
/// absent; `diagonal` is the body's rest bounding-box diagonal.
pub fn collider_inputs(
    slots: usize,
    frame: &Frame,
    targets: &[f64],
    dim: usize,
    diagonal: f64,
    states: &[f64],
) -> Vec<f32> {
    if slots == 0 {
        return Vec::new();
    }
    let rotation: Matrix3<f32> = frame.rotation.map(|v| v as f32);
    let origin: Vector3<f32> = centroid(targets, dim).map(|v| v as f32);
    let mut out = Vec::with_capacity(slots * FEATURES_PER_COLLIDER);
    for slot in 0..slots {
        let state = states
            .get(slot * STATE_PER_COLLIDER..(slot + 1) * STATE_PER_COLLIDER)
            .map(collider_state);
        out.extend(features(&rotation, &origin, diagonal as f32, state.as_ref()));
    }
    out
}

/// The runtime's [`ColliderState`] of one collider's [`STATE_PER_COLLIDER`] numbers.
pub fn collider_state(s: &[f64]) -> ColliderState {
    let three = |i: usize| [s[i] as f32, s[i + 1] as f32, s[i + 2] as f32];
    ColliderState {
        center: three(0),
        rotation: three(3),
        linear_velocity: three(6),
        angular_velocity: three(9),
    }
}
