//! Generates the model (`MOCHI_ARTIFACT`, default the repository's `tests/artifacts/tiny.mochi`,
//! weights `MOCHI_WEIGHTS` = f32 | f16 | int8) and puts `memory.x` on the linker's path.

use std::path::PathBuf;

fn main() {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let out = PathBuf::from(std::env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let (artifact, weights) =
        match mochi_codegen::build_rs_from_env(manifest.join("../../tests/artifacts/tiny.mochi"), "model.rs") {
            Ok(chosen) => chosen,
            Err(e) => panic!("codegen failed: {e}"),
        };
    let name = artifact
        .file_stem()
        .map_or("model".into(), |s| s.to_string_lossy().into_owned());
    std::fs::write(out.join("name.rs"), format!("{name:?}")).expect("writing name.rs");
    std::fs::write(out.join("weights.rs"), format!("{weights:?}")).expect("writing weights.rs");
    std::fs::copy(manifest.join("memory.x"), out.join("memory.x")).expect("copying memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
}
