//! The runtime agrees with the trainer: for each committed artifact (positions- and
//! bend-encoded), generated constants and the same artifact loaded from bytes roll out within
//! 1e-4 of the bounding-box diagonal of the trainer's own rollout over 1,000 frames of every
//! test sequence; the surface decode is the full decode restricted to the drawn vertices (up
//! to round-off).
//!
//! Where the trainer's rollout itself diverges (leaves the training envelope, as `mochi eval`
//! counts it), round-off differences grow without bound and agreement means nothing; where the
//! runtime clamps a latent that left the trained range (its documented recovery), it departs
//! from the trainer on purpose. Frames from either point on are not compared, and at least one
//! sequence must run all frames without either.

use std::path::Path;

use mochi_codegen::quantize::weights_f32;
use mochi_runtime::{Model, OwnedModel, Stepped, ValidModel, WeightFormat};
use mochi_sim::bc::BcSequence;
use mochi_sim::dataset::{self, Split};
use mochi_tests::{collider_states, motions};
use mochi_trainer::artifact::Artifact;
use mochi_trainer::eval::runtime_bench::{agreement, ScriptFrame};
use mochi_trainer::eval::{self, LoadedModel as TrainerModel};

const FRAMES: usize = 1000;
const TOLERANCE: f64 = 1e-4;

/// Test sequences of the artifact's scene, `FRAMES` long.
fn test_sequences(
    artifact: &Artifact,
) -> (
    TrainerModel,
    Vec<BcSequence>,
    mochi_sim::BuiltScene,
    mochi_trainer::learn::encoding::Encoding,
) {
    let (problem, encoding) = eval::rebuild_problem(artifact).unwrap();
    let plans = dataset::plan(&problem.scene.dataset);
    let bcs = plans
        .iter()
        .filter(|p| p.split == Split::Test)
        .map(|p| problem.sequence(&p.speeds, FRAMES, p.seed))
        .collect();
    (TrainerModel::new(artifact.clone()).unwrap(), bcs, problem, encoding)
}

/// Largest vertex distance / diagonal between the trainer's and the runtime's rollouts.
fn worst_disagreement<const K: usize, const S: usize, const H: usize>(artifact_path: &Path, model: &ValidModel) -> f64 {
    let artifact = Artifact::read(artifact_path).unwrap();
    let (trainer, bcs, problem, encoding) = test_sequences(&artifact);
    let mut worst = 0.0f64;
    let mut longest = 0;
    for bc in &bcs {
        let reference = eval::stable_rollout(&trainer, &problem, &encoding, bc, FRAMES).unwrap();
        let script: Vec<_> = (1..=FRAMES)
            .map(|t| ScriptFrame {
                motions: motions(bc, t),
                colliders: collider_states(bc, t, model.model().colliders()),
            })
            .collect();
        let (disagreement, compared) = agreement::<K, S, H>(model, &script, &reference, artifact.diagonal).unwrap();
        worst = worst.max(disagreement);
        longest = longest.max(compared);
    }
    assert_eq!(
        longest, FRAMES,
        "no test sequence of {} stays stable for {FRAMES} frames",
        artifact.scene
    );
    worst
}

#[test]
fn generated_tiny_model_agrees_with_the_trainer() {
    use mochi_tests::tiny;
    let model = ValidModel::new(tiny::MODEL).unwrap();
    let worst = worst_disagreement::<{ tiny::LATENT }, { tiny::SIGNAL }, { tiny::HIDDEN }>(
        Path::new("artifacts/tiny.mochi"),
        &model,
    );
    assert!(
        worst <= TOLERANCE,
        "generated tiny model is {worst:.2e} diagonals from the trainer"
    );
}

/// A model with a run-time collider slot (the ball pressing the tiny block): the generated
/// code steps with the test sequences' ball as the trainer does.
#[test]
fn generated_collider_model_agrees_with_the_trainer() {
    use mochi_tests::tiny_poke;
    let model = ValidModel::new(tiny_poke::MODEL).unwrap();
    assert_eq!(model.model().colliders(), 1);
    let worst = worst_disagreement::<{ tiny_poke::LATENT }, { tiny_poke::SIGNAL }, { tiny_poke::HIDDEN }>(
        Path::new("artifacts/tiny-poke.mochi"),
        &model,
    );
    assert!(
        worst <= TOLERANCE,
        "generated tiny-poke model is {worst:.2e} diagonals from the trainer"
    );
}

#[test]
fn generated_strands_model_agrees_with_the_trainer() {
    // Rods encoded by their bends: the runtime walks every strand from its root.
    use mochi_tests::strands;
    let model = ValidModel::new(strands::MODEL).unwrap();
    let worst = worst_disagreement::<{ strands::LATENT }, { strands::SIGNAL }, { strands::HIDDEN }>(
        Path::new("artifacts/strands.mochi"),
        &model,
    );
    assert!(
        worst <= TOLERANCE,
        "generated strands model is {worst:.2e} diagonals from the trainer"
    );
}

/// Runs `f` on a thread with a stack large enough for fixed-capacity storage of a big model
/// (a `heapless` pool is built on the stack before it is boxed).
fn with_big_stack(f: impl FnOnce() + Send + 'static) {
    std::thread::Builder::new()
        .stack_size(256 << 20)
        .spawn(f)
        .unwrap()
        .join()
        .unwrap();
}

#[test]
fn generated_beam_model_agrees_with_the_trainer() {
    use mochi_tests::beam;
    let model = ValidModel::new(beam::MODEL).unwrap();
    let worst = worst_disagreement::<{ beam::LATENT }, { beam::SIGNAL }, { beam::HIDDEN }>(
        Path::new("artifacts/beam.mochi"),
        &model,
    );
    assert!(
        worst <= TOLERANCE,
        "generated beam model is {worst:.2e} diagonals from the trainer"
    );
}

/// The `rods` scene's model (480 bend-encoded vertices, a linear decoder).
#[test]
fn generated_rods_model_agrees_with_the_trainer() {
    use mochi_tests::rods;
    let model = ValidModel::new(rods::MODEL).unwrap();
    let worst = worst_disagreement::<{ rods::LATENT }, { rods::SIGNAL }, { rods::HIDDEN }>(
        Path::new("artifacts/rods.mochi"),
        &model,
    );
    assert!(
        worst <= TOLERANCE,
        "generated rods model is {worst:.2e} diagonals from the trainer"
    );
}

/// The right-sized beam (a basis decoder of 8 modes, `mochi distill`) generated into code.
#[test]
fn generated_right_sized_beam_model_agrees_with_the_trainer() {
    use mochi_tests::beam_m8;
    let model = ValidModel::new(beam_m8::MODEL).unwrap();
    assert!(model.model().decoder_basis, "beam-m8 ends in a linear basis");
    let worst = worst_disagreement::<{ beam_m8::LATENT }, { beam_m8::SIGNAL }, { beam_m8::HIDDEN }>(
        Path::new("artifacts/beam-m8.mochi"),
        &model,
    );
    assert!(
        worst <= TOLERANCE,
        "generated beam-m8 model is {worst:.2e} diagonals from the trainer"
    );
}

/// The right-sized rods (its strands decoded as positions by a basis of 8 modes, `mochi
/// distill --strand-positions`) generated into code: root-relative origins, one per strand.
#[test]
fn generated_right_sized_rods_model_agrees_with_the_trainer() {
    use mochi_tests::rods_m8;
    let model = ValidModel::new(rods_m8::MODEL).unwrap();
    assert!(model.model().decoder_basis, "rods-m8 ends in a linear basis");
    assert!(!model.model().bends(), "rods-m8 decodes its strands as positions");
    let worst = worst_disagreement::<{ rods_m8::LATENT }, { rods_m8::SIGNAL }, { rods_m8::HIDDEN }>(
        Path::new("artifacts/rods-m8.mochi"),
        &model,
    );
    assert!(
        worst <= TOLERANCE,
        "generated rods-m8 model is {worst:.2e} diagonals from the trainer"
    );
}

#[test]
fn beam_model_loaded_from_bytes_agrees_with_the_trainer() {
    with_big_stack(|| {
        use mochi_tests::beam;
        let bytes = std::fs::read("artifacts/beam.mochi").unwrap();
        let mut storage = Box::new(beam::Loaded::new());
        let model = storage.load(&bytes).unwrap();
        let worst = worst_disagreement::<{ beam::LATENT }, { beam::SIGNAL }, { beam::HIDDEN }>(
            Path::new("artifacts/beam.mochi"),
            &model,
        );
        assert!(
            worst <= TOLERANCE,
            "loaded beam model is {worst:.2e} diagonals from the trainer"
        );
    });
}

#[test]
fn tiny_model_loaded_from_bytes_agrees_with_the_trainer() {
    use mochi_tests::tiny;
    let bytes = std::fs::read("artifacts/tiny.mochi").unwrap();
    // Fixed-capacity storage, as on a target (sizes from the generated module).
    let mut storage = Box::new(tiny::Loaded::new());
    let model = storage.load(&bytes).unwrap();
    let worst = worst_disagreement::<{ tiny::LATENT }, { tiny::SIGNAL }, { tiny::HIDDEN }>(
        Path::new("artifacts/tiny.mochi"),
        &model,
    );
    assert!(
        worst <= TOLERANCE,
        "loaded tiny model is {worst:.2e} diagonals from the trainer"
    );
    // The same numbers as the generated constants. The weights layer by layer: a loader with
    // a wide `f32` kernel stores more layers by columns than generated code does.
    let (loaded, generated) = (model.model(), tiny::MODEL);
    // The capacity code generation writes is what a wide-kernel loader fills, from the shapes.
    let capacity = mochi_runtime::artifact::wide_params_len(loaded);
    assert_eq!(capacity, tiny::ARTIFACT_PARAMS_LEN);
    match mochi_runtime::network::fast::width() {
        mochi_runtime::network::Width::Canonical => assert!(loaded.params.len() <= capacity),
        _ => assert_eq!(loaded.params.len(), capacity),
    }
    assert_eq!(loaded.floats, generated.floats);
    assert_eq!(loaded.indices, generated.indices);
    for (a, b) in [
        (loaded.decoder, generated.decoder),
        (loaded.integrator, generated.integrator),
    ] {
        assert_eq!(a.len(), b.len());
        for (la, lb) in a.iter().zip(b) {
            assert_eq!((la.rows, la.cols), (lb.rows, lb.cols));
            assert_eq!(weights_f32(loaded, la), weights_f32(&generated, lb));
            let bias = |m: &mochi_runtime::Model, l: &mochi_runtime::Layer| {
                m.params[l.bias as usize..][..l.rows as usize].to_vec()
            };
            assert_eq!(bias(loaded, la), bias(&generated, lb));
        }
    }
}

#[test]
fn surface_decode_is_the_full_decode_on_the_drawn_vertices() {
    use mochi_tests::tiny;
    let model = ValidModel::new(tiny::MODEL).unwrap();
    let artifact = Artifact::read(Path::new("artifacts/tiny.mochi")).unwrap();
    let (_, bcs, _, _) = test_sequences(&artifact);
    let mut body = tiny::Instance::new(&model).unwrap();
    let (mut full, mut surface) = ([0.0f32; tiny::STATE_LEN], [0.0f32; tiny::SURFACE_LEN]);
    const { assert!(tiny::SURFACE_LEN < tiny::STATE_LEN, "a tet mesh draws only its surface") };
    for t in 1..=50 {
        assert_eq!(body.step(&model, &motions(&bcs[0], t)).unwrap(), Stepped::Ok);
        body.decode_into(&model, &mut full).unwrap();
        body.decode_surface_into(&model, &mut surface).unwrap();
        let d = tiny::DIM;
        for (i, &v) in model.model().surface_vertices().iter().enumerate() {
            let v = v as usize;
            // The kernels may group the rows differently: equal up to f32 round-off.
            for (a, b) in surface[i * d..i * d + d].iter().zip(&full[v * d..v * d + d]) {
                assert!(
                    (a - b).abs() <= 1e-6 * model.model().diagonal,
                    "vertex {v} at frame {t}: {a} vs {b}"
                );
            }
        }
    }
}

#[test]
fn runtime_loads_what_the_trainer_wrote_field_for_field() {
    let artifact = Artifact::read(Path::new("artifacts/tiny.mochi")).unwrap();
    let bytes = std::fs::read("artifacts/tiny.mochi").unwrap();
    let mut storage = OwnedModel::default();
    let valid = storage.load(&bytes).unwrap();
    let m: &Model = valid.model();
    assert_eq!(
        (m.dim, m.num_vertices, m.latent, m.bc_len),
        (artifact.dim, artifact.num_vertices, artifact.latent, artifact.bc_len)
    );
    assert_eq!(m.rest(), &artifact.rest[..]);
    assert_eq!(m.free_vertices(), &artifact.encoding.free_vertices[..]);
    assert_eq!(m.handle_vertices(), &artifact.encoding.handle_vertices[..]);
    assert_eq!(m.surface_vertices(), &artifact.surface_vertices[..]);
    // The triangles the runtime reads (over the drawn vertices) are the trainer's mesh faces.
    let drawn = m.surface_vertices();
    let triangles: Vec<[u32; 3]> = m
        .surface_triangles()
        .chunks(3)
        .map(|t| [0, 1, 2].map(|c| drawn[t[c] as usize]))
        .collect();
    assert!(!triangles.is_empty());
    assert_eq!(triangles, artifact.surface_triangles);
    assert_eq!(m.initial_latent(), &artifact.initial_latent[..]);
    assert_eq!(
        (m.latent_min(), m.latent_max()),
        (&artifact.latent_min[..], &artifact.latent_max[..])
    );
    for (layers, trained) in [(m.decoder, &artifact.decoder), (m.integrator, &artifact.integrator)] {
        assert_eq!(layers.len(), trained.len());
        for (l, t) in layers.iter().zip(trained) {
            // Row by row, whichever layout the loader chose (`WeightFormat::F32Columns`).
            let w = weights_f32(m, l);
            let b = &m.params[l.bias as usize..l.bias as usize + t.bias.len()];
            assert_eq!(
                (l.rows as usize, l.cols as usize, &w[..], b),
                (t.rows, t.cols, &t.weights[..], &t.bias[..])
            );
        }
        // The decoder's output layer is stored column by column: every column padded to a
        // multiple of 16 rows with zeros.
        let output = m.decoder.last().unwrap();
        assert_eq!(output.format, WeightFormat::F32Columns);
        let (rows, cols) = (output.rows as usize, output.cols as usize);
        let stride = mochi_runtime::column_stride(rows);
        let stored = &m.params[output.weights as usize..][..stride * cols];
        let row_major = &artifact.decoder.last().unwrap().weights;
        for c in 0..cols {
            for r in 0..stride {
                let want = if r < rows { row_major[r * cols + c] } else { 0.0 };
                assert_eq!(stored[c * stride + r], want, "column {c}, row {r}");
            }
        }
    }
}
