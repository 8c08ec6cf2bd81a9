//! The runtime built for `aarch64-unknown-linux-gnu` and run under QEMU user-mode emulation by
//! `scripts/run-aarch64.sh`: every shipped model (beam-m8, cloth-line-m24, rods-m8 and the
//! kept beam), the collider model tiny-poke (stepped with the script's collider) and the
//! render-mesh model tiny-render (its render decode too) in every weight storage agrees with the host over the 1,000-frame reference
//! script (int8 and `f16` bit for bit, `f32` within 1e-5 of the rest diagonal), with the NEON
//! kernels, with the canonical code and without the dot-product extension; the NEON kernels
//! take at most half the instructions per frame of the canonical code on beam-m8; the C
//! static library links into the C program, whose run matches the host's.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use mochi_codegen::{parse_format, Options, Quantized};
use mochi_runtime::{OwnedModel, ValidModel, MAX_HIDDEN, MAX_LATENT, MAX_SIGNAL};
use mochi_target_common::host::{self, Report};
use mochi_tests::tiny;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The report of one run of the script (`target/targets/aarch64-<name>-<weights>-<kernels>.txt`).
fn report(name: &str, weights: &str, kernels: &str) -> Report {
    let path = repo().join(format!("target/targets/aarch64-{name}-{weights}-{kernels}.txt"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let report = host::parse(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert_eq!((report.model.as_str(), report.weights.as_str()), (name, weights));
    report
}

/// Checks `report` against the host's run of the artifact `name` in the report's storage, the
/// model built as code generation builds it (what the runner runs).
fn matches_the_host(name: &str, report: &Report) -> Result<f32, String> {
    let bytes = std::fs::read(repo().join(format!("tests/artifacts/{name}.mochi"))).unwrap();
    let mut storage = OwnedModel::default();
    let loaded = storage.load(&bytes).map_err(|e| format!("{name}: {e}"))?;
    let options = Options::weights(parse_format(&report.weights).expect("a weight storage"));
    let quantized = Quantized::split(loaded.model(), options.decoder, options.integrator);
    let model = ValidModel::new(quantized.model(loaded.model())).map_err(|e| format!("{name}: {e}"))?;
    host::check::<MAX_LATENT, MAX_SIGNAL, MAX_HIDDEN>(&model, report)
}

#[test]
fn aarch64_runs_match_the_host_and_neon_halves_the_instructions() {
    let script = repo().join("scripts/run-aarch64.sh");
    let run = Command::new("bash")
        .arg(&script)
        .output()
        .unwrap_or_else(|e| panic!("running {}: {e}", script.display()));
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{} failed (tools missing? run scripts/install-cross.sh):\n{}\n{stdout}",
        script.display(),
        String::from_utf8_lossy(&run.stderr)
    );
    println!("{stdout}");

    let mut failures = Vec::new();
    let mut per_frame = BTreeMap::new();
    let mut runs: Vec<(&str, &str, &str)> = Vec::new();
    for name in [
        "beam-m8",
        "cloth-line-m24",
        "rods-m8",
        "beam",
        "tiny-poke",
        "tiny-render",
    ] {
        for weights in ["f32", "f16", "int8"] {
            runs.push((name, weights, "neon"));
        }
    }
    for weights in ["f32", "f16", "int8"] {
        runs.push(("beam-m8", weights, "canonical"));
    }
    runs.push(("beam-m8", "int8", "nodot"));
    for (name, weights, kernels) in runs {
        let report = report(name, weights, kernels);
        if name == "tiny-render" {
            assert_eq!(
                report.render_checksums.len(),
                4,
                "{weights}: the render pass's checksums"
            );
        }
        if let Err(e) = matches_the_host(name, &report) {
            failures.push(format!("{name} {weights} {kernels}: {e}"));
        }
        let count = report.instructions_per_frame.expect("instructions per frame");
        assert!(
            count > 10_000 && count < 100_000_000,
            "{name} {weights} {kernels}: {count}"
        );
        per_frame.insert((name, weights, kernels), count);
    }
    assert!(
        failures.is_empty(),
        "runs that differ from the host:\n{}",
        failures.join("\n")
    );

    // The NEON kernels at most half the canonical code's instructions per frame on beam-m8.
    for weights in ["f32", "f16", "int8"] {
        let (neon, canonical) = (
            per_frame[&("beam-m8", weights, "neon")],
            per_frame[&("beam-m8", weights, "canonical")],
        );
        assert!(
            2 * neon <= canonical,
            "beam-m8 {weights}: NEON {neon} instructions per frame, canonical {canonical}"
        );
    }

    // The C program on the static library: the host's tiny model, as the host's C test.
    let text = std::fs::read_to_string(repo().join("target/targets/aarch64-c.txt")).unwrap();
    let c = host::parse(&text).unwrap();
    let model = ValidModel::new(tiny::MODEL).unwrap();
    host::check::<{ tiny::LATENT }, { tiny::SIGNAL }, { tiny::HIDDEN }>(&model, &c).unwrap();
}
