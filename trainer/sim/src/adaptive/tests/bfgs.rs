//! BFGS: the secant condition, positive definiteness, recovery of a quadratic's Hessian,
//! skipped updates and the per-subdomain holder.

use nalgebra::{DMatrix, DVector};

use super::fixtures::{random_spd, random_vector, rng};
use crate::adaptive::bfgs::{Bfgs, SecantUpdate, SubdomainHessians, DEFAULT_CURVATURE_FLOOR};

fn relative_difference(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).norm() / b.norm()
}

#[test]
fn an_update_satisfies_the_secant_condition() {
    let mut rng = rng(1);
    for _ in 0..10 {
        let a = random_spd(6, 1.0, &mut rng);
        let mut bfgs = Bfgs::new(random_spd(6, 0.5, &mut rng));
        let s = DVector::from_vec(random_vector(6, &mut rng));
        let y = &a * &s;
        assert_eq!(bfgs.update(&s, &y), SecantUpdate::Applied);
        let hs = bfgs.hessian() * &s;
        assert!((&hs - &y).norm() < 1e-10 * y.norm(), "H s = {hs}, y = {y}");
        assert_eq!(bfgs.hessian(), &bfgs.hessian().transpose());
    }
}

#[test]
fn random_update_sequences_stay_positive_definite_and_count_skips() {
    let mut rng = rng(2);
    let n = 8;
    let mut bfgs = Bfgs::new(random_spd(n, 1.0, &mut rng));
    let mut expected_skips = 0;
    for k in 0..300 {
        // Secant pairs of a varying curvature (a random SPD matrix per step, scaled over
        // four orders of magnitude, as along a nonlinear energy's path), and every third
        // one with its sign flipped, which must be skipped.
        let s = DVector::from_vec(random_vector(n, &mut rng));
        let scale = 10f64.powf(2.0 * random_vector(1, &mut rng)[0]);
        let mut y = random_spd(n, 0.1, &mut rng) * &s * scale;
        if k % 3 == 0 {
            y = -y;
        }
        let skip = s.dot(&y) <= DEFAULT_CURVATURE_FLOOR * s.norm() * y.norm();
        expected_skips += usize::from(skip);
        let outcome = bfgs.update(&s, &y);
        assert_eq!(outcome == SecantUpdate::Skipped, skip, "update {k}");
        let h = bfgs.hessian().clone();
        assert!(h.clone().cholesky().is_some(), "Cholesky fails after update {k}");
        let smallest = h.symmetric_eigen().eigenvalues.min();
        assert!(smallest > 0.0, "smallest eigenvalue {smallest} after update {k}");
    }
    assert_eq!(expected_skips, 100);
    assert_eq!(bfgs.skipped(), expected_skips);
    assert_eq!(bfgs.applied() + bfgs.skipped(), 300);
}

#[test]
fn exact_line_search_on_a_quadratic_recovers_its_hessian() {
    let mut rng = rng(3);
    let n = 7;
    let a = random_spd(n, 2.0, &mut rng);
    let b = DVector::from_vec(random_vector(n, &mut rng));
    let grad = |x: &DVector<f64>| &a * x - &b;
    let mut bfgs = Bfgs::new(DMatrix::identity(n, n));
    let mut x = DVector::from_vec(random_vector(n, &mut rng));
    for k in 0..n {
        let g = grad(&x);
        let p = -bfgs.hessian().clone().cholesky().expect("SPD").solve(&g);
        let alpha = -g.dot(&p) / p.dot(&(&a * &p));
        let s = &p * alpha;
        let x_next = &x + &s;
        let y = grad(&x_next) - grad(&x);
        assert_eq!(bfgs.update(&s, &y), SecantUpdate::Applied, "step {k}");
        x = x_next;
    }
    let err = relative_difference(bfgs.hessian(), &a);
    assert!(err < 1e-8, "relative error {err:e}");
    assert!(grad(&x).norm() < 1e-8 * b.norm(), "the quadratic is minimised");
}

#[test]
fn conjugate_directions_recover_the_hessian_from_any_start() {
    let mut rng = rng(4);
    let n = 6;
    let a = random_spd(n, 1.0, &mut rng);
    // A-conjugate directions by Gram-Schmidt in the A inner product.
    let mut directions: Vec<DVector<f64>> = Vec::new();
    for _ in 0..n {
        let mut d = DVector::from_vec(random_vector(n, &mut rng));
        for e in &directions {
            let proj = d.dot(&(&a * e)) / e.dot(&(&a * e));
            d -= e * proj;
        }
        directions.push(d);
    }
    let mut bfgs = Bfgs::new(random_spd(n, 3.0, &mut rng));
    for s in &directions {
        assert_eq!(bfgs.update(s, &(&a * s)), SecantUpdate::Applied);
    }
    let err = relative_difference(bfgs.hessian(), &a);
    assert!(err < 1e-8, "relative error {err:e}");
}

#[test]
fn non_positive_curvature_and_zero_steps_are_skipped_and_counted() {
    let mut rng = rng(5);
    let start = random_spd(4, 1.0, &mut rng);
    let mut bfgs = Bfgs::new(start.clone());
    let s = DVector::from_vec(vec![1.0, 0.0, 0.0, 0.0]);
    let orthogonal = DVector::from_vec(vec![0.0, 2.0, 0.0, 0.0]);
    let opposite = DVector::from_vec(vec![-1.0, 0.5, 0.0, 0.0]);
    let zero = DVector::zeros(4);
    assert_eq!(bfgs.update(&s, &orthogonal), SecantUpdate::Skipped);
    assert_eq!(bfgs.update(&s, &opposite), SecantUpdate::Skipped);
    assert_eq!(bfgs.update(&zero, &s), SecantUpdate::Skipped);
    assert_eq!(bfgs.skipped(), 3);
    assert_eq!(bfgs.applied(), 0);
    assert_eq!(bfgs.hessian(), &start);
    // A tiny positive curvature passes a zero floor but not the default one.
    let barely = DVector::from_vec(vec![1e-12, 1.0, 0.0, 0.0]);
    assert_eq!(bfgs.update(&s, &barely), SecantUpdate::Skipped);
    let mut permissive = Bfgs::new(start).with_curvature_floor(0.0);
    assert_eq!(permissive.update(&s, &barely), SecantUpdate::Applied);
}

#[test]
fn the_holder_sums_valid_subdomains_and_leaves_invalid_ones_alone() {
    let mut rng = rng(6);
    let exact: Vec<DMatrix<f64>> = (0..3).map(|_| random_spd(5, 1.0, &mut rng)).collect();
    let mut hessians = SubdomainHessians::new(exact.clone());
    assert_eq!(hessians.len(), 3);
    assert!(relative_difference(&hessians.valid_sum(), &(&exact[0] + &exact[1] + &exact[2])) < 1e-15);
    let s = DVector::from_vec(random_vector(5, &mut rng));
    let y = &exact[0] * &s * 2.0;
    assert_eq!(hessians.update(0, &s, &y), SecantUpdate::Applied);
    let updated = hessians.get(0).expect("valid").hessian().clone();
    assert!((&updated * &s - &y).norm() < 1e-10 * y.norm());

    hessians.invalidate(1);
    assert!(!hessians.is_valid(1) && hessians.get(1).is_none());
    assert_eq!(hessians.update(1, &s, &y), SecantUpdate::Invalid);
    assert!(relative_difference(&hessians.valid_sum(), &(&updated + &exact[2])) < 1e-14);
    assert_eq!(hessians.update(2, &s, &(-&y)), SecantUpdate::Skipped);
    assert_eq!(hessians.skipped(), 1);

    hessians.reinitialize(1, exact[1].clone());
    assert!(hessians.is_valid(1));
    assert!(relative_difference(&hessians.valid_sum(), &(&updated + &exact[1] + &exact[2])) < 1e-14);
}
