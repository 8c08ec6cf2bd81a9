//! Cloth energies: discrete shells (Grinspun et al. 2003) with a Saint Venant-Kirchhoff
//! membrane.
//!
//! - [`ShellMembrane`]: in-plane stretching and shearing of each triangle, StVK with the
//!   plane-stress Lamé parameters, integrated over the thickness.
//! - [`ShellBending`]: one hinge per interior edge, penalising the change of the dihedral
//!   angle between the two faces.

use std::collections::HashMap;
use std::f64::consts::{FRAC_1_SQRT_2, PI};
use std::path::Path;

use nalgebra::{Matrix2, Matrix3, Matrix3x2, SMatrix, SVector, Vector2, Vector3};

use super::psd::project_psd;
use super::{Local, StencilEnergy, Want};
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

/// Hinge bending energy of a triangle mesh in 3D (discrete shells), one stencil per
/// interior edge: the edge's two vertices, then the vertex opposite the edge in each of its
/// two triangles (4 vertices).
///
/// Per hinge, `k (theta - theta_rest)^2 |e_rest|^2 / A_rest` with `theta` the signed angle
/// between the two face normals, `A_rest` the summed rest area of the two triangles and
/// `k = D / 2`, `D = E t^3 / (12 (1 - nu^2))` the plate bending stiffness.
///
/// Choice of `k`: bend a flat sheet onto a cylinder of radius `R` (curvature `kappa = 1/R`),
/// continuum energy density `D/2 kappa^2`. On a regular grid of squares of side `h`, each
/// split into two triangles (either diagonal), with the cylinder axis along a grid line, the
/// faces of one column of squares stay coplanar: only the edges parallel to the axis are
/// bent, each by the angle `theta = kappa h` between neighbouring columns. Such a hinge has
/// `|e| = h` and `A = 2 (h^2 / 2) = h^2`, and there is one per square of area `h^2`, so the
/// discrete energy density is `k (kappa h)^2 h^2 / h^2 / h^2 = k kappa^2`, hence `k = D/2`.
/// The same constant follows on an equilateral mesh for any axis direction: there a hinge
/// bends by `theta = h (3 K_nn - K_tt) / (2 sqrt 3)` (`K` the curvature tensor, `t` along and
/// `n` across the edge), and summing `k theta^2 |e|^2 / A` over the three edge directions
/// gives `k kappa^2` again. The hinge model is mesh-dependent, a known property of it: on the
/// right-triangle grid a cylinder whose axis is across the diagonals gets `3 k kappa^2`, and
/// one at 0.3 rad from a grid line about `0.75 k kappa^2`.
///
/// The energy is that of Grinspun et al. 2003, `3 |e|^2 / A (theta - theta_rest)^2`, with
/// their stiffness equal to `D / 6`. The angle difference is wrapped into `(-pi, pi]`, so the
/// only discontinuity is at a hinge folded by `pi` away from its rest angle (faces through
/// each other).
#[derive(Clone, Debug)]
pub struct ShellBending {
    hinges: Vec<[usize; 4]>,
    params: Vec<HingeParams>,
}

/// Per-hinge constants of the bending energy.
#[derive(Clone, Copy, Debug)]
struct HingeParams {
    /// k |e_rest|^2 / A_rest.
    stiffness: f64,
    /// Rest dihedral angle.
    rest_angle: f64,
    /// 1 / |e_rest|, used to rescale the angle computation to unit size.
    inv_rest_length: f64,
}

impl ShellBending {
    /// Builds the bending energy of triangles `tris` over rest positions `rest` (flat, 3 per
    /// vertex), one hinge per edge shared by two triangles. `materials` holds one material
    /// for all triangles or one per triangle (a hinge uses the average of its two); `source`
    /// names the input in errors. Edges of more than two triangles are rejected.
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
        let mut areas = Vec::with_capacity(tris.len());
        for (t, tri) in tris.iter().enumerate() {
            let [x0, x1, x2] = rest_triangle(rest, num_vertices, t, tri, source)?;
            areas.push(0.5 * (x1 - x0).cross(&(x2 - x0)).norm());
        }
        let mut hinges = Vec::new();
        let mut params = Vec::new();
        for edge in interior_edges(tris, source)? {
            let hinge = [edge.ends[0], edge.ends[1], edge.opposite[0], edge.opposite[1]];
            let [x0, x1, x2, x3] = hinge.map(|v| vertex(rest, v));
            let rest_length = (x1 - x0).norm();
            let rest_angle = dihedral_angle(&(x1 - x0), &(x2 - x0), &(x3 - x0));
            let [m0, m1] = edge.triangles.map(|t| material_of(materials, t));
            let youngs = 0.5 * (m0.youngs + m1.youngs);
            let poisson = 0.5 * (m0.poisson + m1.poisson);
            let plate = youngs * thickness.powi(3) / (12.0 * (1.0 - poisson * poisson));
            let area = areas[edge.triangles[0]] + areas[edge.triangles[1]];
            hinges.push(hinge);
            params.push(HingeParams {
                stiffness: 0.5 * plate * rest_length * rest_length / area,
                rest_angle,
                inv_rest_length: 1.0 / rest_length,
            });
        }
        Ok(ShellBending { hinges, params })
    }

    /// Rest dihedral angle of hinge `h` (zero for a flat sheet).
    pub fn rest_angle(&self, h: usize) -> f64 {
        self.params[h].rest_angle
    }
}

impl StencilEnergy for ShellBending {
    fn name(&self) -> &'static str {
        "bending"
    }

    fn dim(&self) -> usize {
        3
    }

    fn len(&self) -> usize {
        self.hinges.len()
    }

    fn stencil(&self, s: usize) -> &[usize] {
        &self.hinges[s]
    }

    fn eval(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        let p = &self.params[s];
        // The angle is scale invariant: evaluate it on the hinge scaled to unit rest edge
        // length (keeps the degree-8 intermediate terms near 1) and rescale derivatives.
        let scale = p.inv_rest_length;
        let x0 = vertex(x, 0);
        let e = (vertex(x, 1) - x0) * scale;
        let a = (vertex(x, 2) - x0) * scale;
        let b = (vertex(x, 3) - x0) * scale;
        // The angle with as many of its derivatives as asked for (the training loss's hot
        // path, the gradient alone, forms no Hessian).
        let (theta, derivatives) = match want {
            Want::Value => (dihedral_angle(&e, &a, &b), None),
            Want::Gradient => {
                let (theta, dtheta) = DihedralAngle::with_gradient(&e, &a, &b);
                (theta, Some((dtheta, None)))
            }
            Want::Hessian { .. } => {
                let angle = DihedralAngle::with_hessian(&e, &a, &b);
                (angle.theta, Some((angle.grad, Some(angle.hess))))
            }
        };
        // E = k delta^2: dE = 2 k delta dtheta, d2E = 2 k (dtheta dtheta^T + delta d2theta),
        // with d/dx = scale d/d(scaled x).
        let delta = wrap_angle(theta - p.rest_angle);
        if let Some((dtheta, d2theta)) = derivatives {
            let grad = dtheta * (2.0 * p.stiffness * delta * scale);
            let hess = d2theta
                .map(|d2theta| (dtheta * dtheta.transpose() + d2theta * delta) * (2.0 * p.stiffness * scale * scale));
            let project = want.hessian().unwrap_or(false);
            scatter_relative(&HINGE_RELATIVE, &grad, hess.as_ref().map(|h| (h, project)), out);
        }
        p.stiffness * delta * delta
    }
}

/// How the hinge's relative vectors `(x1 - x0, x2 - x0, x3 - x0)` depend on its vertices:
/// row `a` holds the coefficients of vertex `a` in each.
const HINGE_RELATIVE: [[f64; 3]; 4] = [[-1.0, -1.0, -1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

/// Signed dihedral angle of a hinge with edge `e = x1 - x0` and opposite vertices
/// `x2 = x0 + a`, `x3 = x0 + b`: the angle between the face normals `n1 = e x a` and
/// `n2 = b x e`, positive when the faces turn about `e` by the right-hand rule from `n1` to
/// `n2`; zero for a flat hinge with `x2` and `x3` on opposite sides of the edge.
fn dihedral_angle(e: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    AngleParts::new(e, a, b).theta()
}

/// The dihedral angle of a hinge with its gradient and Hessian with respect to the stacked
/// relative vectors `(e, a, b)` (the angle alone: [`dihedral_angle`]; with only the
/// gradient: [`DihedralAngle::with_gradient`]).
///
/// With `n1 = e x a`, `n2 = b x e`: `n1 x n2 = -det(e, a, b) e` and
/// `n1 . n2 = (e.a)(e.b) - |e|^2 (a.b)`, so `theta = atan2(y, x)` with
/// `y = -det(e, a, b) |e|` and `x = (e.a)(e.b) - |e|^2 (a.b)`. The atan2 form is accurate for
/// nearly flat and for strongly folded hinges alike; the derivatives follow by the chain
/// rule through `atan2` from those of `x` and `y`, which are simple closed forms.
struct DihedralAngle {
    theta: f64,
    grad: SVector<f64, 9>,
    hess: SMatrix<f64, 9, 9>,
}

impl DihedralAngle {
    /// The angle and its gradient (zero where a face has collapsed and the angle is
    /// undefined).
    fn with_gradient(e: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> (f64, SVector<f64, 9>) {
        let parts = AngleParts::new(e, a, b);
        let mut grad = SVector::zeros();
        if parts.r2 > 0.0 {
            let (dx, dy) = parts.argument_gradients();
            grad = (dy * parts.x - dx * parts.y) / parts.r2;
        }
        (parts.theta(), grad)
    }

    /// The angle, its gradient and its Hessian.
    fn with_hessian(e: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> Self {
        let parts = AngleParts::new(e, a, b);
        let theta = parts.theta();
        if parts.r2 <= 0.0 {
            // A collapsed face: the angle is undefined, leave it to the membrane.
            return DihedralAngle {
                theta,
                grad: SVector::zeros(),
                hess: SMatrix::zeros(),
            };
        }
        let (dx, dy) = parts.argument_gradients();
        let (hx, hy) = parts.argument_hessians();
        let (x, y, r2) = (parts.x, parts.y, parts.r2);
        let r4 = r2 * r2;
        // First and second partial derivatives of atan2(y, x).
        let (tx, ty) = (-y / r2, x / r2);
        let (txx, tyy, txy) = (2.0 * x * y / r4, -2.0 * x * y / r4, (y * y - x * x) / r4);
        let dxdy = dx * dy.transpose();
        let hess =
            hx * tx + hy * ty + dx * dx.transpose() * txx + dy * dy.transpose() * tyy + (dxdy + dxdy.transpose()) * txy;
        DihedralAngle {
            theta,
            grad: dy * ty + dx * tx,
            hess,
        }
    }
}

/// Intermediate quantities of the dihedral angle of `(e, a, b)`.
struct AngleParts {
    e: Vector3<f64>,
    a: Vector3<f64>,
    b: Vector3<f64>,
    /// |e|.
    length: f64,
    /// det(e, a, b).
    det: f64,
    x: f64,
    y: f64,
    r2: f64,
}

impl AngleParts {
    fn new(e: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> Self {
        let det = e.dot(&a.cross(b));
        let length = e.norm();
        let y = -det * length;
        let x = e.dot(a) * e.dot(b) - e.norm_squared() * a.dot(b);
        AngleParts {
            e: *e,
            a: *a,
            b: *b,
            length,
            det,
            x,
            y,
            r2: x * x + y * y,
        }
    }

    /// The signed angle, `atan2(y, x)`.
    fn theta(&self) -> f64 {
        self.y.atan2(self.x)
    }

    /// Gradient of det(e, a, b) with respect to (e, a, b).
    fn det_gradient(&self) -> SVector<f64, 9> {
        stack3(&self.a.cross(&self.b), &self.b.cross(&self.e), &self.e.cross(&self.a))
    }

    /// Gradients of `x` and `y`.
    fn argument_gradients(&self) -> (SVector<f64, 9>, SVector<f64, 9>) {
        let (e, a, b) = (&self.e, &self.a, &self.b);
        let (ea, eb, ee, ab) = (e.dot(a), e.dot(b), e.norm_squared(), a.dot(b));
        let dx = stack3(
            &(a * eb + b * ea - e * (2.0 * ab)),
            &(e * eb - b * ee),
            &(e * ea - a * ee),
        );
        let unit_e = stack3(&(e / self.length), &Vector3::zeros(), &Vector3::zeros());
        let dy = -(self.det_gradient() * self.length + unit_e * self.det);
        (dx, dy)
    }

    /// Hessians of `x` and `y`.
    fn argument_hessians(&self) -> (SMatrix<f64, 9, 9>, SMatrix<f64, 9, 9>) {
        let (e, a, b) = (&self.e, &self.a, &self.b);
        let (ea, eb, ee, ab) = (e.dot(a), e.dot(b), e.norm_squared(), a.dot(b));
        let id = Matrix3::identity();
        let mut hx = SMatrix::<f64, 9, 9>::zeros();
        let ee_block = a * b.transpose() + b * a.transpose() - id * (2.0 * ab);
        let ea_block = id * eb + b * e.transpose() - e * b.transpose() * 2.0;
        let eb_block = id * ea + a * e.transpose() - e * a.transpose() * 2.0;
        let ab_block = e * e.transpose() - id * ee;
        set_symmetric_block(&mut hx, 0, 0, &ee_block);
        set_symmetric_block(&mut hx, 0, 1, &ea_block);
        set_symmetric_block(&mut hx, 0, 2, &eb_block);
        set_symmetric_block(&mut hx, 1, 2, &ab_block);

        // y = -det |e|.
        let mut hdet = SMatrix::<f64, 9, 9>::zeros();
        set_symmetric_block(&mut hdet, 0, 1, &-b.cross_matrix());
        set_symmetric_block(&mut hdet, 0, 2, &a.cross_matrix());
        set_symmetric_block(&mut hdet, 1, 2, &-e.cross_matrix());
        let unit_e = e / self.length;
        let mut hlength = SMatrix::<f64, 9, 9>::zeros();
        let projector = (id - unit_e * unit_e.transpose()) / self.length;
        set_symmetric_block(&mut hlength, 0, 0, &projector);
        let ddet = self.det_gradient();
        let dlength = stack3(&unit_e, &Vector3::zeros(), &Vector3::zeros());
        let cross = ddet * dlength.transpose();
        let hy = -(hdet * self.length + cross + cross.transpose() + hlength * self.det);
        (hx, hy)
    }
}

/// Wraps an angle difference into `(-pi, pi]`.
fn wrap_angle(delta: f64) -> f64 {
    if delta > PI {
        delta - 2.0 * PI
    } else if delta <= -PI {
        delta + 2.0 * PI
    } else {
        delta
    }
}

/// An edge shared by two triangles.
struct InteriorEdge {
    /// The edge's vertices, in the order of the first triangle.
    ends: [usize; 2],
    /// The vertex opposite the edge in each triangle.
    opposite: [usize; 2],
    /// The two triangles.
    triangles: [usize; 2],
}

/// Edges shared by exactly two triangles, in order of first appearance. An edge of three or
/// more triangles is an error naming the edge and the triangle that made it non-manifold.
fn interior_edges(tris: &[[usize; 3]], source: &Path) -> Result<Vec<InteriorEdge>, InputError> {
    struct Seen {
        ends: [usize; 2],
        opposite: [usize; 2],
        triangles: [usize; 2],
        count: usize,
    }
    let mut index: HashMap<(usize, usize), usize> = HashMap::with_capacity(3 * tris.len() / 2);
    let mut seen: Vec<Seen> = Vec::with_capacity(3 * tris.len() / 2);
    for (t, tri) in tris.iter().enumerate() {
        for k in 0..3 {
            let (i, j, opposite) = (tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]);
            let key = (i.min(j), i.max(j));
            let slot = *index.entry(key).or_insert_with(|| {
                seen.push(Seen {
                    ends: [i, j],
                    opposite: [opposite, usize::MAX],
                    triangles: [t, usize::MAX],
                    count: 0,
                });
                seen.len() - 1
            });
            let edge = &mut seen[slot];
            match edge.count {
                0 => {}
                1 => {
                    edge.opposite[1] = opposite;
                    edge.triangles[1] = t;
                }
                _ => {
                    return Err(InputError::element(
                        source,
                        t,
                        format!(
                            "non-manifold edge ({}, {}): shared by triangles {}, {} and {t}",
                            key.0, key.1, edge.triangles[0], edge.triangles[1]
                        ),
                    ))
                }
            }
            edge.count += 1;
        }
    }
    Ok(seen
        .into_iter()
        .filter(|e| e.count == 2)
        .map(|e| InteriorEdge {
            ends: e.ends,
            opposite: e.opposite,
            triangles: e.triangles,
        })
        .collect())
}

/// Checks a triangle's vertex indices and rest shape, returning its rest vertices.
fn rest_triangle(
    rest: &[f64],
    num_vertices: usize,
    t: usize,
    tri: &[usize; 3],
    source: &Path,
) -> Result<[Vector3<f64>; 3], InputError> {
    for &v in tri {
        if v >= num_vertices {
            return Err(InputError::element(
                source,
                t,
                format!("triangle vertex index {v} out of range ({num_vertices} vertices)"),
            ));
        }
    }
    if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
        return Err(InputError::element(
            source,
            t,
            format!("triangle repeats a vertex: {tri:?}"),
        ));
    }
    let xs = tri.map(|v| vertex(rest, v));
    let e1 = xs[1] - xs[0];
    let e2 = xs[2] - xs[0];
    let longest = e1
        .norm_squared()
        .max(e2.norm_squared())
        .max((xs[2] - xs[1]).norm_squared());
    if e1.cross(&e2).norm() <= 1e-12 * longest {
        return Err(InputError::element(source, t, "degenerate rest triangle (zero area)"));
    }
    Ok(xs)
}

// ---------------------------------------------------------------------------------------
// Helpers shared with the rod energies.

/// Checks that `rest` holds whole 3D points with finite coordinates; returns their number.
pub(crate) fn check_positions(rest: &[f64], source: &Path) -> Result<usize, InputError> {
    if !rest.len().is_multiple_of(3) {
        return Err(InputError::field(
            source,
            "vertices",
            format!("{} coordinates is not a whole number of 3D points", rest.len()),
        ));
    }
    if let Some(k) = rest.iter().position(|c| !c.is_finite()) {
        return Err(InputError::field(
            source,
            format!("vertices[{}]", k / 3),
            format!("rest position coordinate {} is {}", k % 3, rest[k]),
        ));
    }
    Ok(rest.len() / 3)
}

/// Checks that a scalar parameter such as a thickness or radius is finite and positive.
pub(crate) fn check_positive(value: f64, field: &str, source: &Path) -> Result<(), InputError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(InputError::field(
            source,
            field,
            format!("must be positive and finite, got {value}"),
        ))
    }
}

/// Checks that there is one material, or one per `element` (`count` of them), each with a
/// positive finite Young's modulus and a Poisson ratio in (-1, 0.5).
pub(crate) fn check_materials(
    materials: &[ElementMaterial],
    count: usize,
    element: &str,
    source: &Path,
) -> Result<(), InputError> {
    if materials.len() != 1 && materials.len() != count {
        return Err(InputError::field(
            source,
            "materials",
            format!(
                "expected 1 material or one per {element} ({count}), got {}",
                materials.len()
            ),
        ));
    }
    for (k, m) in materials.iter().enumerate() {
        if !(m.youngs.is_finite() && m.youngs > 0.0) {
            return Err(InputError::field(
                source,
                format!("materials[{k}].youngs"),
                format!("Young's modulus must be positive and finite, got {}", m.youngs),
            ));
        }
        if !(m.poisson.is_finite() && m.poisson > -1.0 && m.poisson < 0.5) {
            return Err(InputError::field(
                source,
                format!("materials[{k}].poisson"),
                format!("Poisson ratio must be in (-1, 0.5), got {}", m.poisson),
            ));
        }
    }
    Ok(())
}

/// The material of element `k`: the only one, or the `k`-th.
pub(crate) fn material_of(materials: &[ElementMaterial], k: usize) -> &ElementMaterial {
    if materials.len() == 1 {
        &materials[0]
    } else {
        &materials[k]
    }
}

/// Vertex `v` of a flat 3D position vector (global, or a stencil's local positions).
pub(crate) fn vertex(x: &[f64], v: usize) -> Vector3<f64> {
    Vector3::new(x[3 * v], x[3 * v + 1], x[3 * v + 2])
}

/// Stacks three 3-vectors into a 9-vector.
fn stack3(p: &Vector3<f64>, q: &Vector3<f64>, r: &Vector3<f64>) -> SVector<f64, 9> {
    SVector::<f64, 9>::from_fn(|i, _| [p, q, r][i / 3][i % 3])
}

/// Sets block `(p, q)` of a block-symmetric matrix to `block` and block `(q, p)` to its
/// transpose.
fn set_symmetric_block<const N: usize>(m: &mut SMatrix<f64, N, N>, p: usize, q: usize, block: &Matrix3<f64>) {
    m.fixed_view_mut::<3, 3>(3 * p, 3 * q).copy_from(block);
    if p != q {
        m.fixed_view_mut::<3, 3>(3 * q, 3 * p).copy_from(&block.transpose());
    }
}

/// Writes the 3x3 block `(a, b)` of the row-major `n x n` matrix `hess`.
pub(crate) fn write_block(hess: &mut [f64], n: usize, a: usize, b: usize, block: &Matrix3<f64>) {
    for i in 0..3 {
        for j in 0..3 {
            hess[(3 * a + i) * n + 3 * b + j] = block[(i, j)];
        }
    }
}

/// Writes into `out` the gradient and (optionally, with its projection flag) Hessian with
/// respect to a stencil's vertices of an energy given as a function of `R / 3` relative
/// vectors `r_p = sum_a coef[a][p] x_a`, from its gradient `grad` and Hessian `hess` with
/// respect to the stacked `r_p`.
pub(crate) fn scatter_relative<const P: usize, const R: usize>(
    coef: &[[f64; P]],
    grad: &SVector<f64, R>,
    hess: Option<(&SMatrix<f64, R, R>, bool)>,
    out: &mut Local,
) {
    debug_assert_eq!(R, 3 * P);
    let n = 3 * coef.len();
    for (a, row) in coef.iter().enumerate() {
        let mut g = Vector3::zeros();
        for (p, &c) in row.iter().enumerate() {
            if c != 0.0 {
                g += grad.fixed_rows::<3>(3 * p) * c;
            }
        }
        out.grad[3 * a..3 * a + 3].copy_from_slice(g.as_slice());
    }
    let Some((hess, project)) = hess else {
        return;
    };
    for (a, row_a) in coef.iter().enumerate() {
        for (b, row_b) in coef.iter().enumerate() {
            let mut block = Matrix3::zeros();
            for (p, &ca) in row_a.iter().enumerate() {
                for (q, &cb) in row_b.iter().enumerate() {
                    if ca != 0.0 && cb != 0.0 {
                        block += hess.fixed_view::<3, 3>(3 * p, 3 * q) * (ca * cb);
                    }
                }
            }
            write_block(&mut out.hess, n, a, b, &block);
        }
    }
    if project {
        project_stencil_hessian(&mut out.hess, n);
    }
}

/// Projects the row-major `n x n` Hessian `hess` of a translation-invariant stencil energy
/// (3D, `n / 3` vertices) onto the PSD cone: the same result as [`project_psd`] (symmetrise,
/// clamp eigenvalues at zero), computed without allocation and on the `n - 3` dimensional
/// complement of the rigid translations, which such a Hessian maps to zero.
pub(crate) fn project_stencil_hessian(hess: &mut [f64], n: usize) {
    // Orthonormal vectors orthogonal to (1, ..., 1) (Helmert basis): for a stencil of `v`
    // vertices, the first `v` rows of the first `v - 1` columns.
    const HELMERT: [[f64; 3]; 4] = [
        [FRAC_1_SQRT_2, 0.408_248_290_463_863, 0.288_675_134_594_812_9],
        [-FRAC_1_SQRT_2, 0.408_248_290_463_863, 0.288_675_134_594_812_9],
        [0.0, -0.816_496_580_927_726, 0.288_675_134_594_812_9],
        [0.0, 0.0, -0.866_025_403_784_438_6],
    ];
    macro_rules! clamp_on_complement {
        ($v:literal, $r:literal) => {{
            let basis = |a: usize, p: usize| HELMERT[a][p];
            let mut reduced = SMatrix::<f64, $r, $r>::zeros();
            for p in 0..$v - 1 {
                for q in 0..$v - 1 {
                    let mut block = Matrix3::zeros();
                    for a in 0..$v {
                        for b in 0..$v {
                            let w = basis(a, p) * basis(b, q);
                            if w != 0.0 {
                                block += read_block(hess, n, a, b) * w;
                            }
                        }
                    }
                    reduced.fixed_view_mut::<3, 3>(3 * p, 3 * q).copy_from(&block);
                }
            }
            let reduced = (reduced + reduced.transpose()) * 0.5;
            // Positive definite (cheap to detect) needs no projection.
            if reduced.cholesky().is_some() {
                symmetrise(hess, n);
                return;
            }
            let eig = reduced.symmetric_eigen();
            if eig.eigenvalues.iter().all(|&l| l >= 0.0) {
                symmetrise(hess, n);
                return;
            }
            let clamped = eig.eigenvalues.map(|l| l.max(0.0));
            let projected =
                eig.eigenvectors * SMatrix::<f64, $r, $r>::from_diagonal(&clamped) * eig.eigenvectors.transpose();
            for a in 0..$v {
                for b in 0..$v {
                    let mut block = Matrix3::zeros();
                    for p in 0..$v - 1 {
                        for q in 0..$v - 1 {
                            let w = basis(a, p) * basis(b, q);
                            if w != 0.0 {
                                block += projected.fixed_view::<3, 3>(3 * p, 3 * q) * w;
                            }
                        }
                    }
                    write_block(hess, n, a, b, &block);
                }
            }
        }};
    }
    match n {
        6 => clamp_on_complement!(2, 3),
        9 => clamp_on_complement!(3, 6),
        12 => clamp_on_complement!(4, 9),
        _ => project_psd(&mut hess[..n * n], n),
    }
}

/// Replaces the row-major `n x n` matrix `m` by its symmetric part.
fn symmetrise(m: &mut [f64], n: usize) {
    for i in 0..n {
        for j in 0..i {
            let mean = 0.5 * (m[i * n + j] + m[j * n + i]);
            m[i * n + j] = mean;
            m[j * n + i] = mean;
        }
    }
}

/// Reads the 3x3 block `(a, b)` of the row-major `n x n` matrix `m`.
fn read_block(m: &[f64], n: usize, a: usize, b: usize) -> Matrix3<f64> {
    Matrix3::from_fn(|i, j| m[(3 * a + i) * n + 3 * b + j])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::fd::{assert_all_stencils, check_stencil};
    use crate::energy::psd::min_eigenvalue;
    use crate::energy::{add_gradient, value};
    use crate::error::Location;
    use nalgebra::Rotation3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use std::f64::consts::FRAC_PI_2;

    const SOURCE: &str = "<test>";

    /// Material and thickness giving stiffnesses of order 1..1e3, so that the relative
    /// finite-difference errors are meaningful.
    fn stiff() -> (ElementMaterial, f64) {
        let m = ElementMaterial {
            youngs: 1e6,
            poisson: 0.3,
            density: 1000.0,
        };
        (m, 0.1)
    }

    /// Cloth from the paper: E = 1 MPa (as a physical stand-in), nu = 0.45, t = 3 mm.
    fn cloth() -> (ElementMaterial, f64) {
        let m = ElementMaterial {
            youngs: 1e6,
            poisson: 0.45,
            density: 1500.0,
        };
        (m, 3e-3)
    }

    fn plate_stiffness(m: &ElementMaterial, thickness: f64) -> f64 {
        m.youngs * thickness.powi(3) / (12.0 * (1.0 - m.poisson * m.poisson))
    }

    fn random_rigid(rng: &mut ChaCha8Rng) -> (Rotation3<f64>, Vector3<f64>) {
        let axis = Vector3::new(rng.random(), rng.random(), rng.random::<f64>()) * 2.0 - Vector3::repeat(1.0);
        let rotation = Rotation3::new(axis.normalize() * rng.random_range(0.0..PI));
        let shift = Vector3::new(rng.random(), rng.random(), rng.random::<f64>()) * 4.0;
        (rotation, shift)
    }

    fn transform(x: &[f64], rotation: &Rotation3<f64>, shift: &Vector3<f64>) -> Vec<f64> {
        x.chunks_exact(3)
            .flat_map(|p| {
                let q = rotation * Vector3::new(p[0], p[1], p[2]) + shift;
                [q.x, q.y, q.z]
            })
            .collect()
    }

    fn perturb(x: &[f64], rng: &mut ChaCha8Rng, amount: f64) -> Vec<f64> {
        x.iter().map(|c| c + amount * rng.random_range(-1.0..1.0)).collect()
    }

    /// A hinge with edge (0,0,0)-(length,0,0), first opposite vertex in the +y half plane and
    /// the second one rotated about the edge so that the dihedral angle is `angle`.
    fn hinge(rng: &mut ChaCha8Rng, angle: f64) -> [f64; 12] {
        let length = rng.random_range(0.5..2.0);
        let (u1, u2) = (
            rng.random_range(-0.3..1.3) * length,
            rng.random_range(-0.3..1.3) * length,
        );
        let (h1, h2) = (rng.random_range(0.3..1.5), rng.random_range(0.3..1.5));
        let (c, s) = (angle.cos(), angle.sin());
        [0.0, 0.0, 0.0, length, 0.0, 0.0, u1, h1, 0.0, u2, -h2 * c, -h2 * s]
    }

    const HINGE_TRIS: [[usize; 3]; 2] = [[0, 1, 2], [1, 0, 3]];

    /// A regular grid of `nu x nv` squares of side `h` in the xy-plane, each split along
    /// one diagonal or the other.
    fn grid(nu: usize, nv: usize, h: f64, flip: bool) -> (Vec<f64>, Vec<[usize; 3]>) {
        let mut rest = Vec::new();
        for j in 0..=nv {
            for i in 0..=nu {
                rest.extend([i as f64 * h, j as f64 * h, 0.0]);
            }
        }
        let id = |i: usize, j: usize| j * (nu + 1) + i;
        let mut tris = Vec::new();
        for j in 0..nv {
            for i in 0..nu {
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                if flip {
                    tris.extend([[a, b, d], [b, c, d]]);
                } else {
                    tris.extend([[a, b, c], [a, c, d]]);
                }
            }
        }
        (rest, tris)
    }

    /// Wraps the xy-plane isometrically onto a cylinder of radius `radius` whose axis is
    /// along y (`axis_y`) or along x.
    fn onto_cylinder(flat: &[f64], radius: f64, axis_y: bool) -> Vec<f64> {
        flat.chunks_exact(3)
            .flat_map(|p| {
                let (s, t) = if axis_y { (p[0], p[1]) } else { (p[1], p[0]) };
                let (across, up) = (radius * (s / radius).sin(), radius * (1.0 - (s / radius).cos()));
                if axis_y {
                    [across, t, up]
                } else {
                    [t, across, up]
                }
            })
            .collect()
    }

    fn path() -> &'static Path {
        Path::new(SOURCE)
    }

    #[test]
    fn membrane_matches_finite_differences_on_random_triangles() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let (m, t) = stiff();
        let mut worst = (0.0f64, 0.0f64);
        for _ in 0..200 {
            let rest: Vec<f64> = (0..9).map(|_| rng.random_range(-1.0..1.0)).collect();
            let Ok(energy) = ShellMembrane::new(&rest, &[[0, 1, 2]], &[m], t, path()) else {
                continue;
            };
            // Stretched, sheared, compressed and occasionally inverted triangles in 3D.
            let (rotation, shift) = random_rigid(&mut rng);
            let x = perturb(&transform(&rest, &rotation, &shift), &mut rng, 0.5);
            let r = check_stencil(&energy, 0, &x, 1e-6);
            worst = (worst.0.max(r.grad_error), worst.1.max(r.hess_error));
        }
        assert!(worst.0 < 1e-7 && worst.1 < 1e-7, "{worst:?}");
    }

    #[test]
    fn bending_matches_finite_differences_on_flat_curved_and_folded_hinges() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let (m, t) = stiff();
        let mut worst = (0.0f64, 0.0f64);
        let angles = [0.0, 1e-7, -1e-5, 0.3, -1.0, 2.0, -2.5, 2.9, -3.0, 3.05];
        for _ in 0..40 {
            for &rest_angle in &[0.0, rng.random_range(-1.0..1.0)] {
                let rest = hinge(&mut rng, rest_angle);
                let energy = ShellBending::new(&rest, &HINGE_TRIS, &[m], t, path()).unwrap();
                assert_eq!(energy.len(), 1);
                for &angle in &angles {
                    let (rotation, shift) = random_rigid(&mut rng);
                    let x = transform(&hinge(&mut rng, angle), &rotation, &shift);
                    let r = check_stencil(&energy, 0, &x, 1e-6);
                    assert!(
                        r.grad_error < 1e-6 && r.hess_error < 1e-6,
                        "angle {angle}, rest {rest_angle}: {r:?}"
                    );
                    worst = (worst.0.max(r.grad_error), worst.1.max(r.hess_error));
                }
            }
        }
        eprintln!("hinge FD worst: gradient {:.1e}, Hessian {:.1e}", worst.0, worst.1);
    }

    #[test]
    fn dihedral_angle_is_the_signed_angle_between_the_faces() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for &angle in &[0.0, 1e-9, 0.5, -0.5, FRAC_PI_2, 3.0, -3.1] {
            let x = hinge(&mut rng, angle);
            let (rotation, shift) = random_rigid(&mut rng);
            let x = transform(&x, &rotation, &shift);
            let [x0, x1, x2, x3] = [0, 1, 2, 3].map(|v| vertex(&x, v));
            let theta = dihedral_angle(&(x1 - x0), &(x2 - x0), &(x3 - x0));
            assert!((theta.abs() - angle.abs()).abs() < 1e-12, "{theta} vs {angle}");
        }
    }

    #[test]
    fn zero_energy_and_gradient_at_flat_and_curved_rest_shapes() {
        let (m, t) = stiff();
        let (flat, tris) = grid(4, 3, 0.25, false);
        let curved = onto_cylinder(&flat, 0.7, true);
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let bumpy = perturb(&flat, &mut rng, 0.05);
        for rest in [flat, curved, bumpy] {
            let membrane = ShellMembrane::new(&rest, &tris, &[m], t, path()).unwrap();
            let bending = ShellBending::new(&rest, &tris, &[m], t, path()).unwrap();
            for energy in [&membrane as &dyn StencilEnergy, &bending] {
                let mut grad = vec![0.0; rest.len()];
                let e = add_gradient(energy, 1.0, &rest, &mut grad);
                let g = grad.iter().fold(0.0f64, |m, g| m.max(g.abs()));
                assert!(e.abs() < 1e-20 && g < 1e-9, "{}: {e:e}, {g:e}", energy.name());
            }
        }
    }

    #[test]
    fn energies_are_invariant_under_rigid_motion() {
        let (m, t) = stiff();
        let (flat, tris) = grid(3, 3, 0.3, true);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let rest = perturb(&flat, &mut rng, 0.05);
        let membrane = ShellMembrane::new(&rest, &tris, &[m], t, path()).unwrap();
        let bending = ShellBending::new(&rest, &tris, &[m], t, path()).unwrap();
        for _ in 0..10 {
            let x = perturb(&onto_cylinder(&rest, 0.5, false), &mut rng, 0.1);
            let (rotation, shift) = random_rigid(&mut rng);
            let moved = transform(&x, &rotation, &shift);
            for energy in [&membrane as &dyn StencilEnergy, &bending] {
                let (a, b) = (value(energy, &x), value(energy, &moved));
                assert!(a > 0.0 && (a - b).abs() <= 1e-10 * a, "{}: {a} {b}", energy.name());
            }
        }
    }

    #[test]
    fn energies_match_finite_differences_on_a_deformed_mesh() {
        let (m, t) = stiff();
        let (flat, tris) = grid(3, 2, 0.4, false);
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        let materials: Vec<ElementMaterial> = (0..tris.len())
            .map(|_| ElementMaterial {
                youngs: m.youngs * rng.random_range(0.5..2.0),
                poisson: rng.random_range(0.0..0.45),
                ..m
            })
            .collect();
        let membrane = ShellMembrane::new(&flat, &tris, &materials, t, path()).unwrap();
        let bending = ShellBending::new(&flat, &tris, &materials, t, path()).unwrap();
        let x = perturb(&onto_cylinder(&flat, 0.4, true), &mut rng, 0.05);
        assert_all_stencils(&membrane, &x, 1e-6, 1e-7);
        assert_all_stencils(&bending, &x, 1e-6, 1e-6);
    }

    #[test]
    fn projected_hessians_are_positive_semidefinite() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (m, t) = stiff();
        let mut negative_seen = [false; 2];
        for _ in 0..50 {
            let (rest_angle, angle) = (rng.random_range(-0.5..0.5), rng.random_range(-3.0..3.0));
            let rest = hinge(&mut rng, rest_angle);
            let membrane = ShellMembrane::new(&rest, &HINGE_TRIS, &[m], t, path()).unwrap();
            let bending = ShellBending::new(&rest, &HINGE_TRIS, &[m], t, path()).unwrap();
            let x = hinge(&mut rng, angle);
            let x = perturb(&x, &mut rng, 0.3);
            for (k, energy) in [&membrane as &dyn StencilEnergy, &bending].iter().enumerate() {
                let mut local = [0.0; 12];
                let n = crate::energy::gather(*energy, 0, &x, &mut local);
                let mut out = Local::default();
                energy.eval(0, &local[..n], Want::Hessian { project: false }, &mut out);
                let exact_min = min_eigenvalue(&out.hess[..n * n], n);
                negative_seen[k] |= exact_min < 0.0;
                energy.eval(0, &local[..n], Want::Hessian { project: true }, &mut out);
                let scale = out.hess[..n * n].iter().fold(1.0f64, |m, h| m.max(h.abs()));
                let min = min_eigenvalue(&out.hess[..n * n], n);
                assert!(min > -1e-10 * scale, "{}: {min}", energy.name());
            }
        }
        assert_eq!(negative_seen, [true, true], "the test should include indefinite cases");
    }

    const CYLINDER_RADIUS: f64 = 0.8;

    /// Bends a flat strip of `n x n/2` squares onto a cylinder; returns the membrane and
    /// bending energies as fractions of the continuum bending energy.
    fn cylinder_ratios(n: usize, flip: bool, axis_y: bool) -> (f64, f64) {
        let (m, t) = cloth();
        let (width, radius) = (1.0, CYLINDER_RADIUS);
        let h = width / n as f64;
        let (nu, nv) = if axis_y { (n, n / 2) } else { (n / 2, n) };
        let (flat, tris) = grid(nu, nv, h, flip);
        let x = onto_cylinder(&flat, radius, axis_y);
        let membrane = ShellMembrane::new(&flat, &tris, &[m], t, path()).unwrap();
        let bending = ShellBending::new(&flat, &tris, &[m], t, path()).unwrap();
        let area = width * width / 2.0;
        let continuum = 0.5 * plate_stiffness(&m, t) / (radius * radius) * area;
        (value(&membrane, &x) / continuum, value(&bending, &x) / continuum)
    }

    #[test]
    fn cylinder_bending_matches_the_plate_energy() {
        for flip in [false, true] {
            for axis_y in [true, false] {
                for n in [10, 20, 40, 80] {
                    let (membrane, bending) = cylinder_ratios(n, flip, axis_y);
                    eprintln!(
                        "cylinder n={n} flip={flip} axis_y={axis_y}: bending/continuum \
                         {bending:.5}, membrane/continuum {membrane:.2e}"
                    );
                    // The only discrepancy is the boundary: n - 1 hinge lines for n columns.
                    assert!((bending - (1.0 - 1.0 / n as f64)).abs() < 1e-3, "{bending}");
                    // Chords shorten edges across the axis by ~h^2 / (24 R^2): a membrane
                    // energy of relative size ~h^4 / (48 R^2 t^2).
                    let (h, t) = (1.0 / n as f64, cloth().1);
                    let chord_estimate = h.powi(4) / (48.0 * (CYLINDER_RADIUS * t).powi(2));
                    assert!(membrane < 1.2 * chord_estimate, "{membrane} vs {chord_estimate}");
                    if n >= 40 {
                        assert!((bending - 1.0).abs() < 0.03, "{bending}");
                        assert!(membrane < 2e-3, "{membrane}");
                    }
                }
            }
        }
    }

    /// A patch of equilateral triangles of side `h`: `nv` rows of `2 nu` triangles.
    fn equilateral(nu: usize, nv: usize, h: f64) -> (Vec<f64>, Vec<[usize; 3]>) {
        let mut rest = Vec::new();
        for j in 0..=nv {
            let shift = if j % 2 == 1 { 0.5 * h } else { 0.0 };
            for i in 0..=nu {
                rest.extend([i as f64 * h + shift, j as f64 * h * 0.75f64.sqrt(), 0.0]);
            }
        }
        let id = |i: usize, j: usize| j * (nu + 1) + i;
        let mut tris = Vec::new();
        for j in 0..nv {
            for i in 0..nu {
                if j % 2 == 0 {
                    tris.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
                    tris.push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
                } else {
                    tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
                    tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                }
            }
        }
        (rest, tris)
    }

    /// Wraps the xy-plane isometrically onto a cylinder of radius `radius` whose axis makes
    /// the angle `axis` with the x-axis.
    fn onto_tilted_cylinder(flat: &[f64], radius: f64, axis: f64) -> Vec<f64> {
        let (along, across) = (
            Vector3::new(axis.cos(), axis.sin(), 0.0),
            Vector3::new(-axis.sin(), axis.cos(), 0.0),
        );
        flat.chunks_exact(3)
            .flat_map(|p| {
                let p = Vector3::new(p[0], p[1], p[2]);
                let (t, s) = (p.dot(&along), p.dot(&across));
                let q = along * t
                    + across * (radius * (s / radius).sin())
                    + Vector3::z() * (radius * (1.0 - (s / radius).cos()));
                [q.x, q.y, q.z]
            })
            .collect()
    }

    #[test]
    fn cylinder_bending_on_an_equilateral_mesh_is_isotropic() {
        let (m, t) = cloth();
        let radius = CYLINDER_RADIUS;
        for n in [10, 20, 40, 80] {
            let h = 1.0 / n as f64;
            let (flat, tris) = equilateral(n, n, h);
            let area: f64 = tris
                .iter()
                .map(|tri| {
                    let [a, b, c] = tri.map(|v| vertex(&flat, v));
                    0.5 * (b - a).cross(&(c - a)).norm()
                })
                .sum();
            let bending = ShellBending::new(&flat, &tris, &[m], t, path()).unwrap();
            let continuum = 0.5 * plate_stiffness(&m, t) / (radius * radius) * area;
            let ratios: Vec<f64> = [0.0, 0.4, 1.0, FRAC_PI_2, 2.5]
                .iter()
                .map(|&axis| value(&bending, &onto_tilted_cylinder(&flat, radius, axis)) / continuum)
                .collect();
            eprintln!("equilateral cylinder n={n}: bending/continuum {ratios:.4?}");
            for r in &ratios {
                assert!((r - 1.0).abs() < 2.0 / n as f64, "n = {n}: {ratios:?}");
            }
        }
    }

    #[test]
    fn stencil_projection_equals_full_eigenvalue_clamping() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        for vertices in 2..=4 {
            let n = 3 * vertices;
            for _ in 0..20 {
                // A random symmetric matrix acting on relative vectors x_a - x_0, so that it
                // maps rigid translations to zero, as every stencil Hessian here does.
                let r = n - 3;
                let a: Vec<f64> = (0..r * r).map(|_| rng.random_range(-1.0..1.0)).collect();
                let relative = nalgebra::DMatrix::from_fn(r, r, |i, j| a[i * r + j] + a[j * r + i]);
                let map = nalgebra::DMatrix::from_fn(r, n, |i, j| {
                    let (p, a) = (i / 3, j / 3);
                    let same = if i % 3 == j % 3 { 1.0 } else { 0.0 };
                    same * if a == 0 {
                        -1.0
                    } else if a == p + 1 {
                        1.0
                    } else {
                        0.0
                    }
                });
                let full = map.transpose() * relative * map;
                let mut h: Vec<f64> = (0..n * n).map(|k| full[(k / n, k % n)]).collect();
                let mut want = h.clone();
                project_psd(&mut want, n);
                project_stencil_hessian(&mut h, n);
                let err = h.iter().zip(&want).fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
                assert!(err < 1e-12 * full.amax(), "{vertices} vertices: {err:e}");
            }
        }
    }

    fn error_of<T>(result: Result<T, InputError>) -> InputError {
        match result {
            Ok(_) => panic!("expected an error"),
            Err(e) => e,
        }
    }

    #[test]
    fn bad_input_errors_name_the_element_or_field() {
        let (m, t) = stiff();
        let (rest, tris) = grid(2, 1, 1.0, false);
        let both = |rest: &[f64], tris: &[[usize; 3]], mats: &[ElementMaterial], t: f64| {
            let a = error_of(ShellMembrane::new(rest, tris, mats, t, path()));
            let b = error_of(ShellBending::new(rest, tris, mats, t, path()));
            assert_eq!(a, b);
            assert_eq!(a.file, Path::new(SOURCE));
            a
        };
        let mut out_of_range = tris.clone();
        out_of_range[2][1] = 99;
        let e = both(&rest, &out_of_range, &[m], t);
        assert_eq!(e.location, Location::Element(2));
        assert!(e.message.contains("99"), "{e}");

        let mut nan = rest.clone();
        nan[4] = f64::NAN;
        let e = both(&nan, &tris, &[m], t);
        assert_eq!(e.location, Location::Field("vertices[1]".into()));

        let e = both(&rest, &tris, &[m], 0.0);
        assert_eq!(e.location, Location::Field("thickness".into()));
        let e = both(&rest, &tris, &[m], f64::NAN);
        assert_eq!(e.location, Location::Field("thickness".into()));

        let mut bad = vec![m; tris.len()];
        bad[3].poisson = 0.5;
        let e = both(&rest, &tris, &bad, t);
        assert_eq!(e.location, Location::Field("materials[3].poisson".into()));
        bad[3] = ElementMaterial { youngs: -1.0, ..m };
        let e = both(&rest, &tris, &bad, t);
        assert_eq!(e.location, Location::Field("materials[3].youngs".into()));
        let e = both(&rest, &tris, &[m, m], t);
        assert_eq!(e.location, Location::Field("materials".into()));

        let mut degenerate = rest.clone();
        degenerate[4 * 3..4 * 3 + 3].copy_from_slice(&[0.5, 0.0, 0.0]);
        let e = both(&degenerate, &[[0, 1, 4]], &[m], t);
        assert_eq!(e.location, Location::Element(0));
        let e = both(&rest, &[[0, 1, 4], [1, 1, 2]], &[m], t);
        assert_eq!(e.location, Location::Element(1));

        // Three triangles on edge (0, 1): the third one is named.
        let fan = [[0, 1, 3], [1, 0, 4], [0, 1, 5]];
        ShellMembrane::new(&rest, &fan, &[m], t, path()).unwrap();
        let e = error_of(ShellBending::new(&rest, &fan, &[m], t, path()));
        assert_eq!(e.location, Location::Element(2));
        assert!(e.message.contains("(0, 1)"), "{e}");
    }

    #[test]
    fn hinges_are_the_interior_edges() {
        let (m, t) = stiff();
        let (rest, tris) = grid(3, 2, 1.0, true);
        let bending = ShellBending::new(&rest, &tris, &[m], t, path()).unwrap();
        // 3 x 2 squares: 12 triangles, 6 diagonals, 2 x 2 vertical and 3 x 1 horizontal
        // interior edges.
        assert_eq!(bending.len(), 6 + 4 + 3);
        for h in 0..bending.len() {
            assert_eq!(bending.rest_angle(h), 0.0);
            let s = bending.stencil(h);
            let shared = tris.iter().filter(|t| t.contains(&s[0]) && t.contains(&s[1]));
            assert_eq!(shared.count(), 2);
        }
    }
}
