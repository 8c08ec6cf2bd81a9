//! Scales against hand-computed values on a tet, a triangle and a box.

use super::*;

#[test]
fn single_tet_scales_are_opposite_face_areas_and_quarter_volumes() {
    let rest = [0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.0, 1.0];
    let e = tets(&rest, &[[0, 1, 2, 3]], MaterialLaw::Stvk, RUBBER);
    let s = NodeScales::new(3, &rest, &[&e]).unwrap();
    // Faces opposite each vertex: (2,0,0)-(0,3,0)-(0,0,1) has area |(3, 2, 6)| / 2 = 3.5;
    // the others are right triangles with legs 3 x 1, 2 x 1 and 2 x 3. Volume 2 * 3 / 6 = 1.
    for (got, want) in s.area.iter().zip([3.5, 1.5, 1.0, 3.0]) {
        assert!(close(*got, want, 1e-14), "area {got} vs {want}");
    }
    assert!(s.volume.iter().all(|v| close(*v, 0.25, 1e-14)), "{:?}", s.volume);
    let h = stvk_rest_norm(RUBBER, 3);
    assert!(
        s.hessian_norm.iter().all(|v| close(*v, h, 1e-12)),
        "{:?} vs {h}",
        s.hessian_norm
    );
    assert!(close(s.error_scale(0, 0.1), 0.01 * 3.5 * h, 1e-12));
    assert!(close(s.progress_scale(2, 0.1), 0.01 * 0.25 * h, 1e-12));
}

#[test]
fn single_triangle_scales_are_opposite_edges_and_third_areas() {
    let rest = [0.0, 0.0, 3.0, 0.0, 0.0, 4.0];
    let e = Tri2dElastic::new(MaterialLaw::Stvk, &rest, &[[0, 1, 2]], &[RUBBER], Path::new("test")).unwrap();
    let s = NodeScales::new(2, &rest, &[&e]).unwrap();
    for (got, want) in s.area.iter().zip([5.0, 4.0, 3.0]) {
        assert!(close(*got, want, 1e-14), "length {got} vs {want}");
    }
    assert!(s.volume.iter().all(|v| close(*v, 2.0, 1e-14)), "{:?}", s.volume);
    let h = stvk_rest_norm(RUBBER, 2);
    assert!(
        s.hessian_norm.iter().all(|v| close(*v, h, 1e-12)),
        "{:?} vs {h}",
        s.hessian_norm
    );
}

#[test]
fn box_scales_match_the_kuhn_split_by_hand() {
    // Two unit cubes along x, 6 tets each around the diagonal (0,0,0)-(1,1,1) of each cube.
    let mesh = box_tets([0.0; 3], [2.0, 1.0, 1.0], [2, 1, 1]).unwrap();
    let Elements::Tets(t) = &mesh.elements else {
        unreachable!()
    };
    let neo = tets(&mesh.rest, t, MaterialLaw::StableNeoHookean, RUBBER);
    let s = NodeScales::new(3, &mesh.rest, &[&neo]).unwrap();
    let id = |i: usize, j: usize, k: usize| i + 3 * (j + 2 * k);
    // A cube's diagonal corners lie in all 6 of its tets, the others in 2, each tet a sixth.
    let v = |tets: f64| tets / 6.0 / 4.0;
    let want_volume = [
        (id(0, 0, 0), v(6.0)),
        (id(1, 0, 0), v(2.0 + 6.0)),
        (id(2, 0, 0), v(2.0)),
        (id(1, 1, 1), v(6.0 + 2.0)),
        (id(2, 1, 1), v(6.0)),
        (id(0, 1, 0), v(2.0)),
    ];
    for (vertex, want) in want_volume {
        assert!(
            close(s.volume[vertex], want, 1e-14),
            "V of {vertex}: {} vs {want}",
            s.volume[vertex]
        );
    }
    assert!(close(s.volume.iter().sum(), 2.0, 1e-14));
    // The faces opposite a diagonal corner tile the cube's three far faces (area 3); the
    // faces opposite (1,0,0) in the first cube are the two half-diagonal planes through
    // (0,0,0), (1,1,0) or (1,0,1), and (1,1,1): right triangles of legs 1 and sqrt 2.
    let half_diagonal = 2.0f64.sqrt() / 2.0;
    for (vertex, want) in [
        (id(0, 0, 0), 3.0),
        (id(2, 1, 1), 3.0),
        (id(1, 0, 0), 2.0 * half_diagonal + 3.0),
    ] {
        assert!(
            close(s.area[vertex], want, 1e-14),
            "A of {vertex}: {} vs {want}",
            s.area[vertex]
        );
    }
    // The density Hessian at rest depends on the material only, not on the tet's shape.
    let first = s.hessian_norm[0];
    assert!(
        s.hessian_norm.iter().all(|h| close(*h, first, 1e-10)),
        "{:?}",
        s.hessian_norm
    );
    let stiffer = tets(
        &mesh.rest,
        t,
        MaterialLaw::StableNeoHookean,
        ElementMaterial {
            youngs: 3.0 * RUBBER.youngs,
            ..RUBBER
        },
    );
    let s3 = NodeScales::new(3, &mesh.rest, &[&stiffer]).unwrap();
    assert!(close(s3.hessian_norm[5], 3.0 * first, 1e-12));
}

#[test]
fn scales_reject_non_simplex_stencils_and_uncovered_vertices() {
    let rest = [
        0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 5.0, 5.0, 5.0,
    ];
    let e = tets(&rest, &[[0, 1, 2, 3]], MaterialLaw::Stvk, RUBBER);
    let err = NodeScales::new(3, &rest, &[&e]).unwrap_err();
    assert!(err.to_string().contains("vertex 4"), "{err}");
    let load = ConstantForce::load(3, vec![0], [1.0, 0.0, 0.0]);
    let err = NodeScales::new(3, &rest[..12], &[&load]).unwrap_err();
    assert!(err.to_string().contains("4 vertices"), "{err}");
}
