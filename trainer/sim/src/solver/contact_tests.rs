//! The contact path of the solver: the CCD bound on line-search steps and a fast body
//! against a thin obstacle.

use crate::contact::intersection::has_intersections;
use crate::scene::{BuiltScene, Scene};
use std::path::Path;

/// A 0.2 m soft cube (2 x 2 x 2 cells) over a 2 cm thick slab whose top is at `y = 0`.
fn cube_over_slab(friction: f64) -> BuiltScene {
    let text = format!(
        r#"
name = "cube-over-slab"
dt = 0.02
gravity = [0.0, -9.81, 0.0]
[mesh]
type = "box"
min = [-0.1, 0.05, -0.1]
max = [0.1, 0.25, 0.1]
cells = [2, 2, 2]
[material]
youngs = 1e5
poisson = 0.4
density = 1000.0
[contact]
dhat = 1e-3
friction = {friction}
[[contact.obstacles]]
type = "box"
min = [-1.0, -0.02, -1.0]
max = [1.0, 0.0, 1.0]
"#
    );
    Scene::parse(&text, Path::new("cube-over-slab.toml"))
        .and_then(|s| s.build())
        .unwrap_or_else(|e| panic!("{e}"))
}

fn min_y(x: &[f64]) -> f64 {
    x.chunks(3).map(|p| p[1]).fold(f64::INFINITY, f64::min)
}

#[test]
fn the_line_search_bound_never_lets_an_iterate_intersect() {
    let mut problem = cube_over_slab(0.0);
    let x0 = problem.mesh.rest.clone();
    // A step that carries the cube 1 m down: through the slab and out below it.
    let x1: Vec<f64> = x0
        .iter()
        .enumerate()
        .map(|(k, c)| if k % 3 == 1 { c - 1.0 } else { *c })
        .collect();
    let sim = &mut problem.simulator;
    let contact = sim.contact.as_mut().expect("the scene has contact");
    let t = contact.line_search_bound(&x0, &x1);
    assert!(t > 0.0 && t < 0.06, "bound {t}: the cube is 5 cm above the slab");
    let surface = contact.surface().clone();
    let at = |s: f64| -> Vec<f64> { x0.iter().zip(&x1).map(|(a, b)| a + s * (b - a)).collect() };
    for k in 0..=100 {
        let x = at(t * k as f64 / 100.0);
        assert!(
            !has_intersections(&surface, &contact.extended(&x)),
            "intersects at {k}% of the bound"
        );
        assert!(min_y(&x) > 0.0);
    }
    // The unfiltered step would pass through the slab (its end point alone looks clean).
    assert!(!has_intersections(&surface, &contact.extended(&x1)));
    assert!((1..100).any(|k| has_intersections(&surface, &contact.extended(&at(k as f64 / 100.0)))));
}

#[test]
fn a_fast_body_never_tunnels_through_a_thin_obstacle() {
    let mut problem = cube_over_slab(0.0);
    let sim = &mut problem.simulator;
    let x = sim.positions().to_vec();
    // 20 m/s downwards: 40 cm per step, twenty times the slab's thickness.
    let x_prev: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(k, c)| if k % 3 == 1 { c + 20.0 * sim.dt() } else { *c })
        .collect();
    sim.restart(&x, &x_prev);
    let mut touched = false;
    for step in 0..10 {
        let report = sim.step(&[]).unwrap_or_else(|e| panic!("step {step}: {e}"));
        let (surface, ext) = sim.contact_state().unwrap();
        assert!(!has_intersections(surface, &ext), "step {step} intersects");
        assert!(min_y(sim.positions()) > 0.0, "step {step}: below the slab's top");
        touched |= report.contact_pairs > 0;
    }
    assert!(touched, "the cube never reached the slab");
    assert!(sim.contact_stiffness() > 0.0);
}
