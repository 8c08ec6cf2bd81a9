//! The adaptive model inside the simulator's Newton loop, against full-space Newton, a
//! dense solve of its reduced problem, and its own oracle and downdating.

use std::path::Path;

use nalgebra::{DMatrix, DVector};

use crate::adaptive::{ActiveModel, AdaptiveSettings, SubspaceHessian};
use crate::energy::inertia::Inertia;
use crate::measure::mean_and_max_error;
use crate::scene::{BuiltScene, Energies, Scene, SolverSpec};
use crate::solver::incremental_potential;

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

/// The cantilever with the adaptive solver: rigid and affine candidates only, conjugate
/// gradients to round-off, `settings` changed by `edit`.
fn adaptive(edit: impl Fn(&mut AdaptiveSettings)) -> BuiltScene {
    let mut scene = cantilever();
    let mut settings = AdaptiveSettings {
        linear_modes: 0,
        initial_linear_modes: 0,
        pcg_tolerance: 1e-13,
        subdomain_vertices: 8,
        ..AdaptiveSettings::default()
    };
    edit(&mut settings);
    scene.solver = SolverSpec::Adaptive(settings);
    scene.build().unwrap()
}

/// Fixes the model of `built` (its oracle off): every block active, the vertices where
/// `enriched` says so enriched.
fn fix_model(built: &mut BuiltScene, enriched: impl Fn(&[f64]) -> bool) {
    let rest = built.mesh.rest.clone();
    let solver = built.simulator.adaptive_mut().unwrap();
    let model = ActiveModel {
        blocks: vec![true; solver.candidates().blocks.len()],
        enriched: rest.chunks_exact(3).map(enriched).collect(),
    };
    solver.set_model(&model).unwrap();
}

/// The rest positions of the prescribed vertices (the clamp does not move).
fn clamp_targets(built: &BuiltScene) -> Vec<f64> {
    let rest = &built.mesh.rest;
    built
        .simulator
        .fixed_vertices()
        .iter()
        .flat_map(|&v| rest[3 * v..3 * v + 3].iter().copied())
        .collect()
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
}

/// The implicit-Euler incremental potential of the cantilever's first step from rest
/// (its inertia target the rest shape), from the scene's own energies.
fn first_step_potential(scene: &Scene) -> impl Fn(&[f64]) -> f64 {
    let mesh = scene.build_mesh().unwrap();
    let Energies { masses, potentials } = scene.build_energies(&mesh).unwrap();
    let mut inertia = Inertia::new(3, masses);
    inertia.set_target(&mesh.rest);
    let h2 = scene.dt * scene.dt;
    move |x: &[f64]| incremental_potential(&inertia, &potentials, 1.0, h2, x, None)
}

#[test]
fn with_every_vertex_enriched_the_step_is_full_space_newton() {
    let scene = cantilever();
    let mut full = scene.build().unwrap();
    let mut built = adaptive(|s| s.adapt = false);
    fix_model(&mut built, |_| true);
    let scale = scene.dt * full.mesh.rest_diagonal();
    let targets = clamp_targets(&built);
    for step in 0..3 {
        let reference = full.simulator.step(&targets).unwrap();
        let report = built.simulator.step(&targets).unwrap();
        let stats = report.adaptive.as_ref().unwrap();
        assert_eq!(stats.enriched_vertices, stats.free_vertices);
        assert_eq!(stats.enriched.len(), stats.enriched_vertices);
        assert!(report.converged && reference.converged, "step {step}");
        // Both converge to the Newton tolerance from different starts (the adaptive solve
        // from the last positions, the full-space one from the prediction).
        let gap = max_abs_diff(built.simulator.positions(), full.simulator.positions()) / scale;
        assert!(
            gap < scene.newton.tolerance,
            "step {step}: positions differ by {gap} (h L), tolerance {}",
            scene.newton.tolerance
        );
        let moved = max_abs_diff(built.simulator.positions(), &full.mesh.rest) / scale;
        assert!(moved > 1e-2, "step {step}: the beam barely moved ({moved} h L)");
        // Quadratic convergence: every vertex enriched is exact Newton.
        let norms = &report.step_norms;
        for w in norms.windows(2) {
            assert!(w[1] < 1e-9 || w[1] <= 10.0 * w[0] * w[0], "not quadratic: {norms:?}");
        }
    }
}

/// Minimises `e` over `x0 + U q` by Newton's method with central-difference gradients and
/// Hessians of `e` (dense, independent of the solver's assembly); returns `x0 + U q`.
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
    let mut built = adaptive(|s| {
        s.adapt = false;
        s.pcg_tolerance = 1e-5;
    });
    fix_model(&mut built, |_| false);
    let rest = built.mesh.rest.clone();
    let scale = scene.dt * built.mesh.rest_diagonal();
    let targets = clamp_targets(&built);
    let report = built.simulator.step(&targets).unwrap();
    let stats = report.adaptive.as_ref().unwrap();
    assert_eq!(stats.active_modes, 12, "rigid (6) and the other affine (6) columns");
    assert_eq!(stats.enriched_vertices, 0);
    assert!(report.converged, "{report:?}");
    let candidates = built.simulator.adaptive().unwrap().candidates();
    let u = DMatrix::from_fn(rest.len(), 12, |r, c| candidates.modes[(r, c)]);
    let e = first_step_potential(&scene);
    let dense = dense_subspace_minimum(&e, &rest, &u);
    let gap = max_abs_diff(built.simulator.positions(), &dense) / scale;
    assert!(
        gap < scene.newton.tolerance,
        "the step ends {gap} (h L) from the dense subspace minimum"
    );
    // The subspace is a restriction: full-space Newton reaches a lower E.
    let mut full = scene.build().unwrap();
    full.simulator.step(&targets).unwrap();
    assert!(e(full.simulator.positions()) < e(built.simulator.positions()) - 1e-9 * e(&rest).abs());
}

#[test]
fn a_richer_fixed_model_reaches_a_lower_incremental_potential() {
    let scene = cantilever();
    let e = first_step_potential(&scene);
    let mut energies = Vec::new();
    for enriched in [|_: &[f64]| false, |p: &[f64]| p[0] > 1.5, |_: &[f64]| true] {
        let mut built = adaptive(|s| {
            s.adapt = false;
            s.subspace_hessian = SubspaceHessian::Exact;
        });
        fix_model(&mut built, enriched);
        let targets = clamp_targets(&built);
        let report = built.simulator.step(&targets).unwrap();
        assert!(report.converged, "{report:?}");
        // Exact Newton in the model, the coupling C included: quadratic convergence (a
        // model without C converges linearly).
        for w in report.step_norms.windows(2) {
            assert!(
                w[1] < 1e-9 || w[1] <= 10.0 * w[0] * w[0],
                "not quadratic: {:?}",
                report.step_norms
            );
        }
        energies.push(e(built.simulator.positions()));
    }
    assert!(energies[0] > energies[1] && energies[1] > energies[2], "{energies:?}");
}

/// The per-subdomain BFGS elastic subspace Hessian changes the path, not the solution: on
/// a fixed modal model and on a mixed one, each step ends within the Newton tolerance of the
/// exact subspace Hessian's, with one exact evaluation per step and secant updates after it.
#[test]
fn bfgs_subspace_hessians_reach_the_exact_hessians_solution() {
    let scene = cantilever();
    let scale = scene.dt * cantilever().build().unwrap().mesh.rest_diagonal();
    for enriched in [|_: &[f64]| false, |p: &[f64]| p[0] > 1.5] {
        let run = |hessian: SubspaceHessian| {
            let mut built = adaptive(|s| {
                s.adapt = false;
                s.subspace_hessian = hessian;
            });
            fix_model(&mut built, enriched);
            let targets = clamp_targets(&built);
            let reports: Vec<_> = (0..4).map(|_| built.simulator.step(&targets).unwrap()).collect();
            (built.simulator.positions().to_vec(), reports)
        };
        let (exact, exact_reports) = run(SubspaceHessian::Exact);
        let (bfgs, bfgs_reports) = run(SubspaceHessian::Bfgs);
        let gap = max_abs_diff(&bfgs, &exact) / scale;
        assert!(gap < 10.0 * scene.newton.tolerance, "{gap} h L apart");
        for (b, e) in bfgs_reports.iter().zip(&exact_reports) {
            assert!(b.converged && e.converged);
            let stats = b.adaptive.as_ref().unwrap().subspace_hessian;
            assert_eq!(stats.evaluations, 1, "{stats:?}");
            assert!(stats.updates > 0 && b.iterations > 1, "{stats:?}");
            assert_eq!(e.adaptive.as_ref().unwrap().subspace_hessian.evaluations, 0);
        }
    }
}

#[test]
fn tightening_the_error_threshold_converges_to_full_space() {
    let scene = cantilever();
    let steps = 5;
    let mut full = scene.build().unwrap();
    let targets = clamp_targets(&full);
    for _ in 0..steps {
        full.simulator.step(&targets).unwrap();
    }
    let reference = full.simulator.positions().to_vec();
    let mut errors = Vec::new();
    for threshold in [1e-2, 1e-3, 1e-4, 1e-6] {
        let mut built = adaptive(|s| {
            s.modal_error = threshold;
            s.nodal_error = threshold;
        });
        let mut enriched = 0;
        for _ in 0..steps {
            let report = built.simulator.step(&targets).unwrap();
            assert!(report.converged, "threshold {threshold}: {report:?}");
            enriched = enriched.max(report.adaptive.unwrap().enriched_vertices);
        }
        let (mean, _) = mean_and_max_error(built.simulator.positions(), &reference, 3, full.mesh.rest_diagonal());
        errors.push((threshold, mean, enriched));
    }
    // Looser thresholds leave the solution further from full space, and enrich less.
    for w in errors.windows(2) {
        assert!(w[0].1 > w[1].1 && w[0].2 <= w[1].2, "{errors:?}");
    }
    let tightest = errors.last().unwrap().1;
    assert!(tightest < 1e-6, "{errors:?}");
    assert!(
        errors[0].1 > 1e-4,
        "the loosest model should be visibly off: {errors:?}"
    );
}

#[test]
fn a_still_body_downdates_its_whole_model() {
    let mut scene = cantilever();
    scene.gravity = [0.0; 3];
    let mut settings = AdaptiveSettings {
        linear_modes: 0,
        initial_linear_modes: 0,
        subdomain_vertices: 8,
        ..AdaptiveSettings::default()
    };
    settings.downdate = 0.1;
    scene.solver = SolverSpec::Adaptive(settings);
    let mut built = scene.build().unwrap();
    fix_model(&mut built, |p| p[0] > 1.5);
    let targets = clamp_targets(&built);
    let report = built.simulator.step(&targets).unwrap();
    let stats = report.adaptive.unwrap();
    assert!(
        stats.enriched_vertices > 0 && stats.downdated_subdomains > 0,
        "{stats:?}"
    );
    let model = built.simulator.adaptive().unwrap().model();
    assert!(model.enriched.iter().all(|&e| !e));
    // The rigid and affine blocks stay.
    assert_eq!(stats.downdated_blocks, 0, "{stats:?}");
    assert!(model.blocks.iter().all(|&b| b));
}

#[test]
fn a_model_that_does_not_fit_the_body_is_an_error() {
    let mut built = adaptive(|_| {});
    let solver = built.simulator.adaptive_mut().unwrap();
    let blocks = solver.candidates().blocks.len();
    let short = ActiveModel {
        blocks: vec![true; blocks],
        enriched: vec![false; 3],
    };
    assert!(solver.set_model(&short).unwrap_err().contains("enriched"));
    let n = built.mesh.num_vertices();
    let solver = built.simulator.adaptive_mut().unwrap();
    let wrong = ActiveModel {
        blocks: vec![true],
        enriched: vec![false; n],
    };
    assert!(solver.set_model(&wrong).unwrap_err().contains("blocks"));
}

#[test]
fn bad_adaptive_settings_name_their_field() {
    let text = format!("{CANTILEVER}\n[solver]\nkind = \"adaptive\"\nprogress = -1.0\n");
    let err = Scene::parse(&text, Path::new("cantilever.toml")).unwrap_err();
    assert!(err.to_string().contains("solver.progress"), "{err}");
    let text = format!("{CANTILEVER}\n[solver]\nkind = \"adaptive\"\nlinear_modes = 2\ninitial_linear_modes = 3\n");
    let err = Scene::parse(&text, Path::new("cantilever.toml")).unwrap_err();
    assert!(err.to_string().contains("solver.initial_linear_modes"), "{err}");
    let text = format!("{CANTILEVER}\n[solver]\nkind = \"adaptive\"\ndata_modes = 2\n");
    let err = Scene::parse(&text, Path::new("cantilever.toml")).unwrap_err();
    assert!(err.to_string().contains("solver.data_modes_from"), "{err}");
    let text = format!("{CANTILEVER}\n[solver]\nkind = \"adaptive\"\nthreshold = 1.0\n");
    let err = Scene::parse(&text, Path::new("cantilever.toml")).unwrap_err();
    assert!(err.to_string().contains("threshold"), "{err}");
}

#[test]
fn data_modes_come_from_a_directory_of_trajectories() {
    let dir = tempfile::tempdir().unwrap();
    let scene_path = dir.path().join("cantilever.toml");
    // Full space writes the training trajectory the data modes are taken from.
    let mut full = Scene::parse(CANTILEVER, &scene_path).unwrap().build().unwrap();
    let seq = full.sequence(&crate::dataset::SpeedPlan::constant(0.5), 6, 1);
    let trajectory = full.run(&seq, &crate::progress::Silent).unwrap();
    std::fs::create_dir(dir.path().join("data")).unwrap();
    trajectory.write_npz(&dir.path().join("data/train-00.npz")).unwrap();

    let text = format!(
        "{CANTILEVER}\n[solver]\nkind = \"adaptive\"\nlinear_modes = 2\ninitial_linear_modes = 2\ndata_modes = 3\ninitial_data_modes = 1\ndata_modes_from = \"data\"\n"
    );
    let mut built = Scene::parse(&text, &scene_path).unwrap().build().unwrap();
    let solver = built.simulator.adaptive().unwrap();
    let data = solver
        .candidates()
        .blocks
        .iter()
        .filter(|b| matches!(b.kind, crate::adaptive::candidates::BlockKind::DataMode(_)))
        .count();
    assert_eq!(data, 3);
    // The first data mode is the sag the trajectory holds, so it starts active.
    let targets = clamp_targets(&built);
    let report = built.simulator.step(&targets).unwrap();
    assert!(report.converged);
    assert_eq!(report.adaptive.as_ref().unwrap().active_modes, 12 + 2 + 1);

    let missing = text.replace("\"data\"", "\"nowhere\"");
    let Err(err) = Scene::parse(&missing, &scene_path).unwrap().build() else {
        panic!("a missing data directory built");
    };
    let err = err.to_string();
    assert!(
        err.contains("solver.data_modes_from") && err.contains("nowhere"),
        "{err}"
    );
}

#[test]
fn cloth_is_refused_as_not_a_solid() {
    let text = r#"
name = "sheet"
dt = 0.01
gravity = [0.0, -9.81, 0.0]

[mesh]
type = "cloth-grid"
size = [0.2, 0.2]
verts = [4, 4]

[material]
model = "stvk"
youngs = 1e5
poisson = 0.3
density = 1000.0
thickness = 0.001

[[handles]]
name = "edge"
select = { nearest = [[0.0, 0.0, 0.0]] }

[solver]
kind = "adaptive"
"#;
    let scene = Scene::parse(text, Path::new("sheet.toml")).unwrap();
    let err = scene
        .build()
        .err()
        .expect("a cloth body has no tetrahedra to adapt on")
        .to_string();
    assert!(err.contains("sheet.toml") && err.contains("solver"), "{err}");
    assert!(
        err.contains("solids only") && err.contains("has stencils of 3 vertices"),
        "{err}"
    );
}
