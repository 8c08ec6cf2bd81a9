//! Generates the model (`MOCHI_ARTIFACT`, default the repository's `tests/artifacts/tiny.mochi`,
//! weights `MOCHI_WEIGHTS` = f32 | f16 | int8) and puts `memory.x` on the linker's path.

use std::path::PathBuf;

fn main() {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
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
    let name = artifact
        .file_stem()
        .map_or("model".into(), |s| s.to_string_lossy().into_owned());
    std::fs::write(out.join("name.rs"), format!("{name:?}")).expect("writing name.rs");
    std::fs::write(out.join("weights.rs"), format!("{weights:?}")).expect("writing weights.rs");
    std::fs::copy(manifest.join("memory.x"), out.join("memory.x")).expect("copying memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
}
