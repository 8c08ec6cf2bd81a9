//! Tests of the bending energy.

use super::*;
use crate::energy::shell::bending::dihedral_angle;

#[test]
fn bending_matches_finite_differences_on_flat_curved_and_folded_hinges() {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let (m, t) = stiff();
    let mut worst = (0.0f64, 0.0f64);
    let angles = [0.0, 1e-7, -1e-5, 0.3, -1.0, 2.0, -2.5, 2.9, -3.0, 3.05];
    for _ in 0..40 {
        for &rest_angle in &[0.0, rng.random_range(-1.0..1.0)] {
            let rest = hinge(&mut rng, rest_angle);
            let energy = ShellBending::new(&rest, &HINGE_TRIS, &[m], t, path()).unwrap();
            assert_eq!(energy.len(), 1);
            for &angle in &angles {
                let (rotation, shift) = random_rigid(&mut rng);
                let x = transform(&hinge(&mut rng, angle), &rotation, &shift);
                let r = check_stencil(&energy, 0, &x, 1e-6);
                assert!(
                    r.grad_error < 1e-6 && r.hess_error < 1e-6,
                    "angle {angle}, rest {rest_angle}: {r:?}"
                );
                worst = (worst.0.max(r.grad_error), worst.1.max(r.hess_error));
            }
        }
    }
    eprintln!("hinge FD worst: gradient {:.1e}, Hessian {:.1e}", worst.0, worst.1);
}

#[test]
fn dihedral_angle_is_the_signed_angle_between_the_faces() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    for &angle in &[0.0, 1e-9, 0.5, -0.5, FRAC_PI_2, 3.0, -3.1] {
        let x = hinge(&mut rng, angle);
        let (rotation, shift) = random_rigid(&mut rng);
        let x = transform(&x, &rotation, &shift);
        let [x0, x1, x2, x3] = [0, 1, 2, 3].map(|v| vertex(&x, v));
        let theta = dihedral_angle(&(x1 - x0), &(x2 - x0), &(x3 - x0));
        assert!((theta.abs() - angle.abs()).abs() < 1e-12, "{theta} vs {angle}");
    }
}

const CYLINDER_RADIUS: f64 = 0.8;

/// Bends a flat strip of `n x n/2` squares onto a cylinder; returns the membrane and
/// bending energies as fractions of the continuum bending energy.
fn cylinder_ratios(n: usize, flip: bool, axis_y: bool) -> (f64, f64) {
    let (m, t) = cloth();
    let (width, radius) = (1.0, CYLINDER_RADIUS);
    let h = width / n as f64;
    let (nu, nv) = if axis_y { (n, n / 2) } else { (n / 2, n) };
    let (flat, tris) = grid(nu, nv, h, flip);
    let x = onto_cylinder(&flat, radius, axis_y);
    let membrane = ShellMembrane::new(&flat, &tris, &[m], t, path()).unwrap();
    let bending = ShellBending::new(&flat, &tris, &[m], t, path()).unwrap();
    let area = width * width / 2.0;
    let continuum = 0.5 * plate_stiffness(&m, t) / (radius * radius) * area;
    (value(&membrane, &x) / continuum, value(&bending, &x) / continuum)
}

#[test]
fn cylinder_bending_matches_the_plate_energy() {
    for flip in [false, true] {
        for axis_y in [true, false] {
            for n in [10, 20, 40, 80] {
                let (membrane, bending) = cylinder_ratios(n, flip, axis_y);
                eprintln!(
                    "cylinder n={n} flip={flip} axis_y={axis_y}: bending/continuum \
                     {bending:.5}, membrane/continuum {membrane:.2e}"
                );
                // The only discrepancy is the boundary: n - 1 hinge lines for n columns.
                assert!((bending - (1.0 - 1.0 / n as f64)).abs() < 1e-3, "{bending}");
                // Chords shorten edges across the axis by ~h^2 / (24 R^2): a membrane
                // energy of relative size ~h^4 / (48 R^2 t^2).
                let (h, t) = (1.0 / n as f64, cloth().1);
                let chord_estimate = h.powi(4) / (48.0 * (CYLINDER_RADIUS * t).powi(2));
                assert!(membrane < 1.2 * chord_estimate, "{membrane} vs {chord_estimate}");
                if n >= 40 {
                    assert!((bending - 1.0).abs() < 0.03, "{bending}");
                    assert!(membrane < 2e-3, "{membrane}");
                }
            }
        }
    }
}

/// A patch of equilateral triangles of side `h`: `nv` rows of `2 nu` triangles.
fn equilateral(nu: usize, nv: usize, h: f64) -> (Vec<f64>, Vec<[usize; 3]>) {
    let mut rest = Vec::new();
    for j in 0..=nv {
        let shift = if j % 2 == 1 { 0.5 * h } else { 0.0 };
        for i in 0..=nu {
            rest.extend([i as f64 * h + shift, j as f64 * h * 0.75f64.sqrt(), 0.0]);
        }
    }
    let id = |i: usize, j: usize| j * (nu + 1) + i;
    let mut tris = Vec::new();
    for j in 0..nv {
        for i in 0..nu {
            if j % 2 == 0 {
                tris.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
                tris.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
            } else {
                tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
                tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            }
        }
    }
    (rest, tris)
}

/// Wraps the xy-plane isometrically onto a cylinder of radius `radius` whose axis makes
/// the angle `axis` with the x-axis.
fn onto_tilted_cylinder(flat: &[f64], radius: f64, axis: f64) -> Vec<f64> {
    let (along, across) = (
        Vector3::new(axis.cos(), axis.sin(), 0.0),
        Vector3::new(-axis.sin(), axis.cos(), 0.0),
    );
    flat.chunks_exact(3)
        .flat_map(|p| {
            let p = Vector3::new(p[0], p[1], p[2]);
            let (t, s) = (p.dot(&along), p.dot(&across));
            let q = along * t
                + across * (radius * (s / radius).sin())
                + Vector3::z() * (radius * (1.0 - (s / radius).cos()));
            [q.x, q.y, q.z]
        })
        .collect()
}

#[test]
fn cylinder_bending_on_an_equilateral_mesh_is_isotropic() {
    let (m, t) = cloth();
    let radius = CYLINDER_RADIUS;
    for n in [10, 20, 40, 80] {
        let h = 1.0 / n as f64;
        let (flat, tris) = equilateral(n, n, h);
        let area: f64 = tris
            .iter()
            .map(|tri| {
                let [a, b, c] = tri.map(|v| vertex(&flat, v));
                0.5 * (b - a).cross(&(c - a)).norm()
            })
            .sum();
        let bending = ShellBending::new(&flat, &tris, &[m], t, path()).unwrap();
        let continuum = 0.5 * plate_stiffness(&m, t) / (radius * radius) * area;
        let ratios: Vec<f64> = [0.0, 0.4, 1.0, FRAC_PI_2, 2.5]
            .iter()
            .map(|&axis| value(&bending, &onto_tilted_cylinder(&flat, radius, axis)) / continuum)
            .collect();
        eprintln!("equilateral cylinder n={n}: bending/continuum {ratios:.4?}");
        for r in &ratios {
            assert!((r - 1.0).abs() < 2.0 / n as f64, "n = {n}: {ratios:?}");
        }
    }
}

#[test]
fn hinges_are_the_interior_edges() {
    let (m, t) = stiff();
    let (rest, tris) = grid(3, 2, 1.0, true);
    let bending = ShellBending::new(&rest, &tris, &[m], t, path()).unwrap();
    // 3 x 2 squares: 12 triangles, 6 diagonals, 2 x 2 vertical and 3 x 1 horizontal
    // interior edges.
    assert_eq!(bending.len(), 6 + 4 + 3);
    for h in 0..bending.len() {
        assert_eq!(bending.rest_angle(h), 0.0);
        let s = bending.stencil(h);
        let shared = tris.iter().filter(|t| t.contains(&s[0]) && t.contains(&s[1]));
        assert_eq!(shared.count(), 2);
    }
}
