//! Closest points of contact pairs as barycentric coordinates, their Jacobians with respect
//! to the stencil's positions, and the relative velocity they define (IPC's toolkit
//! conventions: coordinates of the *unclamped* closest points of the lines / plane, which
//! is what a stencil of a given closest-feature type needs).
//!
//! Each coordinate vector `c` solves `A c = b` (a 2x2 Gram system, or one equation for a
//! point and an edge); its Jacobian comes from differentiating the optimality conditions
//! `F(c, z) = 0` implicitly: `dc/dz = -A^{-1} dF/dz`.
//!
//! Where that system is singular (a zero-length edge, parallel edges, a zero-area triangle)
//! the lines or plane have no single closest point: the coordinates are then those of the
//! closest features that the distance's classification picks (what the potentials use
//! there), and the Jacobian is zero.

use crate::contact::distance::reduced::{axpy, cross_accurate, dot, scale, sub, vertex};
use crate::contact::distance::{edge_edge_type, point_triangle_type, EdgeEdgeType, PointTriangleType};

/// `alpha` with `e0 + alpha (e1 - e0)` closest to `p` on the line of `x = [p, e0, e1]`, and
/// `d alpha / dx` (`3 * dim` entries used).
pub fn point_edge_closest_point(x: &[f64], dim: usize) -> (f64, [f64; 9]) {
    let (p, e0, e1) = (vertex(x, dim, 0), vertex(x, dim, 1), vertex(x, dim, 2));
    let (r, e) = (sub(p, e0), sub(e1, e0));
    let (s, c) = (dot(r, e), dot(e, e));
    if c == 0.0 {
        return (0.0, [0.0; 9]);
    }
    let d_r = scale(1.0 / c, e);
    let d_e = axpy(scale(1.0 / c, r), -2.0 * s / (c * c), e);
    let mut jac = [0.0; 9];
    for i in 0..dim {
        jac[i] = d_r[i];
        jac[dim + i] = -d_r[i] - d_e[i];
        jac[2 * dim + i] = d_e[i];
    }
    (s / c, jac)
}

/// Solves the 2x2 system `a c = -df` (determinant `det`, computed by the caller without
/// cancellation) for each of the 9 reduced coordinates and maps them to the 12 vertex dofs
/// with `y_k = sum_a coef[k][a] x_a`.
fn implicit_jacobian(a: [[f64; 2]; 2], det: f64, df: [[[f64; 3]; 3]; 2], coef: [[f64; 4]; 3]) -> [[f64; 12]; 2] {
    let inv = [[a[1][1] / det, -a[0][1] / det], [-a[1][0] / det, a[0][0] / det]];
    let mut jac = [[0.0; 12]; 2];
    for row in 0..2 {
        for k in 0..3 {
            for i in 0..3 {
                let dc = -(inv[row][0] * df[0][k][i] + inv[row][1] * df[1][k][i]);
                for v in 0..4 {
                    jac[row][v * 3 + i] += coef[k][v] * dc;
                }
            }
        }
    }
    jac
}

/// `(alpha, beta)` with `ea0 + alpha (ea1 - ea0)` and `eb0 + beta (eb1 - eb0)` the closest
/// points of the two lines of `x = [ea0, ea1, eb0, eb1]`, and their Jacobian (2 x 12).
pub fn edge_edge_closest_point(x: &[f64]) -> ([f64; 2], [[f64; 12]; 2]) {
    let v = [0, 1, 2, 3].map(|a| vertex(x, 3, a));
    let (u, w, r) = (sub(v[1], v[0]), sub(v[3], v[2]), sub(v[2], v[0]));
    // Optimality of |alpha u - beta w - r|^2: [u.q, w.q] = 0 with q = alpha u - beta w - r.
    let a = [[dot(u, u), -dot(u, w)], [dot(w, u), -dot(w, w)]];
    // Cramer's rule with the determinant -|u x w|^2 and, by Lagrange's identity, the
    // numerators as triple products: no cancellation for nearly parallel edges.
    let n = cross_accurate(u, w);
    let m = dot(n, n);
    if m.is_nan() || m == 0.0 {
        return (edge_edge_feature_coordinates(x, &v), [[0.0; 12]; 2]);
    }
    let alpha = dot(n, cross_accurate(r, w)) / m;
    let beta = dot(n, cross_accurate(r, u)) / m;
    let q = sub(axpy(scale(alpha, u), -beta, w), r);
    // dF/d(u, w, r) per row.
    let df = [
        [axpy(q, alpha, u), scale(-beta, u), scale(-1.0, u)],
        [scale(alpha, w), axpy(q, -beta, w), scale(-1.0, w)],
    ];
    let coef = [[-1.0, 1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 1.0], [-1.0, 0.0, 1.0, 0.0]];
    ([alpha, beta], implicit_jacobian(a, -m, df, coef))
}

/// `(alpha, beta)` of the closest features of edges without a single closest pair of line
/// points (parallel or of zero length), from [`edge_edge_type`].
fn edge_edge_feature_coordinates(x: &[f64], v: &[[f64; 3]; 4]) -> [f64; 2] {
    use EdgeEdgeType::*;
    let on = |p, s, t| segment_parameter(v, p, s, t);
    match edge_edge_type(x) {
        A0B0 | AB => [0.0, 0.0],
        A0B1 => [0.0, 1.0],
        A1B0 => [1.0, 0.0],
        A1B1 => [1.0, 1.0],
        AB0 => [on(2, 0, 1), 0.0],
        AB1 => [on(3, 0, 1), 1.0],
        A0B => [0.0, on(0, 2, 3)],
        A1B => [1.0, on(1, 2, 3)],
    }
}

/// `(beta, gamma)` with `t0 + beta (t1 - t0) + gamma (t2 - t0)` the point of the triangle's
/// plane closest to `p`, for `x = [p, t0, t1, t2]`, and their Jacobian (2 x 12).
pub fn point_triangle_closest_point(x: &[f64]) -> ([f64; 2], [[f64; 12]; 2]) {
    let v = [0, 1, 2, 3].map(|a| vertex(x, 3, a));
    let (e1, e2, r) = (sub(v[2], v[1]), sub(v[3], v[1]), sub(v[0], v[1]));
    // Optimality of |beta e1 + gamma e2 - r|^2: [e1.q, e2.q] = 0.
    let a = [[dot(e1, e1), dot(e1, e2)], [dot(e2, e1), dot(e2, e2)]];
    // Cramer's rule with the determinant |e1 x e2|^2 and triple-product numerators.
    let n = cross_accurate(e1, e2);
    let m = dot(n, n);
    if m.is_nan() || m == 0.0 {
        return (triangle_feature_coordinates(x, &v), [[0.0; 12]; 2]);
    }
    let beta = dot(n, cross_accurate(r, e2)) / m;
    let gamma = dot(n, cross_accurate(e1, r)) / m;
    let q = sub(axpy(scale(beta, e1), gamma, e2), r);
    let df = [
        [axpy(q, beta, e1), scale(gamma, e1), scale(-1.0, e1)],
        [scale(beta, e2), axpy(q, gamma, e2), scale(-1.0, e2)],
    ];
    let coef = [[0.0, -1.0, 1.0, 0.0], [0.0, -1.0, 0.0, 1.0], [1.0, -1.0, 0.0, 0.0]];
    ([beta, gamma], implicit_jacobian(a, m, df, coef))
}

/// `(beta, gamma)` of the closest feature of a zero-area triangle, from
/// [`point_triangle_type`] (which takes such a triangle as its three edges).
fn triangle_feature_coordinates(x: &[f64], v: &[[f64; 3]; 4]) -> [f64; 2] {
    use PointTriangleType::*;
    let on = |s, t| segment_parameter(v, 0, s, t);
    match point_triangle_type(x) {
        T0 | Interior => [0.0, 0.0],
        T1 => [1.0, 0.0],
        T2 => [0.0, 1.0],
        E0 => [on(1, 2), 0.0],
        E1 => {
            let a = on(2, 3);
            [1.0 - a, a]
        }
        E2 => [0.0, 1.0 - on(3, 1)],
    }
}

/// The relative velocity of a contact pair as a weighted sum of its vertices' velocities,
/// `u = sum_a weights[a] v_a` (the matrix `Gamma = [w_0 I, w_1 I, ...]`): first primitive
/// minus second, each at its closest point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RelativeVelocity {
    /// Vertices in the stencil.
    pub verts: usize,
    /// Weight of each vertex.
    pub weights: [f64; 4],
}

impl RelativeVelocity {
    /// `v_p0 - v_p1`.
    pub fn point_point() -> Self {
        RelativeVelocity {
            verts: 2,
            weights: [1.0, -1.0, 0.0, 0.0],
        }
    }
    /// `v_p - ((1 - alpha) v_e0 + alpha v_e1)`.
    pub fn point_edge(alpha: f64) -> Self {
        RelativeVelocity {
            verts: 3,
            weights: [1.0, alpha - 1.0, -alpha, 0.0],
        }
    }
    /// `(1 - alpha) v_ea0 + alpha v_ea1 - ((1 - beta) v_eb0 + beta v_eb1)`.
    pub fn edge_edge([alpha, beta]: [f64; 2]) -> Self {
        RelativeVelocity {
            verts: 4,
            weights: [1.0 - alpha, alpha, beta - 1.0, -beta],
        }
    }
    /// `v_p - ((1 - beta - gamma) v_t0 + beta v_t1 + gamma v_t2)`.
    pub fn point_triangle([beta, gamma]: [f64; 2]) -> Self {
        RelativeVelocity {
            verts: 4,
            weights: [1.0, beta + gamma - 1.0, -beta, -gamma],
        }
    }
}

/// Parameter of vertex `p` projected on the segment `[s, t]` of `v`, clamped to it (zero
/// for a zero-length segment).
fn segment_parameter(v: &[[f64; 3]; 4], p: usize, s: usize, t: usize) -> f64 {
    let e = sub(v[t], v[s]);
    let c = dot(e, e);
    if c > 0.0 {
        (dot(sub(v[p], v[s]), e) / c).clamp(0.0, 1.0)
    } else {
        0.0
    }
}
