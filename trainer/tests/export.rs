//! `mochi export`: the rollout it writes is the runtime's own render decode, the `.glb` reads
//! back (with the `gltf` crate) as those frames, and bad requests are refused naming the file.
//! The Khronos validator and trimesh check the files in `scripts/gltf.sh self-check`.

use std::path::PathBuf;

use mochi_runtime::{AnyInstance, OwnedModel, ValidModel};
use mochi_sim::dataset::SpeedPlan;
use mochi_trainer::export::{glb, roll_out, ExportOptions, ExportedMesh, MeshAnimation};
use mochi_trainer::methods::learned::motions;
use mochi_trainer::{Artifact, Recipe};

fn artifacts() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/artifacts")
}

fn options(frames: usize) -> ExportOptions {
    ExportOptions {
        frames,
        ..ExportOptions::default()
    }
}

/// The motion `roll_out` exports by default: the artifact's scene at speed level 0.5 with
/// its dataset seed.
fn exported_motion(path: &std::path::Path, frames: usize) -> mochi_sim::bc::BcSequence {
    let artifact = Artifact::read(path).unwrap();
    let recipe = Recipe::parse(&artifact.scene_toml, std::path::Path::new(&artifact.scene_path)).unwrap();
    recipe
        .build()
        .unwrap()
        .sequence(&SpeedPlan::constant(0.5), frames, recipe.scene.dataset.seed)
}

#[test]
fn the_render_mesh_frames_are_the_runtimes_render_decode() {
    let path = artifacts().join("tiny-render.mochi");
    let frames = 12;
    let animation = roll_out(&path, &options(frames)).unwrap();
    assert_eq!(animation.mesh, ExportedMesh::Render);
    assert_eq!(animation.frames(), frames + 1);
    assert_eq!((animation.vertices(), animation.triangles.len() / 3), (1014, 1728));
    assert_eq!(animation.uvs.len(), 2 * 1014);

    // The runtime stepped directly on the same motion, decoding its render mesh itself.
    let bytes = std::fs::read(&path).unwrap();
    let mut storage = OwnedModel::default();
    let base = *storage.load(&bytes).unwrap().model();
    // As `mochi codegen --weights f32` stores it (the runtime's layout of the weights).
    let options = mochi_codegen::Options::weights(mochi_runtime::WeightFormat::F32);
    let stored = mochi_codegen::Quantized::split(&base, options.decoder, options.integrator);
    let model = ValidModel::new(stored.model(&base)).unwrap();
    let m = model.model();
    let bc = exported_motion(&path, frames);
    let mut body = AnyInstance::new(&model).unwrap();
    let mut sim = vec![0.0; m.state_len()];
    let (mut positions, mut normals) = (vec![0.0; m.render_len()], vec![0.0; m.render_len()]);
    for t in 0..=frames {
        if t > 0 {
            body.step_with(&model, &motions(&bc, t), &[], m.dt).unwrap();
        }
        body.decode_render_into(&model, &mut sim, &mut positions, &mut normals)
            .unwrap();
        for (what, exported, decoded) in [
            ("positions", animation.frame_positions(t), &positions),
            ("normals", animation.frame_normals(t), &normals),
        ] {
            let gap = exported
                .iter()
                .zip(decoded.iter())
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f32::max);
            assert!(gap == 0.0, "frame {t}: {what} {gap} from the runtime's render decode");
        }
    }
    // It moves.
    let last = animation.frame_positions(frames);
    let moved = last
        .iter()
        .zip(animation.frame_positions(0))
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f32::max);
    assert!(moved > 1e-4, "the render mesh moved {moved}");
}

/// Per frame, three floats per vertex.
type Frames = Vec<Vec<[f32; 3]>>;

/// The `.glb`'s positions and normals per frame (base plus morph target), keyframe times and
/// weights, read back with the `gltf` crate.
fn read_back(bytes: &[u8]) -> (Frames, Frames, Vec<f32>, Vec<f32>) {
    let file = gltf::Gltf::from_slice(bytes).unwrap();
    let blob = file.blob.as_deref().unwrap();
    let document = &file.document;
    assert_eq!(document.meshes().count(), 1);
    let primitive = document.meshes().next().unwrap().primitives().next().unwrap();
    let reader = primitive.reader(|b| (b.index() == 0).then_some(blob));
    let base: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
    let base_normals: Vec<[f32; 3]> = reader.read_normals().unwrap().collect();
    let (mut positions, mut normals) = (vec![base.clone()], vec![base_normals.clone()]);
    for (p, n, _) in reader.read_morph_targets() {
        let add = |base: &[[f32; 3]], offsets: Vec<[f32; 3]>| -> Vec<[f32; 3]> {
            base.iter()
                .zip(offsets)
                .map(|(b, o)| [b[0] + o[0], b[1] + o[1], b[2] + o[2]])
                .collect()
        };
        positions.push(add(&base, p.unwrap().collect()));
        normals.push(add(&base_normals, n.unwrap().collect()));
    }
    let animation = document.animations().next().unwrap();
    let channel = animation.channels().next().unwrap();
    assert_eq!(
        channel.target().property(),
        gltf::animation::Property::MorphTargetWeights
    );
    let reader = channel.reader(|b| (b.index() == 0).then_some(blob));
    let times: Vec<f32> = reader.read_inputs().unwrap().collect();
    let weights: Vec<f32> = match reader.read_outputs().unwrap() {
        gltf::animation::util::ReadOutputs::MorphTargetWeights(w) => w.into_f32().collect(),
        _ => panic!("the channel does not animate weights"),
    };
    (positions, normals, times, weights)
}

fn assert_round_trip(animation: &MeshAnimation) {
    let bytes = glb::to_bytes(animation).unwrap();
    let (positions, normals, times, weights) = read_back(&bytes);
    let frames = animation.frames();
    assert_eq!(positions.len(), frames);
    for f in 0..frames {
        for (read, written) in [
            (&positions[f], animation.frame_positions(f)),
            (&normals[f], animation.frame_normals(f)),
        ] {
            for (r, w) in read.iter().flatten().zip(written) {
                assert!(
                    (r - w).abs() <= 1e-5 * (1.0 + w.abs()),
                    "frame {f}: {r} read back, {w} written"
                );
            }
        }
    }
    // Keyframe f at f dt gives its frame's target (f - 1) the whole weight.
    let targets = frames - 1;
    for (f, t) in times.iter().enumerate() {
        assert!((t - (f as f64 * animation.dt) as f32).abs() < 1e-6);
        for k in 0..targets {
            let want = if f > 0 && k == f - 1 { 1.0 } else { 0.0 };
            assert_eq!(weights[f * targets + k], want, "keyframe {f}, target {k}");
        }
    }
}

#[test]
fn the_glb_reads_back_as_the_frames_with_one_target_each() {
    let dir = tempfile::tempdir().unwrap();
    let animation = roll_out(&artifacts().join("tiny-render.mochi"), &options(6)).unwrap();
    assert_round_trip(&animation);
    let out = dir.path().join("tiny-render.glb");
    let written = glb::write(&animation, &out).unwrap();
    assert_eq!(std::fs::metadata(&out).unwrap().len() as usize, written);
    // Normals are unit length wherever a vertex has a triangle of area.
    for n in animation.normals.chunks_exact(3) {
        let length = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        assert!((length - 1.0).abs() < 1e-5, "normal of length {length}");
    }
}

#[test]
fn a_collider_model_exports_its_surface_pushed_out_of_the_collider() {
    let path = artifacts().join("tiny-poke.mochi");
    let frames = 40;
    let animation = roll_out(&path, &options(frames)).unwrap();
    assert_eq!(animation.mesh, ExportedMesh::Surface);
    assert!(animation.uvs.is_empty());
    assert!(animation.pushed_out > 0, "the scene's collider presses into the body");
    assert_round_trip(&animation);
    // No exported vertex lies inside the collider at its pose of that frame.
    let bytes = std::fs::read(&path).unwrap();
    let mut storage = OwnedModel::default();
    let model = *storage.load(&bytes).unwrap().model();
    let bc = exported_motion(&path, frames);
    for t in 0..=frames {
        let states = mochi_trainer::methods::learned::collider_states(&bc, t, model.colliders());
        for (slot, state) in states.iter().enumerate() {
            let collider = mochi_runtime::collider::slot_collider(&model, slot, state).unwrap();
            for p in animation.frame_positions(t).chunks_exact(3) {
                let d = collider.signed_distance([p[0], p[1], p[2]]);
                assert!(d > -1e-5, "frame {t}: a vertex {d} inside collider {slot}");
            }
        }
    }
}

#[test]
fn bad_requests_are_refused_naming_the_file() {
    let strands = artifacts().join("strands.mochi");
    let e = roll_out(&strands, &options(4)).unwrap_err().to_string();
    assert!(e.contains("strands.mochi") && e.contains("no triangles"), "{e}");
    let tiny = artifacts().join("tiny.mochi");
    let e = roll_out(&tiny, &options(0)).unwrap_err().to_string();
    assert!(e.contains("--frames"), "{e}");
    let e = roll_out(
        &tiny,
        &ExportOptions {
            level: -1.0,
            ..options(4)
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("--level"), "{e}");
    let not_a_model = artifacts().join("tiny.toml");
    let e = roll_out(&not_a_model, &options(4)).unwrap_err().to_string();
    assert!(e.contains("tiny.toml"), "{e}");
    let missing = artifacts().join("missing.mochi");
    let e = roll_out(&missing, &options(4)).unwrap_err().to_string();
    assert!(e.contains("missing.mochi"), "{e}");

    // A directory that does not exist: refused naming it, nothing written.
    let animation = roll_out(&tiny, &options(2)).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("no/such/dir/tiny.glb");
    let e = glb::write(&animation, &out).unwrap_err().to_string();
    assert!(e.contains("tiny.glb"), "{e}");
    assert!(!out.exists());
    // A mesh whose positions are not finite is refused before anything is written.
    let mut broken = animation.clone();
    broken.positions[4] = f32::NAN;
    let out = dir.path().join("broken.glb");
    assert!(glb::write(&broken, &out).is_err());
    assert!(
        std::fs::read_dir(dir.path()).unwrap().next().is_none(),
        "nothing half-written"
    );
}
