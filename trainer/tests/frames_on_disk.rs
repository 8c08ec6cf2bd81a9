//! Training past the memory budget and evaluating against full space: a tiny scene stepped
//! by the adaptive solver trains with its frames read back from disk (the model is the one
//! trained with every frame in memory, to round-off), and `mochi eval --full-space-reference`
//! measures it, its twin and the adaptive solver against a full-space test split of its own.

use mochi_sim::dataset::manifest::{Manifest, MANIFEST};
use mochi_trainer::{evaluate, train_scene, EvalOptions, Quiet, Recipe, TrainOptions};
use std::path::Path;

const TINY: &str = include_str!("../sim/tests/fixtures/tiny-train.toml");

/// The tiny scene, stepped by the adaptive solver, with the MLP decoder only.
fn adaptive_scene(dir: &Path) -> Recipe {
    let path = dir.join("tiny.toml");
    let text = format!("{TINY}\n[latent.selection]\ndecoders = [\"mlp\"]\n[solver]\nkind = \"adaptive\"\n");
    std::fs::write(&path, text).unwrap();
    Recipe::load(path.to_str().unwrap()).unwrap()
}

fn options(out: &Path, frame_memory: u64) -> TrainOptions {
    TrainOptions {
        out_dir: out.to_path_buf(),
        resume: false,
        latent: None,
        frame_memory,
    }
}

#[test]
fn frames_read_from_disk_train_the_model_memory_trains_and_eval_meets_full_space() {
    let dir = tempfile::tempdir().unwrap();
    let recipe = adaptive_scene(dir.path());
    let (memory_out, disk_out) = (dir.path().join("memory"), dir.path().join("disk"));
    let in_memory = train_scene(&recipe, &options(&memory_out, u64::MAX), &Quiet).unwrap();
    // The same dataset, its frames read back from a file.
    std::fs::create_dir_all(&disk_out).unwrap();
    let copy = |from: &Path, to: &Path| {
        std::fs::create_dir_all(to).unwrap();
        for entry in std::fs::read_dir(from).unwrap() {
            let path = entry.unwrap().path();
            std::fs::copy(&path, to.join(path.file_name().unwrap())).unwrap();
        }
    };
    copy(&memory_out.join("dataset"), &disk_out.join("dataset"));
    let on_disk = train_scene(&recipe, &options(&disk_out, 0), &Quiet).unwrap();
    let frames = disk_out.join("frames.f64");
    let width = in_memory.model.encoded_len() as u64;
    // 3 sequences of 41 frames, f64 rows.
    assert_eq!(std::fs::metadata(&frames).unwrap().len(), 3 * 41 * width * 8);
    assert!(!memory_out.join("frames.f64").exists());
    // The randomized PCA meets the thin SVD to round-off, so training follows the same path.
    assert_eq!(in_memory.model.latent, on_disk.model.latent);
    let (a, b) = (&in_memory.model.summary.trials, &on_disk.model.summary.trials);
    for (x, y) in a.iter().zip(b) {
        assert!(
            (x.pca_error - y.pca_error).abs() <= 1e-6 * x.pca_error,
            "{x:?} against {y:?}"
        );
    }
    let (la, lb) = (in_memory.losses.0.last().unwrap(), on_disk.losses.0.last().unwrap());
    assert!((la - lb).abs() <= 5e-2 * la.abs(), "final losses {la} and {lb}");

    // Against full space: the test split made anew by full-space Newton in a directory of
    // its own, the adaptive solver measured against it too.
    let model = disk_out.join("tiny.mochi");
    let eval = EvalOptions {
        out_dir: disk_out.join("eval"),
        stability_frames: 200,
        accuracy_frames: 60,
        adaptive: false,
        full_space_reference: true,
    };
    evaluate(&[model], &eval, &Quiet).unwrap();
    let reference = Manifest::read(&disk_out.join("dataset-full-space").join(MANIFEST))
        .unwrap()
        .unwrap();
    assert_eq!(reference.solver, "full-space Newton");
    assert_eq!(reference.sequences.len(), 2, "the test split only");
    let own = Manifest::read(&disk_out.join("dataset").join(MANIFEST))
        .unwrap()
        .unwrap();
    assert!(own.solver.starts_with("adaptive subspace"), "{}", own.solver);
    let report = std::fs::read_to_string(disk_out.join("eval/report.md")).unwrap();
    assert!(report.contains("the test split simulated in full space"), "{report}");
    assert!(report.contains("## Adaptive subspace solver"), "{report}");
}
