//! Hyperelastic simplex elements written once for both dimensions: the constitutive
//! models as functions of the deformation gradient `F`, and the linear map from a
//! simplex's vertex positions to `F`, and the element energy [`SimplexElastic`] itself:
//! [`super::tet::TetElastic`] (D = 3) and [`super::tri2d::Tri2dElastic`] (D = 2, plane
//! strain) are its two instances.
//!
//! Conventions: `F` is `D x D`; the energy density's Hessian `d2Psi/dF2` is taken over
//! `vec(F)` in column-major order (entry `(i, j)` of `F` at index `i + D * j`, which is
//! nalgebra's storage order), an `N x N` matrix with `N = D * D`.
//!
//! Models (Psi per unit rest measure, `J = det F`, `I_C = |F|^2`, Lamé `mu`, `lambda`):
//! - stable neo-Hookean (Smith et al. 2018), without their log term:
//!   `Psi = mu/2 (I_C - D) - mu (J - 1) + (lambda + mu)/2 (J - 1)^2`.
//!   This is their `lambda'/2 (J - alpha)^2` form with `alpha = 1 + mu / lambda'`, minus
//!   the constant that makes it zero at rest, and with their Lamé reparameterisation
//!   `lambda' = lambda + mu`: expanding around `F = I`, the `-mu (J - 1)` term contributes
//!   `-mu/2 tr(eps)^2`, so with the bare `lambda` the linearisation would be linear
//!   elasticity with `lambda - mu`; with `lambda + mu` it is linear elasticity with exactly
//!   the given `mu` and `lambda`. Polynomial in `F`, so defined and smooth for inverted
//!   elements (`J <= 0`).
//! - Saint Venant-Kirchhoff: `Psi = mu E:E + lambda/2 tr(E)^2`, `E = (F^T F - I) / 2`.
//!
//! Projected Hessians clamp the eigenvalues of the `N x N` `d2Psi/dF2` (analytically for
//! stable neo-Hookean, numerically for StVK) and map it with the constant `dF/dx`; as
//! `dF/dx` is onto, this is PSD, and equal to the exact Hessian whenever that is PSD.

use std::f64::consts::FRAC_1_SQRT_2;

use nalgebra::allocator::Allocator;
use nalgebra::{
    Const, DefaultAllocator, DimDiff, DimMin, DimSub, Matrix2, Matrix3, SMatrix, SVector, SymmetricEigen, SVD, U1,
};

use super::{Local, StencilEnergy, Want};
use crate::error::InputError;
use crate::material::{ElementMaterial, MaterialLaw};

/// A simplex whose rest measure (volume, area) is at most this times its longest edge
/// to the power `D` is rejected as degenerate (a regular tet has about 0.118, an
/// equilateral triangle about 0.433).
pub const DEGENERATE_RATIO: f64 = 1e-8;

/// Iteration cap of the fixed-size eigen and singular value decompositions (they need a
/// handful per eigenvalue; the cap only stops non-finite input from looping).
const MAX_ITERATIONS: usize = 1000;

/// What a simplex of dimension `D` and its measure are called in error messages.
struct Names {
    /// The element: `tet` or `triangle`.
    element: &'static str,
    /// Its rest measure: `volume` or `area`.
    measure: &'static str,
}

impl Names {
    /// The names of `D`-simplices.
    const fn of<const D: usize>() -> Names {
        match D {
            3 => Names {
                element: "tet",
                measure: "volume",
            },
            _ => Names {
                element: "triangle",
                measure: "area",
            },
        }
    }
}

/// Per-element constants of a simplex.
#[derive(Clone, Copy, Debug)]
struct ElementConstants<const D: usize> {
    /// Inverse of the rest edge matrix `Dm`; `F = Ds Dm^-1`.
    dm_inv: SMatrix<f64, D, D>,
    /// Shear modulus.
    mu: f64,
    /// First Lamé parameter.
    lambda: f64,
}

/// Hyperelastic energy of a mesh of `D`-simplices in `D` dimensions:
/// `sum_e measure_e * Psi(F_e)`, one stencil (`D + 1` vertices, `(D + 1) D` local dofs)
/// per element; `N = D * D`. Used as [`super::tet::TetElastic`] and
/// [`super::tri2d::Tri2dElastic`].
pub struct SimplexElastic<const D: usize, const N: usize> {
    model: MaterialLaw,
    /// Vertex indices, `D + 1` per element.
    indices: Vec<usize>,
    /// Rest measures (volumes, areas), positive.
    measures: Vec<f64>,
    elements: Vec<ElementConstants<D>>,
}

impl<const D: usize, const N: usize> SimplexElastic<D, N>
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    /// Builds the energy of `elements` (each `V = D + 1` vertex indices) over the flat
    /// rest positions `rest` (`D` per vertex), with one material for all elements or one
    /// per element (plane-strain Lamé parameters in 2D). Rejects bad materials,
    /// out-of-range vertex indices and degenerate or inverted (in 2D: clockwise) rest
    /// elements, naming `source` and the field or element.
    pub fn new<const V: usize>(
        model: MaterialLaw,
        rest: &[f64],
        elements: &[[usize; V]],
        materials: &[ElementMaterial],
        source: &std::path::Path,
    ) -> Result<Self, InputError> {
        const { assert!(V == D + 1 && N == D * D) };
        let names = Names::of::<D>();
        check_materials(materials, elements.len(), names.element, source)?;
        let num_vertices = rest.len() / D;
        if num_vertices * D != rest.len() {
            return Err(InputError::field(
                source,
                "rest",
                format!("{} coordinates is not a multiple of {D}", rest.len()),
            ));
        }
        let mut constants = Vec::with_capacity(elements.len());
        let mut measures = Vec::with_capacity(elements.len());
        for (e, verts) in elements.iter().enumerate() {
            let mut p = [[0.0; D]; V];
            for (a, &v) in verts.iter().enumerate() {
                if v >= num_vertices {
                    return Err(InputError::element(
                        source,
                        e,
                        format!(
                            "{} vertex index {v} is out of range (the mesh has {num_vertices} vertices)",
                            names.element
                        ),
                    ));
                }
                p[a].copy_from_slice(&rest[v * D..(v + 1) * D]);
            }
            let measure = checked_rest_measure(&p, &names).map_err(|m| InputError::element(source, e, m))?;
            let dm_inv = edge_matrix(&p).try_inverse().ok_or_else(|| {
                InputError::element(source, e, format!("degenerate {}: singular rest shape", names.element))
            })?;
            let material = materials[if materials.len() == 1 { 0 } else { e }];
            measures.push(measure);
            constants.push(ElementConstants {
                dm_inv,
                mu: material.mu(),
                lambda: material.lambda(),
            });
        }
        Ok(SimplexElastic {
            model,
            indices: elements.iter().flatten().copied().collect(),
            measures,
            elements: constants,
        })
    }

    /// Rest measure (volume, area) of each element.
    pub fn rest_measures(&self) -> &[f64] {
        &self.measures
    }

    /// The energy of element `s` at local positions `x` (see [`StencilEnergy::eval`]).
    fn eval_element(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        debug_assert_eq!(x.len(), (D + 1) * D);
        let c = &self.elements[s];
        let measure = self.measures[s];
        let ds = SMatrix::<f64, D, D>::from_fn(|i, a| x[(a + 1) * D + i] - x[i]);
        let f = ds * c.dm_inv;
        let mut p = SMatrix::<f64, D, D>::zeros();
        let mut hf = SMatrix::<f64, N, N>::zeros();
        let psi = energy_density(
            self.model,
            &f,
            c.mu,
            c.lambda,
            want.gradient().then_some(&mut p),
            want.hessian().is_some().then_some(&mut hf),
        );
        if want.gradient() {
            // dF_ij / dx_(a+1),k = delta_ik Dm^-1_aj, and vertex 0 balances the others.
            let g = p * c.dm_inv.transpose() * measure;
            for i in 0..D {
                let mut g0 = 0.0;
                for a in 0..D {
                    out.grad[(a + 1) * D + i] = g[(i, a)];
                    g0 -= g[(i, a)];
                }
                out.grad[i] = g0;
            }
        }
        if let Some(project) = want.hessian() {
            if project {
                // dF/dx maps onto all of F-space, so the local Hessian is PSD exactly when
                // d2Psi/dF2 is: projecting the small matrix suffices.
                project_density_hessian(self.model, &f, c.mu, c.lambda, &mut hf);
            }
            Self::write_local_hessian(&c.dm_inv, &hf, measure, out);
        }
        measure * psi
    }

    /// Writes `measure * (dF/dx)^T hf (dF/dx)` into `out.hess`, using that
    /// `dF_ij / dx_(b,k) = delta_ik w_b[j]` with `w_b` row `b - 1` of `Dm^-1` for `b >= 1`
    /// and `w_0 = -sum_b w_b`.
    fn write_local_hessian(dm_inv: &SMatrix<f64, D, D>, hf: &SMatrix<f64, N, N>, measure: f64, out: &mut Local) {
        let n = (D + 1) * D;
        let row_sum = dm_inv.row_sum();
        let weight = |b: usize, j: usize| {
            if b == 0 {
                -row_sum[j]
            } else {
                dm_inv[(b - 1, j)]
            }
        };
        for b in 0..=D {
            // hf_b[(i, j), k] = measure sum_l hf[(i, j), (k, l)] w_b[l]
            //               = measure d2Psi / dF_ij dx_(b,k).
            let mut hf_b = SMatrix::<f64, N, D>::zeros();
            for k in 0..D {
                for l in 0..D {
                    let w = weight(b, l) * measure;
                    hf_b.column_mut(k).axpy(w, &hf.column(k + D * l), 1.0);
                }
            }
            for a in 0..=D {
                for i in 0..D {
                    for k in 0..D {
                        let mut v = 0.0;
                        for j in 0..D {
                            v += weight(a, j) * hf_b[(i + D * j, k)];
                        }
                        out.hess[(a * D + i) * n + b * D + k] = v;
                    }
                }
            }
        }
    }
}

impl<const D: usize, const N: usize> StencilEnergy for SimplexElastic<D, N>
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    fn name(&self) -> &'static str {
        "elastic"
    }

    fn dim(&self) -> usize {
        D
    }

    fn len(&self) -> usize {
        self.elements.len()
    }

    fn stencil(&self, s: usize) -> &[usize] {
        &self.indices[s * (D + 1)..(s + 1) * (D + 1)]
    }

    fn eval(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        self.eval_element(s, x, want, out)
    }
}

/// Checks that `materials` has one entry or one per element (`count`) and that each is a
/// valid solid material.
fn check_materials(
    materials: &[ElementMaterial],
    count: usize,
    element: &str,
    source: &std::path::Path,
) -> Result<(), InputError> {
    if materials.len() != 1 && materials.len() != count {
        return Err(InputError::field(
            source,
            "materials",
            format!(
                "expected 1 material (homogeneous) or {count} (one per {element}), got {}",
                materials.len()
            ),
        ));
    }
    for (e, m) in materials.iter().enumerate() {
        let field = |name: &str| format!("materials[{e}].{name}");
        if !(m.youngs.is_finite() && m.youngs > 0.0) {
            let msg = format!("Young's modulus must be positive and finite, got {}", m.youngs);
            return Err(InputError::field(source, field("youngs"), msg));
        }
        if !(m.poisson > -1.0 && m.poisson < 0.5) {
            let msg = format!("Poisson ratio must be in (-1, 0.5), got {}", m.poisson);
            return Err(InputError::field(source, field("poisson"), msg));
        }
        if !m.density.is_finite() {
            let msg = format!("density must be finite, got {}", m.density);
            return Err(InputError::field(source, field("density"), msg));
        }
    }
    Ok(())
}

/// The rest measure of the simplex `p`, or why it cannot be an element: non-finite
/// coordinates, degenerate (measure at most [`DEGENERATE_RATIO`] times the longest edge to
/// the power `D`), or inverted (negative measure).
fn checked_rest_measure<const D: usize, const N: usize, const V: usize>(
    p: &[[f64; D]; V],
    names: &Names,
) -> Result<f64, String>
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    let (element, what) = (names.element, names.measure);
    if p.iter().flatten().any(|c| !c.is_finite()) {
        return Err(format!("{element} has a non-finite rest position"));
    }
    let mut longest = 0.0f64;
    for a in 0..V {
        for b in a + 1..V {
            let len2: f64 = (0..D).map(|i| (p[a][i] - p[b][i]).powi(2)).sum();
            longest = longest.max(len2.sqrt());
        }
    }
    let measure = signed_measure(p);
    let tiny = DEGENERATE_RATIO * longest.powi(D as i32);
    if measure.abs() <= tiny {
        return Err(format!(
            "degenerate {element}: rest {what} {measure:.3e} is at most {DEGENERATE_RATIO:e} x \
             (longest edge {longest:.3e})^{D}"
        ));
    }
    if measure < 0.0 {
        return Err(format!(
            "inverted {element}: rest {what} {measure:.3e} is negative (reorder its vertices)"
        ));
    }
    Ok(measure)
}

/// The `D x D` matrix of edge vectors `p[c + 1] - p[0]` (as columns) of a simplex given
/// by its `D + 1` vertices.
pub fn edge_matrix<const D: usize, const V: usize>(p: &[[f64; D]; V]) -> SMatrix<f64, D, D> {
    const { assert!(V == D + 1) };
    SMatrix::from_fn(|i, c| p[c + 1][i] - p[0][i])
}

/// Signed measure (volume in 3D, area in 2D) of a simplex given by its `D + 1` vertices:
/// `det(edges) / D!`, positive for the orientation that the elements here require.
pub fn signed_measure<const D: usize, const N: usize, const V: usize>(p: &[[f64; D]; V]) -> f64
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    let factorial: usize = (1..=D).product();
    edge_matrix(p).det() / factorial as f64
}

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

/// The dimension-specific pieces of the calculus of a `D x D` deformation gradient whose
/// vectorisation has `N = D * D` entries, and the fixed-size decompositions that the
/// Hessian projection needs (nalgebra's require bounds that only concrete sizes meet).
/// Implemented for 2x2 (`N = 4`) and 3x3 (`N = 9`).
pub trait DeformationGradient<const D: usize, const N: usize>: Sized {
    /// `det F`.
    fn det(&self) -> f64;
    /// The cofactor matrix `d det F / dF` (equal to `det(F) F^-T` where `F` is invertible).
    fn cofactor(&self) -> Self;
    /// Adds `scale * d2(det F)/dF2` (over column-major `vec(F)`) to `h`.
    fn add_det_hessian(&self, scale: f64, h: &mut SMatrix<f64, N, N>);
    /// `(U, sigma, V)` with `F = U diag(sigma) V^T` and `U`, `V` rotations, so the last
    /// singular value carries the sign of `det F`; `None` if the SVD does not converge.
    fn rotation_svd(&self) -> Option<(Self, SVector<f64, D>, Self)>;
    /// Eigenvalues and eigenvectors (as columns) of `self`, symmetric; `None` if the
    /// decomposition does not converge.
    fn eigen_decomposition(&self) -> Option<(SVector<f64, D>, Self)>;
    /// Clamps the negative eigenvalues of the symmetric `h` to zero, by a numerical
    /// eigen-decomposition (`h` becomes zero, still PSD, if that does not converge).
    fn clamp_negative_eigenvalues(h: &mut SMatrix<f64, N, N>);
}

impl DeformationGradient<2, 4> for Matrix2<f64> {
    fn det(&self) -> f64 {
        self.determinant()
    }

    fn cofactor(&self) -> Self {
        Matrix2::new(self[(1, 1)], -self[(1, 0)], -self[(0, 1)], self[(0, 0)])
    }

    fn add_det_hessian(&self, scale: f64, h: &mut SMatrix<f64, 4, 4>) {
        // det = F00 F11 - F01 F10, vec(F) = (F00, F10, F01, F11): constant Hessian.
        h[(0, 3)] += scale;
        h[(3, 0)] += scale;
        h[(1, 2)] -= scale;
        h[(2, 1)] -= scale;
    }

    fn rotation_svd(&self) -> Option<(Self, SVector<f64, 2>, Self)> {
        rotation_svd(self)
    }

    fn eigen_decomposition(&self) -> Option<(SVector<f64, 2>, Self)> {
        eigen_decomposition(self)
    }

    fn clamp_negative_eigenvalues(h: &mut SMatrix<f64, 4, 4>) {
        clamp_negative_eigenvalues(h);
    }
}

impl DeformationGradient<3, 9> for Matrix3<f64> {
    fn det(&self) -> f64 {
        self.determinant()
    }

    fn cofactor(&self) -> Self {
        let (f0, f1, f2) = (self.column(0), self.column(1), self.column(2));
        Matrix3::from_columns(&[f1.cross(&f2), f2.cross(&f0), f0.cross(&f1)])
    }

    fn add_det_hessian(&self, scale: f64, h: &mut SMatrix<f64, 9, 9>) {
        // det = f0 . (f1 x f2) with columns f_a; the block of columns (a, a+1 mod 3) is
        // -[f_c]x with c the third column, its transpose is the block (a+1, a).
        for a in 0..3 {
            let b = (a + 1) % 3;
            let c = (a + 2) % 3;
            let fc = self.column(c).into_owned() * scale;
            let block = fc.cross_matrix();
            let mut ab = h.fixed_view_mut::<3, 3>(3 * a, 3 * b);
            ab -= block;
            let mut ba = h.fixed_view_mut::<3, 3>(3 * b, 3 * a);
            ba += block;
        }
    }

    fn rotation_svd(&self) -> Option<(Self, SVector<f64, 3>, Self)> {
        rotation_svd(self)
    }

    fn eigen_decomposition(&self) -> Option<(SVector<f64, 3>, Self)> {
        eigen_decomposition(self)
    }

    fn clamp_negative_eigenvalues(h: &mut SMatrix<f64, 9, 9>) {
        clamp_negative_eigenvalues(h);
    }
}

/// See [`DeformationGradient::rotation_svd`].
#[allow(clippy::type_complexity)]
fn rotation_svd<const D: usize>(
    f: &SMatrix<f64, D, D>,
) -> Option<(SMatrix<f64, D, D>, SVector<f64, D>, SMatrix<f64, D, D>)>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>> + DimSub<U1>,
    DefaultAllocator: Allocator<DimDiff<Const<D>, U1>>,
{
    let svd = SVD::<f64, Const<D>, Const<D>>::try_new(*f, true, true, f64::EPSILON, MAX_ITERATIONS)?;
    let (mut u, mut v) = (svd.u?, svd.v_t?.transpose());
    if u.determinant() < 0.0 {
        u.column_mut(D - 1).neg_mut();
    }
    if v.determinant() < 0.0 {
        v.column_mut(D - 1).neg_mut();
    }
    // Signed singular values, consistent with the sign flips above.
    let sigma = (u.transpose() * f * v).diagonal();
    Some((u, sigma, v))
}

/// See [`DeformationGradient::eigen_decomposition`].
fn eigen_decomposition<const D: usize>(m: &SMatrix<f64, D, D>) -> Option<(SVector<f64, D>, SMatrix<f64, D, D>)>
where
    Const<D>: DimSub<U1>,
    DefaultAllocator: Allocator<DimDiff<Const<D>, U1>>,
{
    let eig = SymmetricEigen::<f64, Const<D>>::try_new(*m, f64::EPSILON, MAX_ITERATIONS)?;
    Some((eig.eigenvalues, eig.eigenvectors))
}

/// See [`DeformationGradient::clamp_negative_eigenvalues`].
fn clamp_negative_eigenvalues<const N: usize>(h: &mut SMatrix<f64, N, N>)
where
    Const<N>: DimSub<U1>,
    DefaultAllocator: Allocator<DimDiff<Const<N>, U1>>,
{
    let Some((values, vectors)) = eigen_decomposition(h) else {
        h.fill(0.0);
        return;
    };
    if values.iter().all(|&l| l >= 0.0) {
        return;
    }
    let clamped = values.map(|l| l.max(0.0));
    *h = vectors * SMatrix::<f64, N, N>::from_diagonal(&clamped) * vectors.transpose();
}

/// Checks shared by the tests of [`super::tet`] and [`super::tri2d`]: each takes a
/// single-element energy (stencil 0 = vertices `0..=D`) and its flat rest positions.
#[cfg(test)]
pub mod checks {
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
    pub fn assert_rest_and_rigid_invariance(
        energy: &dyn StencilEnergy,
        rest: &[f64],
        scale: f64,
        rng: &mut ChaCha8Rng,
    ) {
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
}

#[cfg(test)]
pub(super) mod element_tests;

#[cfg(test)]
mod tests {
    use nalgebra::DMatrix;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    use super::checks::{random_deformation, random_rotation};
    use super::*;

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
