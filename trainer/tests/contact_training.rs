//! A contact scene's dataset trains a latent model: a small cube dropped on a slab under
//! IPC contact (no handles, so the model's boundary signal is empty), trained, selected,
//! timed in the runtime and evaluated end to end.

use mochi_trainer::{artifact_paths, evaluate, train_scene, Artifact, EvalOptions, Quiet, Recipe, TrainOptions};

const DROP: &str = r#"
name = "tiny-drop"
gravity = [0.0, -9.81, 0.0]
[mesh]
type = "box"
min = [-0.1, 0.02, -0.1]
max = [0.1, 0.22, 0.1]
cells = [2, 2, 2]
[material]
youngs = 1e5
poisson = 0.4
density = 1000.0
[contact]
dhat = 1e-3
friction = 0.5
[[contact.obstacles]]
type = "box"
min = [-1.0, -0.1, -1.0]
max = [1.0, 0.0, 1.0]
[dataset]
train = 2
test = 1
frames = 30
test_frames = 30
[latent]
tolerance = 2e-3
sizes = [2, 4]
autoencoder = { hidden = 16, blocks = 1, epochs = 10, batch = 8, learning_rate = 1e-3, final_learning_rate = 1e-4 }
integrator = { hidden = 16, blocks = 1, epochs = 10, batch = 8, learning_rate = 1e-3, final_learning_rate = 1e-4 }
[latent.selection]
decoders = ["linear", "mlp"]
integrator_widths = [16]
"#;

#[test]
fn a_contact_scene_without_handles_trains_and_evaluates() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tiny-drop.toml");
    std::fs::write(&path, DROP).unwrap();
    let recipe = Recipe::load(path.to_str().unwrap()).unwrap();
    assert!(recipe.scene.contact.is_some() && recipe.scene.handles.is_empty());
    let out = dir.path().join("out");
    let options = TrainOptions {
        out_dir: out.clone(),
        resume: false,
        latent: None,
        frame_memory: mochi_trainer::FRAME_MEMORY,
    };
    let outcome = train_scene(&recipe, &options, &Quiet).unwrap_or_else(|e| panic!("{e:#}"));
    // Every candidate was timed in the runtime, whose boundary signal is empty here.
    let candidates = &outcome.model.summary.candidates;
    assert!(!candidates.is_empty());
    assert!(
        candidates.iter().all(|c| c.storages.iter().all(|(_, _, us)| *us > 0.0)),
        "{candidates:?}"
    );
    assert_eq!(candidates.iter().filter(|c| c.kept).count(), 1, "{candidates:?}");
    let (model_path, _) = artifact_paths(&out, "tiny-drop");
    let artifact = Artifact::read(&model_path).unwrap();
    assert_eq!((artifact.handles.len(), artifact.bc_len), (0, 0));
    evaluate(
        std::slice::from_ref(&model_path),
        &EvalOptions {
            out_dir: dir.path().join("eval"),
            stability_frames: 60,
            accuracy_frames: 30,
            adaptive: true,
            full_space_reference: false,
        },
        &Quiet,
    )
    .unwrap_or_else(|e| panic!("{e:#}"));
    let report = std::fs::read_to_string(dir.path().join("eval/report.md")).unwrap();
    assert!(report.contains("tiny-drop"), "{report}");
    // The adaptive solver stepped every test sequence, against the same reference.
    let section = &report[report.find("## Adaptive subspace solver").expect("adaptive section")..];
    let rows: Vec<Vec<f64>> = section
        .lines()
        .filter(|l| l.starts_with("| test-"))
        .map(|l| l.split('|').skip(2).filter_map(|c| c.trim().parse().ok()).collect())
        .collect();
    assert!(!rows.is_empty(), "{section}");
    for row in &rows {
        // mean and max error (% of the diagonal), ms per step: finite, the error bounded.
        assert!(row.len() == 5 && row.iter().all(|v| v.is_finite()), "{section}");
        assert!(row[0] < 10.0 && row[2] > 0.0, "{section}");
    }
}
