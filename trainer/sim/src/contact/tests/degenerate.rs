//! Degenerate primitives (zero-area triangles, zero-length edges), pairs at distance zero and
//! points near an edge's far endpoint: exact distances of the sub-primitives, defined
//! derivatives, never a non-number.

use rand::Rng;

use super::{random_vec, rng};
use crate::contact::barrier::{barrier_force_magnitude, barrier_of_squared_distance, edge_edge_barrier};
use crate::contact::distance::*;
use crate::contact::friction::*;
use crate::energy::{Local, Want};

const EXACT: Want = Want::Hessian { project: false };

/// Every gradient and Hessian entry of a `n`-dof evaluation is a number.
fn all_finite(out: &Local, n: usize) -> bool {
    out.grad[..n].iter().chain(&out.hess[..n * n]).all(|v| v.is_finite())
}

/// The squared distance of `p` to the segment `[s, t]` (3D).
fn to_segment(p: &[f64], s: &[f64], t: &[f64]) -> f64 {
    let x: Vec<f64> = [p, s, t].concat();
    point_edge_distance(&x, 3, Want::Value, &mut Local::default())
}

/// A random dyadic vector (components `k / 8`, `|k| <= 8`): sums and differences of such
/// vectors and their small multiples are exact, so collinear points stay collinear.
fn dyadic(rng: &mut impl Rng) -> [f64; 3] {
    [0; 3].map(|_| rng.random_range(-8i32..=8) as f64 / 8.0)
}

/// Zero-area triangles: collinear vertices (the third on the line of the first two, inside
/// or outside their edge), two coincident vertices, all three coincident.
fn degenerate_triangles(rng: &mut impl Rng) -> Vec<[f64; 9]> {
    let (a, e) = (dyadic(rng), dyadic(rng));
    let at = |k: f64| [0, 1, 2].map(|i| a[i] + k * e[i]);
    let k = rng.random_range(-4i32..=8) as f64 / 4.0;
    [
        [at(0.0), at(1.0), at(k)],
        [at(0.0), at(1.0), at(1.0)],
        [at(0.0), at(0.0), at(1.0)],
        [at(1.0), at(0.0), at(1.0)],
        [at(0.0), at(0.0), at(0.0)],
    ]
    .into_iter()
    .map(|t| {
        let mut out = [0.0; 9];
        out.copy_from_slice(&t.concat());
        out
    })
    .collect()
}

#[test]
fn zero_area_triangles_give_the_distance_to_their_closest_edge() {
    let mut rng = rng(461);
    let mut out = Local::default();
    for _ in 0..200 {
        let p = random_vec(&mut rng, 3);
        for t in degenerate_triangles(&mut rng) {
            let x: Vec<f64> = p.iter().chain(&t).copied().collect();
            let d = point_triangle_distance(&x, EXACT, &mut out);
            assert!(all_finite(&out, 12), "non-number derivatives at {x:?}");
            let (t0, t1, t2) = (&t[0..3], &t[3..6], &t[6..9]);
            let want = to_segment(&p, t0, t1)
                .min(to_segment(&p, t1, t2))
                .min(to_segment(&p, t2, t0));
            assert!((d - want).abs() <= 1e-14 * want, "{d:e} against {want:e} at {x:?}");
            let b = barrier_of_squared_distance(d, 12, 2.0, EXACT, &mut out);
            assert!(b.is_finite() && all_finite(&out, 12), "barrier at {x:?}");
            let ([beta, gamma], jac) = point_triangle_closest_point(&x);
            assert!(beta.is_finite() && gamma.is_finite() && jac.iter().flatten().all(|v| v.is_finite()));
            let basis = point_triangle_tangent_basis(&x);
            assert!(basis.columns.iter().flatten().all(|v| v.is_finite()), "basis at {x:?}");
        }
    }
}

#[test]
fn zero_length_edges_are_their_one_point() {
    let mut rng = rng(462);
    let mut out = Local::default();
    for _ in 0..200 {
        for dim in [2, 3] {
            let p = random_vec(&mut rng, dim);
            let e = random_vec(&mut rng, dim);
            let x: Vec<f64> = [&p[..], &e, &e].concat();
            let d = point_edge_distance(&x, dim, EXACT, &mut out);
            let want: f64 = p.iter().zip(&e).map(|(a, b)| (a - b) * (a - b)).sum();
            assert_eq!(d, want);
            assert!(all_finite(&out, 3 * dim));
            let (alpha, jac) = point_edge_closest_point(&x, dim);
            assert!(alpha.is_finite() && jac.iter().all(|v| v.is_finite()));
        }
        // Edge-edge with one or both edges collapsed: the point against the other edge.
        let (a, b) = (random_vec(&mut rng, 3), random_vec(&mut rng, 6));
        let x: Vec<f64> = [&a[..], &a, &b].concat();
        let d = edge_edge_distance(&x, EXACT, &mut out);
        assert!((d - to_segment(&a, &b[..3], &b[3..])).abs() <= 1e-14 * d);
        assert!(all_finite(&out, 12));
        let m = edge_edge_barrier(&x, 0.0, 10.0, EXACT, &mut out);
        assert!(m.is_finite() && all_finite(&out, 12), "mollified barrier");
        let (c, jac) = edge_edge_closest_point(&x);
        assert!(c.iter().chain(jac.iter().flatten()).all(|v| v.is_finite()));
    }
}

#[test]
fn pairs_at_distance_zero_have_zero_barrier_gradient_force_and_friction() {
    let dhat = 0.5;
    // A point on a vertex, on an edge, inside a face; two edges crossing; coincident points.
    let cases: [(&str, Vec<f64>); 5] = [
        (
            "pt vertex",
            vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
        ),
        (
            "pt edge",
            vec![0.5, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
        ),
        (
            "pt face",
            vec![0.25, 0.25, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
        ),
        ("ee", vec![-1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 1.0, 0.0]),
        ("pp", vec![0.25, 0.5, 0.75, 0.25, 0.5, 0.75]),
    ];
    let mut out = Local::default();
    for (name, x) in cases {
        let n = x.len();
        let d = match name {
            "ee" => edge_edge_distance(&x, EXACT, &mut out),
            "pp" => point_point_distance(&x, 3, EXACT, &mut out),
            _ => point_triangle_distance(&x, EXACT, &mut out),
        };
        assert_eq!(d, 0.0, "{name}");
        let b = if name == "ee" {
            edge_edge_barrier(&x, 1e-3, dhat, EXACT, &mut out)
        } else {
            barrier_of_squared_distance(d, n, dhat, EXACT, &mut out)
        };
        assert_eq!(b, f64::INFINITY, "{name}");
        assert!(
            out.grad[..n].iter().chain(&out.hess[..n * n]).all(|&v| v == 0.0),
            "{name}"
        );
        assert_eq!(barrier_force_magnitude(d, dhat, 1e3), 0.0, "{name}");
        // The tangent frame of a pair at one point has no direction: zero columns, and so
        // zero tangential velocity and friction.
        if name == "pp" {
            let basis = point_point_tangent_basis(&x, 3);
            assert!(basis.columns.iter().flatten().all(|&v| v == 0.0));
            let stencil = FrictionStencil {
                basis,
                relative: RelativeVelocity::point_point(),
                normal_force: barrier_force_magnitude(d, dhat, 1e3),
                mu: 0.5,
            };
            let v = [1.0, -2.0, 0.5, 0.0, 0.25, 3.0];
            let f = stencil.eval(&v, 1e-3, EXACT, &mut out);
            assert!(f == 0.0 && all_finite(&out, 6) && out.grad[..6].iter().all(|&g| g == 0.0));
        }
    }
    // Crossing edges: parallel ones (zero cross product) give a zero second column.
    let parallel = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.5, 0.0, 0.0, 2.0, 0.0, 0.0];
    let basis = edge_edge_tangent_basis(&parallel);
    assert!(basis.columns.iter().flatten().all(|v| v.is_finite()));
}

#[test]
fn points_near_either_endpoint_keep_their_distance_to_the_line_exact() {
    // The edge from -e to 0 (e random), the point at a tiny p (2^-10 .. 2^-40 times a random
    // vector) projecting inside the edge. With the near endpoint at the origin, p and the
    // edge's end are exact, so |p x e|^2 / |e|^2 in plain floating point is within a few ulps
    // of the exact squared distance. Measured from the far endpoint, (p + e) x e cancels:
    // the rounding of p + e (eps |e|) is left against |p x e|.
    let mut rng = rng(463);
    let mut worst = 0.0f64;
    for _ in 0..2000 {
        let e: [f64; 3] = [0; 3].map(|_| rng.random_range(-1.0..1.0));
        let k = rng.random_range(10..=40);
        let p: [f64; 3] = [0; 3].map(|_| rng.random_range(-1.0..1.0) * 2f64.powi(-k));
        let along = p[0] * e[0] + p[1] * e[1] + p[2] * e[2];
        if along >= 0.0 {
            continue; // past the endpoint: not this case
        }
        let n = [
            p[1] * e[2] - p[2] * e[1],
            p[2] * e[0] - p[0] * e[2],
            p[0] * e[1] - p[1] * e[0],
        ];
        let want = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]) / (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]);
        let far = e.map(|v| -v);
        for x in [[p, far, [0.0; 3]].concat(), [p, [0.0; 3], far].concat()] {
            let d = point_edge_distance(&x, 3, Want::Value, &mut Local::default());
            worst = worst.max((d - want).abs() / want);
        }
    }
    assert!(worst < 1e-12, "relative error {worst:e}");
}
