//! The wasm module (`targets/wasm`) built for `wasm32-unknown-unknown` by `scripts/run-wasm.sh`:
//! run in node, its checksums of the decoded positions equal the host runtime's bit for bit;
//! its web page, served locally and opened in headless Chromium, advances frames, moves the
//! mesh under the (synthetic) mouse and leaves a screenshot.

use std::path::Path;
use std::process::Command;

use mochi_runtime::ValidModel;
use mochi_target_common::host;
use mochi_tests::tiny;

#[test]
fn wasm_module_matches_the_host_and_its_page_runs_in_chromium() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let script = repo.join("scripts/run-wasm.sh");
    let run = Command::new("bash")
        .arg(&script)
        .arg(repo.join("tests/artifacts/tiny.mochi"))
        .arg("f32")
        .output()
        .unwrap_or_else(|e| panic!("running {}: {e}", script.display()));
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{} failed (tools missing? run scripts/install-cross.sh):\n{}\n{stdout}",
        script.display(),
        String::from_utf8_lossy(&run.stderr)
    );
    let output = std::fs::read_to_string(repo.join("target/targets/wasm-tiny-f32.txt")).unwrap();
    let report = host::parse(&output).unwrap();
    let model = ValidModel::new(tiny::MODEL).unwrap();
    host::check::<{ tiny::LATENT }, { tiny::SIGNAL }, { tiny::HIDDEN }>(&model, &report).unwrap();
    // The browser check passed (the script fails otherwise) and says so.
    let page = stdout.lines().find(|l| l.starts_with("page: ")).expect("a page line");
    assert!(page.contains(" done"), "{page}");
    let png = std::fs::read(repo.join("target/targets/wasm-page.png")).unwrap();
    assert!(
        png.starts_with(b"\x89PNG\r\n\x1a\n") && png.len() > 10_000,
        "screenshot"
    );
}
