//! Hair-like rods: stretching and bending of discrete elastic rods (Bergou et al. 2008),
//! for isotropic circular cross-sections of radius `r`.
//!
//! - [`RodStretch`]: one stencil per edge, `(E A / 2) (|e| / |e_rest| - 1)^2 |e_rest|`,
//!   `A = pi r^2`.
//! - [`RodBend`]: one stencil per interior vertex, `(E I / l) (|kb| - |kb_rest|)^2` with the
//!   curvature binormal `kb`, `l` the summed rest length of the two edges and
//!   `I = pi r^4 / 4`.
//!
//! Twist is left out. In Bergou et al. the bending energy compares the curvature binormal,
//! expressed in the material frame, with its rest value. For an isotropic cross-section and
//! a straight rest shape it is `|kb|^2`, which does not depend on the material frame at all:
//! bending decouples from twist. The twist energy `sum_i beta m_i^2 / l_i` then depends on
//! the frame angles only through the twists `m_i = theta_i - theta_{i-1} + (reference
//! twist)_i`; with no twist imposed at the root and the tip free, the angles along the strand
//! can be chosen one after the other to make every `m_i` zero, so the quasistatic twist is
//! zero and so is its energy, for any centreline.
//!
//! A naturally curved rest shape would need the material frame to carry the direction of
//! its rest curvature. Without frames, a three-vertex stencil sees the centreline, up to
//! rigid motion, only through `|e0|`, `|e1|` and `e0 . e1`, so a rotation-invariant bending
//! energy can only compare curvature magnitudes: `(|kb| - |kb_rest|)^2` is Bergou's
//! `|kb - R kb_rest|^2` minimised over the rotation `R` of the frame about the edge (a frame
//! free to twist). It equals `|kb - kb_rest|^2` for a straight rest shape; for a curved one it
//! leaves the plane of curvature free and has a cone (a local maximum without derivatives)
//! where a curved vertex is straightened.

use std::f64::consts::PI;
use std::path::Path;

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

use super::shell::{
    check_materials, check_positions, check_positive, material_of, scatter_relative, vertex, write_block,
};
use super::{Local, StencilEnergy, Want};
use crate::error::InputError;
use crate::material::ElementMaterial;

/// Stretching energy of rods, one stencil (2 vertices) per edge.
#[derive(Clone, Debug)]
pub struct RodStretch {
    edges: Vec<[usize; 2]>,
    params: Vec<StretchParams>,
}

/// Per-edge constants of the stretching energy.
#[derive(Clone, Copy, Debug)]
struct StretchParams {
    rest_length: f64,
    /// Axial stiffness E A.
    axial: f64,
}

impl RodStretch {
    /// Builds the stretching energy of the polylines `strands` (vertex indices, each from its
    /// root) over rest positions `rest` (flat, 3 per vertex). `materials` holds one material
    /// for all strands or one per strand; `radius` is the cross-section radius; `source` names
    /// the input in errors.
    pub fn new(
        rest: &[f64],
        strands: &[Vec<usize>],
        materials: &[ElementMaterial],
        radius: f64,
        source: &Path,
    ) -> Result<Self, InputError> {
        check_rods(rest, strands, materials, radius, source)?;
        let mut edges = Vec::new();
        let mut params = Vec::new();
        for (k, strand) in strands.iter().enumerate() {
            let axial = material_of(materials, k).youngs * PI * radius * radius;
            for pair in strand.windows(2) {
                edges.push([pair[0], pair[1]]);
                params.push(StretchParams {
                    rest_length: (vertex(rest, pair[1]) - vertex(rest, pair[0])).norm(),
                    axial,
                });
            }
        }
        Ok(RodStretch { edges, params })
    }
}

impl StencilEnergy for RodStretch {
    fn name(&self) -> &'static str {
        "stretch"
    }

    fn dim(&self) -> usize {
        3
    }

    fn len(&self) -> usize {
        self.edges.len()
    }

    fn stencil(&self, s: usize) -> &[usize] {
        &self.edges[s]
    }

    fn eval(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        let p = &self.params[s];
        let e = vertex(x, 1) - vertex(x, 0);
        let length = e.norm();
        let strain = length / p.rest_length - 1.0;
        let value = 0.5 * p.axial * strain * strain * p.rest_length;
        if !want.gradient() {
            return value;
        }
        // A fully collapsed edge has no direction: no force, axial stiffness in all directions.
        let direction = if length > 0.0 { e / length } else { Vector3::zeros() };
        let grad = direction * (p.axial * strain);
        out.grad[..3].copy_from_slice((-grad).as_slice());
        out.grad[3..6].copy_from_slice(grad.as_slice());
        let Some(project) = want.hessian() else {
            return value;
        };
        // d2E/de2 = EA (u u^T / l_rest + strain (I - u u^T) / |e|); the transverse part is
        // negative under compression and projection drops it, which is the exact PSD
        // projection as the edge Hessian enters the stencil as [[H, -H], [-H, H]].
        let block = if length > 0.0 {
            let along = direction * direction.transpose();
            let transverse_strain = if project { strain.max(0.0) } else { strain };
            (along / p.rest_length + (Matrix3::identity() - along) * (transverse_strain / length)) * p.axial
        } else {
            Matrix3::identity() * (p.axial / p.rest_length)
        };
        write_edge_hessian(&mut out.hess, &block);
        value
    }
}

/// Writes the 6x6 Hessian `[[h, -h], [-h, h]]` of a function of `x1 - x0`.
fn write_edge_hessian(hess: &mut [f64], h: &Matrix3<f64>) {
    write_block(hess, 6, 0, 0, h);
    write_block(hess, 6, 0, 1, &-h);
    write_block(hess, 6, 1, 0, &-h);
    write_block(hess, 6, 1, 1, h);
}

/// Bending energy of rods, one stencil (3 consecutive vertices) per interior vertex.
///
/// With `e0 = x_i - x_{i-1}`, `e1 = x_{i+1} - x_i` and rest lengths `l0`, `l1`, the curvature
/// binormal is `kb = 2 (e0 x e1) / (l0 l1 + e0 . e1)` (`|kb| = 2 tan(phi / 2)` for edges at
/// rest length turning by `phi`), and the energy `(E I / (l0 + l1)) (|kb| - |kb_rest|)^2`
/// (see the module documentation for why magnitudes).
/// On a circular arc of curvature `kappa` sampled every `h`, `|kb| ~ kappa h`, so each
/// interior vertex contributes `E I / (2 h) (kappa h)^2 = (E I / 2) kappa^2 h`, the continuum
/// energy of its length `h` of rod. The energy grows without bound as the denominator goes
/// to zero (edges folding back onto each other); beyond that it is `+inf`.
#[derive(Clone, Debug)]
pub struct RodBend {
    stencils: Vec<[usize; 3]>,
    params: Vec<BendParams>,
}

/// Rest curvatures `|kb_rest|` (about the turning angle in radians) up to this are taken as
/// exactly straight: round-off in a straight input strand must not leave a tiny cone at
/// the rest state, whose Hessian has no stiffness across the curvature direction.
const STRAIGHT_TOLERANCE: f64 = 1e-8;

/// Per-vertex constants of the bending energy.
#[derive(Clone, Copy, Debug)]
struct BendParams {
    /// Length of the rest curvature binormal.
    rest_curvature: f64,
    /// Product of the two rest edge lengths.
    rest_length_product: f64,
    /// E I / (l0 + l1).
    stiffness: f64,
}

impl RodBend {
    /// Builds the bending energy of the polylines `strands` (vertex indices, each from its
    /// root) over rest positions `rest` (flat, 3 per vertex). `materials` holds one material
    /// for all strands or one per strand; `radius` is the cross-section radius; `source` names
    /// the input in errors.
    pub fn new(
        rest: &[f64],
        strands: &[Vec<usize>],
        materials: &[ElementMaterial],
        radius: f64,
        source: &Path,
    ) -> Result<Self, InputError> {
        check_rods(rest, strands, materials, radius, source)?;
        let mut stencils = Vec::new();
        let mut params = Vec::new();
        for (k, strand) in strands.iter().enumerate() {
            let bending = material_of(materials, k).youngs * PI * radius.powi(4) / 4.0;
            for (j, triple) in strand.windows(3).enumerate() {
                let [x0, x1, x2] = [triple[0], triple[1], triple[2]].map(|v| vertex(rest, v));
                let (e0, e1) = (x1 - x0, x2 - x1);
                let (l0, l1) = (e0.norm(), e1.norm());
                let denominator = l0 * l1 + e0.dot(&e1);
                if denominator <= 1e-12 * l0 * l1 {
                    return Err(InputError::element(
                        source,
                        k,
                        format!(
                            "strand {k} folds back onto itself at its vertex {} (vertex {})",
                            j + 1,
                            triple[1]
                        ),
                    ));
                }
                let rest_curvature = 2.0 * e0.cross(&e1).norm() / denominator;
                stencils.push([triple[0], triple[1], triple[2]]);
                params.push(BendParams {
                    rest_curvature: if rest_curvature > STRAIGHT_TOLERANCE {
                        rest_curvature
                    } else {
                        0.0
                    },
                    rest_length_product: l0 * l1,
                    stiffness: bending / (l0 + l1),
                });
            }
        }
        Ok(RodBend { stencils, params })
    }
}

impl StencilEnergy for RodBend {
    fn name(&self) -> &'static str {
        "bend"
    }

    fn dim(&self) -> usize {
        3
    }

    fn len(&self) -> usize {
        self.stencils.len()
    }

    fn stencil(&self, s: usize) -> &[usize] {
        &self.stencils[s]
    }

    fn eval(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        let p = &self.params[s];
        let e0 = vertex(x, 1) - vertex(x, 0);
        let e1 = vertex(x, 2) - vertex(x, 1);
        let cross = e0.cross(&e1);
        let d = p.rest_length_product + e0.dot(&e1);
        if d <= 0.0 {
            out.clear(9);
            return f64::INFINITY;
        }
        let kb = cross * (2.0 / d);
        let c = p.rest_curvature;
        let kappa = kb.norm();
        if c > 0.0 && kappa <= f64::EPSILON * c {
            // Straightened vertex of a curved rod: the tip of the cone (|kb| - c)^2, a local
            // maximum without a gradient or Hessian.
            out.clear(9);
            return p.stiffness * c * c;
        }
        // v = kb - c kb / |kb|, so that |v| = | |kb| - c | and dE = 2 stiffness J^T v.
        let shrink = if c > 0.0 { c / kappa } else { 0.0 };
        let v = kb * (1.0 - shrink);
        let value = p.stiffness * v.norm_squared();
        if !want.gradient() {
            return value;
        }
        // Jacobians of kb = 2 (e0 x e1) / d.
        let j0 = -e1.cross_matrix() * (2.0 / d) - kb * e1.transpose() / d;
        let j1 = e0.cross_matrix() * (2.0 / d) - kb * e0.transpose() / d;
        let g0 = j0.transpose() * v;
        let g1 = j1.transpose() * v;
        let twice = 2.0 * p.stiffness;
        let grad = stack2(&g0, &g1) * twice;
        let Some(project) = want.hessian() else {
            scatter_relative(&ROD_RELATIVE, &grad, None, out);
            return value;
        };
        // E = stiffness (|kb| - c)^2:
        //   d2E = 2 stiffness (J^T M J + sum_k v_k d2 kb_k),
        //   M = I - (c / |kb|) (I - u u^T) with u = kb / |kb| (M = I for c = 0).
        // The second term is the derivative of J^T v at fixed v (with s = kb . v):
        //   J0^T v = (2/d) e1 x v - (s/d) e1,   J1^T v = (2/d) v x e0 - (s/d) e0.
        let s_kv = kb.dot(&v);
        let (d2, id) = (d * d, Matrix3::identity());
        let e1xv = e1.cross(&v);
        let vxe0 = v.cross(&e0);
        let k00 =
            -(e1xv * e1.transpose() + e1 * e1xv.transpose()) * (2.0 / d2) + e1 * e1.transpose() * (2.0 * s_kv / d2);
        let k11 =
            -(vxe0 * e0.transpose() + e0 * vxe0.transpose()) * (2.0 / d2) + e0 * e0.transpose() * (2.0 * s_kv / d2);
        let k01 = -v.cross_matrix() * (2.0 / d)
            - e1xv * e0.transpose() * (2.0 / d2)
            - id * (s_kv / d)
            - e1 * g1.transpose() / d
            + e1 * e0.transpose() * (s_kv / d2);
        let mut curvature_terms = SMatrix::<f64, 6, 6>::zeros();
        let jac = {
            let mut j = SMatrix::<f64, 3, 6>::zeros();
            j.fixed_view_mut::<3, 3>(0, 0).copy_from(&j0);
            j.fixed_view_mut::<3, 3>(0, 3).copy_from(&j1);
            j
        };
        curvature_terms.fixed_view_mut::<3, 3>(0, 0).copy_from(&k00);
        curvature_terms.fixed_view_mut::<3, 3>(0, 3).copy_from(&k01);
        curvature_terms.fixed_view_mut::<3, 3>(3, 0).copy_from(&k01.transpose());
        curvature_terms.fixed_view_mut::<3, 3>(3, 3).copy_from(&k11);
        let metric = if shrink > 0.0 {
            let u = kb / kappa;
            id - (id - u * u.transpose()) * shrink
        } else {
            id
        };
        let hess = (jac.transpose() * metric * jac + curvature_terms) * twice;
        scatter_relative(&ROD_RELATIVE, &grad, Some((&hess, project)), out);
        value
    }
}

/// How the bend stencil's edges `(x1 - x0, x2 - x1)` depend on its vertices: row `a` holds
/// the coefficients of vertex `a` in each.
const ROD_RELATIVE: [[f64; 2]; 3] = [[-1.0, 0.0], [1.0, -1.0], [0.0, 1.0]];

/// Stacks two 3-vectors into a 6-vector.
fn stack2(p: &Vector3<f64>, q: &Vector3<f64>) -> SVector<f64, 6> {
    SVector::<f64, 6>::new(p.x, p.y, p.z, q.x, q.y, q.z)
}

/// Checks rest positions, strands, materials and radius of a rod energy.
fn check_rods(
    rest: &[f64],
    strands: &[Vec<usize>],
    materials: &[ElementMaterial],
    radius: f64,
    source: &Path,
) -> Result<(), InputError> {
    let num_vertices = check_positions(rest, source)?;
    check_positive(radius, "radius", source)?;
    check_materials(materials, strands.len(), "strand", source)?;
    for (k, strand) in strands.iter().enumerate() {
        if strand.len() < 2 {
            return Err(InputError::element(
                source,
                k,
                format!("strand {k} has {} vertices, needs at least 2", strand.len()),
            ));
        }
        if let Some(&v) = strand.iter().find(|&&v| v >= num_vertices) {
            return Err(InputError::element(
                source,
                k,
                format!("strand {k}: vertex index {v} out of range ({num_vertices} vertices)"),
            ));
        }
        for (j, pair) in strand.windows(2).enumerate() {
            let length = (vertex(rest, pair[1]) - vertex(rest, pair[0])).norm();
            if length <= 0.0 {
                return Err(InputError::element(
                    source,
                    k,
                    format!(
                        "strand {k}: edge {j} (vertices {} to {}) has zero rest length",
                        pair[0], pair[1]
                    ),
                ));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
