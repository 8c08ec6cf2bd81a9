use super::{random_vec, rng};
use crate::contact::friction::closest_point::*;

/// Largest relative mismatch between `jac` (rows over `x`) and central differences of `f`.
fn jacobian_error(x: &[f64], rows: usize, f: impl Fn(&[f64]) -> Vec<f64>, jac: &[Vec<f64>]) -> f64 {
    let h = 1e-6;
    let mut worst = 0.0f64;
    let mut xp = x.to_vec();
    for k in 0..x.len() {
        xp[k] = x[k] + h;
        let fp = f(&xp);
        xp[k] = x[k] - h;
        let fm = f(&xp);
        xp[k] = x[k];
        for r in 0..rows {
            let fd = (fp[r] - fm[r]) / (2.0 * h);
            worst = worst.max((fd - jac[r][k]).abs() / jac[r][k].abs().max(1.0));
        }
    }
    worst
}

#[test]
fn closest_point_jacobians_match_finite_differences() {
    let mut rng = rng(21);
    for _ in 0..20 {
        let x = random_vec(&mut rng, 12);
        for dim in [2, 3] {
            let xs = &x[..3 * dim];
            let (_, j) = point_edge_closest_point(xs, dim);
            let err = jacobian_error(
                xs,
                1,
                |x| vec![point_edge_closest_point(x, dim).0],
                &[j[..3 * dim].to_vec()],
            );
            assert!(err < 1e-6, "point-edge {dim}D: {err:e}");
        }
        let (_, j) = edge_edge_closest_point(&x);
        let err = jacobian_error(&x, 2, |x| edge_edge_closest_point(x).0.to_vec(), &j.map(|r| r.to_vec()));
        assert!(err < 1e-5, "edge-edge: {err:e}");
        let (_, j) = point_triangle_closest_point(&x);
        let err = jacobian_error(
            &x,
            2,
            |x| point_triangle_closest_point(x).0.to_vec(),
            &j.map(|r| r.to_vec()),
        );
        assert!(err < 1e-5, "point-triangle: {err:e}");
    }
}

#[test]
fn closest_points_are_where_the_connecting_vector_is_normal() {
    let mut rng = rng(22);
    for _ in 0..20 {
        let x = random_vec(&mut rng, 12);
        let v = |a: usize| [x[3 * a], x[3 * a + 1], x[3 * a + 2]];
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let lerp = |a: [f64; 3], b: [f64; 3], t: f64| [0, 1, 2].map(|i| a[i] + t * (b[i] - a[i]));
        let sub = |a: [f64; 3], b: [f64; 3]| [0, 1, 2].map(|i| a[i] - b[i]);
        let ([s, t], _) = edge_edge_closest_point(&x);
        let gap = sub(lerp(v(0), v(1), s), lerp(v(2), v(3), t));
        assert!(dot(gap, sub(v(1), v(0))).abs() < 1e-12 && dot(gap, sub(v(3), v(2))).abs() < 1e-12);
        let ([b, c], _) = point_triangle_closest_point(&x);
        let q = [0, 1, 2].map(|i| x[3 + i] + b * (x[6 + i] - x[3 + i]) + c * (x[9 + i] - x[3 + i]));
        let gap = sub(v(0), q);
        assert!(dot(gap, sub(v(2), v(1))).abs() < 1e-12 && dot(gap, sub(v(3), v(1))).abs() < 1e-12);
        // Relative velocity weights: the closest points' velocities, first minus second.
        let w = RelativeVelocity::point_triangle([b, c]).weights;
        assert!((w.iter().sum::<f64>()).abs() < 1e-15 && w[0] == 1.0);
    }
}
