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
/// Last change: artifact format 8 (a timed integrator's rate input; none of these is timed):
/// the `MODEL` literal gained the line `rate_input: false,` and the header comment says
/// `// Artifact format 8`; every module is longer by exactly that line's 23 bytes (checked:
/// removing the line and restoring the comment gives the previous lengths and hashes).
/// Before: artifact format 7 (the render mesh riding on the simulation mesh, empty in
/// every one of these): the `MODEL` literal gained the four lines `render_anchors`,
/// `render_weights`, `render_triangles` and `render_uvs` (empty spans), the constants
/// `RENDER_LEN` (0) and its doc line, and the header comment says `// Artifact format 7`;
/// every module is longer by exactly those 398 bytes. Before: artifact format 6 (the trained range of frame times and the run-time collider
/// slots): the `MODEL` literal gained the lines `dt_min: 0.0,`, `dt_max: 0.0,` and
/// `collider_shapes: mochi_runtime::Span { start: N, len: 0 },` (N the length of `FLOATS`) and
/// the header comment says `// Artifact format 6`; every module is longer by exactly those
/// lines' bytes (99 or 100). Before:
/// `ARTIFACT_PARAMS_LEN` (the capacity for loading the artifact) is computed from
/// the layer shapes as a loader with a wide `f32` kernel fills its pool, which on x86-64 now
/// stores every layer of at most 64 columns or of 128-256 rows by columns (more padding):
/// `tiny` 13,348 -> 13,732, `strands` 7,798 -> 8,118, `beam` unchanged; the rest of every
/// module is unchanged (generated code keeps only a decoder's narrow output layer by
/// columns). Before: every layer's `f32` weights start on a cache line of the pool (padded to a
/// multiple of 16 floats, as the loader places them; `tiny` `f32`: `PARAMS_LEN` 13,340 ->
/// 13,348) and the `PARAMS` static is a `mochi_runtime::Aligned` (64-byte boundary), in every
/// module. Before: the loader stores a decoder output layer of at most 64 columns column by
/// column (`WeightFormat::F32Columns`, each column padded to a multiple of 16 rows), and `f32`
/// code keeps that layout: `tiny`'s and `strands`' output layers are written by columns
/// (`tiny`: 216 rows padded to 224 in each of 32 columns, `PARAMS_LEN` 13,084 -> 13,340, the
/// later layers' offsets moved by the 256 floats); `f16` and int8 modules changed only in
/// `ARTIFACT_PARAMS_LEN`, the capacity for loading the artifact. Before: artifact format 5 (the
/// artifacts converted from format 4 by `mochi upgrade`, weights unchanged): the `MODEL` literal gained the line `decoder_basis: false,` and the header
/// comment says `// Artifact format 5`; every module is longer by exactly that line's 26 bytes.
/// Before: artifact format 4 (converted from format 3): the triangles to draw joined the
/// runtime's fields (`INDICES_LEN`, the `INDICES` pool with the triangles after the drawn
/// vertices, the `surface_source` span's start and the new `surface_triangles` span). Before
/// that: the loader's derived `chain_order` (the inverse of the strands' slots).
const EXPECTED: [(&str, WeightFormat, usize, u64); 6] = [
    ("tiny", WeightFormat::F32, 198885, 0x1b856d29b20134d4),
    ("beam", WeightFormat::F32, 11411690, 0x5ca9252f98136b07),
    ("strands", WeightFormat::F32, 94185, 0x099e6fa9a6bb8b10),
    ("tiny", WeightFormat::F16, 121525, 0xf8a4cde4aa98000a),
    ("tiny", WeightFormat::Int8, 87991, 0xe3ae191b2c05a4b3),
    ("beam", WeightFormat::Int8, 3418343, 0x578f147d2522755e),
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
