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
/// Last change: artifact format 4 (the artifacts converted from format 3 by `mochi upgrade`,
/// weights unchanged): the triangles to draw joined the runtime's fields. The modules differ
/// from those of format 3 only in the header comment (`// Artifact format 4`), `INDICES_LEN`,
/// the `INDICES` pool (the triangles inserted after the drawn vertices, every other index
/// unchanged), the `surface_source` span's start (moved past them) and the new
/// `surface_triangles` span; every other array and constant is byte for byte the same (each
/// module is longer by exactly what it grew on its own, over the one with `chain_order`).
/// Before: the loader's derived `chain_order` (the inverse of the strands' slots): every
/// module gained the line `chain_order: mochi_runtime::Span { .. }` in its `MODEL` literal (an
/// empty span without strands); `strands` also the 24 entries `0, 1, ..., 23` at the end of
/// `INDICES`.
const EXPECTED: [(&str, WeightFormat, usize, u64); 6] = [
    ("tiny", WeightFormat::F32, 196906, 0x58356de6e9ceaeab),
    ("beam", WeightFormat::F32, 11411089, 0x00bc42f403faa16d),
    ("strands", WeightFormat::F32, 93582, 0x26dbac8aa54462fa),
    ("tiny", WeightFormat::F16, 120929, 0xb350694335a73c3c),
    ("tiny", WeightFormat::Int8, 87395, 0xdd610f751c4f913d),
    ("beam", WeightFormat::Int8, 3417742, 0xf07625a343f5c73c),
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
