//! Per-element materials from mesh file attributes: a TetGen bar whose halves carry region
//! attributes 1 and 2, a MEDIT file's element references, and the warnings and errors.

use mochi_sim::material::ElementMaterial;
use mochi_sim::mesh::io::{load, MeshKind};
use mochi_sim::{Location, Scene};

mod support;
use support::{build, fixture_path, static_tip_deflection};

/// The two-material bar scene, `from` replaced by `to` (which must apply).
fn bar(from: &str, to: &str) -> String {
    let text = include_str!("fixtures/two-material-bar.toml");
    let patched = text.replace(from, to);
    assert!(from.is_empty() || patched != text, "replacement of {from} applies");
    patched
}

fn material(youngs: f64) -> ElementMaterial {
    ElementMaterial {
        youngs,
        poisson: 0.3,
        density: 1000.0,
    }
}

#[test]
fn tetgen_region_attributes_are_read_and_kept_by_normalize_and_scale() {
    let mesh = load(&fixture_path("data/two-material-bar.ele"), MeshKind::Auto).unwrap();
    let attributes = mesh.attributes.clone().expect("the .ele file has attributes");
    assert_eq!(attributes.len(), 36);
    assert_eq!(attributes, [vec![1; 18], vec![2; 18]].concat());
    assert_eq!(mesh.normalized().attributes.as_ref(), Some(&attributes));
    assert_eq!(mesh.scaled(&[-1.0, 2.0, 1.0]).attributes, Some(attributes));
}

#[test]
fn attribute_regions_set_per_element_materials() {
    let built = build(&bar("", ""));
    assert!(built.warnings.is_empty(), "{:?}", built.warnings);
    let materials = built.scene.element_materials(&built.mesh).unwrap();
    let attributes = built.mesh.attributes.as_ref().unwrap();
    for (m, a) in materials.iter().zip(attributes) {
        let expected = if *a == 1 { material(1e7) } else { material(1e6) };
        assert_eq!(*m, expected);
    }
}

#[test]
fn a_stiff_root_half_sags_less_than_a_soft_one() {
    let deflection = |text: &str| static_tip_deflection(&mut build(text), 1);
    let all_soft = deflection(&bar("attribute = 1\nyoungs = 1e7", "attribute = 1"));
    let all_stiff = deflection(&bar("attribute = 2\n", "attribute = 2\nyoungs = 1e7\n"));
    let stiff_root = deflection(&bar("", ""));
    let stiff_tip = deflection(&bar(
        "attribute = 1\nyoungs = 1e7\n[[material.regions]]\nattribute = 2\n",
        "attribute = 1\n[[material.regions]]\nattribute = 2\nyoungs = 1e7\n",
    ));
    eprintln!(
        "tip deflections: soft {all_soft:e}, stiff {all_stiff:e}, stiff root {stiff_root:e}, stiff tip {stiff_tip:e}"
    );
    assert!(all_soft < 0.0, "the bar sags");
    // Ten times stiffer, ten times less deflection (small strains).
    assert!((all_soft / all_stiff - 10.0).abs() < 0.1, "{all_soft} vs {all_stiff}");
    // The bending moment is largest at the clamp: the root half governs the deflection.
    assert!(all_stiff > stiff_root && stiff_root > stiff_tip && stiff_tip > all_soft);
    // The attribute region is the same as a box around the root half.
    let by_box = deflection(&bar(
        "attribute = 1\n",
        "box = { min = [-1.0, -1.0, -1.0], max = [0.3, 1.0, 1.0] }\n",
    ));
    assert!(
        (by_box - stiff_root).abs() <= 1e-12 * stiff_root.abs(),
        "{by_box} vs {stiff_root}"
    );
}

#[test]
fn attributes_no_region_uses_are_a_warning() {
    let text = bar("[[material.regions]]\nattribute = 2\ndensity = 1000.0\n", "");
    let built = build(&text);
    assert_eq!(built.warnings.len(), 1, "{:?}", built.warnings);
    let warning = &built.warnings[0];
    assert!(
        warning.contains("two-material-bar.node") && warning.contains("attribute 2 is used by no"),
        "{warning}"
    );
    // Without regions, both values are named.
    let plain = bar(
        "[[material.regions]]\nattribute = 1\nyoungs = 1e7\n[[material.regions]]\nattribute = 2\ndensity = 1000.0\n",
        "",
    );
    let built = build(&plain);
    assert!(
        built.warnings[0].contains("attributes 1, 2 are used by no"),
        "{:?}",
        built.warnings
    );
}

/// The error of building `text`, which must name `field`.
fn field_error(text: &str, field: &str) -> String {
    let path = fixture_path("fixtures/bad.toml");
    let error = Scene::parse(text, &path)
        .and_then(|s| s.build())
        .err()
        .expect("the scene is refused");
    assert_eq!(error.location, Location::Field(field.into()), "{error}");
    error.to_string()
}

#[test]
fn bad_regions_name_the_field() {
    let msg = field_error(
        &bar("attribute = 2\n", "attribute = 7\n"),
        "material.regions[1].attribute",
    );
    assert!(
        msg.contains("no element has attribute 7") && msg.contains("1, 2"),
        "{msg}"
    );
    let both = bar(
        "attribute = 1\n",
        "attribute = 1\nbox = { min = [0.0, 0.0, 0.0], max = [1.0, 1.0, 1.0] }\n",
    );
    let msg = field_error(&both, "material.regions[0]");
    assert!(msg.contains("both `box` and `attribute`"), "{msg}");
    let msg = field_error(&bar("attribute = 1\n", ""), "material.regions[0]");
    assert!(msg.contains("needs `box`"), "{msg}");
    // A procedural mesh has no attributes.
    let boxed = bar(
        "type = \"file\"\npath = \"../data/two-material-bar.node\"",
        "type = \"box\"\nmin = [0.0, 0.0, 0.0]\nmax = [0.6, 0.1, 0.1]\ncells = [6, 1, 1]",
    );
    let msg = field_error(&boxed, "material.regions[0].attribute");
    assert!(msg.contains("no element attributes"), "{msg}");
}

#[test]
fn medit_element_references_select_regions() {
    // The peer's beam: every tet has reference 0.
    let path = fixture_path("../../data/beam365.mesh");
    let mesh = load(&path, MeshKind::Solid).unwrap();
    assert_eq!(mesh.attributes, Some(vec![0; mesh.num_elements()]));
    let text = bar(
        "path = \"../data/two-material-bar.node\"",
        "path = \"../../../data/beam365.mesh\"\nnormalize = true",
    )
    .replace("attribute = 1\n", "attribute = 0\n")
    .replace("[[material.regions]]\nattribute = 2\ndensity = 1000.0\n", "");
    let built = build(&text);
    assert!(
        built.warnings.is_empty(),
        "one reference, homogeneous: {:?}",
        built.warnings
    );
    let materials = built.scene.element_materials(&built.mesh).unwrap();
    assert_eq!(materials, vec![material(1e7); mesh.num_elements()]);
    let msg = field_error(
        &text.replace("attribute = 0\n", "attribute = 1\n"),
        "material.regions[0].attribute",
    );
    assert!(
        msg.contains("no element has attribute 1; the mesh's attributes are 0"),
        "{msg}"
    );
}
