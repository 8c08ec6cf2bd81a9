//! Derivatives in *reduced* variables and their scatter onto a stencil's vertex dofs.
//!
//! Every contact distance is a function of at most three difference vectors of the stencil's
//! vertices (`r = p - e0`, `e = e1 - e0`, ...). Kernels differentiate with respect to those
//! vectors (always 3 numbers each; 2D problems embed with `z = 0`, which leaves the x/y
//! derivatives unchanged), and [`Reduced::scatter`] applies the constant chain rule
//! `y_k = sum_a C[k][a] x_a` to reach the vertex-major local layout of `energy`.

use crate::energy::{Local, Want};

/// Largest number of reduced vectors of any kernel.
pub const MAX_REDUCED: usize = 3;
const N: usize = 3 * MAX_REDUCED;

/// Value, gradient and Hessian of a scalar in reduced variables; entry `k * 3 + i` is
/// coordinate `i` of reduced vector `k`; the Hessian is row-major `9 x 9`.
#[derive(Clone, Debug)]
pub struct Reduced {
    /// The value.
    pub value: f64,
    /// Gradient.
    pub grad: [f64; N],
    /// Hessian (row-major).
    pub hess: [f64; N * N],
}

impl Default for Reduced {
    fn default() -> Self {
        Reduced {
            value: 0.0,
            grad: [0.0; N],
            hess: [0.0; N * N],
        }
    }
}

impl Reduced {
    /// Adds `s * u v^T` into the Hessian block `(k, l)`.
    pub fn add_outer(&mut self, k: usize, l: usize, s: f64, u: [f64; 3], v: [f64; 3]) {
        for i in 0..3 {
            for j in 0..3 {
                self.hess[(k * 3 + i) * N + l * 3 + j] += s * u[i] * v[j];
            }
        }
    }

    /// Adds `s * I` into the Hessian block `(k, l)`.
    pub fn add_identity(&mut self, k: usize, l: usize, s: f64) {
        for i in 0..3 {
            self.hess[(k * 3 + i) * N + l * 3 + i] += s;
        }
    }

    /// Adds the 3x3 matrix `m` (row-major) into the Hessian block `(k, l)`.
    pub fn add_block(&mut self, k: usize, l: usize, m: [[f64; 3]; 3]) {
        for i in 0..3 {
            for j in 0..3 {
                self.hess[(k * 3 + i) * N + l * 3 + j] += m[i][j];
            }
        }
    }

    /// Sets the gradient of reduced vector `k`.
    pub fn set_grad(&mut self, k: usize, g: [f64; 3]) {
        self.grad[k * 3..k * 3 + 3].copy_from_slice(&g);
    }

    /// Gradient of reduced vector `k`.
    pub fn grad_of(&self, k: usize) -> [f64; 3] {
        [self.grad[k * 3], self.grad[k * 3 + 1], self.grad[k * 3 + 2]]
    }

    /// Writes the gradient / Hessian over the stencil's `verts` vertices of dimension `dim`
    /// into `out` (overwriting) as `want` asks, with the reduced vectors
    /// `y_k = sum_a coef[k][a] x_a`; returns the value.
    pub fn scatter(&self, coef: &[[f64; 4]], verts: usize, dim: usize, want: Want, out: &mut Local) -> f64 {
        let n = verts * dim;
        if want.gradient() {
            for a in 0..verts {
                for i in 0..dim {
                    out.grad[a * dim + i] = coef.iter().enumerate().map(|(k, c)| c[a] * self.grad[k * 3 + i]).sum();
                }
            }
        }
        if want.hessian().is_some() {
            for a in 0..verts {
                for i in 0..dim {
                    for b in 0..verts {
                        for j in 0..dim {
                            let mut s = 0.0;
                            for (k, ck) in coef.iter().enumerate() {
                                if ck[a] == 0.0 {
                                    continue;
                                }
                                for (l, cl) in coef.iter().enumerate() {
                                    s += ck[a] * cl[b] * self.hess[(k * 3 + i) * N + l * 3 + j];
                                }
                            }
                            out.hess[(a * dim + i) * n + b * dim + j] = s;
                        }
                    }
                }
            }
        }
        self.value
    }
}

/// Coefficients of `x_a - x_b` over a stencil's (at most four) vertices, for
/// [`Reduced::scatter`].
pub fn difference(a: usize, b: usize) -> [f64; 4] {
    let mut c = [0.0; 4];
    c[a] = 1.0;
    c[b] = -1.0;
    c
}

/// Vertex `a` of the local vector `x` (dimension `dim`), padded with `z = 0` in 2D.
pub fn vertex(x: &[f64], dim: usize, a: usize) -> [f64; 3] {
    let mut v = [0.0; 3];
    v[..dim].copy_from_slice(&x[a * dim..(a + 1) * dim]);
    v
}

/// `a - b`.
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `a + s b`.
pub fn axpy(a: [f64; 3], s: f64, b: [f64; 3]) -> [f64; 3] {
    [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]]
}

/// `s a`.
pub fn scale(s: f64, a: [f64; 3]) -> [f64; 3] {
    [s * a[0], s * a[1], s * a[2]]
}

/// Dot product.
pub fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Cross product.
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Cross product with each component's difference of products computed by Kahan's
/// fused-multiply-add algorithm: within 1.5 ulps of the exact component, where [`cross`]
/// loses all relative accuracy for nearly parallel vectors (the two products cancel). Used
/// wherever a cross product's direction decides a distance: the normals of planes and of
/// line pairs, and the sine of the angle between edges.
pub fn cross_accurate(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        difference_of_products(a[1], b[2], a[2], b[1]),
        difference_of_products(a[2], b[0], a[0], b[2]),
        difference_of_products(a[0], b[1], a[1], b[0]),
    ]
}

/// `a b - c d` with the rounding error of `c d` recovered by a fused multiply-add (Kahan;
/// Jeannerod, Louvet and Muller 2013: at most 1.5 ulps). No crate offers it; it is four
/// operations.
pub fn difference_of_products(a: f64, b: f64, c: f64, d: f64) -> f64 {
    let cd = c * d;
    let err = (-c).mul_add(d, cd);
    a.mul_add(b, -cd) + err
}

/// The matrix `[a]_x` with `[a]_x b = a x b`.
pub fn cross_matrix(a: [f64; 3]) -> [[f64; 3]; 3] {
    [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]]
}

/// `s * m`.
pub fn scale_matrix(s: f64, m: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    m.map(|row| row.map(|v| s * v))
}

/// `a b` for 3x3 matrices.
pub fn mat_mul(a: [[f64; 3]; 3], b: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut c = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            c[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    c
}

/// Transpose of a 3x3 matrix.
pub fn transpose(a: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut t = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            t[i][j] = a[j][i];
        }
    }
    t
}
