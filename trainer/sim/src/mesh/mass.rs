//! The mass a mesh carries at its vertices.

use super::{Elements, Mesh};

/// Lumped vertex masses: each element gives an equal share of its mass to its vertices.
///
/// Tets use `density * volume / 4`, 2D triangles `density * area / 3` (unit thickness),
/// cloth `density * thickness * area / 3`, rods `density * pi r^2 * length / 2`.
/// `densities` holds one value, or one per element (per strand for rods).
pub(crate) fn lumped_masses(mesh: &Mesh, densities: &[f64], thickness: f64, radius: f64) -> Vec<f64> {
    let n = mesh.num_vertices();
    let x = &mesh.rest;
    let density = |e: usize| densities[if densities.len() == 1 { 0 } else { e }];
    let mut m = vec![0.0; n];
    let p3 = |v: usize| [x[3 * v], x[3 * v + 1], x[3 * v + 2]];
    match &mesh.elements {
        Elements::Tets(tets) => {
            for (e, t) in tets.iter().enumerate() {
                let vol = crate::energy::tet::signed_volume(t.map(p3)).abs();
                t.iter().for_each(|&v| m[v] += density(e) * vol / 4.0);
            }
        }
        Elements::Triangles(tris) => {
            for (e, t) in tris.iter().enumerate() {
                let area = crate::energy::tri2d::signed_area(t.map(|v| [x[2 * v], x[2 * v + 1]])).abs();
                t.iter().for_each(|&v| m[v] += density(e) * area / 3.0);
            }
        }
        Elements::Shell(tris) => {
            for (e, t) in tris.iter().enumerate() {
                let [a, b, c] = t.map(p3);
                let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
                let w = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
                let cr = [
                    u[1] * w[2] - u[2] * w[1],
                    u[2] * w[0] - u[0] * w[2],
                    u[0] * w[1] - u[1] * w[0],
                ];
                let area = 0.5 * (cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]).sqrt();
                t.iter().for_each(|&v| m[v] += density(e) * thickness * area / 3.0);
            }
        }
        Elements::Rods(strands) => {
            let section = std::f64::consts::PI * radius * radius;
            for (k, strand) in strands.iter().enumerate() {
                for w in strand.windows(2) {
                    let (a, b) = (p3(w[0]), p3(w[1]));
                    let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2) + (b[2] - a[2]).powi(2)).sqrt();
                    let share = density(k) * section * len / 2.0;
                    m[w[0]] += share;
                    m[w[1]] += share;
                }
            }
        }
    }
    m
}
