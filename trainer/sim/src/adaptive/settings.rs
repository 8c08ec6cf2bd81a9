//! The adaptive solver's settings, as a scene's `[solver]` table gives them
//! (`kind = "adaptive"`).

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::oracle::Thresholds;
use super::pcg::PcgSettings;

/// Settings of the adaptive subspace solver (Trusty et al.); every field has the default
/// named in its documentation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AdaptiveSettings {
    /// `ε_G` of modal candidates: a block whose error exceeds it may be activated
    /// (default 0.5, the paper's usual value; lower is more accurate and costlier).
    pub modal_error: f64,
    /// `ε_G` of nodal candidates: a vertex whose error exceeds it may enrich its subdomain
    /// (default 0.5).
    pub nodal_error: f64,
    /// `ε_E`: a candidate is activated only where the active model's progress is below it
    /// (default 1e-4).
    pub progress: f64,
    /// `ε_d` of downdating (Sec. 3.11): after a step, an active block whose displacement,
    /// or an enriched subdomain whose vertices' displacement beyond what the modes give, is
    /// below `ε_d` times the rest diagonal times `dt` is dropped (default 0.1; 0 turns
    /// downdating off).
    pub downdate: f64,
    /// Vertices per subdomain of the fixed decomposition (nodal enrichment groups), so a
    /// mesh of `n` vertices gets `ceil(n / subdomain_vertices)` subdomains (default 64).
    pub subdomain_vertices: usize,
    /// Linear modes of the rest shape among the candidates, each its own block (default 20).
    pub linear_modes: usize,
    /// Linear modes active at the start, next to the rigid and affine blocks (default 6).
    pub initial_linear_modes: usize,
    /// Data modes among the candidates, each its own block: the principal components of
    /// the displacements in the trajectories of `data_modes_from` (default 0, none).
    pub data_modes: usize,
    /// Data modes active at the start (default 0).
    pub initial_data_modes: usize,
    /// A directory of trajectories of this body (`mochi dataset` output): its `train-*.npz`
    /// give the data modes. Relative to the scene file (default none; needed when
    /// `data_modes > 0`).
    pub data_modes_from: Option<PathBuf>,
    /// Relative tolerance of the Schur complement's conjugate gradients (default 1e-5, the
    /// paper's).
    pub pcg_tolerance: f64,
    /// Whether the oracle updates the model inside each step and downdating runs after it
    /// (default true; false keeps the initial model, for checks).
    pub adapt: bool,
    /// How the elastic part of the subspace Hessian is evaluated where no vertex is
    /// enriched (default `bfgs`).
    pub subspace_hessian: SubspaceHessian,
}

/// How the elastic part of the subspace Hessian is evaluated on the subdomains without an
/// enriched vertex ([`super::elastic_subspace`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SubspaceHessian {
    /// A BFGS matrix per subdomain, exact at a step's first iterate and updated by the
    /// secant pairs of the later ones (the paper's Sec. 3.9): the simulator assembles the
    /// elastic Hessian of the exact subdomains only.
    #[default]
    Bfgs,
    /// The exact Hessian at every iterate (the whole elastic Hessian is assembled).
    Exact,
}

impl Default for AdaptiveSettings {
    fn default() -> Self {
        let t = Thresholds::default();
        AdaptiveSettings {
            modal_error: t.modal_error,
            nodal_error: t.nodal_error,
            progress: t.progress,
            downdate: 0.1,
            subdomain_vertices: 64,
            linear_modes: 20,
            initial_linear_modes: 6,
            data_modes: 0,
            initial_data_modes: 0,
            data_modes_from: None,
            pcg_tolerance: PcgSettings::default().tolerance,
            adapt: true,
            subspace_hessian: SubspaceHessian::Bfgs,
        }
    }
}

impl AdaptiveSettings {
    /// The oracle's thresholds.
    pub fn thresholds(&self) -> Thresholds {
        Thresholds {
            modal_error: self.modal_error,
            nodal_error: self.nodal_error,
            progress: self.progress,
        }
    }

    /// The first value out of range, as `(field, message)`.
    pub fn invalid(&self) -> Option<(&'static str, String)> {
        let positive = [
            ("modal_error", self.modal_error),
            ("nodal_error", self.nodal_error),
            ("progress", self.progress),
            ("pcg_tolerance", self.pcg_tolerance),
        ];
        if let Some((name, v)) = positive.iter().find(|(_, v)| !(v.is_finite() && *v > 0.0)) {
            return Some((name, format!("must be positive and finite, got {v}")));
        }
        if !(self.downdate.is_finite() && self.downdate >= 0.0) {
            return Some(("downdate", format!("must be >= 0 and finite, got {}", self.downdate)));
        }
        if self.subdomain_vertices == 0 {
            return Some(("subdomain_vertices", "must be at least 1".into()));
        }
        if self.initial_linear_modes > self.linear_modes {
            return Some((
                "initial_linear_modes",
                format!(
                    "{} is more than linear_modes = {}",
                    self.initial_linear_modes, self.linear_modes
                ),
            ));
        }
        if self.initial_data_modes > self.data_modes {
            return Some((
                "initial_data_modes",
                format!(
                    "{} is more than data_modes = {}",
                    self.initial_data_modes, self.data_modes
                ),
            ));
        }
        if self.data_modes > 0 && self.data_modes_from.is_none() {
            return Some((
                "data_modes_from",
                format!(
                    "data_modes = {} needs a directory of trajectories to take them from",
                    self.data_modes
                ),
            ));
        }
        None
    }
}
