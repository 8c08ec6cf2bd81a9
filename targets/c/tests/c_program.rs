//! The C program (`main.c`) compiled and linked against the static library as an engine would
//! (`cc main.c libmochi_c.a`), run, and its positions checked against the host runtime.

use std::path::{Path, PathBuf};
use std::process::Command;

use mochi_c::model::{HIDDEN, LATENT, SIGNAL};
use mochi_runtime::ValidModel;
use mochi_target_common::host;

/// The static library Cargo built beside the library this test links: the newest
/// `libmochi_c-<hash>.a` in `target/<profile>/deps/` (Cargo builds both crate types of the
/// library together, and copies the static library out of `deps/` only for `cargo build`).
fn static_library() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let deps = exe.parent().expect("target/<profile>/deps/<test>");
    let newest = std::fs::read_dir(deps)
        .expect("reading the deps directory")
        .filter_map(|e| e.ok())
        .filter(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            name.starts_with("libmochi_c-") && name.ends_with(".a")
        })
        .filter_map(|e| Some((e.metadata().ok()?.modified().ok()?, e.path())))
        .max();
    newest
        .map(|(_, path)| path)
        .unwrap_or_else(|| panic!("no libmochi_c-*.a in {}", deps.display()))
}

/// Compiles `main.c` against the generated header and the static library; returns the program.
fn build_program() -> PathBuf {
    let lib = static_library();
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("c-program");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("mochi.h"), mochi_c::HEADER).unwrap();
    let program = dir.join("mochi-c-program");
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let output = Command::new(&cc)
        .args(["-std=c11", "-Wall", "-Wextra", "-Werror", "-O2", "-I"])
        .arg(&dir)
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("main.c"))
        .arg(&lib)
        .args(["-lm", "-lpthread", "-ldl", "-o"])
        .arg(&program)
        .output()
        .unwrap_or_else(|e| panic!("running `{cc}` (a C compiler, needed to link Rust too): {e}"));
    assert!(
        output.status.success(),
        "compiling main.c failed:\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    program
}

#[test]
fn c_program_matches_the_host_checksum() {
    let program = build_program();
    let output = Command::new(&program).output().unwrap();
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(output.status.success(), "the C program failed:\n{stdout}");
    let report = host::parse(&stdout).unwrap();
    assert_eq!(report.frames, mochi_target_common::FRAMES);
    let model = ValidModel::new(mochi_c::model::MODEL).unwrap();
    host::check::<LATENT, SIGNAL, HIDDEN>(&model, &report).unwrap();

    // The collider model, stepped by C with the script's ball each frame: the host's checksums
    // (the same library on the same CPU: the same bits).
    use mochi_c::poke_model;
    let poke = ValidModel::new(poke_model::MODEL).unwrap();
    let mut positions = vec![0.0f32; poke.model().state_len()];
    let mut expected = Vec::new();
    mochi_target_common::run::<{ poke_model::LATENT }, { poke_model::SIGNAL }, { poke_model::HIDDEN }>(
        &poke,
        mochi_target_common::FRAMES,
        &mut positions,
        |frame, sum, _| {
            if mochi_target_common::CHECKPOINTS.contains(&frame) {
                expected.push(format!("collider_checksum {frame} {:016x}", sum.0));
            }
        },
    )
    .unwrap();
    let printed: Vec<&str> = stdout.lines().filter(|l| l.starts_with("collider_checksum")).collect();
    assert_eq!(printed, expected, "the C program's collider model against the host");
}

#[test]
fn committed_header_is_the_generated_one() {
    let committed = Path::new(env!("CARGO_MANIFEST_DIR")).join("include/mochi.h");
    let text = std::fs::read_to_string(&committed).unwrap_or_default();
    assert!(
        text == mochi_c::HEADER,
        "{} is out of date: copy it from the build (`cargo test -p mochi-c -- --ignored write_header`)",
        committed.display()
    );
}

/// Writes the generated header to `include/mochi.h` (run after changing the C ABI).
#[test]
#[ignore]
fn write_header() {
    let committed = Path::new(env!("CARGO_MANIFEST_DIR")).join("include/mochi.h");
    std::fs::write(committed, mochi_c::HEADER).unwrap();
}
