//! Per-node scaling factors of the error and progress measures (Trusty et al., Eqs. 5, 8):
//! `H̄_i`, `A_i` and `V_i`, computed once per body from its rest shape and elastic terms.

use super::OracleError;
use crate::energy::{gather, Local, StencilEnergy, Want, MAX_DOF};

/// The rest-shape quantities that make the oracle's measures dimensionless, per vertex.
///
/// - `hessian_norm[i]` (`H̄_i`): the average, over the elastic elements that hold vertex
///   `i`, of the Frobenius norm of the element's energy *density* Hessian at rest,
///   `|d²Ψ/dF²(I)|_F` (units of stress, M L⁻¹ T⁻²). The energy code exposes an element's
///   Hessian with respect to its vertex positions, `K_e = V_e Bᵀ (d²Ψ/dF²) B` with
///   `B = dF/dx`; the density Hessian is recovered exactly as `Rᵀ K_e R / V_e`, where `R`
///   is the right inverse of `B` that moves vertices `1..=D` by the columns of `δF D_m`
///   (`D_m` the rest edge matrix) and keeps vertex 0 still, so `B R = I`. Dividing `K_e`
///   by the volume alone would leave a factor `|B|² ~ L⁻²` that depends on the element's
///   size, which the paper's scaling removes through `A_i` instead.
/// - `area[i]` (`A_i`): the area of the surface of the one-ring of vertex `i`, taken as
///   the summed areas of the faces opposite to `i` in its tetrahedra (in 2D: the summed
///   lengths of the edges opposite to `i` in its triangles), as the analysis behind Eq. 6
///   uses (`|B_ei|² ∝ (A_ei / V_e)²`).
/// - `volume[i]` (`V_i`): every element's rest volume (area in 2D) split equally among
///   its `D + 1` vertices.
///
/// Element here means a stencil of one of the elastic terms: a `D`-simplex (`D + 1`
/// vertices) of the body's rest shape.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeScales {
    /// Coordinates per vertex (2 or 3).
    pub dim: usize,
    /// `H̄_i`, per vertex.
    pub hessian_norm: Vec<f64>,
    /// `A_i`, per vertex.
    pub area: Vec<f64>,
    /// `V_i`, per vertex.
    pub volume: Vec<f64>,
}

impl NodeScales {
    /// The scales of a body with rest positions `rest` (`dim` per vertex) and elastic terms
    /// `elastic`, whose stencils must be `dim`-simplices of the rest shape and must cover
    /// every vertex.
    pub fn new(dim: usize, rest: &[f64], elastic: &[&dyn StencilEnergy]) -> Result<Self, OracleError> {
        if dim != 2 && dim != 3 {
            return Err(OracleError::Input(format!("dim is {dim}, must be 2 or 3")));
        }
        if !rest.len().is_multiple_of(dim) {
            return Err(OracleError::Input(format!(
                "rest has {} coordinates, not a multiple of dim {dim}",
                rest.len()
            )));
        }
        let n = rest.len() / dim;
        let mut hessian_sum = vec![0.0; n];
        let mut count = vec![0usize; n];
        let mut area = vec![0.0; n];
        let mut volume = vec![0.0; n];
        let mut out = Local::default();
        let mut local = [0.0; MAX_DOF];
        for term in elastic {
            if term.dim() != dim {
                return Err(OracleError::Input(format!(
                    "elastic term `{}` has dim {}, the body {dim}",
                    term.name(),
                    term.dim()
                )));
            }
            for s in 0..term.len() {
                let verts = term.stencil(s);
                if verts.len() != dim + 1 {
                    return Err(OracleError::Input(format!(
                        "stencil {s} of `{}` has {} vertices; the scales need {}-simplices ({} vertices)",
                        term.name(),
                        verts.len(),
                        dim,
                        dim + 1
                    )));
                }
                if let Some(&v) = verts.iter().find(|&&v| v >= n) {
                    return Err(OracleError::Input(format!(
                        "stencil {s} of `{}` names vertex {v}, the body has {n}",
                        term.name()
                    )));
                }
                let len = gather(*term, s, rest, &mut local);
                let p = &local[..len];
                let edges = edge_matrix(dim, p);
                let measure = determinant(dim, &edges).abs() / if dim == 3 { 6.0 } else { 2.0 };
                if measure.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                    return Err(OracleError::Input(format!(
                        "stencil {s} of `{}` has rest measure {measure}",
                        term.name()
                    )));
                }
                term.eval(s, p, Want::Hessian { project: false }, &mut out);
                let h = density_hessian_norm(dim, &edges, &out.hess[..len * len], measure);
                for (a, &v) in verts.iter().enumerate() {
                    hessian_sum[v] += h;
                    count[v] += 1;
                    area[v] += opposite_facet_measure(dim, p, a);
                    volume[v] += measure / (dim + 1) as f64;
                }
            }
        }
        if let Some(v) = count.iter().position(|&c| c == 0) {
            return Err(OracleError::Input(format!(
                "vertex {v} belongs to no elastic element, so it has no scale"
            )));
        }
        let hessian_norm = hessian_sum.iter().zip(&count).map(|(h, &c)| h / c as f64).collect();
        Ok(NodeScales {
            dim,
            hessian_norm,
            area,
            volume,
        })
    }

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.area.len()
    }

    /// The error scale `h² A_i H̄_i` of vertex `i` (Eq. 5) for time step `h`.
    pub fn error_scale(&self, i: usize, h: f64) -> f64 {
        h * h * self.area[i] * self.hessian_norm[i]
    }

    /// The progress scale `h² V_i H̄_i` of vertex `i` (Eq. 8) for time step `h`.
    pub fn progress_scale(&self, i: usize, h: f64) -> f64 {
        h * h * self.volume[i] * self.hessian_norm[i]
    }
}

/// The rest edge matrix `D_m` (row-major, `dim x dim`, column `a` = `p_{a+1} - p_0`) of the
/// simplex with local positions `p`.
fn edge_matrix(dim: usize, p: &[f64]) -> [f64; 9] {
    let mut m = [0.0; 9];
    for a in 0..dim {
        for j in 0..dim {
            m[j * dim + a] = p[(a + 1) * dim + j] - p[j];
        }
    }
    m
}

fn determinant(dim: usize, m: &[f64; 9]) -> f64 {
    if dim == 2 {
        m[0] * m[3] - m[1] * m[2]
    } else {
        m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6]) + m[2] * (m[3] * m[7] - m[4] * m[6])
    }
}

/// `|Rᵀ K R|_F / measure` with `R` the right inverse of `dF/dx` described on
/// [`NodeScales`]: column `(i, j)` of `R` (the displacement for `δF = e_i e_jᵀ`) moves
/// coordinate `i` of vertex `a + 1` by `D_m[j][a]`.
fn density_hessian_norm(dim: usize, edges: &[f64; 9], k: &[f64], measure: f64) -> f64 {
    let n = (dim + 1) * dim;
    let cols = dim * dim;
    // r[c * n + p]: entry p of column c = (i, j) -> c = i * dim + j.
    let mut r = [0.0; 9 * MAX_DOF];
    for i in 0..dim {
        for j in 0..dim {
            for a in 0..dim {
                r[(i * dim + j) * n + (a + 1) * dim + i] = edges[j * dim + a];
            }
        }
    }
    let mut kr = [0.0; MAX_DOF * 9];
    for p in 0..n {
        for c in 0..cols {
            kr[p * cols + c] = (0..n).map(|q| k[p * n + q] * r[c * n + q]).sum();
        }
    }
    let mut sum = 0.0;
    for c in 0..cols {
        for d in 0..cols {
            let v: f64 = (0..n).map(|p| r[c * n + p] * kr[p * cols + d]).sum::<f64>() / measure;
            sum += v * v;
        }
    }
    sum.sqrt()
}

/// The measure of the facet opposite to local vertex `a` of the simplex `p`: a triangle's
/// area in 3D, an edge's length in 2D.
fn opposite_facet_measure(dim: usize, p: &[f64], a: usize) -> f64 {
    let others: Vec<&[f64]> = (0..=dim)
        .filter(|&b| b != a)
        .map(|b| &p[b * dim..(b + 1) * dim])
        .collect();
    let e = |u: &[f64], v: &[f64]| -> [f64; 3] {
        let mut d = [0.0; 3];
        for k in 0..dim {
            d[k] = v[k] - u[k];
        }
        d
    };
    if dim == 2 {
        let d = e(others[0], others[1]);
        return (d[0] * d[0] + d[1] * d[1]).sqrt();
    }
    let (u, v) = (e(others[0], others[1]), e(others[0], others[2]));
    let c = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    0.5 * (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt()
}
