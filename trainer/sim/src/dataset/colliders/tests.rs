//! Collider paths and datasets with colliders: paths start outside the body at the
//! sequence's speed and are seeded; a dataset with a collider is the same bytes from the
//! same seed, records the collider, and no vertex enters it.

use crate::dataset::{self, plan, sequence_path, SpeedPlan};
use crate::scene::{BuiltScene, Scene};
use crate::trajectory::Trajectory;
use crate::Silent;
use std::path::Path;

/// The scene `text` (read as the file `file`), built.
fn built(text: &str, file: &str) -> BuiltScene {
    Scene::parse(text, Path::new(file))
        .and_then(|s| s.build())
        .unwrap_or_else(|e| panic!("{e}"))
}

/// A 0.1 m soft cube (2 x 2 x 2 cells) held at its base, and a sphere that pokes it.
fn poked_cube() -> BuiltScene {
    built(POKED_CUBE, "poked-cube.toml")
}

/// The scene text of [`poked_cube`].
const POKED_CUBE: &str = r#"
name = "poked-cube"
dt = 0.02
gravity = [0.0, -9.81, 0.0]
[mesh]
type = "box"
min = [0.0, 0.0, 0.0]
max = [0.1, 0.1, 0.1]
cells = [2, 2, 2]
[material]
youngs = 1e5
poisson = 0.4
density = 1000.0
[contact]
dhat = 1e-3
[[handles]]
name = "base"
select = { side = { axis = 1, end = "min" } }
[[colliders]]
name = "ball"
shape = "sphere"
radius = 0.03
[colliders.motion]
speed = [0.3, 0.6]
region = { min = [0.03, 0.11, 0.03], max = [0.07, 0.12, 0.07] }
directions = [[0.0, -1.0, 0.0]]
clearance = 0.005
[[colliders]]
name = "parked"
shape = "box"
half_extents = [0.01, 0.02, 0.03]
[dataset]
train = 1
test = 0
validation = 0
frames = 12
"#;

#[test]
fn collider_paths_start_outside_the_body_at_the_sequence_speed_and_are_seeded() {
    let problem = poked_cube();
    let speeds = SpeedPlan::constant(1.0);
    let a = problem.sequence(&speeds, 30, 7);
    assert_eq!(a, problem.sequence(&speeds, 30, 7));
    assert_ne!(a.colliders, problem.sequence(&speeds, 30, 8).colliders);
    let ball = &a.colliders[0];
    assert_eq!(ball.poses.len(), 31);
    // The start lies above the body's box grown by the radius and the clearance.
    assert!(
        ball.poses[0].center.y >= 0.1 + 0.03 + 0.005 - 1e-12,
        "{:?}",
        ball.poses[0]
    );
    // No frame moves faster than the top speed (0.6 m/s), and it reaches an aim point.
    for (w, v) in ball.poses.windows(2).zip(&ball.velocities[1..]) {
        let step = (w[1].center - w[0].center).norm();
        assert!(step <= 0.6 * 0.02 + 1e-12, "step {step}");
        assert!((v[1] * 0.02 - (w[1].center.y - w[0].center.y)).abs() < 1e-12);
    }
    assert!(ball.poses.iter().any(|p| p.center.y <= 0.12 + 1e-12));
    // With `approach = 0` the path starts where the grown sphere leaves the body's box:
    // the same aim points and speeds, its first pose at 0.1 + 0.03 + 0.005 exactly.
    let near = built(
        &POKED_CUBE.replace("clearance = 0.005\n", "clearance = 0.005\napproach = 0.0\n"),
        "poked-cube.toml",
    );
    let b = near.sequence(&speeds, 30, 7);
    assert!(
        (b.colliders[0].poses[0].center.y - 0.135).abs() < 1e-12,
        "{:?}",
        b.colliders[0].poses[0]
    );
    assert!((ball.poses[0].center.y - 0.17).abs() < 1e-12, "{:?}", ball.poses[0]);
    // It reaches the aim height sooner, by the 0.035 m it no longer travels.
    let arrival = |s: &crate::bc::BcSequence| {
        let at = s.colliders[0].poses.iter().position(|p| p.center.y <= 0.12 + 1e-12);
        at.expect("the ball reaches its aim height")
    };
    assert!(arrival(&b) < arrival(&a), "{} {}", arrival(&b), arrival(&a));
    // The collider without a motion rests at its parked pose.
    let parked = &a.colliders[1];
    assert!(parked.poses.iter().all(|p| *p == parked.poses[0]));
    assert!(parked.poses[0].center.y > 1.0);
    // Strided and refined sequences keep the colliders' poses at the shared frames.
    assert_eq!(a.every(3).colliders[0].poses[2], ball.poses[6]);
    assert_eq!(a.refined(2, 0.02).colliders[0].poses[4], ball.poses[2]);
}

#[test]
fn a_dataset_with_colliders_is_the_same_bytes_from_the_same_seed_and_never_penetrates() {
    let dirs = [tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap()];
    // The simulator's parallel sums may round differently from one thread schedule to
    // another, so both runs take one thread: the same schedule, the same sums.
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let mut reports = Vec::new();
    for dir in &dirs {
        let mut problem = poked_cube();
        reports.push(one.install(|| dataset::generate(&mut problem, dir.path(), None, true, &Silent).unwrap()));
    }
    let problem = poked_cube();
    let seq = &plan(&problem.scene.dataset)[0];
    let files = dirs.each_ref().map(|d| sequence_path(d.path(), seq));
    let traj = Trajectory::read_npz(&files[0]).unwrap();
    // Step times differ from run to run; everything else is the same bytes.
    let strip = |path: &Path| {
        let mut t = Trajectory::read_npz(path).unwrap();
        t.step_seconds.iter_mut().for_each(|s| *s = 0.0);
        let copy = path.with_extension("same.npz");
        t.write_npz(&copy).unwrap();
        std::fs::read(copy).unwrap()
    };
    assert_eq!(strip(&files[0]), strip(&files[1]));
    let c = traj.colliders.as_ref().expect("the trajectory records the colliders");
    assert_eq!(c.names, ["ball", "parked"]);
    assert_eq!(c.shapes[0], [0.0, 0.03, 0.0, 0.0]);
    assert_eq!(c.states.len(), 13);
    assert!(traj.meta_value("collider_layout").is_some());
    // The ball came within the barrier's reach of the body, and never inside.
    let closest = reports[0].collider_min_distance.unwrap();
    assert!(closest > 0.0 && closest < 1e-3, "closest approach {closest}");
    assert_eq!(Some(closest), reports[1].collider_min_distance);
}

/// A 0.1 m soft cube dropped from rest on a floor each sequence places (`placement`).
fn dropped_cube() -> BuiltScene {
    let text = r#"
name = "dropped-cube"
dt = 0.02
gravity = [0.0, -9.81, 0.0]
[newton]
max_iterations = 200
[mesh]
type = "box"
min = [-0.05, 0.0, -0.05]
max = [0.05, 0.1, 0.05]
cells = [2, 2, 2]
[material]
youngs = 1e5
poisson = 0.4
density = 1000.0
[contact]
dhat = 1e-3
friction = 0.5
[[colliders]]
name = "floor"
shape = "box"
half_extents = [0.3, 0.02, 0.3]
[colliders.placement]
center = { min = [-0.01, -0.08, 0.0], max = [0.01, -0.04, 0.0] }
tilt = [0.1, 0.2]
[dataset]
train = 2
test = 0
validation = 0
frames = 20
"#;
    built(text, "dropped-cube.toml")
}

#[test]
fn a_placed_collider_rests_where_the_seed_puts_it_tilted_by_the_speed_level() {
    let problem = dropped_cube();
    let angle = |p: &crate::contact::ColliderPose| p.rotation.angle();
    for (level, factor) in [(0.0, 1.0), (0.5, 1.0), (1.0, 1.0), (1.0, 1.5)] {
        let speeds = SpeedPlan {
            pieces: vec![(0, level, factor)],
            steady: None,
        };
        let seq = problem.sequence(&speeds, 10, 3);
        assert_eq!(seq, problem.sequence(&speeds, 10, 3));
        let floor = &seq.colliders[0];
        // It rests the whole sequence, its centre in the box, tilted about a horizontal axis.
        assert!(floor.poses.iter().all(|p| *p == floor.poses[0]));
        assert!(floor.velocities.iter().all(|v| *v == [0.0; 6]));
        let p = floor.poses[0];
        assert!((-0.01..=0.01).contains(&p.center.x) && (-0.08..=-0.04).contains(&p.center.y));
        assert_eq!(p.center.z, 0.0);
        let expected = (0.1 + level * 0.1) * factor;
        assert!(
            (angle(&p) - expected).abs() < 1e-12,
            "tilt {} for {expected}",
            angle(&p)
        );
        let axis = p.rotation.axis().unwrap();
        assert!(axis.y.abs() < 1e-12, "{axis:?}");
    }
    // Another seed, another place.
    let speeds = SpeedPlan::constant(0.5);
    assert_ne!(
        problem.sequence(&speeds, 10, 3).colliders[0].poses[0],
        problem.sequence(&speeds, 10, 4).colliders[0].poses[0]
    );
    // Without a sequence (a simulation of the scene's own), it rests in the middle, untilted.
    let barrier = problem.simulator.collider_barrier().unwrap();
    let idle = barrier.colliders()[0].pose;
    assert!((idle.center.y + 0.06).abs() < 1e-12 && angle(&idle) == 0.0, "{idle:?}");
}

#[test]
fn a_cube_dropped_on_a_placed_floor_lands_and_never_enters_it() {
    let dir = tempfile::tempdir().unwrap();
    let mut problem = dropped_cube();
    let report = dataset::generate(&mut problem, dir.path(), None, true, &Silent).unwrap();
    let seq = &plan(&problem.scene.dataset)[1];
    let traj = Trajectory::read_npz(&sequence_path(dir.path(), seq)).unwrap();
    let c = traj.colliders.as_ref().unwrap();
    // The floor's top lies 2-6 cm under the cube: after 20 frames (0.4 s) the cube has fallen
    // onto it and is held there, within the barrier's reach and never inside.
    let lowest = |x: &[f64]| x.chunks(3).map(|p| p[1]).fold(f64::INFINITY, f64::min);
    assert_eq!(lowest(&traj.positions[0]), 0.0);
    let end = traj.positions.last().unwrap();
    let floor_top = c.states[0][1] + 0.02;
    assert!(
        lowest(end) < floor_top + 0.03,
        "lowest {} over a floor at {floor_top}",
        lowest(end)
    );
    let closest = report.collider_min_distance.unwrap();
    assert!(closest > 0.0 && closest < 1e-3, "closest approach {closest}");
}
