//! Recipes: a scene file read whole. The simulator's [`Scene`] is the body, its environment,
//! boundary conditions and dataset; the `[latent]` table, which only the trainer reads, says
//! how to learn its latent space and integrator. Scene files name both in one TOML file.

use std::path::{Path, PathBuf};

use super::reduced_spec::ReducedSpec;
use mochi_sim::scene::{read_text, BuiltScene, SceneDocument};
use mochi_sim::{InputError, Scene};
use serde::{Deserialize, Serialize};

/// The penalty weight on boundary conditions in the physics loss (Eq. 4 of Li et al.).
pub const PAPER_BC_WEIGHT: f64 = 1e5;

/// Directory of the scenes shipped with mochi.
pub(crate) fn shipped_scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes")
}

/// Names of the shipped scenes, sorted.
pub fn shipped_scene_names() -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(shipped_scenes_dir())
        .map(|dir| {
            dir.filter_map(|e| e.ok())
                .filter_map(|e| {
                    let p = e.path();
                    (p.extension()? == "toml").then(|| p.file_stem()?.to_str().map(String::from))?
                })
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    names
}

/// A scene and how to learn it: the whole of a scene file.
#[derive(Clone, Debug, PartialEq)]
pub struct Recipe {
    /// The physical scene (everything but `[latent]`).
    pub scene: Scene,
    /// Latent space and integrator training (`[latent]`).
    pub latent: LatentSpec,
    /// The reduced-order solver's subspaces (`[reduced]`); `None` when the scene does not
    /// use the reduced method.
    pub reduced: Option<ReducedSpec>,
}

impl Recipe {
    /// Finds a scene by name among the shipped scenes, or by path.
    pub(crate) fn resolve(name_or_path: &str) -> Result<PathBuf, InputError> {
        let as_path = Path::new(name_or_path);
        if as_path.is_file() {
            return Ok(as_path.to_path_buf());
        }
        let shipped = shipped_scenes_dir().join(format!("{name_or_path}.toml"));
        if shipped.is_file() {
            return Ok(shipped);
        }
        Err(InputError::file(
            as_path,
            format!(
                "no such scene file, and not a shipped scene name (shipped: {})",
                shipped_scene_names().join(", ")
            ),
        ))
    }

    /// Loads a scene file by shipped name or path.
    pub fn load(name_or_path: &str) -> Result<Recipe, InputError> {
        let path = Recipe::resolve(name_or_path)?;
        let text = read_text(&path)?;
        let recipe = Recipe::parse(&text, &path)?;
        if let Some(spec) = &recipe.reduced {
            spec.validate_authored()
                .map_err(|(f, msg)| InputError::field(&path, format!("reduced.{f}"), msg))?;
        }
        Ok(recipe)
    }

    /// Parses and validates a scene file's text; `path` is used in errors and to resolve
    /// mesh files.
    pub fn parse(text: &str, path: &Path) -> Result<Recipe, InputError> {
        let mut document = SceneDocument::parse(text, path)?;
        let latent: LatentSpec = document.take_section("latent")?;
        let reduced: Option<ReducedSpec> = document.take_section("reduced")?;
        let scene = document.into_scene()?;
        latent
            .validate()
            .map_err(|(f, msg)| InputError::field(path, format!("latent.{f}"), msg))?;
        if let Some(spec) = &reduced {
            spec.validate()
                .map_err(|(f, msg)| InputError::field(path, format!("reduced.{f}"), msg))?;
        }
        Ok(Recipe { scene, latent, reduced })
    }

    /// The recipe as TOML text that [`Recipe::parse`] reads back (stored in artifacts).
    pub fn to_toml(&self) -> Result<String, toml::ser::Error> {
        #[derive(Serialize)]
        struct Whole<'a> {
            #[serde(flatten)]
            scene: &'a Scene,
            latent: &'a LatentSpec,
            #[serde(skip_serializing_if = "Option::is_none")]
            reduced: &'a Option<ReducedSpec>,
        }
        toml::to_string(&Whole {
            scene: &self.scene,
            latent: &self.latent,
            reduced: &self.reduced,
        })
    }

    /// Builds the scene's mesh, energies, handles and simulator.
    pub fn build(&self) -> Result<BuiltScene, InputError> {
        self.scene.build()
    }
}

/// Sizes and schedule of one network trained by `mochi train`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkSpec {
    /// Width of the hidden layers.
    pub hidden: usize,
    /// Residual blocks.
    pub blocks: usize,
    /// Training epochs.
    pub epochs: usize,
    /// Samples per minibatch.
    pub batch: usize,
    /// Initial learning rate.
    pub learning_rate: f64,
    /// Learning rate at the last epoch (cosine decay from `learning_rate`).
    pub final_learning_rate: f64,
}

/// How `mochi train` builds the latent space and its integrator (scene table `[latent]`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LatentSpec {
    /// Reconstruction tolerance: RMS vertex error of the autoencoder over the training frames
    /// as a fraction of the rest bounding-box diagonal. The latent size is the smallest of
    /// `sizes` that meets it.
    pub tolerance: f64,
    /// Candidate latent sizes, tried in ascending order.
    pub sizes: Vec<usize>,
    /// Autoencoder (Eq. 2).
    pub autoencoder: NetworkSpec,
    /// Latent integrator (Eq. 3), both the self-supervised one and the supervised baseline.
    pub integrator: NetworkSpec,
    /// Noise augmentation (Eq. 5): uniform noise on the input latents, as a fraction of the
    /// batch standard deviation; 0 turns augmentation off.
    pub noise: f64,
    /// Rollout augmentation: each minibatch also trains on inputs whose two latents are the
    /// integrator's own prediction, rolled out without gradient from ground truth for up to
    /// this many steps (the limit grows from 1 over training), so the integrator learns to
    /// step from the states its own errors lead to; 0 turns it off.
    pub rollout: usize,
    /// Penalty weight on the boundary conditions in the physics loss (Eq. 4).
    pub bc_weight: f64,
    /// Floor of the data-balancing speed (Eq. 6), in length units per second. Without a
    /// sensible floor, samples near rest (the first frames, every reversal of a
    /// back-and-forth motion) get weights hundreds of times larger than the rest and the
    /// integrator learns little else: on `beam`, a floor of 1e-3 m/s left the sudden-drop
    /// test diverging at frame 621, 0.05 m/s kept all four test sequences stable.
    pub min_speed: f64,
    /// Weight of a data term added to the self-supervised integrator's physics loss: the
    /// supervised baseline's objective (squared latent error against the ground truth, per
    /// coordinate in units of the increment's standard deviation) times this weight. 0 (the
    /// default) trains on the physics loss alone (Eq. 4-6). A body with no handle has
    /// neutral directions (sliding, turning on a floor) along which the physics loss near
    /// rest is nearly flat; the data term pins the increment there to the data's zero.
    pub data_weight: f64,
    /// Weight of the edge-stretch term in the autoencoder's loss ([`crate::learn::stretch`]): the
    /// mean squared change of edge lengths between decoded and true states, added to the
    /// mean squared reconstruction error (both in squared length units). 0 (the default)
    /// trains on Eq. 2 alone; positions only (not `rods = "bends"`).
    pub stretch: f64,
    /// Seed of initialisation, shuffling and noise.
    pub seed: u64,
    /// What the latent space of a rods scene encodes (`positions` or `bends`).
    pub rods: RodEncoding,
    /// Whether the integrator takes the scene's run-time colliders (`[[colliders]]`) as
    /// inputs, and the physics loss their barrier (default true; false trains a model that
    /// cannot see them, for comparison).
    pub collider_inputs: bool,
    /// Model selection over cost (`[latent.selection]`).
    pub selection: SelectionSpec,
}

/// A decoder family `mochi train` may try (scene field `latent.selection.decoders`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DecoderCandidate {
    /// The PCA basis with as many components as meet the tolerance, not trained (PCA is the
    /// least-squares optimum among linear decoders): `linear`.
    Linear,
    /// A residual MLP of this width (one block) from a smaller latent to the coefficients of
    /// that basis, trained from the PCA initialisation: `{ basis = 32 }`.
    Basis(usize),
    /// The residual MLP of `latent.autoencoder`: `mlp`.
    Mlp,
}

/// Which models `mochi train` trains and how it keeps one (`[latent.selection]`).
///
/// Decoders are tried in the order given; those whose reconstruction meets the tolerance get
/// a self-supervised integrator of each width. Every candidate is rolled out over the
/// validation sequences; among those stable over every validation frame, the cheapest
/// (multiply-adds per frame, then bytes) whose mean error is within `slack` of the best
/// candidate's is kept.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SelectionSpec {
    /// Decoder families, cheapest first. Default: `linear`, `{ basis = 32 }`, `mlp`.
    pub decoders: Vec<DecoderCandidate>,
    /// Integrator widths (blocks, epochs and schedule from `latent.integrator`). Default: the
    /// width of `latent.integrator` alone.
    pub integrator_widths: Vec<usize>,
    /// How far above the best candidate's mean validation error the kept one may be, relative
    /// (default 0.1).
    pub slack: f64,
    /// Decoders distilled from every `mlp` candidate (`[latent.selection.distill]`): each a
    /// candidate of its own, with that candidate's integrator.
    pub distill: DistillCandidates,
}

/// The distilled decoders `mochi train` adds to the selection (`[latent.selection.distill]`):
/// for every candidate with an `mlp` decoder (every candidate with `strand_positions`) and
/// every number of modes listed, a basis decoder fitted to that decoder on the latents its
/// integrator visits over the training motions (`mochi distill`, docs/design.md decision 6).
/// The integrator is the candidate's own.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DistillCandidates {
    /// Columns of each basis (default `[8, 24]`; empty: none distilled). Counts below the
    /// latent size or above the encoded length are skipped.
    pub modes: Vec<usize>,
    /// Width of the MLP before the basis (default 32, one residual block).
    pub hidden: usize,
    /// Training epochs of each fit (default 300).
    pub epochs: usize,
    /// Fit the decoders to rod strands as positions where the scene encodes them by their
    /// bends, so the decode skips the strand walk; every candidate, of any decoder family,
    /// is then distilled (default false).
    pub strand_positions: bool,
}

impl Default for DistillCandidates {
    fn default() -> Self {
        DistillCandidates {
            modes: vec![8, 24],
            hidden: 32,
            epochs: 300,
            strand_positions: false,
        }
    }
}

impl Default for SelectionSpec {
    fn default() -> Self {
        SelectionSpec {
            decoders: vec![
                DecoderCandidate::Linear,
                DecoderCandidate::Basis(32),
                DecoderCandidate::Mlp,
            ],
            integrator_widths: Vec::new(),
            slack: 0.1,
            distill: DistillCandidates::default(),
        }
    }
}

impl SelectionSpec {
    /// The integrator widths to try, `default` when none are listed.
    pub fn widths(&self, default: usize) -> Vec<usize> {
        if self.integrator_widths.is_empty() {
            vec![default]
        } else {
            self.integrator_widths.clone()
        }
    }
}

/// How rod strands are encoded for the latent space (scene field `latent.rods`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RodEncoding {
    /// Vertex positions relative to the strand's root (Li et al. 2025, Sec. 3.2).
    #[default]
    Positions,
    /// The bend of every edge, decoded at rest length ([`crate::learn::encoding::Encoding::with_strand_bends`]):
    /// no latent state can stretch a rod.
    Bends,
}

impl Default for LatentSpec {
    fn default() -> Self {
        LatentSpec {
            tolerance: 2e-3,
            sizes: vec![2, 4, 6, 8, 12, 16],
            autoencoder: NetworkSpec {
                hidden: 128,
                blocks: 2,
                epochs: 300,
                batch: 32,
                learning_rate: 3e-4,
                final_learning_rate: 1e-5,
            },
            integrator: NetworkSpec {
                hidden: 128,
                blocks: 2,
                epochs: 200,
                batch: 32,
                learning_rate: 1e-3,
                final_learning_rate: 1e-5,
            },
            noise: 0.1,
            rollout: 0,
            bc_weight: PAPER_BC_WEIGHT,
            min_speed: 0.05,
            data_weight: 0.0,
            stretch: 0.0,
            seed: 0,
            rods: RodEncoding::Positions,
            collider_inputs: true,
            selection: SelectionSpec::default(),
        }
    }
}

impl LatentSpec {
    /// The collider slots a model of `scene` reads: its colliders, or none when
    /// `collider_inputs` is off.
    pub fn collider_slots(&self, scene: &mochi_sim::scene::Scene) -> usize {
        if self.collider_inputs {
            scene.colliders.len()
        } else {
            0
        }
    }

    /// Checks ranges; returns the offending field (relative to `latent`) and a message.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.tolerance) {
            return Err(("tolerance".into(), format!("must be positive, got {}", self.tolerance)));
        }
        if self.sizes.is_empty() || self.sizes.contains(&0) || !self.sizes.is_sorted() {
            return Err(("sizes".into(), "needs positive sizes in ascending order".into()));
        }
        let largest = *self.sizes.last().unwrap_or(&0);
        for (name, net) in [("autoencoder", &self.autoencoder), ("integrator", &self.integrator)] {
            if net.hidden == 0 || net.epochs == 0 || net.batch == 0 {
                return Err((name.into(), "hidden, epochs and batch must be at least 1".into()));
            }
            if !positive(net.learning_rate) || !positive(net.final_learning_rate) {
                return Err((name.into(), "learning rates must be positive".into()));
            }
        }
        if self.autoencoder.hidden < 2 * largest {
            return Err((
                "autoencoder.hidden".into(),
                format!(
                    "PCA initialisation needs at least twice the largest size ({})",
                    2 * largest
                ),
            ));
        }
        if !(self.noise.is_finite() && self.noise >= 0.0) {
            return Err(("noise".into(), "must be a non-negative number".into()));
        }
        if !positive(self.bc_weight) || !positive(self.min_speed) {
            return Err(("bc_weight".into(), "bc_weight and min_speed must be positive".into()));
        }
        if !(self.stretch.is_finite() && self.stretch >= 0.0) {
            return Err(("stretch".into(), "must be a non-negative number".into()));
        }
        if !(self.data_weight.is_finite() && self.data_weight >= 0.0) {
            return Err(("data_weight".into(), "must be a non-negative number".into()));
        }
        let selection = &self.selection;
        if selection.decoders.is_empty() || selection.decoders.contains(&DecoderCandidate::Basis(0)) {
            return Err((
                "selection.decoders".into(),
                "needs at least one decoder family, and basis widths of at least 1".into(),
            ));
        }
        if selection.integrator_widths.contains(&0) || !(selection.slack.is_finite() && selection.slack >= 0.0) {
            return Err((
                "selection".into(),
                "integrator widths must be positive and slack a non-negative number".into(),
            ));
        }
        let distill = &selection.distill;
        if distill.modes.contains(&0) || distill.hidden == 0 || distill.epochs == 0 {
            return Err((
                "selection.distill".into(),
                "modes, hidden and epochs must be positive".into(),
            ));
        }
        if self.stretch > 0.0 && self.rods == RodEncoding::Bends {
            return Err((
                "stretch".into(),
                "needs encoded positions; rods encoded by bends cannot stretch".into(),
            ));
        }
        Ok(())
    }
}
