//! Which solver steps a scene (`[solver]`): the full-space Newton solver, the same
//! Newton loop with each direction from the adaptive subspace model, or Vertex Block
//! Descent.

use serde::{Deserialize, Serialize};

use super::{Energies, Scene};
use std::path::{Path, PathBuf};

use crate::adaptive::candidates::{data_modes, Body, CandidateError, CandidateSet, CandidateSpec, LinearModeSettings};
use crate::adaptive::elastic_subspace::ElasticSubspace;
use crate::adaptive::oracle::{NodeScales, Oracle};
use crate::adaptive::partition::Partition;
use crate::adaptive::{AdaptiveSettings, AdaptiveSolver, SubspaceHessian};
use crate::energy::StencilEnergy;
use crate::error::InputError;
use crate::mesh::Mesh;
use crate::solver::{Simulator, VbdUnsupported};
use crate::trajectory::Trajectory;
use crate::vbd::VbdSettings;

/// The solver of a scene (default: full space).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, Default)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum SolverSpec {
    /// Newton's method with a sparse Cholesky solve of the full system.
    #[default]
    FullSpace,
    /// The adaptive subspace model of Trusty et al. (its settings, every one optional).
    Adaptive(AdaptiveSettings),
    /// Vertex Block Descent (Chen et al. 2024; its settings, every one optional). Implicit
    /// Euler without IPC contact only.
    Vbd(VbdSettings),
}

impl SolverSpec {
    /// The solver's name in reports and manifests.
    pub fn label(&self) -> &'static str {
        match self {
            SolverSpec::FullSpace => "full-space Newton",
            SolverSpec::Adaptive(_) => "adaptive subspace",
            SolverSpec::Vbd(_) => "VBD",
        }
    }

    /// The first setting out of range, as `(field, message)`.
    pub fn invalid(&self) -> Option<(String, String)> {
        match self {
            SolverSpec::FullSpace => None,
            SolverSpec::Adaptive(s) => s.invalid().map(|(f, m)| (format!("solver.{f}"), m)),
            SolverSpec::Vbd(s) => s.invalid().map(|(f, m)| (format!("solver.{f}"), m)),
        }
    }
}

impl Scene {
    /// `simulator` stepping with VBD, or an error naming the field that rules it out
    /// (`solver.kind` with `[contact]`, `integrator` with another scheme).
    pub(super) fn with_vbd(&self, simulator: Simulator, settings: &VbdSettings) -> Result<Simulator, InputError> {
        simulator.with_vbd(settings.clone()).map_err(|why| {
            let field = match why {
                VbdUnsupported::Contact => "solver.kind",
                VbdUnsupported::Scheme(_) => "integrator",
            };
            InputError::field(&self.source, field, why.to_string())
        })
    }

    /// The candidates of a scene's body: its mesh, elastic terms and lumped masses as
    /// [`Scene::build_elastic_energies`] makes them, its handles' vertices prescribed.
    pub fn candidate_set(&self, spec: &CandidateSpec) -> Result<CandidateSet, CandidateError> {
        let mesh = self.build_mesh()?;
        let Energies { masses, potentials } = self.build_elastic_energies(&mesh)?;
        let fixed: Vec<usize> = self
            .build_handles(&mesh)?
            .iter()
            .flat_map(|h| h.vertices.iter().copied())
            .collect();
        let body = Body {
            dim: mesh.dim,
            rest: &mesh.rest,
            masses: &masses,
            fixed_vertices: &fixed,
        };
        let elastic: Vec<&dyn StencilEnergy> = potentials.iter().map(|p| p.as_ref()).collect();
        CandidateSet::new(&body, &elastic, spec)
    }

    /// Every frame of the `train-*.npz` trajectories in `settings.data_modes_from` (relative
    /// to the scene file), each checked against `mesh`.
    fn data_mode_frames(&self, settings: &AdaptiveSettings, mesh: &Mesh) -> Result<Vec<Vec<f64>>, InputError> {
        let Some(dir) = &settings.data_modes_from else {
            return Ok(Vec::new());
        };
        let dir = self.source.parent().unwrap_or(Path::new(".")).join(dir);
        let field = |message: String| InputError::field(&self.source, "solver.data_modes_from", message);
        let entries = std::fs::read_dir(&dir).map_err(|e| field(format!("{}: {e}", dir.display())))?;
        let mut paths: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
                name.starts_with("train-") && name.ends_with(".npz")
            })
            .collect();
        paths.sort();
        if paths.is_empty() {
            return Err(field(format!(
                "{} holds no train-*.npz trajectory (make them with `mochi dataset`)",
                dir.display()
            )));
        }
        let mut frames = Vec::new();
        for path in paths {
            let trajectory = Trajectory::read_npz(&path)?;
            if trajectory.dim != mesh.dim || trajectory.num_vertices() != mesh.num_vertices() {
                return Err(InputError::file(
                    &path,
                    format!(
                        "holds {} vertices in {}D; the scene's mesh has {} in {}D",
                        trajectory.num_vertices(),
                        trajectory.dim,
                        mesh.num_vertices(),
                        mesh.dim
                    ),
                ));
            }
            frames.extend(trajectory.positions);
        }
        Ok(frames)
    }

    /// The adaptive model of the scene's body, with its prescribed vertices `fixed`: the
    /// candidate bases (rigid, affine and the linear modes of the rest shape), the fixed
    /// decomposition into subdomains and the oracle. The whole mesh is one body.
    pub fn build_adaptive(
        &self,
        settings: &AdaptiveSettings,
        mesh: &Mesh,
        fixed: &[usize],
    ) -> Result<AdaptiveSolver, InputError> {
        let error = |message: String| InputError::field(&self.source, "solver", message);
        let Energies { masses, potentials } = self.build_elastic_energies(mesh)?;
        let elastic: Vec<&dyn StencilEnergy> = potentials.iter().map(|p| p.as_ref()).collect();
        solid_elements_only(&elastic, mesh.dim).map_err(error)?;
        let body = Body {
            dim: mesh.dim,
            rest: &mesh.rest,
            masses: &masses,
            fixed_vertices: fixed,
        };
        let spec = CandidateSpec {
            rigid: true,
            affine: true,
            linear_modes: settings.linear_modes,
            settings: LinearModeSettings::default(),
        };
        let mut candidates =
            CandidateSet::new(&body, &elastic, &spec).map_err(|e| error(format!("candidate modes: {e}")))?;
        if settings.data_modes > 0 {
            let frames = self.data_mode_frames(settings, mesh)?;
            let frames: Vec<&[f64]> = frames.iter().map(Vec::as_slice).collect();
            let modes =
                data_modes(&body, &frames, settings.data_modes).map_err(|e| error(format!("data modes: {e}")))?;
            candidates = candidates
                .with_data_modes(modes)
                .map_err(|e| error(format!("data modes: {e}")))?;
        }
        let n = mesh.num_vertices();
        let parts = n.div_ceil(settings.subdomain_vertices).max(1);
        let partition = Partition::new(mesh, parts).map_err(|e| error(format!("subdomains: {e}")))?;
        let scales = NodeScales::new(mesh.dim, &mesh.rest, &elastic).map_err(|e| error(format!("oracle: {e}")))?;
        let oracle = Oracle::new(scales, fixed, partition.vertex_subdomains(), settings.thresholds())
            .map_err(|e| error(format!("oracle: {e}")))?;
        let subdomains = (0..partition.num_subdomains())
            .map(|l| partition.vertices(l).to_vec())
            .collect();
        let solver = AdaptiveSolver::new(
            settings.clone(),
            candidates,
            oracle,
            subdomains,
            fixed,
            mesh.rest_diagonal(),
        );
        Ok(match settings.subspace_hessian {
            SubspaceHessian::Exact => solver,
            SubspaceHessian::Bfgs => {
                // The simulator's first potentials are these elastic terms, stencil for
                // stencil (`Scene::build_energies` starts from them).
                let stencils = elastic
                    .iter()
                    .map(|e| (0..e.len()).map(|s| e.stencil(s).to_vec()).collect())
                    .collect();
                let subspace = ElasticSubspace::new(
                    mesh.dim,
                    stencils,
                    partition.vertex_subdomains(),
                    partition.num_subdomains(),
                );
                solver.with_elastic_subspace(subspace)
            }
        })
    }
}

/// Why the adaptive solver cannot take the body of `elastic` (`dim`-simplices only, the
/// elements its oracle scales node errors by and its linear modes are built on: a solid, not
/// cloth's membrane and bending stencils or a rod's).
fn solid_elements_only(elastic: &[&dyn StencilEnergy], dim: usize) -> Result<(), String> {
    for term in elastic {
        if let Some(s) = (0..term.len()).find(|&s| term.stencil(s).len() != dim + 1) {
            return Err(format!(
                "the adaptive solver takes solids only ({} elements); `{}` has stencils of {} vertices (stencil {s})",
                if dim == 3 { "tetrahedral" } else { "triangle" },
                term.name(),
                term.stencil(s).len()
            ));
        }
    }
    Ok(())
}
