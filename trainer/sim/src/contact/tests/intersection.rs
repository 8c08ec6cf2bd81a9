use super::broad_phase::square_2d;
use crate::contact::intersection::*;
use crate::contact::ContactSurface;
use crate::mesh::procedural::box_tets;

const T: [[f64; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];

#[test]
fn segments_and_triangles_meet_when_they_cross_touch_or_overlap_in_plane() {
    let hit = |a: [f64; 3], b: [f64; 3]| segment_triangle_intersect(a, b, T);
    assert!(hit([0.2, 0.2, 1.0], [0.2, 0.2, -1.0]), "through the interior");
    assert!(hit([0.2, 0.2, 1.0], [0.2, 0.2, 0.0]), "ending on the face");
    assert!(hit([1.0, 0.0, 1.0], [1.0, 0.0, -1.0]), "through a vertex");
    assert!(hit([0.5, 0.5, 1.0], [0.5, 0.5, -1.0]), "through an edge");
    assert!(hit([-1.0, 0.2, 0.0], [2.0, 0.2, 0.0]), "in the plane, across");
    assert!(hit([0.1, 0.1, 0.0], [0.2, 0.1, 0.0]), "in the plane, inside");
    assert!(!hit([0.2, 0.2, 1.0], [0.2, 0.2, 1e-100]), "ending just above");
    assert!(!hit([0.6, 0.6, 1.0], [0.6, 0.6, -1.0]), "beside the hypotenuse");
    assert!(
        !hit([0.5 + 1e-15, 0.5, 1.0], [0.5 + 1e-15, 0.5, -1.0]),
        "beside an edge by 1e-15"
    );
    assert!(!hit([-1.0, 0.2, 1e-3], [2.0, 0.2, 1e-3]), "parallel above");
    assert!(!hit([-1.0, 2.0, 0.0], [2.0, 2.0, 0.0]), "in the plane, outside");
}

#[test]
fn plane_segments_meet_when_they_cross_touch_or_overlap_on_a_line() {
    let hit = segments_intersect_2d;
    assert!(hit([0.0, 0.0], [1.0, 1.0], [0.0, 1.0], [1.0, 0.0]), "an X");
    assert!(hit([0.0, 0.0], [1.0, 0.0], [0.5, 0.0], [0.5, 1.0]), "a T");
    assert!(hit([0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [2.0, 1.0]), "end to end");
    assert!(
        hit([0.0, 0.0], [2.0, 0.0], [1.0, 0.0], [3.0, 0.0]),
        "overlapping on a line"
    );
    assert!(!hit([0.0, 0.0], [1.0, 0.0], [1.5, 0.0], [3.0, 0.0]), "apart on a line");
    assert!(!hit([0.0, 0.0], [1.0, 0.0], [0.0, 1e-100], [1.0, 1e-100]), "parallel");
    assert!(
        !hit([0.0, 0.0], [1.0, 0.0], [0.5, 1e-100], [0.5, 1.0]),
        "a T short by 1e-100"
    );
    assert!(
        hit([0.5, 0.0], [0.5, 0.0], [0.0, 0.0], [1.0, 0.0]),
        "a point on a segment"
    );
    assert!(
        !hit([0.5, 1.0], [0.5, 1.0], [0.0, 0.0], [1.0, 0.0]),
        "a point off a segment"
    );
}

#[test]
fn two_boxes_intersect_only_when_they_overlap() {
    let a = box_tets([0.0; 3], [1.0; 3], [2, 2, 2]).unwrap();
    let mut surface = ContactSurface::of_mesh(&a);
    let n = a.rest.len() / 3;
    surface.append(&ContactSurface::of_mesh(&a), n);
    let placed = |shift: [f64; 3]| -> Vec<f64> {
        let b = a.rest.iter().enumerate().map(|(i, v)| v + shift[i % 3]);
        a.rest.iter().copied().chain(b).collect()
    };
    assert!(!has_intersections(&surface, &placed([1.5, 0.2, 0.1])));
    assert!(!has_intersections(&surface, &placed([1.0 + 1e-12, 0.2, 0.1])));
    let pairs = intersecting_pairs(&surface, &placed([0.7, 0.2, 0.1]));
    assert!(!pairs.is_empty());
    for [e, f] in pairs {
        assert!(surface.edges[e].iter().all(|&v| v < n) != surface.faces[f].iter().all(|&v| v < n));
    }
    // A single box does not intersect itself.
    assert!(!has_intersections(&ContactSurface::of_mesh(&a), &a.rest));
}

#[test]
fn two_squares_intersect_only_when_they_overlap() {
    let a = square_2d(3, [0.0, 0.0], 1.0);
    let mut surface = ContactSurface::of_mesh(&a);
    let n = a.rest.len() / 2;
    surface.append(&ContactSurface::of_mesh(&a), n);
    let placed = |shift: [f64; 2]| -> Vec<f64> {
        let b = a.rest.iter().enumerate().map(|(i, v)| v + shift[i % 2]);
        a.rest.iter().copied().chain(b).collect()
    };
    assert!(!has_intersections(&surface, &placed([1.01, 0.3])));
    assert!(has_intersections(&surface, &placed([0.9, 0.3])));
    assert!(has_intersections(&surface, &placed([1.0, 0.3])), "touching counts");
}
