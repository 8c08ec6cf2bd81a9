//! Inertia: the kinetic part of the incremental potential, sum_i m_i / 2 |x_i - xhat_i|^2,
//! and lumped vertex masses.

use super::{Local, StencilEnergy, Want};
use crate::mesh::{Elements, Mesh};

/// Per-vertex inertia term `m_i / 2 |x_i - xhat_i|^2` around predicted positions `xhat`.
#[derive(Clone, Debug)]
pub struct Inertia {
    dim: usize,
    masses: Vec<f64>,
    target: Vec<f64>,
    ids: Vec<usize>,
}

impl Inertia {
    /// Inertia with the given per-vertex masses; the prediction starts at zero.
    pub fn new(dim: usize, masses: Vec<f64>) -> Self {
        let n = masses.len();
        Inertia {
            dim,
            target: vec![0.0; n * dim],
            ids: (0..n).collect(),
            masses,
        }
    }
    /// Per-vertex masses.
    pub fn masses(&self) -> &[f64] {
        &self.masses
    }
    /// Sets the predicted positions `xhat` (flat, `dim` per vertex).
    pub fn set_target(&mut self, xhat: &[f64]) {
        self.target.copy_from_slice(xhat);
    }
    /// The predicted positions `xhat`.
    pub fn target(&self) -> &[f64] {
        &self.target
    }
    /// Kinetic energy 1/2 v^T M v of the velocities `v`.
    pub fn kinetic_energy(&self, v: &[f64]) -> f64 {
        v.chunks_exact(self.dim)
            .zip(&self.masses)
            .map(|(vi, m)| 0.5 * m * vi.iter().map(|c| c * c).sum::<f64>())
            .sum()
    }
}

impl StencilEnergy for Inertia {
    fn name(&self) -> &'static str {
        "inertia"
    }
    fn dim(&self) -> usize {
        self.dim
    }
    fn len(&self) -> usize {
        self.masses.len()
    }
    fn stencil(&self, s: usize) -> &[usize] {
        &self.ids[s..s + 1]
    }
    fn eval(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        let d = self.dim;
        let m = self.masses[s];
        let target = &self.target[s * d..(s + 1) * d];
        let mut value = 0.0;
        for i in 0..d {
            let r = x[i] - target[i];
            value += 0.5 * m * r * r;
            if want.gradient() {
                out.grad[i] = m * r;
            }
        }
        if want.hessian().is_some() {
            out.clear_hessian(d);
            for i in 0..d {
                out.hess[i * d + i] = m;
            }
        }
        value
    }
}

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
                let vol = super::tet::signed_volume(t.map(p3)).abs();
                t.iter().for_each(|&v| m[v] += density(e) * vol / 4.0);
            }
        }
        Elements::Triangles(tris) => {
            for (e, t) in tris.iter().enumerate() {
                let area = super::tri2d::signed_area(t.map(|v| [x[2 * v], x[2 * v + 1]])).abs();
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::fd;

    #[test]
    fn inertia_derivatives_match_finite_differences() {
        let mut inertia = Inertia::new(3, vec![1.0, 2.5, 0.3]);
        inertia.set_target(&[0.1, 0.2, 0.3, -1.0, 0.5, 2.0, 0.0, 0.0, 1.0]);
        let x = [0.4, -0.2, 0.9, -0.3, 0.1, 1.0, 0.7, 0.2, -0.5];
        fd::assert_all_stencils(&inertia, &x, 1e-6, 1e-7);
        let v = [1.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0];
        assert!((inertia.kinetic_energy(&v) - (0.5 + 0.5 * 2.5 * 4.0)).abs() < 1e-12);
    }
}
