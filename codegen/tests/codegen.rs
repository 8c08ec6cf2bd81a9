//! Generated modules are deterministic and rustfmt-clean (for positions- and bend-encoded
//! models), and bad artifacts are refused with the file named.

use std::io::Write;
use std::path::Path;
use std::process::{Command, Stdio};

const TINY: &str = "../tests/artifacts/tiny.mochi";
/// Rods encoded by their bends (`encoding.chains` not empty).
const STRANDS: &str = "../tests/artifacts/strands.mochi";

#[test]
fn output_is_deterministic() {
    let bytes = std::fs::read(TINY).unwrap();
    let a = mochi_codegen::generate(&bytes, "tiny.mochi").unwrap();
    let b = mochi_codegen::generate(&bytes, "tiny.mochi").unwrap();
    assert_eq!(a, b);
    assert!(a.contains("pub static MODEL: mochi_runtime::Model<'static>"));
    assert!(a.contains("pub type Instance = mochi_runtime::Instance<LATENT, SIGNAL, HIDDEN>;"));
}

#[test]
fn chain_tables_are_empty_for_positions_and_filled_for_bends() {
    let chains = |source: &str| {
        let line = source.lines().find(|l| l.trim_start().starts_with("chains: ")).unwrap();
        line.trim().to_string()
    };
    let tiny = mochi_codegen::generate(&std::fs::read(TINY).unwrap(), "tiny.mochi").unwrap();
    assert!(chains(&tiny).ends_with("len: 0 },"), "{}", chains(&tiny));
    let format = format!("// Artifact format {};", mochi_codegen::ARTIFACT_VERSION);
    assert!(tiny.contains(&format));
    let strands = std::fs::read(STRANDS).unwrap();
    let a = mochi_codegen::generate(&strands, "strands.mochi").unwrap();
    assert_eq!(a, mochi_codegen::generate(&strands, "strands.mochi").unwrap());
    assert!(!chains(&a).ends_with("len: 0 },"), "{}", chains(&a));
}

#[test]
fn output_is_rustfmt_clean() {
    for path in [TINY, STRANDS] {
        rustfmt_clean(path);
    }
}

fn rustfmt_clean(path: &str) {
    let bytes = std::fs::read(path).unwrap();
    let source = mochi_codegen::generate(&bytes, path).unwrap();
    let mut rustfmt = Command::new("rustfmt")
        .args(["--check", "--edition", "2021", "--config", "max_width=100"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("rustfmt is installed with the toolchain");
    rustfmt.stdin.take().unwrap().write_all(source.as_bytes()).unwrap();
    let out = rustfmt.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "rustfmt would change the output:\n{}",
        String::from_utf8_lossy(&out.stdout)
    );
}

#[test]
fn bad_artifacts_are_refused_naming_the_file() {
    let dir = std::env::temp_dir().join(format!("mochi-codegen-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let bytes = std::fs::read(TINY).unwrap();
    let truncated = dir.join("truncated.mochi");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    let out = dir.join("model.rs");
    let err = mochi_codegen::generate_file(&truncated, &out).unwrap_err().to_string();
    assert!(err.contains("truncated.mochi") && err.contains("truncated"), "{err}");
    assert!(!out.exists(), "nothing is written for a refused artifact");
    let missing = mochi_codegen::generate_file(Path::new("no/such.mochi"), &out)
        .unwrap_err()
        .to_string();
    assert!(missing.contains("no/such.mochi"), "{missing}");
    std::fs::remove_dir_all(&dir).unwrap();
}
