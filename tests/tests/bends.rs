//! Rods encoded by their bends (`[latent] rods = "bends"`, `artifacts/strands.mochi`) in the
//! runtime: decoded positions agree with the trainer's `Encoding::decode` of the same encoded
//! state within 1e-5 of the diagonal, the artifact round-trips and loads field for field,
//! generated constants and the artifact loaded from bytes decode alike (within 1e-5 of the
//! diagonal; the surface decode the full decode's bits), and malformed
//! strands are refused naming the field.

use std::path::Path;

use mochi_codegen::quantize::weights_f32;
use mochi_runtime::{AnyInstance, LoadError, Model, OwnedModel, Problem, ValidModel};
use mochi_sim::bc::BcSequence;
use mochi_sim::dataset::{self, Split};
use mochi_sim::BuiltScene as Scene;
use mochi_tests::{motions, strands};
use mochi_trainer::artifact::Artifact;
use mochi_trainer::eval;
use mochi_trainer::learn::encoding::Encoding;
use mochi_trainer::learn::network::DenseLayer;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const PATH: &str = "artifacts/strands.mochi";
/// Frames of each test sequence decoded.
const FRAMES: usize = 300;
/// Largest vertex distance between the runtime's and the trainer's decode, over the diagonal.
const TOLERANCE: f64 = 1e-5;

fn artifact() -> Artifact {
    Artifact::read(Path::new(PATH)).unwrap()
}

/// The rebuilt scene of `artifact`, its encoding and its test sequences, `frames` long.
fn scene(artifact: &Artifact, frames: usize) -> (Scene, Encoding, Vec<BcSequence>) {
    let (problem, encoding) = eval::rebuild_problem(artifact).unwrap();
    assert!(encoding.strand_bends(), "strands.mochi must be bend-encoded");
    let bcs = dataset::plan(&problem.scene.dataset)
        .iter()
        .filter(|p| p.split == Split::Test)
        .map(|p| problem.sequence(&p.speeds, frames, p.seed))
        .collect();
    (problem, encoding, bcs)
}

/// Largest vertex distance / diagonal between a runtime decode and the trainer's.
fn distance(runtime: &[f32], trainer: &[f64], diagonal: f64) -> f64 {
    mochi_sim::measure::vertex_errors(runtime, trainer, 3, diagonal).fold(0.0, f64::max)
}

#[test]
fn runtime_bend_decode_agrees_with_the_trainer_encoding() {
    let a = artifact();
    let (problem, encoding, bcs) = scene(&a, FRAMES);
    let decoder = a.decoder().unwrap();
    let model = ValidModel::new(strands::MODEL).unwrap();
    let mut x = [0.0f32; strands::STATE_LEN];
    let (mut worst, mut largest_bend) = (0.0f64, 0.0f32);
    for bc in &bcs {
        let mut body = strands::Instance::new(&model).unwrap();
        for t in 1..=FRAMES {
            body.step(&model, &motions(bc, t)).unwrap();
            body.decode_into(&model, &mut x).unwrap();
            // The trainer decodes the same latent: its decoder, then its encoding.
            let q = decoder.decode(body.latent()).unwrap();
            largest_bend = q.iter().fold(largest_bend, |m, v| m.max(v.abs()));
            let q: Vec<f64> = q.iter().map(|&v| v as f64).collect();
            let want = encoding.decode(&q, &bc.targets(&problem.handles, t, 3)).unwrap();
            worst = worst.max(distance(&x, &want, a.diagonal));
        }
    }
    assert!(largest_bend > 0.0, "the decoder bends nothing");
    assert!(
        worst <= TOLERANCE,
        "runtime decode is {worst:.2e} diagonals from the trainer's"
    );
}

#[test]
fn arbitrary_bends_decode_as_in_the_trainer() {
    // A decoder that outputs a chosen encoded state whatever the latent (zero weights, the
    // state as the last bias), so both sides decode exactly the same numbers: every edge bent
    // by up to 2 atan(2 sqrt 2) = 141 degrees, the roots translating and turning.
    let mut a = artifact();
    let (problem, encoding, bcs) = scene(&a, 60);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let hidden = 8;
    let k = a.latent as usize;
    for round in 0..4 {
        let mut q = vec![0.0f32; a.encoded_len()];
        for chain in &a.encoding.chains {
            for (&j, &length) in chain.slots.iter().zip(&chain.lengths) {
                for c in 0..2 {
                    q[2 * j as usize + c] = length * rng.random_range(-2.0..2.0) * (round as f32 / 3.0);
                }
            }
        }
        a.decoder = vec![
            DenseLayer {
                rows: hidden,
                cols: k,
                weights: vec![0.0; hidden * k],
                bias: vec![0.0; hidden],
            },
            DenseLayer {
                rows: q.len(),
                cols: hidden,
                weights: vec![0.0; hidden * q.len()],
                bias: q.clone(),
            },
        ];
        let bytes = a.to_bytes().unwrap();
        // The trainer accepts it (its own checks and the runtime's).
        Artifact::from_bytes(&bytes, Path::new("bent.mochi")).unwrap();
        let mut storage = OwnedModel::default();
        let model = storage.load(&bytes).unwrap();
        let q: Vec<f64> = q.iter().map(|&v| v as f64).collect();
        let mut x = vec![0.0f32; model.model().state_len()];
        let mut worst = 0.0f64;
        for bc in &bcs {
            let mut body = AnyInstance::new(&model).unwrap();
            for t in 1..=60 {
                body.step(&model, &motions(bc, t)).unwrap();
                body.decode_into(&model, &mut x).unwrap();
                let want = encoding.decode(&q, &bc.targets(&problem.handles, t, 3)).unwrap();
                worst = worst.max(distance(&x, &want, a.diagonal));
            }
        }
        assert!(
            worst <= TOLERANCE,
            "round {round}: runtime decode is {worst:.2e} diagonals from the trainer's"
        );
    }
}

#[test]
fn strands_artifact_round_trips_and_loads_field_for_field() {
    let a = artifact();
    let bytes = std::fs::read(PATH).unwrap();
    assert_eq!(
        a.to_bytes().unwrap(),
        bytes,
        "the artifact re-serialises to the same bytes"
    );
    let mut storage = OwnedModel::default();
    let valid = storage.load(&bytes).unwrap();
    let m: &Model = valid.model();
    assert!(m.bends());
    assert_eq!(m.encoded_len(), a.encoded_len());
    assert_eq!(m.chains().count(), a.encoding.chains.len());
    for (c, want) in m.chains().zip(&a.encoding.chains) {
        assert_eq!(c.parent, want.parent);
        assert_eq!(c.rest_normal, want.rest_normal);
        assert_eq!(c.slots, &want.slots[..]);
        assert_eq!(c.lengths, &want.lengths[..]);
    }
    // The generated constants hold the same numbers (the weights layer by layer: a loader
    // with a wide `f32` kernel stores more layers by columns than generated code does).
    let generated = strands::MODEL;
    for (a, b) in [(m.decoder, generated.decoder), (m.integrator, generated.integrator)] {
        assert_eq!(a.len(), b.len());
        for (la, lb) in a.iter().zip(b) {
            assert_eq!(weights_f32(m, la), weights_f32(&generated, lb));
            let bias = |m: &Model, l: &mochi_runtime::Layer| m.params[l.bias as usize..][..l.rows as usize].to_vec();
            assert_eq!(bias(m, la), bias(&generated, lb));
        }
    }
    assert_eq!(m.floats, generated.floats);
    assert_eq!(m.indices, generated.indices);
    assert_eq!(
        (m.chains, m.chain_floats, m.chain_order),
        (generated.chains, generated.chain_floats, generated.chain_order)
    );
    // The loader's inverse of the strands' slots.
    let order = m.chain_order.of(m.indices).unwrap();
    assert_eq!(order.len(), m.free_vertices().len());
    for (p, j) in m.chains().flat_map(|c| c.slots.iter().copied()).enumerate() {
        assert_eq!(order[j as usize] as usize, p);
    }
}

#[test]
fn generated_and_loaded_strands_decode_alike() {
    let a = artifact();
    let (_, _, bcs) = scene(&a, FRAMES);
    let generated = ValidModel::new(strands::MODEL).unwrap();
    let bytes = std::fs::read(PATH).unwrap();
    let mut storage = Box::new(strands::Loaded::new());
    let loaded = storage.load(&bytes).unwrap();
    let (mut a_body, mut b_body) = (
        strands::Instance::new(&generated).unwrap(),
        strands::Instance::new(&loaded).unwrap(),
    );
    let (mut xa, mut xb) = ([0.0f32; strands::STATE_LEN], [0.0f32; strands::STATE_LEN]);
    let diagonal = mochi_target_common::diagonal(generated.model().rest(), 3);
    let mut surface = [0.0f32; strands::SURFACE_LEN];
    for t in 1..=FRAMES {
        let bc = motions(&bcs[0], t);
        assert_eq!(a_body.step(&generated, &bc), b_body.step(&loaded, &bc));
        a_body.decode_into(&generated, &mut xa).unwrap();
        b_body.decode_into(&loaded, &mut xb).unwrap();
        // Where the loader stored layers by columns for a wide kernel, the `f32` sums are
        // ordered differently: the two agree as `f32` targets do, within 1e-5 of the diagonal.
        let worst = xa.iter().zip(&xb).fold(0.0f32, |w, (a, b)| w.max((a - b).abs()));
        assert!(
            worst <= 1e-5 * diagonal,
            "frame {t}: {worst:.3e} apart (diagonal {diagonal})"
        );
        // The surface decode walks the same strands: the same bits on the drawn vertices.
        b_body.decode_surface_into(&loaded, &mut surface).unwrap();
        for (i, &v) in loaded.model().surface_vertices().iter().enumerate() {
            let v = v as usize;
            assert_eq!(surface[3 * i..3 * i + 3], xb[3 * v..3 * v + 3], "vertex {v}, frame {t}");
        }
    }
}

#[test]
fn malformed_strands_are_refused_naming_the_field() {
    type Edit = fn(&mut Artifact);
    let cases: [(Edit, &str, Problem); 6] = [
        (
            |a| {
                a.encoding.chains[0].lengths.pop();
            },
            "chains.lengths",
            Problem::Length { expected: 6, found: 5 },
        ),
        (
            |a| a.encoding.chains[0].lengths[2] = 0.0,
            "chains.lengths",
            Problem::Domain,
        ),
        (
            |a| a.encoding.chains[1].rest_normal = [1.0, 1.0, 0.0],
            "chains.rest_normal",
            Problem::Domain,
        ),
        (
            |a| a.encoding.chains[0].parent[0] = 1000,
            "chains.parent",
            Problem::OutOfRange,
        ),
        (
            |a| a.encoding.chains[1].slots[0] = a.encoding.chains[0].slots[0],
            "chains.slots",
            Problem::Inconsistent,
        ),
        (
            |a| {
                a.encoding.chains.pop();
            },
            "chains.slots",
            Problem::Length {
                expected: 24,
                found: 18,
            },
        ),
    ];
    let good = artifact();
    for (edit, field, problem) in cases {
        let mut bad = good.clone();
        edit(&mut bad);
        let bytes = bad.to_bytes().unwrap();
        // The trainer names the artifact field ...
        let err = Artifact::from_bytes(&bytes, Path::new("bad.mochi"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("bad.mochi") && err.contains("encoding.chains"),
            "{field}: {err}"
        );
        // ... and the runtime the model field, without panicking.
        let e = match OwnedModel::default().load(&bytes) {
            Err(LoadError::Invalid(e)) => e,
            other => panic!("{field}: {other:?}"),
        };
        assert_eq!((e.field, e.problem), (field, problem));
    }
}
