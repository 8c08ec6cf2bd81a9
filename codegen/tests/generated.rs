//! The generated module of every committed artifact (`tests/artifacts/*.mochi`, with the weight
//! storages `tests/build.rs` uses) is pinned by its length and FNV-1a hash, so any change to
//! the generated code is seen here first. When a change is intended, rerun with
//! `MOCHI_CODEGEN_DUMP=DIR` to write the modules to `DIR`, compare them with the previous
//! ones, and update the table with the values this test prints.

use std::path::Path;

use mochi_codegen::{generate_with, Options};
use mochi_runtime::WeightFormat;

/// Artifact, weight storage, length and FNV-1a 64 of the generated module.
///
/// Last change: artifact format 3 (the artifacts converted from format 2, weights unchanged).
/// The modules differ from those of format 2 only in their second line, the header comment
/// `// Artifact format 3; ...` (was 2); every array, constant and the `MODEL` literal are
/// byte for byte the same.
const EXPECTED: [(&str, WeightFormat, usize, u64); 6] = [
    ("tiny", WeightFormat::F32, 195034, 0xa4e8b90b2462acf4),
    ("beam", WeightFormat::F32, 11385382, 0xc9006abe23a5a24b),
    ("strands", WeightFormat::F32, 93363, 0x9c8b08c2a7c200b6),
    ("tiny", WeightFormat::F16, 119057, 0xd950a19ca57e4bfb),
    ("tiny", WeightFormat::Int8, 85523, 0xd2128fcdd2200f76),
    ("beam", WeightFormat::Int8, 3392035, 0x198db90e6404ed26),
];

fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
    })
}

#[test]
fn generated_modules_of_the_committed_artifacts_do_not_change() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/artifacts");
    let dump = std::env::var_os("MOCHI_CODEGEN_DUMP");
    let mut found = Vec::new();
    for (name, format, _, _) in EXPECTED {
        let file = format!("{name}.mochi");
        let bytes = std::fs::read(dir.join(&file)).unwrap();
        let source = generate_with(&bytes, &file, &Options::weights(format)).unwrap();
        if let Some(out) = &dump {
            let out = Path::new(out).join(format!("{name}_{}.rs", mochi_codegen::format_name(format)));
            std::fs::write(out, &source).unwrap();
        }
        found.push((name, format, source.len(), fnv1a(source.as_bytes())));
    }
    for f in &found {
        println!("    (\"{}\", WeightFormat::{:?}, {}, {:#018x}),", f.0, f.1, f.2, f.3);
    }
    assert_eq!(found, EXPECTED, "generated code changed (see the module docs)");
}
