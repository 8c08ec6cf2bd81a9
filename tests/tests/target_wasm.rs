//! The wasm module (`targets/wasm`) built for `wasm32-unknown-unknown` by `scripts/run-wasm.sh`:
//! run in node, its checksums of the decoded positions equal the host runtime's bit for bit;
//! its web page, served locally and opened in headless Chromium (`scripts/check-page.py`),
//! offers the compiled-in tiny model and the fetched right-sized beam and cloth-line
//! artifacts (`beam-m8`, `cloth-line-m24`), and for
//! each one chosen in its model list steps frames, moves the surface under the (synthetic)
//! mouse, draws it with WebGL2 (pixels read back) and shows a time per frame; screenshots are
//! left behind. The collider model `tiny-poke` (int8) then runs the same way, its page's ball
//! the model's collider input, and the render-mesh model `tiny-render` (`f32`): its render
//! decode in node agrees with the host's and the page draws its render mesh.

use std::path::Path;
use std::process::Command;

use mochi_runtime::ValidModel;
use mochi_target_common::host;
use mochi_tests::{tiny, tiny_poke, tiny_poke_int8, tiny_render};

/// `scripts/run-wasm.sh` on `artifact` in `weights`, the page offering that model alone;
/// returns the script's output.
fn run_alone(script: &Path, artifact: &Path, weights: &str) -> String {
    let run = Command::new("bash")
        .arg(script)
        .arg(artifact)
        .arg(weights)
        .env("MOCHI_PAGE_MODELS", artifact)
        .output()
        .unwrap_or_else(|e| panic!("running {}: {e}", script.display()));
    let stdout = String::from_utf8_lossy(&run.stdout).into_owned();
    assert!(
        run.status.success(),
        "{} {} failed:\n{}\n{stdout}",
        script.display(),
        artifact.display(),
        String::from_utf8_lossy(&run.stderr)
    );
    stdout
}

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
    // The viewer: the artifact loaded from bytes steps as the compiled model (test.mjs).
    let bytes = std::fs::metadata(repo.join("tests/artifacts/tiny.mochi"))
        .unwrap()
        .len();
    let triangles = tiny::MODEL.surface_triangles.len / 3;
    assert!(
        output.contains(&format!("viewer loaded {bytes} bytes, {triangles} triangles")),
        "{output}"
    );
    // The browser check passed (the script fails otherwise) and says so, model by model.
    let pages: Vec<&str> = stdout.lines().filter_map(|l| l.strip_prefix("page: ")).collect();
    let field = |line: &str, key: &str| -> String {
        let value = line
            .split(' ')
            .find_map(|kv| kv.strip_prefix(key).and_then(|v| v.strip_prefix('=')));
        value.unwrap_or_else(|| panic!("no {key} in {line:?}")).to_string()
    };
    let models: Vec<String> = pages.iter().map(|l| field(l, "model")).collect();
    assert_eq!(
        models,
        ["beam-m8", "tiny", "cloth-line-m24"],
        "the models the page showed: {pages:?}"
    );
    for line in &pages {
        let number = |key| field(line, key).parse::<f64>().unwrap();
        assert!(number("frames") >= 120.0, "{line}");
        assert!(number("moved") > 1e-3, "{line}");
        assert!(number("status") >= 0.0, "{line}");
        assert!(number("drawn") >= 0.01 * 800.0 * 480.0, "{line}");
        assert!(number("ms") > 0.0, "time per frame: {line}");
        let png = std::fs::read(repo.join(format!("target/targets/wasm-page-{}.png", field(line, "model")))).unwrap();
        assert!(
            png.starts_with(b"\x89PNG\r\n\x1a\n") && png.len() > 10_000,
            "screenshot of {line}"
        );
    }

    // A model with a collider slot (tiny-poke, int8): in node its checksums equal the host's
    // with the reference script's collider, and on the page the mouse's ball is its input.
    // (After the first run: the two share the page's folder.)
    let stdout = run_alone(&script, &repo.join("tests/artifacts/tiny-poke.mochi"), "int8");
    let output = std::fs::read_to_string(repo.join("target/targets/wasm-tiny-poke-int8.txt")).unwrap();
    let report = host::parse(&output).unwrap();
    let model = ValidModel::new(tiny_poke_int8::MODEL).unwrap();
    host::check::<{ tiny_poke::LATENT }, { tiny_poke::SIGNAL }, { tiny_poke::HIDDEN }>(&model, &report).unwrap();
    let page = stdout
        .lines()
        .find_map(|l| l.strip_prefix("page: "))
        .unwrap_or_else(|| panic!("no page line: {stdout}"));
    assert_eq!(field(page, "model"), "tiny-poke", "{page}");
    assert!(field(page, "pushed").parse::<u64>().unwrap() > 0, "{page}");

    // A model with a render mesh (tiny-render, f32): in node the render pass agrees with the
    // host's and the viewer's render mesh has unit normals; the page draws the render mesh.
    let stdout = run_alone(&script, &repo.join("tests/artifacts/tiny-render.mochi"), "f32");
    let output = std::fs::read_to_string(repo.join("target/targets/wasm-tiny-render-f32.txt")).unwrap();
    let report = host::parse(&output).unwrap();
    assert_eq!(report.render_checksums.len(), 4, "the render pass ran");
    let model = ValidModel::new(tiny_render::MODEL).unwrap();
    host::check::<{ tiny_render::LATENT }, { tiny_render::SIGNAL }, { tiny_render::HIDDEN }>(&model, &report).unwrap();
    assert!(
        output.contains("viewer render 1014 vertices, 1728 triangles"),
        "{output}"
    );
    let page = stdout
        .lines()
        .find_map(|l| l.strip_prefix("page: "))
        .unwrap_or_else(|| panic!("no page line: {stdout}"));
    assert_eq!(field(page, "model"), "tiny-render", "{page}");
    assert!(field(page, "moved").parse::<f64>().unwrap() > 1e-3, "{page}");
}
