//! Helpers shared by the simulator's integration tests (each test file declares
//! `mod support;`).
#![allow(dead_code)]

use mochi_sim::{BuiltScene, Scene};
use std::path::{Path, PathBuf};

/// The path of the test fixture `name` (a file in `tests/fixtures` or `tests/data`).
pub fn fixture_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests").join(name)
}

/// Builds the scene `toml` (its mesh files resolve against `tests/fixtures`).
pub fn build(toml: &str) -> BuiltScene {
    Scene::parse(toml, &fixture_path("fixtures/<test scene>"))
        .expect("valid scene")
        .build()
        .expect("scene builds")
}

/// The handles' vertices at their rest placement, as the simulator's boundary targets.
pub fn rest_targets(problem: &BuiltScene) -> Vec<f64> {
    let dim = problem.mesh.dim;
    problem
        .handles
        .iter()
        .flat_map(|h| h.reference.iter().flat_map(|p| p[..dim].to_vec()))
        .collect()
}

/// Static tip deflection (mean displacement along `axis` of the vertices at the free end,
/// x = x_max) under the scene's loads with the handles at rest.
pub fn static_tip_deflection(problem: &mut BuiltScene, axis: usize) -> f64 {
    let dim = problem.mesh.dim;
    let targets = rest_targets(problem);
    let report = problem.simulator.solve_static(&targets).expect("static solve");
    assert!(
        report.converged,
        "static solve did not converge: {:?}",
        report.step_norms
    );
    let (_, hi) = problem.mesh.bounding_box(&problem.mesh.rest);
    let n = problem.mesh.num_vertices();
    let x = problem.simulator.positions();
    let tip: Vec<usize> = (0..n)
        .filter(|&v| (problem.mesh.rest[v * dim] - hi[0]).abs() < 1e-9)
        .collect();
    tip.iter()
        .map(|&v| x[v * dim + axis] - problem.mesh.rest[v * dim + axis])
        .sum::<f64>()
        / tip.len() as f64
}
