use super::broad_phase::square_2d;
use crate::contact::ccd::{max_step, AdditiveCcd};
use crate::contact::intersection::has_intersections;
use crate::contact::ContactSurface;
use crate::mesh::procedural::{box_tets, cloth_grid};
use crate::mesh::Mesh;

fn lerp(x0: &[f64], x1: &[f64], t: f64) -> Vec<f64> {
    x0.iter().zip(x1).map(|(a, b)| a + t * (b - a)).collect()
}

/// Two meshes in one position vector: `a` at rest and `b` shifted by `shift`.
fn pair(a: &Mesh, b: &Mesh, shift: &[f64]) -> (ContactSurface, Vec<f64>) {
    let mut surface = ContactSurface::of_mesh(a);
    surface.append(&ContactSurface::of_mesh(b), a.rest.len() / a.dim);
    let dim = a.dim;
    let x = a
        .rest
        .iter()
        .copied()
        .chain(b.rest.iter().enumerate().map(|(i, v)| v + shift[i % dim]))
        .collect();
    (surface, x)
}

/// Moves the vertices of the second mesh (from vertex `split` on) by `by`.
fn moved(x: &[f64], dim: usize, split: usize, by: &[f64]) -> Vec<f64> {
    x.iter()
        .enumerate()
        .map(|(i, v)| if i >= split * dim { v + by[i % dim] } else { *v })
        .collect()
}

#[test]
fn two_boxes_thrown_at_each_other_stop_before_touching() {
    let a = box_tets([0.0; 3], [1.0; 3], [2, 2, 2]).unwrap();
    let (surface, x0) = pair(&a, &a, &[1.5, 0.3, -0.2]);
    let split = a.rest.len() / 3;
    // Box a moves +2 in x, box b -2: they would meet at t = 0.5 / 4 and pass through.
    let x1: Vec<f64> = moved(&x0, 3, 0, &[2.0, 0.0, 0.0]);
    let x1 = moved(&x1, 3, split, &[-4.0, 0.0, 0.0]);
    let t = max_step(&surface, &x0, &x1, 0.0, &AdditiveCcd::default());
    assert!(t < 0.125 && t > 0.8 * 0.125, "max step {t}");
    assert!(!has_intersections(&surface, &lerp(&x0, &x1, t)));
    assert!(
        has_intersections(&surface, &lerp(&x0, &x1, 0.2)),
        "the full step passes through"
    );
    // With a minimum separation the step stops earlier.
    let t_sep = max_step(&surface, &x0, &x1, 0.1, &AdditiveCcd::default());
    assert!(t_sep < t && t_sep > 0.8 * 0.1, "max step {t_sep}");
    // Moving apart: the full step.
    let away = moved(&x0, 3, split, &[3.0, 1.0, 0.0]);
    assert_eq!(max_step(&surface, &x0, &away, 0.0, &AdditiveCcd::default()), 1.0);
}

#[test]
fn a_box_tunnelling_through_a_sheet_in_one_step_is_stopped() {
    // Both ends of the step are free of intersections; the middle is not.
    let sheet = cloth_grid(
        [2.0, 2.0],
        [5, 5],
        [-0.5, -0.5, 0.0],
        ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
    )
    .unwrap();
    let cube = box_tets([0.0; 3], [0.4; 3], [1, 1, 1]).unwrap();
    let (surface, x0) = pair(&sheet, &cube, &[0.3, 0.3, 1.0]);
    let split = sheet.rest.len() / 3;
    let x1 = moved(&x0, 3, split, &[0.0, 0.0, -100.0]);
    assert!(!has_intersections(&surface, &x0) && !has_intersections(&surface, &x1));
    let t = max_step(&surface, &x0, &x1, 0.0, &AdditiveCcd::default());
    // The cube's bottom reaches the sheet at t = 1 / 100.
    assert!(t < 0.01 && t > 0.8 * 0.01, "max step {t}");
    assert!(!has_intersections(&surface, &lerp(&x0, &x1, t)));
}

#[test]
fn two_squares_thrown_at_each_other_stop_before_touching_in_2d() {
    let a = square_2d(2, [0.0, 0.0], 1.0);
    let (surface, x0) = pair(&a, &a, &[1.5, 0.5]);
    let split = a.rest.len() / 2;
    let x1 = moved(&x0, 2, split, &[-3.0, 0.0]);
    let t = max_step(&surface, &x0, &x1, 0.0, &AdditiveCcd::default());
    assert!(t < 0.5 / 3.0 && t > 0.8 * 0.5 / 3.0, "max step {t}");
    assert!(!has_intersections(&surface, &lerp(&x0, &x1, t)));
    assert!(has_intersections(&surface, &lerp(&x0, &x1, 0.5)));
    let mut bad = x1.clone();
    bad[0] = f64::NAN;
    assert_eq!(max_step(&surface, &x0, &bad, 0.0, &AdditiveCcd::default()), 0.0);
}

#[test]
fn a_folded_flap_passing_through_its_own_sheet_is_stopped() {
    // A 2 x 1 sheet whose last column of vertices is folded back over the sheet, 0.3 above
    // it, and pushed to 0.3 below: the flap lies in the sheet at t = 1/2 and under it at the
    // end, so only self-contact CCD sees the pass.
    let sheet = cloth_grid([2.0, 1.0], [5, 3], [0.0; 3], ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])).unwrap();
    let surface = ContactSurface::of_mesh(&sheet);
    let fold = |z: f64| -> Vec<f64> {
        let mut x = sheet.rest.clone();
        for j in 0..3 {
            let v = 4 + 5 * j;
            x[3 * v] = 0.5;
            x[3 * v + 2] = z;
        }
        x
    };
    let (x0, x1) = (fold(0.3), fold(-0.3));
    assert!(!has_intersections(&surface, &x0) && !has_intersections(&surface, &x1));
    assert!(has_intersections(&surface, &lerp(&x0, &x1, 0.5)));
    let t = max_step(&surface, &x0, &x1, 0.0, &AdditiveCcd::default());
    assert!(t < 0.5 && t > 0.2, "max step {t}");
    assert!(!has_intersections(&surface, &lerp(&x0, &x1, t)));
}
