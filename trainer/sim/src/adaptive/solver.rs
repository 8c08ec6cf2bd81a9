//! The adaptive model inside the full-space Newton loop (Trusty et al., Algorithm 1).
//!
//! The [`Simulator`](crate::solver::Simulator) keeps its time integration, energies, contact,
//! CCD-bounded line search and convergence test; with an [`AdaptiveSolver`] attached, each
//! Newton iterate's direction comes from here instead of a sparse Cholesky solve:
//!
//! 1. [`AdaptiveSolver::update_model`] (Sec. 3.7): the unmasked active subspace's Newton
//!    step `p = -H_q⁻¹ U_aᵀ g` (Eq. 18), rescaled by a line search, is the step the oracle
//!    judges; it activates the candidate blocks and enriches the subdomains whose error
//!    exceeds `ε_G` where that step's progress is below `ε_E`;
//! 2. [`AdaptiveSolver::solve`] (Sec. 3.8, 3.10): the masked model's system
//!    `[B^T H B, B^T H S; S^T H B, S^T H S] [d_q; d_x] = -[B^T g; S^T g]` by the Schur
//!    complement, with the Hessian `H` the simulator assembled (inertia, contact and the
//!    elasticity of the subdomains near enriched vertices, exactly) and, with the default
//!    `subspace_hessian = "bfgs"`, the per-subdomain BFGS matrices of the others' elasticity
//!    added to `B^T H B` ([`super::elastic_subspace`]); every vertex enriched is full-space
//!    Newton;
//! 3. [`AdaptiveSolver::accept`] adds the line search's share of the modal step to the
//!    step's modal displacement, and [`AdaptiveSolver::end_step`] downdates (Sec. 3.11).
//!
//! `U_a` is dense over the free dofs.

use std::time::Instant;

use faer::sparse::{SparseColMat, SparseColMatRef};
use nalgebra::{DMatrix, DVector, SymmetricEigen};

use super::candidates::{BlockKind, CandidateSet};
use super::elastic_subspace::{ElasticSubspace, SubspaceHessianStats};
use super::model::{active_columns, ActiveModel, EnrichedDofs, ModalBasis};
use super::oracle::{Oracle, Query, WeightedTerm};
use super::pcg::PcgSettings;
use super::settings::AdaptiveSettings;
use super::system::{hessian_times, model_direction, time_solvers, KeptSystem, LinearSolverTimings};
use super::SolveError;
use crate::dofs::{free_dof_index, NOT_FREE};

/// One Newton iterate as the simulator sees it.
pub struct Iterate<'a> {
    /// Lower triangle of the free-free Hessian of the objective.
    pub hessian: SparseColMatRef<'a, u32, f64>,
    /// Current positions, every dof.
    pub x: &'a [f64],
    /// The objective's gradient, every dof (with contact).
    pub gradient: &'a [f64],
    /// The right-hand side over the free dofs: the negative gradient (and a moving
    /// obstacle's push).
    pub rhs: &'a [f64],
    /// The objective's stencil terms with their weights (the oracle's progress): inertia
    /// first, then the potentials, the body's elastic terms first among them.
    pub terms: &'a [WeightedTerm<'a>],
    /// Time step of the oracle's scales.
    pub dt: f64,
}

/// What the adaptive model did in one time step.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AdaptiveStepStats {
    /// Enriched free vertices at the end of the solve (before downdating).
    pub enriched_vertices: usize,
    /// Those vertices, ascending (previews mark them).
    pub enriched: Vec<usize>,
    /// Free vertices of the body.
    pub free_vertices: usize,
    /// Active candidate columns at the end of the solve (before downdating).
    pub active_modes: usize,
    /// Candidate columns in all.
    pub candidate_modes: usize,
    /// Blocks the oracle activated during the step.
    pub activated_blocks: usize,
    /// Subdomains the oracle enriched during the step.
    pub enriched_subdomains: usize,
    /// Blocks downdated after the step.
    pub downdated_blocks: usize,
    /// Subdomains downdated after the step.
    pub downdated_subdomains: usize,
    /// Conjugate-gradient iterations of the step's Schur complement solves.
    pub pcg_iterations: usize,
    /// Seconds in the oracle (its step, scores and decisions).
    pub oracle_seconds: f64,
    /// Seconds building and solving the model's systems.
    pub system_seconds: f64,
    /// What the per-subdomain BFGS approximations did (zero with `subspace_hessian =
    /// "exact"`).
    pub subspace_hessian: SubspaceHessianStats,
}

/// The model's bases, rebuilt when the model changes.
#[derive(Clone)]
struct Bases {
    unmasked: ModalBasis,
    masked: ModalBasis,
    enriched: EnrichedDofs,
}

/// The adaptive model of one body and its state across steps.
#[derive(Clone)]
pub struct AdaptiveSolver {
    settings: AdaptiveSettings,
    dim: usize,
    length_scale: f64,
    candidates: CandidateSet,
    oracle: Oracle,
    subdomain_vertices: Vec<Vec<usize>>,
    free_index: Vec<usize>,
    num_free: usize,
    free_vertex: Vec<bool>,
    active_blocks: Vec<bool>,
    enriched_subdomains: Vec<bool>,
    bases: Option<Bases>,
    /// `H U_a` of the oracle's step at this iterate, handed to the model's solve when the
    /// model kept its blocks and enriches nothing (its masked basis is then `U_a` itself).
    unmasked_product: Option<DMatrix<f64>>,
    /// The last solve's modal step, as coefficients of the candidate columns.
    last_coefficients: Vec<f64>,
    /// The step's accumulated modal displacement, as coefficients of the candidate columns.
    step_coefficients: Vec<f64>,
    stats: AdaptiveStepStats,
    /// The largest system met, when asked to keep it.
    kept: Option<KeptSystem>,
    /// The elastic subspace Hessian by per-subdomain BFGS, when the settings ask for it.
    elastic: Option<ElasticSubspace>,
    /// Whether `elastic` was brought to the current iterate.
    elastic_prepared: bool,
}

impl AdaptiveSolver {
    /// The solver of a body with `candidates`, the `oracle` built on its fixed decomposition
    /// (`subdomain_vertices[l]`: the vertices of subdomain `l`), prescribed vertices
    /// `fixed_vertices` and rest diagonal `length_scale`. It starts with the rigid and
    /// affine blocks and the first `initial_linear_modes` linear modes active, and nothing
    /// enriched.
    pub fn new(
        settings: AdaptiveSettings,
        candidates: CandidateSet,
        oracle: Oracle,
        subdomain_vertices: Vec<Vec<usize>>,
        fixed_vertices: &[usize],
        length_scale: f64,
    ) -> Self {
        let dim = candidates.dim;
        let n = candidates.modes.nrows();
        let (free_index, num_free) = free_dof_index(dim, n, fixed_vertices);
        let free_vertex = (0..n / dim).map(|i| free_index[i * dim] != NOT_FREE).collect();
        let active_blocks = candidates
            .blocks
            .iter()
            .map(|b| match b.kind {
                BlockKind::Rigid | BlockKind::Affine => true,
                BlockKind::LinearMode(j) => j < settings.initial_linear_modes,
                BlockKind::DataMode(j) => j < settings.initial_data_modes,
            })
            .collect();
        let columns = candidates.modes.ncols();
        AdaptiveSolver {
            enriched_subdomains: vec![false; subdomain_vertices.len()],
            settings,
            dim,
            length_scale,
            oracle,
            subdomain_vertices,
            free_index,
            num_free,
            free_vertex,
            active_blocks,
            bases: None,
            unmasked_product: None,
            last_coefficients: vec![0.0; columns],
            step_coefficients: vec![0.0; columns],
            stats: AdaptiveStepStats::default(),
            kept: None,
            elastic: None,
            elastic_prepared: false,
            candidates,
        }
    }

    /// Evaluates the elastic subspace Hessian of the subdomains without an enriched vertex
    /// by `elastic`'s per-subdomain BFGS (its terms the first potentials of the iterates).
    pub fn with_elastic_subspace(mut self, mut elastic: ElasticSubspace) -> Self {
        elastic.set_enriched(&self.enriched_vertices());
        elastic.take_newly_exact();
        self.elastic = Some(elastic);
        self
    }

    /// The per-subdomain BFGS of the elastic subspace Hessian, if used: the simulator
    /// assembles the elastic Hessian of its exact subdomains only.
    pub fn elastic_subspace(&self) -> Option<&ElasticSubspace> {
        self.elastic.as_ref()
    }

    /// The same, to take the subdomains made exact since the simulator assembled.
    pub fn elastic_subspace_mut(&mut self) -> Option<&mut ElasticSubspace> {
        self.elastic.as_mut()
    }

    /// The settings.
    pub fn settings(&self) -> &AdaptiveSettings {
        &self.settings
    }

    /// The candidate bases.
    pub fn candidates(&self) -> &CandidateSet {
        &self.candidates
    }

    /// The current model.
    pub fn model(&self) -> ActiveModel {
        ActiveModel {
            blocks: self.active_blocks.clone(),
            enriched: self.enriched_vertices(),
        }
    }

    /// Replaces the model: the given blocks active, and every subdomain holding an enriched
    /// vertex of `model` enriched (the model's enriched vertices are rounded up to whole
    /// subdomains).
    pub fn set_model(&mut self, model: &ActiveModel) -> Result<(), String> {
        model.check(&self.candidates, self.free_vertex.len())?;
        self.active_blocks.clone_from(&model.blocks);
        for (l, verts) in self.subdomain_vertices.iter().enumerate() {
            self.enriched_subdomains[l] = verts.iter().any(|&v| model.enriched[v]);
        }
        self.bases = None;
        self.enrichment_changed();
        Ok(())
    }

    /// Whether each vertex is enriched.
    pub fn enriched_vertices(&self) -> Vec<bool> {
        let mut enriched = vec![false; self.free_vertex.len()];
        for (verts, _) in self
            .subdomain_vertices
            .iter()
            .zip(&self.enriched_subdomains)
            .filter(|(_, &on)| on)
        {
            for &v in verts {
                enriched[v] = true;
            }
        }
        enriched
    }

    /// Starts a time step: clears the step's modal displacement and statistics.
    pub fn begin_step(&mut self) {
        self.step_coefficients.fill(0.0);
        self.last_coefficients.fill(0.0);
        self.elastic_prepared = false;
        if let Some(e) = &mut self.elastic {
            e.begin_step();
        }
        self.stats = AdaptiveStepStats {
            free_vertices: self.free_vertex.iter().filter(|&&f| f).count(),
            candidate_modes: self.candidates.modes.ncols(),
            ..AdaptiveStepStats::default()
        };
    }

    /// The oracle's update of the model at the start of a Newton iterate (module docs,
    /// step 1); `objective_along(step)` returns the line search's scale of `step` (a
    /// displacement of every dof). With adaptivity off the model stays.
    pub fn update_model(
        &mut self,
        it: &Iterate<'_>,
        objective_along: &mut dyn FnMut(&[f64]) -> f64,
    ) -> Result<(), String> {
        if !self.settings.adapt {
            return Ok(());
        }
        let clock = Instant::now();
        self.prepare_elastic(it);
        self.bases();
        let unmasked = &self
            .bases
            .as_ref()
            .unwrap_or_else(|| unreachable!("built above"))
            .unmasked;
        let approximated = approximated_part(self.elastic.as_ref(), unmasked);
        let mut step = vec![0.0; it.x.len()];
        let mut product = None;
        if !unmasked.is_empty() {
            let u = &unmasked.basis;
            let hu = hessian_times(it.hessian, u);
            let mut h_q = u.transpose() * &hu;
            if let Some(extra) = &approximated {
                h_q += extra;
            }
            product = Some(hu);
            let g_q = u.transpose() * DVector::from_column_slice(it.rhs);
            let p = projected_solve(h_q, &g_q);
            let free_step = u * p;
            for (k, &f) in self.free_index.iter().enumerate() {
                if f != NOT_FREE {
                    step[k] = free_step[f];
                }
            }
            let alpha = objective_along(&step);
            step.iter_mut().for_each(|s| *s *= alpha);
        }
        let query = Query {
            terms: it.terms,
            x: it.x,
            gradient: it.gradient,
            step: &step,
            dt: it.dt,
        };
        let decision = self
            .oracle
            .decide(&query, &self.candidates, &self.active_blocks, &self.enriched_subdomains)
            .map_err(|e| e.to_string())?;
        for &b in &decision.activate_blocks {
            self.active_blocks[b] = true;
        }
        for s in &decision.enrich_subdomains {
            self.enriched_subdomains[s.subdomain] = true;
        }
        self.stats.activated_blocks += decision.activate_blocks.len();
        self.stats.enriched_subdomains += decision.enrich_subdomains.len();
        if !decision.activate_blocks.is_empty() || !decision.enrich_subdomains.is_empty() {
            self.bases = None;
        }
        if !decision.enrich_subdomains.is_empty() {
            self.enrichment_changed();
        }
        let unmasked_is_masked = self.bases.as_ref().is_some_and(|b| b.enriched.dofs.is_empty());
        self.unmasked_product = product.filter(|_| unmasked_is_masked);
        self.stats.oracle_seconds += clock.elapsed().as_secs_f64();
        Ok(())
    }

    /// The Newton direction over the free dofs in the current model (module docs, step 2).
    pub fn solve(&mut self, it: &Iterate<'_>) -> Result<Vec<f64>, SolveError> {
        let clock = Instant::now();
        let pcg = self.pcg();
        let num_free = self.num_free;
        self.prepare_elastic(it);
        self.bases();
        let bases = self.bases.take().unwrap_or_else(|| unreachable!("built above"));
        let (b, enriched) = (&bases.masked, &bases.enriched);
        let approximated = approximated_part(self.elastic.as_ref(), b);
        // The oracle's product serves this solve only (a retry with the projected Hessian
        // computes its own).
        let product = self.unmasked_product.take();
        let found = model_direction(
            b,
            enriched,
            num_free,
            (it.hessian, approximated.as_ref()),
            product,
            it.rhs,
            &pcg,
        );
        let columns = b.columns.clone();
        let keep = self
            .kept
            .as_ref()
            .is_some_and(|k| k.hessian.nrows() == 0 || k.enriched.dofs.len() < enriched.dofs.len());
        // Only a system all three solvers can take: the full Hessian positive definite.
        if keep && found.is_ok() && super::full_space::factors(it.hessian) {
            if let Ok(symbolic) = it.hessian.symbolic().to_owned() {
                self.kept = Some(KeptSystem {
                    hessian: SparseColMat::new(symbolic, it.hessian.val().to_vec()),
                    rhs: it.rhs.to_vec(),
                    masked: b.clone(),
                    enriched: enriched.clone(),
                });
            }
        }
        self.bases = Some(bases);
        let found = found?;
        self.last_coefficients.fill(0.0);
        for (&c, v) in columns.iter().zip(found.candidate_step.iter()) {
            self.last_coefficients[c] = *v;
        }
        self.stats.pcg_iterations += found.pcg_iterations;
        self.stats.system_seconds += clock.elapsed().as_secs_f64();
        Ok(found.direction)
    }

    /// The Schur complement's conjugate-gradient settings.
    fn pcg(&self) -> PcgSettings {
        PcgSettings {
            tolerance: self.settings.pcg_tolerance,
            block: self.dim,
            ..PcgSettings::default()
        }
    }

    /// From now on, keeps the system of the iterate with the most enriched coordinates whose
    /// full Hessian is positive definite, for [`AdaptiveSolver::time_linear_solvers`]. Only
    /// with `subspace_hessian = "exact"`: with the per-subdomain BFGS the simulator does not
    /// assemble the full Hessian, so nothing is kept.
    pub fn keep_largest_system(&mut self) {
        if self.kept.is_none() && self.elastic.is_none() {
            self.kept = Some(KeptSystem {
                hessian: SparseColMat::try_new_from_triplets(0, 0, &[]).unwrap_or_else(|_| unreachable!("empty")),
                rhs: Vec::new(),
                masked: ModalBasis::new(&self.candidates, Vec::new(), &self.free_index, 0, None),
                enriched: EnrichedDofs::new(&[], self.dim, &[], 0),
            });
        }
    }

    /// Times the three solvers of the kept system (the paper's Table 3): the model's Schur
    /// complement PCG, and on the full system faer's sparse Cholesky and block-Jacobi PCG.
    pub fn time_linear_solvers(&self) -> Option<Result<LinearSolverTimings, SolveError>> {
        let kept = self.kept.as_ref().filter(|k| k.hessian.nrows() > 0)?;
        Some(time_solvers(kept, self.num_free, &self.pcg()))
    }

    /// Adds `alpha` times the last solve's modal step to the step's modal displacement.
    pub fn accept(&mut self, alpha: f64) {
        for (s, l) in self.step_coefficients.iter_mut().zip(&self.last_coefficients) {
            *s += alpha * l;
        }
        self.elastic_prepared = false;
    }

    /// Brings the elastic subspace approximations to the iterate, once per iterate and
    /// again when the active columns changed.
    fn prepare_elastic(&mut self, it: &Iterate<'_>) {
        let columns = active_columns(&self.candidates, &self.active_blocks);
        let Some(e) = &mut self.elastic else {
            return;
        };
        if self.elastic_prepared && e.is_current(&columns) {
            return;
        }
        let terms = it.terms.get(1..1 + e.num_terms()).unwrap_or(&[]);
        e.prepare(
            terms,
            it.x,
            &self.candidates.modes,
            &self.free_index,
            &columns,
            &self.step_coefficients,
        );
        self.elastic_prepared = true;
    }

    /// Tells the elastic subspace which vertices are enriched now.
    fn enrichment_changed(&mut self) {
        let enriched = self.enriched_vertices();
        if let Some(e) = &mut self.elastic {
            e.set_enriched(&enriched);
        }
    }

    /// Ends a time step whose solve moved the body from `x_start` to `x_end` (every dof)
    /// with time step `dt`: records the model's size and downdates (Sec. 3.11). Returns
    /// the step's statistics.
    pub fn end_step(&mut self, x_start: &[f64], x_end: &[f64], dt: f64) -> AdaptiveStepStats {
        let enriched = self.enriched_vertices();
        self.stats.enriched = (0..enriched.len())
            .filter(|&i| enriched[i] && self.free_vertex[i])
            .collect();
        self.stats.enriched_vertices = self.stats.enriched.len();
        self.stats.active_modes = active_columns(&self.candidates, &self.active_blocks).len();
        self.stats.subspace_hessian = self.elastic.as_ref().map(|e| e.stats()).unwrap_or_default();
        if self.settings.adapt && self.settings.downdate > 0.0 {
            self.downdate(x_start, x_end, dt, &enriched);
        }
        self.stats.clone()
    }

    /// Drops the linear-mode blocks whose displacement this step was small, and the
    /// enriched subdomains whose every free vertex moved as the modes would have moved it.
    /// The rigid and affine blocks stay (a departure from the paper, which may drop any
    /// mode): they are at most 12 columns, and without them a vertex that is not enriched
    /// could not move at all until the oracle's error, which is small for smooth loads such
    /// as gravity, brought a mode back.
    fn downdate(&mut self, x_start: &[f64], x_end: &[f64], dt: f64, enriched: &[bool]) {
        let d = self.dim;
        let limit = self.settings.downdate * self.length_scale * dt;
        let n = x_start.len();
        // The modal displacement of every dof, unmasked, from the active columns.
        let mut modal = vec![0.0; n];
        for (b, block) in self.candidates.blocks.iter().enumerate() {
            if !self.active_blocks[b] {
                continue;
            }
            let kept = matches!(block.kind, BlockKind::Rigid | BlockKind::Affine);
            let mut block_disp = vec![0.0; n];
            for c in block.columns.clone() {
                let coefficient = self.step_coefficients[c];
                if coefficient == 0.0 {
                    continue;
                }
                for (k, o) in block_disp.iter_mut().enumerate() {
                    *o += self.candidates.modes[(k, c)] * coefficient;
                }
            }
            let largest = block_disp
                .iter()
                .enumerate()
                .filter(|(k, _)| self.free_vertex[k / d] && !enriched[k / d])
                .fold(0.0f64, |m, (_, v)| m.max(v.abs()));
            for (m, v) in modal.iter_mut().zip(&block_disp) {
                *m += v;
            }
            if largest < limit && !kept {
                self.active_blocks[b] = false;
                self.stats.downdated_blocks += 1;
            }
        }
        for l in 0..self.subdomain_vertices.len() {
            if !self.enriched_subdomains[l] {
                continue;
            }
            let captured = self.subdomain_vertices[l]
                .iter()
                .filter(|&&v| self.free_vertex[v])
                .all(|&v| {
                    let gap: f64 = (v * d..(v + 1) * d)
                        .map(|k| (x_end[k] - x_start[k] - modal[k]).powi(2))
                        .sum();
                    gap.sqrt() < limit
                });
            if captured {
                self.enriched_subdomains[l] = false;
                self.stats.downdated_subdomains += 1;
            }
        }
        if self.stats.downdated_blocks > 0 || self.stats.downdated_subdomains > 0 {
            self.bases = None;
        }
        if self.stats.downdated_subdomains > 0 {
            self.enrichment_changed();
        }
    }

    /// The current model's bases, built if the model changed.
    fn bases(&mut self) -> &Bases {
        if self.bases.is_none() {
            let model = self.model();
            let columns = model.columns(&self.candidates);
            let (c, fi, nf) = (&self.candidates, &self.free_index, self.num_free);
            self.bases = Some(Bases {
                unmasked: ModalBasis::new(c, columns.clone(), fi, nf, None),
                masked: ModalBasis::new(c, columns, fi, nf, Some(&model.enriched)),
                enriched: EnrichedDofs::new(&model.enriched, self.dim, fi, nf),
            });
        }
        self.bases.as_ref().unwrap_or_else(|| unreachable!("built above"))
    }
}

/// `Wᵀ (Σ_l B_l) W` of `basis` (`W` its coefficients) over the subdomains `elastic`
/// approximates, when it approximates any over the basis' columns.
fn approximated_part(elastic: Option<&ElasticSubspace>, basis: &ModalBasis) -> Option<DMatrix<f64>> {
    let sum = elastic?.approximated_sum(&basis.columns)?;
    let w = &basis.coefficients;
    Some(w.transpose() * sum * w)
}

/// `H_q⁻¹ r` with `H_q` projected to positive definite (eigenvalues clamped to a small
/// fraction of the largest) when it is not.
fn projected_solve(h_q: DMatrix<f64>, r: &DVector<f64>) -> DVector<f64> {
    if let Some(chol) = h_q.clone().cholesky() {
        return chol.solve(r);
    }
    let eigen = SymmetricEigen::new(h_q);
    let largest = eigen.eigenvalues.iter().fold(0.0f64, |m, &l| m.max(l.abs()));
    let floor = (1e-8 * largest).max(f64::MIN_POSITIVE);
    let v = &eigen.eigenvectors;
    let vr = v.transpose() * r;
    let scaled = DVector::from_iterator(
        vr.len(),
        vr.iter()
            .zip(eigen.eigenvalues.iter())
            .map(|(a, l)| a / l.abs().max(floor)),
    );
    v * scaled
}
