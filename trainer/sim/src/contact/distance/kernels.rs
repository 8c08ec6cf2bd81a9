//! The three squared-distance kernels every contact distance reduces to, and the squared
//! norm of a cross product (the edge-edge mollifier's argument), each with its exact
//! gradient and Hessian in reduced variables (see [`super::reduced`]).
//!
//! Derivations (`I` the identity, `[a]x` the cross-product matrix):
//! - point-point, `d = r.r`: `grad = 2r`, `H = 2I`.
//! - point-line, `d = m / c` with `n = r x e`, `m = n.n`, `c = e.e` (`r = p - e0`,
//!   `e = e1 - e0`): in `(n, c)`: `d_n = 2n / c`, `d_c = -m / c^2`, `H_nn = 2I / c`,
//!   `H_nc = -2n / c^2`, `H_cc = 2m / c^3`; then `dn/dr = -[e]x`, `dn/de = [r]x` (with the
//!   bilinear term below) and `dc/de = 2e`, `d2c/de2 = 2I`.
//! - point-plane / line-line, `d = q^2 / m` with `n = u x v`, `q = r.n`, `m = n.n`:
//!   in `(r, n)`: `d_r = 2q n / m`, `d_n = 2q r / m - 2q^2 n / m^2`,
//!   `H_rr = 2 n n^T / m`, `H_rn = 2 (n r^T + q I) / m - 4q n n^T / m^2`,
//!   `H_nn = 2 r r^T / m - 4q (r n^T + n r^T) / m^2 - 2q^2 I / m^2 + 8q^2 n n^T / m^3`;
//!   then `dn/du = -[v]x`, `dn/dv = [u]x`, and the bilinear `g.(u x v)` adds `-[g]x` to the
//!   `(u, v)` block (and `[g]x` to `(v, u)`) for `g = d_n`.
//! - cross squared norm, `x = n.n`: `x_n = 2n`, `H_nn = 2I`, chained as above.

use super::reduced::{cross, cross_accurate, cross_matrix, dot, mat_mul, scale, scale_matrix, transpose, Reduced};

/// `d = |r|^2` in the reduced vector `r` (index 0).
pub fn point_point(r: [f64; 3], hessian: bool) -> Reduced {
    let mut out = Reduced {
        value: dot(r, r),
        ..Reduced::default()
    };
    out.set_grad(0, scale(2.0, r));
    if hessian {
        out.add_identity(0, 0, 2.0);
    }
    out
}

/// Squared distance from `p` to the line through `e0` along `e`, with `r = p - e0` (index 0)
/// and `e = e1 - e0` (index 1), as `|r x e|^2 / e.e` (no cancellation near the line; 2D
/// embeds with `z = 0`). `r` may start at either endpoint (the value is the same): callers
/// take the endpoint nearer `p`, where `r x e` keeps its relative accuracy.
pub fn point_line(r: [f64; 3], e: [f64; 3], hessian: bool) -> Reduced {
    let n = cross_accurate(r, e);
    let m = dot(n, n);
    let c = dot(e, e);
    let mut out = Reduced {
        value: m / c,
        ..Reduced::default()
    };
    let h_nn = hessian.then_some([[2.0 / c, 0.0, 0.0], [0.0, 2.0 / c, 0.0], [0.0, 0.0, 2.0 / c]]);
    chain_cross(&mut out, 0, 1, r, e, scale(2.0 / c, n), h_nn);
    // The dependence through c = e.e.
    let de = out.grad_of(1);
    out.set_grad(1, [0, 1, 2].map(|i| de[i] - 2.0 * m * e[i] / (c * c)));
    if hessian {
        out.add_outer(1, 1, 8.0 * m / (c * c * c), e, e);
        out.add_identity(1, 1, -2.0 * m / (c * c));
        // Mixed n-c terms: d2f/dn dc = -2n / c^2, dn/dr = -[e]x, dn/de = [r]x, dc/de = 2e.
        let a_r = scale(-2.0 / (c * c), cross(e, n));
        let a_e = scale(2.0 / (c * c), cross(r, n));
        let two_e = scale(2.0, e);
        out.add_outer(0, 1, 1.0, a_r, two_e);
        out.add_outer(1, 0, 1.0, two_e, a_r);
        out.add_outer(1, 1, 1.0, a_e, two_e);
        out.add_outer(1, 1, 1.0, two_e, a_e);
    }
    out
}

/// Chains derivatives known in `n = u x v` (`g_n`, `h_nn`) onto the reduced vectors `u`
/// (index `ku`) and `v` (index `kv`): gradient and the `uu`, `uv`, `vu`, `vv` blocks.
fn chain_cross(
    out: &mut Reduced,
    ku: usize,
    kv: usize,
    u: [f64; 3],
    v: [f64; 3],
    g_n: [f64; 3],
    h_nn: Option<[[f64; 3]; 3]>,
) {
    out.set_grad(ku, cross(v, g_n));
    out.set_grad(kv, cross(g_n, u));
    if let Some(h) = h_nn {
        let ju = scale_matrix(-1.0, cross_matrix(v));
        let jv = cross_matrix(u);
        out.add_block(ku, ku, mat_mul(transpose(ju), mat_mul(h, ju)));
        out.add_block(ku, kv, mat_mul(transpose(ju), mat_mul(h, jv)));
        out.add_block(kv, ku, mat_mul(transpose(jv), mat_mul(h, ju)));
        out.add_block(kv, kv, mat_mul(transpose(jv), mat_mul(h, jv)));
        let gx = cross_matrix(g_n);
        out.add_block(ku, kv, scale_matrix(-1.0, gx));
        out.add_block(kv, ku, gx);
    }
}

/// `d = (r . n)^2 / |n|^2` with `n = u x v`: the squared distance from a point to a plane
/// (`r = p - t0`, `u = t1 - t0`, `v = t2 - t0`) or between two lines (`r = eb0 - ea0`,
/// `u = ea1 - ea0`, `v = eb1 - eb0`). Indices: `r` 0, `u` 1, `v` 2.
pub fn plane(r: [f64; 3], u: [f64; 3], v: [f64; 3], hessian: bool) -> Reduced {
    let n = cross_accurate(u, v);
    let q = dot(r, n);
    let m = dot(n, n);
    let mut out = Reduced {
        value: q * q / m,
        ..Reduced::default()
    };
    out.set_grad(0, scale(2.0 * q / m, n));
    let g_n = [0, 1, 2].map(|i| 2.0 * q * r[i] / m - 2.0 * q * q * n[i] / (m * m));
    let h_nn = hessian.then(|| {
        let mut h = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                h[i][j] = 2.0 * r[i] * r[j] / m - 4.0 * q * (r[i] * n[j] + n[i] * r[j]) / (m * m)
                    + 8.0 * q * q * n[i] * n[j] / (m * m * m);
            }
            h[i][i] -= 2.0 * q * q / (m * m);
        }
        h
    });
    chain_cross(&mut out, 1, 2, u, v, g_n, h_nn);
    if hessian {
        out.add_outer(0, 0, 2.0 / m, n, n);
        // H_rn, then chained: H_ru = H_rn (-[v]x), H_rv = H_rn [u]x.
        let mut h_rn = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                h_rn[i][j] = 2.0 * n[i] * r[j] / m - 4.0 * q * n[i] * n[j] / (m * m);
            }
            h_rn[i][i] += 2.0 * q / m;
        }
        let h_ru = mat_mul(h_rn, scale_matrix(-1.0, cross_matrix(v)));
        let h_rv = mat_mul(h_rn, cross_matrix(u));
        out.add_block(0, 1, h_ru);
        out.add_block(1, 0, transpose(h_ru));
        out.add_block(0, 2, h_rv);
        out.add_block(2, 0, transpose(h_rv));
    }
    out
}

/// `x = |u x v|^2`, with `u` at index 0 and `v` at index 1.
pub fn cross_squared_norm(u: [f64; 3], v: [f64; 3], hessian: bool) -> Reduced {
    let n = cross(u, v);
    let mut out = Reduced {
        value: dot(n, n),
        ..Reduced::default()
    };
    let h = hessian.then_some([[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.0]]);
    chain_cross(&mut out, 0, 1, u, v, scale(2.0, n), h);
    out
}
