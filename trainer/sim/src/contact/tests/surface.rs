use crate::contact::surface::*;
use crate::mesh::procedural::box_tets;
use crate::mesh::{Elements, Mesh};

/// Signed volume enclosed by outward triangles (divergence theorem).
fn enclosed_volume(rest: &[f64], faces: &[[usize; 3]]) -> f64 {
    let p = |v: usize| [rest[3 * v], rest[3 * v + 1], rest[3 * v + 2]];
    faces
        .iter()
        .map(|f| {
            let (a, b, c) = (p(f[0]), p(f[1]), p(f[2]));
            let bc = [
                b[1] * c[2] - b[2] * c[1],
                b[2] * c[0] - b[0] * c[2],
                b[0] * c[1] - b[1] * c[0],
            ];
            (a[0] * bc[0] + a[1] * bc[1] + a[2] * bc[2]) / 6.0
        })
        .sum()
}

#[test]
fn surface_of_a_single_tet_is_the_tet() {
    let mesh = Mesh {
        dim: 3,
        rest: vec![0., 0., 0., 1., 0., 0., 0., 1., 0., 0., 0., 1.],
        elements: Elements::Tets(vec![[0, 1, 2, 3]]),
        attributes: None,
    };
    let s = ContactSurface::of_mesh(&mesh);
    assert_eq!(s.faces.len(), 4);
    assert_eq!(s.edges, vec![[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]);
    assert_eq!(s.vertices, vec![0, 1, 2, 3]);
    assert!((enclosed_volume(&mesh.rest, &s.faces) - 1.0 / 6.0).abs() < 1e-15);
}

#[test]
fn surface_of_a_box_is_closed_outward_and_skips_the_interior() {
    let mesh = box_tets([0.0; 3], [2.0, 1.0, 1.0], [3, 2, 2]).unwrap();
    let s = ContactSurface::of_mesh(&mesh);
    // Two triangles per boundary square.
    assert_eq!(s.faces.len(), 2 * 2 * (3 * 2 + 3 * 2 + 2 * 2));
    // Closed surface of a ball: V - E + F = 2, and each edge bounds two faces.
    assert_eq!(s.vertices.len() as i64 - s.edges.len() as i64 + s.faces.len() as i64, 2);
    assert_eq!(2 * s.edges.len(), 3 * s.faces.len());
    assert!((enclosed_volume(&mesh.rest, &s.faces) - 2.0).abs() < 1e-12, "outward");
    // Grid vertices not on the boundary: (3-1)(2-1)(2-1) = 2 interior ones.
    assert_eq!(s.vertices.len(), mesh.num_vertices() - 2);
}

#[test]
fn surface_of_a_2d_square_is_its_four_boundary_edges_and_cloth_keeps_its_triangles() {
    let tris = vec![[0, 1, 2], [0, 2, 3]];
    let square = Mesh {
        dim: 2,
        rest: vec![0., 0., 1., 0., 1., 1., 0., 1.],
        elements: Elements::Triangles(tris.clone()),
        attributes: None,
    };
    let s = ContactSurface::of_mesh(&square);
    assert_eq!(s.edges, vec![[0, 1], [1, 2], [2, 3], [3, 0]]);
    assert!(s.faces.is_empty());
    assert_eq!(triangle_edges(&tris), vec![[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]);
    let cloth = Mesh {
        dim: 3,
        rest: vec![0.0; 12],
        elements: Elements::Shell(tris.clone()),
        attributes: None,
    };
    let s = ContactSurface::of_mesh(&cloth);
    assert_eq!((s.faces, s.edges.len(), s.vertices.len()), (tris, 5, 4));
}
