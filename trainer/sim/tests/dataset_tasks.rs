//! A dataset made in pieces: any selection of its sequences, by any number of processes and
//! threads, gives the bytes one process makes; a run killed mid-sequence resumes without
//! redoing complete sequences; a directory of another scene or version is refused.

use std::path::Path;

use mochi_sim::dataset::manifest::{Manifest, MANIFEST};
use mochi_sim::dataset::{generate_selected, Selection};
use mochi_sim::{Scene, Silent};

const SCENE: &str = r#"
name = "pieces"
dt = 0.0333333333333333
gravity = [0.0, -9.81, 0.0]
[mesh]
type = "box"
min = [0.0, -0.03, -0.03]
max = [0.3, 0.03, 0.03]
cells = [5, 1, 1]
[material]
youngs = 2e5
poisson = 0.4
density = 1000.0
[[handles]]
name = "clamp"
select = { side = { axis = 0, end = "min" } }
[handles.motion]
segment_frames = [5, 10]
directions = [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
speed = [0.1, 0.4]
[dataset]
train = 3
test = 2
validation = 1
frames = 12
test_frames = 16
"#;

fn scene(text: &str) -> Scene {
    Scene::parse(text, Path::new("pieces.toml")).unwrap()
}

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "npz"))
        .map(|p| {
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read(&p).unwrap(),
            )
        })
        .collect();
    out.sort();
    out
}

#[test]
fn shards_on_other_thread_counts_make_the_bytes_of_one_run() {
    let root = tempfile::tempdir().unwrap();
    let (whole, pieces) = (root.path().join("whole"), root.path().join("pieces"));
    let mut problem = scene(SCENE).build().unwrap();
    generate_selected(&mut problem, &whole, &Selection::All, false, &Silent).unwrap();
    // Two shards, one on a single thread and one on three.
    for (index, threads) in [(0, 1), (1, 3)] {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        let mut problem = scene(SCENE).build().unwrap();
        pool.install(|| {
            generate_selected(
                &mut problem,
                &pieces,
                &Selection::Shard { index, count: 2 },
                false,
                &Silent,
            )
        })
        .unwrap();
    }
    let (a, b) = (files(&whole), files(&pieces));
    assert_eq!(
        a.len(),
        6,
        "3 train, 1 validation, 2 test: {:?}",
        a.iter().map(|f| &f.0).collect::<Vec<_>>()
    );
    assert_eq!(
        a.iter().map(|f| &f.0).collect::<Vec<_>>(),
        b.iter().map(|f| &f.0).collect::<Vec<_>>()
    );
    for ((name, x), (_, y)) in a.iter().zip(&b) {
        assert!(x == y, "{name} differs between one run and two shards");
    }
    // Both manifests record every sequence.
    let manifest = Manifest::read(&pieces.join(MANIFEST)).unwrap().unwrap();
    assert_eq!(manifest.sequences.len(), a.len());
    assert_eq!(manifest.scene, "pieces");
    // A named selection, and names the plan does not have.
    let named = root.path().join("named");
    let report = generate_selected(
        &mut problem,
        &named,
        &Selection::Names(vec!["test-01".into()]),
        false,
        &Silent,
    )
    .unwrap();
    assert_eq!(report.sequences, 1);
    assert_eq!(
        std::fs::read(named.join("test-01.npz")).unwrap(),
        std::fs::read(whole.join("test-01.npz")).unwrap()
    );
    let e = generate_selected(
        &mut problem,
        &named,
        &Selection::Names(vec!["train-99".into()]),
        false,
        &Silent,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("train-99") && e.contains("train-00"), "{e}");
}

#[test]
fn a_killed_run_resumes_without_redoing_complete_sequences() {
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    let mut problem = scene(SCENE).build().unwrap();
    let first = generate_selected(&mut problem, dir, &Selection::All, false, &Silent).unwrap();
    assert_eq!(first.sequences, 6);
    let reference = files(dir);
    // As a kill leaves it: one sequence's file cut short, another's not yet renamed from
    // its partial file, and neither recorded as written.
    let cut = dir.join("train-01.npz");
    let bytes = std::fs::read(&cut).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    std::fs::rename(dir.join("test-00.npz"), dir.join("test-00.npz.partial")).unwrap();
    let mut manifest = Manifest::read(&dir.join(MANIFEST)).unwrap().unwrap();
    manifest
        .sequences
        .retain(|s| s.name != "train-01" && s.name != "test-00");
    std::fs::write(dir.join(MANIFEST), toml::to_string(&manifest).unwrap()).unwrap();
    // A recorded, whole file is kept.
    let kept_time = std::fs::metadata(dir.join("train-00.npz")).unwrap().modified().unwrap();
    let resumed = generate_selected(&mut problem, dir, &Selection::All, false, &Silent).unwrap();
    assert_eq!(resumed.sequences, 2, "only the two interrupted sequences are simulated");
    assert_eq!(
        std::fs::metadata(dir.join("train-00.npz")).unwrap().modified().unwrap(),
        kept_time,
        "a complete sequence is not rewritten"
    );
    assert_eq!(files(dir), reference, "the resumed dataset is the first one's bytes");
    // Nothing left to do.
    let again = generate_selected(&mut problem, dir, &Selection::All, false, &Silent).unwrap();
    assert_eq!(again.sequences, 0);
}

#[test]
fn a_directory_of_another_scene_or_version_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    let mut problem = scene(SCENE).build().unwrap();
    generate_selected(
        &mut problem,
        dir,
        &Selection::Shard { index: 0, count: 4 },
        false,
        &Silent,
    )
    .unwrap();
    let mut other = scene(&SCENE.replace("youngs = 2e5", "youngs = 3e5")).build().unwrap();
    let e = generate_selected(&mut other, dir, &Selection::All, false, &Silent)
        .unwrap_err()
        .to_string();
    assert!(e.contains(MANIFEST) && e.contains("another output directory"), "{e}");
    // Another version.
    let path = dir.join(MANIFEST);
    let mut manifest = Manifest::read(&path).unwrap().unwrap();
    manifest.mochi = "0.0.1".into();
    std::fs::write(&path, toml::to_string(&manifest).unwrap()).unwrap();
    let e = generate_selected(&mut problem, dir, &Selection::All, false, &Silent)
        .unwrap_err()
        .to_string();
    assert!(e.contains("mochi 0.0.1"), "{e}");
    // Made anew on request.
    let report = generate_selected(&mut problem, dir, &Selection::All, true, &Silent).unwrap();
    assert_eq!(report.sequences, 6);
    let manifest = Manifest::read(&path).unwrap().unwrap();
    assert_eq!(
        (manifest.mochi.as_str(), manifest.sequences.len()),
        (env!("CARGO_PKG_VERSION"), 6)
    );
}

/// The solver state one sequence leaves (the adaptive model's blocks, enrichment and BFGS
/// matrices; the contact barrier's stiffness) does not reach the next: each sequence made
/// alone, in a fresh process as a distributed run makes it, is the bytes of one run.
#[test]
fn no_solver_state_carries_from_one_sequence_to_the_next() {
    let adaptive = format!("{SCENE}\n[solver]\nkind = \"adaptive\"\nmodal_error = 0.01\n");
    let contact = format!(
        "{SCENE}\n[contact]\ndhat = 1e-3\n[[contact.obstacles]]\ntype = \"box\"\n\
         min = [0.15, -0.2, -0.1]\nmax = [0.5, -0.036, 0.1]\n"
    );
    for (kind, text) in [("adaptive", adaptive), ("contact", contact)] {
        let root = tempfile::tempdir().unwrap();
        let whole = root.path().join("whole");
        let mut problem = scene(&text).build().unwrap();
        generate_selected(
            &mut problem,
            &whole,
            &Selection::Split(mochi_sim::Split::Train),
            false,
            &Silent,
        )
        .unwrap();
        for name in ["train-01", "train-02"] {
            let alone = root.path().join(name);
            let mut problem = scene(&text).build().unwrap();
            let names = Selection::Names(vec![name.to_string()]);
            generate_selected(&mut problem, &alone, &names, false, &Silent).unwrap();
            let file = format!("{name}.npz");
            let (a, b) = (
                std::fs::read(whole.join(&file)).unwrap(),
                std::fs::read(alone.join(&file)).unwrap(),
            );
            assert!(
                a == b,
                "{kind}: {name} made alone differs from {name} made after the others"
            );
        }
    }
}
