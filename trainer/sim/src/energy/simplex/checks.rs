//! Checks shared by the tests of [`crate::energy::tet`] and [`crate::energy::tri2d`]: each
//! takes a single-element energy (stencil 0 = vertices `0..=D`) and its flat rest positions.

use nalgebra::{DMatrix, DVector};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use crate::energy::fd::check_stencil;
use crate::energy::psd::min_eigenvalue;
use crate::energy::{Local, StencilEnergy, Want};

/// Positions `F X + t` of the rest positions `X` (flat, `dim` per vertex).
pub fn deform(rest: &[f64], f: &DMatrix<f64>, t: &DVector<f64>) -> Vec<f64> {
    let dim = f.nrows();
    rest.chunks_exact(dim)
        .flat_map(|p| (f * DVector::from_column_slice(p) + t).data.as_vec().clone())
        .collect()
}

/// A random rotation (orthogonal, determinant +1).
pub fn random_rotation(dim: usize, rng: &mut ChaCha8Rng) -> DMatrix<f64> {
    let m = DMatrix::from_fn(dim, dim, |_, _| rng.random_range(-1.0..1.0));
    let mut q = m.qr().q();
    if q.determinant() < 0.0 {
        q.column_mut(0).neg_mut();
    }
    q
}

/// A random translation.
pub fn random_translation(dim: usize, rng: &mut ChaCha8Rng) -> DVector<f64> {
    DVector::from_fn(dim, |_, _| rng.random_range(-2.0..2.0))
}

/// The `k`-th of a family of random deformation gradients cycling through mild,
/// strongly compressed, inverted (det < 0) and arbitrary (large, either sign) ones.
pub fn random_deformation(k: usize, dim: usize, rng: &mut ChaCha8Rng) -> DMatrix<f64> {
    let mut stretches =
        |lo: f64, hi: f64| DMatrix::from_diagonal(&DVector::from_fn(dim, |_, _| rng.random_range(lo..hi)));
    let mut sigma = match k % 4 {
        0 => stretches(0.7, 1.4),
        1 => stretches(0.02, 0.3),
        2 => stretches(0.05, 1.5),
        _ => stretches(0.01, 3.0),
    };
    if k % 4 == 2 || (k % 4 == 3 && rng.random_bool(0.5)) {
        let i = rng.random_range(0..dim);
        sigma[(i, i)] = -sigma[(i, i)];
    }
    random_rotation(dim, rng) * sigma * random_rotation(dim, rng)
}

/// Central differences (step `h`) of value and gradient against the analytic
/// gradient and exact Hessian over `count` random deformed states; returns the largest
/// relative gradient and Hessian errors (see [`check_stencil`]).
pub fn max_fd_errors(
    energy: &dyn StencilEnergy,
    rest: &[f64],
    count: usize,
    h: f64,
    rng: &mut ChaCha8Rng,
) -> (f64, f64) {
    let dim = energy.dim();
    let (mut grad_error, mut hess_error) = (0.0f64, 0.0f64);
    for k in 0..count {
        let f = random_deformation(k, dim, rng);
        let x = deform(rest, &f, &random_translation(dim, rng));
        let r = check_stencil(energy, 0, &x, h);
        grad_error = grad_error.max(r.grad_error);
        hess_error = hess_error.max(r.hess_error);
    }
    (grad_error, hess_error)
}

/// Asserts zero energy and gradient at rest, and that the energy of random deformed
/// states does not change under a random rotation and translation. `scale` is the
/// element's typical energy (Young's modulus times rest measure).
pub fn assert_rest_and_rigid_invariance(energy: &dyn StencilEnergy, rest: &[f64], scale: f64, rng: &mut ChaCha8Rng) {
    let dim = energy.dim();
    let n = rest.len();
    let mut out = Local::default();
    let at_rest = energy.eval(0, rest, Want::Gradient, &mut out);
    assert!(at_rest.abs() <= 1e-14 * scale, "energy at rest {at_rest:e}");
    let g_max = out.grad[..n].iter().fold(0.0f64, |m, g| m.max(g.abs()));
    assert!(g_max <= 1e-13 * scale, "gradient at rest {g_max:e}");
    for k in 0..64 {
        let f = random_deformation(k, dim, rng);
        let x = deform(rest, &f, &random_translation(dim, rng));
        let moved = deform(rest, &(random_rotation(dim, rng) * &f), &random_translation(dim, rng));
        let e = energy.eval(0, &x, Want::Value, &mut out);
        let e_moved = energy.eval(0, &moved, Want::Value, &mut out);
        assert!(
            (e - e_moved).abs() <= 1e-11 * e.abs().max(scale),
            "state {k}: energy {e:e} becomes {e_moved:e} after a rigid motion"
        );
    }
}

/// Hessians at `x`: (exact, projected, number of local dofs).
fn hessians(energy: &dyn StencilEnergy, x: &[f64]) -> (Vec<f64>, Vec<f64>, usize) {
    let n = x.len();
    let mut out = Local::default();
    energy.eval(0, x, Want::Hessian { project: false }, &mut out);
    let exact = out.hess[..n * n].to_vec();
    energy.eval(0, x, Want::Hessian { project: true }, &mut out);
    (exact, out.hess[..n * n].to_vec(), n)
}

/// Asserts that projected Hessians are PSD (min eigenvalue >= -1e-9 times the largest
/// entry) on random states, that some of those states had indefinite exact Hessians,
/// and that near rest under a small uniform stretch, where the exact Hessian is PSD,
/// projection returns it unchanged (to 1e-12 times the largest entry).
pub fn assert_projection(energy: &dyn StencilEnergy, rest: &[f64], rng: &mut ChaCha8Rng) {
    let dim = energy.dim();
    let max_abs = |h: &[f64]| h.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut indefinite = 0;
    for k in 0..200 {
        let f = random_deformation(k, dim, rng);
        let x = deform(rest, &f, &random_translation(dim, rng));
        let (exact, projected, n) = hessians(energy, &x);
        let scale = max_abs(&exact);
        if min_eigenvalue(&exact, n) < -1e-6 * scale {
            indefinite += 1;
        }
        let min = min_eigenvalue(&projected, n);
        assert!(min >= -1e-9 * scale, "state {k}: projected min eigenvalue {min:e}");
    }
    assert!(indefinite > 20, "only {indefinite} indefinite exact Hessians");
    for _ in 0..20 {
        let f = random_rotation(dim, rng) * 1.01;
        let x = deform(rest, &f, &random_translation(dim, rng));
        let (exact, projected, n) = hessians(energy, &x);
        let scale = max_abs(&exact);
        let min = min_eigenvalue(&exact, n);
        assert!(min >= -1e-9 * scale, "exact Hessian near rest: min eigenvalue {min:e}");
        let diff = exact
            .iter()
            .zip(&projected)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(diff <= 1e-12 * scale, "projection changed a PSD Hessian by {diff:e}");
    }
}

/// Asserts that under small uniaxial and pure-shear strains `eps` (along random
/// directions) the energy matches linear elasticity,
/// `measure * (lambda/2 tr(eps)^2 + mu eps:eps)`, to relative 1e-3.
pub fn assert_linear_limit(
    energy: &dyn StencilEnergy,
    rest: &[f64],
    measure: f64,
    mu: f64,
    lambda: f64,
    rng: &mut ChaCha8Rng,
) {
    let dim = energy.dim();
    let mut out = Local::default();
    for strain in [1e-4, -1e-4, 3e-4] {
        let r = random_rotation(dim, rng);
        let (e0, e1) = (r.column(0), r.column(1));
        let uniaxial = e0 * e0.transpose() * strain;
        let shear = (e0 * e1.transpose() + e1 * e0.transpose()) * strain;
        for eps in [uniaxial, shear] {
            let f = DMatrix::identity(dim, dim) + &eps;
            let x = deform(rest, &f, &random_translation(dim, rng));
            let e = energy.eval(0, &x, Want::Value, &mut out);
            let linear = measure * (0.5 * lambda * eps.trace().powi(2) + mu * eps.norm_squared());
            assert!(
                (e - linear).abs() <= 1e-3 * linear,
                "strain {eps}: energy {e:e}, linear elasticity {linear:e}"
            );
        }
    }
}
