//! The peers' cases that `mochi compare` writes (`eval::compare::case`) and the conditions of
//! its matrix for a scene moved by a run-time collider: obstacle boxes and run-time colliders
//! go into a case where the simulator had them, a collider's motion gets the speed
//! conditions, a capsule is written by its kind.

use std::path::PathBuf;

use mochi_sim::npz::NpzFile;
use mochi_trainer::eval::compare::conditions::{self, MatrixSpan};
use mochi_trainer::Recipe;

/// A contact scene's peer case carries its obstacle boxes where the simulator puts them: each
/// scripted box's centre at frame t is the centroid of the simulator's box corners after t
/// steps (stomp-keyframed's box starts down at 0.5 s, frame 15), with the scene's contact
/// parameters.
#[test]
fn a_contact_case_carries_the_obstacles_where_the_simulator_puts_them() {
    let mut problem = Recipe::load("stomp-keyframed").unwrap().build().unwrap();
    let frames = 20;
    let bc = conditions::chart_sequences(&problem, 1, frames).remove(0).1;
    let dim = problem.mesh.dim;
    let mut reference = vec![problem.simulator.positions().to_vec()];
    let mut corners = vec![problem.simulator.obstacle_positions().unwrap().to_vec()];
    for t in 1..=frames {
        let targets = bc.targets(&problem.handles, t, dim);
        problem.simulator.step(&targets).unwrap();
        reference.push(problem.simulator.positions().to_vec());
        corners.push(problem.simulator.obstacle_positions().unwrap().to_vec());
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("case.npz");
    mochi_trainer::eval::compare::case::write_case(&path, &problem, &bc, &reference).unwrap();
    let mut npz = NpzFile::open(&path).unwrap();
    assert!(npz.has("obstacle_kinds"));
    let centres = npz.array("obstacle_centres").unwrap();
    centres.expect_shape(&[frames as u64 + 1, 2, 3]).unwrap();
    let centres = centres.into_vec::<f64>("float64").unwrap();
    for (t, corners) in corners.iter().enumerate() {
        // The ground's 8 corners, then the box's.
        for (k, box_corners) in corners.chunks_exact(24).enumerate() {
            for i in 0..3 {
                let centroid = box_corners.chunks_exact(3).map(|p| p[i]).sum::<f64>() / 8.0;
                let written = centres[(t * 2 + k) * 3 + i];
                assert!(
                    (written - centroid).abs() < 1e-12,
                    "frame {t} box {k} axis {i}: {written} vs {centroid}"
                );
            }
        }
    }
    let box_y = |t: usize| centres[(t * 2 + 1) * 3 + 1];
    assert!(box_y(15) - box_y(frames) > 3e-3, "the box moves down after 0.5 s");
    let friction = npz
        .array("contact_friction")
        .unwrap()
        .into_vec::<f64>("float64")
        .unwrap();
    assert_eq!(friction, [0.5]);
}

/// Run-time colliders go into the case as obstacle boxes where the simulator had them: stomp's
/// ground (placed) and its box (on the sequence's path, coming down onto the beam), each
/// centre that of the pose the simulator recorded at the frame, with their edge lengths.
#[test]
fn a_case_carries_the_run_time_colliders_where_the_simulator_had_them() {
    let frames = 20;
    let (_dir, path, _bc, traj) = stepped_case("stomp", frames);
    let mut npz = NpzFile::open(&path).unwrap();
    npz.array("obstacle_kinds").unwrap().expect_shape(&[2]).unwrap();
    let extents = npz
        .array("obstacle_extents")
        .unwrap()
        .into_vec::<f64>("float64")
        .unwrap();
    assert_eq!(extents, [2.0, 0.1, 2.0, 0.12, 0.11, 0.2]);
    let centres = npz.array("obstacle_centres").unwrap();
    centres.expect_shape(&[frames as u64 + 1, 2, 3]).unwrap();
    let centres = centres.into_vec::<f64>("float64").unwrap();
    let recorded = &traj.colliders.as_ref().expect("run-time colliders").states;
    for t in 0..=frames {
        for k in 0..2 {
            for i in 0..3 {
                let (written, pose) = (centres[(t * 2 + k) * 3 + i], recorded[t][k * 12 + i]);
                assert!(
                    (written - pose).abs() < 1e-12,
                    "frame {t} collider {k} axis {i}: {written} vs {pose}"
                );
            }
        }
    }
    assert_eq!(centres[1], -0.05, "the ground's top face at y = 0");
    let box_y = |t: usize| centres[(t * 2 + 1) * 3 + 1];
    assert!(box_y(0) - box_y(frames) > 5e-3, "the box comes down");
}

/// The case of `scene`'s first chart sequence stepped `frames` frames in full space, written
/// into a temporary folder (kept alive by the first item), with the sequence and trajectory.
fn stepped_case(
    scene: &str,
    frames: usize,
) -> (
    tempfile::TempDir,
    PathBuf,
    mochi_sim::bc::BcSequence,
    mochi_sim::Trajectory,
) {
    let mut problem = Recipe::load(scene).unwrap().build().unwrap();
    let bc = conditions::chart_sequences(&problem, 1, frames).remove(0).1;
    let mut traj = problem.start(&bc).unwrap();
    for t in 1..=frames {
        problem.advance(&bc, t, &mut traj).unwrap();
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("case.npz");
    mochi_trainer::eval::compare::case::write_case(&path, &problem, &bc, &traj.positions).unwrap();
    (dir, path, bc, traj)
}

/// A scene whose only sampled motion is a run-time collider's (stomp's box) gets the speed
/// conditions too: its box 1.5x and 2x the top training speed, and stopped.
#[test]
fn a_collider_motion_gets_the_speed_conditions() {
    let problem = Recipe::load("stomp").unwrap().build().unwrap();
    let span = MatrixSpan {
        frames: 4,
        long_frames: 4,
    };
    let names: Vec<String> = conditions::conditions(&problem, span)
        .into_iter()
        .map(|c| c.name)
        .collect();
    for name in ["1.5x top speed", "2x top speed", "sudden stop"] {
        assert!(names.iter().any(|n| n == name), "{name} missing from {names:?}");
    }
}

/// A run-time capsule (poke's finger) goes into the case by its kind, which the XPBD peer
/// refuses by name (it drives boxes only), with no edge lengths.
#[test]
fn a_capsule_collider_is_written_by_its_kind() {
    let (_dir, path, bc, _traj) = stepped_case("poke", 2);
    let mut npz = NpzFile::open(&path).unwrap();
    npz.array("obstacle_kinds").unwrap().expect_shape(&[1]).unwrap();
    let extents = npz
        .array("obstacle_extents")
        .unwrap()
        .into_vec::<f64>("float64")
        .unwrap();
    assert!(extents.iter().all(|e| e.is_nan()), "{extents:?}");
    let centres = npz
        .array("obstacle_centres")
        .unwrap()
        .into_vec::<f64>("float64")
        .unwrap();
    assert_eq!(centres[6..9], *bc.colliders[0].poses[2].center.as_slice());
}
