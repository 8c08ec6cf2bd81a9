//! The render decode against its definition written out in `f64`, and the render mesh's
//! validation.

use super::*;
use crate::payload::{HandleData, LayerData, Payload, RenderData};
use crate::{HandleMotion, LoadError, OwnedModel};
use std::vec;
use std::vec::Vec;

/// A unit tet: a handle on vertices 0, 1 and 2, vertex 3 free; a render mesh of `render`.
fn payload(render: RenderData) -> Payload {
    let layer = |rows: u64, cols: u64, seed: f32| LayerData {
        rows,
        cols,
        weights: (0..rows * cols)
            .map(|i| 0.3 * (seed * (i as f32 + 1.0)).sin())
            .collect(),
        bias: (0..rows).map(|i| 0.05 * i as f32).collect(),
    };
    Payload {
        dt: 0.01,
        dim: 3,
        num_vertices: 4,
        rest: vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        diagonal: 3f64.sqrt(),
        rotates: false,
        handle_vertices: vec![0, 1, 2],
        free_vertices: vec![3],
        origin_of: vec![0],
        root_slots: vec![],
        chains: vec![],
        handles: vec![HandleData {
            vertices: vec![0, 1, 2],
            reference: vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
            pivot: [0.3, 0.3, 0.0],
        }],
        bc_len: 12,
        surface_vertices: vec![0, 1, 2, 3],
        latent: 1,
        initial_latent: vec![0.2],
        latent_min: vec![-1.0],
        latent_max: vec![1.0],
        decoder: vec![layer(4, 1, 0.7), layer(3, 4, 1.3)],
        integrator: vec![layer(4, 38, 0.4), layer(1, 4, 0.9)],
        surface_triangles: vec![0, 2, 1, 0, 1, 3, 1, 2, 3, 0, 3, 2],
        decoder_basis: false,
        dt_range: [0.0; 2],
        collider_shapes: vec![],
        render,
        rate_input: false,
    }
}

/// Five render vertices in the tet (a mix of its corners, one on an edge, a corner, the
/// centroid, one on a face), three triangles over them and texture coordinates.
fn render() -> RenderData {
    let weights: Vec<[f32; 4]> = vec![
        [0.1, 0.2, 0.3, 0.4],
        [0.5, 0.0, 0.5, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.25, 0.25, 0.25, 0.25],
        [0.0, 0.3, 0.3, 0.4],
    ];
    RenderData {
        anchors: (0..5).flat_map(|_| [0, 1, 2, 3]).collect(),
        weights: weights.into_iter().flatten().collect(),
        triangles: vec![0, 2, 1, 1, 2, 4, 0, 4, 3],
        uvs: (0..10).map(|i| i as f32 / 10.0).collect(),
    }
}

fn load(p: &Payload) -> Result<OwnedModel, LoadError> {
    let mut storage = OwnedModel::default();
    storage.load(&p.to_section().unwrap())?;
    Ok(storage)
}

fn refused(render: RenderData) -> Option<(&'static str, Problem)> {
    match load(&payload(render)) {
        Err(LoadError::Invalid(e)) => Some((e.field, e.problem)),
        Ok(_) => None,
        Err(e) => panic!("{e:?}"),
    }
}

/// Barycentric coordinates of `p` in the tet `x[0..4]`, in `f64`.
fn barycentric(x: &[[f64; 3]; 4], p: [f64; 3]) -> [f64; 4] {
    let e = |i: usize| Vector3::from(x[i]) - Vector3::from(x[0]);
    let m = nalgebra::Matrix3::from_columns(&[e(1), e(2), e(3)]);
    let l = m.try_inverse().unwrap() * (Vector3::from(p) - Vector3::from(x[0]));
    [1.0 - l.sum(), l[0], l[1], l[2]]
}

#[test]
fn render_positions_are_the_weighted_tets_and_stay_in_their_hulls() {
    let p = payload(render());
    let storage = load(&p).unwrap();
    let model = storage.model().unwrap();
    let m = model.model();
    assert_eq!((m.render_vertices(), m.render_len()), (5, 15));
    assert_eq!(m.render_uvs(), &p.render.uvs[..]);
    let mut body = Instance::<1, 12, 8>::new(&model).unwrap();
    let turn = HandleMotion {
        translation: [0.2, -0.1, 0.3],
        rotation: [0.0, 0.0, 0.4],
        ..HandleMotion::default()
    };
    let (mut sim, mut positions, mut normals) = (vec![0.0; 12], vec![0.0; 15], vec![0.0; 15]);
    for frame in 0..6 {
        body.step(&model, &[turn]).unwrap();
        body.decode_render_into(&model, &mut sim, &mut positions, &mut normals)
            .unwrap();
        let x: [[f64; 3]; 4] = core::array::from_fn(|v| core::array::from_fn(|c| sim[3 * v + c] as f64));
        for (r, w) in p.render.weights.chunks_exact(4).enumerate() {
            let want: [f64; 3] = core::array::from_fn(|c| (0..4).map(|i| w[i] as f64 * x[i][c]).sum());
            for c in 0..3 {
                let error = (positions[3 * r + c] as f64 - want[c]).abs() / p.diagonal;
                assert!(error < 1e-6, "frame {frame}, vertex {r}: {error}");
            }
            let got = core::array::from_fn(|c| positions[3 * r + c] as f64);
            let hull = barycentric(&x, got);
            assert!(
                hull.iter().all(|&l| l >= -1e-5),
                "frame {frame}, vertex {r} outside its tet: {hull:?}"
            );
        }
        // Normals: unit, and a vertex of one triangle (3, in triangle 0 4 3) has its normal.
        for v in 0..5 {
            let n = Vector3::new(normals[3 * v], normals[3 * v + 1], normals[3 * v + 2]);
            assert!((n.norm() - 1.0).abs() < 1e-5, "vertex {v}: {n:?}");
        }
        let at = |v: usize| Vector3::new(positions[3 * v], positions[3 * v + 1], positions[3 * v + 2]);
        let face = (at(0) - at(3)).cross(&(at(4) - at(3))).normalize();
        let n3 = Vector3::new(normals[9], normals[10], normals[11]);
        assert!((n3 - face).norm() < 1e-5, "{n3:?} vs {face:?}");
    }
}

#[test]
fn normals_are_area_weighted() {
    // Two triangles about vertex 0: a large one in the z = 0 plane and a small one in x = 0.
    let p = payload(RenderData {
        anchors: (0..5).flat_map(|_| [0, 1, 2, 3]).collect(),
        weights: vec![
            1.0, 0.0, 0.0, 0.0, // the origin
            0.0, 1.0, 0.0, 0.0, // (1, 0, 0)
            0.0, 0.0, 1.0, 0.0, // (0, 1, 0)
            0.9, 0.0, 0.1, 0.0, // (0, 0.1, 0)
            0.9, 0.0, 0.0, 0.1, // (0, 0, 0.1)
        ],
        triangles: vec![0, 1, 2, 0, 3, 4],
        uvs: vec![],
    });
    let storage = load(&p).unwrap();
    let model = storage.model().unwrap();
    let rest = model.model().rest();
    let mut positions = [0.0f32; 15];
    render_positions(&model, rest, &mut positions).unwrap();
    let mut normals = [0.0f32; 15];
    render_normals(&model, &positions, &mut normals).unwrap();
    // Areas 1/2 along +z and 1/200 along +x.
    let want = Vector3::new(0.01f32, 0.0, 1.0).normalize();
    assert!((Vector3::new(normals[0], normals[1], normals[2]) - want).norm() < 1e-6);
    assert_eq!(&normals[3..6], &[0.0, 0.0, 1.0]);
    assert_eq!(&normals[9..12], &[1.0, 0.0, 0.0]);
}

#[test]
fn a_model_without_a_render_mesh_decodes_an_empty_one() {
    let storage = load(&payload(RenderData::default())).unwrap();
    let model = storage.model().unwrap();
    assert!(!model.model().has_render());
    let body = Instance::<1, 12, 8>::new(&model).unwrap();
    let mut sim = [0.0; 12];
    body.decode_render_into(&model, &mut sim, &mut [], &mut []).unwrap();
    let wrong = body.decode_render_into(&model, &mut sim, &mut [0.0; 3], &mut []);
    assert_eq!(wrong, Err(DecodeError::BufferLength { expected: 0, found: 3 }));
}

#[test]
fn buffers_of_the_wrong_length_are_refused() {
    let storage = load(&payload(render())).unwrap();
    let model = storage.model().unwrap();
    let body = Instance::<1, 12, 8>::new(&model).unwrap();
    let (mut sim, mut positions, mut normals) = ([0.0; 12], [0.0; 15], [0.0; 15]);
    let short = |expected, found| Err(DecodeError::BufferLength { expected, found });
    assert_eq!(
        body.decode_render_into(&model, &mut sim[..11], &mut positions, &mut normals),
        short(12, 11)
    );
    assert_eq!(
        body.decode_render_into(&model, &mut sim, &mut positions[..14], &mut normals),
        short(15, 14)
    );
    assert_eq!(
        body.decode_render_into(&model, &mut sim, &mut positions, &mut [0.0; 16]),
        short(15, 16)
    );
    assert_eq!(render_positions(&model, &sim[..3], &mut positions), short(12, 3));
    assert_eq!(render_normals(&model, &positions, &mut normals[..3]), short(15, 3));
}

#[test]
fn bad_render_meshes_are_refused_naming_the_field() {
    let with = |f: &dyn Fn(&mut RenderData)| {
        let mut r = render();
        f(&mut r);
        refused(r)
    };
    assert_eq!(with(&|_| {}), None);
    assert_eq!(
        with(&|r| r.anchors[19] = 4),
        Some(("render.anchors", Problem::OutOfRange))
    );
    assert_eq!(
        with(&|r| {
            r.anchors.pop();
        }),
        Some(("render.anchors", length(16, 19)))
    );
    assert_eq!(
        with(&|r| {
            r.weights.truncate(16);
        }),
        Some(("render.weights", length(20, 16)))
    );
    assert_eq!(
        with(&|r| r.weights[2] = f32::NAN),
        Some(("render.weights", Problem::NotFinite))
    );
    // Outside the tet: a negative weight, or weights that do not sum to one.
    assert_eq!(
        with(&|r| r.weights[..4].copy_from_slice(&[-0.1, 0.3, 0.4, 0.4])),
        Some(("render.weights", Problem::Domain))
    );
    assert_eq!(
        with(&|r| r.weights[..4].copy_from_slice(&[0.3, 0.3, 0.3, 0.3])),
        Some(("render.weights", Problem::Domain))
    );
    assert_eq!(
        with(&|r| r.triangles[8] = 5),
        Some(("render.triangles", Problem::OutOfRange))
    );
    assert_eq!(
        with(&|r| {
            r.triangles.pop();
        }),
        Some(("render.triangles", length(6, 8)))
    );
    assert_eq!(
        with(&|r| {
            r.uvs.pop();
        }),
        Some(("render.uvs", length(10, 9)))
    );
    assert_eq!(
        with(&|r| r.uvs[0] = f32::INFINITY),
        Some(("render.uvs", Problem::NotFinite))
    );
    assert_eq!(with(&|r| r.uvs.clear()), None);
    let triangles_alone = RenderData {
        triangles: vec![0, 0, 0],
        ..RenderData::default()
    };
    assert_eq!(refused(triangles_alone), Some(("render.triangles", length(0, 3))));
}
