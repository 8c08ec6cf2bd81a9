//! Tests of `mesh`.

use super::procedural::{box_tets, cloth_grid};
use super::*;
use crate::error::Location;
use std::path::Path;

fn unit_tet() -> Mesh {
    Mesh {
        dim: 3,
        rest: vec![0., 0., 0., 1., 0., 0., 0., 1., 0., 0., 0., 1.],
        elements: Elements::Tets(vec![[0, 1, 2, 3]]),
        attributes: None,
    }
}

fn total_volume(mesh: &Mesh) -> f64 {
    mesh.signed_measures().unwrap().iter().sum()
}

#[test]
fn edges_are_listed_once() {
    assert_eq!(unit_tet().edges(), vec![[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]);
    // A 3 x 3 grid of squares: 12 horizontal, 12 vertical and 9 diagonal edges.
    let grid = cloth_grid([1.0, 1.0], [4, 4], [0.0; 3], ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])).unwrap();
    assert_eq!(grid.edges().len(), 33);
    let rods = Mesh {
        dim: 3,
        rest: vec![0.0; 15],
        elements: Elements::Rods(vec![vec![0, 1, 2], vec![4, 3]]),
        attributes: None,
    };
    assert_eq!(rods.edges(), vec![[0, 1], [1, 2], [3, 4]]);
}

#[test]
fn normalized_centres_and_fits_the_largest_extent() {
    let mesh = box_tets([1.0, -2.0, 3.0], [5.0, 0.0, 4.0], [2, 1, 1]).unwrap();
    let normal = mesh.normalized();
    let (lo, hi) = normal.bounding_box(&normal.rest);
    assert_eq!(lo, [-0.5, -0.25, -0.125]);
    assert_eq!(hi, [0.5, 0.25, 0.125]);
    assert_eq!(normal.elements, mesh.elements);
    // 2D meshes stay 2D.
    let bar = Mesh {
        dim: 2,
        rest: vec![0.0, 0.0, 8.0, 0.0, 8.0, 1.0],
        elements: Elements::Triangles(vec![[0, 1, 2]]),
        attributes: None,
    };
    assert_eq!(bar.normalized().rest, vec![-0.5, -0.0625, 0.5, -0.0625, 0.5, 0.0625]);
}

#[test]
fn scaled_per_axis_and_mirrored_stays_positive() {
    let mesh = unit_tet();
    let stretched = mesh.scaled(&[2.0, 3.0]);
    assert_eq!(stretched.rest, vec![0., 0., 0., 2., 0., 0., 0., 3., 0., 0., 0., 1.]);
    approx::assert_relative_eq!(total_volume(&stretched), 1.0, max_relative = 1e-15);
    let mirrored = mesh.scaled(&[-1.0, 1.0, 1.0, 7.0]);
    assert_eq!(mirrored.elements, Elements::Tets(vec![[0, 1, 3, 2]]));
    approx::assert_relative_eq!(total_volume(&mirrored), 1.0 / 6.0, max_relative = 1e-15);
    mirrored.validate(Path::new("mirrored")).unwrap();
    let flat = mesh.scaled(&[1.0, 0.0, 1.0]);
    let err = flat.validate(Path::new("flat")).unwrap_err();
    assert_eq!(err.location, Location::Element(0));
    assert!(
        err.to_string()
            .starts_with("flat: element 0: tetrahedron is degenerate"),
        "{err}"
    );
    // Mirrored cloth keeps its (mirrored) facing.
    let cloth = cloth_grid([1.0, 1.0], [2, 2], [0.0; 3], ([1., 0., 0.], [0., 1., 0.])).unwrap();
    let Elements::Shell(t) = &cloth.scaled(&[1.0, 1.0, -1.0]).elements else {
        unreachable!()
    };
    assert_eq!(t[0], [0, 3, 1]);
}

#[test]
fn with_positive_orientation_flips_only_when_all_are_inverted() {
    let inverted = Mesh {
        elements: Elements::Tets(vec![[0, 2, 1, 3]]),
        ..unit_tet()
    };
    assert!(total_volume(&inverted) < 0.0);
    let err = inverted.validate(Path::new("x")).unwrap_err();
    assert!(
        err.to_string().contains("all 1 tetrahedra are negatively oriented"),
        "{err}"
    );
    let fixed = inverted.with_positive_orientation();
    assert!(total_volume(&fixed) > 0.0);
    fixed.validate(Path::new("x")).unwrap();
    // Mixed orientations are left for validate to report.
    let mut mixed = box_tets([0.0; 3], [1.0; 3], [1, 1, 1]).unwrap();
    if let Elements::Tets(tets) = &mut mixed.elements {
        tets[4].swap(0, 1);
    }
    let still = mixed.clone().with_positive_orientation();
    assert_eq!(still, mixed);
    let err = mixed.validate(Path::new("box")).unwrap_err();
    assert_eq!(err.location, Location::Element(4), "{err}");
    assert!(err.message.contains("inverted relative to the others"), "{err}");
    // Out-of-range indices do not panic.
    let mut broken = unit_tet();
    broken.elements = Elements::Tets(vec![[0, 1, 2, 9]]);
    assert_eq!(broken.clone().with_positive_orientation(), broken);
}

#[test]
fn validate_names_vertices_and_elements() {
    let path = Path::new("m");
    let mut mesh = unit_tet();
    mesh.rest.extend([5.0, 5.0, 5.0]);
    let err = mesh.validate(path).unwrap_err();
    assert_eq!(err.location, Location::File);
    assert!(err.message.starts_with("vertex 4 is used by no element"), "{err}");
    mesh.rest[4] = f64::NAN;
    let err = mesh.validate(path).unwrap_err();
    assert_eq!(
        err.to_string(),
        "m: vertex 1 has a non-finite coordinate [1.0, NaN, 0.0]"
    );
    let mut mesh = unit_tet();
    mesh.elements = Elements::Tets(vec![[0, 1, 2, 3], [0, 1, 2, 4]]);
    let err = mesh.validate(path).unwrap_err();
    assert_eq!(
        err.to_string(),
        "m: element 1: tetrahedron refers to vertex 4, but the vertices are 0..=3"
    );
    mesh.elements = Elements::Triangles(vec![[0, 1, 2]]);
    let err = mesh.validate(path).unwrap_err();
    assert!(
        err.to_string()
            .contains("triangles need 2 coordinates per vertex, the mesh has 3"),
        "{err}"
    );
    mesh.elements = Elements::Rods(vec![vec![0, 1, 2, 3], vec![3]]);
    let err = mesh.validate(path).unwrap_err();
    assert_eq!(
        err.to_string(),
        "m: element 1: rod has 1 vertices, at least 2 are needed"
    );
    mesh.elements = Elements::Rods(vec![vec![0, 1, 2, 0, 3]]);
    let err = mesh.validate(path).unwrap_err();
    assert_eq!(err.to_string(), "m: element 0: rod repeats vertex 0");
    mesh.elements = Elements::Rods(vec![]);
    let err = mesh.validate(path).unwrap_err();
    assert_eq!(err.to_string(), "m: the mesh has no rods");
    mesh.rest.clear();
    let err = mesh.validate(path).unwrap_err();
    assert_eq!(err.to_string(), "m: the mesh has no vertices");
}

#[test]
fn sorted_with_parity_counts_swaps() {
    assert_eq!(sorted_with_parity([3, 1, 2]), ([1, 2, 3], false));
    assert_eq!(sorted_with_parity([1, 3, 2]), ([1, 2, 3], true));
    assert_eq!(sorted_with_parity([3, 2, 1]), ([1, 2, 3], true));
    assert_eq!(sorted_with_parity([2, 1]), ([1, 2], true));
}
