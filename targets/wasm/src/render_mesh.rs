//! The render mesh of a model that carries one (`mochi_runtime::render`): the viewer decodes
//! it after each step (positions and area-weighted normals, pushed out of the page's collider
//! like the drawn vertices), and the reference run decodes it for the checksums every target
//! compares. Its buffers are zero-initialised statics, as the viewer's others.

use core::ptr::{addr_of, addr_of_mut};

use mochi_runtime::collider::{push_out, Collider};
use mochi_runtime::render::triangle_normals;
use mochi_runtime::{AnyInstance, ValidModel};
use mochi_target_common::{run_render, CHECKPOINTS};

/// Most render vertices the viewer decodes.
pub const MAX_RENDER: usize = 1 << 15;
/// Most simulation vertices a render decode goes through (its full decode's scratch).
const MAX_SIM: usize = 1 << 16;

static mut SIM: [f32; 3 * MAX_SIM] = [0.0; 3 * MAX_SIM];
static mut POSITIONS: [f32; 3 * MAX_RENDER] = [0.0; 3 * MAX_RENDER];
static mut NORMALS: [f32; 3 * MAX_RENDER] = [0.0; 3 * MAX_RENDER];
/// Checksums of the reference run's render pass at the [`CHECKPOINTS`].
static mut CHECKSUMS: [u64; CHECKPOINTS.len()] = [0; CHECKPOINTS.len()];

/// The scratch and the two render buffers, each as long as `model` needs; `None` when the
/// model has no render mesh or one larger than the buffers.
fn buffers(model: &ValidModel) -> Option<(&'static mut [f32], &'static mut [f32], &'static mut [f32])> {
    if !fits(model) {
        return None;
    }
    let m = model.model();
    // SAFETY: wasm32-unknown-unknown runs one thread and the exports do not call each other,
    // so these are the only references to the three statics while they live.
    unsafe {
        Some((
            &mut (&mut *addr_of_mut!(SIM))[..m.state_len()],
            &mut (&mut *addr_of_mut!(POSITIONS))[..m.render_len()],
            &mut (&mut *addr_of_mut!(NORMALS))[..m.render_len()],
        ))
    }
}

/// Whether the viewer can show `model`'s render mesh (it has one, and it fits).
pub fn fits(model: &ValidModel) -> bool {
    let m = model.model();
    m.has_render() && m.render_len() <= 3 * MAX_RENDER && m.state_len() <= 3 * MAX_SIM
}

/// Decodes `body`'s render mesh for the viewer, pushing it out of `collider`; nothing for a
/// model without one. `Err` when the runtime refused the decode.
pub fn decode(model: &ValidModel, body: &AnyInstance, collider: Option<Collider>) -> Result<(), ()> {
    let Some((sim, positions, normals)) = buffers(model) else {
        return Ok(());
    };
    body.decode_render_into(model, sim, positions, normals)
        .map_err(|_| ())?;
    if let Some(c) = collider {
        if push_out(positions, 3, &[c], 0.0).map_err(|_| ())? > 0 {
            triangle_normals(model.model().render_triangles(), positions, normals);
        }
    }
    Ok(())
}

/// Runs the reference script for `frames` frames through the render decode
/// ([`run_render`]), recording the checksum at each checkpoint it reaches; the final render
/// positions and normals stay in the viewer's buffers. `Err` for a model without a render
/// mesh (or one too large) and when the run was refused.
pub fn reference_run<const K: usize, const S: usize, const H: usize>(
    model: &ValidModel,
    frames: u32,
) -> Result<(), ()> {
    let (sim, positions, normals) = buffers(model).ok_or(())?;
    // SAFETY: as in `buffers`.
    let checksums = unsafe { &mut *addr_of_mut!(CHECKSUMS) };
    run_render::<K, S, H>(model, frames, sim, positions, normals, |frame, sum, _, _| {
        if let Some(i) = CHECKPOINTS.iter().position(|&c| c == frame) {
            checksums[i] = sum.0;
        }
    })
    .map(|_| ())
    .map_err(|_| ())
}

/// The render pass's checksum at checkpoint `i` (0 out of range).
pub fn checksum(i: u32) -> u64 {
    // SAFETY: a read of a plain static on the one thread.
    unsafe { (*addr_of!(CHECKSUMS)).get(i as usize).copied().unwrap_or(0) }
}

/// The render positions after the last decode.
pub fn positions() -> *const f32 {
    addr_of!(POSITIONS).cast()
}

/// The render normals after the last decode.
pub fn normals() -> *const f32 {
    addr_of!(NORMALS).cast()
}
