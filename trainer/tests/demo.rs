//! The README's main job, `mochi demo`, on the tiny test scene (the default scene's whole path:
//! dataset, training, artifact, codegen into a stand-alone crate compiled against the
//! runtime, the compiled program against the full-space solver), and `mochi simulate` on the
//! default scene: the command line a new user runs first, through the binary itself.

use std::path::Path;
use std::process::Command;

fn mochi(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_mochi"))
        .args(args)
        .output()
        .expect("mochi runs")
}

fn tiny_scene() -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../tests/artifacts/tiny.toml")
        .to_string_lossy()
        .into_owned()
}

/// The value in the row `label` of the demo report's quantity table.
fn quantity(report: &str, label: &str) -> f64 {
    let row = report
        .lines()
        .find(|l| l.starts_with(&format!("| {label} |")))
        .unwrap_or_else(|| panic!("no row `{label}` in the report:\n{report}"));
    let cell = row.split('|').nth(2).unwrap().trim();
    let number: String = cell.chars().take_while(|c| !c.is_whitespace() && *c != 'x').collect();
    number
        .parse()
        .unwrap_or_else(|e| panic!("`{cell}` in row `{label}`: {e}"))
}

#[test]
fn demo_runs_the_whole_path_and_the_compiled_program_matches_the_trainer() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let o = mochi(&["demo", &tiny_scene(), "--out", out.to_str().unwrap(), "--frames", "30"]);
    assert!(
        o.status.success(),
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    // The program compiled from the generated module agrees with the trainer's rollout.
    let disagreement = quantity(&report, "runtime vs trainer rollout (max, diagonals)");
    assert!(
        disagreement <= 1e-5,
        "runtime and trainer differ by {disagreement} diagonals"
    );
    // The rollout is measured against the full-space solver and stays finite.
    let mean = quantity(&report, "mean vertex error (% of diagonal)");
    assert!(mean.is_finite() && mean > 0.0, "mean error {mean}");
    assert!(quantity(&report, "runtime step + full decode") > 0.0);
    for file in [
        "tiny.mochi",
        "runtime-demo/src/model.rs",
        "demo-error.png",
        "demo-frames.png",
    ] {
        assert!(out.join(file).is_file(), "{file} missing from {}", out.display());
    }
}

#[test]
fn simulate_runs_the_default_scene() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("beam.npz");
    let o = mochi(&["simulate", "beam", "--frames", "3", "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.starts_with("beam: 3 frames"), "{stdout}");
    assert!(out.is_file());
}
