//! The barrier and lagged friction potentials over a whole surface: gradients and Hessians
//! against finite differences, projected Hessians PSD, and the stencil list following the
//! broad phase.

use super::rng;
use crate::contact::barrier_potential::BarrierPotential;
use crate::contact::broad_phase::Candidates;
use crate::contact::friction_potential::FrictionPotential;
use crate::contact::ContactSurface;
use crate::energy::fd::assert_all_stencils;
use crate::energy::psd::min_eigenvalue;
use crate::energy::{self, gather, Local, StencilEnergy, Want, MAX_DOF};
use rand::Rng;

/// A tetrahedron (vertices 0..4) above a triangle (vertices 4..7) in the plane `z = 0`,
/// perturbed at random, and its surface: every kind of 3D pair is near.
fn tet_over_triangle(seed: u64) -> (ContactSurface, Vec<f64>) {
    let mut r = rng(seed);
    let mut x = vec![
        0.0, 0.0, 0.15, 0.6, 0.1, 0.2, 0.1, 0.5, 0.25, 0.2, 0.2, 0.7, // tet
        -1.0, -1.0, 0.0, 1.5, -0.8, 0.0, 0.0, 1.5, 0.0, // triangle
    ];
    x.iter_mut().for_each(|c| *c += r.random_range(-0.03..0.03));
    let surface = ContactSurface {
        dim: 3,
        vertices: (0..7).collect(),
        edges: vec![[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3], [4, 5], [4, 6], [5, 6]],
        faces: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3], [4, 5, 6]],
    };
    (surface, x)
}

fn assert_projected_psd(e: &dyn StencilEnergy, x: &[f64]) {
    let mut xl = [0.0; MAX_DOF];
    let mut out = Local::default();
    for s in 0..e.len() {
        let n = gather(e, s, x, &mut xl);
        e.eval(s, &xl[..n], Want::Hessian { project: true }, &mut out);
        let scale = out.hess[..n * n].iter().fold(1.0f64, |m, v| m.max(v.abs()));
        assert!(min_eigenvalue(&out.hess, n) > -1e-9 * scale, "{} stencil {s}", e.name());
    }
}

#[test]
fn barrier_potential_matches_finite_differences_and_projects_to_psd() {
    let dhat = 0.3;
    for seed in 0..5 {
        let (surface, x) = tet_over_triangle(seed);
        let mut b = BarrierPotential::new(surface.clone(), x.clone(), dhat);
        b.set_candidates(&Candidates::within(&surface, &x, dhat));
        let active = (0..b.len())
            .filter(|&s| {
                let mut xl = [0.0; MAX_DOF];
                let n = gather(&b, s, &x, &mut xl);
                b.squared_distance(s, &xl[..n]) < dhat * dhat
            })
            .count();
        assert!(active >= 3, "seed {seed}: only {active} pairs within dhat");
        assert!(energy::value(&b, &x) > 0.0);
        assert_all_stencils(&b, &x, 1e-7, 1e-4);
        assert_projected_psd(&b, &x);
    }
}

#[test]
fn barrier_potential_counts_only_the_loaded_pairs() {
    let (surface, x) = tet_over_triangle(0);
    let mut b = BarrierPotential::new(surface.clone(), x.clone(), 0.3);
    assert_eq!(energy::value(&b, &x), 0.0);
    b.set_candidates(&Candidates::within(&surface, &x, 0.3));
    let full = energy::value(&b, &x);
    // Far apart, nothing is within dhat and the rebuilt list is empty.
    let lifted: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(k, c)| if k < 12 && k % 3 == 2 { c + 5.0 } else { *c })
        .collect();
    b.set_candidates(&Candidates::within(&surface, &lifted, 0.3));
    assert!(full > 0.0);
    // Only pairs within the tet itself can remain near each other.
    assert!((0..b.len()).all(|s| b.stencil(s).iter().all(|&v| v < 4)));
    let near = Candidates::within(&surface, &x, 0.3);
    assert!(
        near.point_triangle.iter().any(|p| p[1] == 4),
        "a tet vertex over the triangle"
    );
}

#[test]
fn lagged_friction_matches_finite_differences_and_projects_to_psd() {
    let dhat = 0.3;
    for seed in 0..5 {
        let (surface, x) = tet_over_triangle(seed);
        let mut b = BarrierPotential::new(surface.clone(), x.clone(), dhat);
        b.set_candidates(&Candidates::within(&surface, &x, dhat));
        let f = FrictionPotential::lagged(&b, &x, 10.0, 0.5, 1e-2);
        assert!(f.len() >= 3, "seed {seed}: {} friction stencils", f.len());
        // Displacements both below (sticking) and above (sliding) the smoothing threshold.
        for amp in [3e-3, 0.1] {
            let mut r = rng(100 + seed);
            let y: Vec<f64> = x.iter().map(|c| c + amp * r.random_range(-1.0..1.0)).collect();
            assert_all_stencils(&f, &y, 1e-7, 1e-4);
            assert_projected_psd(&f, &y);
            assert!(energy::value(&f, &y) > 0.0);
        }
        // No displacement, no friction force.
        let mut g = vec![0.0; x.len()];
        energy::add_gradient(&f, 1.0, &x, &mut g);
        assert!(g.iter().all(|v| *v == 0.0));
    }
}

#[test]
fn frictionless_contact_has_no_friction_stencils() {
    let (surface, x) = tet_over_triangle(1);
    let mut b = BarrierPotential::new(surface.clone(), x.clone(), 0.3);
    b.set_candidates(&Candidates::within(&surface, &x, 0.3));
    assert!(FrictionPotential::lagged(&b, &x, 10.0, 0.0, 1e-2).is_empty());
}
