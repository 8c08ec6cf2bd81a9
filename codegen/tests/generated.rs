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
/// Last change: the loader's derived `chain_order` (the inverse of the strands' slots). Every
/// module gains the line `chain_order: mochi_runtime::Span { .. }` in its `MODEL` literal (an
/// empty span without strands); `strands` also gains the 24 entries `0, 1, ..., 23` at the
/// end of `INDICES` (`INDICES_LEN` 168 -> 192). Nothing else differs.
const EXPECTED: [(&str, WeightFormat, usize, u64); 6] = [
    ("tiny", WeightFormat::F32, 195095, 0x78ad8624e43fec24),
    ("beam", WeightFormat::F32, 11385444, 0xd53aae0cd66cd495),
    ("strands", WeightFormat::F32, 93515, 0x366c96193aa40cb2),
    ("tiny", WeightFormat::F16, 119118, 0x0b1a5d9bbd5a2765),
    ("tiny", WeightFormat::Int8, 85584, 0x191abfe105327c12),
    ("beam", WeightFormat::Int8, 3392097, 0xc906bc6d733fc590),
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
