use super::{random_vec, rng};
use crate::contact::broad_phase::aabb::Aabb;
use crate::contact::broad_phase::spatial_hash::*;
use crate::contact::broad_phase::Candidates;
use crate::contact::distance::*;
use crate::contact::ContactSurface;
use crate::energy::{Local, Want};
use crate::mesh::procedural::box_tets;
use crate::mesh::{Elements, Mesh};
use rand::Rng;

/// A 2D square of `n` by `n` cells, each split in two counter-clockwise triangles.
pub fn square_2d(n: usize, origin: [f64; 2], size: f64) -> Mesh {
    let idx = |i: usize, j: usize| i + (n + 1) * j;
    let rest = (0..=n)
        .flat_map(|j| (0..=n).flat_map(move |i| [i, j]))
        .map(|k| k as f64 * size / n as f64)
        .enumerate()
        .map(|(c, v)| v + origin[c % 2])
        .collect();
    let tris = (0..n)
        .flat_map(|j| {
            (0..n).flat_map(move |i| {
                [
                    [idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)],
                    [idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)],
                ]
            })
        })
        .collect();
    Mesh {
        dim: 2,
        rest,
        elements: Elements::Triangles(tris),
        attributes: None,
    }
}

/// Positions of `surface`'s mesh jittered by up to `amount` per coordinate.
fn jitter(x: &[f64], amount: f64, rng: &mut rand_chacha::ChaCha8Rng) -> Vec<f64> {
    x.iter().map(|v| v + amount * rng.random_range(-1.0..1.0)).collect()
}

fn surfaces() -> Vec<(ContactSurface, Vec<f64>)> {
    let cube = box_tets([0.0; 3], [1.0; 3], [3, 3, 3]).unwrap();
    let square = square_2d(4, [0.0, 0.0], 1.0);
    vec![
        (ContactSurface::of_mesh(&cube), cube.rest.clone()),
        (ContactSurface::of_mesh(&square), square.rest.clone()),
    ]
}

#[test]
fn grid_pairs_equal_brute_force_on_random_boxes() {
    let mut rng = rng(11);
    for trial in 0..30 {
        let n = 1 + trial * 7;
        let scale = [1e-3, 0.05, 0.3, 2.0][trial % 4];
        let make = |rng: &mut rand_chacha::ChaCha8Rng, k: usize| -> Vec<Aabb> {
            (0..k)
                .map(|_| {
                    let c = random_vec(rng, 3);
                    let e: Vec<f64> = (0..3).map(|_| scale * rng.random_range(0.0..1.0f64).powi(3)).collect();
                    Aabb {
                        min: [c[0], c[1], c[2]],
                        max: [c[0] + e[0], c[1] + e[1], c[2] + e[2]],
                    }
                })
                .collect()
        };
        let (a, b) = (make(&mut rng, n), make(&mut rng, n / 2 + 1));
        let keep = |i: usize, j: usize| !(i + j).is_multiple_of(5);
        assert_eq!(
            overlapping_pairs(&a, &b, keep),
            overlapping_pairs_brute_force(&a, &b, keep),
            "trial {trial}"
        );
        assert_eq!(
            overlapping_self_pairs(&a, keep),
            overlapping_self_pairs_brute_force(&a, keep),
            "trial {trial}"
        );
    }
}

/// A fine mesh's boxes beside a few boxes far longer than the grid's cells (an obstacle's
/// faces): these are tested against every box, and the pairs are still each pair once.
#[test]
fn grid_pairs_with_long_boxes_equal_brute_force() {
    let mut rng = rng(12);
    let small = |rng: &mut rand_chacha::ChaCha8Rng, k: usize| -> Vec<Aabb> {
        (0..k)
            .map(|_| {
                let c = random_vec(rng, 3);
                Aabb {
                    min: [c[0], c[1], c[2]],
                    max: [c[0] + 0.02, c[1] + 0.02, c[2] + 0.02],
                }
            })
            .collect()
    };
    for trial in 0..6 {
        let (mut a, mut b) = (small(&mut rng, 400), small(&mut rng, 300));
        for k in 0..=trial {
            let y = rng.random_range(-1.0..1.0);
            let slab = Aabb {
                min: [-2.0, y, -2.0],
                max: [2.0, y + 0.3, 2.0],
            };
            // Long boxes in either set, at varied positions among the small ones.
            if k % 2 == 0 {
                a.insert(k * 37 % a.len(), slab);
            } else {
                b.insert(k * 53 % b.len(), slab);
            }
        }
        let keep = |i: usize, j: usize| !(i + 2 * j).is_multiple_of(7);
        let grid = overlapping_pairs(&a, &b, keep);
        assert_eq!(grid, overlapping_pairs_brute_force(&a, &b, keep), "trial {trial}");
        assert!(grid.len() > 20, "trial {trial}: the slabs meet many boxes");
        assert_eq!(
            overlapping_self_pairs(&a, keep),
            overlapping_self_pairs_brute_force(&a, keep),
            "trial {trial}"
        );
    }
}

#[test]
fn non_finite_boxes_overlap_nothing() {
    let unit = Aabb {
        min: [0.0; 3],
        max: [1.0; 3],
    };
    let nan = Aabb {
        min: [f64::NAN, 0.0, 0.0],
        max: [1.0; 3],
    };
    assert_eq!(overlapping_self_pairs(&[unit, nan, unit], |_, _| true), vec![[0, 2]]);
}

#[test]
fn candidates_equal_brute_force_on_random_configurations() {
    let mut rng = rng(12);
    for (surface, rest) in surfaces() {
        for trial in 0..10 {
            let x = jitter(&rest, 0.1 * (trial % 4) as f64, &mut rng);
            let x1 = jitter(&x, 0.5, &mut rng);
            for dhat in [0.0, 0.05, 0.3] {
                let within = Candidates::within(&surface, &x, dhat);
                assert_eq!(within, Candidates::within_brute_force(&surface, &x, dhat));
                let swept = Candidates::swept(&surface, &x, &x1, dhat);
                assert_eq!(swept, Candidates::swept_brute_force(&surface, &x, &x1, dhat));
                assert!(swept.len() >= within.len());
            }
            let within = Candidates::within(&surface, &x, 0.3);
            assert!(!within.is_empty());
            if surface.dim == 2 {
                assert!(within.point_triangle.is_empty() && within.edge_edge.is_empty());
            } else {
                assert!(within.point_edge.is_empty());
            }
        }
    }
}

#[test]
fn every_pair_within_dhat_is_a_candidate_and_none_shares_a_vertex() {
    let mut rng = rng(13);
    let mut out = Local::default();
    for (surface, rest) in surfaces() {
        let dim = surface.dim;
        let x = jitter(&rest, 0.2, &mut rng);
        let dhat = 0.3;
        let c = Candidates::within(&surface, &x, dhat);
        let gather =
            |verts: &[usize]| -> Vec<f64> { verts.iter().flat_map(|&v| x[v * dim..(v + 1) * dim].to_vec()).collect() };
        let mut close = 0;
        for &v in &surface.vertices {
            for (fi, f) in surface.faces.iter().enumerate() {
                let d = point_triangle_distance(&gather(&[v, f[0], f[1], f[2]]), Want::Value, &mut out);
                if !f.contains(&v) && d < dhat * dhat {
                    close += 1;
                    assert!(c.point_triangle.binary_search(&[v, fi]).is_ok(), "vertex {v} face {fi}");
                }
            }
            for (ei, e) in surface.edges.iter().enumerate() {
                let d = point_edge_distance(&gather(&[v, e[0], e[1]]), dim, Want::Value, &mut out);
                if dim == 2 && !e.contains(&v) && d < dhat * dhat {
                    close += 1;
                    assert!(c.point_edge.binary_search(&[v, ei]).is_ok(), "vertex {v} edge {ei}");
                }
            }
        }
        if dim == 3 {
            for (i, a) in surface.edges.iter().enumerate() {
                for (j, b) in surface.edges.iter().enumerate().skip(i + 1) {
                    let d = edge_edge_distance(&gather(&[a[0], a[1], b[0], b[1]]), Want::Value, &mut out);
                    if !a.iter().any(|v| b.contains(v)) && d < dhat * dhat {
                        close += 1;
                        assert!(c.edge_edge.binary_search(&[i, j]).is_ok(), "edges {i} {j}");
                    }
                }
            }
        }
        assert!(close >= 5, "{close} close pairs");
        assert!(c.point_triangle.iter().all(|&[v, f]| !surface.faces[f].contains(&v)));
        assert!(c.point_edge.iter().all(|&[v, e]| !surface.edges[e].contains(&v)));
        assert!(c
            .edge_edge
            .iter()
            .all(|&[i, j]| i < j && !surface.edges[i].iter().any(|v| surface.edges[j].contains(v))));
    }
}
