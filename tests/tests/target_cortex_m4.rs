//! The Cortex-M4F firmware (`targets/cortex-m4`) built for `thumbv7em-none-eabihf` and run
//! under QEMU (mps2-an386) by `scripts/run-cortex-m4.sh`: its checksums of the decoded
//! positions equal the host runtime's, bit for bit, over the 1,000-frame reference script.

use std::path::Path;
use std::process::Command;

use mochi_runtime::{Model, ValidModel};
use mochi_target_common::host;
use mochi_tests::{tiny, tiny_int8};

/// Runs the firmware for the tiny artifact with `weights` and checks it against `model`.
fn firmware_matches_the_host(weights: &str, model: Model<'static>) {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let script = repo.join("scripts/run-cortex-m4.sh");
    let run = Command::new("bash")
        .arg(&script)
        .arg(repo.join("tests/artifacts/tiny.mochi"))
        .arg(weights)
        .output()
        .unwrap_or_else(|e| panic!("running {}: {e}", script.display()));
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        run.status.success(),
        "{} failed (tools missing? run scripts/install-cross.sh):\n{stderr}\n{}",
        script.display(),
        String::from_utf8_lossy(&run.stdout)
    );
    let output = std::fs::read_to_string(repo.join(format!("target/targets/cortex-m4-tiny-{weights}.txt"))).unwrap();
    let report = host::parse(&output).unwrap();
    assert_eq!((report.model.as_str(), report.weights.as_str()), ("tiny", weights));
    let model = ValidModel::new(model).unwrap();
    host::check::<{ tiny::LATENT }, { tiny::SIGNAL }, { tiny::HIDDEN }>(&model, &report).unwrap();
    let per_frame = report.instructions_per_frame.expect("instructions per frame");
    assert!(
        per_frame > 10_000 && per_frame < 10_000_000,
        "{per_frame} instructions per frame"
    );
}

#[test]
fn firmware_under_qemu_matches_the_host_bit_for_bit() {
    firmware_matches_the_host("f32", tiny::MODEL);
    // The int8 kernels too (int8 decoder, f16 integrator).
    firmware_matches_the_host("int8", tiny_int8::MODEL);
}
