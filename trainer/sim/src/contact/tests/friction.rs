use super::{assert_fd, fd, random_vec, rng};
use crate::contact::friction::*;
use crate::energy::psd::min_eigenvalue;
use crate::energy::{Local, Want};

#[test]
fn smoothing_functions_are_derivatives_of_each_other_and_c1_at_eps_v() {
    let eps = 0.3;
    for y in [1e-3, 0.05, 0.1, 0.29, 0.31, 1.0] {
        let h = 1e-7;
        let d0 = (f0(y + h, eps) - f0(y - h, eps)) / (2.0 * h);
        let d1 = (f1(y + h, eps) - f1(y - h, eps)) / (2.0 * h);
        assert!((d0 - f1(y, eps)).abs() < 1e-7, "f1 at {y}");
        assert!((d1 - f2(y, eps)).abs() < 1e-6, "f2 at {y}");
        assert!((f1_over_x(y, eps) - f1(y, eps) / y).abs() < 1e-12);
        let want = (f2(y, eps) * y - f1(y, eps)) / y.powi(3);
        assert!((f2_x_minus_f1_over_x3(y, eps) - want).abs() < 1e-9 * want.abs());
    }
    let (below, above) = (eps * (1.0 - 1e-12), eps * (1.0 + 1e-12));
    assert!((f0(below, eps) - f0(above, eps)).abs() < 1e-12 && (f1(below, eps) - 1.0).abs() < 1e-11);
    assert!((f0(0.0, eps) - eps / 3.0).abs() < 1e-15 && f1(0.0, eps) == 0.0);
}

fn orthonormal_and_normal_to(b: &TangentBasis, normal: [f64; 3]) {
    let dot = |a: [f64; 3], c: [f64; 3]| a[0] * c[0] + a[1] * c[1] + a[2] * c[2];
    let scale = dot(normal, normal).sqrt();
    for k in 0..b.len() {
        assert!((dot(b.columns[k], b.columns[k]) - 1.0).abs() < 1e-12, "{b:?}");
        assert!(
            dot(b.columns[k], normal).abs() < 1e-12 * scale,
            "{b:?} vs normal {normal:?}"
        );
    }
    if b.len() == 2 {
        assert!(dot(b.columns[0], b.columns[1]).abs() < 1e-12);
    }
}

#[test]
fn tangent_bases_are_orthonormal_and_normal_to_the_contact_normal() {
    let mut rng = rng(31);
    for _ in 0..20 {
        let x = random_vec(&mut rng, 12);
        let v = |a: usize| [x[3 * a], x[3 * a + 1], x[3 * a + 2]];
        let sub = |a: [f64; 3], b: [f64; 3]| [0, 1, 2].map(|i| a[i] - b[i]);
        let cross = |a: [f64; 3], b: [f64; 3]| {
            [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ]
        };
        orthonormal_and_normal_to(&point_point_tangent_basis(&x[..6], 3), sub(v(1), v(0)));
        let (alpha, _) = point_edge_closest_point(&x[..9], 3);
        let foot = [0, 1, 2].map(|i| x[3 + i] + alpha * (x[6 + i] - x[3 + i]));
        orthonormal_and_normal_to(&point_edge_tangent_basis(&x[..9], 3), sub(v(0), foot));
        orthonormal_and_normal_to(&edge_edge_tangent_basis(&x), cross(sub(v(1), v(0)), sub(v(3), v(2))));
        orthonormal_and_normal_to(
            &point_triangle_tangent_basis(&x),
            cross(sub(v(2), v(1)), sub(v(3), v(1))),
        );
        let b2 = point_point_tangent_basis(&x[..4], 2);
        orthonormal_and_normal_to(&b2, [x[2] - x[0], x[3] - x[1], 0.0]);
    }
}

#[test]
fn friction_potential_matches_finite_differences_in_both_regimes_and_projects_to_psd() {
    let mut rng = rng(32);
    let eps_v = 1e-2;
    for case in 0..40 {
        let x = random_vec(&mut rng, 12);
        let (coords, _) = point_triangle_closest_point(&x);
        let stencil = FrictionStencil {
            basis: point_triangle_tangent_basis(&x),
            relative: RelativeVelocity::point_triangle(coords),
            normal_force: 3.0,
            mu: 0.4,
        };
        // Half the cases static (|tau| < eps_v), half kinetic: scale v to a chosen |tau|.
        let target = if case % 2 == 0 { 0.3 * eps_v } else { 30.0 * eps_v };
        let v = random_vec(&mut rng, 12);
        let tau = stencil.tangential_velocity(&v);
        let scale = target / (tau[0] * tau[0] + tau[1] * tau[1]).sqrt();
        let v: Vec<f64> = v.iter().map(|u| u * scale).collect();
        let tau = stencil.tangential_velocity(&v);
        assert!(((tau[0] * tau[0] + tau[1] * tau[1]).sqrt() / target - 1.0).abs() < 1e-12);
        let h = 1e-4 * scale.min(1.0);
        assert_fd(fd(3, &v, h, |v, w, o| stencil.eval(v, eps_v, w, o)), 1e-6, "friction");
        let mut out = Local::default();
        stencil.eval(&v, eps_v, Want::Hessian { project: true }, &mut out);
        let hmax = out.hess.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        assert!(min_eigenvalue(&out.hess[..144], 12) > -1e-10 * hmax);
    }
    // 2D point-edge stencil (one tangent).
    let x = [0.3, 0.4, -1.0, 0.0, 1.0, 0.1];
    let (alpha, _) = point_edge_closest_point(&x, 2);
    let stencil = FrictionStencil {
        basis: point_edge_tangent_basis(&x, 2),
        relative: RelativeVelocity::point_edge(alpha),
        normal_force: 2.0,
        mu: 0.5,
    };
    for v in [[1e-3, 2e-3, -1e-3, 0.0, 4e-3, 1e-3], [0.1, 0.2, -0.3, 0.0, 0.4, 0.1]] {
        assert_fd(
            fd(2, &v, 1e-7, |v, w, o| stencil.eval(v, eps_v, w, o)),
            1e-6,
            "2D friction",
        );
    }
}

#[test]
fn friction_force_is_kinetic_above_eps_v_and_vanishes_at_rest() {
    let x = [0.2, 0.3, 0.5, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let (coords, _) = point_triangle_closest_point(&x);
    let stencil = FrictionStencil {
        basis: point_triangle_tangent_basis(&x),
        relative: RelativeVelocity::point_triangle(coords),
        normal_force: 2.0,
        mu: 0.5,
    };
    let mut out = Local::default();
    // Point sliding along +x over a fixed triangle: force on the point is mu N along +x.
    let v = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    let d = stencil.eval(&v, 1e-3, Want::Gradient, &mut out);
    assert!((d - 1.0).abs() < 1e-12 && (out.grad[0] - 1.0).abs() < 1e-12 && out.grad[1].abs() < 1e-12);
    // Normal motion does not count.
    let v = [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    assert!(stencil.tangential_velocity(&v).iter().all(|t| t.abs() < 1e-15));
    stencil.eval(&[0.0; 12], 1e-3, Want::Gradient, &mut out);
    assert!(out.grad[..12].iter().all(|g| *g == 0.0));
}
