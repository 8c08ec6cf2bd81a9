//! Tests of the mesh readers: helpers, the real data files, robustness.

use super::*;
use crate::error::Location;
use crate::mesh::{tet_signed_volume, triangle_signed_area, Elements};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::PathBuf;

mod medit;
mod obj;
mod tetgen;

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../data").join(name)
}

/// Writes `files` (name, text) into a fresh temporary directory and loads the first.
fn load_files(files: &[(&str, &str)], kind: MeshKind) -> Result<Mesh, InputError> {
    let dir = tempfile::tempdir().unwrap();
    for (name, text) in files {
        std::fs::write(dir.path().join(name), text).unwrap();
    }
    load(&dir.path().join(files[0].0), kind)
}

fn load_text(name: &str, text: &str, kind: MeshKind) -> Result<Mesh, InputError> {
    load_files(&[(name, text)], kind)
}

/// Asserts the error is at `line` of a file called `name` and its message holds `needle`.
fn assert_line_error(result: Result<Mesh, InputError>, name: &str, line: usize, needle: &str) {
    let err = result.expect_err("expected an error");
    let shown = err.to_string();
    assert_eq!(err.location, Location::Line(line), "{shown}");
    assert!(err.file.ends_with(name), "{shown}");
    assert!(shown.contains(&format!("{name}:{line}: ")), "{shown}");
    assert!(shown.contains(needle), "`{needle}` not in: {shown}");
}

/// Asserts the error is about the file `name` as a whole and its message holds `needle`.
fn assert_file_error(result: Result<Mesh, InputError>, name: &str, needle: &str) {
    let err = result.expect_err("expected an error");
    let shown = err.to_string();
    assert_eq!(err.location, Location::File, "{shown}");
    assert!(err.file.ends_with(name), "{shown}");
    assert!(shown.contains(needle), "`{needle}` not in: {shown}");
}

fn tet_volumes(mesh: &Mesh) -> Vec<f64> {
    let Elements::Tets(tets) = &mesh.elements else {
        panic!("not tets")
    };
    tets.iter()
        .map(|t| {
            let p: Vec<Vector3<f64>> = t.iter().map(|&v| mesh.point(v)).collect();
            tet_signed_volume(&p)
        })
        .collect()
}

fn triangle_areas(mesh: &Mesh) -> Vec<f64> {
    let Elements::Triangles(tris) = &mesh.elements else {
        panic!("not 2D triangles")
    };
    tris.iter()
        .map(|t| {
            let p: Vec<Vector3<f64>> = t.iter().map(|&v| mesh.point(v)).collect();
            triangle_signed_area(&p)
        })
        .collect()
}

// --- real files -------------------------------------------------------------------------

#[test]
fn beam365_mesh_loads_with_positive_tets() {
    let mesh = load(&data("beam365.mesh"), MeshKind::Auto).unwrap();
    assert_eq!(mesh.dim, 3);
    assert_eq!(mesh.num_vertices(), 365);
    assert_eq!(mesh.num_elements(), 1343);
    let volumes = tet_volumes(&mesh);
    assert!(volumes.iter().all(|&v| v > 0.0));
    // The beam spans 1.2 x 1.2 x 4.11 (a box of 5.92); volume summed independently.
    let total: f64 = volumes.iter().sum();
    approx::assert_relative_eq!(total, 5.920910101003435, max_relative = 1e-12);
    assert_eq!(mesh, load(&data("beam365.mesh"), MeshKind::Solid).unwrap());
    // First vertex and first tet as written (1-based `91 70 135 169`).
    assert_eq!(&mesh.rest[..3], &[-0.610143, -0.6336986703486888, 0.03592465556080646]);
    let Elements::Tets(tets) = &mesh.elements else {
        unreachable!()
    };
    assert_eq!(tets[0], [90, 69, 134, 168]);
}

#[test]
fn beam365_mesh_kind_mismatches_are_errors() {
    assert_file_error(
        load(&data("beam365.mesh"), MeshKind::Cloth),
        "beam365.mesh",
        "no triangles (the file has 1343 tetrahedra)",
    );
    assert_file_error(
        load(&data("beam365.mesh"), MeshKind::Planar),
        "beam365.mesh",
        "a 3D MEDIT file cannot be read as a planar solid",
    );
    assert_file_error(
        load(&data("beam365.mesh"), MeshKind::Rods),
        "beam365.mesh",
        "cannot be read as rods",
    );
}

#[test]
fn cantilever_node_ele_loads_with_positive_triangles() {
    let mesh = load(&data("longerCantileverP2.node"), MeshKind::Auto).unwrap();
    assert_eq!(mesh.dim, 2);
    assert_eq!(mesh.num_vertices(), 431);
    assert_eq!(mesh.num_elements(), 738);
    let areas = triangle_areas(&mesh);
    assert!(areas.iter().all(|&a| a > 0.0));
    // The bar is 8 x 1 (its curved-free boundary is sampled exactly up to ~1e-9).
    approx::assert_relative_eq!(areas.iter().sum::<f64>(), 8.0, max_relative = 1e-8);
    assert_eq!(&mesh.rest[..2], &[-4.0, -0.5]);
    // Reading the pair through the .ele path gives the same mesh.
    let via_ele = load(&data("longerCantileverP2.ele"), MeshKind::Planar).unwrap();
    assert_eq!(mesh, via_ele);
}

#[test]
fn cantilever_as_solid_is_an_error() {
    assert_line_error(
        load(&data("longerCantileverP2.node"), MeshKind::Solid),
        "longerCantileverP2.node",
        1,
        "a 2D .node file (Triangle) cannot be read as a solid (tetrahedra); load it as \
         MeshKind::Planar",
    );
}

#[test]
fn all_inverted_beam_is_flipped_back() {
    let original = load(&data("beam365.mesh"), MeshKind::Solid).unwrap();
    let text = std::fs::read_to_string(data("beam365.mesh")).unwrap();
    // Swap the last two indices of every tet: all volumes negative.
    let start = text.find("Tetrahedra").unwrap();
    let mut flipped = text[..start].to_string();
    for line in text[start..].lines() {
        let words: Vec<&str> = line.split_whitespace().collect();
        if words.len() == 5 {
            flipped += &format!("{} {} {} {} {}\n", words[0], words[1], words[3], words[2], words[4]);
        } else {
            flipped += line;
            flipped.push('\n');
        }
    }
    let mesh = load_text("flipped.mesh", &flipped, MeshKind::Solid).unwrap();
    // Flipping swaps the last two indices again, giving back the original tets.
    assert_eq!(mesh, original);
}

// --- robustness -------------------------------------------------------------------------

/// Parses `text` as each format (no files needed); must not panic.
fn parse_all(text: &str) -> [bool; 3] {
    let file = Path::new("fuzz");
    [
        parse_medit(text, file, MeshKind::Auto).is_ok(),
        parse_node_ele(text, file, text, file, MeshKind::Auto).is_ok(),
        parse_obj(text, file, MeshKind::Auto).is_ok(),
    ]
}

#[test]
fn random_bytes_and_token_soup_never_panic() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for _ in 0..300 {
        let len = rng.random_range(0..600);
        let bytes: Vec<u8> = (0..len).map(|_| rng.random()).collect();
        assert_eq!(parse_all(&String::from_utf8_lossy(&bytes)), [false; 3]);
    }
    // Plausible tokens in random order reach deeper into the parsers.
    const WORDS: [&str; 24] = [
        "Dimension",
        "3",
        "2",
        "Vertices",
        "Tetrahedra",
        "Triangles",
        "End",
        "1",
        "0",
        "-1",
        "4",
        "0.5",
        "nan",
        "1e308",
        "99999999999999999999",
        "\n",
        "\n",
        "#",
        "v",
        "f",
        "l",
        "1/2/3",
        "-2//1",
        "\\\n",
    ];
    let mut parsed = 0;
    for _ in 0..3000 {
        let len = rng.random_range(0..80);
        let text: Vec<&str> = (0..len).map(|_| WORDS[rng.random_range(0..WORDS.len())]).collect();
        parsed += parse_all(&text.join(" ")).iter().filter(|&&ok| ok).count();
    }
    // Soup is almost never a valid mesh; what matters is that nothing panicked.
    assert!(parsed < 30, "{parsed}");
}

#[test]
fn truncated_and_mutated_real_files_are_errors_not_panics() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mesh_text = std::fs::read_to_string(data("beam365.mesh")).unwrap();
    let node_text = std::fs::read_to_string(data("longerCantileverP2.node")).unwrap();
    let ele_text = std::fs::read_to_string(data("longerCantileverP2.ele")).unwrap();
    let file = Path::new("cut");
    let full_mesh = parse_medit(&mesh_text, file, MeshKind::Auto).unwrap();
    assert!(parse_node_ele(&node_text, file, &ele_text, file, MeshKind::Auto).is_ok());
    for _ in 0..60 {
        // A cut file either fails or (cut after the last record) reads the same.
        let cut = rng.random_range(0..mesh_text.len());
        match parse_medit(&mesh_text[..cut], file, MeshKind::Auto) {
            Ok(mesh) => assert_eq!(mesh, full_mesh, "cut at {cut}"),
            Err(e) => assert!(matches!(e.location, Location::Line(_) | Location::File), "{e}"),
        }
        // Node and ele files cut after a whole line lack records; cut inside the last
        // line they may still be a valid (different) mesh, so anywhere else: no panic.
        let line_end = |text: &str, at: usize| text[..at].rfind('\n').map_or(0, |i| i + 1);
        let cut = line_end(&node_text, rng.random_range(0..node_text.len()));
        assert!(parse_node_ele(&node_text[..cut], file, &ele_text, file, MeshKind::Auto).is_err());
        let cut = line_end(&ele_text, rng.random_range(0..ele_text.len()));
        assert!(parse_node_ele(&node_text, file, &ele_text[..cut], file, MeshKind::Auto).is_err());
        let cut = rng.random_range(0..ele_text.len());
        let _ = parse_node_ele(&node_text[..cut], file, &ele_text[..cut], file, MeshKind::Auto);
        // A few random bytes overwritten: any result, but no panic.
        let mut bytes = mesh_text.clone().into_bytes();
        for _ in 0..rng.random_range(1..4) {
            let at = rng.random_range(0..bytes.len());
            bytes[at] = rng.random();
        }
        let _ = parse_medit(&String::from_utf8_lossy(&bytes), file, MeshKind::Auto);
        let mut bytes = ele_text.clone().into_bytes();
        let at = rng.random_range(0..bytes.len());
        bytes[at] = b"0123456789 -\n"[rng.random_range(0..13)];
        let _ = parse_node_ele(&node_text, file, &String::from_utf8_lossy(&bytes), file, MeshKind::Auto);
    }
}
