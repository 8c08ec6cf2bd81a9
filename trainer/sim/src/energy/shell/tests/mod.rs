//! Tests of the cloth energies: helpers and the properties both energies share.

use super::*;
use crate::energy::fd::{assert_all_stencils, check_stencil};
use crate::energy::psd::min_eigenvalue;
use crate::energy::{add_gradient, value, StencilEnergy, Want};
use crate::error::Location;
use nalgebra::Rotation3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::{FRAC_PI_2, PI};

mod bending;
mod membrane;

const SOURCE: &str = "<test>";

/// Material and thickness giving stiffnesses of order 1..1e3, so that the relative
/// finite-difference errors are meaningful.
fn stiff() -> (ElementMaterial, f64) {
    let m = ElementMaterial {
        youngs: 1e6,
        poisson: 0.3,
        density: 1000.0,
    };
    (m, 0.1)
}

/// Cloth from the paper: E = 1 MPa (as a physical stand-in), nu = 0.45, t = 3 mm.
fn cloth() -> (ElementMaterial, f64) {
    let m = ElementMaterial {
        youngs: 1e6,
        poisson: 0.45,
        density: 1500.0,
    };
    (m, 3e-3)
}

fn plate_stiffness(m: &ElementMaterial, thickness: f64) -> f64 {
    m.youngs * thickness.powi(3) / (12.0 * (1.0 - m.poisson * m.poisson))
}

fn random_rigid(rng: &mut ChaCha8Rng) -> (Rotation3<f64>, Vector3<f64>) {
    let axis = Vector3::new(rng.random(), rng.random(), rng.random::<f64>()) * 2.0 - Vector3::repeat(1.0);
    let rotation = Rotation3::new(axis.normalize() * rng.random_range(0.0..PI));
    let shift = Vector3::new(rng.random(), rng.random(), rng.random::<f64>()) * 4.0;
    (rotation, shift)
}

fn transform(x: &[f64], rotation: &Rotation3<f64>, shift: &Vector3<f64>) -> Vec<f64> {
    x.chunks_exact(3)
        .flat_map(|p| {
            let q = rotation * Vector3::new(p[0], p[1], p[2]) + shift;
            [q.x, q.y, q.z]
        })
        .collect()
}

fn perturb(x: &[f64], rng: &mut ChaCha8Rng, amount: f64) -> Vec<f64> {
    x.iter().map(|c| c + amount * rng.random_range(-1.0..1.0)).collect()
}

/// A hinge with edge (0,0,0)-(length,0,0), first opposite vertex in the +y half plane and
/// the second one rotated about the edge so that the dihedral angle is `angle`.
fn hinge(rng: &mut ChaCha8Rng, angle: f64) -> [f64; 12] {
    let length = rng.random_range(0.5..2.0);
    let (u1, u2) = (
        rng.random_range(-0.3..1.3) * length,
        rng.random_range(-0.3..1.3) * length,
    );
    let (h1, h2) = (rng.random_range(0.3..1.5), rng.random_range(0.3..1.5));
    let (c, s) = (angle.cos(), angle.sin());
    [0.0, 0.0, 0.0, length, 0.0, 0.0, u1, h1, 0.0, u2, -h2 * c, -h2 * s]
}

const HINGE_TRIS: [[usize; 3]; 2] = [[0, 1, 2], [1, 0, 3]];

/// A regular grid of `nu x nv` squares of side `h` in the xy-plane, each split along
/// one diagonal or the other.
fn grid(nu: usize, nv: usize, h: f64, flip: bool) -> (Vec<f64>, Vec<[usize; 3]>) {
    let mut rest = Vec::new();
    for j in 0..=nv {
        for i in 0..=nu {
            rest.extend([i as f64 * h, j as f64 * h, 0.0]);
        }
    }
    let id = |i: usize, j: usize| j * (nu + 1) + i;
    let mut tris = Vec::new();
    for j in 0..nv {
        for i in 0..nu {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            if flip {
                tris.extend([[a, b, d], [b, c, d]]);
            } else {
                tris.extend([[a, b, c], [a, c, d]]);
            }
        }
    }
    (rest, tris)
}

/// Wraps the xy-plane isometrically onto a cylinder of radius `radius` whose axis is
/// along y (`axis_y`) or along x.
fn onto_cylinder(flat: &[f64], radius: f64, axis_y: bool) -> Vec<f64> {
    flat.chunks_exact(3)
        .flat_map(|p| {
            let (s, t) = if axis_y { (p[0], p[1]) } else { (p[1], p[0]) };
            let (across, up) = (radius * (s / radius).sin(), radius * (1.0 - (s / radius).cos()));
            if axis_y {
                [across, t, up]
            } else {
                [t, across, up]
            }
        })
        .collect()
}

fn path() -> &'static Path {
    Path::new(SOURCE)
}

#[test]
fn zero_energy_and_gradient_at_flat_and_curved_rest_shapes() {
    let (m, t) = stiff();
    let (flat, tris) = grid(4, 3, 0.25, false);
    let curved = onto_cylinder(&flat, 0.7, true);
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let bumpy = perturb(&flat, &mut rng, 0.05);
    for rest in [flat, curved, bumpy] {
        let membrane = ShellMembrane::new(&rest, &tris, &[m], t, path()).unwrap();
        let bending = ShellBending::new(&rest, &tris, &[m], t, path()).unwrap();
        for energy in [&membrane as &dyn StencilEnergy, &bending] {
            let mut grad = vec![0.0; rest.len()];
            let e = add_gradient(energy, 1.0, &rest, &mut grad);
            let g = grad.iter().fold(0.0f64, |m, g| m.max(g.abs()));
            assert!(e.abs() < 1e-20 && g < 1e-9, "{}: {e:e}, {g:e}", energy.name());
        }
    }
}

#[test]
fn energies_are_invariant_under_rigid_motion() {
    let (m, t) = stiff();
    let (flat, tris) = grid(3, 3, 0.3, true);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let rest = perturb(&flat, &mut rng, 0.05);
    let membrane = ShellMembrane::new(&rest, &tris, &[m], t, path()).unwrap();
    let bending = ShellBending::new(&rest, &tris, &[m], t, path()).unwrap();
    for _ in 0..10 {
        let x = perturb(&onto_cylinder(&rest, 0.5, false), &mut rng, 0.1);
        let (rotation, shift) = random_rigid(&mut rng);
        let moved = transform(&x, &rotation, &shift);
        for energy in [&membrane as &dyn StencilEnergy, &bending] {
            let (a, b) = (value(energy, &x), value(energy, &moved));
            assert!(a > 0.0 && (a - b).abs() <= 1e-10 * a, "{}: {a} {b}", energy.name());
        }
    }
}

#[test]
fn energies_match_finite_differences_on_a_deformed_mesh() {
    let (m, t) = stiff();
    let (flat, tris) = grid(3, 2, 0.4, false);
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    let materials: Vec<ElementMaterial> = (0..tris.len())
        .map(|_| ElementMaterial {
            youngs: m.youngs * rng.random_range(0.5..2.0),
            poisson: rng.random_range(0.0..0.45),
            ..m
        })
        .collect();
    let membrane = ShellMembrane::new(&flat, &tris, &materials, t, path()).unwrap();
    let bending = ShellBending::new(&flat, &tris, &materials, t, path()).unwrap();
    let x = perturb(&onto_cylinder(&flat, 0.4, true), &mut rng, 0.05);
    assert_all_stencils(&membrane, &x, 1e-6, 1e-7);
    assert_all_stencils(&bending, &x, 1e-6, 1e-6);
}

#[test]
fn projected_hessians_are_positive_semidefinite() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (m, t) = stiff();
    let mut negative_seen = [false; 2];
    for _ in 0..50 {
        let (rest_angle, angle) = (rng.random_range(-0.5..0.5), rng.random_range(-3.0..3.0));
        let rest = hinge(&mut rng, rest_angle);
        let membrane = ShellMembrane::new(&rest, &HINGE_TRIS, &[m], t, path()).unwrap();
        let bending = ShellBending::new(&rest, &HINGE_TRIS, &[m], t, path()).unwrap();
        let x = hinge(&mut rng, angle);
        let x = perturb(&x, &mut rng, 0.3);
        for (k, energy) in [&membrane as &dyn StencilEnergy, &bending].iter().enumerate() {
            let mut local = [0.0; 12];
            let n = crate::energy::gather(*energy, 0, &x, &mut local);
            let mut out = Local::default();
            energy.eval(0, &local[..n], Want::Hessian { project: false }, &mut out);
            let exact_min = min_eigenvalue(&out.hess[..n * n], n);
            negative_seen[k] |= exact_min < 0.0;
            energy.eval(0, &local[..n], Want::Hessian { project: true }, &mut out);
            let scale = out.hess[..n * n].iter().fold(1.0f64, |m, h| m.max(h.abs()));
            let min = min_eigenvalue(&out.hess[..n * n], n);
            assert!(min > -1e-10 * scale, "{}: {min}", energy.name());
        }
    }
    assert_eq!(negative_seen, [true, true], "the test should include indefinite cases");
}

#[test]
fn stencil_projection_equals_full_eigenvalue_clamping() {
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    for vertices in 2..=4 {
        let n = 3 * vertices;
        for _ in 0..20 {
            // A random symmetric matrix acting on relative vectors x_a - x_0, so that it
            // maps rigid translations to zero, as every stencil Hessian here does.
            let r = n - 3;
            let a: Vec<f64> = (0..r * r).map(|_| rng.random_range(-1.0..1.0)).collect();
            let relative = nalgebra::DMatrix::from_fn(r, r, |i, j| a[i * r + j] + a[j * r + i]);
            let map = nalgebra::DMatrix::from_fn(r, n, |i, j| {
                let (p, a) = (i / 3, j / 3);
                let same = if i % 3 == j % 3 { 1.0 } else { 0.0 };
                same * if a == 0 {
                    -1.0
                } else if a == p + 1 {
                    1.0
                } else {
                    0.0
                }
            });
            let full = map.transpose() * relative * map;
            let mut h: Vec<f64> = (0..n * n).map(|k| full[(k / n, k % n)]).collect();
            let mut want = h.clone();
            project_psd(&mut want, n);
            project_stencil_hessian(&mut h, n);
            let err = h.iter().zip(&want).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(err < 1e-12 * full.amax(), "{vertices} vertices: {err:e}");
        }
    }
}

fn error_of<T>(result: Result<T, InputError>) -> InputError {
    match result {
        Ok(_) => panic!("expected an error"),
        Err(e) => e,
    }
}

#[test]
fn bad_input_errors_name_the_element_or_field() {
    let (m, t) = stiff();
    let (rest, tris) = grid(2, 1, 1.0, false);
    let both = |rest: &[f64], tris: &[[usize; 3]], mats: &[ElementMaterial], t: f64| {
        let a = error_of(ShellMembrane::new(rest, tris, mats, t, path()));
        let b = error_of(ShellBending::new(rest, tris, mats, t, path()));
        assert_eq!(a, b);
        assert_eq!(a.file, Path::new(SOURCE));
        a
    };
    let mut out_of_range = tris.clone();
    out_of_range[2][1] = 99;
    let e = both(&rest, &out_of_range, &[m], t);
    assert_eq!(e.location, Location::Element(2));
    assert!(e.message.contains("99"), "{e}");

    let mut nan = rest.clone();
    nan[4] = f64::NAN;
    let e = both(&nan, &tris, &[m], t);
    assert_eq!(e.location, Location::Field("vertices[1]".into()));

    let e = both(&rest, &tris, &[m], 0.0);
    assert_eq!(e.location, Location::Field("thickness".into()));
    let e = both(&rest, &tris, &[m], f64::NAN);
    assert_eq!(e.location, Location::Field("thickness".into()));

    let mut bad = vec![m; tris.len()];
    bad[3].poisson = 0.5;
    let e = both(&rest, &tris, &bad, t);
    assert_eq!(e.location, Location::Field("materials[3].poisson".into()));
    bad[3] = ElementMaterial { youngs: -1.0, ..m };
    let e = both(&rest, &tris, &bad, t);
    assert_eq!(e.location, Location::Field("materials[3].youngs".into()));
    let e = both(&rest, &tris, &[m, m], t);
    assert_eq!(e.location, Location::Field("materials".into()));

    let mut degenerate = rest.clone();
    degenerate[4 * 3..4 * 3 + 3].copy_from_slice(&[0.5, 0.0, 0.0]);
    let e = both(&degenerate, &[[0, 1, 4]], &[m], t);
    assert_eq!(e.location, Location::Element(0));
    let e = both(&rest, &[[0, 1, 4], [1, 1, 2]], &[m], t);
    assert_eq!(e.location, Location::Element(1));

    // Three triangles on edge (0, 1): the third one is named.
    let fan = [[0, 1, 3], [1, 0, 4], [0, 1, 5]];
    ShellMembrane::new(&rest, &fan, &[m], t, path()).unwrap();
    let e = error_of(ShellBending::new(&rest, &fan, &[m], t, path()));
    assert_eq!(e.location, Location::Element(2));
    assert!(e.message.contains("(0, 1)"), "{e}");
}
