//! Generates the model: `MOCHI_ARTIFACT` (default the repository's `tests/artifacts/tiny.mochi`)
//! with weights `MOCHI_WEIGHTS` (f32 | f16 | int8).

use std::path::PathBuf;

fn main() {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    println!("cargo:rerun-if-env-changed=MOCHI_ARTIFACT");
    println!("cargo:rerun-if-env-changed=MOCHI_WEIGHTS");
    let artifact = std::env::var_os("MOCHI_ARTIFACT")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest.join("../../tests/artifacts/tiny.mochi"));
    let weights = std::env::var("MOCHI_WEIGHTS").unwrap_or_else(|_| "f32".into());
    let Some(format) = mochi_codegen::parse_format(&weights) else {
        panic!("MOCHI_WEIGHTS=`{weights}` is not one of f32, f16, int8");
    };
    if let Err(e) = mochi_codegen::build_rs_with(&artifact, "model.rs", &mochi_codegen::Options::weights(format)) {
        panic!("codegen failed: {e}");
    }
}
