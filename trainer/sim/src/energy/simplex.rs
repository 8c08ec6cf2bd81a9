//! Hyperelastic simplex elements written once for both dimensions: the constitutive
//! models as functions of the deformation gradient `F` ([`density`], with `F`'s calculus
//! in [`deformation`]), the linear map from a simplex's vertex positions to `F`, and the
//! element energy [`SimplexElastic`] itself:
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

#[cfg(test)]
pub mod checks;
mod deformation;
mod density;

pub use deformation::DeformationGradient;
pub use density::{energy_density, project_density_hessian};

use nalgebra::SMatrix;

use super::{Local, StencilEnergy, Want};
use crate::error::InputError;
use crate::material::{ElementMaterial, MaterialLaw};

/// A simplex whose rest measure (volume, area) is at most this times its longest edge
/// to the power `D` is rejected as degenerate (a regular tet has about 0.118, an
/// equilateral triangle about 0.433).
pub const DEGENERATE_RATIO: f64 = 1e-8;

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

#[cfg(test)]
pub(super) mod element_tests;
