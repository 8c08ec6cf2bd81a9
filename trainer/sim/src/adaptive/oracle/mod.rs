//! The adaptive update oracle (Trusty et al., Secs. 3.3-3.5 and 3.7): per-vertex error and
//! progress measures, their modal and modal-block versions, and the decision of which
//! candidate blocks to activate and which subdomains to enrich.
//!
//! - [`scales`]: `H̄_i`, `A_i`, `V_i`, the rest-shape factors that make the measures
//!   dimensionless (Eqs. 5, 8);
//! - [`nodal`]: the nodal error `G_i` and progress `E_i` (Eqs. 7, 9-11);
//! - [`modal`]: the modal and modal-block error and progress (Eqs. 12-17).
//!
//! A candidate (a block of modes, or a vertex and with it its whole subdomain of the fixed
//! decomposition) is activated when its error exceeds the error threshold and the progress
//! that the active subspace's step makes on it is below the progress threshold: the current
//! model is wrong there and cannot fix it by itself.
//!
//! The energies are the solver's own [`StencilEnergy`] terms with their weights in the
//! incremental potential `E = K + α h² Ψ` (inertia with weight 1, the potentials with the
//! time scheme's `α h²`), so no energy is written twice.

pub mod modal;
pub mod nodal;
pub mod scales;
#[cfg(test)]
mod tests;

pub use modal::BlockScore;
pub use nodal::NodalMeasures;
pub use scales::NodeScales;

use super::candidates::CandidateSet;
use crate::energy::StencilEnergy;

/// Why the oracle could not score a query.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum OracleError {
    /// An input is inconsistent (lengths, dimensions, indices, non-finite or
    /// non-positive values); the message names it.
    #[error("oracle input: {0}")]
    Input(String),
}

/// One term of the incremental potential and its weight there.
#[derive(Clone, Copy)]
pub struct WeightedTerm<'a> {
    /// The term, as the solver evaluates it.
    pub energy: &'a dyn StencilEnergy,
    /// Its weight in the incremental potential (1 for inertia, `α h²` for potentials).
    pub weight: f64,
}

/// The oracle's thresholds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Thresholds {
    /// `ε_G` of modal candidates: a block whose error exceeds it is a candidate.
    pub modal_error: f64,
    /// `ε_G` of nodal candidates.
    pub nodal_error: f64,
    /// `ε_E`: a candidate is activated only where the active subspace's progress is below it.
    pub progress: f64,
}

impl Default for Thresholds {
    /// The paper's defaults (Sec. 4): `ε_E = 1e-4` in every example, and `ε_G = 0.5` for
    /// both nodal and modal candidates in most of them (its threshold study, Fig. 12,
    /// shows that lowering `ε_G` trades cost for a smaller residual, down to full
    /// enrichment near `1e-2`). Both measures are dimensionless, so the same values hold
    /// across scales, materials and time steps.
    fn default() -> Self {
        Thresholds {
            modal_error: 0.5,
            nodal_error: 0.5,
            progress: 1e-4,
        }
    }
}

/// The state an oracle query looks at: the start of a Newton iterate.
#[derive(Clone, Copy)]
pub struct Query<'a> {
    /// The incremental potential's stencil terms with their weights.
    pub terms: &'a [WeightedTerm<'a>],
    /// Current positions (`dim` per vertex, prescribed vertices at their targets).
    pub x: &'a [f64],
    /// The full incremental-potential gradient at `x` (it may hold terms without a stencil
    /// form, such as contact, beyond `terms`); its prescribed entries are ignored.
    pub gradient: &'a [f64],
    /// The line-search-scaled descent step of the active subspace (Eq. 18), as a
    /// displacement of every dof.
    pub step: &'a [f64],
    /// Time step `h` of the scales `h² A_i H̄_i` and `h² V_i H̄_i`.
    pub dt: f64,
}

/// A subdomain to enrich and the vertex that qualified it.
#[derive(Clone, Debug, PartialEq)]
pub struct SubdomainScore {
    /// The subdomain.
    pub subdomain: usize,
    /// Its qualifying vertex of largest error.
    pub vertex: usize,
    /// That vertex's error `G_i`.
    pub error: f64,
    /// That vertex's progress `E_i`.
    pub progress: f64,
}

/// What the oracle decided, with the scores behind it.
#[derive(Clone, Debug, PartialEq)]
pub struct Decision {
    /// Every vertex's measures.
    pub nodal: NodalMeasures,
    /// The score of every block that was not already active, in block order.
    pub blocks: Vec<BlockScore>,
    /// The blocks to activate, ascending.
    pub activate_blocks: Vec<usize>,
    /// The subdomains to enrich (not already enriched), ascending.
    pub enrich_subdomains: Vec<SubdomainScore>,
}

/// The oracle of one body: its scales, prescribed vertices, fixed decomposition and
/// thresholds.
#[derive(Clone, Debug)]
pub struct Oracle {
    scales: NodeScales,
    /// The one-rings of the terms of the first query (checked then), reused while the
    /// terms are the same.
    rings: std::sync::OnceLock<nodal::RingCache>,
    free: Vec<bool>,
    vertex_subdomain: Vec<usize>,
    num_subdomains: usize,
    thresholds: Thresholds,
}

impl Oracle {
    /// The oracle of a body with `scales`, prescribed vertices `fixed_vertices`, and the
    /// fixed decomposition's subdomain of every vertex (`Partition::vertex_subdomains`).
    pub fn new(
        scales: NodeScales,
        fixed_vertices: &[usize],
        vertex_subdomains: &[usize],
        thresholds: Thresholds,
    ) -> Result<Self, OracleError> {
        let n = scales.num_vertices();
        if vertex_subdomains.len() != n {
            return Err(OracleError::Input(format!(
                "vertex_subdomains has {} entries, the body {n} vertices",
                vertex_subdomains.len()
            )));
        }
        let mut free = vec![true; n];
        for &v in fixed_vertices {
            if v >= n {
                return Err(OracleError::Input(format!(
                    "fixed vertex {v} out of range ({n} vertices)"
                )));
            }
            free[v] = false;
        }
        let t = thresholds;
        if ![t.modal_error, t.nodal_error, t.progress].iter().all(|v| v.is_finite()) {
            return Err(OracleError::Input(format!("thresholds must be finite, got {t:?}")));
        }
        Ok(Oracle {
            rings: std::sync::OnceLock::new(),
            num_subdomains: vertex_subdomains.iter().max().map_or(0, |m| m + 1),
            vertex_subdomain: vertex_subdomains.to_vec(),
            scales,
            free,
            thresholds,
        })
    }

    /// The per-vertex scales.
    pub fn scales(&self) -> &NodeScales {
        &self.scales
    }

    /// The thresholds.
    pub fn thresholds(&self) -> Thresholds {
        self.thresholds
    }

    /// The nodal measures of `query` (Eqs. 7, 9-11).
    pub fn nodal(&self, query: &Query<'_>) -> Result<NodalMeasures, OracleError> {
        self.check(query)?;
        let n = self.scales.num_vertices();
        let fresh;
        let cache = match self.rings.get() {
            Some(c) if c.fits(query.terms) => c,
            Some(_) => {
                nodal::check_terms(self.scales.dim, n, query.terms)?;
                fresh = nodal::RingCache::new(n, query.terms);
                &fresh
            }
            None => {
                nodal::check_terms(self.scales.dim, n, query.terms)?;
                self.rings.get_or_init(|| nodal::RingCache::new(n, query.terms))
            }
        };
        Ok(nodal::nodal_measures(
            &self.scales,
            cache,
            query.terms,
            query.x,
            query.gradient,
            query.step,
            query.dt,
            &self.free,
        ))
    }

    /// Scores every inactive block of `candidates` and every vertex, and decides (Sec. 3.7):
    /// a block is activated when its error exceeds `modal_error` and its progress is below
    /// `progress`; a free vertex whose error exceeds `nodal_error` and whose progress is
    /// below `progress` enriches its whole subdomain, unless that one is already enriched.
    /// `active_blocks[b]` says whether block `b` is already active, `enriched[l]` whether
    /// subdomain `l` is.
    pub fn decide(
        &self,
        query: &Query<'_>,
        candidates: &CandidateSet,
        active_blocks: &[bool],
        enriched: &[bool],
    ) -> Result<Decision, OracleError> {
        let n = self.scales.num_vertices();
        let dim = self.scales.dim;
        if candidates.dim != dim || candidates.modes.nrows() != n * dim {
            return Err(OracleError::Input(format!(
                "candidates have dim {} and {} rows, the body dim {dim} and {} dofs",
                candidates.dim,
                candidates.modes.nrows(),
                n * dim
            )));
        }
        if active_blocks.len() != candidates.blocks.len() {
            return Err(OracleError::Input(format!(
                "active_blocks has {} entries, the candidates {} blocks",
                active_blocks.len(),
                candidates.blocks.len()
            )));
        }
        if enriched.len() != self.num_subdomains {
            return Err(OracleError::Input(format!(
                "enriched has {} entries, the decomposition {} subdomains",
                enriched.len(),
                self.num_subdomains
            )));
        }
        let nodal = self.nodal(query)?;
        let t = self.thresholds;
        let gradient: Vec<f64> = query
            .gradient
            .iter()
            .enumerate()
            .map(|(k, g)| if self.free[k / dim] { *g } else { 0.0 })
            .collect();
        let blocks: Vec<BlockScore> = (0..candidates.blocks.len())
            .filter(|&b| !active_blocks[b])
            .map(|b| {
                let u = candidates.block(b);
                modal::block_score(
                    b,
                    u,
                    &gradient,
                    &nodal.energy_change,
                    &self.scales,
                    query.dt,
                    &self.free,
                )
            })
            .collect();
        let activate_blocks = blocks
            .iter()
            .filter(|s| s.error > t.modal_error && s.progress < t.progress)
            .map(|s| s.block)
            .collect();
        let mut best: Vec<Option<SubdomainScore>> = vec![None; self.num_subdomains];
        for i in (0..n).filter(|&i| self.free[i]) {
            let (error, progress) = (nodal.error[i], nodal.progress[i]);
            let l = self.vertex_subdomain[i];
            if enriched[l] || !(error > t.nodal_error && progress < t.progress) {
                continue;
            }
            if best[l].as_ref().is_none_or(|s| error > s.error) {
                best[l] = Some(SubdomainScore {
                    subdomain: l,
                    vertex: i,
                    error,
                    progress,
                });
            }
        }
        Ok(Decision {
            nodal,
            blocks,
            activate_blocks,
            enrich_subdomains: best.into_iter().flatten().collect(),
        })
    }

    fn check(&self, q: &Query<'_>) -> Result<(), OracleError> {
        let len = self.scales.num_vertices() * self.scales.dim;
        for (name, v) in [("x", q.x), ("gradient", q.gradient), ("step", q.step)] {
            if v.len() != len {
                return Err(OracleError::Input(format!(
                    "{name} has {} entries, expected {len}",
                    v.len()
                )));
            }
            if let Some(k) = v.iter().position(|c| !c.is_finite()) {
                return Err(OracleError::Input(format!("{name}[{k}] is not finite ({})", v[k])));
            }
        }
        if !(q.dt.is_finite() && q.dt > 0.0) {
            return Err(OracleError::Input(format!(
                "dt must be positive and finite, got {}",
                q.dt
            )));
        }
        // The terms' stencils are checked when their one-rings are built (once).
        for t in q.terms {
            if t.energy.dim() != self.scales.dim || !t.weight.is_finite() {
                return Err(OracleError::Input(format!(
                    "term `{}` has dim {} and weight {}, the body dim {}",
                    t.energy.name(),
                    t.energy.dim(),
                    t.weight,
                    self.scales.dim
                )));
            }
        }
        Ok(())
    }
}
