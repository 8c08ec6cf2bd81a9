//! Static library for C and C++ engines: the runtime's C ABI (`mochi_instance_*`, see
//! `include/mochi.h`) with one generated model (`mochi_model_tiny`), the same with a render
//! mesh (`mochi_model_tiny_render`), a model with a collider slot (`mochi_model_tiny_poke`),
//! and the reference boundary-condition script every target runs (`mochi_reference_motion`,
//! `mochi_reference_poke`), so that the C program in `main.c` can check its positions against
//! the host's.

use std::sync::OnceLock;

use mochi_runtime::capi::{MochiModel, MochiStatus};
use mochi_runtime::collider::ColliderState;
use mochi_runtime::HandleMotion;
use mochi_target_common::Script;

/// The generated model (see build.rs).
#[allow(missing_docs)]
pub mod model {
    include!(concat!(env!("OUT_DIR"), "/model.rs"));
}

/// The generated model with a render mesh (`tests/artifacts/tiny-render.mochi`, see build.rs).
#[allow(missing_docs)]
pub mod render_model {
    include!(concat!(env!("OUT_DIR"), "/render_model.rs"));
}

/// The generated model with one collider slot (`tests/artifacts/tiny-poke.mochi`, see build.rs).
#[allow(missing_docs)]
pub mod poke_model {
    include!(concat!(env!("OUT_DIR"), "/poke_model.rs"));
}

/// The C header, as cbindgen generated it for this build.
pub const HEADER: &str = include_str!(concat!(env!("OUT_DIR"), "/mochi.h"));

/// The model, validated on first use.
fn validated() -> Option<&'static MochiModel> {
    static MODEL: OnceLock<Option<MochiModel>> = OnceLock::new();
    MODEL.get_or_init(|| MochiModel::new(model::MODEL).ok()).as_ref()
}

/// The generated model, or null if it failed validation (it cannot, unless the generated
/// code was edited).
#[no_mangle] // exported under a fixed name: the lint counts that as unsafe code
#[allow(unsafe_code)]
pub extern "C" fn mochi_model_tiny() -> *const MochiModel {
    validated().map_or(core::ptr::null(), |m| m as *const MochiModel)
}

/// The generated model with a render mesh (`tiny` with its box's surface riding on its tets),
/// or null if it failed validation.
#[no_mangle] // exported under a fixed name: the lint counts that as unsafe code
#[allow(unsafe_code)]
pub extern "C" fn mochi_model_tiny_render() -> *const MochiModel {
    static MODEL: OnceLock<Option<MochiModel>> = OnceLock::new();
    let model = MODEL.get_or_init(|| MochiModel::new(render_model::MODEL).ok()).as_ref();
    model.map_or(core::ptr::null(), |m| m as *const MochiModel)
}

/// The motion every handle of the generated model makes over the step that ends at `frame` in
/// the reference script (`mochi-target-common`), written to `out`.
///
/// # Safety
/// `out` must be null or writable.
#[no_mangle]
#[allow(unsafe_code)]
pub unsafe extern "C" fn mochi_reference_motion(frame: u32, out: *mut HandleMotion) -> MochiStatus {
    // SAFETY: null or writable (the function's contract).
    let Some(out) = (unsafe { out.as_mut() }) else {
        return MochiStatus::NullPointer;
    };
    let m = &model::MODEL;
    *out = Script::new(m.rest(), m.dim(), m.dt).motion(frame);
    MochiStatus::Ok
}

/// The generated model with one run-time collider slot (`tiny-poke`: a ball pressed into a
/// small block), or null if it failed validation.
#[no_mangle] // exported under a fixed name: the lint counts that as unsafe code
#[allow(unsafe_code)]
pub extern "C" fn mochi_model_tiny_poke() -> *const MochiModel {
    static MODEL: OnceLock<Option<MochiModel>> = OnceLock::new();
    let model = MODEL.get_or_init(|| MochiModel::new(poke_model::MODEL).ok()).as_ref();
    model.map_or(core::ptr::null(), |m| m as *const MochiModel)
}

/// Frame `frame` of the reference script for `mochi_model_tiny_poke`: every handle's motion
/// into `motion` and its collider slot's state (the ball circling the body's top) into
/// `collider`.
///
/// # Safety
/// `motion` and `collider` must each be null or writable.
#[no_mangle]
#[allow(unsafe_code)]
pub unsafe extern "C" fn mochi_reference_poke(
    frame: u32,
    motion: *mut HandleMotion,
    collider: *mut ColliderState,
) -> MochiStatus {
    // SAFETY: null or writable (the function's contract).
    let (Some(motion), Some(collider)) = (unsafe { motion.as_mut() }, unsafe { collider.as_mut() }) else {
        return MochiStatus::NullPointer;
    };
    let m = &poke_model::MODEL;
    let script = Script::new(m.rest(), m.dim(), m.dt);
    *motion = script.motion(frame);
    *collider = script.collider(frame, 0, m.colliders());
    MochiStatus::Ok
}
