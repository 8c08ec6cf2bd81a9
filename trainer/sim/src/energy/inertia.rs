//! Inertia: the kinetic part of the incremental potential, sum_i m_i / 2 |x_i - xhat_i|^2
//! (the masses are lumped by [`crate::mesh::lumped_masses`]).

use super::{Local, StencilEnergy, Want};

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
