//! Generates runtime code from the committed artifacts, as a user's build script would.

use mochi_codegen::{build_rs, build_rs_with, Options};
use mochi_runtime::WeightFormat;

fn main() {
    for name in mochi_tests_artifacts() {
        let artifact = format!("artifacts/{name}.mochi");
        if let Err(e) = build_rs(&artifact, &format!("{}.rs", name.replace('-', "_"))) {
            panic!("codegen failed: {e}");
        }
    }
    // Other weight storages (beam int8: the reference model that fits 1 MiB of flash).
    for (artifact, format, out) in [
        ("tiny", WeightFormat::F16, "tiny_f16.rs"),
        ("tiny", WeightFormat::Int8, "tiny_int8.rs"),
        ("beam", WeightFormat::Int8, "beam_int8.rs"),
        ("beam-m8", WeightFormat::Int8, "beam_m8_int8.rs"),
        ("tiny-poke", WeightFormat::Int8, "tiny_poke_int8.rs"),
        ("tiny-render", WeightFormat::Int8, "tiny_render_int8.rs"),
    ] {
        let artifact = format!("artifacts/{artifact}.mochi");
        if let Err(e) = build_rs_with(&artifact, out, &Options::weights(format)) {
            panic!("codegen failed: {e}");
        }
    }
}

/// The committed artifacts (see `artifacts/README.md`).
fn mochi_tests_artifacts() -> [&'static str; 8] {
    [
        "tiny",
        "beam",
        "strands",
        "beam-m8",
        "rods",
        "rods-m8",
        "tiny-poke",
        "tiny-render",
    ]
}
