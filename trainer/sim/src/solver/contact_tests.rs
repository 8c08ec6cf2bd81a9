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

/// Two 0.1 m cubes of one mesh, the upper one 2 cm above the lower, with self-contact.
fn two_cubes() -> crate::solver::Simulator {
    use crate::contact::ContactSurface;
    use crate::mesh::{procedural::box_tets, Elements};
    use crate::solver::{ContactConfig, ContactSettings, SimulatorConfig};
    let scene = Scene::parse(
        r#"
name = "two-cubes"
dt = 0.01
[mesh]
type = "box"
min = [0.0, 0.0, 0.0]
max = [0.1, 0.1, 0.1]
cells = [1, 1, 1]
[material]
youngs = 1e5
poisson = 0.4
density = 1000.0
"#,
        Path::new("two-cubes.toml"),
    )
    .unwrap();
    let mut mesh = box_tets([0.0; 3], [0.1; 3], [1, 1, 1]).unwrap();
    let n = mesh.num_vertices();
    let upper: Vec<f64> = mesh
        .rest
        .chunks(3)
        .flat_map(|p| [p[0] + 0.03, p[1] + 0.12, p[2] + 0.02])
        .collect();
    mesh.rest.extend(upper);
    if let Elements::Tets(tets) = &mut mesh.elements {
        let copies: Vec<[usize; 4]> = tets.iter().map(|t| t.map(|v| v + n)).collect();
        tets.extend(copies);
    }
    let energies = scene.build_energies(&mesh).unwrap();
    crate::solver::Simulator::new(SimulatorConfig {
        dim: 3,
        x0: mesh.rest.clone(),
        masses: energies.masses,
        potentials: energies.potentials,
        fixed_vertices: Vec::new(),
        dt: scene.dt,
        scheme: Default::default(),
        settings: Default::default(),
        length_scale: mesh.rest_diagonal(),
        contact: Some(ContactConfig {
            settings: ContactSettings {
                self_contact: true,
                ..Default::default()
            },
            surface: ContactSurface::of_mesh(&mesh),
            obstacles: Vec::new(),
            colliders: Vec::new(),
        }),
    })
}

#[test]
fn self_contact_keeps_two_parts_of_one_mesh_apart_and_conserves_momentum() {
    let mut sim = two_cubes();
    let n = sim.positions().len() / 3;
    let x = sim.positions().to_vec();
    // The upper cube (second half of the vertices) moves down at 2 m/s.
    let x_prev: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(k, c)| {
            if k / 3 >= n / 2 && k % 3 == 1 {
                c + 2.0 * sim.dt()
            } else {
                *c
            }
        })
        .collect();
    sim.restart(&x, &x_prev);
    let momentum = |sim: &crate::solver::Simulator| -> f64 {
        sim.velocities()
            .chunks(3)
            .zip(sim.masses())
            .map(|(v, m)| m * v[1])
            .sum()
    };
    let p0 = momentum(&sim);
    let mut touched = false;
    for step in 0..30 {
        let report = sim.step(&[]).unwrap_or_else(|e| panic!("step {step}: {e}"));
        assert!(report.converged, "step {step}: {report:?}");
        let (surface, ext) = sim.contact_state().unwrap();
        assert!(!has_intersections(surface, &ext), "step {step} intersects");
        touched |= report.contact_pairs > 0;
    }
    assert!(touched, "the cubes never met");
    // Contact pairs couple vertices of the two cubes, which no element joins.
    assert!(!sim.extra_couplings.is_empty());
    // The lower cube was pushed down, and momentum is conserved (contact forces are internal).
    let lower_vy: f64 = sim.velocities().chunks(3).take(n / 2).map(|v| v[1]).sum::<f64>() / (n / 2) as f64;
    assert!(lower_vy < -0.1, "lower cube moves at {lower_vy} m/s");
    let p1 = momentum(&sim);
    assert!((p1 - p0).abs() < 1e-3 * p0.abs(), "momentum {p0} -> {p1}");
}

#[test]
fn a_scripted_obstacle_follows_its_keyframes_and_pushes_what_it_meets() {
    // A box starting 5 cm over the cube's top, sent down by 10 cm over 0.5 s and held: it
    // meets the cube on the way and presses it into the slab.
    let mut problem = cube_over_slab(0.0);
    let text = r#"
[[obstacles]]
type = "box"
min = [-0.3, 0.3, -0.3]
max = [0.3, 0.4, 0.3]
keyframes = [[0.0, 0.0, 0.0, 0.0], [0.5, 0.0, -0.1, 0.0]]
"#;
    let mut scene = problem.scene.clone();
    let extra: crate::scene::ContactSpec = toml::from_str(text).unwrap();
    scene.contact.as_mut().unwrap().obstacles.extend(extra.obstacles);
    problem = scene.build().unwrap_or_else(|e| panic!("{e}"));
    let sim = &mut problem.simulator;
    let body = sim.positions().len();
    let (_, rest) = sim.contact_state().unwrap();
    let lid = rest.len() - 24..rest.len();
    let dt = sim.dt();
    for frame in 1..=40 {
        let report = sim.step(&[]).unwrap_or_else(|e| panic!("frame {frame}: {e}"));
        assert!(report.converged, "frame {frame}: {report:?}");
        let (surface, ext) = sim.contact_state().unwrap();
        assert!(!has_intersections(surface, &ext), "frame {frame} intersects");
        // Every solve ends with the moving box exactly where its script puts it.
        let dy = -0.1 * (frame as f64 * dt / 0.5).min(1.0);
        for (k, (now, at_rest)) in ext[lid.clone()].iter().zip(&rest[lid.clone()]).enumerate() {
            let expected = at_rest + if k % 3 == 1 { dy } else { 0.0 };
            assert!(
                (now - expected).abs() < 1e-12,
                "frame {frame}: lid coordinate {k} at {now}, not {expected}"
            );
        }
        assert_eq!(ext.len() - body, rest.len() - body);
    }
    // The cube (0.2 m tall on the slab) now sits under the lid's bottom at 0.2 m minus the
    // squash: its top is below where it started and above the slab.
    let x = sim.positions();
    let top = x.chunks(3).map(|p| p[1]).fold(f64::NEG_INFINITY, f64::max);
    assert!(top < 0.2 + 1e-3 && top > 0.1, "cube top {top}");
    assert!(min_y(x) > 0.0, "through the slab: {}", min_y(x));
}
