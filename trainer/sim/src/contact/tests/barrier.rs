use super::{assert_fd, fd, random_vec, rng};
use crate::contact::barrier::*;
use crate::contact::distance::{edge_edge_mollifier_threshold, point_triangle_distance};
use crate::contact::stiffness::{initial_barrier_stiffness, update_barrier_stiffness, MIN_STIFFNESS_SCALE};
use crate::energy::psd::min_eigenvalue;
use crate::energy::{Local, Want};

#[test]
fn barrier_derivatives_match_finite_differences() {
    let dhat = 0.7;
    for d in [1e-4, 1e-2, 0.1, 0.3, 0.6, 0.69] {
        let h = 1e-7 * d;
        let fd1 = (barrier(d + h, dhat) - barrier(d - h, dhat)) / (2.0 * h);
        let fd2 = (barrier_first_derivative(d + h, dhat) - barrier_first_derivative(d - h, dhat)) / (2.0 * h);
        let (b1, b2) = (barrier_first_derivative(d, dhat), barrier_second_derivative(d, dhat));
        assert!((fd1 - b1).abs() <= 1e-6 * b1.abs().max(1.0), "d {d}: b' {b1} vs {fd1}");
        assert!((fd2 - b2).abs() <= 1e-6 * b2.abs().max(1.0), "d {d}: b'' {b2} vs {fd2}");
        assert!(barrier(d, dhat) > 0.0 && b1 < 0.0 && b2 > 0.0, "d {d}");
    }
}

#[test]
fn barrier_vanishes_to_second_order_at_dhat_and_grows_without_bound_at_contact() {
    let dhat = 2.0;
    for d in [2.0, 2.5] {
        assert_eq!(
            (
                barrier(d, dhat),
                barrier_first_derivative(d, dhat),
                barrier_second_derivative(d, dhat)
            ),
            (0.0, 0.0, 0.0)
        );
    }
    let just_below = dhat * (1.0 - 1e-6);
    assert!(barrier(just_below, dhat) < 1e-17 && barrier_first_derivative(just_below, dhat).abs() < 1e-11);
    assert!(barrier_second_derivative(just_below, dhat).abs() < 1e-5);
    assert!(barrier(1e-12, dhat) > 100.0 && barrier(0.0, dhat).is_infinite());
}

#[test]
fn barrier_on_squared_distances_matches_finite_differences_and_projects_to_psd() {
    let mut rng = rng(11);
    let dhat = 0.5;
    let f = |x: &[f64], w: Want, o: &mut Local| {
        let exact = if w.hessian().is_some() {
            Want::Hessian { project: false }
        } else {
            w
        };
        let d2 = point_triangle_distance(x, exact, o);
        barrier_of_squared_distance(d2, 12, dhat, w, o)
    };
    let mut tested = 0;
    while tested < 20 {
        let mut x = random_vec(&mut rng, 12);
        x.iter_mut().skip(3).for_each(|v| *v *= 2.0);
        x[2] = 0.1 * x[2].abs();
        let mut out = Local::default();
        if f(&x, Want::Value, &mut out) == 0.0 {
            continue;
        }
        tested += 1;
        assert_fd(fd(3, &x, 1e-7, f), 1e-5, "point-triangle barrier");
        f(&x, Want::Hessian { project: true }, &mut out);
        assert!(min_eigenvalue(&out.hess[..144], 12) > -1e-9 * out.hess.iter().fold(1.0f64, |m, v| m.max(v.abs())));
    }
}

#[test]
fn mollified_edge_edge_barrier_matches_finite_differences() {
    let mut rng = rng(12);
    let dhat = 0.5;
    let mut tested = 0;
    while tested < 20 {
        // Nearly parallel edges close to each other, so the mollifier acts.
        let mut x = random_vec(&mut rng, 12);
        for i in 0..3 {
            x[6 + i] = x[i] + 0.2 * x[6 + i];
            x[9 + i] = x[3 + i] + 0.2 * x[9 + i];
        }
        let eps_x = 4.0 * edge_edge_mollifier_threshold(&x);
        if edge_edge_barrier(&x, eps_x, dhat, Want::Value, &mut Local::default()) == 0.0 {
            continue;
        }
        tested += 1;
        assert_fd(
            fd(3, &x, 1e-7, |x, w, o| edge_edge_barrier(x, eps_x, dhat, w, o)),
            1e-5,
            "edge-edge barrier",
        );
    }
}

#[test]
fn force_magnitude_is_minus_the_barrier_derivative_in_distance() {
    let (dhat, kappa, d) = (0.5f64, 3.0, 0.2f64);
    let h = 1e-7;
    let db_dd = (barrier((d + h).powi(2), dhat * dhat) - barrier((d - h).powi(2), dhat * dhat)) / (2.0 * h);
    assert!((barrier_force_magnitude(d * d, dhat, kappa) + kappa * db_dd).abs() < 1e-6);
}

#[test]
fn initial_stiffness_balances_gradients_within_its_bounds() {
    let (diag, dhat, mass) = (1.0, 1e-3, 0.5);
    let lo = initial_barrier_stiffness(diag, dhat, mass, &[0.0; 3], &[0.0; 3], MIN_STIFFNESS_SCALE);
    assert!(
        (lo.max / lo.kappa - 100.0).abs() < 1e-9,
        "zero gradients give the smallest stiffness"
    );
    // kappa = -g_b.g_e / |g_b|^2 when inside the bounds.
    let want = 10.0 * lo.kappa;
    let gb = [1.0, -2.0, 0.5];
    let ge: Vec<f64> = gb.iter().map(|g| -want * g).collect();
    let mid = initial_barrier_stiffness(diag, dhat, mass, &ge, &gb, MIN_STIFFNESS_SCALE);
    assert!((mid.kappa / want - 1.0).abs() < 1e-12 && mid.max == lo.max);
    let huge: Vec<f64> = ge.iter().map(|g| g * 1e6).collect();
    assert_eq!(
        initial_barrier_stiffness(diag, dhat, mass, &huge, &gb, MIN_STIFFNESS_SCALE).kappa,
        lo.max
    );
}

#[test]
fn stiffness_doubles_only_while_a_small_distance_keeps_shrinking() {
    let (max, kappa, diag) = (100.0, 30.0, 1.0);
    let tiny = 1e-20; // squared; below (1e-9 * diag)^2 = 1e-18
    assert_eq!(update_barrier_stiffness(2.0 * tiny, tiny, max, kappa, diag, 1e-9), 60.0);
    assert_eq!(update_barrier_stiffness(2.0 * tiny, tiny, max, 60.0, diag, 1e-9), 100.0);
    assert_eq!(
        update_barrier_stiffness(tiny, 2.0 * tiny, max, kappa, diag, 1e-9),
        kappa
    );
    assert_eq!(update_barrier_stiffness(1.0, tiny, max, kappa, diag, 1e-9), kappa);
}
