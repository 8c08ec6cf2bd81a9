//! Collider paths and datasets with colliders: paths start outside the body at the
//! sequence's speed and are seeded; a dataset with a collider is the same bytes from the
//! same seed, records the collider, and no vertex enters it.

use crate::dataset::{self, plan, sequence_path, SpeedPlan};
use crate::scene::{BuiltScene, Scene};
use crate::trajectory::Trajectory;
use crate::Silent;
use std::path::Path;

/// A 0.1 m soft cube (2 x 2 x 2 cells) held at its base, and a sphere that pokes it.
fn poked_cube() -> BuiltScene {
    let text = r#"
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
    Scene::parse(text, Path::new("poked-cube.toml"))
        .and_then(|s| s.build())
        .unwrap_or_else(|e| panic!("{e}"))
}

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
