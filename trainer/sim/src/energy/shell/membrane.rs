//! The StVK membrane energy of cloth.

use std::path::Path;

use nalgebra::{Matrix2, Matrix3, Matrix3x2, Vector2};

use super::{
    check_materials, check_positions, check_positive, material_of, project_stencil_hessian, rest_triangle, vertex,
    write_block,
};
use crate::energy::{Local, StencilEnergy, Want};
use crate::error::InputError;
use crate::material::ElementMaterial;

/// StVK membrane energy of a triangle mesh in 3D, one stencil (3 vertices) per triangle.
///
/// Per triangle, with `F` the 3x2 deformation gradient relative to a 2D frame of the rest
/// triangle and `E = (F^T F - I) / 2` the Green strain:
/// `thickness * rest_area * (mu E:E + lambda_ps / 2 tr(E)^2)`.
#[derive(Clone, Debug)]
pub struct ShellMembrane {
    triangles: Vec<[usize; 3]>,
    params: Vec<MembraneParams>,
}

/// Per-triangle constants of the membrane energy.
#[derive(Clone, Copy, Debug)]
struct MembraneParams {
    /// Inverse of the rest edge matrix in the triangle's 2D frame (`F = [x1-x0, x2-x0] * this`).
    rest_inv: Matrix2<f64>,
    /// thickness * rest area.
    weight: f64,
    /// Shear modulus.
    mu: f64,
    /// Plane-stress first Lamé parameter.
    lambda: f64,
}

impl ShellMembrane {
    /// Builds the membrane energy of triangles `tris` over rest positions `rest` (flat, 3 per
    /// vertex). `materials` holds one material for all triangles or one per triangle;
    /// `source` names the input in errors.
    pub fn new(
        rest: &[f64],
        tris: &[[usize; 3]],
        materials: &[ElementMaterial],
        thickness: f64,
        source: &Path,
    ) -> Result<Self, InputError> {
        let num_vertices = check_positions(rest, source)?;
        check_positive(thickness, "thickness", source)?;
        check_materials(materials, tris.len(), "triangle", source)?;
        let mut params = Vec::with_capacity(tris.len());
        for (t, tri) in tris.iter().enumerate() {
            let [x0, x1, x2] = rest_triangle(rest, num_vertices, t, tri, source)?;
            let e1 = x1 - x0;
            let e2 = x2 - x0;
            let normal = e1.cross(&e2);
            let along = e1.normalize();
            let across = normal.normalize().cross(&along);
            let rest_edges = Matrix2::new(e1.norm(), e2.dot(&along), 0.0, e2.dot(&across));
            let rest_inv = rest_edges
                .try_inverse()
                .ok_or_else(|| InputError::element(source, t, "degenerate rest triangle (zero area)"))?;
            let m = material_of(materials, t);
            params.push(MembraneParams {
                rest_inv,
                weight: thickness * 0.5 * normal.norm(),
                mu: m.mu(),
                lambda: m.lambda_plane_stress(),
            });
        }
        Ok(ShellMembrane {
            triangles: tris.to_vec(),
            params,
        })
    }
}

impl StencilEnergy for ShellMembrane {
    fn name(&self) -> &'static str {
        "membrane"
    }

    fn dim(&self) -> usize {
        3
    }

    fn len(&self) -> usize {
        self.triangles.len()
    }

    fn stencil(&self, s: usize) -> &[usize] {
        &self.triangles[s]
    }

    fn eval(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        let p = &self.params[s];
        let xs = [vertex(x, 0), vertex(x, 1), vertex(x, 2)];
        let edges = Matrix3x2::from_columns(&[xs[1] - xs[0], xs[2] - xs[0]]);
        let f = edges * p.rest_inv;
        let strain = (f.transpose() * f - Matrix2::identity()) * 0.5;
        let tr = strain.trace();
        let value = p.weight * (p.mu * strain.norm_squared() + 0.5 * p.lambda * tr * tr);
        if !want.gradient() {
            return value;
        }
        // Second Piola-Kirchhoff stress S and first Piola-Kirchhoff stress P = F S.
        let stress = strain * (2.0 * p.mu) + Matrix2::identity() * (p.lambda * tr);
        let piola = f * stress;
        // F = sum_a x_a g_a^T, so dpsi/dx_a = P g_a.
        let g1: Vector2<f64> = p.rest_inv.row(0).transpose();
        let g2: Vector2<f64> = p.rest_inv.row(1).transpose();
        let g = [-(g1 + g2), g1, g2];
        for a in 0..3 {
            let ga = piola * g[a] * p.weight;
            out.grad[3 * a..3 * a + 3].copy_from_slice(ga.as_slice());
        }
        let Some(project) = want.hessian() else {
            return value;
        };
        // d(P g_a)/dx_b = (g_b.S g_a) I + mu (F g_b)(F g_a)^T + mu (g_a.g_b) F F^T
        //                 + lambda (F g_a)(F g_b)^T.
        let fg = [f * g[0], f * g[1], f * g[2]];
        let fft = f * f.transpose();
        for a in 0..3 {
            for b in 0..3 {
                let block = (Matrix3::identity() * g[b].dot(&(stress * g[a]))
                    + fg[b] * fg[a].transpose() * p.mu
                    + fft * (p.mu * g[a].dot(&g[b]))
                    + fg[a] * fg[b].transpose() * p.lambda)
                    * p.weight;
                write_block(&mut out.hess, 9, a, b, &block);
            }
        }
        if project {
            project_stencil_hessian(&mut out.hess, 9);
        }
        value
    }
}
