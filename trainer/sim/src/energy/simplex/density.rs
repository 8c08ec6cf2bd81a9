//! The constitutive models' energy densities as functions of the deformation gradient `F`
//! (stable neo-Hookean, Saint Venant-Kirchhoff; forms and conventions in the parent
//! module's documentation), their derivatives, and the projection of their Hessians onto
//! the PSD cone.

use std::f64::consts::FRAC_1_SQRT_2;

use nalgebra::{SMatrix, SVector};

use super::DeformationGradient;
use crate::material::MaterialLaw;

/// Energy density `Psi(F)` of `model`; writes `dPsi/dF` into `grad` and `d2Psi/dF2` into
/// `hess` when given.
pub fn energy_density<const D: usize, const N: usize>(
    model: MaterialLaw,
    f: &SMatrix<f64, D, D>,
    mu: f64,
    lambda: f64,
    grad: Option<&mut SMatrix<f64, D, D>>,
    hess: Option<&mut SMatrix<f64, N, N>>,
) -> f64
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    match model {
        MaterialLaw::StableNeoHookean => stable_neo_hookean(f, mu, lambda, grad, hess),
        MaterialLaw::Stvk => stvk(f, mu, lambda, grad, hess),
    }
}

/// Projects `h = d2Psi/dF2` of `model` at `f` onto the positive semi-definite cone
/// (negative eigenvalues clamped to zero). A positive-definite `h` (a cheap Cholesky
/// test) and one with non-finite entries are left as they are; stable neo-Hookean uses
/// its analytic eigensystem, StVK a numerical eigen-decomposition.
pub fn project_density_hessian<const D: usize, const N: usize>(
    model: MaterialLaw,
    f: &SMatrix<f64, D, D>,
    mu: f64,
    lambda: f64,
    h: &mut SMatrix<f64, N, N>,
) where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    if h.iter().any(|v| !v.is_finite()) || h.cholesky().is_some() {
        return;
    }
    let analytic = match model {
        MaterialLaw::StableNeoHookean => project_stable_neo_hookean(f, mu, lambda, h),
        MaterialLaw::Stvk => false,
    };
    if !analytic {
        <SMatrix<f64, D, D> as DeformationGradient<D, N>>::clamp_negative_eigenvalues(h);
    }
}

/// Coefficient of `(J - 1)^2 / 2` in stable neo-Hookean (see the module documentation).
fn snh_volume_stiffness(mu: f64, lambda: f64) -> f64 {
    lambda + mu
}

/// `dPsi/dJ` of stable neo-Hookean at `J = j`.
fn snh_dpsi_dj(mu: f64, lambda: f64, j: f64) -> f64 {
    snh_volume_stiffness(mu, lambda) * (j - 1.0) - mu
}

/// Stable neo-Hookean density (see the module documentation for the exact form).
fn stable_neo_hookean<const D: usize, const N: usize>(
    f: &SMatrix<f64, D, D>,
    mu: f64,
    lambda: f64,
    grad: Option<&mut SMatrix<f64, D, D>>,
    hess: Option<&mut SMatrix<f64, N, N>>,
) -> f64
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    let volume_stiffness = snh_volume_stiffness(mu, lambda);
    let j = f.det();
    let psi = 0.5 * mu * (f.norm_squared() - D as f64) - mu * (j - 1.0) + 0.5 * volume_stiffness * (j - 1.0).powi(2);
    if grad.is_none() && hess.is_none() {
        return psi;
    }
    // P = mu F + dPsi/dJ cof(F).
    let psi_j = snh_dpsi_dj(mu, lambda, j);
    let cof = f.cofactor();
    if let Some(p) = grad {
        *p = f * mu + cof * psi_j;
    }
    if let Some(h) = hess {
        let g = SVector::<f64, N>::from_column_slice(cof.as_slice());
        *h = SMatrix::<f64, N, N>::identity() * mu + g * g.transpose() * volume_stiffness;
        f.add_det_hessian(psi_j, h);
    }
    psi
}

/// PSD projection of the stable neo-Hookean `h = d2Psi/dF2 = mu I + k g g^T + s d2J/dF2`
/// (`g = vec cof F`, `k` the volume stiffness, `s = dPsi/dJ`) from its analytic
/// eigensystem (Smith et al. 2019, "Analytic eigensystems for isotropic distortion
/// energies"). With `F = U diag(sigma) V^T`, `U`, `V` rotations, and `pi_ij` the product
/// of the singular values other than `i` and `j` (1 in 2D), the orthonormal eigenvectors
/// are `vec(U A V^T)` for
/// - each pair `i < j`: twist `A = (e_i e_j^T - e_j e_i^T) / sqrt 2` with eigenvalue
///   `mu + s pi_ij` and flip `A = (e_i e_j^T + e_j e_i^T) / sqrt 2` with `mu - s pi_ij`;
/// - `A = diag(q)` for each eigenpair of the `D x D` scaling block
///   `mu I + k c c^T + s P`, `c_i = pi_ii`, `P_ij = pi_ij` off the diagonal and 0 on it.
///
/// Each negative eigenvalue `l` is clamped by adding `-l q q^T`. Returns false, leaving `h`
/// as it is, if a decomposition does not converge.
fn project_stable_neo_hookean<const D: usize, const N: usize>(
    f: &SMatrix<f64, D, D>,
    mu: f64,
    lambda: f64,
    h: &mut SMatrix<f64, N, N>,
) -> bool
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    let Some((u, sigma, v)) = f.rotation_svd() else {
        return false;
    };
    let k = snh_volume_stiffness(mu, lambda);
    let s = snh_dpsi_dj(mu, lambda, f.det());
    let others = |i: usize, j: usize| -> f64 { (0..D).filter(|&m| m != i && m != j).map(|m| sigma[m]).product() };
    let scaling = SMatrix::<f64, D, D>::from_fn(|i, j| {
        if i == j {
            mu + k * others(i, i).powi(2)
        } else {
            k * others(i, i) * others(j, j) + s * others(i, j)
        }
    });
    let scaling_modes = if scaling.cholesky().is_some() {
        None
    } else {
        let Some(modes) = scaling.eigen_decomposition() else {
            return false;
        };
        Some(modes)
    };
    let mut clamp = |a: SMatrix<f64, D, D>, eigenvalue: f64| {
        if eigenvalue < 0.0 {
            let q = SVector::<f64, N>::from_column_slice((u * a * v.transpose()).as_slice());
            *h -= q * q.transpose() * eigenvalue;
        }
    };
    for i in 0..D {
        for j in i + 1..D {
            let mut a = SMatrix::<f64, D, D>::zeros();
            a[(i, j)] = FRAC_1_SQRT_2;
            a[(j, i)] = -FRAC_1_SQRT_2;
            clamp(a, mu + s * others(i, j));
            a[(j, i)] = FRAC_1_SQRT_2;
            clamp(a, mu - s * others(i, j));
        }
    }
    if let Some((values, vectors)) = scaling_modes {
        for m in 0..D {
            clamp(SMatrix::from_diagonal(&vectors.column(m)), values[m]);
        }
    }
    true
}

/// Saint Venant-Kirchhoff density.
fn stvk<const D: usize, const N: usize>(
    f: &SMatrix<f64, D, D>,
    mu: f64,
    lambda: f64,
    grad: Option<&mut SMatrix<f64, D, D>>,
    hess: Option<&mut SMatrix<f64, N, N>>,
) -> f64 {
    let green = (f.transpose() * f - SMatrix::<f64, D, D>::identity()) * 0.5;
    let trace = green.trace();
    let psi = mu * green.norm_squared() + 0.5 * lambda * trace * trace;
    if grad.is_none() && hess.is_none() {
        return psi;
    }
    // Second Piola-Kirchhoff stress S = 2 mu E + lambda tr(E) I; P = F S.
    let stress = green * (2.0 * mu) + SMatrix::<f64, D, D>::identity() * (lambda * trace);
    if let Some(p) = grad {
        *p = f * stress;
    }
    if let Some(h) = hess {
        // d2Psi / dF_ij dF_kl
        //   = delta_ik S_lj + mu F_il F_kj + mu (F F^T)_ik delta_jl + lambda F_ij F_kl.
        let ff_t = f * f.transpose();
        for l in 0..D {
            for k in 0..D {
                for j in 0..D {
                    for i in 0..D {
                        let mut v = mu * f[(i, l)] * f[(k, j)] + lambda * f[(i, j)] * f[(k, l)];
                        if i == k {
                            v += stress[(l, j)];
                        }
                        if j == l {
                            v += mu * ff_t[(i, k)];
                        }
                        h[(i + D * j, k + D * l)] = v;
                    }
                }
            }
        }
    }
    psi
}

#[cfg(test)]
mod tests {
    use nalgebra::DMatrix;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::energy::simplex::checks::{random_deformation, random_rotation};

    /// Analytic stable neo-Hookean projection against numerical eigenvalue clamping of
    /// the same `d2Psi/dF2`, at `f`; returns the largest entry difference relative to the
    /// largest entry of the exact matrix.
    fn analytic_vs_numeric<const D: usize, const N: usize>(f: &SMatrix<f64, D, D>) -> f64
    where
        SMatrix<f64, D, D>: DeformationGradient<D, N>,
    {
        let (mu, lambda) = (3.0, 5.0);
        let mut exact = SMatrix::<f64, N, N>::zeros();
        let model = MaterialLaw::StableNeoHookean;
        energy_density(model, f, mu, lambda, None, Some(&mut exact));
        let mut analytic = exact;
        assert!(project_stable_neo_hookean(f, mu, lambda, &mut analytic));
        let mut numeric = exact;
        <SMatrix<f64, D, D> as DeformationGradient<D, N>>::clamp_negative_eigenvalues(&mut numeric);
        (analytic - numeric).amax() / exact.amax()
    }

    fn special_and_random<const D: usize>() -> Vec<SMatrix<f64, D, D>> {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let to_fixed = |m: &DMatrix<f64>| SMatrix::<f64, D, D>::from_fn(|i, j| m[(i, j)]);
        let r = to_fixed(&random_rotation(D, &mut rng));
        let mut diag = |values: [f64; 3]| {
            let q = to_fixed(&random_rotation(D, &mut rng));
            r * SMatrix::from_fn(|i, j| if i == j { values[i] } else { 0.0 }) * q
        };
        let mut fs = vec![
            SMatrix::identity(),
            r,
            r * 0.5,
            SMatrix::zeros(),
            diag([2.0, 2.0, 0.5]),
            diag([0.3, 0.0, 1.0]),
            diag([1.0, -1.0, 1.0]),
            diag([-0.2, -0.2, -0.2]),
        ];
        fs.extend((0..400).map(|k| to_fixed(&random_deformation(k, D, &mut rng))));
        fs
    }

    #[test]
    fn analytic_snh_projection_matches_numerical_clamping() {
        let worst2 = special_and_random::<2>()
            .iter()
            .map(analytic_vs_numeric)
            .fold(0.0, f64::max);
        let worst3 = special_and_random::<3>()
            .iter()
            .map(analytic_vs_numeric)
            .fold(0.0, f64::max);
        eprintln!("analytic vs numerical projection: 2D {worst2:.2e}, 3D {worst3:.2e}");
        assert!(worst2 < 1e-12 && worst3 < 1e-12, "2D {worst2:e}, 3D {worst3:e}");
    }
}
