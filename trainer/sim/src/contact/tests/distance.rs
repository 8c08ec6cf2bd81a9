use super::{assert_fd, fd, random_vec, rng};
use crate::contact::distance::*;
use crate::energy::{Local, Want};

const H: f64 = 1e-6;
const TOL: f64 = 1e-6;

const PT_TYPES: [PointTriangleType; 7] = [
    PointTriangleType::T0,
    PointTriangleType::T1,
    PointTriangleType::T2,
    PointTriangleType::E0,
    PointTriangleType::E1,
    PointTriangleType::E2,
    PointTriangleType::Interior,
];

const EE_TYPES: [EdgeEdgeType; 9] = [
    EdgeEdgeType::A0B0,
    EdgeEdgeType::A0B1,
    EdgeEdgeType::A1B0,
    EdgeEdgeType::A1B1,
    EdgeEdgeType::AB0,
    EdgeEdgeType::AB1,
    EdgeEdgeType::A0B,
    EdgeEdgeType::A1B,
    EdgeEdgeType::AB,
];

fn value(f: impl Fn(&mut Local) -> f64) -> f64 {
    f(&mut Local::default())
}

#[test]
fn point_point_and_point_edge_derivatives_match_finite_differences_in_2d_and_3d() {
    let mut rng = rng(1);
    for dim in [2, 3] {
        for _ in 0..20 {
            let x = random_vec(&mut rng, 2 * dim);
            assert_fd(
                fd(dim, &x, H, |x, w, o| point_point_distance(x, dim, w, o)),
                TOL,
                "point-point",
            );
            let x = random_vec(&mut rng, 3 * dim);
            for ty in [PointEdgeType::E0, PointEdgeType::E1, PointEdgeType::Interior] {
                let r = fd(dim, &x, H, |x, w, o| point_edge_distance_typed(x, dim, ty, w, o));
                assert_fd(r, TOL, &format!("point-edge {ty:?} {dim}D"));
            }
        }
    }
}

#[test]
fn point_triangle_and_edge_edge_derivatives_match_finite_differences_for_every_type() {
    let mut rng = rng(2);
    for _ in 0..20 {
        let x = random_vec(&mut rng, 12);
        for ty in PT_TYPES {
            assert_fd(
                fd(3, &x, H, |x, w, o| point_triangle_distance_typed(x, ty, w, o)),
                TOL,
                &format!("{ty:?}"),
            );
        }
        for ty in EE_TYPES {
            assert_fd(
                fd(3, &x, H, |x, w, o| edge_edge_distance_typed(x, ty, w, o)),
                TOL,
                &format!("{ty:?}"),
            );
        }
    }
}

#[test]
fn mollifier_derivatives_match_finite_differences_inside_its_ramp() {
    let mut rng = rng(3);
    for _ in 0..20 {
        // Nearly parallel edges: b = a + small perturbation, so |a x b|^2 < eps_x.
        let mut x = random_vec(&mut rng, 12);
        for i in 0..3 {
            x[9 + i] = x[6 + i] + (x[3 + i] - x[i]) + 0.01 * x[9 + i];
        }
        let eps_x = edge_edge_mollifier_threshold(&x) * 10.0;
        let m = value(|o| edge_edge_mollifier(&x, eps_x, Want::Value, o));
        assert!(m > 0.0 && m < 1.0, "mollifier {m} should be inside its ramp");
        assert_fd(
            fd(3, &x, 1e-7, |x, w, o| edge_edge_mollifier(x, eps_x, w, o)),
            1e-5,
            "mollifier",
        );
    }
}

#[test]
fn mollifier_is_zero_for_parallel_edges_and_c1_at_its_threshold() {
    assert_eq!(mollifier(0.0, 2.0), 0.0);
    let (eps, below, above) = (2.0, 2.0 * (1.0 - 1e-9), 2.0 * (1.0 + 1e-9));
    let (m0, d0, _) = mollifier_derivatives(below, eps);
    let (m1, d1, _) = mollifier_derivatives(above, eps);
    assert!((m0 - 1.0).abs() < 1e-12 && m1 == 1.0);
    assert!(d0.abs() < 1e-8 && d1 == 0.0);
    // Rest threshold: 1e-3 |a|^2 |b|^2.
    let rest = [0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 3.0];
    assert!((edge_edge_mollifier_threshold(&rest) - 1e-3 * 4.0 * 9.0).abs() < 1e-15);
}

#[test]
fn point_edge_classification_and_values_on_hand_made_cases() {
    // Edge from (0, 0) to (2, 0).
    let cases = [
        ([-1.0, 1.0], PointEdgeType::E0, 2.0),
        ([3.0, -1.0], PointEdgeType::E1, 2.0),
        ([0.5, 3.0], PointEdgeType::Interior, 9.0),
    ];
    for (p, ty, d) in cases {
        let x = [p[0], p[1], 0.0, 0.0, 2.0, 0.0];
        assert_eq!(point_edge_type(&x, 2), ty);
        assert!((value(|o| point_edge_distance(&x, 2, Want::Value, o)) - d).abs() < 1e-14);
    }
}

#[test]
fn point_triangle_classification_on_hand_made_cases() {
    // Triangle (0,0,0), (1,0,0), (0,1,0); point heights 0.5.
    let cases = [
        ([0.2, 0.2], PointTriangleType::Interior, 0.25),
        ([0.5, -1.0], PointTriangleType::E0, 1.25),
        ([1.0, 1.0], PointTriangleType::E1, 0.25 + 0.5),
        ([-1.0, 0.5], PointTriangleType::E2, 1.25),
        ([-1.0, -1.0], PointTriangleType::T0, 2.25),
        ([2.0, -0.5], PointTriangleType::T1, 1.0 + 0.25 + 0.25),
        ([-0.5, 2.0], PointTriangleType::T2, 0.25 + 1.0 + 0.25),
    ];
    for (p, ty, d) in cases {
        let x = [p[0], p[1], 0.5, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
        assert_eq!(point_triangle_type(&x), ty, "{p:?}");
        let got = value(|o| point_triangle_distance(&x, Want::Value, o));
        assert!((got - d).abs() < 1e-14, "{p:?}: {got} vs {d}");
    }
}

#[test]
fn edge_edge_classification_on_hand_made_cases() {
    // Edge a from (0,0,0) to (2,0,0); edge b given, each case's closest pair known.
    let cases = [
        ([1.0, -1.0, 1.0], [1.0, 1.0, 1.0], EdgeEdgeType::AB, 1.0),
        ([-1.0, -1.0, 1.0], [-1.0, 1.0, 1.0], EdgeEdgeType::A0B, 2.0),
        ([3.0, -1.0, 1.0], [3.0, 1.0, 1.0], EdgeEdgeType::A1B, 2.0),
        ([1.0, 0.0, 1.0], [1.0, 0.0, 3.0], EdgeEdgeType::AB0, 1.0),
        ([1.0, 0.0, 3.0], [1.0, 0.0, 1.0], EdgeEdgeType::AB1, 1.0),
        ([-1.0, 0.0, 1.0], [-1.0, 0.0, 3.0], EdgeEdgeType::A0B0, 2.0),
        ([3.0, 0.0, 3.0], [3.0, 0.0, 1.0], EdgeEdgeType::A1B1, 2.0),
        ([3.0, 0.0, 1.0], [3.0, 0.0, 3.0], EdgeEdgeType::A1B0, 2.0),
        ([-1.0, 0.0, 3.0], [-1.0, 0.0, 1.0], EdgeEdgeType::A0B1, 2.0),
        // Parallel, overlapping: an endpoint of b above the interior of a.
        ([0.5, 0.0, 1.0], [3.0, 0.0, 1.0], EdgeEdgeType::AB0, 1.0),
        // Parallel, disjoint along the line: endpoint to endpoint.
        ([5.0, 0.0, 0.0], [3.0, 0.0, 0.0], EdgeEdgeType::A1B1, 1.0),
    ];
    for (b0, b1, ty, d) in cases {
        let x = [0.0, 0.0, 0.0, 2.0, 0.0, 0.0, b0[0], b0[1], b0[2], b1[0], b1[1], b1[2]];
        assert_eq!(edge_edge_type(&x), ty, "{b0:?} {b1:?}");
        let got = value(|o| edge_edge_distance(&x, Want::Value, o));
        assert!((got - d).abs() < 1e-14, "{b0:?} {b1:?}: {got} vs {d}");
    }
}

/// Brute-force squared distance between `p` and the triangle `t`, on a barycentric grid.
fn sampled_point_triangle(x: &[f64]) -> f64 {
    let n = 400;
    let mut best = f64::INFINITY;
    for i in 0..=n {
        for j in 0..=n - i {
            let (b, c) = (i as f64 / n as f64, j as f64 / n as f64);
            let d: f64 = (0..3)
                .map(|k| {
                    let q = x[3 + k] + b * (x[6 + k] - x[3 + k]) + c * (x[9 + k] - x[3 + k]);
                    (x[k] - q).powi(2)
                })
                .sum();
            best = best.min(d);
        }
    }
    best
}

/// Brute-force squared distance between two segments, on a parameter grid.
fn sampled_edge_edge(x: &[f64]) -> f64 {
    let n = 1000;
    let mut best = f64::INFINITY;
    for i in 0..=n {
        for j in 0..=n {
            let (s, t) = (i as f64 / n as f64, j as f64 / n as f64);
            let d: f64 = (0..3)
                .map(|k| (x[k] + s * (x[3 + k] - x[k]) - x[6 + k] - t * (x[9 + k] - x[6 + k])).powi(2))
                .sum();
            best = best.min(d);
        }
    }
    best
}

#[test]
fn classified_distances_are_the_true_minima() {
    let mut rng = rng(4);
    for _ in 0..40 {
        let x = random_vec(&mut rng, 12);
        let pt = value(|o| point_triangle_distance(&x, Want::Value, o));
        let sampled = sampled_point_triangle(&x);
        assert!(
            pt <= sampled + 1e-12 && sampled - pt < 1e-4,
            "point-triangle {pt} vs sampled {sampled}"
        );
        let ee = value(|o| edge_edge_distance(&x, Want::Value, o));
        let sampled = sampled_edge_edge(&x);
        assert!(
            ee <= sampled + 1e-12 && sampled - ee < 1e-4,
            "edge-edge {ee} vs sampled {sampled}"
        );
    }
}

#[test]
fn classified_distances_have_matching_derivatives_away_from_type_boundaries() {
    let mut rng = rng(5);
    for _ in 0..50 {
        let x = random_vec(&mut rng, 12);
        assert_fd(fd(3, &x, H, point_triangle_distance), TOL, "point-triangle");
        assert_fd(fd(3, &x, H, edge_edge_distance), TOL, "edge-edge");
        assert_fd(
            fd(3, &x[..9], H, |x, w, o| point_edge_distance(x, 3, w, o)),
            TOL,
            "point-edge",
        );
    }
}
