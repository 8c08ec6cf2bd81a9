//! A wasm32 module around one generated model, with a small C-like API (numbers and pointers
//! into the module's memory only) for JavaScript: one interactive object driven by a handle
//! pose, and the reference run every target makes (`mochi-target-common`), whose checksums
//! must equal the host runtime's.
//!
//! No allocation: the object, its positions and the checkpoints live in statics. A wasm module
//! runs on one thread, so the exported functions are never re-entered.
#![no_std]

use core::ptr::addr_of_mut;

use mochi_runtime::{HandleMotion, HandlePose, ValidModel};
use mochi_target_common::{run, CHECKPOINTS};

#[allow(dead_code, missing_docs)]
mod model {
    include!(concat!(env!("OUT_DIR"), "/model.rs"));
}

/// Status codes: 0 ok, 1 clamped, 2 held; negative: refused.
const OK: i32 = 0;
const NOT_INITIALISED: i32 = -1;
const INVALID_MODEL: i32 = -2;
const STEP_REFUSED: i32 = -3;
const DECODE_REFUSED: i32 = -4;

/// The interactive object and the module's buffers.
struct State {
    model: Option<ValidModel<'static>>,
    body: Option<model::Instance>,
    pose: HandlePose,
    positions: [f32; model::STATE_LEN],
    checksums: [u64; CHECKPOINTS.len()],
}

static mut STATE: State = State {
    model: None,
    body: None,
    pose: HandlePose {
        translation: [0.0; 3],
        rotation: [0.0; 3],
    },
    positions: [0.0; model::STATE_LEN],
    checksums: [0; CHECKPOINTS.len()],
};

/// The module's state.
fn state() -> &'static mut State {
    // SAFETY: wasm32-unknown-unknown runs one thread and the exports do not call each other,
    // so at most one reference to STATE exists at a time.
    unsafe { &mut *addr_of_mut!(STATE) }
}

/// Validates the model and puts the object at rest (positions = rest shape). 0 on success.
#[no_mangle]
pub extern "C" fn mochi_init() -> i32 {
    let s = state();
    let Ok(model) = ValidModel::new(model::MODEL) else {
        return INVALID_MODEL;
    };
    s.model = Some(model);
    mochi_reset()
}

/// Puts the object back at rest with its handle at the reference pose.
#[no_mangle]
pub extern "C" fn mochi_reset() -> i32 {
    let s = state();
    let Some(model) = s.model.as_ref() else {
        return NOT_INITIALISED;
    };
    s.body = model::Instance::new(model).ok();
    s.pose = HandlePose::default();
    s.positions.copy_from_slice(model.model().rest());
    OK
}

/// Vertices of the model.
#[no_mangle]
pub extern "C" fn mochi_vertex_count() -> u32 {
    model::NUM_VERTICES as u32
}

/// Coordinates per vertex.
#[no_mangle]
pub extern "C" fn mochi_dim() -> u32 {
    model::DIM as u32
}

/// Time step in seconds.
#[no_mangle]
pub extern "C" fn mochi_dt() -> f32 {
    model::DT
}

/// Rest bounding-box diagonal.
#[no_mangle]
pub extern "C" fn mochi_diagonal() -> f32 {
    model::MODEL.diagonal
}

/// The current positions (`vertex_count * dim` floats in the module's memory).
#[no_mangle]
pub extern "C" fn mochi_positions() -> *const f32 {
    state().positions.as_ptr()
}

/// The rest positions (`vertex_count * dim` floats).
#[no_mangle]
pub extern "C" fn mochi_rest() -> *const f32 {
    model::MODEL.rest().as_ptr()
}

/// Moves every handle to the pose `(t, r)` (translation, rotation vector) over one frame and
/// steps and decodes the object; the velocities come from the previous pose. Returns 0 (ok),
/// 1 (latent clamped to the trained range), 2 (held), or a negative code when refused (a
/// non-finite pose; the object is unchanged).
#[no_mangle]
pub extern "C" fn mochi_step_pose(tx: f32, ty: f32, tz: f32, rx: f32, ry: f32, rz: f32) -> i32 {
    let s = state();
    let (Some(model), Some(body)) = (s.model.as_ref(), s.body.as_mut()) else {
        return NOT_INITIALISED;
    };
    let pose = HandlePose {
        translation: [tx, ty, tz],
        rotation: [rx, ry, rz],
    };
    let bc = [HandleMotion::from_poses(&s.pose, &pose, model::DT); model::HANDLES];
    let status = match body.step(model, &bc) {
        Ok(stepped) => stepped as i32,
        Err(_) => return STEP_REFUSED,
    };
    s.pose = pose;
    match body.decode_into(model, &mut s.positions) {
        Ok(()) => status,
        Err(_) => DECODE_REFUSED,
    }
}

/// Runs the reference script for `frames` frames from rest (a separate object), recording
/// the checksum at each checkpoint frame it reaches; the final positions are left in
/// `mochi_positions`. 0 on success.
#[no_mangle]
pub extern "C" fn mochi_reference_run(frames: u32) -> i32 {
    let s = state();
    let Some(model) = s.model.as_ref() else {
        return NOT_INITIALISED;
    };
    let checksums = &mut s.checksums;
    let result = run::<{ model::LATENT }, { model::SIGNAL }, { model::HIDDEN }>(
        model,
        frames,
        &mut s.positions,
        |frame, sum, _| {
            if let Some(i) = CHECKPOINTS.iter().position(|&c| c == frame) {
                checksums[i] = sum.0;
            }
        },
    );
    match result {
        Ok(_) => OK,
        Err(_) => STEP_REFUSED,
    }
}

/// Checkpoints of the reference run.
#[no_mangle]
pub extern "C" fn mochi_checkpoint_count() -> u32 {
    CHECKPOINTS.len() as u32
}

/// Frame of checkpoint `i` (0 when out of range).
#[no_mangle]
pub extern "C" fn mochi_checkpoint_frame(i: u32) -> u32 {
    CHECKPOINTS.get(i as usize).copied().unwrap_or(0)
}

/// High 32 bits of the checksum at checkpoint `i`.
#[no_mangle]
pub extern "C" fn mochi_checkpoint_hi(i: u32) -> u32 {
    (state().checksums.get(i as usize).copied().unwrap_or(0) >> 32) as u32
}

/// Low 32 bits of the checksum at checkpoint `i`.
#[no_mangle]
pub extern "C" fn mochi_checkpoint_lo(i: u32) -> u32 {
    state().checksums.get(i as usize).copied().unwrap_or(0) as u32
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    core::arch::wasm32::unreachable()
}
