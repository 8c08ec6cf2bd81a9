//! Tests of the contact primitives, one file per source concept, with finite-difference
//! checks through the energy module's helpers.

mod barrier;
mod broad_phase;
mod ccd;
mod ccd_near_parallel;
mod closest_point;
mod collider;
mod degenerate;
mod distance;
mod friction;
mod intersection;
mod max_step;
mod potentials;
mod surface;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::energy::fd::{check_stencil, FdReport};
use crate::energy::{Local, StencilEnergy, Want};

/// A single stencil made of a closure, so free contact functions run through the
/// energy module's finite-difference checks.
pub struct Stencil<F> {
    pub dim: usize,
    pub verts: Vec<usize>,
    pub f: F,
}

impl<F: Fn(&[f64], Want, &mut Local) -> f64 + Send + Sync> StencilEnergy for Stencil<F> {
    fn name(&self) -> &'static str {
        "contact test stencil"
    }
    fn dim(&self) -> usize {
        self.dim
    }
    fn len(&self) -> usize {
        1
    }
    fn stencil(&self, _: usize) -> &[usize] {
        &self.verts
    }
    fn eval(&self, _: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        (self.f)(x, want, out)
    }
}

/// Finite-difference report of `f` at `x` (`x.len() / dim` vertices).
pub fn fd<F: Fn(&[f64], Want, &mut Local) -> f64 + Send + Sync>(dim: usize, x: &[f64], h: f64, f: F) -> FdReport {
    let s = Stencil {
        dim,
        verts: (0..x.len() / dim).collect(),
        f,
    };
    check_stencil(&s, 0, x, h)
}

/// Asserts a finite-difference report is within `tol`.
pub fn assert_fd(r: FdReport, tol: f64, what: &str) {
    assert!(
        r.grad_error < tol && r.hess_error < tol,
        "{what}: gradient error {:.3e}, Hessian error {:.3e}",
        r.grad_error,
        r.hess_error
    );
}

/// `n` uniform numbers in `[-1, 1)`.
pub fn random_vec(rng: &mut ChaCha8Rng, n: usize) -> Vec<f64> {
    (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
}

/// A seeded generator.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}
