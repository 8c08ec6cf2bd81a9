//! Instance memory that a C caller overwrote gets a status, never a panic (which would abort
//! the engine behind `extern "C"`): an instance claiming a latent larger than its room, used
//! with a model of that latent size, is refused by every call.
// The test calls the C ABI's `unsafe extern "C"` functions, as a C caller does.
#![allow(unsafe_code)]

use mochi_runtime::capi::{
    mochi_instance_decode, mochi_instance_decode_render, mochi_instance_decode_surface, mochi_instance_init,
    mochi_instance_step, MochiInstance, MochiModel, MochiStatus, MOCHI_INSTANCE_WORDS,
};
use mochi_runtime::payload::{HandleData, LayerData, Payload};
use mochi_runtime::{HandleMotion, OwnedModel, MAX_LATENT};

/// A 2D triangle (one handle on vertices 0 and 1, vertex 2 free) with latent size `latent`,
/// every latent coordinate starting at 0.5.
fn model(latent: usize) -> MochiModel {
    let layer = |rows: usize, cols: usize| LayerData {
        rows: rows as u64,
        cols: cols as u64,
        weights: vec![0.01; rows * cols],
        bias: vec![0.0; rows],
    };
    let payload = Payload {
        dt: 0.01,
        dim: 2,
        num_vertices: 3,
        rest: vec![0.0, 0.0, 1.0, 0.0, 0.0, 1.0],
        diagonal: 2f64.sqrt(),
        rotates: false,
        handle_vertices: vec![0, 1],
        free_vertices: vec![2],
        origin_of: vec![0],
        root_slots: vec![],
        chains: vec![],
        handles: vec![HandleData {
            vertices: vec![0, 1],
            reference: vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
            pivot: [0.5, 0.0, 0.0],
        }],
        bc_len: 12,
        surface_vertices: vec![0, 1, 2],
        latent: latent as u32,
        initial_latent: vec![0.5; latent],
        latent_min: vec![-1.0; latent],
        latent_max: vec![1.0; latent],
        decoder: vec![layer(4, latent), layer(2, 4)],
        integrator: vec![layer(4, 2 * latent + 36), layer(latent, 4)],
        surface_triangles: vec![0, 1, 2],
        decoder_basis: false,
        dt_range: [0.0; 2],
        collider_shapes: vec![],
        render: Default::default(),
        rate_input: false,
    };
    let storage: &'static mut OwnedModel = Box::leak(Box::default());
    let valid = storage.load(&payload.to_section().unwrap()).unwrap();
    MochiModel::new(*valid.model()).unwrap()
}

/// The instance's bytes as 16-bit words, as a C caller sees them.
fn words(instance: &MochiInstance) -> Vec<u16> {
    let bytes: Vec<u8> = instance.opaque.iter().flat_map(|w| w.to_ne_bytes()).collect();
    bytes
        .chunks_exact(2)
        .map(|b| u16::from_ne_bytes([b[0], b[1]]))
        .collect()
}

#[test]
fn an_instance_claiming_more_latent_than_its_room_gets_a_status() {
    let (fits, wide) = (model(MAX_LATENT), model(MAX_LATENT + 1));
    let mut instance = MochiInstance {
        opaque: [0; MOCHI_INSTANCE_WORDS],
    };
    // SAFETY (every call here): the model and the instance are live and the buffers as long as
    // the lengths given.
    assert_eq!(unsafe { mochi_instance_init(&wide, &mut instance) }, MochiStatus::Size);
    assert_eq!(unsafe { mochi_instance_init(&fits, &mut instance) }, MochiStatus::Ok);
    // The stored latent size is the one 16-bit word equal to it (the latents' bit patterns,
    // the signal's zeros, the signal length 12 and the frame count 0 differ): overwrite it.
    let latent_at: Vec<usize> = (0..)
        .zip(words(&instance))
        .filter(|&(_, w)| w as usize == MAX_LATENT)
        .map(|(i, _)| i)
        .collect();
    assert_eq!(latent_at.len(), 1, "{latent_at:?}");
    let word = latent_at[0];
    let (u64_at, shift) = (word / 4, 16 * (word % 4));
    let claimed = ((MAX_LATENT + 1) as u64) << shift;
    let opaque = &mut instance.opaque[u64_at];
    *opaque = (*opaque & !(0xffff << shift)) | claimed;
    let before = instance.opaque;
    let motion = [HandleMotion::REST];
    let mut out = [0.0f32; 6];
    assert_eq!(
        unsafe { mochi_instance_step(&wide, &mut instance, motion.as_ptr(), 1) },
        MochiStatus::Size
    );
    assert_eq!(
        unsafe { mochi_instance_decode(&wide, &mut instance, out.as_mut_ptr(), 6) },
        MochiStatus::Size
    );
    assert_eq!(
        unsafe { mochi_instance_decode_surface(&wide, &mut instance, out.as_mut_ptr(), 6) },
        MochiStatus::Size
    );
    let (mut positions, mut normals) = ([0.0f32; 0], [0.0f32; 0]);
    assert_eq!(
        unsafe {
            mochi_instance_decode_render(
                &wide,
                &mut instance,
                out.as_mut_ptr(),
                6,
                positions.as_mut_ptr(),
                normals.as_mut_ptr(),
                0,
            )
        },
        MochiStatus::Size
    );
    assert_eq!(instance.opaque, before, "a refused call changes nothing");
    assert_eq!(out, [0.0; 6], "a refused decode writes nothing");
    // The model the instance was made for is refused too (the stored size is not its).
    assert_eq!(
        unsafe { mochi_instance_step(&fits, &mut instance, motion.as_ptr(), 1) },
        MochiStatus::Size
    );
}
