//! Analytic colliders in the full-space solve: a sphere and a turning box pressed into a
//! soft cube held at its base never get a vertex inside them, reach their poses exactly at
//! the end of every step, and deform the body; with friction, a plate dragged across the
//! top carries the top along.

use crate::contact::ColliderPose;
use crate::scene::{BuiltScene, Scene};
use std::path::Path;

/// A 0.1 m soft cube (2 x 2 x 2 cells) held at its base, with the collider `collider` and
/// the friction coefficient `friction`.
fn held_cube(collider: &str, friction: f64) -> BuiltScene {
    let text = format!(
        r#"
name = "held-cube"
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
friction = {friction}
[[handles]]
name = "base"
select = {{ side = {{ axis = 1, end = "min" }} }}
[[colliders]]
{collider}
"#
    );
    Scene::parse(&text, Path::new("held-cube.toml"))
        .and_then(|s| s.build())
        .unwrap_or_else(|e| panic!("{e}"))
}

/// Steps `problem` through `poses` (frame 0 placed, then one step each), checking every
/// frame: converged, every surface vertex outside the collider, the collider where asked.
/// Returns the top centre vertex's lowest height.
fn press(problem: &mut BuiltScene, poses: &[ColliderPose]) -> f64 {
    let sim = &mut problem.simulator;
    let targets: Vec<f64> = sim
        .fixed_vertices()
        .iter()
        .flat_map(|&v| problem.mesh.rest[3 * v..3 * v + 3].to_vec())
        .collect();
    sim.place_colliders(&poses[..1]).unwrap();
    let top = (0..problem.mesh.num_vertices())
        .find(|&v| {
            let p = &problem.mesh.rest[3 * v..3 * v + 3];
            (p[0] - 0.05).abs() < 1e-9 && (p[1] - 0.1).abs() < 1e-9 && (p[2] - 0.05).abs() < 1e-9
        })
        .expect("a top centre vertex");
    let mut lowest = f64::INFINITY;
    for (frame, pose) in poses.iter().enumerate().skip(1) {
        sim.set_collider_poses(&[*pose]).unwrap();
        let report = sim.step(&targets).unwrap_or_else(|e| panic!("frame {frame}: {e}"));
        assert!(report.converged, "frame {frame}: {report:?}");
        let barrier = sim.collider_barrier().unwrap();
        assert_eq!(barrier.poses(), vec![*pose], "frame {frame}: the collider lags");
        let closest = barrier.min_signed_distance(sim.positions());
        assert!(closest > 0.0, "frame {frame}: a vertex {closest} inside the collider");
        lowest = lowest.min(sim.positions()[3 * top + 1]);
    }
    lowest
}

#[test]
fn a_sphere_pressed_into_a_held_cube_pushes_its_top_down_and_stays_outside() {
    let mut problem = held_cube("shape = \"sphere\"\nradius = 0.03", 0.0);
    // From 3 cm over the top down to 2 cm into it, 5 mm per step, then held.
    let poses: Vec<ColliderPose> = (0..16)
        .map(|f| ColliderPose::new([0.05, 0.16 - 0.005 * (f.min(10) as f64), 0.05], [0.0; 3]))
        .collect();
    let lowest = press(&mut problem, &poses);
    assert!(lowest < 0.1 - 0.005, "top centre only reached {lowest}");
    // A wrong number of poses is refused.
    assert!(problem.simulator.set_collider_poses(&[]).is_err());
}

#[test]
fn a_turning_box_swept_into_a_held_cube_stays_outside_its_vertices() {
    let mut problem = held_cube("shape = \"box\"\nhalf_extents = [0.08, 0.01, 0.015]", 0.0);
    // Descends onto the top while turning about the vertical by 0.05 rad per step.
    let poses: Vec<ColliderPose> = (0..12)
        .map(|f| {
            let f = f as f64;
            ColliderPose::new([0.05, 0.13 - 0.004 * f, 0.05], [0.0, 0.05 * f, 0.0])
        })
        .collect();
    let lowest = press(&mut problem, &poses);
    assert!(lowest < 0.1 - 0.01, "top centre only reached {lowest}");
}

#[test]
fn a_plate_dragged_across_the_top_carries_it_along_only_with_friction() {
    // A plate wider than the cube comes down from 2 mm over its top to 4 mm into it, then
    // slides 2 cm along x.
    let poses: Vec<ColliderPose> = (0..20)
        .map(|f| {
            let f = f as f64;
            let y = 0.112 - 0.0015 * f.min(4.0);
            ColliderPose::new([0.05 + 0.002 * (f - 10.0).max(0.0), y, 0.05], [0.0; 3])
        })
        .collect();
    let mut shift = Vec::new();
    for friction in [0.0, 0.8] {
        let mut problem = held_cube("shape = \"box\"\nhalf_extents = [0.1, 0.01, 0.1]", friction);
        press(&mut problem, &poses);
        let x = problem.simulator.positions();
        let rest = &problem.mesh.rest;
        let top: Vec<usize> = (0..rest.len() / 3).filter(|&v| rest[3 * v + 1] > 0.1 - 1e-9).collect();
        let mean = top.iter().map(|&v| x[3 * v] - rest[3 * v]).sum::<f64>() / top.len() as f64;
        shift.push(mean);
    }
    assert!(
        shift[0].abs() < 1e-3,
        "frictionless plate moved the top by {}",
        shift[0]
    );
    assert!(
        shift[1] > 3e-3,
        "the plate with friction moved the top by only {}",
        shift[1]
    );
}
