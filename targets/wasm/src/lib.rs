//! A wasm32 module with a small C-like API (numbers and pointers into the module's memory only)
//! for JavaScript:
//!
//! - the viewer: one interactive object of the *current* model, driven by a handle pose, whose
//!   drawn vertices ([`mochi_surface`]) and triangles ([`mochi_triangles`]) a page draws, or,
//!   for a model with a render mesh, its render positions, normals and triangles
//!   ([`mochi_render_positions`], [`mochi_render_normals`], [`mochi_render_triangles`]). The
//!   current model is the one generated into the module ([`mochi_init`]) or an artifact loaded
//!   from bytes at run time ([`mochi_load`]), so a page can switch between models it fetches;
//! - the reference run every target makes with the generated model (`mochi-target-common`),
//!   whose checksums must equal the host runtime's.
//!
//! No allocation: the objects, the loaded model's pools and every buffer live in statics. A
//! wasm module runs on one thread, so the exported functions are never re-entered.
#![no_std]

use core::fmt::Write as _;
use core::ptr::{addr_of, addr_of_mut};

use mochi_runtime::collider::{push_out, Collider, ColliderState};
use mochi_runtime::model::{MAX_HANDLES, MAX_LAYERS};
use mochi_runtime::{AnyInstance, Handle, HandleMotion, HandlePose, Layer, Storage, ValidModel};
use mochi_target_common::{run, CHECKPOINTS};

mod render_mesh;
mod slab;
use slab::Slab;

#[allow(dead_code, missing_docs)]
mod model {
    include!(concat!(env!("OUT_DIR"), "/model.rs"));
}

/// Largest artifact [`mochi_load`] takes, in bytes.
const ARTIFACT_CAPACITY: usize = 8 << 20;
/// Most drawn vertices the viewer decodes (3 coordinates each at most).
const MAX_SURFACE: usize = 1 << 16;
/// Bytes of the last error's text.
const ERROR_CAPACITY: usize = 256;

/// Status codes: 0 ok, 1 clamped, 2 held; negative: refused.
const OK: i32 = 0;
const NOT_INITIALISED: i32 = -1;
const INVALID_MODEL: i32 = -2;
const STEP_REFUSED: i32 = -3;
const DECODE_REFUSED: i32 = -4;
const LOAD_REFUSED: i32 = -5;
const COLLIDER_REFUSED: i32 = -6;

/// The loaded model's storage (room: [`slab`]).
type Viewer = Storage<
    Slab<f32, 0>,
    Slab<f32, 1>,
    Slab<u32, 2>,
    heapless::Vec<Layer, MAX_LAYERS>,
    heapless::Vec<Handle, MAX_HANDLES>,
>;

/// The objects and the module's buffers.
struct State {
    /// The generated model, once validated.
    compiled: Option<ValidModel<'static>>,
    /// The viewer's model: `compiled` or the one in [`LOADED`].
    current: Option<ValidModel<'static>>,
    body: Option<AnyInstance>,
    pose: HandlePose,
    /// The page's collider, when it has one: its last pose, and how many drawn vertices it
    /// pushed out after the last step.
    collider: Option<Collider>,
    pushed: u32,
    checksums: [u64; CHECKPOINTS.len()],
    error: ErrorText,
}

/// The text of the last refused call, truncated to [`ERROR_CAPACITY`] bytes.
struct ErrorText {
    bytes: [u8; ERROR_CAPACITY],
    len: usize,
}

impl core::fmt::Write for ErrorText {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        for &b in s.as_bytes() {
            if self.len < ERROR_CAPACITY {
                self.bytes[self.len] = b;
                self.len += 1;
            }
        }
        Ok(())
    }
}

static mut STATE: State = State {
    compiled: None,
    current: None,
    body: None,
    pose: HandlePose {
        translation: [0.0; 3],
        rotation: [0.0; 3],
    },
    collider: None,
    pushed: 0,
    checksums: [0; CHECKPOINTS.len()],
    error: ErrorText {
        bytes: [0; ERROR_CAPACITY],
        len: 0,
    },
};

/// The viewer's drawn vertices (`dim` each). Buffers are statics of their own, all zero, so
/// that they are not written into the module (as [`STATE`], whose `None`s are not all zero
/// bytes, is).
static mut SURFACE: [f32; 3 * MAX_SURFACE] = [0.0; 3 * MAX_SURFACE];

/// The reference run's final positions.
static mut POSITIONS: [f32; model::STATE_LEN] = [0.0; model::STATE_LEN];

/// Where JavaScript writes an artifact for [`mochi_load`].
static mut ARTIFACT: [u8; ARTIFACT_CAPACITY] = [0; ARTIFACT_CAPACITY];

/// The model [`mochi_load`] loaded (its storage made at the first load).
static mut LOADED: Option<Viewer> = None;

/// The module's state.
fn state() -> &'static mut State {
    // SAFETY: wasm32-unknown-unknown runs one thread and the exports do not call each other,
    // so at most one reference to STATE exists at a time.
    unsafe { &mut *addr_of_mut!(STATE) }
}

/// The viewer's drawn vertices.
fn surface() -> &'static mut [f32; 3 * MAX_SURFACE] {
    // SAFETY: as for `state`.
    unsafe { &mut *addr_of_mut!(SURFACE) }
}

/// Validates the generated model, makes it the viewer's model and puts the object at rest
/// (drawn vertices at their rest positions). 0 on success.
#[no_mangle]
pub extern "C" fn mochi_init() -> i32 {
    let s = state();
    let Ok(model) = ValidModel::new(model::MODEL) else {
        return INVALID_MODEL;
    };
    s.compiled = Some(model);
    s.current = Some(model);
    mochi_reset()
}

/// Room for an artifact of `len` bytes: where to write it before [`mochi_load`], or null when
/// it does not fit.
#[no_mangle]
pub extern "C" fn mochi_artifact_buffer(len: u32) -> *mut u8 {
    if len as usize > ARTIFACT_CAPACITY {
        return core::ptr::null_mut();
    }
    addr_of_mut!(ARTIFACT).cast()
}

/// Loads the artifact of `len` bytes written at [`mochi_artifact_buffer`], makes it the
/// viewer's model and puts the object at rest. 0 on success; otherwise negative, with the
/// reason in [`mochi_error_text`] (the viewer then has no model until the next load or
/// [`mochi_init`]).
#[no_mangle]
pub extern "C" fn mochi_load(len: u32) -> i32 {
    let s = state();
    // Nothing may refer to the loaded pools while they are replaced.
    s.current = None;
    s.body = None;
    s.error.len = 0;
    if len as usize > ARTIFACT_CAPACITY {
        let _ = write!(s.error, "artifact of {len} bytes, the page takes {ARTIFACT_CAPACITY}");
        return LOAD_REFUSED;
    }
    // SAFETY: one thread; JavaScript wrote the bytes before this call, and the module writes
    // ARTIFACT nowhere.
    let bytes = unsafe { &(&*addr_of!(ARTIFACT))[..len as usize] };
    // SAFETY: one thread, and `current` (the only reference into LOADED) was cleared above.
    let storage = unsafe { &mut *addr_of_mut!(LOADED) }.get_or_insert_with(Viewer::default);
    let model = match storage.load(bytes) {
        Ok(model) => model,
        Err(e) => {
            let _ = write!(s.error, "{e}");
            return LOAD_REFUSED;
        }
    };
    if model.model().surface_len() > 3 * MAX_SURFACE {
        let drawn = model.model().surface_vertices.len;
        let _ = write!(s.error, "{drawn} drawn vertices, the page takes {MAX_SURFACE}");
        return LOAD_REFUSED;
    }
    s.current = Some(model);
    mochi_reset()
}

/// The text of the last refused [`mochi_load`] or [`mochi_reset`] (UTF-8,
/// [`mochi_error_len`] bytes).
#[no_mangle]
pub extern "C" fn mochi_error_text() -> *const u8 {
    state().error.bytes.as_ptr()
}

/// Bytes of [`mochi_error_text`].
#[no_mangle]
pub extern "C" fn mochi_error_len() -> u32 {
    state().error.len as u32
}

/// Puts the viewer's object back at rest with its handles at the reference pose.
#[no_mangle]
pub extern "C" fn mochi_reset() -> i32 {
    let s = state();
    let Some(model) = s.current.as_ref() else {
        return NOT_INITIALISED;
    };
    s.body = match AnyInstance::new(model) {
        Ok(body) => Some(body),
        Err(e) => {
            s.error.len = 0;
            let _ = write!(s.error, "{e}");
            return INVALID_MODEL;
        }
    };
    s.pose = HandlePose::default();
    if let Some(body) = s.body.as_ref() {
        if render_mesh::decode(model, body, None).is_err() {
            return DECODE_REFUSED;
        }
    }
    let m = model.model();
    let d = m.dim();
    for (out, &v) in surface().chunks_exact_mut(d).zip(m.surface_vertices()) {
        let rest = m.rest().get(v as usize * d..).unwrap_or(&[]);
        out.iter_mut().zip(rest).for_each(|(o, r)| *o = *r);
    }
    OK
}

/// The viewer's model, for the queries below.
fn current() -> Option<&'static mochi_runtime::Model<'static>> {
    state().current.as_ref().map(|m| m.model())
}

/// Vertices of the viewer's model (0 without one).
#[no_mangle]
pub extern "C" fn mochi_vertex_count() -> u32 {
    current().map_or(0, |m| m.num_vertices)
}

/// Coordinates per vertex of the viewer's model.
#[no_mangle]
pub extern "C" fn mochi_dim() -> u32 {
    current().map_or(0, |m| m.dim)
}

/// Time step of the viewer's model in seconds.
#[no_mangle]
pub extern "C" fn mochi_dt() -> f32 {
    current().map_or(0.0, |m| m.dt)
}

/// Shortest frame time the viewer's model was trained at (0: it steps by its `dt` only).
#[no_mangle]
pub extern "C" fn mochi_dt_min() -> f32 {
    current().map_or(0.0, |m| m.dt_min)
}

/// Longest frame time the viewer's model was trained at; when positive,
/// [`mochi_step_pose_dt`] takes the page's own frame time (0: the model's `dt` only).
#[no_mangle]
pub extern "C" fn mochi_dt_max() -> f32 {
    current().map_or(0.0, |m| m.dt_max)
}

/// Rest bounding-box diagonal of the viewer's model.
#[no_mangle]
pub extern "C" fn mochi_diagonal() -> f32 {
    current().map_or(0.0, |m| m.diagonal)
}

/// Handles of the viewer's model.
#[no_mangle]
pub extern "C" fn mochi_handle_count() -> u32 {
    current().map_or(0, |m| m.handles.len() as u32)
}

/// The rest positions of the viewer's model (`vertex_count * dim` floats).
#[no_mangle]
pub extern "C" fn mochi_rest() -> *const f32 {
    current().map_or(core::ptr::null(), |m| m.rest().as_ptr())
}

/// Drawn vertices of the viewer's model.
#[no_mangle]
pub extern "C" fn mochi_surface_count() -> u32 {
    current().map_or(0, |m| m.surface_vertices.len)
}

/// The drawn vertices' positions after the last step (`surface_count * dim` floats).
#[no_mangle]
pub extern "C" fn mochi_surface() -> *const f32 {
    surface().as_ptr()
}

/// Triangles to draw of the viewer's model.
#[no_mangle]
pub extern "C" fn mochi_triangle_count() -> u32 {
    current().map_or(0, |m| m.surface_triangles.len / 3)
}

/// The triangles (`3 * triangle_count` indices into the drawn vertices, `u32`).
#[no_mangle]
pub extern "C" fn mochi_triangles() -> *const u32 {
    current().map_or(core::ptr::null(), |m| m.surface_triangles().as_ptr())
}

/// Moves every handle to the pose `(t, r)` (translation, rotation vector) over one frame, steps
/// the viewer's object and decodes its drawn vertices ([`mochi_surface`]); the velocities come
/// from the previous pose. Returns 0 (ok), 1 (latent clamped to the trained range), 2 (held),
/// or a negative code when refused (a non-finite pose; the object is unchanged).
#[no_mangle]
pub extern "C" fn mochi_step_pose(tx: f32, ty: f32, tz: f32, rx: f32, ry: f32, rz: f32) -> i32 {
    mochi_step_pose_dt(mochi_dt(), tx, ty, tz, rx, ry, rz)
}

/// [`mochi_step_pose`] over a frame of `dt` seconds (the page's own frame time): any positive
/// `dt` for a model trained over a range of frame times ([`mochi_dt_max`] positive), only the
/// model's `dt` otherwise (refused with a negative code, the object unchanged).
#[no_mangle]
pub extern "C" fn mochi_step_pose_dt(dt: f32, tx: f32, ty: f32, tz: f32, rx: f32, ry: f32, rz: f32) -> i32 {
    let s = state();
    let (Some(model), Some(body)) = (s.current.as_ref(), s.body.as_mut()) else {
        return NOT_INITIALISED;
    };
    let pose = HandlePose {
        translation: [tx, ty, tz],
        rotation: [rx, ry, rz],
    };
    let motion = HandleMotion::from_poses(&s.pose, &pose, dt);
    let bc = [motion; MAX_HANDLES];
    // A model with collider slots reads the page's collider in its first slot (its velocity
    // from the last two poses is set by `mochi_set_collider`).
    let touch = match (s.collider, model.model().colliders()) {
        (Some(c), 1..) => Some(ColliderState {
            center: c.center,
            rotation: c.rotation,
            ..ColliderState::default()
        }),
        _ => None,
    };
    let status = match body.step_with(model, &bc[..model.model().handles.len()], touch.as_slice(), dt) {
        Ok(stepped) => stepped as i32,
        Err(_) => return STEP_REFUSED,
    };
    s.pose = pose;
    let len = model.model().surface_len();
    if body.decode_surface_into(model, &mut surface()[..len]).is_err() {
        return DECODE_REFUSED;
    }
    // The run-time correction: drawn vertices inside the collider go to its surface.
    s.pushed = 0;
    if let Some(c) = s.collider {
        match push_out(&mut surface()[..len], model.model().dim(), &[c], 0.0) {
            Ok(n) => s.pushed = n as u32,
            Err(_) => return COLLIDER_REFUSED,
        }
    }
    if render_mesh::decode(model, body, s.collider).is_err() {
        return DECODE_REFUSED;
    }
    status
}

/// Puts the page's collider (a sphere of `radius` at `(x, y, z)`) in the scene, or takes it
/// out (`radius` <= 0). Each step then pushes the drawn vertices inside it out to its surface
/// ([`mochi_pushed`] says how many) and a model with collider slots reads it as its first.
/// Returns 0, or a negative code for a non-finite number (nothing changed).
#[no_mangle]
pub extern "C" fn mochi_set_collider(radius: f32, x: f32, y: f32, z: f32) -> i32 {
    let s = state();
    if !(radius.is_finite() && x.is_finite() && y.is_finite() && z.is_finite()) {
        return COLLIDER_REFUSED;
    }
    s.collider = (radius > 0.0).then_some(Collider {
        shape: mochi_runtime::collider::SPHERE,
        size: [radius, 0.0, 0.0],
        center: [x, y, z],
        rotation: [0.0; 3],
    });
    OK
}

/// Drawn vertices the page's collider pushed out after the last step.
#[no_mangle]
pub extern "C" fn mochi_pushed() -> u32 {
    state().pushed
}

/// The positions after the last reference run (`vertex_count * dim` floats of the generated
/// model).
#[no_mangle]
pub extern "C" fn mochi_positions() -> *const f32 {
    addr_of!(POSITIONS).cast()
}

/// Runs the reference script with the generated model for `frames` frames from rest (a
/// separate object), recording the checksum at each checkpoint frame it reaches; the final
/// positions are left in [`mochi_positions`]. 0 on success.
#[no_mangle]
pub extern "C" fn mochi_reference_run(frames: u32) -> i32 {
    let s = state();
    let Some(model) = s.compiled.as_ref() else {
        return NOT_INITIALISED;
    };
    let checksums = &mut s.checksums;
    // SAFETY: as for `state`.
    let positions = unsafe { &mut *addr_of_mut!(POSITIONS) };
    let result =
        run::<{ model::LATENT }, { model::SIGNAL }, { model::HIDDEN }>(model, frames, positions, |frame, sum, _| {
            if let Some(i) = CHECKPOINTS.iter().position(|&c| c == frame) {
                checksums[i] = sum.0;
            }
        });
    match result {
        Ok(_) => OK,
        Err(_) => STEP_REFUSED,
    }
}

/// Runs the reference script through the render decode with the generated model (as
/// [`mochi_reference_run`]), recording the render checksum at each checkpoint it reaches
/// ([`mochi_render_checkpoint_hi`]); the final render positions and normals are left in
/// [`mochi_render_positions`] and [`mochi_render_normals`]. 0 on success; negative for a
/// model without a render mesh.
#[no_mangle]
pub extern "C" fn mochi_reference_render_run(frames: u32) -> i32 {
    let Some(model) = state().compiled.as_ref() else {
        return NOT_INITIALISED;
    };
    match render_mesh::reference_run::<{ model::LATENT }, { model::SIGNAL }, { model::HIDDEN }>(model, frames) {
        Ok(()) => OK,
        Err(()) => DECODE_REFUSED,
    }
}

/// High 32 bits of the render checksum at checkpoint `i`.
#[no_mangle]
pub extern "C" fn mochi_render_checkpoint_hi(i: u32) -> u32 {
    (render_mesh::checksum(i) >> 32) as u32
}

/// Low 32 bits of the render checksum at checkpoint `i`.
#[no_mangle]
pub extern "C" fn mochi_render_checkpoint_lo(i: u32) -> u32 {
    render_mesh::checksum(i) as u32
}

/// Render vertices of the viewer's model (0 without a render mesh, or with one larger than
/// the viewer's 32,768 vertices).
#[no_mangle]
pub extern "C" fn mochi_render_count() -> u32 {
    match state().current.as_ref() {
        Some(model) if render_mesh::fits(model) => model.model().render_vertices() as u32,
        _ => 0,
    }
}

/// The render vertices' positions after the last step (`3 * render_count` floats).
#[no_mangle]
pub extern "C" fn mochi_render_positions() -> *const f32 {
    render_mesh::positions()
}

/// The render vertices' unit normals after the last step (`3 * render_count` floats).
#[no_mangle]
pub extern "C" fn mochi_render_normals() -> *const f32 {
    render_mesh::normals()
}

/// Render triangles of the viewer's model.
#[no_mangle]
pub extern "C" fn mochi_render_triangle_count() -> u32 {
    current().map_or(0, |m| m.render_triangles.len / 3)
}

/// The render triangles (`3 * render_triangle_count` indices into the render vertices, `u32`).
#[no_mangle]
pub extern "C" fn mochi_render_triangles() -> *const u32 {
    current().map_or(core::ptr::null(), |m| m.render_triangles().as_ptr())
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
