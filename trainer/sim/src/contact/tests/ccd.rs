use super::{random_vec, rng};
use crate::contact::ccd::AdditiveCcd;
use crate::contact::distance::*;
use crate::energy::{Local, Want};

const ETA: f64 = 0.9;

fn ccd() -> AdditiveCcd {
    AdditiveCcd::default()
}

/// Which pair a stencil holds, to evaluate its distance and run its CCD.
#[derive(Clone, Copy, Debug)]
enum Kind {
    PointPoint(usize),
    PointEdge(usize),
    PointTriangle,
    EdgeEdge,
}

impl Kind {
    fn len(self) -> usize {
        match self {
            Kind::PointPoint(d) => 2 * d,
            Kind::PointEdge(d) => 3 * d,
            _ => 12,
        }
    }

    fn vertices(self) -> usize {
        match self {
            Kind::PointPoint(_) => 2,
            Kind::PointEdge(_) => 3,
            _ => 4,
        }
    }

    fn distance(self, x: &[f64]) -> f64 {
        let mut out = Local::default();
        let squared = match self {
            Kind::PointPoint(d) => point_point_distance(x, d, Want::Value, &mut out),
            Kind::PointEdge(d) => point_edge_distance(x, d, Want::Value, &mut out),
            Kind::PointTriangle => point_triangle_distance(x, Want::Value, &mut out),
            Kind::EdgeEdge => edge_edge_distance(x, Want::Value, &mut out),
        };
        squared.sqrt()
    }

    fn toi(self, x0: &[f64], x1: &[f64], min_distance: f64) -> Option<f64> {
        let c = ccd();
        match self {
            Kind::PointPoint(d) => c.point_point(x0, x1, d, min_distance, 1.0),
            Kind::PointEdge(d) => c.point_edge(x0, x1, d, min_distance, 1.0),
            Kind::PointTriangle => c.point_triangle(x0, x1, min_distance, 1.0),
            Kind::EdgeEdge => c.edge_edge(x0, x1, min_distance, 1.0),
        }
    }
}

fn lerp(x0: &[f64], x1: &[f64], t: f64) -> Vec<f64> {
    x0.iter().zip(x1).map(|(a, b)| a + t * (b - a)).collect()
}

/// The smallest distance over `samples + 1` evenly spaced times of `[0, t]`.
fn min_distance_until(kind: Kind, x0: &[f64], x1: &[f64], t: f64, samples: usize) -> f64 {
    (0..=samples)
        .map(|k| kind.distance(&lerp(x0, x1, t * k as f64 / samples as f64)))
        .fold(f64::INFINITY, f64::min)
}

const TRIANGLE: [f64; 9] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];

fn point_triangle(p: [f64; 3]) -> Vec<f64> {
    p.iter().chain(&TRIANGLE).copied().collect()
}

#[test]
fn parallel_edges_moving_into_each_other_stop_at_a_tenth_of_the_gap() {
    // Edge a at height 1 drops to -1 through edge b (static, parallel, right below it): the
    // distance is |1 - 2t|, contact at t = 1/2. Additive CCD advances 0.9 of the distance at
    // a relative speed of 2, then stops once the distance is below 0.1 of the initial one.
    let x0 = [0.0, 0.0, 1.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
    let mut x1 = x0;
    x1[2] = -1.0;
    x1[5] = -1.0;
    let toi = ccd().edge_edge(&x0, &x1, 0.0, 1.0).expect("the edges collide");
    assert!((toi - 0.45).abs() < 1e-12, "toi {toi}");
    // Edges crossing at right angles, a above b, moving towards each other: the same.
    let x0 = [0.5, -1.0, 1.0, 0.5, 1.0, 1.0, 0.0, 0.0, -1.0, 1.0, 0.0, -1.0];
    let x1 = [0.5, -1.0, -1.0, 0.5, 1.0, -1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 1.0];
    let toi = ccd().edge_edge(&x0, &x1, 0.0, 1.0).expect("the edges collide");
    assert!((0.45 - 1e-12..0.5).contains(&toi), "toi {toi}");
}

#[test]
fn a_vertex_on_the_face_at_the_start_allows_no_step_and_one_reaching_it_at_the_end_is_caught() {
    let on_face = point_triangle([0.2, 0.2, 0.0]);
    let above = point_triangle([0.2, 0.2, 1.0]);
    assert_eq!(ccd().point_triangle(&on_face, &above, 0.0, 1.0), Some(0.0));
    let toi = ccd()
        .point_triangle(&above, &on_face, 0.0, 1.0)
        .expect("reaches the face at t = 1");
    assert!((toi - 0.9).abs() < 1e-12, "toi {toi}");
    // Within the minimum separation at the start: no step either.
    let close = point_triangle([0.2, 0.2, 0.05]);
    assert_eq!(ccd().point_triangle(&close, &above, 0.1, 1.0), Some(0.0));
}

#[test]
fn a_fast_point_tunnelling_through_a_thin_triangle_is_caught() {
    // A sliver 1e-3 wide; the point crosses it at t = 1/2 from 1000 away on either side, so
    // neither end of the step shows anything.
    let sliver = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1e-3, 0.0];
    let stencil = |z: f64| -> Vec<f64> { [0.1, 1e-4, z].iter().chain(&sliver).copied().collect() };
    let (x0, x1) = (stencil(1000.0), stencil(-1000.0));
    let toi = ccd().point_triangle(&x0, &x1, 0.0, 1.0).expect("crosses the sliver");
    assert!((0.45 - 1e-12..0.5).contains(&toi), "toi {toi}");
    // Point-edge (2D) and point-point at high speed likewise.
    let x0 = [0.3, 1000.0, 0.0, 0.0, 1.0, 0.0];
    let x1 = [0.3, -1000.0, 0.0, 0.0, 1.0, 0.0];
    let toi = ccd().point_edge(&x0, &x1, 2, 0.0, 1.0).expect("crosses the edge");
    assert!((0.45 - 1e-12..0.5).contains(&toi), "toi {toi}");
    let toi = ccd().point_point(
        &[-1e3, 0.0, 0.0, 1e3, 0.0, 0.0],
        &[1e3, 0.0, 0.0, -1e3, 0.0, 0.0],
        3,
        0.0,
        1.0,
    );
    let toi = toi.expect("the points meet");
    assert!((0.45 - 1e-12..0.5).contains(&toi), "toi {toi}");
}

#[test]
fn glancing_motions_that_miss_report_no_impact() {
    // A miss is only reported for motions that stay farther apart than the gap, 0.1 of the
    // initial distance: each case starts within a few times its closest approach.
    // The point passes 0.05 beside the triangle's vertex (1, 0, 0), in its plane.
    let x0 = point_triangle([1.05, -0.1, 0.0]);
    let x1 = point_triangle([1.05, 0.1, 0.0]);
    assert_eq!(ccd().point_triangle(&x0, &x1, 0.0, 1.0), None);
    // Edge b sweeps past edge a's end, missing it by 0.01.
    let x0 = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.01, -0.05, -1.0, 1.01, -0.05, 1.0];
    let x1 = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.01, 0.05, -1.0, 1.01, 0.05, 1.0];
    assert_eq!(ccd().edge_edge(&x0, &x1, 0.0, 1.0), None);
    // ... but with a minimum separation of 0.02 it is an impact.
    assert!(ccd().edge_edge(&x0, &x1, 0.02, 1.0).is_some());
    // A point (3D) passing 0.1 beside an edge's end.
    let x0 = [1.1, -0.2, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
    let x1 = [1.1, 0.2, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
    assert_eq!(ccd().point_edge(&x0, &x1, 3, 0.0, 1.0), None);
    // Starting ten times farther, the same pass comes within the gap: reported.
    let x0 = [1.1, -2.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
    let x1 = [1.1, 2.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
    assert!(ccd().point_edge(&x0, &x1, 3, 0.0, 1.0).is_some());
}

#[test]
fn points_moving_parallel_to_a_face_never_collide() {
    for height in [0.5, 1e-2, 1e-4] {
        let x0 = point_triangle([0.1, 0.1, height]);
        let x1 = point_triangle([0.6, 0.3, height]);
        assert_eq!(ccd().point_triangle(&x0, &x1, 0.0, 1.0), None, "height {height}");
        // The whole triangle sliding along its plane under a static point.
        let mut t1 = x0.clone();
        for a in 1..4 {
            t1[3 * a] += 0.3;
        }
        assert_eq!(ccd().point_triangle(&x0, &t1, 0.0, 1.0), None, "height {height}");
    }
}

#[test]
fn no_motion_means_no_impact_and_tmax_bounds_the_search() {
    let x = point_triangle([0.2, 0.2, 0.3]);
    assert_eq!(ccd().point_triangle(&x, &x, 0.0, 1.0), None);
    // Rigid translation of the whole stencil: the mean displacement is removed.
    let moved: Vec<f64> = x.iter().enumerate().map(|(i, v)| v + [5.0, -3.0, 2.0][i % 3]).collect();
    assert_eq!(ccd().point_triangle(&x, &moved, 0.0, 1.0), None);
    // An impact at 0.9 (reached at t = 1) is beyond tmax = 0.5.
    let x0 = point_triangle([0.2, 0.2, 1.0]);
    let x1 = point_triangle([0.2, 0.2, 0.0]);
    assert_eq!(ccd().point_triangle(&x0, &x1, 0.0, 0.5), None);
    // A non-number allows no step.
    let nan = point_triangle([f64::NAN, 0.2, 1.0]);
    assert_eq!(ccd().point_triangle(&x0, &nan, 0.0, 1.0), Some(0.0));
}

#[test]
fn the_iteration_cap_reports_the_time_reached_as_an_impact() {
    // Sliding at height 1e-3 with a speed of 1: each advance covers 9e-4 of the step.
    let x0 = point_triangle([0.1, 0.1, 1e-3]);
    let x1 = point_triangle([0.6, 0.1, 1e-3]);
    let capped = AdditiveCcd {
        max_iterations: 10,
        ..AdditiveCcd::default()
    };
    let toi = capped.point_triangle(&x0, &x1, 0.0, 1.0).expect("capped");
    // lp = |dp| + max |dt| = 0.375 + 0.125 after removing the mean motion.
    let advance = ETA * 1e-3 / 0.5;
    assert!((toi - 10.0 * advance).abs() < 1e-12, "toi {toi}");
}

#[test]
fn random_motions_keep_a_hundredth_of_the_initial_gap_until_the_reported_time() {
    // Each advance closes at most 0.9 of the distance left, and the search stops before the
    // distance falls under 0.1 of the initial one: sampled densely, the distance over the
    // cleared interval (the whole step when no impact is reported) stays above
    // 0.1 * 0.1 of the initial distance (less the minimum separation).
    let mut rng = rng(27);
    let kinds = [
        Kind::PointPoint(2),
        Kind::PointPoint(3),
        Kind::PointEdge(2),
        Kind::PointEdge(3),
        Kind::PointTriangle,
        Kind::EdgeEdge,
    ];
    let (mut hits, mut misses) = (0, 0);
    for kind in kinds {
        for case in 0..150 {
            let x0 = random_vec(&mut rng, kind.len());
            let mut x1: Vec<f64> = x0
                .iter()
                .zip(random_vec(&mut rng, kind.len()))
                .map(|(a, b)| a + 2.0 * b)
                .collect();
            if case % 2 == 1 {
                // The first vertex meets the last (of the other primitive) at t = 1/2.
                let (dim, last) = (kind.len() / kind.vertices(), kind.len() - kind.len() / kind.vertices());
                for k in 0..dim {
                    x1[k] = x0[last + k] + x1[last + k] - x0[k];
                }
            }
            let xi = if case % 3 == 0 { 0.01 } else { 0.0 };
            let d0 = kind.distance(&x0);
            if d0 <= xi {
                continue;
            }
            let cleared = match kind.toi(&x0, &x1, xi) {
                Some(t) => {
                    hits += 1;
                    t
                }
                None => {
                    misses += 1;
                    1.0
                }
            };
            let low = min_distance_until(kind, &x0, &x1, cleared, 400);
            assert!(
                low - xi >= 0.01 * (d0 - xi) * (1.0 - 1e-9),
                "{kind:?} case {case}: distance {low} over [0, {cleared}], initial {d0}"
            );
        }
    }
    assert!(hits > 300 && misses > 200, "{hits} impacts, {misses} misses");
}
