//! The adaptive implicit-Euler step against the full-space Newton solver and against a
//! dense solve of its reduced problem.

use std::path::Path;

use nalgebra::{DMatrix, DVector};

use crate::adaptive::candidates::{CandidateSet, CandidateSpec};
use crate::adaptive::pcg::PcgSettings;
use crate::adaptive::step::{ActiveModel, AdaptiveStepError, AdaptiveStepper};
use crate::scene::Scene;

/// A rubber cantilever of 6 x 2 x 2 cubes split into tets, clamped at `x = 0`, under
/// gravity, with a tight Newton tolerance.
const CANTILEVER: &str = r#"
name = "cantilever"
dt = 0.02
gravity = [0.0, 0.0, -9.81]
[newton]
tolerance = 1e-6
[mesh]
type = "box"
min = [0.0, 0.0, 0.0]
max = [3.0, 0.5, 0.5]
cells = [6, 2, 2]
[material]
youngs = 1e5
poisson = 0.4
density = 1000.0
[[handles]]
name = "clamp"
select = { side = { axis = 0, end = "min" } }
"#;

fn cantilever() -> Scene {
    Scene::parse(CANTILEVER, Path::new("cantilever.toml")).unwrap()
}

/// Conjugate gradients to round-off, so the Schur complement solve is exact.
fn exact_pcg() -> PcgSettings {
    PcgSettings {
        tolerance: 1e-13,
        ..PcgSettings::default()
    }
}

fn rigid_affine(scene: &Scene) -> CandidateSet {
    let spec = CandidateSpec {
        linear_modes: 0,
        ..CandidateSpec::default()
    };
    CandidateSet::from_scene(scene, &spec).unwrap()
}

/// The rest positions of the prescribed vertices (the clamp does not move).
fn clamp_targets(stepper: &AdaptiveStepper, rest: &[f64]) -> Vec<f64> {
    stepper
        .fixed_vertices()
        .iter()
        .flat_map(|&v| rest[3 * v..3 * v + 3].iter().copied())
        .collect()
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
}

#[test]
fn with_every_vertex_enriched_the_step_is_full_space_newton() {
    let scene = cantilever();
    let mut full = scene.build().unwrap();
    let rest = full.mesh.rest.clone();
    let scale = scene.dt * full.mesh.rest_diagonal();
    let candidates = rigid_affine(&scene);
    let mut stepper = AdaptiveStepper::from_scene(&scene, exact_pcg()).unwrap();
    let targets = clamp_targets(&stepper, &rest);
    assert_eq!(full.simulator.fixed_vertices(), stepper.fixed_vertices());
    let model = ActiveModel {
        blocks: vec![true; candidates.blocks.len()],
        enriched: vec![true; rest.len() / 3],
    };
    for step in 0..3 {
        let reference = full.simulator.step(&targets).unwrap();
        let report = stepper.step(&targets, &candidates, &model).unwrap();
        // Every modal column is masked away; the enriched coordinates are all free dofs.
        assert_eq!(report.modal_columns, 0);
        assert_eq!(report.enriched_dofs, full.simulator.num_free_dofs());
        assert!(report.converged && reference.converged, "step {step}");
        assert_eq!(report.iterations, reference.iterations, "step {step}");
        for (a, b) in report.step_norms.iter().zip(&reference.step_norms) {
            assert!(
                (a - b).abs() <= 1e-6 * b.max(1e-3),
                "step {step}: step norms {a} and {b}"
            );
        }
        let gap = max_abs_diff(stepper.positions(), full.simulator.positions()) / scale;
        assert!(
            gap < scene.newton.tolerance,
            "step {step}: positions differ by {gap} (h L), tolerance {}",
            scene.newton.tolerance
        );
        let moved = max_abs_diff(stepper.positions(), &rest) / scale;
        assert!(moved > 1e-2, "step {step}: the beam barely moved ({moved} h L)");
    }
    let gap = max_abs_diff(stepper.velocities(), full.simulator.velocities());
    assert!(gap < 1e-6, "velocities differ by {gap}");
}

/// Minimises `e` over `x0 + U q` by Newton's method with central-difference gradients and
/// Hessians of `e` (dense, independent of the stepper's assembly); returns `x0 + U q`.
fn dense_subspace_minimum(e: impl Fn(&[f64]) -> f64, x0: &[f64], u: &DMatrix<f64>) -> Vec<f64> {
    let a = u.ncols();
    let eps = 1e-4;
    let at = |q: &DVector<f64>| -> Vec<f64> { (DVector::from_column_slice(x0) + u * q).as_slice().to_vec() };
    let mut q = DVector::zeros(a);
    for _ in 0..8 {
        let e0 = e(&at(&q));
        let shifted = |i: usize, si: f64, j: usize, sj: f64| {
            let mut p = q.clone();
            p[i] += si * eps;
            p[j] += sj * eps;
            e(&at(&p))
        };
        let g = DVector::from_fn(a, |i, _| {
            (shifted(i, 1.0, i, 0.0) - shifted(i, -1.0, i, 0.0)) / (2.0 * eps)
        });
        let mut h = DMatrix::zeros(a, a);
        for i in 0..a {
            h[(i, i)] = (shifted(i, 1.0, i, 0.0) - 2.0 * e0 + shifted(i, -1.0, i, 0.0)) / (eps * eps);
            for j in 0..i {
                let v = (shifted(i, 1.0, j, 1.0) - shifted(i, 1.0, j, -1.0) - shifted(i, -1.0, j, 1.0)
                    + shifted(i, -1.0, j, -1.0))
                    / (4.0 * eps * eps);
                h[(i, j)] = v;
                h[(j, i)] = v;
            }
        }
        q -= h.cholesky().expect("reduced Hessian is positive definite").solve(&g);
    }
    at(&q)
}

#[test]
fn with_rigid_and_affine_modes_only_the_step_finds_the_subspace_minimum() {
    let scene = cantilever();
    let rest = scene.build_mesh().unwrap().rest;
    let scale = scene.dt * scene.build_mesh().unwrap().rest_diagonal();
    let candidates = rigid_affine(&scene);
    let mut stepper = AdaptiveStepper::from_scene(&scene, PcgSettings::default()).unwrap();
    let targets = clamp_targets(&stepper, &rest);
    let model = ActiveModel {
        blocks: vec![true; candidates.blocks.len()],
        enriched: vec![false; rest.len() / 3],
    };
    // The start of the step: the prediction x + h v with the clamp at its targets (at rest,
    // the positions themselves).
    let start = stepper.positions().to_vec();
    let report = stepper.step(&targets, &candidates, &model).unwrap();
    assert_eq!(report.modal_columns, 12, "rigid and affine modes, linearly independent");
    assert_eq!(report.enriched_dofs, 0);
    assert!(report.converged, "{report:?}");
    for w in report.objectives.windows(2) {
        // (Up to round-off: E with and without its gradient sums in different orders.)
        assert!(
            w[1] <= w[0] + 1e-14 * w[0].abs(),
            "E increased: {:?}",
            report.objectives
        );
    }
    assert!(report.objectives.last() < report.objectives.first());
    let u = DMatrix::from_fn(start.len(), 12, |r, c| candidates.modes[(r, c)]);
    let e = |x: &[f64]| stepper.incremental_potential(x);
    let dense = dense_subspace_minimum(e, &start, &u);
    let gap = max_abs_diff(stepper.positions(), &dense) / scale;
    assert!(
        gap < scene.newton.tolerance,
        "the step ends {gap} (h L) from the dense subspace minimum"
    );
    // The subspace is a restriction: full-space Newton reaches a lower E.
    let mut full = scene.build().unwrap();
    full.simulator.step(&targets).unwrap();
    assert!(e(full.simulator.positions()) < e(stepper.positions()) - 1e-9 * e(&start).abs());
}

#[test]
fn mixed_model_decreases_e_and_lands_between_subspace_and_full_space() {
    let scene = cantilever();
    let rest = scene.build_mesh().unwrap().rest;
    let candidates = rigid_affine(&scene);
    let targets_of = |s: &AdaptiveStepper| clamp_targets(s, &rest);
    // The free half of the beam enriched, the rest in the rigid and affine modes.
    let enriched: Vec<bool> = rest.chunks_exact(3).map(|p| p[0] > 1.5).collect();
    let mut energies = Vec::new();
    for enriched in [vec![false; enriched.len()], enriched, vec![true; rest.len() / 3]] {
        let mut stepper = AdaptiveStepper::from_scene(&scene, exact_pcg()).unwrap();
        let model = ActiveModel {
            blocks: vec![true; candidates.blocks.len()],
            enriched,
        };
        let report = stepper.step(&targets_of(&stepper), &candidates, &model).unwrap();
        assert!(report.converged, "{report:?}");
        for w in report.objectives.windows(2) {
            // (Up to round-off: E with and without its gradient sums in different orders.)
            assert!(
                w[1] <= w[0] + 1e-14 * w[0].abs(),
                "E increased: {:?}",
                report.objectives
            );
        }
        // Exact Newton in the model: quadratic convergence (measured here: each scaled
        // step norm below 0.02 times the square of the one before; a model without the
        // coupling C converges linearly, its second step above the square of its first).
        for w in report.step_norms.windows(2) {
            assert!(
                w[1] < 1e-12 || w[1] <= w[0] * w[0],
                "not quadratic: {:?}",
                report.step_norms
            );
        }
        energies.push(*report.objectives.last().unwrap());
    }
    // A richer model reaches a lower incremental potential.
    assert!(energies[0] > energies[1] && energies[1] > energies[2], "{energies:?}");
}

#[test]
fn a_model_that_does_not_fit_the_body_is_an_error() {
    let scene = cantilever();
    let rest = scene.build_mesh().unwrap().rest;
    let candidates = rigid_affine(&scene);
    let mut stepper = AdaptiveStepper::from_scene(&scene, PcgSettings::default()).unwrap();
    let targets = clamp_targets(&stepper, &rest);
    let short = ActiveModel {
        blocks: vec![true; candidates.blocks.len()],
        enriched: vec![false; 3],
    };
    let err = stepper.step(&targets, &candidates, &short).unwrap_err();
    assert!(matches!(err, AdaptiveStepError::Model(_)), "{err}");
    assert!(err.to_string().contains("enriched"), "{err}");
    let model = ActiveModel {
        blocks: vec![true],
        enriched: vec![false; rest.len() / 3],
    };
    let err = stepper.step(&targets, &candidates, &model).unwrap_err();
    assert!(err.to_string().contains("blocks"), "{err}");
    let err = stepper.step(&targets[1..], &candidates, &model).unwrap_err();
    assert!(matches!(err, AdaptiveStepError::Step(_)), "{err}");
    assert_eq!(stepper.positions(), &rest[..], "a failed step leaves the state");
}
