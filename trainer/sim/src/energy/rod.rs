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
mod tests {
    use super::*;
    use crate::energy::fd::{assert_all_stencils, check_stencil};
    use crate::energy::psd::min_eigenvalue;
    use crate::energy::{add_gradient, gather, value};
    use crate::error::Location;
    use nalgebra::Rotation3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    const SOURCE: &str = "<test>";

    fn path() -> &'static Path {
        Path::new(SOURCE)
    }

    /// Material and radius giving E A ~ 3e3 and E I ~ 0.6, so that relative finite-difference
    /// errors are meaningful.
    fn stiff() -> (ElementMaterial, f64) {
        let m = ElementMaterial {
            youngs: 1e6,
            poisson: 0.3,
            density: 1320.0,
        };
        (m, 0.03)
    }

    fn random_unit(rng: &mut ChaCha8Rng) -> Vector3<f64> {
        loop {
            let v = Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            if v.norm() > 0.1 && v.norm() < 1.0 {
                return v.normalize();
            }
        }
    }

    /// Three vertices: an edge of length `l0` along a random direction, then one of length
    /// `l1` turning by `angle` about a random axis.
    fn bent_triple(rng: &mut ChaCha8Rng, angle: f64, l0: f64, l1: f64) -> Vec<f64> {
        let dir = random_unit(rng);
        let axis = dir.cross(&random_unit(rng)).normalize();
        let next = Rotation3::new(axis * angle) * dir;
        let x0 = Vector3::new(rng.random(), rng.random(), rng.random());
        let x1 = x0 + dir * l0;
        let x2 = x1 + next * l1;
        [x0, x1, x2].iter().flat_map(|p| [p.x, p.y, p.z]).collect()
    }

    fn transform(x: &[f64], rotation: &Rotation3<f64>, shift: &Vector3<f64>) -> Vec<f64> {
        x.chunks_exact(3)
            .flat_map(|p| {
                let q = rotation * Vector3::new(p[0], p[1], p[2]) + shift;
                [q.x, q.y, q.z]
            })
            .collect()
    }

    /// A helix sampled every `step` of arc length (a curved, twisted rest shape).
    fn helix(n: usize, step: f64) -> Vec<f64> {
        let (radius, pitch): (f64, f64) = (0.3, 0.1);
        let speed = (radius * radius + pitch * pitch).sqrt();
        (0..n)
            .flat_map(|j| {
                let t = j as f64 * step / speed;
                [radius * t.cos(), radius * t.sin(), pitch * t]
            })
            .collect()
    }

    fn straight(n: usize, step: f64) -> Vec<f64> {
        (0..n).flat_map(|j| [0.0, 0.0, -(j as f64) * step]).collect()
    }

    #[test]
    fn bend_matches_finite_differences_from_straight_to_sharply_bent() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let (m, r) = stiff();
        let mut worst = (0.0f64, 0.0f64);
        let angles = [0.0, 1e-7, 1e-4, 0.1, 0.8, 1.5, 2.2, 2.6];
        for _ in 0..40 {
            for &rest_angle in &[0.0, rng.random_range(0.3..1.5)] {
                let (l0, l1) = (rng.random_range(0.2..1.0), rng.random_range(0.2..1.0));
                let rest = bent_triple(&mut rng, rest_angle, l0, l1);
                let bend = RodBend::new(&rest, &[vec![0, 1, 2]], &[m], r, path()).unwrap();
                // A curved rest shape has a cone where the vertex is straight: stay clear.
                let smooth = angles.iter().filter(|&&a| rest_angle == 0.0 || a >= 0.1);
                for &angle in smooth {
                    // Stretched or compressed edges, keeping l0 l1 + e0.e1 > 0.
                    let stretch = [rng.random_range(0.85..1.05), rng.random_range(0.85..1.05)];
                    let x = bent_triple(&mut rng, angle, l0 * stretch[0], l1 * stretch[1]);
                    let report = check_stencil(&bend, 0, &x, 1e-6);
                    assert!(
                        report.grad_error < 1e-6 && report.hess_error < 1e-6,
                        "angle {angle}, rest {rest_angle}: {report:?}"
                    );
                    worst = (worst.0.max(report.grad_error), worst.1.max(report.hess_error));
                }
            }
        }
        eprintln!("bend FD worst: gradient {:.1e}, Hessian {:.1e}", worst.0, worst.1);
    }

    #[test]
    fn stretch_matches_finite_differences_in_tension_and_compression() {
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        let (m, r) = stiff();
        for _ in 0..100 {
            let rest_length = rng.random_range(0.1..1.0);
            let rest = bent_triple(&mut rng, 0.0, rest_length, 1.0);
            let stretch = RodStretch::new(&rest[..6], &[vec![0, 1]], &[m], r, path()).unwrap();
            let length = rng.random_range(0.1..2.0);
            let x = bent_triple(&mut rng, 0.0, length, 1.0);
            let report = check_stencil(&stretch, 0, &x[..6], 1e-6);
            assert!(report.grad_error < 1e-7 && report.hess_error < 1e-7, "{report:?}");
        }
    }

    #[test]
    fn energies_match_finite_differences_on_a_deformed_strand() {
        let mut rng = ChaCha8Rng::seed_from_u64(13);
        let (m, r) = stiff();
        let rest = helix(8, 0.2);
        let strands = vec![(0..8).collect::<Vec<_>>()];
        let stretch = RodStretch::new(&rest, &strands, &[m], r, path()).unwrap();
        let bend = RodBend::new(&rest, &strands, &[m], r, path()).unwrap();
        let x: Vec<f64> = rest.iter().map(|c| c + rng.random_range(-0.05..0.05)).collect();
        assert_all_stencils(&stretch, &x, 1e-6, 1e-7);
        assert_all_stencils(&bend, &x, 1e-6, 1e-6);
    }

    #[test]
    fn zero_energy_and_gradient_at_straight_and_curved_rest_shapes() {
        let (m, r) = stiff();
        let strands = vec![(0..6).collect::<Vec<_>>(), (6..12).collect()];
        let mut rest = straight(6, 0.1);
        rest.extend(helix(6, 0.15));
        let stretch = RodStretch::new(&rest, &strands, &[m], r, path()).unwrap();
        let bend = RodBend::new(&rest, &strands, &[m, m], r, path()).unwrap();
        assert_eq!((stretch.len(), bend.len()), (10, 8));
        for energy in [&stretch as &dyn StencilEnergy, &bend] {
            let mut grad = vec![0.0; rest.len()];
            let e = add_gradient(energy, 1.0, &rest, &mut grad);
            let g = grad.iter().fold(0.0f64, |m, g| m.max(g.abs()));
            assert!(e.abs() < 1e-20 && g < 1e-9, "{}: {e:e}, {g:e}", energy.name());
        }
    }

    #[test]
    fn energies_are_invariant_under_rigid_motion() {
        let mut rng = ChaCha8Rng::seed_from_u64(14);
        let (m, r) = stiff();
        let rest = helix(10, 0.1);
        let strands = vec![(0..10).collect::<Vec<_>>()];
        let stretch = RodStretch::new(&rest, &strands, &[m], r, path()).unwrap();
        let bend = RodBend::new(&rest, &strands, &[m], r, path()).unwrap();
        for _ in 0..10 {
            let x: Vec<f64> = rest.iter().map(|c| c + rng.random_range(-0.03..0.03)).collect();
            let rotation = Rotation3::new(random_unit(&mut rng) * rng.random_range(0.0..3.0));
            let moved = transform(&x, &rotation, &Vector3::new(1.0, -2.0, 0.5));
            for energy in [&stretch as &dyn StencilEnergy, &bend] {
                let (a, b) = (value(energy, &x), value(energy, &moved));
                assert!(a > 0.0 && (a - b).abs() <= 1e-10 * a, "{}: {a} {b}", energy.name());
            }
        }
    }

    /// A straight rod of `n` edges and length 1 bent without stretching onto a circular arc
    /// of curvature `kappa`; returns (bend energy / (E I / 2 kappa^2 L), stretch energy).
    fn arc_ratio(n: usize, kappa: f64) -> (f64, f64) {
        let (m, r) = stiff();
        let h = 1.0 / n as f64;
        let rest = straight(n + 1, h);
        let strands = vec![(0..=n).collect::<Vec<_>>()];
        let bend = RodBend::new(&rest, &strands, &[m], r, path()).unwrap();
        let stretch = RodStretch::new(&rest, &strands, &[m], r, path()).unwrap();
        // Vertices on the circle with chords exactly h: turning angle 2 asin(kappa h / 2).
        let step = 2.0 * (0.5 * kappa * h).asin();
        let x: Vec<f64> = (0..=n)
            .flat_map(|j| {
                let a = j as f64 * step;
                [a.sin() / kappa, 0.0, (1.0 - a.cos()) / kappa]
            })
            .collect();
        let bending = m.youngs * PI * r.powi(4) / 4.0;
        let continuum = 0.5 * bending * kappa * kappa * 1.0;
        (value(&bend, &x) / continuum, value(&stretch, &x))
    }

    #[test]
    fn arc_bending_matches_the_continuum_energy() {
        for n in [25, 50, 100, 200, 400] {
            let (ratio, stretch) = arc_ratio(n, 3.0);
            eprintln!("arc n={n}: bend/continuum {ratio:.5}, stretch {stretch:.1e}");
            // Exactly: |kb| = 2 tan(phi / 2) with sin(phi / 2) = kappa h / 2 at each of the
            // n - 1 interior vertices, so ratio = (1 - 1/n) / (1 - (kappa h / 2)^2): a boundary
            // deficit of one edge and a second-order discretisation excess.
            let half = 0.5 * 3.0 / n as f64;
            let expected = (1.0 - 1.0 / n as f64) / (1.0 - half * half);
            assert!((ratio - expected).abs() < 1e-9, "{ratio} vs {expected}");
            assert!(stretch < 1e-20);
            if n >= 200 {
                assert!((ratio - 1.0).abs() < 0.01, "{ratio}");
            }
        }
    }

    #[test]
    fn uniform_stretch_matches_the_continuum_energy() {
        let (m, r) = stiff();
        let n = 7;
        let rest = straight(n + 1, 0.3);
        let strands = vec![(0..=n).collect::<Vec<_>>()];
        let stretch = RodStretch::new(&rest, &strands, &[m], r, path()).unwrap();
        let bend = RodBend::new(&rest, &strands, &[m], r, path()).unwrap();
        let length = 0.3 * n as f64;
        for eps in [1e-3, 0.05, -0.1] {
            let x: Vec<f64> = rest.iter().map(|c| c * (1.0 + eps)).collect();
            let want = 0.5 * m.youngs * PI * r * r * eps * eps * length;
            let got = value(&stretch, &x);
            assert!((got - want).abs() < 1e-10 * want, "{got} vs {want}");
            assert!(value(&bend, &x).abs() < 1e-20);
        }
    }

    #[test]
    fn projected_hessians_are_positive_semidefinite() {
        let mut rng = ChaCha8Rng::seed_from_u64(15);
        let (m, r) = stiff();
        let mut negative_seen = [false; 2];
        for _ in 0..50 {
            let rest_angle = rng.random_range(0.0..1.0);
            let rest = bent_triple(&mut rng, rest_angle, 0.5, 0.7);
            let strands = [vec![0, 1, 2]];
            let stretch = RodStretch::new(&rest, &strands, &[m], r, path()).unwrap();
            let bend = RodBend::new(&rest, &strands, &[m], r, path()).unwrap();
            let (angle, l0, l1) = (
                rng.random_range(0.0..2.5),
                rng.random_range(0.3..0.7),
                rng.random_range(0.5..0.9),
            );
            let x = bent_triple(&mut rng, angle, l0, l1);
            for (k, energy) in [&stretch as &dyn StencilEnergy, &bend].iter().enumerate() {
                let mut local = [0.0; 12];
                let n = gather(*energy, 0, &x, &mut local);
                let mut out = Local::default();
                energy.eval(0, &local[..n], Want::Hessian { project: false }, &mut out);
                negative_seen[k] |= min_eigenvalue(&out.hess[..n * n], n) < 0.0;
                energy.eval(0, &local[..n], Want::Hessian { project: true }, &mut out);
                let scale = out.hess[..n * n].iter().fold(1.0f64, |m, h| m.max(h.abs()));
                let min = min_eigenvalue(&out.hess[..n * n], n);
                assert!(min > -1e-10 * scale, "{}: {min}", energy.name());
            }
        }
        assert_eq!(negative_seen, [true, true], "the test should include indefinite cases");
    }

    #[test]
    fn folding_back_is_an_infinite_barrier() {
        let (m, r) = stiff();
        let rest = straight(3, 1.0);
        let bend = RodBend::new(&rest, &[vec![0, 1, 2]], &[m], r, path()).unwrap();
        let mut out = Local::default();
        let near = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.01, 0.0];
        let folded = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, -0.5, 0.0, 0.0];
        assert!(bend.eval(0, &near, Want::Value, &mut out) > 1e3);
        let e = bend.eval(0, &folded, Want::Hessian { project: true }, &mut out);
        assert_eq!(e, f64::INFINITY);
        assert!(out.grad[..9].iter().all(|g| *g == 0.0));
    }

    fn error_of<T: std::fmt::Debug>(result: Result<T, InputError>) -> InputError {
        result.expect_err("expected an error")
    }

    #[test]
    fn bad_input_errors_name_the_element_or_field() {
        let (m, r) = stiff();
        let rest = straight(6, 0.1);
        let good = vec![vec![0, 1, 2], vec![3, 4, 5]];
        let both = |rest: &[f64], strands: &[Vec<usize>], mats: &[ElementMaterial], r: f64| {
            let a = error_of(RodStretch::new(rest, strands, mats, r, path()));
            let b = error_of(RodBend::new(rest, strands, mats, r, path()));
            assert_eq!(a, b);
            assert_eq!(a.file, Path::new(SOURCE));
            a
        };
        let e = both(&rest, &[vec![0, 1, 2], vec![3, 9]], &[m], r);
        assert_eq!(e.location, Location::Element(1));
        assert!(e.message.contains('9'), "{e}");
        let e = both(&rest, &[vec![0, 1, 2], vec![3]], &[m], r);
        assert_eq!(e.location, Location::Element(1));
        let e = both(&rest, &[vec![0, 1, 1, 2]], &[m], r);
        assert_eq!(e.location, Location::Element(0));
        assert!(e.message.contains("zero rest length"), "{e}");

        let mut nan = rest.clone();
        nan[7] = f64::NAN;
        let e = both(&nan, &good, &[m], r);
        assert_eq!(e.location, Location::Field("vertices[2]".into()));
        let e = both(&rest[..17], &good, &[m], r);
        assert_eq!(e.location, Location::Field("vertices".into()));

        for bad in [0.0, -1.0, f64::INFINITY] {
            let e = both(&rest, &good, &[m], bad);
            assert_eq!(e.location, Location::Field("radius".into()));
        }
        let e = both(&rest, &good, &[m, m, m], r);
        assert_eq!(e.location, Location::Field("materials".into()));
        let e = both(&rest, &good, &[m, ElementMaterial { youngs: 0.0, ..m }], r);
        assert_eq!(e.location, Location::Field("materials[1].youngs".into()));
        let e = both(&rest, &good, &[ElementMaterial { poisson: -1.0, ..m }], r);
        assert_eq!(e.location, Location::Field("materials[0].poisson".into()));

        // A rest strand folding back onto itself has no bending rest state.
        let hairpin = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        RodStretch::new(&hairpin, &[vec![0, 1, 2]], &[m], r, path()).unwrap();
        let e = error_of(RodBend::new(&hairpin, &[vec![0, 1, 2]], &[m], r, path()));
        assert_eq!(e.location, Location::Element(0));
    }
}
