//! Generates runtime code from the committed artifacts, as a user's build script would.

use mochi_codegen::{build_rs, build_rs_with, Options};
use mochi_runtime::WeightFormat;

fn main() {
    for name in mochi_tests_artifacts() {
        let artifact = format!("artifacts/{name}.mochi");
        if let Err(e) = build_rs(&artifact, &format!("{name}.rs")) {
            panic!("codegen failed: {e}");
        }
    }
    // The tiny model in the other weight storages.
    for (format, out) in [(WeightFormat::F16, "tiny_f16.rs"), (WeightFormat::Int8, "tiny_int8.rs")] {
        if let Err(e) = build_rs_with("artifacts/tiny.mochi", out, &Options::weights(format)) {
            panic!("codegen failed: {e}");
        }
    }
}

/// The committed artifacts (see `artifacts/README.md`).
fn mochi_tests_artifacts() -> [&'static str; 2] {
    ["tiny", "beam"]
}
