//! Orthonormal bases of the plane (3D) or line (2D) tangent to each contact pair, with the
//! conventions of IPC's toolkit (same columns, same signs) so lagged quantities compare.

use crate::contact::distance::reduced::{cross, dot, scale, sub, vertex};

/// `dim - 1` orthonormal columns, each 3 numbers (z zero in 2D).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TangentBasis {
    /// Coordinates per vertex (2 or 3).
    pub dim: usize,
    /// The columns; only the first `dim - 1` are used.
    pub columns: [[f64; 3]; 2],
}

/// `v / |v|`, or `v` itself when it is zero (as Eigen's `normalized`, so the toolkit's
/// conventions hold): a pair at distance zero, or parallel edges, has no tangent direction,
/// and a zero column makes its tangential velocity, and so its friction, zero.
fn normalized(v: [f64; 3]) -> [f64; 3] {
    let norm2 = dot(v, v);
    if norm2 == 0.0 {
        return v;
    }
    scale(1.0 / norm2.sqrt(), v)
}

impl TangentBasis {
    fn plane(a: [f64; 3], b: [f64; 3]) -> Self {
        TangentBasis {
            dim: 3,
            columns: [normalized(a), normalized(b)],
        }
    }

    fn line(a: [f64; 3]) -> Self {
        TangentBasis {
            dim: 2,
            columns: [normalized(a), [0.0; 3]],
        }
    }

    /// Number of columns (`dim - 1`).
    pub fn len(&self) -> usize {
        self.dim - 1
    }

    /// Whether the basis has no columns (never: `dim >= 2`).
    pub fn is_empty(&self) -> bool {
        self.dim < 2
    }
}

/// Tangent basis of `x = [p0, p1]`, normal `n = p1 - p0`. 3D: `n` crossed with the x or y axis,
/// whichever gives the longer vector, then `n` crossed with that. 2D: `n` turned by +90 degrees.
pub fn point_point_tangent_basis(x: &[f64], dim: usize) -> TangentBasis {
    let n = sub(vertex(x, dim, 1), vertex(x, dim, 0));
    if dim == 2 {
        return TangentBasis::line([-n[1], n[0], 0.0]);
    }
    let cx = cross([1.0, 0.0, 0.0], n);
    let cy = cross([0.0, 1.0, 0.0], n);
    let c = if dot(cx, cx) > dot(cy, cy) { cx } else { cy };
    TangentBasis::plane(c, cross(n, c))
}

/// Tangent basis of `x = [p, e0, e1]`: along the edge, then (3D) `e x (p - e0)`.
pub fn point_edge_tangent_basis(x: &[f64], dim: usize) -> TangentBasis {
    let (p, e0, e1) = (vertex(x, dim, 0), vertex(x, dim, 1), vertex(x, dim, 2));
    let e = sub(e1, e0);
    if dim == 2 {
        return TangentBasis::line(e);
    }
    TangentBasis::plane(e, cross(e, sub(p, e0)))
}

/// Tangent basis of `x = [ea0, ea1, eb0, eb1]`: along edge a, then `(a x b) x a`.
pub fn edge_edge_tangent_basis(x: &[f64]) -> TangentBasis {
    let a = sub(vertex(x, 3, 1), vertex(x, 3, 0));
    let b = sub(vertex(x, 3, 3), vertex(x, 3, 2));
    TangentBasis::plane(a, cross(cross(a, b), a))
}

/// Tangent basis of `x = [p, t0, t1, t2]`: along `t1 - t0`, then `n x (t1 - t0)` with
/// `n = (t1 - t0) x (t2 - t0)`.
pub fn point_triangle_tangent_basis(x: &[f64]) -> TangentBasis {
    let t0 = vertex(x, 3, 1);
    let e0 = sub(vertex(x, 3, 2), t0);
    let e1 = sub(vertex(x, 3, 3), t0);
    TangentBasis::plane(e0, cross(cross(e0, e1), e0))
}
