//! The `[[colliders]]` tables: every bad field refused with its name, and a good table built
//! into the simulator at the parked pose.

use crate::scene::{Scene, PARKED_DIAGONALS};
use std::path::Path;

const BODY: &str = r#"
name = "poke-test"
[mesh]
type = "box"
min = [0.0, 0.0, 0.0]
max = [0.1, 0.1, 0.1]
cells = [1, 1, 1]
[material]
youngs = 1e5
poisson = 0.4
density = 1000.0
"#;

fn parse(contact: bool, colliders: &str) -> Result<Scene, crate::InputError> {
    let contact = if contact { "[contact]\ndhat = 1e-3\n" } else { "" };
    Scene::parse(&format!("{BODY}{contact}{colliders}"), Path::new("poke-test.toml"))
}

/// Asserts `colliders` is refused with an error naming `field`.
fn refused(colliders: &str, field: &str) {
    let e = parse(true, colliders).expect_err(colliders);
    assert_eq!(e.location, crate::Location::Field(field.into()), "{e}");
    assert!(e.to_string().contains("poke-test.toml"), "{e}");
}

#[test]
fn every_bad_collider_field_is_refused_by_name() {
    let capsule = "[[colliders]]\nshape = \"capsule\"\nradius = 0.01\nlength = 0.05\n";
    let ok = parse(true, capsule).unwrap();
    assert_eq!(ok.colliders.len(), 1);
    // Without `[contact]`.
    let e = parse(false, capsule).unwrap_err();
    assert_eq!(e.location, crate::Location::Field("colliders".into()), "{e}");
    assert!(e.message.contains("[contact]"), "{e}");
    // Shape fields: missing, foreign to the shape, out of range.
    refused("[[colliders]]\nshape = \"sphere\"\n", "colliders[0].radius");
    refused(
        "[[colliders]]\nshape = \"capsule\"\nradius = 0.01\n",
        "colliders[0].length",
    );
    refused("[[colliders]]\nshape = \"box\"\n", "colliders[0].half_extents");
    refused(
        "[[colliders]]\nshape = \"box\"\nhalf_extents = [0.1, 0.1, 0.1]\nradius = 0.1\n",
        "colliders[0].radius",
    );
    refused(
        "[[colliders]]\nshape = \"sphere\"\nradius = 0.1\nhalf_extents = [0.1, 0.1, 0.1]\n",
        "colliders[0].half_extents",
    );
    refused(
        "[[colliders]]\nshape = \"sphere\"\nradius = 0.1\nlength = 0.2\n",
        "colliders[0].length",
    );
    refused(
        &format!("{capsule}[[colliders]]\nshape = \"sphere\"\nradius = -0.1\n"),
        "colliders[1].radius",
    );
    refused(
        "[[colliders]]\nshape = \"capsule\"\nradius = 0.01\nlength = -1.0\n",
        "colliders[0].length",
    );
    refused(
        "[[colliders]]\nshape = \"box\"\nhalf_extents = [0.1, 0.0, 0.1]\n",
        "colliders[0].half_extents[1]",
    );
    refused(
        "[[colliders]]\nshape = \"sphere\"\nradius = 0.1\nrotation = [0.0, 9.0, 0.0]\n",
        "colliders[0].rotation",
    );
    // Motion fields.
    let motion = |extra: &str| format!("{capsule}[colliders.motion]\nspeed = [0.1, 0.2]\n{extra}");
    parse(true, &motion("")).unwrap();
    refused(
        &format!("{capsule}[colliders.motion]\nspeed = [0.3, 0.2]\n"),
        "colliders[0].motion.speed",
    );
    refused(
        &motion("directions = [[0.0, 0.0, 0.0]]\n"),
        "colliders[0].motion.directions",
    );
    refused(&motion("hold_frames = [5, 2]\n"), "colliders[0].motion.hold_frames");
    refused(&motion("clearance = -0.1\n"), "colliders[0].motion.clearance");
    refused(&motion("approach = -0.01\n"), "colliders[0].motion.approach");
    refused(&motion("share = 1.5\n"), "colliders[0].motion.share");
    refused(
        &motion("region = { min = [0.0, 0.0, 0.0], max = [0.1, -0.1, 0.1] }\n"),
        "colliders[0].motion.region.max",
    );
    // Placement fields.
    let floor = "[[colliders]]\nshape = \"box\"\nhalf_extents = [0.5, 0.05, 0.5]\n";
    let placed = |table: &str| format!("{floor}[colliders.placement]\n{table}");
    parse(
        true,
        &placed("center = { min = [0.0, -0.3, 0.0], max = [0.0, -0.1, 0.0] }\ntilt = [0.0, 0.2]\n"),
    )
    .unwrap();
    let e = parse(true, &placed("tilt = [0.0, 0.2]\n")).unwrap_err();
    assert!(e.to_string().contains("center"), "{e}");
    refused(
        &placed("center = { min = [0.0, -0.1, 0.0], max = [0.0, -0.3, 0.0] }\n"),
        "colliders[0].placement.center.max",
    );
    refused(
        &placed("center = { min = [0.0, -0.3, 0.0], max = [0.0, -0.1, 0.0] }\ntilt = [0.3, 0.2]\n"),
        "colliders[0].placement.tilt",
    );
    refused(
        &placed("center = { min = [0.0, -0.3, 0.0], max = [0.0, -0.1, 0.0] }\ntilt = [0.0, 2.0]\n"),
        "colliders[0].placement.tilt",
    );
    refused(
        &format!(
            "{}[colliders.placement]\ncenter = {{ min = [0.0, 0.2, 0.0], max = [0.0, 0.3, 0.0] }}\n",
            motion("")
        ),
        "colliders[0].placement",
    );
    // Too many.
    let many = capsule.repeat(crate::scene::MAX_COLLIDERS + 1);
    refused(&many, "colliders");
    // Unknown fields are refused by the reader, at their line.
    assert!(parse(true, "[[colliders]]\nshape = \"sphere\"\nradius = 0.1\ncolour = 1\n").is_err());
    assert!(parse(true, "[[colliders]]\nshape = \"cone\"\nradius = 0.1\n").is_err());
}

#[test]
fn colliders_start_parked_far_above_the_body() {
    let scene = parse(true, "[[colliders]]\nshape = \"sphere\"\nradius = 0.02\n").unwrap();
    let built = scene.build().unwrap();
    let barrier = built.simulator.collider_barrier().unwrap();
    assert_eq!(barrier.colliders().len(), 1);
    let center = barrier.colliders()[0].pose.center;
    let diagonal = built.mesh.rest_diagonal();
    assert!(
        (center.y - 0.05 - PARKED_DIAGONALS * diagonal).abs() < 1e-12,
        "{center:?}"
    );
    assert!(barrier.min_distance(built.simulator.positions()) > 5.0 * diagonal);
}

#[test]
fn a_scene_with_colliders_writes_back_to_the_same_tables() {
    let text = "[[colliders]]\nname = \"finger\"\nshape = \"capsule\"\nradius = 0.01\nlength = 0.05\n\
                rotation = [0.0, 0.0, 0.5]\n[colliders.motion]\nspeed = [0.1, 0.2]\n\
                region = { min = [0.0, 0.05, 0.0], max = [0.1, 0.12, 0.1] }\nhold_frames = [2, 4]\n";
    let scene = parse(true, text).unwrap();
    let written = toml::to_string(&scene).unwrap();
    let again = Scene::parse(&written, Path::new("poke-test.toml")).unwrap();
    assert_eq!(again.colliders, scene.colliders);
    assert_eq!(again.colliders[0].name_or_default(0), "finger");
    assert_eq!(
        parse(true, "[[colliders]]\nshape = \"sphere\"\nradius = 0.1\n")
            .unwrap()
            .colliders[0]
            .name_or_default(3),
        "collider-3"
    );
}
