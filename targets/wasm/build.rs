//! Generates the model: `MOCHI_ARTIFACT` (default the repository's `tests/artifacts/tiny.mochi`)
//! with weights `MOCHI_WEIGHTS` (f32 | f16 | int8).

use std::path::PathBuf;

fn main() {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    if let Err(e) = mochi_codegen::build_rs_from_env(manifest.join("../../tests/artifacts/tiny.mochi"), "model.rs") {
        panic!("codegen failed: {e}");
    }
}
