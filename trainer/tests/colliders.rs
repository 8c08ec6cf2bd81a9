//! Run-time colliders as inputs of the learned integrator, end to end on a tiny poked block:
//! `mochi train` gives the model one collider slot (its shape in the artifact, twelve inputs
//! more in the integrator), the trainer's rollout and the runtime agree with the colliders
//! moving, the model reads them, a model trained without collider inputs has none, and
//! `mochi eval` measures penetration with and without the runtime's push-out.

use std::path::{Path, PathBuf};

use mochi_runtime::collider::{FEATURES_PER_COLLIDER, SPHERE};
use mochi_runtime::OwnedModel;
use mochi_sim::dataset::{self, Split};
use mochi_trainer::eval::{carried_encoding, rebuild_problem, roll, LoadedModel};
use mochi_trainer::methods::learned::LearnedRuntime;
use mochi_trainer::methods::method::Method;
use mochi_trainer::{evaluate, train_scene, Artifact, EvalOptions, Quiet, Recipe, TrainOptions};

fn fixture() -> String {
    include_str!("../sim/tests/fixtures/tiny-poke.toml").to_string()
}

/// Trains the tiny poke scene (`text`) into `dir/out`; returns the model's path.
fn train(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).unwrap();
    let recipe = Recipe::load(path.to_str().unwrap()).unwrap();
    let options = TrainOptions {
        out_dir: dir.join(name),
        resume: false,
        latent: None,
        frame_memory: mochi_trainer::FRAME_MEMORY,
    };
    train_scene(&recipe, &options, &Quiet).unwrap();
    dir.join(name).join("tiny-poke.mochi")
}

#[test]
fn a_model_of_a_scene_with_colliders_reads_them_in_the_trainer_and_the_runtime_alike() {
    let dir = tempfile::tempdir().unwrap();
    let path = train(dir.path(), "with", &fixture());
    let model = Artifact::read(&path).unwrap();
    // One slot, the ball's shape row, and twelve more integrator inputs than latents and signals.
    assert_eq!(model.collider_shapes, vec![SPHERE as f32, 0.02, 0.0, 0.0]);
    let k = model.latent as usize;
    let width = 2 * k + 3 * model.bc_len as usize + FEATURES_PER_COLLIDER;
    assert_eq!(model.integrator[0].cols, width);
    let baseline = Artifact::read(&path.with_file_name("tiny-poke.supervised.mochi")).unwrap();
    assert_eq!(baseline.collider_shapes, model.collider_shapes);

    // The trainer's rollout and the runtime's, the ball moving along a test path.
    let (problem, _) = rebuild_problem(&model).unwrap();
    let plan = dataset::plan(&problem.scene.dataset)
        .into_iter()
        .find(|p| p.split == Split::Test)
        .unwrap();
    let frames = 40;
    let bc = problem.sequence(&plan.speeds, frames, plan.seed);
    let loaded = LoadedModel::new(model.clone()).unwrap();
    let own = carried_encoding(&model, &problem).unwrap();
    let mut trainer = Vec::new();
    roll(&loaded, &problem, &own, &bc, frames, |_, _, _, x| {
        trainer.push(x.to_vec());
        true
    })
    .unwrap();
    let bytes = model.to_bytes().unwrap();
    let mut storage = OwnedModel::default();
    let valid = storage.load(&bytes).unwrap();
    assert_eq!(valid.model().colliders(), 1);
    let mut runtime = LearnedRuntime::new(&valid, "learned", String::new()).unwrap();
    runtime.reset(&bc).unwrap();
    let diagonal = problem.mesh.rest_diagonal();
    for (t, x) in trainer.iter().enumerate() {
        runtime.step(&bc, t + 1).unwrap();
        let gap = runtime
            .positions()
            .iter()
            .zip(x)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(gap <= 1e-5 * diagonal, "frame {}: {gap:e}", t + 1);
    }

    // The model reads the ball: with the ball held where it starts (outside the block) the
    // same handles give other states once the moving ball has come near.
    let mut parked = bc.clone();
    for track in &mut parked.colliders {
        let first = track.poses[0];
        track.poses.iter_mut().for_each(|p| *p = first);
        track.velocities.iter_mut().for_each(|v| *v = [0.0; 6]);
    }
    let mut still = Vec::new();
    roll(&loaded, &problem, &own, &parked, frames, |_, _, _, x| {
        still.push(x.to_vec());
        true
    })
    .unwrap();
    assert_ne!(still.last(), trainer.last(), "the ball's motion changed nothing");
}

#[test]
fn a_model_trained_without_collider_inputs_has_none_and_eval_measures_penetration_of_both() {
    let dir = tempfile::tempdir().unwrap();
    let blind_text = fixture().replace("[latent]\n", "[latent]\ncollider_inputs = false\n");
    let seeing = train(dir.path(), "with", &fixture());
    let blind = train(dir.path(), "without", &blind_text);
    let model = Artifact::read(&blind).unwrap();
    assert!(model.collider_shapes.is_empty());
    assert_eq!(
        model.integrator[0].cols,
        2 * model.latent as usize + 3 * model.bc_len as usize
    );
    for (path, name) in [(&seeing, "with"), (&blind, "without")] {
        let options = EvalOptions {
            out_dir: dir.path().join(format!("eval-{name}")),
            stability_frames: 200,
            accuracy_frames: 40,
            adaptive: false,
            full_space_reference: false,
        };
        let (reports, _) = evaluate(std::slice::from_ref(path), &options, &Quiet).unwrap();
        for r in &reports {
            for (plan, m) in &r.sequences {
                let p = m
                    .penetration
                    .as_ref()
                    .unwrap_or_else(|| panic!("{name} {}: no penetration", plan.name));
                assert!(p.frames > 0 && p.dhat == 1e-3, "{name}: {p:?}");
                assert!((0.0..=1.0).contains(&p.inside_share) && p.deep_share <= p.inside_share);
                // The push-out leaves no surface vertex inside (up to f32 rounding).
                assert!(p.pushed_max_depth <= 1e-6, "{name}: {p:?}");
                assert!(p.pushed_mean_error.is_finite());
            }
        }
        let page = std::fs::read_to_string(dir.path().join(format!("eval-{name}/report.md"))).unwrap();
        assert!(page.contains("## Colliders") && page.contains("pushed out"), "{page}");
    }
}
