//! Tests of the `.obj` reader.

use super::*;

#[test]
fn obj_cloth_with_all_reference_forms() {
    let text = "# two quads\nmtllib x.mtl\no sheet\nv 0 0 0\nv 1 0 0 1.0\nv 2 0 0\nv 0 1 0\n\
                v 1 1 0 0.5 0.5 0.5\nv 2 1 0\nvt 0 0\nvn 0 0 1\ns off\n\
                f 1/1/1 2/1/1 5/1/1 4/1/1\nf -5//1 -4 \\\n -1/1 -2\n";
    let mesh = load_text("quads.obj", text, MeshKind::Auto).unwrap();
    assert_eq!(mesh.num_vertices(), 6);
    assert_eq!(mesh.rest[3..6], [1.0, 0.0, 0.0]);
    assert_eq!(
        mesh.elements,
        Elements::Shell(vec![[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
    );
    assert_eq!(mesh, load_text("quads.obj", text, MeshKind::Cloth).unwrap());
    // A pentagon is fanned from its first vertex.
    let pentagon = "v 0 0 0\nv 2 0 0\nv 3 1 0\nv 1 2 0\nv -1 1 0\nf 1 2 3 4 5\n";
    let mesh = load_text("pentagon.obj", pentagon, MeshKind::Cloth).unwrap();
    assert_eq!(mesh.elements, Elements::Shell(vec![[0, 1, 2], [0, 2, 3], [0, 3, 4]]));
}

#[test]
fn obj_rods() {
    let text = "v 0 0 0\nv 0 -1 0\nv 0 -2 0\nv 1 0 0\nv 1 -1 0\nl 1 2 3\nl 4/1 5/2\n";
    let mesh = load_text("rods.obj", text, MeshKind::Auto).unwrap();
    assert_eq!(mesh.elements, Elements::Rods(vec![vec![0, 1, 2], vec![3, 4]]));
    assert_eq!(mesh.num_elements(), 3);
    assert_eq!(mesh, load_text("rods.obj", text, MeshKind::Rods).unwrap());
    assert_file_error(
        load_text("rods.obj", text, MeshKind::Cloth),
        "rods.obj",
        "no faces (`f`) to read as cloth; the file holds lines: load it as MeshKind::Rods",
    );
    assert_file_error(
        load_text("rods.obj", text, MeshKind::Solid),
        "rods.obj",
        ".obj files hold cloth (faces) or rods (lines), not a solid (tetrahedra)",
    );
}

#[test]
fn obj_errors() {
    let square = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";
    let cases: [(&str, usize, &str); 11] = [
        (
            "f 1 2 3\nf 1 3 4\nl 1 2\n",
            7,
            "a line (`l`) after faces (`f`, from line 5): a body is either cloth or rods",
        ),
        ("f 1 2\n", 5, "a face needs at least 3 vertices, this one has 2"),
        ("l 1\n", 5, "a line needs at least 2 vertices, this one has 1"),
        ("f 1 2 0\n", 5, "vertex reference `0`: .obj indices start at 1, not 0"),
        ("f 1 2 5\n", 5, "vertex index 5 is out of range: the vertices are 1..=4"),
        (
            "f 1 2 -5\n",
            5,
            "vertex reference -5 is before the first vertex (4 defined so far)",
        ),
        (
            "f 1 2 3/x\n",
            5,
            "`3/x` is not a vertex reference (expected v, v/vt, v//vn or v/vt/vn)",
        ),
        ("f 1 2 3/1/1/1\n", 5, "is not a vertex reference"),
        ("f 1 2 2\nf 1 3 4\n", 5, "triangle repeats vertex 2"),
        (
            "f 1 2 3\nf 1 4 3\n",
            6,
            "triangle is wound against the element on line 5 across their shared edge (1 3)",
        ),
        ("f 1 2 3\n", 4, "vertex 4 is used by no element"),
    ];
    for (faces, line, needle) in cases {
        let text = format!("{square}{faces}");
        assert_line_error(load_text("bad.obj", &text, MeshKind::Auto), "bad.obj", line, needle);
    }
    assert_line_error(
        load_text("v.obj", "v 0 0\n", MeshKind::Auto),
        "v.obj",
        1,
        "a vertex needs x y z (and optionally w, or r g b colours); this one has 2 numbers",
    );
    assert_line_error(
        load_text("v.obj", "v 0 inf 0\n", MeshKind::Auto),
        "v.obj",
        1,
        "coordinate `inf` is not finite",
    );
    assert_line_error(
        load_text("flat.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", MeshKind::Auto),
        "flat.obj",
        4,
        "triangle is degenerate: area 0e0",
    );
    assert_line_error(
        load_text("short.obj", "v 0 0 0\nv 0 0 0\nl 1 2\n", MeshKind::Auto),
        "short.obj",
        3,
        "rod is degenerate: shortest segment 0e0",
    );
    assert_file_error(
        load_text("none.obj", "v 0 0 0\n", MeshKind::Auto),
        "none.obj",
        "no faces (`f`) or lines (`l`)",
    );
    assert_file_error(
        load_text("empty.obj", "# nothing\n", MeshKind::Auto),
        "empty.obj",
        "no vertices",
    );
    assert_file_error(
        load_text("mesh.stl", "solid", MeshKind::Auto),
        "mesh.stl",
        "unknown mesh format",
    );
}
