//! Scenes with IPC contact: the `[contact]` table's errors, and every shipped contact scene
//! (drop, thrown ball, two bodies, stomp, twisted strip) stepped with every frame checked
//! (converged, intersection-free, no inverted tet) and its own outcome asserted; the larger
//! shipped sizes run as ignored tests.

use crate::contact::intersection::has_intersections;
use crate::energy::tet::signed_volume;
use crate::mesh::Elements;
use crate::scene::{MeshSpec, Scene};
use crate::solver::{Simulator, StepReport};
use std::path::Path;

/// The shipped scene `name` (`trainer/scenes/NAME.toml`), with every box of its mesh (or
/// of its parts) at `cells` cells when given.
fn shipped(name: &str, cells: Option<[usize; 3]>) -> Scene {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("../scenes/{name}.toml"));
    let mut scene = Scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
    if let Some(cells) = cells {
        let boxes: Vec<&mut MeshSpec> = match &mut scene.mesh {
            MeshSpec::Parts { parts } => parts.iter_mut().collect(),
            one => vec![one],
        };
        for spec in boxes {
            if let MeshSpec::Box { cells: c, .. } = spec {
                *c = cells;
            }
        }
    }
    scene
}

/// Steps once to `targets`, asserting the solve converged, no part of the contact surface
/// intersects another (exact check) and no tet inverted.
fn step_checked(sim: &mut Simulator, targets: &[f64], tets: &[[usize; 4]], frame: usize) -> StepReport {
    let report = sim.step(targets).unwrap_or_else(|e| panic!("frame {frame}: {e}"));
    assert!(report.converged, "frame {frame}: Newton did not converge: {report:?}");
    let (surface, ext) = sim.contact_state().expect("a contact scene");
    assert!(!has_intersections(surface, &ext), "frame {frame} intersects");
    let x = sim.positions();
    for t in tets {
        let p = t.map(|v| [x[3 * v], x[3 * v + 1], x[3 * v + 2]]);
        assert!(signed_volume(p) > 0.0, "frame {frame}: inverted element {t:?}");
    }
    report
}

/// The tets of a tet body.
fn tets_of(scene: &crate::scene::BuiltScene) -> Vec<[usize; 4]> {
    let Elements::Tets(tets) = &scene.mesh.elements else {
        panic!("a tet body")
    };
    tets.clone()
}

#[test]
fn a_small_drop_never_intersects_never_inverts_converges_and_comes_to_rest() {
    check_drop(&shipped("ball-drop", Some([2, 2, 2])), 90);
}

/// The full shipped scene for `mochi simulate`'s 300 frames (seconds in an optimised build;
/// `cargo test -p mochi-sim -- --ignored shipped_drop`).
#[test]
#[ignore]
fn the_shipped_drop_runs_300_frames_intersection_free_and_comes_to_rest() {
    check_drop(&shipped("ball-drop", None), 300);
}

/// Drops the scene's body for `frames` frames: asserts every step converged, no frame
/// intersects (exact check), no element inverts, the body stays above the ground and ends
/// at rest on it.
fn check_drop(scene: &Scene, frames: usize) {
    let mut problem = scene.build().unwrap_or_else(|e| panic!("{e}"));
    let tets = tets_of(&problem);
    let height = ground_height(scene);
    let sim = &mut problem.simulator;
    let mut speeds = Vec::new();
    let (mut iterations, mut most_iterations, mut seconds) = (0, 0, 0.0);
    let centroid_x = |x: &[f64]| x.chunks(3).map(|p| p[0]).sum::<f64>() / (x.len() / 3) as f64;
    let x_start = centroid_x(sim.positions());
    for frame in 1..=frames {
        let report = step_checked(sim, &[], &tets, frame);
        iterations += report.iterations;
        most_iterations = most_iterations.max(report.iterations);
        seconds += report.seconds;
        let x = sim.positions();
        let lowest = x.chunks(3).map(&height).fold(f64::INFINITY, f64::min);
        assert!(lowest > 0.0, "frame {frame}: below the ground");
        speeds.push(
            sim.velocities()
                .chunks(3)
                .map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt())
                .fold(0.0, f64::max),
        );
    }
    // It reached the ground (the fall is 5 cm) and rests there.
    let x = sim.positions();
    let lowest = x.chunks(3).map(&height).fold(f64::INFINITY, f64::min);
    assert!(
        lowest < 2.0 * scene.contact.as_ref().unwrap().dhat,
        "rests {lowest} above the ground"
    );
    let peak = speeds.iter().copied().fold(0.0, f64::max);
    let last = speeds[frames - 10..].iter().copied().fold(0.0, f64::max);
    println!(
        "{}: {frames} frames, {:.2} ms/step, Newton iterations {:.2}/step (max {most_iterations}), \
         peak speed {peak:.3} m/s, last 10 frames <= {last:.2e} m/s, rests {lowest:.2e} m over the ground, \
         centroid moved {:.4} m along x, kappa {:.3e}",
        scene.name,
        1e3 * seconds / frames as f64,
        iterations as f64 / frames as f64,
        centroid_x(x) - x_start,
        sim.contact_stiffness()
    );
    assert!(peak > 0.5, "peak speed {peak}");
    assert!(last < 1e-2, "still moving at {last} m/s over the last 10 frames");
}

/// The signed height of a point over the top face of the scene's first obstacle (a box).
fn ground_height(scene: &Scene) -> impl Fn(&[f64]) -> f64 {
    let crate::scene::ObstacleMesh::Box { min, max, rotation, .. } = scene.contact.as_ref().unwrap().obstacles[0]
    else {
        panic!("a box ground")
    };
    let rot = nalgebra::Rotation3::new(nalgebra::Vector3::from(rotation.unwrap_or_default()));
    let centre = nalgebra::Vector3::from([0, 1, 2].map(|i| 0.5 * (min[i] + max[i])));
    let normal = rot * nalgebra::Vector3::y();
    let top = centre + normal * (0.5 * (max[1] - min[1]));
    move |p: &[f64]| normal.dot(&(nalgebra::Vector3::new(p[0], p[1], p[2]) - top))
}

#[test]
fn without_friction_the_body_slides_down_the_tilted_ground() {
    let mut scene = shipped("ball-drop", Some([2, 2, 2]));
    scene.contact.as_mut().unwrap().friction = 0.0;
    let mut problem = scene.build().unwrap();
    let sim = &mut problem.simulator;
    for frame in 1..=60 {
        sim.step(&[]).unwrap_or_else(|e| panic!("frame {frame}: {e}"));
        let (surface, ext) = sim.contact_state().unwrap();
        assert!(!has_intersections(surface, &ext), "frame {frame} intersects");
    }
    let speed = sim.velocities().chunks(3).map(|v| v[0].hypot(v[1])).fold(0.0, f64::max);
    assert!(speed > 0.3, "frictionless, it still moves at only {speed} m/s");
}

#[test]
fn the_shipped_drop_scene_builds_with_contact() {
    let scene = shipped("ball-drop", None);
    let c = scene.contact.as_ref().expect("a [contact] table");
    assert!(c.friction > 0.0 && !c.obstacles.is_empty());
    let problem = scene.build().unwrap_or_else(|e| panic!("{e}"));
    let (surface, ext) = problem.simulator.contact_state().unwrap();
    assert!(!has_intersections(surface, &ext));
    assert_eq!(
        ext.len(),
        problem.mesh.rest.len() + 3 * 8,
        "the body and the ground's 8 corners"
    );
}

#[test]
fn contact_table_defaults_and_errors_name_the_file_and_field() {
    let plain = r#"
name = "plain"
[mesh]
type = "box"
min = [0.0, 0.0, 0.0]
max = [1.0, 1.0, 1.0]
cells = [1, 1, 1]
[material]
youngs = 1e5
poisson = 0.4
density = 1000.0
"#;
    let with = |table: &str| format!("{plain}\n{table}\n");
    let defaults = Scene::parse(&with("[contact]"), Path::new("d.toml")).unwrap();
    let c = defaults.contact.unwrap();
    assert_eq!((c.dhat, c.friction, c.epsv, c.self_contact), (1e-3, 0.0, 1e-3, false));
    assert!(Scene::parse(plain, Path::new("d.toml")).unwrap().contact.is_none());
    for (table, field) in [
        ("[contact]\ndhat = -1.0", "contact.dhat"),
        ("[contact]\nfriction = -0.5", "contact.friction"),
        ("[contact]\nepsv = 0.0", "contact.epsv"),
        (
            "[contact]\n[[contact.obstacles]]\ntype = \"box\"\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, -1.0, 1.0]",
            "contact.obstacles[0].max",
        ),
        (
            "[contact]\n[[contact.obstacles]]\ntype = \"file\"\npath = \"g.obj\"\nscale = 0.0",
            "contact.obstacles[0].scale",
        ),
        (
            "[contact]\n[[contact.obstacles]]\ntype = \"box\"\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\n\
             keyframes = [[1.0, 0.0, 0.0, 0.0], [0.5, 0.0, 1.0, 0.0]]",
            "contact.obstacles[0].keyframes",
        ),
        (
            "[contact]\n[[contact.obstacles]]\ntype = \"box\"\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\n\
             keyframes = [[0.0, 0.0, nan, 0.0]]",
            "contact.obstacles[0].keyframes",
        ),
    ] {
        let err = Scene::parse(&with(table), Path::new("bad-contact.toml")).unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("bad-contact.toml") && msg.contains(field),
            "{table}: {msg}"
        );
    }
    let err = Scene::parse(&with("[contact]\nself_contact = true"), Path::new("bad-contact.toml")).unwrap_err();
    assert!(err.to_string().contains("bad-contact.toml"), "{err}");
    // A part's errors name the part.
    let parts = plain.replace(
        "type = \"box\"\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\ncells = [1, 1, 1]",
        "type = \"parts\"\nparts = [{ type = \"box\", min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0], cells = [1, 1, 1] }, \
         { type = \"file\", path = \"p.obj\", kind = \"hair\" }]",
    );
    assert!(parts.contains("parts = ["));
    let err = Scene::parse(&parts, Path::new("parts.toml"))
        .and_then(|s| s.build().map(|_| s))
        .unwrap_err();
    assert!(err.to_string().contains("mesh.parts[1].kind"), "{err}");
}

#[test]
fn an_obstacle_file_with_a_zero_area_face_is_refused_naming_the_file_and_face() {
    // Degenerate faces are refused at load (the body's and the obstacles' alike); faces that
    // collapse during a step are contact primitives like any other (their closest edges).
    let dir = tempfile::tempdir().unwrap();
    let obj = "v 0 0 0\nv 1 0 0\nv 0 0 1\nv 2 0 0\nf 1 2 3\nf 1 2 4\n";
    std::fs::write(dir.path().join("sliver.obj"), obj).unwrap();
    let text = r#"
name = "sliver"
[mesh]
type = "box"
min = [0.0, 0.1, 0.0]
max = [0.2, 0.3, 0.2]
cells = [1, 1, 1]
[material]
youngs = 1e5
poisson = 0.4
density = 1000.0
[contact]
[[contact.obstacles]]
type = "file"
path = "sliver.obj"
"#;
    let scene_file = dir.path().join("sliver.toml");
    let err = Scene::parse(text, &scene_file)
        .and_then(|s| s.build().map(|_| s))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("sliver.obj") && err.contains('6') && err.contains("triangle is degenerate"),
        "{err}"
    );
}

#[test]
fn two_small_cubes_collide_and_stack_without_intersecting() {
    check_stack(&shipped("two-cubes", Some([2, 2, 2])), 60);
}

/// The full shipped scene for `mochi simulate`'s 300 frames (an optimised build:
/// `cargo test -p mochi-sim --release -- --ignored shipped_two_cubes`).
#[test]
#[ignore]
fn the_shipped_two_cubes_run_300_frames_intersection_free_and_stack() {
    check_stack(&shipped("two-cubes", None), 300);
}

/// Steps the two-body scene for `frames` frames: every step converges, no frame
/// intersects, no element inverts; the upper cube lands on the lower one (it ends within a
/// few `dhat` of it, having fallen) and the lower one stays on the ground.
fn check_stack(scene: &Scene, frames: usize) {
    let mut problem = scene.build().unwrap_or_else(|e| panic!("{e}"));
    let tets = tets_of(&problem);
    let half = problem.mesh.num_vertices() / 2;
    let dhat = scene.contact.as_ref().unwrap().dhat;
    let sim = &mut problem.simulator;
    let (mut iterations, mut seconds, mut most_pairs) = (0, 0.0, 0);
    for frame in 1..=frames {
        let report = step_checked(sim, &[], &tets, frame);
        iterations += report.iterations;
        seconds += report.seconds;
        most_pairs = most_pairs.max(report.contact_pairs);
    }
    let x = sim.positions();
    let heights = |range: std::ops::Range<usize>| {
        let ys: Vec<f64> = range.map(|v| x[3 * v + 1]).collect();
        let lo = ys.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = ys.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (lo, hi)
    };
    let (lower_bottom, lower_top) = heights(0..half);
    let (upper_bottom, _) = heights(half..2 * half);
    println!(
        "{}: {frames} frames, {:.2} ms/step, Newton iterations {:.2}/step, up to {most_pairs} contact pairs, \
         lower cube {lower_bottom:.2e}..{lower_top:.4} m, upper cube from {upper_bottom:.4} m",
        scene.name,
        1e3 * seconds / frames as f64,
        iterations as f64 / frames as f64,
    );
    assert!(
        lower_bottom > 0.0 && lower_bottom < 2.0 * dhat,
        "lower cube over the ground: {lower_bottom}"
    );
    // The upper cube's lowest vertex sits on the lower cube's top (its corners may hang
    // past the edge, so the gap is measured between the faces' heights).
    let gap = upper_bottom - lower_top;
    assert!(
        gap > -0.02 && gap < 0.01,
        "upper cube {upper_bottom} over the lower top {lower_top}"
    );
}

#[test]
fn a_descending_box_squashes_a_small_beam_without_intersecting() {
    check_stomp(&keyframed_stomp(Some([8, 2, 2])), 100);
}

/// The full keyframed stomp for 300 frames (an optimised build:
/// `cargo test -p mochi-sim --release -- --ignored keyframed_stomp`).
#[test]
#[ignore]
fn the_keyframed_stomp_runs_300_frames_intersection_free_and_the_beam_recovers() {
    check_stomp(&keyframed_stomp(None), 300);
}

/// The stomp whose box is a keyframed obstacle (descends 5.5 cm from 0.5 s to 3 s, holds,
/// lifts off by 7.5 s).
fn keyframed_stomp(cells: Option<[usize; 3]>) -> Scene {
    shipped("stomp-keyframed", cells)
}

/// Steps the stomp for `frames` frames: every step converges, no frame intersects (the
/// moving box included), no element inverts, the beam stays on the ground; while the box is
/// down (frames 90 to 150) the beam under it is squashed to the box's bottom, and once the
/// box has lifted off (from frame 225) the beam springs back to most of its height.
fn check_stomp(scene: &Scene, frames: usize) {
    let mut problem = scene.build().unwrap_or_else(|e| panic!("{e}"));
    let tets = tets_of(&problem);
    let rest_top = problem
        .mesh
        .rest
        .chunks(3)
        .map(|p| p[1])
        .fold(f64::NEG_INFINITY, f64::max);
    let dhat = scene.contact.as_ref().unwrap().dhat;
    let box_bottom_down = 0.09 - 0.055;
    let sim = &mut problem.simulator;
    let (mut iterations, mut seconds, mut most_pairs, mut squashed) = (0, 0.0, 0, f64::INFINITY);
    let under_box_top = |x: &[f64]| {
        x.chunks(3)
            .filter(|p| p[0].abs() < 0.05)
            .map(|p| p[1])
            .fold(f64::NEG_INFINITY, f64::max)
    };
    for frame in 1..=frames {
        let report = step_checked(sim, &[], &tets, frame);
        iterations += report.iterations;
        seconds += report.seconds;
        most_pairs = most_pairs.max(report.contact_pairs);
        let x = sim.positions();
        let lowest = x.chunks(3).map(|p| p[1]).fold(f64::INFINITY, f64::min);
        assert!(lowest > 0.0, "frame {frame}: below the ground");
        if (90..=150).contains(&frame) {
            let top = under_box_top(x);
            assert!(
                top < box_bottom_down + 2.0 * dhat,
                "frame {frame}: the beam under the box reaches {top}"
            );
            squashed = squashed.min(top);
        }
    }
    let top = under_box_top(sim.positions());
    println!(
        "{}: {frames} frames, {:.2} ms/step, Newton iterations {:.2}/step, up to {most_pairs} contact pairs, \
         squashed to {squashed:.4} m (rest top {rest_top:.4} m), top at the end {top:.4} m",
        scene.name,
        1e3 * seconds / frames as f64,
        iterations as f64 / frames as f64,
    );
    if frames >= 225 {
        assert!(top > 0.9 * rest_top, "the beam stays squashed: {top} of {rest_top}");
    }
}

#[test]
fn a_coarse_twisted_strip_coils_into_self_contact_without_intersecting() {
    check_coil(&shipped("twisted-strip", Some([20, 2, 1])), 300);
}

/// The full shipped scene for `mochi simulate`'s 300 frames (an optimised build:
/// `cargo test -p mochi-sim --release -- --ignored shipped_twisted_strip`).
#[test]
#[ignore]
fn the_shipped_twisted_strip_coils_300_frames_intersection_free() {
    check_coil(&shipped("twisted-strip", None), 300);
}

/// Twists the strip for `frames` frames: every step converges, no frame intersects, no
/// element inverts, and the strip comes within `dhat` of itself (the barrier turns
/// positive) once the twist has coiled it.
fn check_coil(scene: &Scene, frames: usize) {
    let mut problem = scene.build().unwrap_or_else(|e| panic!("{e}"));
    let tets = tets_of(&problem);
    let seq = problem.sequence(&crate::dataset::SpeedPlan::constant(1.0), frames, 1);
    let (mut iterations, mut seconds, mut most_pairs, mut first_contact) = (0, 0.0, 0, None);
    for frame in 1..=frames {
        let targets = seq.targets(&problem.handles, frame, 3);
        let sim = &mut problem.simulator;
        let report = step_checked(sim, &targets, &tets, frame);
        iterations += report.iterations;
        seconds += report.seconds;
        most_pairs = most_pairs.max(report.contact_pairs);
        // The barrier is positive only where two parts of the surface are within `dhat`.
        let barrier = sim
            .energies()
            .iter()
            .find(|(n, _)| *n == "contact barrier")
            .map_or(0.0, |e| e.1);
        if barrier > 0.0 && first_contact.is_none() {
            first_contact = Some(frame);
        }
    }
    println!(
        "{}: {frames} frames, {:.2} ms/step, Newton iterations {:.2}/step, self-contact from frame {first_contact:?}, \
         up to {most_pairs} candidate pairs",
        scene.name,
        1e3 * seconds / frames as f64,
        iterations as f64 / frames as f64,
    );
    assert!(first_contact.is_some(), "the strip never came within dhat of itself");
}

#[test]
fn the_shipped_ball_bounces_rolls_and_comes_to_rest_without_intersecting() {
    check_bounce(&shipped("ball-bounce", None), 300);
}

/// Throws the ball for `frames` frames: every step converges, no frame intersects, no
/// element inverts, no vertex goes below the ground; after landing the ball bounces (its
/// centre rises), rolls (a surface vertex turns about the centre by more than half a
/// turn), and comes to rest: its kinetic energy over the last 10 frames is below 1e-6 of the
/// peak.
fn check_bounce(scene: &Scene, frames: usize) {
    let mut problem = scene.build().unwrap_or_else(|e| panic!("{e}"));
    let tets = tets_of(&problem);
    let dt = scene.dt;
    let v0 = scene.initial_velocity.expect("thrown");
    let sim = &mut problem.simulator;
    let rest = problem.mesh.rest.clone();
    let back: Vec<f64> = rest.iter().enumerate().map(|(k, c)| c - dt * v0[k % 3]).collect();
    sim.restart(&rest, &back);
    let masses = sim.masses().to_vec();
    let centre = |x: &[f64]| {
        let n = (x.len() / 3) as f64;
        [0, 1, 2].map(|i| x.chunks(3).map(|p| p[i]).sum::<f64>() / n)
    };
    // A surface vertex's angle about the centre in the x-y plane (the ball rolls along x).
    let marker = problem.mesh.surface_vertices()[0];
    let angle = |x: &[f64]| {
        let c = centre(x);
        (x[3 * marker + 1] - c[1]).atan2(x[3 * marker] - c[0])
    };
    let (mut landed, mut rose, mut turned, mut kinetic) = (None, 0.0f64, 0.0, Vec::new());
    for frame in 1..=frames {
        let before = sim.positions().to_vec();
        step_checked(sim, &[], &tets, frame);
        let x = sim.positions();
        let lowest = x.chunks(3).map(|p| p[1]).fold(f64::INFINITY, f64::min);
        assert!(lowest > 0.0, "frame {frame}: below the ground");
        if landed.is_none() && lowest < 2.0 * scene.contact.as_ref().unwrap().dhat {
            landed = Some(frame);
        }
        if landed.is_some() {
            rose = rose.max((centre(x)[1] - centre(&before)[1]) / dt);
        }
        let d = angle(x) - angle(&before);
        turned += (d + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI;
        kinetic.push(
            0.5 * x
                .iter()
                .zip(&before)
                .enumerate()
                .map(|(k, (a, b))| masses[k / 3] * ((a - b) / dt).powi(2))
                .sum::<f64>(),
        );
    }
    let peak = kinetic.iter().copied().fold(0.0, f64::max);
    let last = kinetic[frames - 10..].iter().copied().fold(0.0, f64::max);
    println!(
        "{}: landed at frame {landed:?}, centre rose at up to {rose:.3} m/s after landing, turned {turned:.2} rad, \
         travelled {:.3} m, kinetic energy over the last 10 frames <= {:.2e} of the peak",
        scene.name,
        centre(sim.positions())[0] - centre(&rest)[0],
        last / peak
    );
    assert!(landed.is_some(), "never reached the ground");
    assert!(rose > 0.05, "no bounce: the centre rose at {rose} m/s at most");
    assert!(turned.abs() > std::f64::consts::PI, "rolled only {turned} rad");
    assert!(last < 1e-6 * peak, "still moving: {last} of {peak}");
}
