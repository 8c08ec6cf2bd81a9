//! Which methods `mochi compare` runs, at which budgets, on a scene: the simulator's solvers
//! (full space, a coarse mesh, the adaptive solver, VBD), the reduced solver in each subspace
//! of the scene's `.reduced` file, the learned integrator in the runtime in each weight
//! storage (and its supervised twin), and the peers' recordings. What a method cannot take
//! (a learned model at another time step or stiffness, VBD with contact) comes back as a
//! reason instead of a method.

use std::path::{Path, PathBuf};

use mochi_runtime::ValidModel;
use mochi_sim::energy::StencilEnergy;
use mochi_sim::scene::ObstacleMesh;
use mochi_sim::{AdaptiveSettings, BuiltScene, Scene, SolverSpec, TimeScheme, VbdSettings};

use super::conditions::RunTimeChange;
use crate::artifact::Artifact;
use crate::error::{fs, TrainerError, TrainerResult};
use crate::learn::encoding::Encoding;
use crate::learn::network::ExportedMlp;
use crate::learn::pca::Pca;
use crate::learn::recipe::{Recipe, RodEncoding};
use crate::methods::learned::LearnedRuntime;
use crate::methods::method::Method;
use crate::methods::peer::PeerRecording;
use crate::methods::reduced::method::ReducedMethod;
use crate::methods::reduced::stepper::StepperSettings;
use crate::methods::reduced::subspace::SubspaceDecoder;
use crate::methods::simulated::Simulated;

/// The family the selection's other candidates chart as (each a budget: model size and shape).
pub const CANDIDATES_FAMILY: &str = "learned (runtime), other candidates";

/// The learned models of `model`: the model (`SCENE.mochi`, "learned (runtime)"), its
/// supervised twin beside it (`SCENE.supervised.mochi`) and the selection's other candidates
/// (`candidates/*.mochi` beside it, as `mochi train` writes them, but for the kept model's own
/// networks; [`CANDIDATES_FAMILY`]), each with its family, bytes and path.
pub fn model_files(model: &Path) -> TrainerResult<Vec<(&'static str, Vec<u8>, PathBuf)>> {
    let kept = fs::read(model)?;
    let mut files = Vec::new();
    let name = model.file_name().and_then(|n| n.to_str()).unwrap_or("");
    if let Some(stem) = name.strip_suffix(".mochi") {
        let twin = model.with_file_name(format!("{stem}.supervised.mochi"));
        if twin.is_file() {
            files.push(("supervised (runtime)", fs::read(&twin)?, twin));
        }
    }
    let dir = model.with_file_name("candidates");
    let mut candidates = Vec::new();
    if let Ok(read) = std::fs::read_dir(&dir) {
        for entry in read {
            let path = entry.map_err(|e| TrainerError::io(&dir, e))?.path();
            if path.extension().is_some_and(|e| e == "mochi") {
                candidates.push(path);
            }
        }
    }
    candidates.sort();
    let networks = |bytes: &[u8], path: &Path| -> TrainerResult<_> {
        let a = Artifact::from_bytes(bytes, path)?;
        Ok((a.latent, a.decoder, a.decoder_basis, a.pca_basis, a.integrator))
    };
    let kept_networks = networks(&kept, model)?;
    for path in candidates {
        let bytes = fs::read(&path)?;
        // The kept model is also among the candidates, with another summary.
        if networks(&bytes, &path)? != kept_networks {
            files.push((CANDIDATES_FAMILY, bytes, path));
        }
    }
    files.insert(0, ("learned (runtime)", kept, model.to_path_buf()));
    Ok(files)
}

/// A learned model in one storage, ready for the runtime.
pub struct LearnedModel<'m> {
    /// "learned (runtime)", "supervised (runtime)" or [`CANDIDATES_FAMILY`].
    pub family: &'static str,
    /// Latent size and storage ("k=8, int8"), and the candidate's name for the selection's
    /// other candidates.
    pub setting: String,
    /// The validated model.
    pub model: ValidModel<'m>,
}

/// A reduced subspace's decoder, owned.
pub enum SubspaceMap {
    /// A trained decoder (vanilla, Lipschitz-optimised).
    Network(Box<ExportedMlp>),
    /// A PCA.
    Linear(Pca),
}

impl SubspaceMap {
    /// The decoder as the reduced solver takes it.
    pub fn decoder(&self) -> SubspaceDecoder<'_> {
        match self {
            SubspaceMap::Network(mlp) => mlp.as_ref().into(),
            SubspaceMap::Linear(pca) => pca.into(),
        }
    }
}

/// A reduced subspace and the energies it steps with.
pub struct ReducedSubspace<'a> {
    /// "PCA", "vanilla", "Lipschitz", with ", runtime cubature" where the elastic terms are.
    pub name: String,
    /// Its decoder.
    pub decoder: SubspaceMap,
    /// The latent of the scene's start.
    pub initial_latent: Vec<f64>,
    /// The energies it steps with: `None` for the condition's exact energies, `Some` for a
    /// fixed set (runtime cubature, fitted to the scene as trained).
    pub energies: Option<Vec<&'a dyn StencilEnergy>>,
}

/// Everything trained for the scene that the lineup can run.
pub struct Trained<'a> {
    /// The learned models, each storage.
    pub learned: Vec<LearnedModel<'a>>,
    /// The reduced subspaces.
    pub reduced: Vec<ReducedSubspace<'a>>,
    /// The positions encoding of the reduced subspaces.
    pub encoding: Option<Encoding>,
    /// The reduced solver's settings (the scene's `[reduced]` table).
    pub reduced_settings: StepperSettings,
    /// The paper's solver at the same tolerance (cold L-BFGS, Armijo backtracking, emulated
    /// single precision), run beside it on the exact energies.
    pub paper_settings: Option<StepperSettings>,
    /// Directory of peers' recordings (`DIR/CASE/*.npz`).
    pub peers: Option<PathBuf>,
    /// Why there is no learned model, when there is none ([`absent_learned`]).
    pub learned_absent: Option<String>,
    /// Why there are no reduced subspaces, when there are none ([`absent_reduced`]).
    pub reduced_absent: Option<String>,
    /// Why there are no peers' recordings, when there are none ([`absent_peers`]).
    pub peers_absent: Option<String>,
}

/// Why XPBD cannot be compared on `recipe`'s scene when no recordings are given.
pub fn absent_peers(recipe: &Recipe) -> String {
    if recipe.scene.integrator == TimeScheme::QuasiStatic {
        "steps dynamics only; the scene is quasi-static".into()
    } else {
        "no recordings given (`--peers`; `scripts/compare.sh` runs pypbd)".into()
    }
}

/// Why the learned runtime cannot be compared on `recipe`'s scene when no model is given.
pub fn absent_learned(recipe: &Recipe) -> String {
    if moving_obstacles(recipe) {
        "takes no scripted obstacle: the scene's obstacle moves on its own keyframes, the same in every \
         sequence (a run-time collider, `[[colliders]]`, is an input of a learned model)"
            .into()
    } else {
        "no model given (`--model`; `mochi train SCENE` makes one)".into()
    }
}

/// Why the reduced solver cannot be compared on `recipe`'s scene when no subspaces are given.
pub fn absent_reduced(recipe: &Recipe) -> String {
    if recipe.scene.contact.is_some() {
        "no contact barrier among the energies it reduces (the scene has IPC contact)".into()
    } else if recipe.latent.rods == RodEncoding::Bends {
        "the scene's subspace encodes strands by their bends (`latent.rods`); the reduced solver steps positions".into()
    } else if recipe.reduced.is_none() {
        "the scene has no `[reduced]` table (`mochi train` trains the subspaces of scenes with one)".into()
    } else {
        "no subspaces given (`--reduced`; `mochi train SCENE` writes `SCENE.reduced`)".into()
    }
}

fn moving_obstacles(recipe: &Recipe) -> bool {
    recipe.scene.contact.as_ref().is_some_and(|c| {
        c.obstacles.iter().any(|o| match o {
            ObstacleMesh::Box { keyframes, .. } | ObstacleMesh::File { keyframes, .. } => !keyframes.is_empty(),
        })
    })
}

/// A method, or why the family cannot take the condition.
pub enum Entry<'a> {
    /// Runs.
    Runs(Box<dyn Method + 'a>),
    /// Cannot, with the reason ("needs retraining", ...).
    Cannot {
        /// The family.
        family: String,
        /// Why.
        reason: String,
    },
}

/// The budgets of the chart, or one representative setting per family (the matrix).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Budgets {
    /// Several per family.
    Sweep,
    /// One per family.
    One,
}

/// The simulator's solvers on `scene` (whose reference run is `reference`): full space (one
/// step per frame and, in a sweep, two), the coarse mesh, the adaptive solver and VBD.
pub fn simulated<'a>(scene: &Scene, reference: &BuiltScene, budgets: Budgets) -> Vec<Entry<'a>> {
    let mut out = Vec::new();
    let mut full = scene.clone();
    full.solver = SolverSpec::FullSpace;
    let substeps: &[usize] = match budgets {
        Budgets::Sweep => &[1, 2],
        Budgets::One => &[1],
    };
    for &k in substeps {
        out.push(entry(
            "full space",
            Simulated::new(&full, k, format!("{k} step(s) per frame")),
        ));
    }
    out.push(entry("coarse mesh", Simulated::coarse(&full, reference)));
    // The error thresholds: the solver's default, and two where it enriches (the scene's own
    // when its solver is adaptive).
    let adaptive = match &scene.solver {
        SolverSpec::Adaptive(s) => vec![s.clone()],
        _ => match budgets {
            Budgets::Sweep => [AdaptiveSettings::default().modal_error, 1e-3, 1e-4]
                .map(|e| AdaptiveSettings {
                    modal_error: e,
                    nodal_error: e,
                    ..AdaptiveSettings::default()
                })
                .to_vec(),
            Budgets::One => vec![AdaptiveSettings {
                modal_error: 1e-3,
                nodal_error: 1e-3,
                ..AdaptiveSettings::default()
            }],
        },
    };
    for settings in adaptive {
        let mut s = scene.clone();
        let setting = format!("error thresholds {} / {}", settings.modal_error, settings.nodal_error);
        s.solver = SolverSpec::Adaptive(settings);
        out.push(entry("adaptive", Simulated::new(&s, 1, setting)));
    }
    // VBD as games run it: a few iterations in several substeps, with and without the
    // Chebyshev acceleration, or many iterations in one step.
    let vbd: &[(usize, usize, Option<f64>)] = match budgets {
        Budgets::Sweep => &[
            (1, 5, None),
            (1, 20, None),
            (1, 20, Some(0.0)),
            (4, 5, None),
            (4, 10, Some(0.0)),
            (8, 5, None),
        ],
        Budgets::One => &[(4, 5, None)],
    };
    for &(substeps, iterations, rho) in vbd {
        let mut s = scene.clone();
        let defaults = VbdSettings::default();
        let settings = VbdSettings {
            iterations,
            rho: rho.unwrap_or(defaults.rho),
            ..defaults
        };
        let setting = format!(
            "{substeps} x {iterations} iterations{}",
            if settings.rho == 0.0 { ", no acceleration" } else { "" }
        );
        s.solver = SolverSpec::Vbd(settings);
        out.push(entry("VBD", Simulated::new(&s, substeps, setting)));
    }
    out
}

/// A method, or why it cannot run: the scene's refusal without the file and field it names
/// and the advice after it ("the vbd solver does not handle IPC contact").
fn entry<'a>(family: &str, method: TrainerResult<Simulated>) -> Entry<'a> {
    match method {
        Ok(m) => Entry::Runs(Box::new(m)),
        Err(e) => {
            let text = e.to_string();
            let reason = text.rsplit("`: ").next().unwrap_or(&text);
            Entry::Cannot {
                family: family.into(),
                reason: reason.split(';').next().unwrap_or(reason).trim().into(),
            }
        }
    }
}

/// The reduced subspaces on `problem` (the condition's scene) at its time step: each with
/// the scene's solver and, for the exact energies, with the paper's.
pub fn reduced<'a>(trained: &'a Trained<'a>, problem: &'a BuiltScene, change: RunTimeChange) -> Vec<Entry<'a>> {
    let Some(encoding) = &trained.encoding else {
        return absent("reduced", &trained.reduced_absent);
    };
    let mut out = Vec::new();
    for s in &trained.reduced {
        let family = format!("reduced, {}", s.name);
        if s.energies.is_some() && matches!(change, RunTimeChange::Stiffness(_)) {
            out.push(Entry::Cannot {
                family: format!("{family} r={}", s.initial_latent.len()),
                reason: "needs refitting (cubature of the trained material)".into(),
            });
            continue;
        }
        let energies = s
            .energies
            .clone()
            .unwrap_or_else(|| problem.simulator.potentials().iter().map(|p| p.as_ref()).collect());
        let paper = trained.paper_settings.as_ref().filter(|_| s.energies.is_none());
        let solvers = std::iter::once((family.clone(), &trained.reduced_settings))
            .chain(paper.map(|p| (format!("{family}, paper's solver"), p)));
        for (family, settings) in solvers {
            out.push(Entry::Runs(Box::new(ReducedMethod::new(
                family,
                format!("r={}", s.initial_latent.len()),
                problem,
                s.decoder.decoder(),
                &s.initial_latent,
                encoding,
                energies.clone(),
                settings.clone(),
                problem.scene.dt,
            ))));
        }
    }
    out
}

/// The learned models in the runtime, unless the condition changes what they were trained
/// for.
pub fn learned<'a>(trained: &'a Trained<'a>, change: RunTimeChange, budgets: Budgets) -> Vec<Entry<'a>> {
    if trained.learned.is_empty() {
        return absent("learned (runtime)", &trained.learned_absent);
    }
    let models: Vec<&LearnedModel> = match budgets {
        Budgets::Sweep => trained.learned.iter().collect(),
        // The f32 and the int8 storage of the kept model.
        Budgets::One => trained
            .learned
            .iter()
            .filter(|m| m.family == "learned (runtime)" && !m.setting.ends_with("f16"))
            .collect(),
    };
    models
        .into_iter()
        .map(|m| match change {
            RunTimeChange::None => runtime_entry(m, m.model.model().dt as f64),
            // A model that takes the frame time steps at the condition's.
            RunTimeChange::TimeStep(factor) if m.model.model().timed() => {
                runtime_entry(m, factor * m.model.model().dt as f64)
            }
            RunTimeChange::TimeStep(_) => Entry::Cannot {
                family: format!("{} {}", m.family, m.setting),
                reason: "needs retraining (trained at one time step)".into(),
            },
            RunTimeChange::Stiffness(_) => Entry::Cannot {
                family: format!("{} {}", m.family, m.setting),
                reason: "needs retraining (trained on one material)".into(),
            },
        })
        .collect()
}

/// `m` in the runtime, stepping frames of `dt` seconds.
fn runtime_entry<'a>(m: &'a LearnedModel, dt: f64) -> Entry<'a> {
    match LearnedRuntime::new(&m.model, m.family, m.setting.clone()) {
        Ok(r) => Entry::Runs(Box::new(r.at_frame_time(dt))),
        Err(e) => Entry::Cannot {
            family: m.family.into(),
            reason: e.to_string(),
        },
    }
}

/// The peers' recordings of case `case` (`DIR/CASE/*.npz`), in file-name order.
pub fn peers<'a>(trained: &Trained, case: &str, vertices: usize, dim: usize) -> Vec<Entry<'a>> {
    let Some(dir) = &trained.peers else {
        return absent("XPBD (pypbd)", &trained.peers_absent);
    };
    let dir = dir.join(case);
    let Ok(read) = std::fs::read_dir(&dir) else {
        return vec![Entry::Cannot {
            family: "XPBD (pypbd)".into(),
            reason: format!("no recordings in {}", dir.display()),
        }];
    };
    let mut files: Vec<PathBuf> = read
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "npz"))
        .collect();
    files.sort();
    files
        .iter()
        .map(|p| match PeerRecording::read(p, "XPBD (pypbd)", vertices, dim) {
            Ok(r) => Entry::Runs(Box::new(r)),
            Err(e) => Entry::Cannot {
                family: "XPBD (pypbd)".into(),
                reason: format!("{}: {e}", display(p)),
            },
        })
        .collect()
}

/// A family that is not there, and why (nothing when no reason is given).
fn absent<'a>(family: &str, reason: &Option<String>) -> Vec<Entry<'a>> {
    reason
        .iter()
        .map(|r| Entry::Cannot {
            family: family.into(),
            reason: r.clone(),
        })
        .collect()
}

fn display(p: &Path) -> String {
    p.display().to_string()
}
