//! Tests of the MEDIT reader.

use super::*;

/// Two positive unit tets sharing the face (1 2 3), with one line per item:
/// line 1 `MeshVersionFormatted`, 2 `Dimension`, 3 `Vertices`, 4 count, 5..=9 vertices,
/// 10 `Tetrahedra`, 11 count, 12..=13 tets, 14 `End`.
fn two_tets(vertices: &[&str], tets: &[&str]) -> String {
    let mut text = String::from("MeshVersionFormatted 1\nDimension 3\nVertices\n");
    text += &format!("{}\n", vertices.len());
    for v in vertices {
        text += v;
        text.push('\n');
    }
    text += &format!("Tetrahedra\n{}\n", tets.len());
    for t in tets {
        text += t;
        text.push('\n');
    }
    text + "End\n"
}

const VERTICES: [&str; 5] = ["0 0 0 0", "1 0 0 0", "0 1 0 0", "0 0 1 0", "1 1 1 0"];
const TETS: [&str; 2] = ["1 2 3 4 0", "2 3 4 5 0"];

#[test]
fn medit_small_file_loads() {
    let mesh = load_text("ok.mesh", &two_tets(&VERTICES, &TETS), MeshKind::Auto).unwrap();
    assert_eq!(mesh.elements, Elements::Tets(vec![[0, 1, 2, 3], [1, 2, 3, 4]]));
    assert!(tet_volumes(&mesh).iter().all(|&v| v > 0.0));
    // Keywords in any case, records spread over lines, comments, Edges and Triangles
    // sections, and a missing `End` are all fine.
    let free = "# a comment\nmeshversionformatted 2\nDIMENSION\n3\nvertices 5\n0 0 0 0 1 0 0 0\n\
                0 1 0 0 0 0 1 0 1 1 1 0 # five vertices\nEdges 1\n1 2 0\nTriangles 1 1 2 3 0\n\
                tetrahedra 2\n1 2 3 4 0\n2 3 4\n5 0\n";
    assert_eq!(load_text("free.mesh", free, MeshKind::Solid).unwrap(), mesh);
}

#[test]
fn medit_count_errors() {
    // Header says 5 vertices, 4 follow.
    let text = two_tets(&VERTICES, &TETS).replacen("5\n0 0 0 0", "6\n0 0 0 0", 1);
    assert_line_error(
        load_text("fewer.mesh", &text, MeshKind::Solid),
        "fewer.mesh",
        3,
        "`Vertices` declares 6 records but only 5 follow (the section ends at `Tetrahedra` on \
         line 10)",
    );
    // Header says 1 tet, 2 follow: the extra one is named.
    let text = two_tets(&VERTICES, &TETS).replacen("Tetrahedra\n2", "Tetrahedra\n1", 1);
    assert_line_error(
        load_text("more.mesh", &text, MeshKind::Solid),
        "more.mesh",
        13,
        "declares 1 records; this is one more",
    );
    // The file ends inside the tets.
    let text = two_tets(&VERTICES, &TETS).replace("2 3 4 5 0\nEnd\n", "");
    assert_line_error(
        load_text("truncated.mesh", &text, MeshKind::Solid),
        "truncated.mesh",
        10,
        "declares 2 records but only 1 follow (the file ends)",
    );
}

#[test]
fn medit_missing_sections() {
    let no_tets = "Dimension 3\nVertices\n1\n0 0 0 0\nEnd\n";
    assert_file_error(
        load_text("no_tets.mesh", no_tets, MeshKind::Solid),
        "no_tets.mesh",
        "no tetrahedra",
    );
    let no_vertices = "Dimension 3\nTetrahedra\n1\n1 2 3 4 0\n";
    assert_file_error(
        load_text("no_vertices.mesh", no_vertices, MeshKind::Solid),
        "no_vertices.mesh",
        "no `Vertices` section",
    );
    let no_dimension = "Vertices\n1\n0 0 0 0\n";
    assert_line_error(
        load_text("no_dimension.mesh", no_dimension, MeshKind::Solid),
        "no_dimension.mesh",
        1,
        "`Vertices` before `Dimension`",
    );
    let empty = "Dimension 3\nVertices\n0\nTetrahedra\n0\nEnd\n";
    assert_line_error(
        load_text("empty.mesh", empty, MeshKind::Solid),
        "empty.mesh",
        2,
        "`Vertices` is empty",
    );
    assert_file_error(
        load_text("blank.mesh", "", MeshKind::Auto),
        "blank.mesh",
        "no `Dimension`",
    );
}

#[test]
fn medit_token_errors() {
    let mut vertices = VERTICES;
    vertices[2] = "0 1x 0 0";
    assert_line_error(
        load_text("token.mesh", &two_tets(&vertices, &TETS), MeshKind::Solid),
        "token.mesh",
        7,
        "`1x` is neither a number nor a keyword",
    );
    // A word inside a section ends it early; the count error says where.
    vertices[2] = "0 one 0 0";
    assert_line_error(
        load_text("word.mesh", &two_tets(&vertices, &TETS), MeshKind::Solid),
        "word.mesh",
        7,
        "a vertex (coordinates and a reference) needs 4 numbers, this line has 1 \
         (in `Vertices` of line 3); `one` is not a number",
    );
    vertices[2] = "0 nan 0 0";
    assert_line_error(
        load_text("nan.mesh", &two_tets(&vertices, &TETS), MeshKind::Solid),
        "nan.mesh",
        7,
        "coordinate `nan` is not finite",
    );
    vertices[2] = "0 -inf 0 0";
    assert_line_error(
        load_text("inf.mesh", &two_tets(&vertices, &TETS), MeshKind::Solid),
        "inf.mesh",
        7,
        "coordinate `-inf` is not finite",
    );
    assert_line_error(
        load_text(
            "fraction.mesh",
            &two_tets(&VERTICES, &["1 2 3 4.5 0", TETS[1]]),
            MeshKind::Solid,
        ),
        "fraction.mesh",
        12,
        "`4.5` is not an integer (vertex index)",
    );
}

#[test]
fn medit_element_errors() {
    let cases: [(&str, [&str; 2], usize, &str); 6] = [
        (
            "indices.mesh",
            ["1 2 3 0", TETS[1]],
            12,
            "needs 5 numbers, this line has 4",
        ),
        (
            "range.mesh",
            ["1 2 3 6 0", TETS[1]],
            12,
            "index 6 is out of range: the vertices are 1..=5",
        ),
        (
            "zero.mesh",
            ["0 2 3 4 0", TETS[1]],
            12,
            "vertex index 0 is out of range",
        ),
        (
            "repeat.mesh",
            [TETS[0], "2 3 3 5 0"],
            13,
            "tetrahedron repeats vertex 3",
        ),
        (
            "mixed.mesh",
            [TETS[0], "2 4 3 5 0"],
            13,
            "tetrahedron is inverted relative to the others: signed volume -3.3",
        ),
        (
            "overlap.mesh",
            [TETS[0], "1 2 3 5 0"],
            13,
            "element on line 12: both lie on the same side of their shared face (1 2 3)",
        ),
    ];
    for (name, tets, line, needle) in cases {
        assert_line_error(
            load_text(name, &two_tets(&VERTICES, &tets), MeshKind::Solid),
            name,
            line,
            needle,
        );
    }
}

#[test]
fn medit_geometry_errors() {
    // Vertex 5 flattened into the plane of 2 3 4: the second tet is degenerate.
    let mut vertices = VERTICES;
    vertices[4] = "0.5 0.5 0 0";
    let flat = ["1 2 3 4 0", "2 3 5 1 0"];
    assert_line_error(
        load_text("flat.mesh", &two_tets(&vertices, &flat), MeshKind::Solid),
        "flat.mesh",
        13,
        "tetrahedron is degenerate: signed volume 0e0 (longest edge 1.4",
    );
    // A vertex no tet uses is named at its own line.
    assert_line_error(
        load_text("unused.mesh", &two_tets(&VERTICES, &TETS[..1]), MeshKind::Solid),
        "unused.mesh",
        9,
        "vertex 5 is used by no element, so it would have no mass (1 unused vertices in all)",
    );
    // A third tet on the face (2 3 4) between the first two.
    let vertices = [
        VERTICES[0],
        VERTICES[1],
        VERTICES[2],
        VERTICES[3],
        VERTICES[4],
        "0.1 0.1 0.1 0",
    ];
    let tets = ["1 2 3 4 0", "2 3 4 5 0", "6 2 3 4 0"];
    let text = two_tets(&vertices, &tets);
    assert_line_error(
        load_text("fan.mesh", &text, MeshKind::Solid),
        "fan.mesh",
        15,
        "face (2 3 4) is shared by more than two tetrahedra: also by the element on line 13 \
         and the element on line 14",
    );
}

#[test]
fn medit_two_dimensional_and_surface_files() {
    let planar = "Dimension 2\nVertices\n3\n0 0 0\n1 0 0\n0 1 0\nTriangles\n1\n1 2 3 0\nEnd\n";
    let mesh = load_text("planar.mesh", planar, MeshKind::Auto).unwrap();
    assert_eq!(mesh.dim, 2);
    assert_eq!(mesh.elements, Elements::Triangles(vec![[0, 1, 2]]));
    assert_file_error(
        load_text("planar.mesh", planar, MeshKind::Solid),
        "planar.mesh",
        "a 2D MEDIT file cannot be read as a solid (tetrahedra); load it as MeshKind::Planar",
    );
    let surface = "Dimension 3\nVertices\n3\n0 0 0 0\n1 0 0 0\n0 1 0 0\nTriangles\n1\n1 2 3 0\nEnd\n";
    let mesh = load_text("surface.mesh", surface, MeshKind::Cloth).unwrap();
    assert_eq!(mesh.elements, Elements::Shell(vec![[0, 1, 2]]));
    assert_file_error(
        load_text("surface.mesh", surface, MeshKind::Auto),
        "surface.mesh",
        "no tetrahedra (the file has 1 triangles: load it as MeshKind::Cloth",
    );
    assert_line_error(
        load_text("dim4.mesh", "Dimension 4\n", MeshKind::Auto),
        "dim4.mesh",
        1,
        "dimension 4 is not supported",
    );
}

#[test]
fn medit_element_references_are_kept() {
    let tets = ["1 2 3 4 7", "2 3 4 5 -2"];
    let mesh = load_text("ok.mesh", &two_tets(&VERTICES, &tets), MeshKind::Auto).unwrap();
    assert_eq!(mesh.attributes, Some(vec![7, -2]));
    let fraction = ["1 2 3 4 7", "2 3 4 5 1.5"];
    let result = load_text("bad.mesh", &two_tets(&VERTICES, &fraction), MeshKind::Auto);
    assert!(result
        .unwrap_err()
        .to_string()
        .contains("`1.5` is not an integer (element reference)"));
}
