//! Tests of the `.node` + `.ele` reader.

use super::*;

/// A unit square of two triangles, numbered from 0, with an attribute and a marker.
const SQUARE_NODE: &str = "# square\n4 2 1 1\n0 0 0 7 1\n1 1 0 7 1\n2 1 1 7 1\n3 0 1 7 1\n";
const SQUARE_ELE: &str = "2 3 1\n0 0 1 2 5\n1 0 2 3 5\n";

fn load_node_ele(node: &str, ele: &str, kind: MeshKind) -> Result<Mesh, InputError> {
    load_files(&[("sq.node", node), ("sq.ele", ele)], kind)
}

#[test]
fn node_ele_zero_based_with_attributes_loads() {
    let mesh = load_node_ele(SQUARE_NODE, SQUARE_ELE, MeshKind::Auto).unwrap();
    assert_eq!(mesh.rest, vec![0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0]);
    assert_eq!(mesh.elements, Elements::Triangles(vec![[0, 1, 2], [0, 2, 3]]));
    // Clockwise triangles are all flipped.
    let clockwise = "2 3 1\n0 0 2 1 5\n1 0 3 2 5\n";
    let flipped = load_node_ele(SQUARE_NODE, clockwise, MeshKind::Planar).unwrap();
    assert!(triangle_areas(&flipped).iter().all(|&a| a > 0.0));
}

#[test]
fn ele_region_attributes_are_kept() {
    let mesh = load_node_ele(SQUARE_NODE, SQUARE_ELE, MeshKind::Auto).unwrap();
    assert_eq!(mesh.attributes, Some(vec![5, 5]));
    // The first of several attributes, integers written as floats, none without any.
    let two = "2 3 2\n0 0 1 2 -3.0 0.25\n1 0 2 3 4e0 7\n";
    let mesh = load_node_ele(SQUARE_NODE, two, MeshKind::Auto).unwrap();
    assert_eq!(mesh.attributes, Some(vec![-3, 4]));
    let none = "2 3\n0 0 1 2\n1 0 2 3\n";
    assert_eq!(
        load_node_ele(SQUARE_NODE, none, MeshKind::Auto).unwrap().attributes,
        None
    );
    let fraction = "2 3 1\n0 0 1 2 5\n1 0 2 3 0.5\n";
    assert_line_error(
        load_node_ele(SQUARE_NODE, fraction, MeshKind::Auto),
        "sq.ele",
        3,
        "region attribute `0.5` is not an integer",
    );
}

#[test]
fn node_kind_mismatch_names_the_header_line() {
    assert_line_error(
        load_node_ele(SQUARE_NODE, SQUARE_ELE, MeshKind::Cloth),
        "sq.node",
        2,
        "a 2D .node file (Triangle) cannot be read as cloth (3D triangles)",
    );
}

#[test]
fn node_ele_tetgen_loads() {
    let node = "5 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n";
    let ele = "2 4 0\n1 1 2 3 4\n2 2 3 4 5\n";
    let mesh = load_files(&[("t.ele", ele), ("t.node", node)], MeshKind::Solid).unwrap();
    assert_eq!(mesh.elements, Elements::Tets(vec![[0, 1, 2, 3], [1, 2, 3, 4]]));
    assert_line_error(
        load_files(&[("t.node", node), ("t.ele", ele)], MeshKind::Planar),
        "t.node",
        1,
        "a 3D .node file (TetGen) cannot be read as a planar solid (2D triangles); load it as \
         MeshKind::Solid",
    );
    assert_line_error(
        load_files(
            &[("t.node", node), ("t.ele", "1 10 0\n1 1 2 3 4 5 6 7 8 9 10\n")],
            MeshKind::Solid,
        ),
        "t.ele",
        1,
        "elements have 10 vertices; the 3D .node file needs 4 (quadratic elements are not \
         supported)",
    );
}

#[test]
fn node_errors() {
    let cases: [(&str, usize, &str); 7] = [
        (
            "5 2 1 1\n0 0 0 7 1\n1 1 0 7 1\n2 1 1 7 1\n3 0 1 7 1\n",
            1,
            "the header declares 5 vertices but the file has only 4",
        ),
        (
            "3 2 1 1\n0 0 0 7 1\n1 1 0 7 1\n2 1 1 7 1\n3 0 1 7 1\n",
            5,
            "the header (line 1) declares 3 vertices; this is one more",
        ),
        (
            "4 2 1 1\n0 0 0 7 1\n1 1 0 7\n2 1 1 7 1\n3 0 1 7 1\n",
            3,
            "needs 5 numbers (index, 2 coordinates, 1 attributes, 1 markers), this one has 4",
        ),
        (
            "4 2 1 1\n0 0 0 7 1\n1 1 0 7 1\n2 1 one 7 1\n3 0 1 7 1\n",
            4,
            "`one` is not a number (coordinate)",
        ),
        (
            "4 2 1 1\n0 0 0 7 1\n1 1 0 7 1\n2 1 NaN 7 1\n3 0 1 7 1\n",
            4,
            "coordinate `NaN` is not finite",
        ),
        (
            "4 2 1 1\n0 0 0 7 1\n1 1 0 7 1\n3 1 1 7 1\n3 0 1 7 1\n",
            4,
            "vertices must be numbered consecutively: expected 2, found 3",
        ),
        ("0 2 0 0\n", 1, "the header declares no vertices"),
    ];
    for (node, line, needle) in cases {
        assert_line_error(load_node_ele(node, SQUARE_ELE, MeshKind::Auto), "sq.node", line, needle);
    }
    assert_file_error(
        load_files(&[("lonely.node", SQUARE_NODE)], MeshKind::Auto),
        "lonely.ele",
        "cannot read",
    );
}

#[test]
fn ele_errors() {
    let cases: [(&str, usize, &str); 7] = [
        (
            "3 3 1\n0 0 1 2 5\n1 0 2 3 5\n",
            1,
            "the header declares 3 elements but the file has only 2",
        ),
        (
            "1 3 1\n0 0 1 2 5\n1 0 2 3 5\n",
            3,
            "the header (line 1) declares 1 elements; this is one more",
        ),
        (
            "2 3 1\n0 0 1 2 5\n1 0 2 3\n",
            3,
            "needs 5 numbers (index, 3 vertex indices, 1 attributes), this one has 4",
        ),
        (
            "2 3 1\n0 0 1 2 5\n1 0 2 4 5\n",
            3,
            "vertex index 4 is out of range: the vertices are 0..=3",
        ),
        ("2 3 1\n0 0 1 2 5\n1 0 2 2 5\n", 3, "triangle repeats vertex 2"),
        (
            "2 3 1\n0 0 1 2 5\n1 0 3 2 5\n",
            3,
            "triangle is inverted relative to the others: signed area -5e-1",
        ),
        (
            "2 3 1\n0 0 1 2 5\n1 0 1 3 5\n",
            3,
            "triangle overlaps the element on line 2",
        ),
    ];
    for (ele, line, needle) in cases {
        assert_line_error(load_node_ele(SQUARE_NODE, ele, MeshKind::Auto), "sq.ele", line, needle);
    }
    // A vertex no triangle uses is reported in the .node file.
    assert_line_error(
        load_node_ele(SQUARE_NODE, "1 3 0\n0 0 1 2\n", MeshKind::Auto),
        "sq.node",
        6,
        "vertex 3 is used by no element",
    );
    // Collinear vertices.
    let node = "3 2\n1 0 0\n2 1 1\n3 2 2\n";
    assert_line_error(
        load_files(&[("line.node", node), ("line.ele", "1 3\n1 1 2 3\n")], MeshKind::Auto),
        "line.ele",
        2,
        "triangle is degenerate: signed area 0e0",
    );
}
