//! The `mochi` command line: outputs land where asked, bad input exits non-zero with an
//! error naming the file.

use mochi_sim::trajectory::Trajectory;
use std::path::Path;
use std::process::Command;

fn mochi(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_mochi"))
        .args(args)
        .output()
        .expect("mochi runs")
}

const TINY: &str = include_str!("../sim/tests/fixtures/tiny.toml");

#[test]
fn simulate_writes_trajectory_obj_and_preview() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("tiny.toml");
    std::fs::write(&scene, TINY).unwrap();
    let out = dir.path().join("run.npz");
    let objs = dir.path().join("obj");
    let o = mochi(&[
        "simulate",
        scene.to_str().unwrap(),
        "--frames",
        "5",
        "--out",
        out.to_str().unwrap(),
        "--obj",
        objs.to_str().unwrap(),
        "--png-frames",
        "0,5",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let traj = Trajectory::read_npz(&out).unwrap();
    assert_eq!(traj.positions.len(), 6);
    assert_eq!(traj.scene, "tiny");
    assert!(traj.newton_iterations[1..].iter().all(|&i| i >= 1));
    assert!(out.with_extension("png").is_file());
    assert_eq!(std::fs::read_dir(&objs).unwrap().count(), 6);
}

#[test]
fn dataset_writes_train_and_test_sequences() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("tiny.toml");
    std::fs::write(&scene, TINY).unwrap();
    let out = dir.path().join("data");
    let o = mochi(&["dataset", scene.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            "manifest.lock",
            "manifest.toml",
            "test-00.npz",
            "test-01.npz",
            "test-02.npz",
            "train-00.npz",
            "train-01.npz",
            "validation-00.npz",
            "validation-01.npz"
        ]
    );
    let test = Trajectory::read_npz(&out.join("test-00.npz")).unwrap();
    assert_eq!(test.meta_value("split"), Some("test"));
    assert_eq!(test.positions.len(), 5);
    assert!(
        test.step_seconds.is_empty(),
        "timings go to the manifest, not the sequence"
    );
    // Run again: every sequence is complete, none is simulated.
    let o = mochi(&["dataset", scene.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(said.contains("(0 simulated, 7 already complete)"), "{said}");
    // The plan, a shard of it, and a bad shard.
    let o = mochi(&["dataset", scene.to_str().unwrap(), "--plan", "--shard", "1/3"]);
    let said = String::from_utf8_lossy(&o.stdout);
    assert_eq!(
        said.lines().collect::<Vec<_>>(),
        ["train-01 train 4", "test-02 test 4"],
        "{said}"
    );
    let o = mochi(&["dataset", scene.to_str().unwrap(), "--shard", "3/3"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("3/3"));
}

#[test]
fn bad_scene_exits_non_zero_naming_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("broken.toml");
    std::fs::write(&scene, TINY.replace("poisson = 0.3", "poisson = [0.3]")).unwrap();
    let o = mochi(&["simulate", scene.to_str().unwrap(), "--frames", "2"]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("broken.toml:11:"), "{err}");
    let o = mochi(&["simulate", "no-such-scene"]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no-such-scene"));
    assert!(!Path::new("out/no-such-scene").exists());
}

/// A ball (tet mesh) dropped onto a rotated slab under IPC contact.
const BALL_ON_SLAB: &str = r#"
name = "ball-on-slab"
gravity = [0.0, -9.81, 0.0]
[mesh]
type = "ball"
center = [0.0, 0.2, 0.0]
radius = 0.1
cells = 4
[material]
youngs = 1e5
poisson = 0.3
density = 1000.0
[contact]
[[contact.obstacles]]
type = "box"
min = [-1.0, -0.1, -1.0]
max = [1.0, 0.0, 1.0]
rotation = [0.0, 0.0, 0.1745]
"#;

#[test]
fn out_of_range_physical_input_exits_at_once_naming_the_field() {
    let region = "density = 500.0\n[[material.regions]]\nbox = { min = [0.2, -1.0, -1.0], max = [1.0, 1.0, 1.0] }\nyoungs = 1.5e308";
    let cases = [
        (TINY, "youngs = 1e5", "youngs = 1.5e308", "material.youngs"),
        (TINY, "density = 500.0", region, "material.regions[0].youngs"),
        (
            TINY,
            "end = \"min\"",
            "end = \"min\", tolerance = nan",
            "handles[0].select.side.tolerance",
        ),
        (BALL_ON_SLAB, "radius = 0.1", "radius = 1e-300", "mesh.radius"),
        (
            BALL_ON_SLAB,
            "[0.0, 0.0, 0.1745]",
            "[0.0, 0.0, 1e300]",
            "contact.obstacles[0].rotation",
        ),
    ];
    let dir = tempfile::tempdir().unwrap();
    for (k, (text, from, to, field)) in cases.into_iter().enumerate() {
        let edited = text.replace(from, to);
        assert_ne!(edited, text, "{from} applies");
        let scene = dir.path().join(format!("bad-{k}.toml"));
        std::fs::write(&scene, edited).unwrap();
        let out = dir.path().join(format!("bad-{k}.npz"));
        let clock = std::time::Instant::now();
        let o = mochi(&[
            "simulate",
            scene.to_str().unwrap(),
            "--frames",
            "2",
            "--out",
            out.to_str().unwrap(),
        ]);
        let seconds = clock.elapsed().as_secs_f64();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{field}: {err}");
        let expected = format!("{}: field `{field}`: ", scene.display());
        assert!(err.contains(&expected), "expected {expected}: {err}");
        // Refused when the scene is read: no step is taken (a debug build starts in well
        // under this).
        assert!(seconds < 10.0, "{field}: {seconds} s");
        assert!(!out.exists(), "no output for a refused scene");
    }
}

#[test]
fn codegen_writes_the_generated_module_and_names_a_bad_artifact() {
    let dir = tempfile::tempdir().unwrap();
    let artifact = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/artifacts/tiny.mochi");
    let out = dir.path().join("tiny.rs");
    let run = mochi(&["codegen", artifact.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let expected = mochi_codegen::generate(&std::fs::read(&artifact).unwrap(), "tiny.mochi").unwrap();
    assert_eq!(std::fs::read_to_string(&out).unwrap(), expected);

    let bad = dir.path().join("bad.mochi");
    std::fs::write(&bad, b"MOCHIMDL not really").unwrap();
    let run = mochi(&[
        "codegen",
        bad.to_str().unwrap(),
        "-o",
        dir.path().join("x.rs").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success() && err.contains("bad.mochi"), "{err}");
}

#[test]
fn bench_runtime_reports_the_ratio_and_agreement() {
    let artifact = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/artifacts/tiny.mochi");
    let run = mochi(&[
        "bench",
        "runtime",
        artifact.to_str().unwrap(),
        "--frames",
        "20",
        "--weights",
        "f32,int8",
    ]);
    let text = String::from_utf8_lossy(&run.stdout);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let rows: Vec<Vec<&str>> = text
        .lines()
        .filter(|l| l.starts_with("| tiny.mochi"))
        .map(|row| row.split('|').map(str::trim).collect())
        .collect();
    assert_eq!(rows.len(), 2, "one row per storage:\n{text}");
    for (cells, weights, limit) in [(&rows[0], "f32", 1e-4), (&rows[1], "int8", 5e-2)] {
        assert_eq!(cells[2], weights, "{cells:?}");
        assert_eq!(
            (cells[4], cells[7], cells[8]),
            ("0", "-", "-"),
            "no collider slots, no push-out, no render mesh: {cells:?}"
        );
        assert!(cells[10].ends_with('x'), "speed-up column: {cells:?}");
        let disagreement: f64 = cells[14].split_whitespace().next().unwrap().parse().unwrap();
        assert!(disagreement < limit, "{cells:?}");
    }
    // Fewer bytes per weight.
    let kib = |cells: &[&str]| -> f64 { cells[12].split_whitespace().next().unwrap().parse().unwrap() };
    assert!(kib(&rows[1]) < 0.5 * kib(&rows[0]), "{rows:?}");
}

#[test]
fn unused_mesh_attributes_are_a_warning_on_stderr() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = Path::new(env!("CARGO_MANIFEST_DIR")).join("sim/tests/data/two-material-bar.node");
    let text = TINY.replace(
        "type = \"box\"\nmin = [0.0, 0.0, 0.0]\nmax = [0.4, 0.1, 0.1]\ncells = [4, 1, 1]",
        &format!("type = \"file\"\npath = \"{}\"", mesh.display()),
    );
    assert_ne!(text, TINY);
    let scene = dir.path().join("bar.toml");
    std::fs::write(&scene, text).unwrap();
    let out = dir.path().join("run.npz");
    let o = mochi(&[
        "simulate",
        scene.to_str().unwrap(),
        "--frames",
        "1",
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let warning = err
        .lines()
        .find(|l| l.starts_with("warning: "))
        .expect("a warning line");
    assert!(
        warning.contains("two-material-bar.node") && warning.contains("attributes 1, 2"),
        "{err}"
    );
}

#[test]
fn a_narrowed_selection_that_cannot_be_read_is_refused_before_training() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    for (flag, value, says) in [
        ("--decoder", "resnet", "expected `linear`, `mlp` or `basis=W`"),
        ("--decoder", "basis=0", "basis=W"),
        ("--integrator-width", "0", "--integrator-width must be at least 1"),
    ] {
        let o = mochi(&["train", "beam", "--out", out.to_str().unwrap(), flag, value]);
        assert!(!o.status.success());
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(says), "{flag} {value}: {err}");
        assert!(!out.exists(), "nothing written before the refusal");
    }
}
