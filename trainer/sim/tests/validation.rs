//! Validation of the full-space simulator against analytic solutions and physical laws.

use mochi_sim::dataset::SpeedPlan;
use mochi_sim::solver::StepError;
use mochi_sim::{BuiltScene, Scene, SceneDocument};
use std::path::Path;

mod support;
use support::{build, rest_targets, static_tip_deflection};

/// A scene shipped with the trainer (its `[latent]` and `[reduced]` tables, the trainer's,
/// set aside).
fn shipped(name: &str) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../scenes/{name}.toml"));
    let text = std::fs::read_to_string(&path).unwrap();
    let mut document = SceneDocument::parse(&text, &path).unwrap();
    for trainer_table in ["latent", "reduced"] {
        document.take_section::<toml::Table>(trainer_table).unwrap();
    }
    document.into_scene().unwrap()
}

fn relative_errors(deflections: &[f64], exact: f64) -> Vec<f64> {
    deflections.iter().map(|d| (d.abs() - exact).abs() / exact).collect()
}

fn assert_converges(errors: &[f64], last_tol: f64, what: &str) {
    eprintln!("{what}: relative errors by refinement {errors:.4?}");
    for w in errors.windows(2) {
        assert!(w[1] < w[0], "{what}: error must shrink with refinement: {errors:?}");
    }
    assert!(
        *errors.last().unwrap() < last_tol,
        "{what}: finest error {errors:?} above {last_tol}"
    );
}

#[test]
fn tet_cantilever_matches_euler_bernoulli() {
    // L = 1, square section h = 0.1, nu = 0.3: tip deflection w L^4 / (8 E I) = 1.5 rho g L^4 / (E h^2).
    let (e, rho, g, h) = (1e8, 1000.0, 1.0, 0.1);
    let exact = 1.5 * rho * g / (e * h * h);
    let deflections: Vec<f64> = [[20, 2, 2], [40, 4, 4], [80, 8, 8]]
        .iter()
        .map(|cells| {
            let mut p = build(&format!(
                r#"
name = "cantilever"
gravity = [0.0, -{g}, 0.0]
[mesh]
type = "box"
min = [0.0, -0.05, -0.05]
max = [1.0, 0.05, 0.05]
cells = {cells:?}
[material]
youngs = {e}
poisson = 0.3
density = {rho}
[newton]
tolerance = 1e-7
[[handles]]
name = "clamp"
select = {{ side = {{ axis = 0, end = "min" }} }}
"#
            ));
            static_tip_deflection(&mut p, 1)
        })
        .collect();
    assert!(deflections.iter().all(|d| *d < 0.0), "the beam sags: {deflections:?}");
    assert_converges(&relative_errors(&deflections, exact), 0.10, "tet beam");
}

#[test]
fn rod_cantilever_matches_euler_bernoulli() {
    // Horizontal rod of length L, radius r: w L^4 / (8 E I) = rho g L^4 / (2 E r^2).
    let (e, rho, g, r, len): (f64, f64, f64, f64, f64) = (1e9, 1000.0, 1.0, 1e-3, 0.2);
    let exact = rho * g * len.powi(4) / (2.0 * e * r * r);
    let deflections: Vec<f64> = [6, 11, 21, 41]
        .iter()
        .map(|verts| {
            let mut p = build(&format!(
                r#"
name = "rod-cantilever"
gravity = [0.0, -{g}, 0.0]
[mesh]
type = "rods"
count = 1
verts_per_rod = {verts}
length = {len}
spacing = 0.01
direction = [1.0, 0.0, 0.0]
[material]
youngs = {e}
poisson = 0.3
density = {rho}
radius = {r}
[newton]
tolerance = 1e-7
[[handles]]
name = "root"
select = {{ rod-roots = 2 }}
"#
            ));
            static_tip_deflection(&mut p, 1)
        })
        .collect();
    assert_converges(&relative_errors(&deflections, exact), 0.10, "rod");
}

#[test]
fn cloth_strip_matches_plate_bending_stiffness() {
    // Tip deflection w L^4 / (8 D b) with the plate stiffness D = E t^3 / (12 (1 - nu^2)).
    // The hinge model has no Poisson coupling between bending directions (its stiffness is
    // calibrated to D on cylinders), so the strip bends with D whatever its width.
    let (e, nu, rho, g, t, len, width): (f64, f64, f64, f64, f64, f64, f64) = (1e7, 0.3, 1000.0, 1e-4, 1e-4, 0.2, 0.05);
    let d = e * t.powi(3) / (12.0 * (1.0 - nu * nu));
    let exact = rho * t * g * len.powi(4) / (8.0 * d);
    let deflections: Vec<f64> = [(11, 11), (21, 21), (41, 41)]
        .iter()
        .map(|&(nx, ny)| {
            let dx = len / (nx - 1) as f64;
            let mut p = build(&format!(
                r#"
name = "strip"
gravity = [0.0, -{g}, 0.0]
[mesh]
type = "cloth-grid"
size = [{len}, {width}]
verts = [{nx}, {ny}]
axes = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
[material]
model = "stvk"
youngs = {e}
poisson = {nu}
density = {rho}
thickness = {t}
[newton]
tolerance = 1e-7
[[handles]]
name = "clamp"
select = {{ box = {{ min = [-1.0, -1.0, -1.0], max = [{}, 1.0, 1.0] }} }}
"#,
                dx * 1.01
            ));
            static_tip_deflection(&mut p, 1)
        })
        .collect();
    eprintln!("cloth strip deflections {deflections:?}, Kirchhoff plate {exact}");
    assert_converges(&relative_errors(&deflections, exact), 0.15, "cloth strip");
}

const BEAM: &str = include_str!("fixtures/vibrating-beam.toml");

/// Bends the beam with a tip load, then releases it: returns the problem in the bent
/// static state with the load removed.
fn released_beam(integrator: &str) -> BuiltScene {
    let loaded =
        format!("{BEAM}\n[[loads]]\nselect = {{ side = {{ axis = 0, end = \"max\" }} }}\nforce = [0.0, -20.0, 0.0]\n");
    let mut bent = build(&loaded);
    static_tip_deflection(&mut bent, 1);
    let mut free = build(&BEAM.replace(
        "name = \"vibrating-beam\"",
        &format!("name = \"vibrating-beam\"\nintegrator = \"{integrator}\""),
    ));
    free.simulator.reset(bent.simulator.positions());
    free
}

fn vibrate(problem: &mut BuiltScene, frames: usize) -> Vec<f64> {
    let targets = rest_targets(problem);
    let mut energies = vec![problem.simulator.total_energy()];
    for _ in 0..frames {
        problem.simulator.step(&targets).expect("step");
        energies.push(problem.simulator.total_energy());
    }
    energies
}

#[test]
fn implicit_euler_never_gains_energy_in_free_vibration() {
    let mut beam = released_beam("implicit-euler");
    let energies = vibrate(&mut beam, 60);
    assert!(energies[0] > 0.0);
    for (k, w) in energies.windows(2).enumerate() {
        assert!(
            w[1] <= w[0] * (1.0 + 1e-9),
            "energy grew at step {k}: {} -> {}",
            w[0],
            w[1]
        );
    }
    assert!(energies[60] < energies[0], "implicit Euler dissipates");
}

#[test]
fn restart_mid_motion_continues_the_implicit_euler_run_exactly() {
    // One run of 10 steps, and a second simulator restarted from the first's frames 4
    // and 5 (positions and velocity), then stepped 5 times: the same frame 10.
    let mut beam = released_beam("implicit-euler");
    let mut frames = vec![beam.simulator.positions().to_vec()];
    for _ in 0..10 {
        vibrate(&mut beam, 1);
        frames.push(beam.simulator.positions().to_vec());
    }
    let mut restarted = released_beam("implicit-euler");
    restarted.simulator.restart(&frames[5], &frames[4]);
    assert_eq!(
        restarted.simulator.velocities(),
        beam_velocity(&frames[5], &frames[4], restarted.simulator.dt())
    );
    vibrate(&mut restarted, 5);
    let gap = max_distance(restarted.simulator.positions(), &frames[10]);
    assert!(gap < 1e-12, "restarted run is {gap:e} off");
    // A restart at rest (the two frames equal) is not the continuation.
    let mut at_rest = released_beam("implicit-euler");
    at_rest.simulator.restart(&frames[5], &frames[5]);
    vibrate(&mut at_rest, 5);
    assert!(max_distance(at_rest.simulator.positions(), &frames[10]) > 1e-4);
}

fn max_distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

fn beam_velocity(x: &[f64], x_prev: &[f64], dt: f64) -> Vec<f64> {
    x.iter().zip(x_prev).map(|(a, b)| (a - b) / dt).collect()
}

#[test]
fn a_quasi_static_step_is_the_static_equilibrium_of_its_targets() {
    // Released from the bent state, a quasi-static step lands on the unloaded equilibrium
    // (the rest shape, as gravity is off) at once, where implicit Euler starts to swing;
    // the velocity is the difference of the two equilibria over dt.
    let mut quasi = released_beam("quasi-static");
    let bent = quasi.simulator.positions().to_vec();
    let rest = quasi.mesh.rest.clone();
    assert!(max_distance(&bent, &rest) > 1e-3, "the beam starts bent");
    vibrate(&mut quasi, 1);
    let x = quasi.simulator.positions().to_vec();
    assert!(
        max_distance(&x, &rest) < 1e-6,
        "{:e} from rest",
        max_distance(&x, &rest)
    );
    let v = beam_velocity(&x, &bent, quasi.simulator.dt());
    assert!(max_distance(quasi.simulator.velocities(), &v) < 1e-12);
    vibrate(&mut quasi, 1);
    assert!(
        max_distance(quasi.simulator.positions(), &rest) < 1e-6,
        "and stays there"
    );
    let mut euler = released_beam("implicit-euler");
    vibrate(&mut euler, 1);
    assert!(max_distance(euler.simulator.positions(), &rest) > 1e-4);
}

#[test]
fn bdf2_dissipates_less_than_implicit_euler() {
    let ie = vibrate(&mut released_beam("implicit-euler"), 30);
    let bdf2 = vibrate(&mut released_beam("bdf2"), 30);
    eprintln!(
        "energy after 30 steps: implicit Euler {:.4e}, BDF2 {:.4e} (start {:.4e})",
        ie[30], bdf2[30], ie[0]
    );
    assert!(bdf2[30] > ie[30], "BDF2 keeps more energy than implicit Euler");
    assert!(bdf2[30] < bdf2[0] * 1.01, "BDF2 does not blow up");
}

#[test]
fn newton_converges_superlinearly() {
    let scene = shipped("beam");
    let mut problem = scene.build().unwrap();
    problem.simulator = {
        // Tighter tolerance so the tail of the iteration is visible.
        let mut s = scene.clone();
        s.newton.tolerance = 1e-7;
        s.build().unwrap().simulator
    };
    let seq = problem.sequence(&SpeedPlan::constant(1.0), 12, 11);
    let dim = problem.mesh.dim;
    let mut best: Option<Vec<f64>> = None;
    for frame in 1..=12 {
        let report = problem
            .simulator
            .step(&seq.targets(&problem.handles, frame, dim))
            .unwrap();
        assert!(report.converged, "frame {frame}: {:?}", report.step_norms);
        if report.step_norms.len() >= 4 && best.as_ref().is_none_or(|b| report.step_norms.len() > b.len()) {
            best = Some(report.step_norms.clone());
        }
    }
    let norms = best.expect("some step takes at least 4 Newton iterations");
    eprintln!("Newton step norms: {norms:?}");
    // The last norm met the tolerance; the three before it show the rate. For order p,
    // e_{k+1} ~ e_k^p, so log(e2/e1) / log(e1/e0) estimates p: above 1 is superlinear.
    let n = norms.len();
    let (e0, e1, e2) = (norms[n - 4], norms[n - 3], norms[n - 2]);
    let order = (e2 / e1).ln() / (e1 / e0).ln();
    assert!(order > 1.1, "convergence order {order:.2} from {norms:?}");
    assert!(e2 / e1 < 0.05, "fast contraction near the solution: {norms:?}");
}

#[test]
fn nan_boundary_conditions_are_refused_without_losing_the_state() {
    let mut problem = build(BEAM);
    let dim = problem.mesh.dim;
    let mut targets: Vec<f64> = problem.handles[0]
        .reference
        .iter()
        .flat_map(|p| p[..dim].to_vec())
        .collect();
    problem.simulator.step(&targets).unwrap();
    let before = problem.simulator.positions().to_vec();
    targets[4] = f64::NAN;
    let err = problem.simulator.step(&targets).unwrap_err();
    assert!(matches!(err, StepError::NonFiniteBoundary { .. }), "{err}");
    assert_eq!(problem.simulator.positions(), &before[..]);
    let err = problem.simulator.step(&targets[1..]).unwrap_err();
    assert!(matches!(err, StepError::BoundaryLength { .. }), "{err}");
}

#[test]
fn stiffer_region_reduces_deflection_and_a_neutral_region_changes_nothing() {
    let loaded = BEAM.replace(
        "name = \"vibrating-beam\"",
        "name = \"beam\"\ngravity = [0.0, -1.0, 0.0]",
    );
    // A region covering the root half of the beam (x <= 0.5).
    let region = |youngs: f64| {
        loaded.replace(
            "density = 1000.0",
            &format!("density = 1000.0\n[[material.regions]]\nbox = {{ min = [-1.0, -1.0, -1.0], max = [0.5, 1.0, 1.0] }}\nyoungs = {youngs:e}"),
        )
    };
    let homogeneous = static_tip_deflection(&mut build(&loaded), 1);
    let neutral = static_tip_deflection(&mut build(&region(1e6)), 1);
    let stiff = static_tip_deflection(&mut build(&region(1e7)), 1);
    assert!(
        (neutral - homogeneous).abs() <= 1e-9 * homogeneous.abs(),
        "{neutral} vs {homogeneous}"
    );
    // Euler-Bernoulli under a uniform load: the root half contributes 15/16 of the tip
    // deflection, so making it 10x stiffer leaves 15/160 + 1/16 = 0.156 of it.
    let ratio = stiff / homogeneous;
    assert!((ratio - 0.156).abs() < 0.05, "deflection ratio {ratio}");
}

#[test]
fn falling_block_comes_to_rest_on_a_plane_obstacle() {
    let mut p = build(include_str!("fixtures/falling-block.toml"));
    let dim = 3;
    let mut min_y = f64::INFINITY;
    for _ in 0..45 {
        let report = p.simulator.step(&[]).expect("step");
        assert!(report.converged);
        let x = p.simulator.positions();
        min_y = min_y.min((0..x.len() / dim).map(|v| x[v * dim + 1]).fold(f64::INFINITY, f64::min));
    }
    // Never sinks noticeably into the plane, and ends at rest on it (within the margin).
    assert!(min_y > -0.01, "penetration {min_y}");
    let x = p.simulator.positions();
    let bottom = (0..x.len() / dim).map(|v| x[v * dim + 1]).fold(f64::INFINITY, f64::min);
    assert!(bottom < 0.005 && bottom > -0.005, "resting on the plane: {bottom}");
    let speed = p.simulator.velocities().iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(speed < 0.05, "comes to rest: {speed}");
}
