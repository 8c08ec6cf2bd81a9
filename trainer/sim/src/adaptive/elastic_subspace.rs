//! The elastic part of the subspace Hessian inside the Newton loop, by per-subdomain BFGS
//! (Trusty et al., Sec. 3.9).
//!
//! Every stencil of the body's elastic terms belongs to one subdomain of the fixed
//! decomposition (the one holding most of its vertices, as an element does in
//! [`super::partition`]; for a tet mesh the stencils are its elements). A subdomain none of whose stencils touches an enriched vertex is
//! *approximated*: its share `Wᵀ ∇²Ψ_l W` of the subspace Hessian (`W` the active candidate
//! columns over the free dofs) is a BFGS matrix ([`super::bfgs`]), evaluated exactly at the
//! first iterate of a time step and then updated at every iterate by the secant pair
//! `s = Δq` (the accepted modal step, in candidate-column coordinates) and
//! `y = Wᵀ (∇Ψ_l(x_k) - ∇Ψ_l(x_{k-1}))`. On such a subdomain every vertex moves through the
//! modes (none is enriched), so `s` is exactly its displacement's coordinates. The other
//! subdomains are *exact*: the simulator assembles their stencils' Hessians into the sparse
//! matrix with inertia and contact, which then serves the enriched coordinates and their
//! coupling exactly. So the simulator never assembles the elastic Hessian of the approximated
//! subdomains, the cost that dominates an iterate whose model is mostly modal.

use faer::Mat;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use super::bfgs::{SecantUpdate, SubdomainHessians};
use super::oracle::WeightedTerm;
use super::partition::majority_subdomains;
use super::vertex_blocks::VertexBlocks;
use crate::dofs::NOT_FREE;
use crate::energy::Want;

/// What the per-subdomain approximations did in one time step.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SubspaceHessianStats {
    /// Exact evaluations of every approximated subdomain (at the step's first iterate and
    /// when the active columns change).
    pub evaluations: usize,
    /// Secant updates applied, summed over subdomains.
    pub updates: usize,
    /// Secant updates skipped for too small a curvature, summed over subdomains.
    pub skipped: usize,
}

/// The approximations of the current columns and the last iterate's subspace gradients.
#[derive(Clone, Debug)]
struct SecantState {
    /// The candidate columns the matrices are over.
    columns: Vec<usize>,
    /// Those columns row-major over every dof, zero on the prescribed ones.
    rows: Vec<f64>,
    hessians: SubdomainHessians,
    /// `Wᵀ ∇Ψ_l` of every subdomain at the last iterate (zero for exact ones).
    gradients: Vec<DVector<f64>>,
    /// The step's modal displacement (candidate coordinates) at the last iterate.
    coefficients: Vec<f64>,
}

/// The elastic subspace Hessian of one body: which subdomains are exact, and the BFGS
/// approximations of the others.
#[derive(Clone, Debug)]
pub struct ElasticSubspace {
    /// `[term][subdomain]`: the term's stencils in the subdomain, ascending.
    subdomain_stencils: Vec<Vec<Vec<usize>>>,
    /// `[term][stencil]`: the stencil's vertices.
    stencil_vertices: Vec<Vec<Vec<usize>>>,
    /// Each subdomain's vertex-pair pattern.
    blocks: Vec<VertexBlocks>,
    exact: Vec<bool>,
    /// Subdomains made exact since the simulator last asked.
    newly_exact: Vec<usize>,
    state: Option<SecantState>,
    stats: SubspaceHessianStats,
}

impl ElasticSubspace {
    /// The elastic terms' stencils (`stencils[term][s]`: the vertices of stencil `s`) over
    /// the subdomains `vertex_subdomain` assigns (`num_subdomains` of them); every subdomain
    /// starts approximated.
    pub fn new(dim: usize, stencils: Vec<Vec<Vec<usize>>>, vertex_subdomain: &[usize], num_subdomains: usize) -> Self {
        let subdomain_stencils: Vec<Vec<Vec<usize>>> = stencils
            .iter()
            .map(|term| {
                let mut by_subdomain = vec![Vec::new(); num_subdomains];
                for (s, l) in majority_subdomains(term, vertex_subdomain, num_subdomains)
                    .into_iter()
                    .enumerate()
                {
                    by_subdomain[l].push(s);
                }
                by_subdomain
            })
            .collect();
        let blocks = (0..num_subdomains)
            .into_par_iter()
            .map(|l| {
                let lists: Vec<Vec<usize>> = subdomain_stencils.iter().map(|t| t[l].clone()).collect();
                VertexBlocks::new(dim, &lists, &stencils)
            })
            .collect();
        ElasticSubspace {
            blocks,
            subdomain_stencils,
            stencil_vertices: stencils,
            exact: vec![false; num_subdomains],
            newly_exact: Vec::new(),
            state: None,
            stats: SubspaceHessianStats::default(),
        }
    }

    /// Number of elastic terms.
    pub fn num_terms(&self) -> usize {
        self.subdomain_stencils.len()
    }

    /// Whether each subdomain is evaluated exactly.
    pub fn exact_subdomains(&self) -> &[bool] {
        &self.exact
    }

    /// The stencils of `term` in exact subdomains, ascending: the ones the simulator
    /// assembles.
    pub fn exact_stencils(&self, term: usize) -> Vec<usize> {
        self.stencils_of(term, (0..self.exact.len()).filter(|&l| self.exact[l]))
    }

    /// The stencils of `term` in the subdomains made exact since the last call of
    /// [`Self::take_newly_exact`], which the simulator adds to what it assembled.
    pub fn newly_exact_stencils(&self, term: usize) -> Vec<usize> {
        self.stencils_of(term, self.newly_exact.iter().copied())
    }

    /// Forgets the subdomains made exact since the last call.
    pub fn take_newly_exact(&mut self) {
        self.newly_exact.clear();
    }

    fn stencils_of(&self, term: usize, subdomains: impl Iterator<Item = usize>) -> Vec<usize> {
        let mut out: Vec<usize> = subdomains
            .flat_map(|l| self.subdomain_stencils[term][l].iter().copied())
            .collect();
        out.sort_unstable();
        out
    }

    /// Makes exact every subdomain with a stencil that touches a vertex where `enriched`
    /// holds, and approximated every other one. A subdomain that turns exact drops its
    /// approximation (and is recorded for the simulator); one that turns approximated
    /// restarts every approximation at the next iterate.
    pub fn set_enriched(&mut self, enriched: &[bool]) {
        let mut exact = vec![false; self.exact.len()];
        for (term, by_subdomain) in self.subdomain_stencils.iter().enumerate() {
            for (l, stencils) in by_subdomain.iter().enumerate() {
                exact[l] |= stencils
                    .iter()
                    .any(|&s| self.stencil_vertices[term][s].iter().any(|&v| enriched[v]));
            }
        }
        for (l, (&now, &before)) in exact.iter().zip(&self.exact).enumerate() {
            if now && !before {
                self.newly_exact.push(l);
                if let Some(state) = &mut self.state {
                    state.hessians.invalidate(l);
                    state.gradients[l].fill(0.0);
                }
            } else if before && !now {
                self.state = None;
            }
        }
        self.exact = exact;
    }

    /// Starts a time step: the approximations restart from exact values at its first
    /// iterate, and the statistics from zero.
    pub fn begin_step(&mut self) {
        self.state = None;
        self.stats = SubspaceHessianStats::default();
    }

    /// The statistics of the current time step.
    pub fn stats(&self) -> SubspaceHessianStats {
        self.stats
    }

    /// Brings the approximations to the iterate `x`: exact evaluations when there are none
    /// yet or they are over other columns, the secant update by the modal displacement since
    /// the last iterate (`coefficients`, the step's so far) otherwise. The evaluations
    /// project every stencil Hessian to positive semi-definite, so each approximation starts
    /// positive semi-definite and stays so (the paper's guarantee), whether or not the
    /// simulator assembles the exact subdomains from projected Hessians. `elastic` are the
    /// elastic terms with their weights, `modes` the candidate columns over every dof,
    /// `free_index` maps a dof to its free index or `NOT_FREE`.
    #[allow(clippy::too_many_arguments)]
    pub fn prepare(
        &mut self,
        elastic: &[WeightedTerm<'_>],
        x: &[f64],
        modes: &Mat<f64>,
        free_index: &[usize],
        columns: &[usize],
        coefficients: &[f64],
    ) {
        let a = columns.len();
        let current = self.state.as_ref().filter(|s| s.columns == columns);
        let Some(rows) = current.map(|s| &s.rows) else {
            let rows = active_rows(modes, free_index, columns);
            let evaluated = self.project_subdomains(elastic, x, &rows, a, Want::Hessian { project: true });
            let mut matrices = Vec::with_capacity(evaluated.len());
            let mut gradients = Vec::with_capacity(evaluated.len());
            for (h, g) in evaluated {
                matrices.push(h);
                gradients.push(g);
            }
            let mut hessians = SubdomainHessians::new(matrices);
            for (l, &exact) in self.exact.iter().enumerate() {
                if exact {
                    hessians.invalidate(l);
                }
            }
            self.state = Some(SecantState {
                columns: columns.to_vec(),
                rows,
                hessians,
                gradients,
                coefficients: coefficients.to_vec(),
            });
            self.stats.evaluations += 1;
            return;
        };
        let evaluated = self.project_subdomains(elastic, x, rows, a, Want::Gradient);
        let state = self.state.as_mut().unwrap_or_else(|| unreachable!("current above"));
        let s = DVector::from_iterator(a, columns.iter().map(|&c| coefficients[c] - state.coefficients[c]));
        state.coefficients = coefficients.to_vec();
        for (l, (_, g)) in evaluated.into_iter().enumerate() {
            if self.exact[l] {
                continue;
            }
            let y = &g - &state.gradients[l];
            match state.hessians.update(l, &s, &y) {
                SecantUpdate::Applied => self.stats.updates += 1,
                SecantUpdate::Skipped => self.stats.skipped += 1,
                SecantUpdate::Invalid => {}
            }
            state.gradients[l] = g;
        }
    }

    /// Whether the approximations are over `columns`.
    pub fn is_current(&self, columns: &[usize]) -> bool {
        self.state.as_ref().is_some_and(|s| s.columns == columns)
    }

    /// The sum of the approximated subdomains' matrices over `columns`, if the
    /// approximations are over those columns.
    pub fn approximated_sum(&self, columns: &[usize]) -> Option<DMatrix<f64>> {
        let state = self.state.as_ref().filter(|s| s.columns == columns)?;
        Some(state.hessians.valid_sum())
    }

    /// `(Wᵀ ∇²Ψ_l W, Wᵀ ∇Ψ_l)` of every approximated subdomain at `x` (the Hessian part only
    /// when `want` asks for it; zero for the exact subdomains), in parallel over subdomains,
    /// each summed in stencil order. `rows` holds the `a` active columns row-major over every
    /// dof (zero on the prescribed ones).
    fn project_subdomains(
        &self,
        elastic: &[WeightedTerm<'_>],
        x: &[f64],
        rows: &[f64],
        a: usize,
        want: Want,
    ) -> Vec<(DMatrix<f64>, DVector<f64>)> {
        (0..self.exact.len())
            .into_par_iter()
            .map(|l| {
                if self.exact[l] {
                    return (DMatrix::zeros(a, a), DVector::zeros(a));
                }
                let stencils: Vec<&[usize]> = self.subdomain_stencils.iter().map(|t| t[l].as_slice()).collect();
                let (h, g) = self.blocks[l].project(elastic, &stencils, x, rows, a, want);
                let h = if h.is_empty() {
                    DMatrix::zeros(a, a)
                } else {
                    DMatrix::from_row_slice(a, a, &h)
                };
                (h, DVector::from_vec(g))
            })
            .collect()
    }
}

/// The `columns` of `modes` row-major over every dof, zero on the prescribed ones.
fn active_rows(modes: &Mat<f64>, free_index: &[usize], columns: &[usize]) -> Vec<f64> {
    let a = columns.len();
    let mut rows = vec![0.0; modes.nrows() * a];
    for (k, &f) in free_index.iter().enumerate() {
        if f == NOT_FREE {
            continue;
        }
        for (j, &c) in columns.iter().enumerate() {
            rows[k * a + j] = modes[(k, c)];
        }
    }
    rows
}
