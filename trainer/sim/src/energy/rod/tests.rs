//! Tests of the rod energies: derivatives against finite differences, invariances and
//! analytic cases.

use super::*;
use crate::energy::fd::{assert_all_stencils, check_stencil};
use crate::energy::psd::min_eigenvalue;
use crate::energy::{add_gradient, gather, value};
use crate::error::Location;
use nalgebra::Rotation3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const SOURCE: &str = "<test>";

fn path() -> &'static Path {
    Path::new(SOURCE)
}

/// Material and radius giving E A ~ 3e3 and E I ~ 0.6, so that relative finite-difference
/// errors are meaningful.
fn stiff() -> (ElementMaterial, f64) {
    let m = ElementMaterial {
        youngs: 1e6,
        poisson: 0.3,
        density: 1320.0,
    };
    (m, 0.03)
}

fn random_unit(rng: &mut ChaCha8Rng) -> Vector3<f64> {
    loop {
        let v = Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        );
        if v.norm() > 0.1 && v.norm() < 1.0 {
            return v.normalize();
        }
    }
}

/// Three vertices: an edge of length `l0` along a random direction, then one of length
/// `l1` turning by `angle` about a random axis.
fn bent_triple(rng: &mut ChaCha8Rng, angle: f64, l0: f64, l1: f64) -> Vec<f64> {
    let dir = random_unit(rng);
    let axis = dir.cross(&random_unit(rng)).normalize();
    let next = Rotation3::new(axis * angle) * dir;
    let x0 = Vector3::new(rng.random(), rng.random(), rng.random());
    let x1 = x0 + dir * l0;
    let x2 = x1 + next * l1;
    [x0, x1, x2].iter().flat_map(|p| [p.x, p.y, p.z]).collect()
}

fn transform(x: &[f64], rotation: &Rotation3<f64>, shift: &Vector3<f64>) -> Vec<f64> {
    x.chunks_exact(3)
        .flat_map(|p| {
            let q = rotation * Vector3::new(p[0], p[1], p[2]) + shift;
            [q.x, q.y, q.z]
        })
        .collect()
}

/// A helix sampled every `step` of arc length (a curved, twisted rest shape).
fn helix(n: usize, step: f64) -> Vec<f64> {
    let (radius, pitch): (f64, f64) = (0.3, 0.1);
    let speed = (radius * radius + pitch * pitch).sqrt();
    (0..n)
        .flat_map(|j| {
            let t = j as f64 * step / speed;
            [radius * t.cos(), radius * t.sin(), pitch * t]
        })
        .collect()
}

fn straight(n: usize, step: f64) -> Vec<f64> {
    (0..n).flat_map(|j| [0.0, 0.0, -(j as f64) * step]).collect()
}

#[test]
fn bend_matches_finite_differences_from_straight_to_sharply_bent() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let (m, r) = stiff();
    let mut worst = (0.0f64, 0.0f64);
    let angles = [0.0, 1e-7, 1e-4, 0.1, 0.8, 1.5, 2.2, 2.6];
    for _ in 0..40 {
        for &rest_angle in &[0.0, rng.random_range(0.3..1.5)] {
            let (l0, l1) = (rng.random_range(0.2..1.0), rng.random_range(0.2..1.0));
            let rest = bent_triple(&mut rng, rest_angle, l0, l1);
            let bend = RodBend::new(&rest, &[vec![0, 1, 2]], &[m], r, path()).unwrap();
            // A curved rest shape has a cone where the vertex is straight: stay clear.
            let smooth = angles.iter().filter(|&&a| rest_angle == 0.0 || a >= 0.1);
            for &angle in smooth {
                // Stretched or compressed edges, keeping l0 l1 + e0.e1 > 0.
                let stretch = [rng.random_range(0.85..1.05), rng.random_range(0.85..1.05)];
                let x = bent_triple(&mut rng, angle, l0 * stretch[0], l1 * stretch[1]);
                let report = check_stencil(&bend, 0, &x, 1e-6);
                assert!(
                    report.grad_error < 1e-6 && report.hess_error < 1e-6,
                    "angle {angle}, rest {rest_angle}: {report:?}"
                );
                worst = (worst.0.max(report.grad_error), worst.1.max(report.hess_error));
            }
        }
    }
    eprintln!("bend FD worst: gradient {:.1e}, Hessian {:.1e}", worst.0, worst.1);
}

#[test]
fn stretch_matches_finite_differences_in_tension_and_compression() {
    let mut rng = ChaCha8Rng::seed_from_u64(12);
    let (m, r) = stiff();
    for _ in 0..100 {
        let rest_length = rng.random_range(0.1..1.0);
        let rest = bent_triple(&mut rng, 0.0, rest_length, 1.0);
        let stretch = RodStretch::new(&rest[..6], &[vec![0, 1]], &[m], r, path()).unwrap();
        let length = rng.random_range(0.1..2.0);
        let x = bent_triple(&mut rng, 0.0, length, 1.0);
        let report = check_stencil(&stretch, 0, &x[..6], 1e-6);
        assert!(report.grad_error < 1e-7 && report.hess_error < 1e-7, "{report:?}");
    }
}

#[test]
fn energies_match_finite_differences_on_a_deformed_strand() {
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    let (m, r) = stiff();
    let rest = helix(8, 0.2);
    let strands = vec![(0..8).collect::<Vec<_>>()];
    let stretch = RodStretch::new(&rest, &strands, &[m], r, path()).unwrap();
    let bend = RodBend::new(&rest, &strands, &[m], r, path()).unwrap();
    let x: Vec<f64> = rest.iter().map(|c| c + rng.random_range(-0.05..0.05)).collect();
    assert_all_stencils(&stretch, &x, 1e-6, 1e-7);
    assert_all_stencils(&bend, &x, 1e-6, 1e-6);
}

#[test]
fn zero_energy_and_gradient_at_straight_and_curved_rest_shapes() {
    let (m, r) = stiff();
    let strands = vec![(0..6).collect::<Vec<_>>(), (6..12).collect()];
    let mut rest = straight(6, 0.1);
    rest.extend(helix(6, 0.15));
    let stretch = RodStretch::new(&rest, &strands, &[m], r, path()).unwrap();
    let bend = RodBend::new(&rest, &strands, &[m, m], r, path()).unwrap();
    assert_eq!((stretch.len(), bend.len()), (10, 8));
    for energy in [&stretch as &dyn StencilEnergy, &bend] {
        let mut grad = vec![0.0; rest.len()];
        let e = add_gradient(energy, 1.0, &rest, &mut grad);
        let g = grad.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        assert!(e.abs() < 1e-20 && g < 1e-9, "{}: {e:e}, {g:e}", energy.name());
    }
}

#[test]
fn energies_are_invariant_under_rigid_motion() {
    let mut rng = ChaCha8Rng::seed_from_u64(14);
    let (m, r) = stiff();
    let rest = helix(10, 0.1);
    let strands = vec![(0..10).collect::<Vec<_>>()];
    let stretch = RodStretch::new(&rest, &strands, &[m], r, path()).unwrap();
    let bend = RodBend::new(&rest, &strands, &[m], r, path()).unwrap();
    for _ in 0..10 {
        let x: Vec<f64> = rest.iter().map(|c| c + rng.random_range(-0.03..0.03)).collect();
        let rotation = Rotation3::new(random_unit(&mut rng) * rng.random_range(0.0..3.0));
        let moved = transform(&x, &rotation, &Vector3::new(1.0, -2.0, 0.5));
        for energy in [&stretch as &dyn StencilEnergy, &bend] {
            let (a, b) = (value(energy, &x), value(energy, &moved));
            assert!(a > 0.0 && (a - b).abs() <= 1e-10 * a, "{}: {a} {b}", energy.name());
        }
    }
}

/// A straight rod of `n` edges and length 1 bent without stretching onto a circular arc
/// of curvature `kappa`; returns (bend energy / (E I / 2 kappa^2 L), stretch energy).
fn arc_ratio(n: usize, kappa: f64) -> (f64, f64) {
    let (m, r) = stiff();
    let h = 1.0 / n as f64;
    let rest = straight(n + 1, h);
    let strands = vec![(0..=n).collect::<Vec<_>>()];
    let bend = RodBend::new(&rest, &strands, &[m], r, path()).unwrap();
    let stretch = RodStretch::new(&rest, &strands, &[m], r, path()).unwrap();
    // Vertices on the circle with chords exactly h: turning angle 2 asin(kappa h / 2).
    let step = 2.0 * (0.5 * kappa * h).asin();
    let x: Vec<f64> = (0..=n)
        .flat_map(|j| {
            let a = j as f64 * step;
            [a.sin() / kappa, 0.0, (1.0 - a.cos()) / kappa]
        })
        .collect();
    let bending = m.youngs * PI * r.powi(4) / 4.0;
    let continuum = 0.5 * bending * kappa * kappa * 1.0;
    (value(&bend, &x) / continuum, value(&stretch, &x))
}

#[test]
fn arc_bending_matches_the_continuum_energy() {
    for n in [25, 50, 100, 200, 400] {
        let (ratio, stretch) = arc_ratio(n, 3.0);
        eprintln!("arc n={n}: bend/continuum {ratio:.5}, stretch {stretch:.1e}");
        // Exactly: |kb| = 2 tan(phi / 2) with sin(phi / 2) = kappa h / 2 at each of the
        // n - 1 interior vertices, so ratio = (1 - 1/n) / (1 - (kappa h / 2)^2): a boundary
        // deficit of one edge and a second-order discretisation excess.
        let half = 0.5 * 3.0 / n as f64;
        let expected = (1.0 - 1.0 / n as f64) / (1.0 - half * half);
        assert!((ratio - expected).abs() < 1e-9, "{ratio} vs {expected}");
        assert!(stretch < 1e-20);
        if n >= 200 {
            assert!((ratio - 1.0).abs() < 0.01, "{ratio}");
        }
    }
}

#[test]
fn uniform_stretch_matches_the_continuum_energy() {
    let (m, r) = stiff();
    let n = 7;
    let rest = straight(n + 1, 0.3);
    let strands = vec![(0..=n).collect::<Vec<_>>()];
    let stretch = RodStretch::new(&rest, &strands, &[m], r, path()).unwrap();
    let bend = RodBend::new(&rest, &strands, &[m], r, path()).unwrap();
    let length = 0.3 * n as f64;
    for eps in [1e-3, 0.05, -0.1] {
        let x: Vec<f64> = rest.iter().map(|c| c * (1.0 + eps)).collect();
        let want = 0.5 * m.youngs * PI * r * r * eps * eps * length;
        let got = value(&stretch, &x);
        assert!((got - want).abs() < 1e-10 * want, "{got} vs {want}");
        assert!(value(&bend, &x).abs() < 1e-20);
    }
}

#[test]
fn projected_hessians_are_positive_semidefinite() {
    let mut rng = ChaCha8Rng::seed_from_u64(15);
    let (m, r) = stiff();
    let mut negative_seen = [false; 2];
    for _ in 0..50 {
        let rest_angle = rng.random_range(0.0..1.0);
        let rest = bent_triple(&mut rng, rest_angle, 0.5, 0.7);
        let strands = [vec![0, 1, 2]];
        let stretch = RodStretch::new(&rest, &strands, &[m], r, path()).unwrap();
        let bend = RodBend::new(&rest, &strands, &[m], r, path()).unwrap();
        let (angle, l0, l1) = (
            rng.random_range(0.0..2.5),
            rng.random_range(0.3..0.7),
            rng.random_range(0.5..0.9),
        );
        let x = bent_triple(&mut rng, angle, l0, l1);
        for (k, energy) in [&stretch as &dyn StencilEnergy, &bend].iter().enumerate() {
            let mut local = [0.0; 12];
            let n = gather(*energy, 0, &x, &mut local);
            let mut out = Local::default();
            energy.eval(0, &local[..n], Want::Hessian { project: false }, &mut out);
            negative_seen[k] |= min_eigenvalue(&out.hess[..n * n], n) < 0.0;
            energy.eval(0, &local[..n], Want::Hessian { project: true }, &mut out);
            let scale = out.hess[..n * n].iter().fold(1.0f64, |m, h| m.max(h.abs()));
            let min = min_eigenvalue(&out.hess[..n * n], n);
            assert!(min > -1e-10 * scale, "{}: {min}", energy.name());
        }
    }
    assert_eq!(negative_seen, [true, true], "the test should include indefinite cases");
}

#[test]
fn folding_back_is_an_infinite_barrier() {
    let (m, r) = stiff();
    let rest = straight(3, 1.0);
    let bend = RodBend::new(&rest, &[vec![0, 1, 2]], &[m], r, path()).unwrap();
    let mut out = Local::default();
    let near = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.01, 0.0];
    let folded = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -0.5, 0.0, 0.0];
    assert!(bend.eval(0, &near, Want::Value, &mut out) > 1e3);
    let e = bend.eval(0, &folded, Want::Hessian { project: true }, &mut out);
    assert_eq!(e, f64::INFINITY);
    assert!(out.grad[..9].iter().all(|g| *g == 0.0));
}

fn error_of<T: std::fmt::Debug>(result: Result<T, InputError>) -> InputError {
    result.expect_err("expected an error")
}

#[test]
fn bad_input_errors_name_the_element_or_field() {
    let (m, r) = stiff();
    let rest = straight(6, 0.1);
    let good = vec![vec![0, 1, 2], vec![3, 4, 5]];
    let both = |rest: &[f64], strands: &[Vec<usize>], mats: &[ElementMaterial], r: f64| {
        let a = error_of(RodStretch::new(rest, strands, mats, r, path()));
        let b = error_of(RodBend::new(rest, strands, mats, r, path()));
        assert_eq!(a, b);
        assert_eq!(a.file, Path::new(SOURCE));
        a
    };
    let e = both(&rest, &[vec![0, 1, 2], vec![3, 9]], &[m], r);
    assert_eq!(e.location, Location::Element(1));
    assert!(e.message.contains('9'), "{e}");
    let e = both(&rest, &[vec![0, 1, 2], vec![3]], &[m], r);
    assert_eq!(e.location, Location::Element(1));
    let e = both(&rest, &[vec![0, 1, 1, 2]], &[m], r);
    assert_eq!(e.location, Location::Element(0));
    assert!(e.message.contains("zero rest length"), "{e}");

    let mut nan = rest.clone();
    nan[7] = f64::NAN;
    let e = both(&nan, &good, &[m], r);
    assert_eq!(e.location, Location::Field("vertices[2]".into()));
    let e = both(&rest[..17], &good, &[m], r);
    assert_eq!(e.location, Location::Field("vertices".into()));

    for bad in [0.0, -1.0, f64::INFINITY] {
        let e = both(&rest, &good, &[m], bad);
        assert_eq!(e.location, Location::Field("radius".into()));
    }
    let e = both(&rest, &good, &[m, m, m], r);
    assert_eq!(e.location, Location::Field("materials".into()));
    let e = both(&rest, &good, &[m, ElementMaterial { youngs: 0.0, ..m }], r);
    assert_eq!(e.location, Location::Field("materials[1].youngs".into()));
    let e = both(&rest, &good, &[ElementMaterial { poisson: -1.0, ..m }], r);
    assert_eq!(e.location, Location::Field("materials[0].poisson".into()));

    // A rest strand folding back onto itself has no bending rest state.
    let hairpin = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    RodStretch::new(&hairpin, &[vec![0, 1, 2]], &[m], r, path()).unwrap();
    let e = error_of(RodBend::new(&hairpin, &[vec![0, 1, 2]], &[m], r, path()));
    assert_eq!(e.location, Location::Element(0));
}
