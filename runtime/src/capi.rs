//! C ABI (feature `capi`) for engines written in C and C++: a model handle, caller-allocated
//! instances with room for any model, and status codes instead of panics. The header is
//! generated with cbindgen (`targets/c`); every function checks its pointers and sizes and
//! returns a [`MochiStatus`].
//!
//! A model handle comes from the crate that holds the generated model (`targets/c` exports
//! `mochi_model_tiny()`); instances are plain memory ([`MochiInstance`], no allocation), so an
//! engine can keep thousands in its own arrays.
#![allow(unsafe_code)]

use core::mem::{align_of, size_of};

use crate::collider::{push_out, Collider, ColliderError, ColliderState};
use crate::frame::HandleMotion;
use crate::instance::{AnyInstance, DecodeError, StepError, Stepped, ValidModel};
use crate::model::{Model, ModelError};

/// 8-byte words of a [`MochiInstance`].
pub const MOCHI_INSTANCE_WORDS: usize = 257;

const _: () = assert!(size_of::<AnyInstance>() <= size_of::<MochiInstance>());
const _: () = assert!(align_of::<AnyInstance>() <= align_of::<MochiInstance>());

/// A validated model, shared by any number of instances (opaque to C).
#[derive(Clone, Copy, Debug)]
pub struct MochiModel(ValidModel<'static>);

impl MochiModel {
    /// Validates `model` for use through the C ABI.
    pub fn new(model: Model<'static>) -> Result<Self, ModelError> {
        ValidModel::new(model).map(MochiModel)
    }
}

/// Memory for one simulated object, with room for any model (latent up to 64, 16 handles,
/// hidden width up to 1,024). Allocate it anywhere; initialise it with
/// [`mochi_instance_init`] before any other call.
#[repr(C)]
pub struct MochiInstance {
    /// The instance's bytes (see [`AnyInstance`]); only the functions here read them.
    pub opaque: [u64; MOCHI_INSTANCE_WORDS],
}

/// What a call did. Non-negative: success; negative: refused, nothing changed (except
/// [`MochiStatus::DecodeNotFinite`], which writes the rest positions).
#[repr(i32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MochiStatus {
    /// Done.
    Ok = 0,
    /// Stepped; the latent left the trained range and was clamped.
    Clamped = 1,
    /// Stepped; the network gave a non-finite latent and the previous one was kept.
    Held = 2,
    /// A pointer argument was null.
    NullPointer = -1,
    /// The number of handle motions is not the model's handle count.
    HandleCount = -2,
    /// A handle motion holds a NaN or an infinity.
    NotFinite = -3,
    /// The model does not fit an instance, or is not the one the instance was created for.
    Size = -4,
    /// The output buffer's length is not the model's state (or surface, or render) length, or
    /// buffers that must be distinct overlap.
    BufferLength = -5,
    /// The decoded state was not finite; the rest positions were written instead.
    DecodeNotFinite = -6,
    /// The frame time is not a positive finite number, or the model takes only its own
    /// (`dt_max` of [`MochiModelInfo`] is 0) and another was given.
    FrameTime = -7,
    /// A collider has an unknown shape, a size that is not positive or a non-finite number,
    /// the margin is negative or not finite, or more collider states were given than the
    /// model has slots.
    Collider = -8,
}

/// Sizes of a model.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MochiModelInfo {
    /// Latent size.
    pub latent: u32,
    /// Handles (one [`HandleMotion`] each per step).
    pub handles: u32,
    /// Coordinates per vertex (2 or 3).
    pub dim: u32,
    /// Vertices of the full mesh.
    pub vertices: u32,
    /// Floats of a full state ([`mochi_instance_decode`]).
    pub state_len: u32,
    /// Floats of a drawn-vertices state ([`mochi_instance_decode_surface`]).
    pub surface_len: u32,
    /// Time step in seconds ([`mochi_instance_step`]'s frame time).
    pub dt: f32,
    /// Rest bounding-box diagonal.
    pub diagonal: f32,
    /// Shortest frame time the model was trained at (0 for a model of one frame time).
    pub dt_min: f32,
    /// Longest frame time the model was trained at; when positive,
    /// [`mochi_instance_step_dt`] takes any positive frame time, otherwise only `dt`.
    pub dt_max: f32,
    /// Run-time collider slots ([`mochi_instance_step_colliders`]).
    pub colliders: u32,
    /// Floats of the render mesh's positions and of its normals
    /// ([`mochi_instance_decode_render`]): 3 per render vertex, 0 without a render mesh.
    pub render_len: u32,
    /// Render triangles (three `u32` each, [`mochi_model_render_mesh`]).
    pub render_triangles: u32,
    /// Floats of the render mesh's texture coordinates (2 per render vertex, or 0).
    pub render_uvs: u32,
}

/// The instance in `instance`'s memory.
///
/// # Safety
/// `instance` must be null or point to a `MochiInstance` (any bytes: every field of an
/// [`AnyInstance`] is a number, so every bit pattern is a value).
unsafe fn state<'i>(instance: *mut MochiInstance) -> Option<&'i mut AnyInstance> {
    // SAFETY: size and alignment are asserted above; see the function's contract.
    unsafe { instance.cast::<AnyInstance>().as_mut() }
}

/// Writes the sizes of `model` into `info`.
///
/// # Safety
/// `model` must be null or come from a model export; `info` null or writable.
#[no_mangle]
pub unsafe extern "C" fn mochi_model_info(model: *const MochiModel, info: *mut MochiModelInfo) -> MochiStatus {
    // SAFETY: see the function's contract.
    let (Some(model), Some(info)) = (unsafe { model.as_ref() }, unsafe { info.as_mut() }) else {
        return MochiStatus::NullPointer;
    };
    let m = model.0.model();
    *info = MochiModelInfo {
        latent: m.latent,
        handles: m.handles.len() as u32,
        dim: m.dim,
        vertices: m.num_vertices,
        state_len: m.state_len() as u32,
        surface_len: m.surface_len() as u32,
        dt: m.dt,
        diagonal: m.diagonal,
        dt_min: m.dt_min,
        dt_max: m.dt_max,
        colliders: m.colliders() as u32,
        render_len: m.render_len() as u32,
        render_triangles: (m.render_triangles().len() / 3) as u32,
        render_uvs: m.render_uvs().len() as u32,
    };
    MochiStatus::Ok
}

/// Writes where the render mesh's triangles (`3 * render_triangles` render-vertex indices,
/// counter-clockwise seen from outside) and texture coordinates (`render_uvs` floats) of
/// [`MochiModelInfo`] are into `triangles` and `uvs`: the model's own memory, valid as long as
/// the model; null where there are none.
///
/// # Safety
/// `model` must be null or come from a model export; `triangles` and `uvs` null or writable.
#[no_mangle]
pub unsafe extern "C" fn mochi_model_render_mesh(
    model: *const MochiModel,
    triangles: *mut *const u32,
    uvs: *mut *const f32,
) -> MochiStatus {
    // SAFETY: see the function's contract.
    let (Some(model), Some(triangles), Some(uvs)) =
        (unsafe { model.as_ref() }, unsafe { triangles.as_mut() }, unsafe {
            uvs.as_mut()
        })
    else {
        return MochiStatus::NullPointer;
    };
    let m = model.0.model();
    *triangles = match m.render_triangles() {
        [] => core::ptr::null(),
        values => values.as_ptr(),
    };
    *uvs = match m.render_uvs() {
        [] => core::ptr::null(),
        values => values.as_ptr(),
    };
    MochiStatus::Ok
}

/// Puts a new object of `model` at rest into `instance`.
///
/// # Safety
/// `model` must be null or come from a model export; `instance` null or writable memory of a
/// `MochiInstance`.
#[no_mangle]
pub unsafe extern "C" fn mochi_instance_init(model: *const MochiModel, instance: *mut MochiInstance) -> MochiStatus {
    // SAFETY: see the function's contract.
    let Some(model) = (unsafe { model.as_ref() }) else {
        return MochiStatus::NullPointer;
    };
    if instance.is_null() {
        return MochiStatus::NullPointer;
    }
    match AnyInstance::new(&model.0) {
        Ok(body) => {
            // SAFETY: non-null, sized and aligned for an `AnyInstance` (asserted above).
            unsafe { instance.cast::<AnyInstance>().write(body) };
            MochiStatus::Ok
        }
        Err(_) => MochiStatus::Size,
    }
}

/// Advances `instance` one frame of the model's time step (`dt` of [`MochiModelInfo`]) with
/// `count` handle motions (the model's handle order).
///
/// # Safety
/// `model` as for [`mochi_instance_init`]; `instance` initialised by it; `motions` null or
/// `count` readable motions.
#[no_mangle]
pub unsafe extern "C" fn mochi_instance_step(
    model: *const MochiModel,
    instance: *mut MochiInstance,
    motions: *const HandleMotion,
    count: usize,
) -> MochiStatus {
    // SAFETY: see the function's contract.
    let Some(dt) = (unsafe { model.as_ref() }).map(|m| m.0.model().dt) else {
        return MochiStatus::NullPointer;
    };
    // SAFETY: the same contract.
    unsafe { mochi_instance_step_dt(model, instance, motions, count, dt) }
}

/// Advances `instance` one frame of `dt` seconds (the engine's frame time) with `count` handle
/// motions: any positive `dt` for a model trained over a range of frame times (`dt_max` of
/// [`MochiModelInfo`] positive), only the model's own `dt` otherwise
/// ([`MochiStatus::FrameTime`]).
///
/// # Safety
/// As [`mochi_instance_step`].
#[no_mangle]
pub unsafe extern "C" fn mochi_instance_step_dt(
    model: *const MochiModel,
    instance: *mut MochiInstance,
    motions: *const HandleMotion,
    count: usize,
    dt: f32,
) -> MochiStatus {
    // SAFETY: the same contract, and no colliders.
    unsafe { mochi_instance_step_colliders(model, instance, motions, count, core::ptr::null(), 0, dt) }
}

/// [`mochi_instance_step_dt`] with this frame's run-time colliders: `ncolliders` states, at
/// most the model's collider slots (`colliders` of [`MochiModelInfo`]), in slot order; the
/// slots past them are empty. A state that is not finite, or more states than slots, is
/// refused ([`MochiStatus::Collider`]).
///
/// # Safety
/// As [`mochi_instance_step`]; `colliders` null (with `ncolliders` 0) or `ncolliders` readable
/// states.
#[no_mangle]
pub unsafe extern "C" fn mochi_instance_step_colliders(
    model: *const MochiModel,
    instance: *mut MochiInstance,
    motions: *const HandleMotion,
    count: usize,
    colliders: *const ColliderState,
    ncolliders: usize,
    dt: f32,
) -> MochiStatus {
    // SAFETY: see the function's contract.
    let (Some(model), Some(body)) = (unsafe { model.as_ref() }, unsafe { state(instance) }) else {
        return MochiStatus::NullPointer;
    };
    if motions.is_null() || (colliders.is_null() && ncolliders > 0) {
        return MochiStatus::NullPointer;
    }
    // SAFETY: `count` readable motions and `ncolliders` readable states (the contract).
    let (bc, touch) = unsafe {
        (
            core::slice::from_raw_parts(motions, count),
            if ncolliders == 0 {
                &[][..]
            } else {
                core::slice::from_raw_parts(colliders, ncolliders)
            },
        )
    };
    match body.step_with(&model.0, bc, touch, dt) {
        Ok(Stepped::Ok) => MochiStatus::Ok,
        Ok(Stepped::Clamped) => MochiStatus::Clamped,
        Ok(Stepped::Held) => MochiStatus::Held,
        Err(StepError::HandleCount { .. }) => MochiStatus::HandleCount,
        Err(StepError::NotFinite { .. }) => MochiStatus::NotFinite,
        Err(StepError::Model(_)) => MochiStatus::Size,
        Err(StepError::FrameTime | StepError::FixedFrameTime) => MochiStatus::FrameTime,
        Err(StepError::ColliderCount { .. } | StepError::ColliderNotFinite { .. }) => MochiStatus::Collider,
    }
}

/// Writes the world positions of every vertex (`state_len` floats) into `out`.
///
/// # Safety
/// As [`mochi_instance_step`]; `out` null or `len` writable floats.
#[no_mangle]
pub unsafe extern "C" fn mochi_instance_decode(
    model: *const MochiModel,
    instance: *mut MochiInstance,
    out: *mut f32,
    len: usize,
) -> MochiStatus {
    // SAFETY: see the function's contract.
    unsafe { decode(model, instance, out, len, false) }
}

/// Writes the world positions of the drawn vertices (`surface_len` floats) into `out`.
///
/// # Safety
/// As [`mochi_instance_decode`].
#[no_mangle]
pub unsafe extern "C" fn mochi_instance_decode_surface(
    model: *const MochiModel,
    instance: *mut MochiInstance,
    out: *mut f32,
    len: usize,
) -> MochiStatus {
    // SAFETY: see the function's contract.
    unsafe { decode(model, instance, out, len, true) }
}

/// Writes the render mesh's positions and area-weighted unit normals (`len` floats each, the
/// model's `render_len`) for the instance's current state into `positions` and `normals`, from
/// the simulation positions it decodes into `scratch` (`scratch_len` floats, the model's
/// `state_len`; its contents afterwards are that full decode). Buffers that overlap are refused
/// with [`MochiStatus::BufferLength`]. A state that decodes to a non-finite value gives the
/// render mesh at rest and [`MochiStatus::DecodeNotFinite`].
///
/// # Safety
/// As [`mochi_instance_step`]; `scratch` null or `scratch_len` writable floats; `positions` and
/// `normals` null or `len` writable floats each.
#[no_mangle]
pub unsafe extern "C" fn mochi_instance_decode_render(
    model: *const MochiModel,
    instance: *mut MochiInstance,
    scratch: *mut f32,
    scratch_len: usize,
    positions: *mut f32,
    normals: *mut f32,
    len: usize,
) -> MochiStatus {
    // SAFETY: see the function's contract.
    let (Some(model), Some(body)) = (unsafe { model.as_ref() }, unsafe { state(instance) }) else {
        return MochiStatus::NullPointer;
    };
    if scratch.is_null() || positions.is_null() || normals.is_null() {
        return MochiStatus::NullPointer;
    }
    let range = |p: *mut f32, n: usize| {
        let start = p as usize;
        (start, start.saturating_add(n.saturating_mul(size_of::<f32>())))
    };
    let buffers = [range(scratch, scratch_len), range(positions, len), range(normals, len)];
    let overlap = |(a, b): (usize, usize), (c, d): (usize, usize)| a < d && c < b;
    if overlap(buffers[0], buffers[1]) || overlap(buffers[0], buffers[2]) || overlap(buffers[1], buffers[2]) {
        return MochiStatus::BufferLength;
    }
    // SAFETY: writable and disjoint (the function's contract, the overlap checked above).
    let (sim, out, normals) = unsafe {
        (
            core::slice::from_raw_parts_mut(scratch, scratch_len),
            core::slice::from_raw_parts_mut(positions, len),
            core::slice::from_raw_parts_mut(normals, len),
        )
    };
    status(body.decode_render_into(&model.0, sim, out, normals))
}

fn status(result: Result<(), DecodeError>) -> MochiStatus {
    match result {
        Ok(()) => MochiStatus::Ok,
        Err(DecodeError::BufferLength { .. }) => MochiStatus::BufferLength,
        Err(DecodeError::NotFinite) => MochiStatus::DecodeNotFinite,
        Err(DecodeError::Model(_)) => MochiStatus::Size,
    }
}

/// # Safety
/// As [`mochi_instance_decode`].
unsafe fn decode(
    model: *const MochiModel,
    instance: *mut MochiInstance,
    out: *mut f32,
    len: usize,
    surface: bool,
) -> MochiStatus {
    // SAFETY: see the caller's contract.
    let (Some(model), Some(body)) = (unsafe { model.as_ref() }, unsafe { state(instance) }) else {
        return MochiStatus::NullPointer;
    };
    if out.is_null() {
        return MochiStatus::NullPointer;
    }
    // SAFETY: `len` writable floats (the caller's contract).
    let out = unsafe { core::slice::from_raw_parts_mut(out, len) };
    let result = if surface {
        body.decode_surface_into(&model.0, out)
    } else {
        body.decode_into(&model.0, out)
    };
    status(result)
}

/// Pushes every vertex of `positions` (`len` floats: a state or drawn-vertices buffer of
/// `model`, `dim` per vertex) nearer than `margin` to one of `count` colliders, or inside it,
/// out to `margin` from its surface (`mochi_runtime::collider`); writes how many moves were
/// made into `moved` (may be null). Refused input changes nothing.
///
/// # Safety
/// `model` as for [`mochi_instance_init`]; `positions` null or `len` writable floats;
/// `colliders` null or `count` readable colliders; `moved` null or writable.
#[no_mangle]
pub unsafe extern "C" fn mochi_push_out(
    model: *const MochiModel,
    positions: *mut f32,
    len: usize,
    colliders: *const Collider,
    count: usize,
    margin: f32,
    moved: *mut u32,
) -> MochiStatus {
    // SAFETY: see the function's contract.
    let Some(model) = (unsafe { model.as_ref() }) else {
        return MochiStatus::NullPointer;
    };
    if positions.is_null() || (colliders.is_null() && count > 0) {
        return MochiStatus::NullPointer;
    }
    // SAFETY: `len` writable floats and `count` readable colliders (the function's contract).
    let (out, list) = unsafe {
        (
            core::slice::from_raw_parts_mut(positions, len),
            if count == 0 {
                &[][..]
            } else {
                core::slice::from_raw_parts(colliders, count)
            },
        )
    };
    match push_out(out, model.0.model().dim(), list, margin) {
        Ok(n) => {
            // SAFETY: null or writable (the function's contract).
            if let Some(m) = unsafe { moved.as_mut() } {
                *m = n as u32;
            }
            MochiStatus::Ok
        }
        Err(ColliderError::Invalid { .. }) => MochiStatus::Collider,
        Err(ColliderError::Arguments) if !len.is_multiple_of(model.0.model().dim()) => MochiStatus::BufferLength,
        Err(ColliderError::Arguments) => MochiStatus::Collider,
    }
}
