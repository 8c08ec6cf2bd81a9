//! How `mochi train` builds the subspaces of the reduced-order solver (scene table
//! `[reduced]`; Lyu et al. 2024): which subspace, how it is Lipschitz-optimised, and how the
//! solver steps in it. A scene without the table does not use the reduced method.

use crate::learn::network::Activation;
use serde::{Deserialize, Serialize};

/// Where the vanilla subspace comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum SubspaceSource {
    /// The autoencoder `mochi train` fits to the dataset (Eq. 3, Fulton et al. 2019).
    #[default]
    Supervised,
    /// Trained on the scene's potential alone, without data (Eq. 4, Sharp et al. 2023).
    DataFree,
}

/// Which network of a supervised scene is the vanilla subspace.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum VanillaNetwork {
    /// The autoencoder `mochi train` keeps for the latent model: a residual MLP initialised
    /// as the PCA of the data.
    #[default]
    Autoencoder,
    /// An autoencoder of its own, as the paper's baseline: an encoder and a decoder that are
    /// MLPs of the `plain_*` network fields (by default one hidden layer,
    /// `W_o swish(W_i x + b_i) + b_o`), randomly initialised and trained on the reconstruction
    /// loss (Eq. 3) alone for `plain_epochs` epochs. On a data-free subspace: its decoder is
    /// an MLP of those network fields (`plain_hidden`, `plain_blocks`, `plain_activation`,
    /// `plain_residual`) instead of the data-free default (128 wide, 2 residual Swish blocks).
    PlainMlp,
}

/// The learning-rate schedule of `vanilla = "plain-mlp"`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum PlainSchedule {
    /// Cosine decay from `plain_learning_rate` to `plain_final_learning_rate`, minibatches
    /// of the autoencoder's batch size.
    #[default]
    Cosine,
    /// The paper's configs: minibatches of 256 frames, a linear warm-up over the first 2,000
    /// iterations to `plain_learning_rate`, then a factor 0.8 every 30,000 iterations.
    Paper,
}

/// Which elastic energy the Lipschitz loss (Eq. 9) differentiates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum LipschitzEnergy {
    /// The cubature fitted on the vanilla subspace (at most `cubature` elements; the
    /// paper's, Sec. 4.3).
    #[default]
    Cubature,
    /// Every element of the scene's elastic terms: no approximation, about `elements / S`
    /// times the cost of a cubature step of the loss.
    Exact,
    /// Supervised only: every minibatch a fresh uniform draw of `cubature` elements of each
    /// elastic term, weighted so that the Hessian is an unbiased estimate of the exact one
    /// (the cost of a cubature step; the decoder cannot hide curvature in elements a fixed
    /// cubature leaves out).
    Sampled,
}

/// The optimiser of each reduced step.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum SolverChoice {
    /// L-BFGS with line search (the paper's choice).
    #[default]
    Lbfgs,
    /// Newton on the PSD-projected reduced Hessian.
    Newton,
    /// L-BFGS as the paper's code runs it, for measuring in the paper's regime: cold every
    /// step, Armijo-only backtracking by 0.8 (128 trials), 10 pairs, `tolerance` on the
    /// unscaled objective and an absolute `ftol` of 2.2e-9 (`methods::reduced::paper`).
    LbfgsPaper,
}

/// The arithmetic of each reduced step.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum SolverPrecision {
    /// Double precision (the product's).
    #[default]
    Double,
    /// Single precision, emulated by rounding at each stage (`methods::reduced::rounding`):
    /// the paper's code runs in `f32`.
    Single,
}

/// The `[reduced]` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ReducedSpec {
    /// Where the vanilla subspace comes from (default `"supervised"`).
    pub subspace: SubspaceSource,
    /// Which network is the vanilla subspace of a supervised scene (default
    /// `"autoencoder"`; `"plain-mlp"` trains the paper's baseline, with the `plain_*` fields).
    pub vanilla: VanillaNetwork,
    /// Hidden width of the plain MLPs of `vanilla = "plain-mlp"` (default 128).
    pub plain_hidden: usize,
    /// Blocks of those MLPs (default 0: one hidden layer; 1 gives two hidden layers of
    /// `plain_hidden`, the paper's depth).
    pub plain_blocks: usize,
    /// Activation of those MLPs (default `"swish"`; `"elu"`, the paper code's).
    pub plain_activation: Activation,
    /// Their blocks are residual (default true); `false`: plain hidden layers
    /// `h = W a(h)`, as the paper code's MLPs.
    pub plain_residual: bool,
    /// Supervised: when set, the plain autoencoder works between the fixed maps of a PCA of
    /// the training frames (the encoder reads `B^T (q - mean)`, the decoder writes
    /// `mean + B y`, as the paper code's with a PCA basis), with the fewest components whose
    /// RMS vertex error / diagonal is at most this (default none: no PCA).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plain_pca: Option<f64>,
    /// Learning-rate schedule of `vanilla = "plain-mlp"` (default `"cosine"`; `"paper"`).
    pub plain_schedule: PlainSchedule,
    /// Training epochs of `vanilla = "plain-mlp"` (default 2000).
    pub plain_epochs: usize,
    /// Initial learning rate of `vanilla = "plain-mlp"` (default 1e-3; cosine decay to
    /// `plain_final_learning_rate`, which is also the Lipschitz optimisation's rate).
    pub plain_learning_rate: f64,
    /// Learning rate at the last epoch of `vanilla = "plain-mlp"` (default 1e-5).
    pub plain_final_learning_rate: f64,
    /// Latent size of a data-free subspace (default 8, the paper's); a supervised one uses
    /// the autoencoder's.
    pub latent: usize,
    /// Data-free training iterations of the vanilla subspace (default 4000).
    pub data_free_iterations: usize,
    /// Seed of a data-free subspace: its decoder's initialisation, its latent samples and
    /// those of its cubature and Lipschitz optimisation (default 0). A supervised subspace
    /// starts from the autoencoder, whose seed is `[latent] seed`; a scene file that sets
    /// this on one is refused ([`ReducedSpec::validate_authored`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// Weight of the Lipschitz term relative to the construction loss at the vanilla start
    /// (default 1; see `methods::lipschitz::train`).
    pub lipschitz: f64,
    /// Epochs (supervised) or iterations (data-free) of the Lipschitz optimisation (default
    /// 200).
    pub lipschitz_epochs: usize,
    /// Learning rate of the Lipschitz optimisation (default: supervised, the vanilla
    /// network's final learning rate, at least 1e-5; data-free, the data-free training's
    /// constant 1e-3).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lipschitz_learning_rate: Option<f64>,
    /// Times a supervised Lipschitz optimisation refits its cubature on the current
    /// decoder (default 0: the cubature fitted on the vanilla subspace throughout). With
    /// `n` refits the epochs run in `n + 1` rounds, each with a cubature fitted on the
    /// decoder it starts from and its own AdamW state, all at the first round's `lambda`.
    pub cubature_refits: usize,
    /// Supervised only: when positive, half of each minibatch's Lipschitz samples are the
    /// other half's latents moved by this fraction of their spread, so Eq. 9 also sees
    /// nearby pairs (default 0: every sample an encoded frame, the paper's).
    pub lipschitz_local: f64,
    /// The elastic energy whose subspace Hessian the Lipschitz loss regularises (default
    /// `"cubature"`, the paper's; `"exact"` takes every element, `"sampled"` a fresh draw of
    /// `cubature` elements per minibatch).
    pub lipschitz_energy: LipschitzEnergy,
    /// Latent samples of the Lipschitz loss per step (default 8).
    pub samples: usize,
    /// Largest cubature of the elastic energy used for the Lipschitz loss (default 300, the
    /// paper's `S`).
    pub cubature: usize,
    /// The step optimiser (default `"lbfgs"`; `"newton"`, or `"lbfgs-paper"`, the paper's
    /// solver, which ignores `warm_start` and `memory`).
    pub solver: SolverChoice,
    /// The arithmetic of each step (default `"double"`; `"single"` is emulated).
    pub precision: SolverPrecision,
    /// Gradient tolerance of each step, on the scaled objective (default 1e-5, the paper's;
    /// with `solver = "lbfgs-paper"` on the paper code's unscaled objective).
    pub tolerance: f64,
    /// Iteration cap of each step (default 1024, the paper's).
    pub max_iterations: usize,
    /// L-BFGS starts each step from the curvature pairs of the previous step instead of
    /// steepest descent (default true).
    pub warm_start: bool,
    /// Curvature pairs L-BFGS keeps (default 8; 0 is steepest descent).
    pub memory: usize,
}

impl Default for ReducedSpec {
    fn default() -> Self {
        ReducedSpec {
            subspace: SubspaceSource::Supervised,
            vanilla: VanillaNetwork::Autoencoder,
            plain_hidden: 128,
            plain_blocks: 0,
            plain_activation: Activation::Swish,
            plain_residual: true,
            plain_pca: None,
            plain_schedule: PlainSchedule::Cosine,
            plain_epochs: 2000,
            plain_learning_rate: 1e-3,
            plain_final_learning_rate: 1e-5,
            latent: 8,
            data_free_iterations: 4000,
            seed: None,
            lipschitz: 1.0,
            lipschitz_epochs: 200,
            lipschitz_learning_rate: None,
            cubature_refits: 0,
            lipschitz_local: 0.0,
            lipschitz_energy: LipschitzEnergy::Cubature,
            samples: 8,
            cubature: 300,
            solver: SolverChoice::Lbfgs,
            precision: SolverPrecision::Double,
            tolerance: 1e-5,
            max_iterations: 1024,
            warm_start: true,
            memory: 8,
        }
    }
}

impl ReducedSpec {
    /// Checks the values; returns the offending field's name and a message.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        let positive = [
            ("latent", self.latent),
            ("data_free_iterations", self.data_free_iterations),
            ("cubature", self.cubature),
            ("max_iterations", self.max_iterations),
            ("plain_hidden", self.plain_hidden),
            ("plain_epochs", self.plain_epochs),
        ];
        for (field, value) in positive {
            if value == 0 {
                return Err((field, "must be at least 1".into()));
            }
        }
        if self.samples < 2 {
            return Err(("samples", format!("needs at least 2 samples, got {}", self.samples)));
        }
        if !(self.lipschitz.is_finite() && self.lipschitz >= 0.0) {
            return Err((
                "lipschitz",
                format!("must be finite and non-negative, got {}", self.lipschitz),
            ));
        }
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(("tolerance", format!("must be positive, got {}", self.tolerance)));
        }
        for (field, value) in [
            ("plain_learning_rate", self.plain_learning_rate),
            ("plain_final_learning_rate", self.plain_final_learning_rate),
            ("lipschitz_learning_rate", self.lipschitz_learning_rate.unwrap_or(1.0)),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err((field, format!("must be positive, got {value}")));
            }
        }
        if !(self.lipschitz_local.is_finite() && self.lipschitz_local >= 0.0) {
            return Err((
                "lipschitz_local",
                format!("must be finite and non-negative, got {}", self.lipschitz_local),
            ));
        }
        if self.cubature_refits > 0 && self.subspace != SubspaceSource::Supervised {
            return Err((
                "cubature_refits",
                "refits apply to a supervised Lipschitz optimisation: it needs subspace = \"supervised\"".into(),
            ));
        }
        if self.lipschitz_energy == LipschitzEnergy::Sampled && self.subspace != SubspaceSource::Supervised {
            return Err((
                "lipschitz_energy",
                "\"sampled\" draws elements per minibatch of a supervised optimisation: it needs subspace = \"supervised\"".into(),
            ));
        }
        if self.cubature_refits > 0 && self.lipschitz_energy != LipschitzEnergy::Cubature {
            return Err((
                "cubature_refits",
                "refits renew the cubature of the Lipschitz loss: they need lipschitz_energy = \"cubature\"".into(),
            ));
        }
        if let Some(tolerance) = self.plain_pca {
            if !(tolerance.is_finite() && tolerance > 0.0) {
                return Err((
                    "plain_pca",
                    format!("a PCA's tolerance must be positive and finite, got {tolerance}"),
                ));
            }
        }
        if self.cubature_refits >= self.lipschitz_epochs {
            return Err((
                "cubature_refits",
                format!(
                    "{} refits need at least {} Lipschitz epochs (one per round), got {}",
                    self.cubature_refits,
                    self.cubature_refits + 1,
                    self.lipschitz_epochs
                ),
            ));
        }
        Ok(())
    }

    /// The checks of a table as a person wrote it, beyond [`ReducedSpec::validate`]'s: a
    /// setting that would be ignored. Not applied to the recipes stored in artifacts, which
    /// the trainer wrote (those of some earlier builds carry `seed = 0` on every scene).
    pub fn validate_authored(&self) -> Result<(), (&'static str, String)> {
        let plain_supervised = self.vanilla == VanillaNetwork::PlainMlp && self.subspace == SubspaceSource::Supervised;
        if self.plain_pca.is_some() && !plain_supervised {
            return Err((
                "plain_pca",
                "projects the plain autoencoder of a supervised subspace: it needs vanilla = \"plain-mlp\" and subspace = \"supervised\""
                    .into(),
            ));
        }
        if self.seed.is_some() && self.subspace == SubspaceSource::Supervised {
            return Err((
                "seed",
                "seeds a data-free subspace: a supervised one starts from the autoencoder, whose seed is [latent] seed"
                    .into(),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_values_name_their_field() {
        assert!(ReducedSpec::default().validate().is_ok());
        let cases = [
            (
                ReducedSpec {
                    latent: 0,
                    ..Default::default()
                },
                "latent",
            ),
            (
                ReducedSpec {
                    samples: 1,
                    ..Default::default()
                },
                "samples",
            ),
            (
                ReducedSpec {
                    lipschitz: -1.0,
                    ..Default::default()
                },
                "lipschitz",
            ),
            (
                ReducedSpec {
                    tolerance: 0.0,
                    ..Default::default()
                },
                "tolerance",
            ),
            (
                ReducedSpec {
                    cubature: 0,
                    ..Default::default()
                },
                "cubature",
            ),
            (
                ReducedSpec {
                    plain_hidden: 0,
                    ..Default::default()
                },
                "plain_hidden",
            ),
            (
                ReducedSpec {
                    plain_epochs: 0,
                    ..Default::default()
                },
                "plain_epochs",
            ),
            (
                ReducedSpec {
                    plain_learning_rate: f64::NAN,
                    ..Default::default()
                },
                "plain_learning_rate",
            ),
            (
                ReducedSpec {
                    plain_final_learning_rate: 0.0,
                    ..Default::default()
                },
                "plain_final_learning_rate",
            ),
            (
                ReducedSpec {
                    lipschitz_local: -0.5,
                    ..Default::default()
                },
                "lipschitz_local",
            ),
            (
                ReducedSpec {
                    cubature_refits: 200,
                    ..Default::default()
                },
                "cubature_refits",
            ),
            (
                ReducedSpec {
                    cubature_refits: 1,
                    subspace: SubspaceSource::DataFree,
                    ..Default::default()
                },
                "cubature_refits",
            ),
            (
                ReducedSpec {
                    cubature_refits: 1,
                    lipschitz_energy: LipschitzEnergy::Exact,
                    ..Default::default()
                },
                "cubature_refits",
            ),
            (
                ReducedSpec {
                    lipschitz_energy: LipschitzEnergy::Sampled,
                    subspace: SubspaceSource::DataFree,
                    ..Default::default()
                },
                "lipschitz_energy",
            ),
            (
                ReducedSpec {
                    lipschitz_learning_rate: Some(-1e-3),
                    ..Default::default()
                },
                "lipschitz_learning_rate",
            ),
        ];
        for (spec, field) in cases {
            assert_eq!(spec.validate().unwrap_err().0, field);
        }
    }

    #[test]
    fn the_vanilla_network_is_read_from_the_table() {
        let spec: ReducedSpec = toml::from_str("vanilla = \"plain-mlp\"\nplain_hidden = 64").unwrap();
        assert_eq!(spec.vanilla, VanillaNetwork::PlainMlp);
        assert_eq!(spec.plain_hidden, 64);
        assert_eq!(spec.plain_epochs, 2000);
        assert_eq!((spec.plain_blocks, spec.plain_schedule), (0, PlainSchedule::Cosine));
        let spec: ReducedSpec = toml::from_str("plain_blocks = 1\nplain_schedule = \"paper\"").unwrap();
        assert_eq!((spec.plain_blocks, spec.plain_schedule), (1, PlainSchedule::Paper));
        assert!(toml::from_str::<ReducedSpec>("vanilla = \"plain\"").is_err());
    }

    #[test]
    fn the_paper_solver_is_an_option_and_not_the_default() {
        let spec = ReducedSpec::default();
        assert_eq!(
            (spec.solver, spec.precision),
            (SolverChoice::Lbfgs, SolverPrecision::Double)
        );
        assert!(spec.warm_start);
        let spec: ReducedSpec = toml::from_str("solver = \"lbfgs-paper\"\nprecision = \"single\"").unwrap();
        assert_eq!(
            (spec.solver, spec.precision),
            (SolverChoice::LbfgsPaper, SolverPrecision::Single)
        );
    }

    #[test]
    fn the_data_free_seed_is_read_from_the_table() {
        assert_eq!(ReducedSpec::default().seed, None);
        let spec: ReducedSpec = toml::from_str("subspace = \"data-free\"\nseed = 3").unwrap();
        assert_eq!((spec.subspace, spec.seed), (SubspaceSource::DataFree, Some(3)));
        assert!(spec.validate().is_ok());
        assert!(spec.validate_authored().is_ok());
        let supervised: ReducedSpec = toml::from_str("subspace = \"supervised\"\nseed = 3").unwrap();
        assert!(supervised.validate().is_ok());
        assert_eq!(supervised.validate_authored().unwrap_err().0, "seed");
        assert!(toml::from_str::<ReducedSpec>("seed = -1").is_err());
    }
}
