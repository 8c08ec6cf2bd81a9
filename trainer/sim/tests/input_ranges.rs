//! Physical inputs out of range are refused when the scene is loaded, with an error naming
//! the scene file and the field's path; a solver that meets a non-finite Hessian stops with
//! an error naming the frame instead of searching for a diagonal shift for ever.

use mochi_sim::error::Location;
use mochi_sim::solver::{Quantity, StepError};
use mochi_sim::Scene;
use std::path::Path;
use std::sync::mpsc;
use std::time::Duration;

mod support;
use support::rest_targets;

const GOOD: &str = include_str!("fixtures/good.toml");

/// A cube over a ground slab, under IPC contact (the `[[contact.obstacles]]` box is rotated).
const SLAB: &str = r#"
name = "slab"
gravity = [0.0, -9.81, 0.0]
[mesh]
type = "box"
min = [-0.1, 0.06, -0.1]
max = [0.1, 0.26, 0.1]
cells = [2, 2, 2]
[material]
youngs = 1e5
poisson = 0.4
density = 1000.0
[contact]
[[contact.obstacles]]
type = "box"
min = [-1.0, -0.1, -1.0]
max = [1.0, 0.0, 1.0]
rotation = [0.0, 0.0, 0.1745]
"#;

/// A ball of radius 0.1 dropped under gravity.
const BALL: &str = r#"
name = "ball"
gravity = [0.0, -9.81, 0.0]
[mesh]
type = "ball"
center = [0.0, 0.0, 0.0]
radius = 0.1
cells = 4
[material]
youngs = 1e5
poisson = 0.3
density = 1000.0
"#;

/// `text` with `from` replaced by `to` (which must apply).
fn edit(text: &str, from: &str, to: &str) -> String {
    let edited = text.replace(from, to);
    assert_ne!(edited, text, "replacement of {from} applies");
    edited
}

/// The error loading `text` as `bad.toml` gives; it must name the file and `field`.
fn load_error(text: &str, field: &str) -> String {
    let err = Scene::parse(text, Path::new("bad.toml")).expect_err("must be refused at load");
    let msg = err.to_string();
    assert_eq!(err.location, Location::Field(field.into()), "{msg}");
    assert!(msg.starts_with("bad.toml: field `"), "names the file and field: {msg}");
    msg
}

#[test]
fn a_huge_youngs_modulus_is_refused_at_load_naming_the_field() {
    let msg = load_error(&edit(GOOD, "youngs = 1e5", "youngs = 1.5e308"), "material.youngs");
    assert!(msg.contains("1.5e308") && msg.contains("1e30"), "{msg}");
    // The largest modulus allowed still loads; the smallest refused one does not.
    Scene::parse(&edit(GOOD, "youngs = 1e5", "youngs = 1e30"), Path::new("ok.toml")).unwrap();
    load_error(&edit(GOOD, "youngs = 1e5", "youngs = 1.0001e30"), "material.youngs");
}

#[test]
fn a_huge_youngs_modulus_in_a_region_is_refused_naming_the_region() {
    let region = "\n[[material.regions]]\nbox = { min = [0.5, -1.0, -1.0], max = [2.0, 1.0, 1.0] }\nyoungs = 1.5e308\n";
    let text = edit(GOOD, "density = 1000.0\n", &format!("density = 1000.0\n{region}"));
    let msg = load_error(&text, "material.regions[0].youngs");
    assert!(msg.contains("1.5e308"), "{msg}");
}

#[test]
fn density_and_poisson_ratio_out_of_range_are_refused_naming_the_field() {
    load_error(&edit(GOOD, "density = 1000.0", "density = 1e300"), "material.density");
    load_error(&edit(GOOD, "density = 1000.0", "density = 1e-300"), "material.density");
    load_error(&edit(GOOD, "poisson = 0.3", "poisson = -1.0"), "material.poisson");
}

#[test]
fn a_huge_obstacle_rotation_is_refused_at_load_naming_the_field() {
    Scene::parse(SLAB, Path::new("slab.toml")).unwrap();
    for rotation in ["[0.0, 0.0, 1e300]", "[1e300, 1e300, 1e300]", "[0.0, 4.0, 5.0]"] {
        let text = edit(SLAB, "[0.0, 0.0, 0.1745]", rotation);
        let msg = load_error(&text, "contact.obstacles[0].rotation");
        assert!(msg.contains("rad"), "{msg}");
    }
}

#[test]
fn a_tiny_ball_radius_is_refused_at_load_naming_the_radius() {
    Scene::parse(BALL, Path::new("ball.toml")).unwrap().build().unwrap();
    let msg = load_error(&edit(BALL, "radius = 0.1", "radius = 1e-300"), "mesh.radius");
    assert!(msg.contains("1e-300") && !msg.contains("cells"), "{msg}");
    // Inside parts too.
    let parts = edit(BALL, "[mesh]\n", "[mesh]\ntype = \"parts\"\n[[mesh.parts]]\n");
    let text = edit(&parts, "radius = 0.1", "radius = 1e-300");
    load_error(&text, "mesh.parts[0].radius");
}

#[test]
fn a_nan_side_tolerance_is_refused_at_load_naming_the_tolerance() {
    for tolerance in ["nan", "-1.0", "inf"] {
        let text = edit(
            GOOD,
            "end = \"min\"",
            &format!("end = \"min\", tolerance = {tolerance}"),
        );
        let msg = load_error(&text, "handles[0].select.side.tolerance");
        assert!(!msg.contains("selects no vertices"), "{msg}");
    }
}

#[test]
fn other_physical_numbers_are_range_checked_naming_the_field() {
    for (from, to, field) in [
        (
            "name = \"ok\"",
            "name = \"ok\"\ngravity = [0.0, -1e300, 0.0]",
            "gravity[1]",
        ),
        ("name = \"ok\"", "name = \"ok\"\ndt = 1e300", "dt"),
        ("max = [1.0, 0.2, 0.2]", "max = [1.0, 0.2, 1e300]", "mesh.max[2]"),
        ("max = [1.0, 0.2, 0.2]", "max = [1.0, 0.2, 1e-300]", "mesh.max[2]"),
        (
            "end = \"min\" } }",
            "end = \"min\" } }\npivot = [0.0, 1e300, 0.0]",
            "handles[0].pivot[1]",
        ),
        (
            "density = 1000.0",
            "density = 1000.0\n[[loads]]\nselect = { indices = [0] }\nforce = [1e300, 0.0, 0.0]",
            "loads[0].force[0]",
        ),
        (
            "density = 1000.0",
            "density = 1000.0\n[[obstacles]]\ntype = \"sphere\"\ncenter = [0.0, 0.0, 0.0]\nradius = 1e-300",
            "obstacles[0].radius",
        ),
    ] {
        load_error(&edit(GOOD, from, to), field);
    }
}

/// Runs `f` on a thread and waits at most `seconds` for it: a solver that loops for ever
/// fails the test instead of hanging it.
fn within<T: Send + 'static>(seconds: u64, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (send, receive) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = send.send(f());
    });
    receive
        .recv_timeout(Duration::from_secs(seconds))
        .unwrap_or_else(|_| panic!("no answer within {seconds} s: the solver loops"))
}

#[test]
fn a_non_finite_hessian_stops_the_step_with_an_error_naming_the_frame() {
    for (youngs, region) in [(1.5e308, false), (f64::MAX, true)] {
        let err = within(60, move || {
            // The load checks would refuse the modulus: it is set after them, as a library
            // user building a scene in code could.
            let mut scene = Scene::parse(GOOD, Path::new("good.toml")).unwrap();
            if region {
                scene.material.regions.push(mochi_sim::scene::RegionSpec {
                    bounds: Some(mochi_sim::scene::BoxSpec {
                        min: [-1.0; 3],
                        max: [2.0; 3],
                    }),
                    attribute: None,
                    youngs: Some(youngs),
                    poisson: None,
                    density: None,
                });
            } else {
                scene.material.youngs = youngs;
            }
            let mut problem = scene.build().unwrap();
            let targets = rest_targets(&problem);
            problem
                .simulator
                .step(&targets)
                .expect_err("a non-finite Hessian is an error")
        });
        assert!(
            matches!(
                err,
                StepError::NonFinite {
                    frame: 1,
                    quantity: Quantity::Hessian,
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().starts_with("frame 1, Newton iteration 0"), "{err}");
    }
}

#[test]
fn a_non_finite_energy_stops_the_step_with_an_error_naming_the_frame() {
    let err = within(60, || {
        let mut problem = Scene::parse(GOOD, Path::new("good.toml")).unwrap().build().unwrap();
        // One free vertex (the last, at the unclamped end) moved absurdly far: the elastic
        // energy of its tets overflows.
        let mut x = problem.mesh.rest.clone();
        let last = x.len() - 1;
        x[last] = 1e300;
        problem.simulator.reset(&x);
        let targets = rest_targets(&problem);
        problem
            .simulator
            .step(&targets)
            .expect_err("a non-finite energy is an error")
    });
    assert!(
        matches!(
            err,
            StepError::NonFinite {
                frame: 1,
                iteration: 0,
                quantity: Quantity::Energy | Quantity::Gradient,
            }
        ),
        "{err}"
    );
}
