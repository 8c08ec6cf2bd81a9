//! Tests of [`crate::instance`]: bend-encoded strands decoded to known shapes, turned with
//! their handle, the surface decode against the full decode, malformed strands refused.

use std::vec::Vec;

use super::*;
use crate::frame::HandleMotion;
use crate::model::{Handle, Problem, Span};

/// Hidden width of the test networks.
const HIDDEN: usize = 8;
/// Rest length of every edge of the test strand.
const L: f32 = 0.1;
/// The instance type of the test model.
type Body = Instance<1, 12, HIDDEN>;

/// A one-strand model: vertices 0 and 1 prescribed (one handle), 2, 3 and 4 free, hanging
/// along -y at spacing `L`, the chain tables as the trainer writes them and the loader
/// completes them (`chain_order`); networks of zeros whose decoder outputs the bends `q`
/// whatever the latent.
struct Strand {
    params: Vec<f32>,
    floats: Vec<f32>,
    indices: Vec<u32>,
    decoder: [Layer; 2],
    integrator: [Layer; 2],
    handles: [Handle; 1],
    rotates: bool,
    spans: [Span; 13],
}

/// Appends `values` to `pool`; their span.
fn push<T: Copy>(pool: &mut Vec<T>, values: &[T]) -> Span {
    let span = Span {
        start: pool.len() as u32,
        len: values.len() as u32,
    };
    pool.extend_from_slice(values);
    span
}

impl Strand {
    fn new(q: [f32; 6], rotates: bool) -> Self {
        let mut params = Vec::new();
        let mut layer = |rows: usize, cols: usize, bias: &[f32]| Layer {
            rows: rows as u32,
            cols: cols as u32,
            weights: push(&mut params, &std::vec![0.0; rows * cols]).start,
            bias: push(&mut params, bias).start,
            ..Layer::default()
        };
        let decoder = [layer(HIDDEN, 1, &[0.0; HIDDEN]), layer(6, HIDDEN, &q)];
        let integrator = [layer(HIDDEN, 2 + 3 * 12, &[0.0; HIDDEN]), layer(1, HIDDEN, &[0.0])];
        let (mut floats, mut indices) = (Vec::new(), Vec::new());
        let rest: Vec<f32> = (0..5).flat_map(|i| [0.0, -L * i as f32, 0.0]).collect();
        let spans = [
            push(&mut floats, &rest),
            push(&mut floats, &[0.0]),
            push(&mut floats, &[-1.0]),
            push(&mut floats, &[1.0]),
            push(&mut indices, &[0, 1]),
            push(&mut indices, &[2, 3, 4]),
            push(&mut indices, &[0, 0, 0]),
            push(&mut indices, &[0]),
            push(&mut indices, &[0, 1, 3, 0, 1, 2]),
            push(&mut floats, &[1.0, 0.0, 0.0, L, L, L]),
            push(&mut indices, &[0, 1, 2, 3, 4]),
            push(&mut indices, &[HANDLE_SOURCE, HANDLE_SOURCE | 1, 0, 1, 2]),
            push(&mut indices, &[0, 1, 2]),
        ];
        let handles = [Handle {
            vertices: spans[4],
            reference: push(&mut floats, &rest[..6]),
            pivot: [0.0, -0.05, 0.0],
        }];
        Strand {
            params,
            floats,
            indices,
            decoder,
            integrator,
            handles,
            rotates,
            spans,
        }
    }

    fn model(&self) -> Model<'_> {
        let [rest, initial_latent, latent_min, latent_max, handle_vertices, free_vertices, origin_of, root_slots, chains, chain_floats, surface_vertices, surface_source, chain_order] =
            self.spans;
        Model {
            dim: 3,
            num_vertices: 5,
            latent: 1,
            bc_len: 12,
            dt: 0.03,
            diagonal: 0.4,
            rotates: self.rotates,
            params: &self.params,
            halves: &[],
            bytes: &[],
            floats: &self.floats,
            indices: &self.indices,
            decoder: &self.decoder,
            decoder_basis: false,
            dt_min: 0.0,
            dt_max: 0.0,
            rate_input: false,
            collider_shapes: Span { start: 0, len: 0 },
            render_anchors: Span { start: 0, len: 0 },
            render_weights: Span { start: 0, len: 0 },
            render_triangles: Span { start: 0, len: 0 },
            render_uvs: Span { start: 0, len: 0 },
            integrator: &self.integrator,
            handles: &self.handles,
            rest,
            handle_vertices,
            free_vertices,
            origin_of,
            root_slots,
            chains,
            chain_floats,
            chain_order,
            surface_vertices,
            surface_source,
            surface_triangles: Span::default(),
            initial_latent,
            latent_min,
            latent_max,
        }
    }

    /// The full decode after one step to the handle pose `motion`.
    fn decode(&self, motion: HandleMotion) -> [f32; 15] {
        let model = ValidModel::new(self.model()).unwrap();
        let mut body = Body::new(&model).unwrap();
        body.step(&model, &[motion]).unwrap();
        let mut x = [0.0; 15];
        body.decode_into(&model, &mut x).unwrap();
        x
    }
}

fn close(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(a, b)| (a - b).abs() <= 1e-6)
}

#[test]
fn bends_decode_known_shapes_at_rest_length() {
    let rest = HandleMotion::REST;
    // No bend: the strand continues its parent edge.
    let straight = Strand::new([0.0; 6], false).decode(rest);
    let want: Vec<f32> = (0..5).flat_map(|i| [0.0, -L * i as f32, 0.0]).collect();
    assert!(close(&straight, &want), "{straight:?}");
    // A bend of tan(45 deg) about u = x (the rest normal) turns d = -y by 90 degrees into
    // -w = -z; the next edges continue straight.
    let bent = Strand::new([L, 0.0, 0.0, 0.0, 0.0, 0.0], false).decode(rest);
    let want = [
        0.0,
        0.0,
        0.0,
        0.0,
        -L,
        0.0,
        0.0,
        -L,
        -L,
        0.0,
        -L,
        -2.0 * L,
        0.0,
        -L,
        -3.0 * L,
    ];
    assert!(close(&bent, &want), "{bent:?}");
    // Any bends keep every edge at its rest length.
    let random = Strand::new([0.3, -0.7, 2.0, 0.05, -1.5, 0.9], false).decode(rest);
    for e in 1..4 {
        let edge: f32 = (0..3)
            .map(|c| (random[3 * e + 3 + c] - random[3 * e + c]).powi(2))
            .sum();
        assert!((edge.sqrt() - L).abs() < 1e-6, "edge {e}: {}", edge.sqrt());
    }
}

#[test]
fn bends_turn_with_a_rotating_handle() {
    let q = [0.03, -0.05, 0.08, 0.02, -0.04, 0.06];
    let strand = Strand::new(q, true);
    let at_rest = strand.decode(HandleMotion::REST);
    let (t, r) = ([0.2f32, -0.1, 0.3], [0.3f32, 0.9, -0.4]);
    let moved = strand.decode(HandleMotion {
        translation: t,
        rotation: r,
        ..HandleMotion::REST
    });
    // Rodrigues in f64: the pose applied to the rest decode.
    let angle = r.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt();
    let k = r.map(|v| v as f64 / angle);
    let pivot = [0.0, -0.05, 0.0];
    for v in 0..5 {
        let p: [f64; 3] = core::array::from_fn(|c| at_rest[3 * v + c] as f64 - pivot[c]);
        let kxp = [
            k[1] * p[2] - k[2] * p[1],
            k[2] * p[0] - k[0] * p[2],
            k[0] * p[1] - k[1] * p[0],
        ];
        let kp = k[0] * p[0] + k[1] * p[1] + k[2] * p[2];
        for c in 0..3 {
            let want =
                pivot[c] + t[c] as f64 + p[c] * angle.cos() + kxp[c] * angle.sin() + k[c] * kp * (1.0 - angle.cos());
            let got = moved[3 * v + c] as f64;
            assert!((got - want).abs() < 1e-5, "vertex {v}: {got} vs {want}");
        }
    }
}

#[test]
fn bends_surface_decode_is_the_full_decode() {
    let strand = Strand::new([0.3, -0.7, 2.0, 0.05, -1.5, 0.9], true);
    let model = ValidModel::new(strand.model()).unwrap();
    let mut body = Body::new(&model).unwrap();
    let motion = HandleMotion {
        translation: [0.1, 0.2, 0.3],
        rotation: [0.5, 0.0, 0.2],
        ..HandleMotion::REST
    };
    body.step(&model, &[motion]).unwrap();
    let (mut full, mut surface) = ([0.0; 15], [0.0; 15]);
    body.decode_into(&model, &mut full).unwrap();
    body.decode_surface_into(&model, &mut surface).unwrap();
    assert_eq!(full, surface);
    // Only some vertices drawn: the same bits for those.
    let mut drawn = strand;
    let sources = push(&mut drawn.indices, &[HANDLE_SOURCE, 2]);
    drawn.spans[10] = push(&mut drawn.indices, &[0, 4]);
    drawn.spans[11] = sources;
    let model = ValidModel::new(drawn.model()).unwrap();
    let mut some = [0.0; 6];
    body.decode_surface_into(&model, &mut some).unwrap();
    assert_eq!(some[..3], full[..3]);
    assert_eq!(some[3..], full[12..]);
}

#[test]
fn malformed_chains_are_refused_naming_the_field() {
    let good = Strand::new([0.0; 6], false);
    assert!(good.model().validate().is_ok());
    let refused = |edit: &dyn Fn(&mut Strand)| {
        let mut s = Strand::new([0.0; 6], false);
        edit(&mut s);
        let e = s.model().validate().unwrap_err();
        (e.field, e.problem)
    };
    let (chains, chain_floats) = (good.spans[8].start as usize, good.spans[9].start as usize);
    type Edit<'e> = &'e dyn Fn(&mut Strand);
    let order = good.spans[12].start as usize;
    let cases: [(Edit, &str, Problem); 12] = [
        (&|s| s.indices[chains] = 2, "chains.parent", Problem::OutOfRange),
        (&|s| s.indices[chains] = 1, "chains.parent", Problem::Inconsistent),
        (&|s| s.indices[chains + 2] = 9, "chains", Problem::Inconsistent),
        (&|s| s.indices[chains + 4] = 3, "chains.slots", Problem::OutOfRange),
        (&|s| s.indices[chains + 4] = 0, "chains.slots", Problem::Inconsistent),
        (
            &|s| s.indices.swap(order, order + 1),
            "chain_order",
            Problem::Inconsistent,
        ),
        (
            &|s| s.spans[12].len -= 1,
            "chain_order",
            Problem::Length { expected: 3, found: 2 },
        ),
        (&|s| s.floats[chain_floats] = 1.1, "chains.rest_normal", Problem::Domain),
        (
            &|s| s.floats[chain_floats + 1] = f32::NAN,
            "chains.rest_normal",
            Problem::NotFinite,
        ),
        (&|s| s.floats[chain_floats + 4] = 0.0, "chains.lengths", Problem::Domain),
        (
            &|s| s.spans[9].len -= 1,
            "chains.lengths",
            Problem::Length { expected: 6, found: 5 },
        ),
        (
            &|s| s.spans[8].start = s.indices.len() as u32,
            "chains",
            Problem::OutOfRange,
        ),
    ];
    for (edit, field, problem) in cases {
        assert_eq!(refused(edit), (field, problem));
    }
    // A strand that covers only two of the three free vertices.
    let short = refused(&|s| {
        s.indices[chains + 2] = 2;
        s.spans[8].len -= 1;
        s.spans[9].len -= 1;
    });
    assert_eq!(short, ("chains.slots", Problem::Length { expected: 3, found: 2 }));
}
