//! Generates runtime code from the committed artifacts, as a user's build script would.

fn main() {
    for name in mochi_tests_artifacts() {
        let artifact = format!("artifacts/{name}.mochi");
        if let Err(e) = mochi_codegen::build_rs(&artifact, &format!("{name}.rs")) {
            panic!("codegen failed: {e}");
        }
    }
}

/// The committed artifacts (see `artifacts/README.md`).
fn mochi_tests_artifacts() -> [&'static str; 2] {
    ["tiny", "beam"]
}
