//! One subdomain's elastic stencils summed by vertex and vertex pair, and projected onto
//! the active columns: `Wᵀ ∇Ψ_l` and `Wᵀ ∇²Ψ_l W` (Trusty et al., Sec. 3.9).
//!
//! Projecting stencil by stencil costs `n² a + n a²` multiply-adds per stencil (`n` its
//! coordinates, `a` the columns), and neighbouring stencils share most vertex pairs: a tet
//! mesh has about 5 tets per vertex but under 8 edges. So the stencils' `dim x dim` blocks are
//! first summed per ordered vertex pair (a sparse matrix over the subdomain's vertices), and
//! the projection runs once per vertex: `T_u = Σ_v H_uv W_v`, then `Wᵀ H W += W_uᵀ T_u`.

use crate::energy::{gather, Local, Want, MAX_DOF};

use super::oracle::WeightedTerm;

/// The vertex-pair pattern of one subdomain's stencils.
#[derive(Clone, Debug)]
pub(super) struct VertexBlocks {
    dim: usize,
    /// Global vertices the stencils touch, ascending (local vertex `u` is `vertices[u]`).
    vertices: Vec<usize>,
    /// Blocks of local vertex `u`: `row_start[u]..row_start[u + 1]` in `neighbours`.
    row_start: Vec<usize>,
    /// The local vertex `v` of each block `(u, v)`.
    neighbours: Vec<usize>,
    /// `[term]`: the local vertex of each vertex of each of the subdomain's stencils, in
    /// stencil order.
    locals: Vec<Vec<usize>>,
    /// `[term]`: the block of each ordered vertex pair `(a, b)` of each stencil, `a`-major,
    /// in stencil order.
    slots: Vec<Vec<usize>>,
}

impl VertexBlocks {
    /// The pattern of the stencils `stencils[term]` (indices into `vertices_of[term]`, each
    /// stencil's global vertices).
    pub(super) fn new(dim: usize, stencils: &[Vec<usize>], vertices_of: &[Vec<Vec<usize>>]) -> VertexBlocks {
        let mut vertices: Vec<usize> = stencils
            .iter()
            .zip(vertices_of)
            .flat_map(|(list, verts)| list.iter().flat_map(move |&s| verts[s].iter().copied()))
            .collect();
        vertices.sort_unstable();
        vertices.dedup();
        let local = |v: usize| {
            vertices
                .binary_search(&v)
                .unwrap_or_else(|_| unreachable!("collected above"))
        };
        let locals: Vec<Vec<usize>> = stencils
            .iter()
            .zip(vertices_of)
            .map(|(list, verts)| list.iter().flat_map(|&s| verts[s].iter().map(|&v| local(v))).collect())
            .collect();
        let mut pairs: Vec<(usize, usize)> = Vec::new();
        for ((list, verts), term_locals) in stencils.iter().zip(vertices_of).zip(&locals) {
            let mut at = 0;
            for &s in list {
                let ls = &term_locals[at..at + verts[s].len()];
                for &u in ls {
                    pairs.extend(ls.iter().map(|&v| (u, v)));
                }
                at += ls.len();
            }
        }
        pairs.sort_unstable();
        pairs.dedup();
        let mut row_start = vec![0; vertices.len() + 1];
        for &(u, _) in &pairs {
            row_start[u + 1] += 1;
        }
        for u in 0..vertices.len() {
            row_start[u + 1] += row_start[u];
        }
        let neighbours: Vec<usize> = pairs.iter().map(|&(_, v)| v).collect();
        let slot = |u: usize, v: usize| {
            let row = &neighbours[row_start[u]..row_start[u + 1]];
            row_start[u] + row.binary_search(&v).unwrap_or_else(|_| unreachable!("paired above"))
        };
        let slots = locals
            .iter()
            .zip(stencils.iter().zip(vertices_of))
            .map(|(term_locals, (list, verts))| {
                let mut out = Vec::new();
                let mut at = 0;
                for &s in list {
                    let k = verts[s].len();
                    let ls = &term_locals[at..at + k];
                    for &u in ls {
                        for &v in ls {
                            out.push(slot(u, v));
                        }
                    }
                    at += k;
                }
                out
            })
            .collect();
        VertexBlocks {
            dim,
            vertices,
            row_start,
            neighbours,
            locals,
            slots,
        }
    }

    /// `(Wᵀ ∇²Ψ_l W, Wᵀ ∇Ψ_l)` at `x` of the stencils `stencils[term]` of the weighted terms
    /// `elastic` (the pattern's, in its order), both row-major (`a x a`, `a`), the Hessian
    /// part empty unless `want` asks for it. `rows` holds the `a` active columns row-major
    /// over every dof.
    pub(super) fn project(
        &self,
        elastic: &[WeightedTerm<'_>],
        stencils: &[&[usize]],
        x: &[f64],
        rows: &[f64],
        a: usize,
        want: Want,
    ) -> (Vec<f64>, Vec<f64>) {
        let d = self.dim;
        let with_hessian = matches!(want, Want::Hessian { .. });
        let mut blocks = vec![0.0; if with_hessian { self.neighbours.len() * d * d } else { 0 }];
        let mut gradient = vec![0.0; self.vertices.len() * d];
        let (mut out, mut xl) = (Local::default(), [0.0; MAX_DOF]);
        for (term, t) in elastic.iter().enumerate() {
            let (mut at, mut slot_at) = (0, 0);
            for &s in stencils[term] {
                let n = gather(t.energy, s, x, &mut xl);
                t.energy.eval(s, &xl[..n], want, &mut out);
                let k = n / d;
                let ls = &self.locals[term][at..at + k];
                for (p, &u) in ls.iter().enumerate() {
                    for i in 0..d {
                        gradient[u * d + i] += t.weight * out.grad[p * d + i];
                    }
                }
                if with_hessian {
                    let slots = &self.slots[term][slot_at..slot_at + k * k];
                    for p in 0..k {
                        for q in 0..k {
                            let block = &mut blocks[slots[p * k + q] * d * d..][..d * d];
                            for i in 0..d {
                                for j in 0..d {
                                    block[i * d + j] += t.weight * out.hess[(p * d + i) * n + q * d + j];
                                }
                            }
                        }
                    }
                }
                at += k;
                slot_at += k * k;
            }
        }
        let w = |u: usize| {
            let k = self.vertices[u] * d;
            &rows[k * a..(k + d) * a]
        };
        let mut g = vec![0.0; a];
        for u in 0..self.vertices.len() {
            for (i, w_row) in w(u).chunks_exact(a).enumerate() {
                let gi = gradient[u * d + i];
                for (o, wv) in g.iter_mut().zip(w_row) {
                    *o += gi * wv;
                }
            }
        }
        if !with_hessian {
            return (Vec::new(), g);
        }
        let mut h = vec![0.0; a * a];
        let mut t = vec![0.0; d * a];
        for u in 0..self.vertices.len() {
            // T_u = Σ_v H_uv W_v (d x a), then Wᵀ H W += W_uᵀ T_u.
            t.fill(0.0);
            for b in self.row_start[u]..self.row_start[u + 1] {
                let block = &blocks[b * d * d..][..d * d];
                let wv = w(self.neighbours[b]);
                for (i, t_row) in t.chunks_exact_mut(a).enumerate() {
                    for (j, w_row) in wv.chunks_exact(a).enumerate() {
                        let hij = block[i * d + j];
                        for (o, x) in t_row.iter_mut().zip(w_row) {
                            *o += hij * x;
                        }
                    }
                }
            }
            for (w_row, t_row) in w(u).chunks_exact(a).zip(t.chunks_exact(a)) {
                for (p, &wp) in w_row.iter().enumerate() {
                    for (o, x) in h[p * a..(p + 1) * a].iter_mut().zip(t_row) {
                        *o += wp * x;
                    }
                }
            }
        }
        (h, g)
    }
}
