//! One adaptive implicit-Euler time step (Trusty et al., Sec. 3.6 and the Newton loop of
//! Algorithm 1): Newton's method on the incremental potential
//! `E(x) = 1/2 |x - x̂|²_M + h² Ψ(x)`, each iterate's direction restricted to the active
//! model, `d = U_a d_q + S d_x`.
//!
//! - `U_a` holds the columns of the active candidate blocks over the free dofs, zeroed on
//!   the enriched vertices (the non-overlapping decomposition of Sec. 3.6: a vertex moves
//!   either through the modes or through its own coordinates, never both), then
//!   re-orthonormalised, which drops the directions the masking annihilated (with every
//!   vertex enriched no modal column is left);
//! - `S` selects the enriched vertices' coordinates.
//!
//! The energy terms, their gradient and the free-free Hessian `H` are those of the
//! full-space [`Simulator`](crate::solver::Simulator), built from the same
//! [`SimulatorConfig`] and assembled by the same sparse assembly, so no energy is written
//! twice. Each iterate solves
//! `[U_a^T H U_a, U_a^T H S; S^T H U_a, S^T H S] [d_q; d_x] = -[U_a^T g; S^T g]` by the
//! Schur complement ([`AdaptiveSystem::solve`]), then takes the full-space solver's
//! backtracking Armijo line search on `E` and its convergence test
//! (`max |d| / (h L) < tolerance`).
//!
//! This first version assembles `H_q = U_a^T H U_a` exactly from the full Hessian (no
//! per-subdomain BFGS, Sec. 3.8), has no contact, and keeps the active model it is given
//! for the whole step (no oracle-driven activation inside the step).

use faer::sparse::{SparseColMat, Triplet};
use nalgebra::{DMatrix, SymmetricEigen};

use super::candidates::CandidateSet;
use super::lower_csc::symmetric_product;
use super::pcg::PcgSettings;
use super::schur::{AdaptiveSystem, Coupling};
use super::SolveError;
use crate::energy::{inertia::Inertia, StencilEnergy};
use crate::error::{InputError, StepError};
use crate::scene::{Energies, Scene};
use crate::solver::hessian::HessianPattern;
use crate::solver::{
    check_targets, free_dof_index, incremental_potential, place_fixed, HessianMode, NewtonSettings, SimulatorConfig,
    TimeScheme, NOT_FREE,
};

/// Relative eigenvalue of the masked basis' Gram matrix below which a direction counts as
/// annihilated by the masking (and is dropped).
const RANK_TOLERANCE: f64 = 1e-10;

/// Why an adaptive step failed.
#[derive(Debug, thiserror::Error)]
pub enum AdaptiveStepError {
    /// The configuration asks for something this step does not do (contact, BDF2,
    /// quasi-statics).
    #[error("adaptive step: {0}")]
    Unsupported(String),
    /// The active model does not fit the body (lengths, block indices).
    #[error("adaptive step: active model: {0}")]
    Model(String),
    /// Bad boundary targets, or a non-finite state.
    #[error(transparent)]
    Step(#[from] StepError),
    /// The scene could not be built.
    #[error(transparent)]
    Input(#[from] InputError),
    /// The Newton-iterate system could not be solved (also with the projected Hessian).
    #[error("adaptive step: Newton iteration {iteration}: {source}")]
    Solve {
        /// The iteration.
        iteration: usize,
        /// The linear solver's error.
        source: SolveError,
    },
}

/// The active model of a step: which candidate blocks span the subspace and which
/// vertices are enriched.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ActiveModel {
    /// `blocks[b]`: whether block `b` of the candidate set is active.
    pub blocks: Vec<bool>,
    /// `enriched[i]`: whether vertex `i` is enriched (prescribed vertices are ignored).
    pub enriched: Vec<bool>,
}

/// What one adaptive step did.
#[derive(Clone, Debug, Default)]
pub struct AdaptiveStepReport {
    /// Newton iterations taken.
    pub iterations: usize,
    /// Scaled step norm `max |d| / (h L)` of each iteration.
    pub step_norms: Vec<f64>,
    /// `E` at the start of each iteration, then at the solution.
    pub objectives: Vec<f64>,
    /// Whether the tolerance was met.
    pub converged: bool,
    /// Iterations whose exact Hessian made the system indefinite, so the projected one was
    /// used.
    pub projected_iterations: usize,
    /// Columns of the masked, re-orthonormalised modal basis (`a`).
    pub modal_columns: usize,
    /// Enriched free coordinates (`n`).
    pub enriched_dofs: usize,
    /// Conjugate-gradient iterations of each Newton iteration's Schur complement solve.
    pub pcg_iterations: Vec<usize>,
}

/// Implicit-Euler stepping of one body in an adaptive model.
pub struct AdaptiveStepper {
    dim: usize,
    dt: f64,
    settings: NewtonSettings,
    pcg: PcgSettings,
    length_scale: f64,
    inertia: Inertia,
    potentials: Vec<Box<dyn StencilEnergy>>,
    fixed_vertices: Vec<usize>,
    free_index: Vec<usize>,
    num_free: usize,
    hessian: HessianPattern,
    x: Vec<f64>,
    v: Vec<f64>,
}

/// The per-iterate model: the masked basis over the free dofs and the enriched free dofs.
struct IterateModel {
    /// `U_a`, `num_free x a`, orthonormal columns.
    basis: DMatrix<f64>,
    /// The enriched free dofs, ascending.
    enriched: Vec<usize>,
    /// `position[f]`: index of free dof `f` among `enriched`, if enriched.
    position: Vec<Option<usize>>,
}

impl AdaptiveStepper {
    /// A stepper starting at rest at `config.x0`, with the energy terms, masses, prescribed
    /// vertices, time step, Newton settings and length scale of `config` (as the
    /// full-space simulator would take them) and `pcg` for the Schur complement solves.
    pub fn new(config: SimulatorConfig, pcg: PcgSettings) -> Result<Self, AdaptiveStepError> {
        if config.contact.is_some() {
            return Err(AdaptiveStepError::Unsupported("contact is not supported".into()));
        }
        if config.scheme != TimeScheme::ImplicitEuler {
            return Err(AdaptiveStepError::Unsupported(format!(
                "time scheme {:?}; only implicit Euler is supported",
                config.scheme
            )));
        }
        let n = config.x0.len();
        if let Some(&v) = config.fixed_vertices.iter().find(|&&v| (v + 1) * config.dim > n) {
            return Err(AdaptiveStepError::Model(format!("fixed vertex {v} out of range")));
        }
        let (free_index, num_free) = free_dof_index(config.dim, n, &config.fixed_vertices);
        let inertia = Inertia::new(config.dim, config.masses);
        let terms: Vec<&dyn StencilEnergy> = std::iter::once(&inertia as &dyn StencilEnergy)
            .chain(config.potentials.iter().map(|p| p.as_ref()))
            .collect();
        let hessian = HessianPattern::new(&terms, &free_index, num_free, &[]);
        Ok(AdaptiveStepper {
            dim: config.dim,
            dt: config.dt,
            settings: config.settings,
            pcg,
            length_scale: config.length_scale,
            inertia,
            potentials: config.potentials,
            fixed_vertices: config.fixed_vertices,
            free_index,
            num_free,
            hessian,
            v: vec![0.0; n],
            x: config.x0,
        })
    }

    /// The stepper of a scene's body, configured as [`Scene::build`] configures the
    /// full-space simulator.
    pub fn from_scene(scene: &Scene, pcg: PcgSettings) -> Result<Self, AdaptiveStepError> {
        let mesh = scene.build_mesh()?;
        let Energies { masses, potentials } = scene.build_energies(&mesh)?;
        let fixed_vertices = scene
            .build_handles(&mesh)?
            .iter()
            .flat_map(|h| h.vertices.iter().copied())
            .collect();
        let contact = match &scene.contact {
            Some(c) => Some(c.build(crate::contact::ContactSurface::of_mesh(&mesh), &scene.source)?),
            None => None,
        };
        Self::new(
            SimulatorConfig {
                dim: mesh.dim,
                length_scale: mesh.rest_diagonal(),
                x0: mesh.rest,
                masses,
                potentials,
                fixed_vertices,
                dt: scene.dt,
                scheme: scene.integrator,
                settings: scene.newton,
                contact,
            },
            pcg,
        )
    }

    /// Current positions.
    pub fn positions(&self) -> &[f64] {
        &self.x
    }
    /// Current velocities.
    pub fn velocities(&self) -> &[f64] {
        &self.v
    }
    /// Vertices whose positions are prescribed, in the order targets are given.
    pub fn fixed_vertices(&self) -> &[usize] {
        &self.fixed_vertices
    }

    /// The incremental potential `E(x)` of the last step taken (its inertia target is that
    /// step's prediction `x̂`; before the first step, the initial positions).
    pub fn incremental_potential(&self, x: &[f64]) -> f64 {
        self.objective(x, None)
    }

    /// Advances one implicit-Euler step with the prescribed vertices at `targets` and the
    /// direction of every Newton iterate restricted to `model` over `candidates`.
    pub fn step(
        &mut self,
        targets: &[f64],
        candidates: &CandidateSet,
        model: &ActiveModel,
    ) -> Result<AdaptiveStepReport, AdaptiveStepError> {
        check_targets(&self.fixed_vertices, self.dim, targets)?;
        let iterate = self.iterate_model(candidates, model)?;
        let h = self.dt;
        let xhat: Vec<f64> = self.x.iter().zip(&self.v).map(|(x, v)| x + h * v).collect();
        self.inertia.set_target(&xhat);
        let mut x = xhat;
        place_fixed(&self.fixed_vertices, self.dim, &mut x, targets);
        let report = self.minimize(&mut x, &iterate)?;
        self.v = x.iter().zip(&self.x).map(|(a, b)| (a - b) / h).collect();
        self.x = x;
        Ok(report)
    }

    /// `U_a` (masked on enriched vertices, restricted to the free dofs, re-orthonormalised)
    /// and the enriched free dofs.
    fn iterate_model(&self, candidates: &CandidateSet, model: &ActiveModel) -> Result<IterateModel, AdaptiveStepError> {
        let (d, n) = (self.dim, self.x.len());
        if candidates.dim != d || candidates.modes.nrows() != n {
            return Err(AdaptiveStepError::Model(format!(
                "candidates have dim {} and {} rows, the body dim {d} and {n} dofs",
                candidates.dim,
                candidates.modes.nrows()
            )));
        }
        if model.blocks.len() != candidates.blocks.len() {
            return Err(AdaptiveStepError::Model(format!(
                "blocks has {} entries, the candidates {} blocks",
                model.blocks.len(),
                candidates.blocks.len()
            )));
        }
        if model.enriched.len() * d != n {
            return Err(AdaptiveStepError::Model(format!(
                "enriched has {} entries, the body {} vertices",
                model.enriched.len(),
                n / d
            )));
        }
        let columns: Vec<usize> = candidates
            .blocks
            .iter()
            .zip(&model.blocks)
            .filter(|(_, &on)| on)
            .flat_map(|(b, _)| b.columns.clone())
            .collect();
        let nf = self.num_free;
        let mut masked = DMatrix::zeros(nf, columns.len());
        let mut enriched = Vec::new();
        let mut position = vec![None; nf];
        for (k, &f) in self.free_index.iter().enumerate() {
            if f == NOT_FREE {
                continue;
            }
            if model.enriched[k / d] {
                position[f] = Some(enriched.len());
                enriched.push(f);
            } else {
                for (j, &c) in columns.iter().enumerate() {
                    masked[(f, j)] = candidates.modes[(k, c)];
                }
            }
        }
        Ok(IterateModel {
            basis: orthonormal_range(&masked),
            enriched,
            position,
        })
    }

    /// `E(x)` and, if asked, its gradient over all dofs.
    fn objective(&self, x: &[f64], grad: Option<&mut Vec<f64>>) -> f64 {
        incremental_potential(&self.inertia, &self.potentials, 1.0, self.dt * self.dt, x, grad)
    }

    /// Assembles the free-free Hessian of `E` at `x`.
    fn assemble(&mut self, x: &[f64], project: bool) {
        let w = self.dt * self.dt;
        let terms = std::iter::once((&self.inertia as &dyn StencilEnergy, 1.0))
            .chain(self.potentials.iter().map(|p| (p.as_ref(), w)));
        self.hessian.assemble(terms, x, project);
    }

    /// The direction `U_a d_q + S d_x` (free dofs) of the assembled Hessian and the free
    /// gradient `g`, with the conjugate-gradient iterations it took.
    fn direction(&self, model: &IterateModel, g: &[f64]) -> Result<(Vec<f64>, usize), SolveError> {
        let h = self.hessian.lower();
        let u = &model.basis;
        let (nf, a, nx) = (self.num_free, u.ncols(), model.enriched.len());
        // H U_a, column by column.
        let mut hu = DMatrix::zeros(nf, a);
        let mut out = vec![0.0; nf];
        for j in 0..a {
            symmetric_product(h, u.column(j).as_slice(), &mut out);
            hu.column_mut(j).copy_from_slice(&out);
        }
        let h_q = u.transpose() * &hu;
        // C = U_a^T H S: the enriched rows of H U_a, transposed.
        let coupling = DMatrix::from_fn(a, nx, |r, c| hu[(model.enriched[c], r)]);
        let mut triplets = Vec::new();
        for (c, &fc) in model.enriched.iter().enumerate() {
            for (fr, &v) in h.symbolic().row_idx_of_col(fc).zip(h.val_of_col(fc)) {
                if let Some(r) = model.position[fr] {
                    triplets.push(Triplet::new(r as u32, c as u32, v));
                }
            }
        }
        let h_x = SparseColMat::<u32, f64>::try_new_from_triplets(nx, nx, &triplets)
            .map_err(|_| SolveError::NonFinite("H_x"))?;
        let g_q: Vec<f64> = (0..a)
            .map(|j| u.column(j).iter().zip(g).map(|(a, b)| a * b).sum())
            .collect();
        let g_x: Vec<f64> = model.enriched.iter().map(|&f| g[f]).collect();
        let system = AdaptiveSystem {
            h_q: &h_q,
            coupling: Coupling::Dense(&coupling),
            h_x: h_x.as_ref(),
            g_q: &g_q,
            g_x: &g_x,
        };
        let solution = system.solve(&self.pcg)?;
        let mut dir = vec![0.0; nf];
        for (j, dq) in solution.d_q.iter().enumerate() {
            for (o, b) in dir.iter_mut().zip(u.column(j).iter()) {
                *o += dq * b;
            }
        }
        for (&f, dx) in model.enriched.iter().zip(&solution.d_x) {
            dir[f] += dx;
        }
        Ok((dir, solution.report.iterations))
    }

    /// Newton with backtracking line search over the free dofs of `x`, each direction in
    /// the active model.
    fn minimize(&mut self, x: &mut [f64], model: &IterateModel) -> Result<AdaptiveStepReport, AdaptiveStepError> {
        let mut report = AdaptiveStepReport {
            modal_columns: model.basis.ncols(),
            enriched_dofs: model.enriched.len(),
            ..AdaptiveStepReport::default()
        };
        let norm_scale = self.dt * self.length_scale;
        let mut grad = Vec::new();
        let mut g_free = vec![0.0; self.num_free];
        let mut trial = x.to_vec();
        for iteration in 0..self.settings.max_iterations {
            let e = self.objective(x, Some(&mut grad));
            if !e.is_finite() {
                return Err(StepError::Diverged { iteration }.into());
            }
            report.objectives.push(e);
            for (k, &f) in self.free_index.iter().enumerate() {
                if f != NOT_FREE {
                    g_free[f] = grad[k];
                }
            }
            // As the full-space solver: the exact Hessian where the system it gives is
            // positive definite, the per-stencil PSD projection otherwise.
            let exact_first = self.settings.hessian == HessianMode::ExactIfDefinite;
            self.assemble(x, !exact_first);
            let (dir, pcg_iterations) = match self.direction(model, &g_free) {
                Ok(found) => found,
                Err(
                    SolveError::NotPositiveDefinite(_)
                    | SolveError::PreconditionerBlock { .. }
                    | SolveError::Indefinite { .. },
                ) if exact_first => {
                    report.projected_iterations += 1;
                    self.assemble(x, true);
                    self.direction(model, &g_free)
                        .map_err(|source| AdaptiveStepError::Solve { iteration, source })?
                }
                Err(source) => return Err(AdaptiveStepError::Solve { iteration, source }),
            };
            report.pcg_iterations.push(pcg_iterations);
            let step_norm = dir.iter().fold(0.0f64, |m, d| m.max(d.abs())) / norm_scale;
            if !step_norm.is_finite() {
                return Err(StepError::Diverged { iteration }.into());
            }
            report.step_norms.push(step_norm);
            report.iterations = iteration + 1;
            let slope: f64 = g_free.iter().zip(&dir).map(|(g, d)| g * d).sum();
            // At the round-off floor the predicted decrease is below what E resolves.
            if -slope <= 1e-14 * e.abs() {
                report.converged = true;
                break;
            }
            let mut alpha = 1.0;
            loop {
                for (k, &f) in self.free_index.iter().enumerate() {
                    if f != NOT_FREE {
                        trial[k] = x[k] + alpha * dir[f];
                    }
                }
                let et = self.objective(&trial, None);
                if et.is_finite() && et <= e + 1e-4 * alpha * slope.min(0.0) {
                    break;
                }
                alpha *= 0.5;
                if alpha < 1e-12 {
                    alpha = 0.0;
                    break;
                }
            }
            for (k, &f) in self.free_index.iter().enumerate() {
                if f != NOT_FREE {
                    x[k] += alpha * dir[f];
                }
            }
            if step_norm < self.settings.tolerance || alpha == 0.0 {
                report.converged = step_norm < self.settings.tolerance;
                break;
            }
        }
        if x.iter().any(|c| !c.is_finite()) {
            return Err(StepError::Diverged {
                iteration: report.iterations,
            }
            .into());
        }
        report.objectives.push(self.objective(x, None));
        Ok(report)
    }
}

/// An orthonormal basis of the column space of `u` (from the eigen-decomposition of its
/// Gram matrix, dropping directions whose eigenvalue is below `RANK_TOLERANCE` times the
/// largest, or all of them when `u` is zero).
fn orthonormal_range(u: &DMatrix<f64>) -> DMatrix<f64> {
    if u.ncols() == 0 {
        return u.clone();
    }
    let eigen = SymmetricEigen::new(u.transpose() * u);
    let largest = eigen.eigenvalues.iter().fold(0.0f64, |m, &l| m.max(l));
    let keep: Vec<usize> = (0..u.ncols())
        .filter(|&j| largest > 0.0 && eigen.eigenvalues[j] > RANK_TOLERANCE * largest)
        .collect();
    let mut basis = DMatrix::zeros(u.nrows(), keep.len());
    for (c, &j) in keep.iter().enumerate() {
        let col = u * eigen.eigenvectors.column(j) / eigen.eigenvalues[j].sqrt();
        basis.column_mut(c).copy_from(&col);
    }
    basis
}
