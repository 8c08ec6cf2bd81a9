//! Loading is linear (or n log n) in every count: artifacts with a 200,000-vertex handle, a
//! 200,000-vertex surface and a 200,000-vertex strand listed out of order load in
//! milliseconds, give the model that was written, and still have their repeated vertices
//! refused naming the field.
// `clock_gettime` (the CPU time of the test's thread) is a C function.
#![allow(unsafe_code)]

use std::collections::HashMap;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use mochi_runtime::payload::{ChainData, HandleData, LayerData, Payload};
use mochi_runtime::{LoadError, ModelError, OwnedModel, Problem, HANDLE_SOURCE};

/// Vertices of the large vertex lists.
const LARGE: usize = 200_000;
/// The most CPU time a load of one of these artifacts may take (the test profile, see
/// Cargo.toml). CPU time, not the wall clock: the machine may be busy with other work.
const BUDGET: Duration = Duration::from_millis(50);

/// Held by every test here, so that no load is timed while another test computes.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

fn layer(rows: usize, cols: usize) -> LayerData {
    LayerData {
        rows: rows as u64,
        cols: cols as u64,
        weights: (0..rows * cols).map(|i| 0.01 * (i % 7) as f32).collect(),
        bias: vec![0.0; rows],
    }
}

/// A 2D mesh of `LARGE + FREE` vertices: every vertex prescribed (one handle) but `FREE`
/// spread through the mesh, every vertex drawn.
fn one_large_handle() -> Payload {
    const FREE: usize = 8;
    let n = LARGE + FREE;
    let free: Vec<u32> = (0..FREE).map(|i| (i * n / FREE) as u32).collect();
    let handle: Vec<u32> = (0..n as u32).filter(|v| free.binary_search(v).is_err()).collect();
    Payload {
        dt: 0.01,
        dim: 2,
        num_vertices: n as u32,
        rest: (0..2 * n).map(|i| (i % 100) as f32 * 0.01).collect(),
        diagonal: 1.5,
        rotates: false,
        handle_vertices: handle.clone(),
        free_vertices: free,
        origin_of: vec![0; FREE],
        root_slots: vec![],
        chains: vec![],
        handles: vec![HandleData {
            reference: handle.iter().flat_map(|&v| [v as f32, 0.0, 0.0]).collect(),
            vertices: handle,
            pivot: [0.0; 3],
        }],
        bc_len: 12,
        surface_vertices: (0..n as u32).collect(),
        latent: 1,
        initial_latent: vec![0.0],
        latent_min: vec![-1.0],
        latent_max: vec![1.0],
        decoder: vec![layer(4, 1), layer(2 * FREE, 4)],
        integrator: vec![layer(4, 2 + 36), layer(1, 4)],
        // A strip of triangles over every drawn vertex.
        surface_triangles: (0..n as u32 - 2).flat_map(|i| [i, i + 1, i + 2]).collect(),
        decoder_basis: false,
        dt_range: [0.0; 2],
        collider_shapes: vec![],
        render: Default::default(),
        rate_input: false,
    }
}

/// A 3D rod: vertices 0 and 1 prescribed (one handle), the `LARGE` others free on one strand
/// that lists them tip first (so not in free-vertex order), every vertex drawn.
fn one_large_strand() -> Payload {
    let n = LARGE + 2;
    Payload {
        dt: 0.01,
        dim: 3,
        num_vertices: n as u32,
        rest: (0..n).flat_map(|v| [0.0, -0.1 * v as f32, 0.0]).collect(),
        diagonal: 0.1 * n as f64,
        rotates: false,
        handle_vertices: vec![0, 1],
        free_vertices: (2..n as u32).collect(),
        origin_of: vec![0; LARGE],
        root_slots: vec![0],
        chains: vec![ChainData {
            parent: [0, 1],
            rest_normal: [1.0, 0.0, 0.0],
            slots: (0..LARGE as u32).rev().collect(),
            lengths: vec![0.1; LARGE],
        }],
        handles: vec![HandleData {
            vertices: vec![0, 1],
            reference: vec![0.0, 0.0, 0.0, 0.0, -0.1, 0.0],
            pivot: [0.0; 3],
        }],
        bc_len: 12,
        surface_vertices: (0..n as u32).collect(),
        latent: 1,
        initial_latent: vec![0.0],
        latent_min: vec![-1.0],
        latent_max: vec![1.0],
        decoder: vec![layer(1, 1), layer(2 * LARGE, 1)],
        integrator: vec![layer(4, 2 + 36), layer(1, 4)],
        surface_triangles: vec![],
        decoder_basis: false,
        dt_range: [0.0; 2],
        collider_shapes: vec![],
        render: Default::default(),
        rate_input: false,
    }
}

/// CPU time used by this thread so far.
#[cfg(unix)]
fn cpu_time() -> Duration {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `t` is a live `timespec` for the call to write.
    assert_eq!(unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) }, 0);
    Duration::new(t.tv_sec as u64, t.tv_nsec as u32)
}

/// The wall clock where the thread's CPU time is not at hand.
#[cfg(not(unix))]
fn cpu_time() -> Duration {
    static START: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
    START.get_or_init(Instant::now).elapsed()
}

/// The least CPU time of five loads of `payload` (printed with its wall-clock time), and the
/// result.
fn timed_load(payload: &Payload) -> (Duration, Result<(), LoadError>) {
    let bytes = payload.to_section().unwrap();
    let (mut fastest, mut wall) = (Duration::MAX, Duration::MAX);
    let mut result = Ok(());
    for _ in 0..5 {
        let mut storage = OwnedModel::default();
        let (cpu, clock) = (cpu_time(), Instant::now());
        result = storage.load(&bytes).map(|_| ());
        let took = cpu_time() - cpu;
        if took < fastest {
            (fastest, wall) = (took, clock.elapsed());
        }
    }
    println!("{} bytes: {fastest:?} CPU ({wall:?} wall), {result:?}", bytes.len());
    (fastest, result)
}

fn invalid(field: &'static str, problem: Problem) -> Result<(), LoadError> {
    Err(LoadError::Invalid(ModelError { field, problem }))
}

#[test]
fn large_artifacts_load_in_milliseconds() {
    let _alone = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let loads = [("handle", one_large_handle()), ("strand", one_large_strand())].map(|(name, payload)| {
        let (took, result) = timed_load(&payload);
        (name, took, result)
    });
    for (name, took, result) in loads {
        assert_eq!(result, Ok(()), "{name}");
        assert!(took < BUDGET, "one {LARGE}-vertex {name}: {took:?}");
    }
}

#[test]
fn a_large_artifact_loads_as_written() {
    let _alone = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let payload = one_large_handle();
    let mut storage = OwnedModel::default();
    let m = *storage.load(&payload.to_section().unwrap()).unwrap().model();
    assert_eq!(m.handle_vertices(), &payload.handle_vertices[..]);
    assert_eq!(m.free_vertices(), &payload.free_vertices[..]);
    assert_eq!(m.surface_vertices(), &payload.surface_vertices[..]);
    let slot: HashMap<u32, u32> = (0..).zip(&payload.handle_vertices).map(|(s, &v)| (v, s)).collect();
    let free: HashMap<u32, u32> = (0..).zip(&payload.free_vertices).map(|(j, &v)| (v, j)).collect();
    let expected: Vec<u32> = payload
        .surface_vertices
        .iter()
        .map(|v| free.get(v).copied().unwrap_or_else(|| HANDLE_SOURCE | slot[v]))
        .collect();
    assert_eq!(m.surface_source(), &expected[..]);

    let payload = one_large_strand();
    let m = *storage.load(&payload.to_section().unwrap()).unwrap().model();
    let chains: Vec<_> = m.chains().collect();
    assert_eq!(chains.len(), 1);
    assert_eq!(chains[0].slots, &payload.chains[0].slots[..]);
    assert_eq!(chains[0].lengths, &payload.chains[0].lengths[..]);
}

#[test]
fn repeated_vertices_in_large_artifacts_are_refused_naming_the_field() {
    let _alone = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let inconsistent = |field| invalid(field, Problem::Inconsistent);
    // A prescribed vertex listed twice in one handle, and its neighbour never: refused by
    // validation when the neighbour is not drawn, by the loader's search when it is.
    for drawn in [false, true] {
        let mut p = one_large_handle();
        let at = LARGE / 2;
        let lost = p.handle_vertices[at + 1];
        for list in [&mut p.handle_vertices, &mut p.handles[0].vertices] {
            list[at + 1] = list[at];
        }
        if !drawn {
            p.surface_vertices.retain(|&v| v != lost);
        }
        assert_eq!(timed_load(&p).1, inconsistent("handle_vertices"), "drawn: {drawn}");
    }
    // The same vertex in two handles that interleave (each still ascending).
    let mut p = one_large_handle();
    let all = std::mem::take(&mut p.handles[0].vertices);
    let halves: [Vec<u32>; 2] = [0, 1].map(|r| all.iter().skip(r).step_by(2).copied().collect());
    p.handle_vertices = halves.concat();
    p.handles = halves
        .into_iter()
        .map(|vertices| HandleData {
            reference: vertices.iter().flat_map(|&v| [v as f32, 0.0, 0.0]).collect(),
            vertices,
            pivot: [0.0; 3],
        })
        .collect();
    p.bc_len = 24;
    p.integrator[0] = layer(4, 2 + 72);
    assert_eq!(timed_load(&p).1, Ok(()), "two handles");
    let k = LARGE / 4;
    let (repeated, lost) = (p.handles[0].vertices[k], p.handles[1].vertices[k]);
    p.handles[1].vertices[k] = repeated;
    let first = p.handles[0].vertices.len();
    p.handle_vertices[first + k] = repeated;
    // The vertex no handle lists any more is drawn: the loader finds no source for it.
    let malformed = Err(LoadError::Malformed {
        field: "surface_vertices",
    });
    assert_eq!(timed_load(&p).1, malformed);
    p.surface_vertices.retain(|&v| v != lost);
    let (took, result) = timed_load(&p);
    assert_eq!(result, inconsistent("handle_vertices"));
    assert!(took < BUDGET, "refusing a vertex in two handles took {took:?}");
    // A handle that does not list its vertices in ascending order.
    let mut p = one_large_handle();
    for list in [&mut p.handle_vertices, &mut p.handles[0].vertices] {
        list.swap(10, LARGE - 10);
    }
    assert_eq!(timed_load(&p).1, inconsistent("handle_vertices"));
    // A drawn vertex that is neither free nor prescribed.
    let mut p = one_large_handle();
    p.num_vertices += 1;
    p.rest.extend([0.0, 0.0]);
    p.surface_vertices.push(p.num_vertices - 1);
    assert_eq!(timed_load(&p).1, malformed);
    // A free vertex on the strand twice (and another never), far apart, then next to each other.
    for (a, b) in [(3, LARGE - 3), (LARGE / 2, LARGE / 2 + 1)] {
        let mut p = one_large_strand();
        let slots = &mut p.chains[0].slots;
        slots[b] = slots[a];
        let (took, result) = timed_load(&p);
        assert_eq!(result, inconsistent("chains.slots"), "slots {a} and {b}");
        assert!(took < BUDGET, "refusing a repeated slot took {took:?}");
    }
}
