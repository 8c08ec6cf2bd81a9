//! The hinge bending energy of cloth (discrete shells).

use std::collections::HashMap;
use std::f64::consts::PI;
use std::path::Path;

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

use super::{check_materials, check_positions, check_positive, material_of, rest_triangle, scatter_relative, vertex};
use crate::energy::{Local, StencilEnergy, Want};
use crate::error::InputError;
use crate::material::ElementMaterial;

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
pub(super) fn dihedral_angle(e: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
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
