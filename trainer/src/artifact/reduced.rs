//! The reduced-method file `<scene>.reduced` (beside the model artifacts): the vanilla and the
//! Lipschitz-optimised subspace of one scene, the linear (PCA) subspace of the same frames, the cubature they were optimised with, and what
//! their training measured. Only the trainer reads it (the reduced solver runs on the
//! desktop), through the runtime's envelope:
//!
//! ```text
//! envelope(MOCHIRED, REDUCED_VERSION, postcard(ReducedArtifact))
//! ```
//!
//! Files of version 2 (before a decoder's style was stored; every decoder a residual Swish
//! MLP) still load (`v2`).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::ArtifactError;
use crate::learn::network::{DenseLayer, ExportedMlp, MlpStyle};
use crate::learn::pca::Pca;
use mochi_runtime::envelope;
use mochi_sim::error::InputError;

/// Magic of a reduced-method file.
pub const REDUCED_MAGIC: &[u8; 8] = b"MOCHIRED";
/// Its format version.
pub const REDUCED_VERSION: u32 = 3;

/// One cubature rule of an energy term: the term's name, its selected stencils and weights.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CubatureData {
    /// The energy term (`StencilEnergy::name`).
    pub term: String,
    /// Selected stencils.
    pub elements: Vec<usize>,
    /// Their weights.
    pub weights: Vec<f64>,
    /// Relative residual of the fit on its training samples.
    pub residual: f64,
}

/// One subspace of the reduced method.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SubspaceData {
    /// The decoder's layers (input, blocks' inner and outer, output).
    pub decoder: Vec<DenseLayer>,
    /// The decoder's activation and how its hidden layers are joined.
    pub style: MlpStyle,
    /// The latent of the scene's start (the encoder's image of the start state, or the
    /// reduced static solve from zero for a data-free subspace).
    pub initial_latent: Vec<f64>,
    /// Wall-clock seconds of its training.
    pub training_seconds: f64,
    /// `Lip[d^2 P / dz^2]` by Eq. 7 on the held-out samples.
    pub lipschitz_estimate: f64,
    /// Loss of each epoch (or iteration) of its training.
    pub losses: Vec<f64>,
}

impl SubspaceData {
    /// The runnable decoder.
    pub fn decoder(&self) -> Result<ExportedMlp, ArtifactError> {
        Ok(ExportedMlp::from_styled_layers(self.decoder.clone(), self.style)?)
    }
}

/// The linear subspace: the PCA of the training frames (encoded) at the vanilla's latent size.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinearSubspaceData {
    /// The mean encoded frame.
    pub mean: Vec<f64>,
    /// The components, orthonormal, by decreasing variance.
    pub basis: Vec<Vec<f64>>,
    /// The projection of the scene's start.
    pub initial_latent: Vec<f64>,
}

impl LinearSubspaceData {
    /// The subspace of `pca`, starting at the projection of `start` (encoded).
    pub fn new(pca: &Pca, start: &[f64]) -> Result<Self, ArtifactError> {
        let initial_latent = pca
            .project(start)
            .map_err(|e| crate::learn::network::NetworkError::Invalid(format!("PCA of the start state: {e}")))?;
        Ok(LinearSubspaceData {
            mean: pca.mean.clone(),
            basis: pca.basis.clone(),
            initial_latent,
        })
    }

    /// Its linear map.
    pub fn pca(&self) -> Pca {
        Pca {
            mean: self.mean.clone(),
            basis: self.basis.clone(),
            singular_values: Vec::new(),
        }
    }
}

/// The reduced method of one scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReducedArtifact {
    /// Scene name.
    pub scene: String,
    /// The scene file the subspaces were trained on, whole (its `[reduced]` table included).
    pub scene_toml: String,
    /// Where that file was read from (relative mesh paths resolve against it).
    pub scene_path: String,
    /// `"supervised"` or `"data-free"`.
    pub source: String,
    /// Subspace trained on the construction loss alone.
    pub vanilla: SubspaceData,
    /// The same subspace after the Lipschitz optimisation (Eq. 10).
    pub lipschitz: SubspaceData,
    /// The cubature of each elastic term used by the Lipschitz loss.
    pub cubature: Vec<CubatureData>,
    /// The absolute weight of the Lipschitz term.
    pub lambda: f64,
    /// The linear subspace (`None` for a data-free subspace: there are no frames to fit).
    pub pca: Option<LinearSubspaceData>,
}

/// The reduced-method file of `scene` in `out_dir`.
pub fn reduced_path(out_dir: &Path, scene: &str) -> PathBuf {
    out_dir.join(format!("{scene}.reduced"))
}

impl ReducedArtifact {
    /// Writes the file (atomically: a crash leaves the old file or the new one).
    pub fn save(&self, path: &Path) -> Result<(), ArtifactError> {
        let payload = postcard::to_allocvec(self).map_err(|source| ArtifactError::Encode {
            section: "reduced-method file",
            source,
        })?;
        let bytes = envelope::wrap(REDUCED_MAGIC, REDUCED_VERSION, &payload);
        crate::learn::train::write_atomically(path, &bytes).map_err(|source| ArtifactError::Write {
            path: path.to_path_buf(),
            source,
        })
    }

    /// Reads a file written by [`ReducedArtifact::save`].
    pub fn load(path: &Path) -> Result<Self, InputError> {
        let bytes = std::fs::read(path).map_err(|e| InputError::file(path, format!("cannot read: {e}")))?;
        let unreadable = |e: postcard::Error| InputError::file(path, format!("reduced-method file is unreadable: {e}"));
        let artifact: ReducedArtifact = match envelope::open(&bytes, REDUCED_MAGIC, REDUCED_VERSION) {
            Ok(payload) => postcard::from_bytes(payload).map_err(unreadable)?,
            Err(e) => match envelope::open(&bytes, REDUCED_MAGIC, v2::VERSION) {
                Ok(payload) => v2::read(payload).map_err(unreadable)?,
                Err(_) => return Err(InputError::file(path, format!("reduced-method file {e}"))),
            },
        };
        for (name, s) in [("vanilla", &artifact.vanilla), ("lipschitz", &artifact.lipschitz)] {
            let decoder = s
                .decoder()
                .map_err(|e| InputError::file(path, format!("{name} decoder: {e}")))?;
            if decoder.spec().input != s.initial_latent.len() {
                return Err(InputError::file(
                    path,
                    format!(
                        "{name} subspace: initial latent of {} values for a decoder taking {}",
                        s.initial_latent.len(),
                        decoder.spec().input
                    ),
                ));
            }
        }
        if let Some(linear) = &artifact.pca {
            let n = linear.mean.len();
            if linear.basis.iter().any(|c| c.len() != n) || linear.initial_latent.len() != linear.basis.len() {
                return Err(InputError::file(
                    path,
                    format!(
                        "linear subspace: {} components of a {n}-value mean need as many values each and an initial \
                         latent of {} values",
                        linear.basis.len(),
                        linear.basis.len()
                    ),
                ));
            }
        }
        Ok(artifact)
    }
}

/// Reduced-method files of version 2: the layout of this file before a decoder's style
/// was stored. Every decoder of such a file is a residual Swish MLP, so it reads as a current
/// file with the default style.
mod v2 {
    use serde::{Deserialize, Serialize};

    use super::{CubatureData, LinearSubspaceData, ReducedArtifact, SubspaceData};
    use crate::learn::network::{DenseLayer, MlpStyle};

    /// The format version these files carry.
    pub(super) const VERSION: u32 = 2;

    /// [`SubspaceData`] of version 2.
    #[derive(Serialize, Deserialize)]
    struct SubspaceDataV2 {
        decoder: Vec<DenseLayer>,
        initial_latent: Vec<f64>,
        training_seconds: f64,
        lipschitz_estimate: f64,
        losses: Vec<f64>,
    }

    /// [`ReducedArtifact`] of version 2.
    #[derive(Serialize, Deserialize)]
    struct ReducedArtifactV2 {
        scene: String,
        scene_toml: String,
        scene_path: String,
        source: String,
        vanilla: SubspaceDataV2,
        lipschitz: SubspaceDataV2,
        cubature: Vec<CubatureData>,
        lambda: f64,
        pca: Option<LinearSubspaceData>,
    }

    impl From<SubspaceDataV2> for SubspaceData {
        fn from(old: SubspaceDataV2) -> Self {
            SubspaceData {
                decoder: old.decoder,
                style: MlpStyle::default(),
                initial_latent: old.initial_latent,
                training_seconds: old.training_seconds,
                lipschitz_estimate: old.lipschitz_estimate,
                losses: old.losses,
            }
        }
    }

    /// The artifact in a version-2 payload.
    pub(super) fn read(payload: &[u8]) -> Result<ReducedArtifact, postcard::Error> {
        let old: ReducedArtifactV2 = postcard::from_bytes(payload)?;
        Ok(ReducedArtifact {
            scene: old.scene,
            scene_toml: old.scene_toml,
            scene_path: old.scene_path,
            source: old.source,
            vanilla: old.vanilla.into(),
            lipschitz: old.lipschitz.into(),
            cubature: old.cubature,
            lambda: old.lambda,
            pca: old.pca,
        })
    }

    #[cfg(test)]
    mod tests {
        use super::super::{reduced_path, REDUCED_MAGIC};
        use super::*;
        use mochi_runtime::envelope;

        /// A file written in version 2's layout loads, its decoders residual Swish MLPs.
        #[test]
        fn version_2_files_load_with_the_residual_swish_style() {
            let layer = |rows: usize, cols: usize| DenseLayer {
                rows,
                cols,
                weights: vec![0.5; rows * cols],
                bias: vec![0.25; rows],
            };
            let subspace = || SubspaceDataV2 {
                decoder: vec![layer(3, 2), layer(3, 3), layer(3, 3), layer(6, 3)],
                initial_latent: vec![0.5, -0.5],
                training_seconds: 1.0,
                lipschitz_estimate: 2.0,
                losses: vec![1.0],
            };
            let old = ReducedArtifactV2 {
                scene: "bar".into(),
                scene_toml: "name = \"bar\"".into(),
                scene_path: "bar.toml".into(),
                source: "data-free".into(),
                vanilla: subspace(),
                lipschitz: subspace(),
                cubature: Vec::new(),
                lambda: 0.5,
                pca: None,
            };
            let dir = tempfile::tempdir().unwrap();
            let path = reduced_path(dir.path(), "bar");
            let bytes = envelope::wrap(REDUCED_MAGIC, VERSION, &postcard::to_allocvec(&old).unwrap());
            std::fs::write(&path, bytes).unwrap();
            let loaded = ReducedArtifact::load(&path).unwrap();
            assert_eq!(loaded.vanilla.style, MlpStyle::default());
            let decoder = loaded.lipschitz.decoder().unwrap();
            assert_eq!((decoder.spec().blocks, decoder.style()), (1, MlpStyle::default()));
            assert_eq!(loaded.lambda, 0.5);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn subspace(seed: f32) -> SubspaceData {
        let layer = |rows: usize, cols: usize| DenseLayer {
            rows,
            cols,
            weights: (0..rows * cols).map(|k| seed + k as f32).collect(),
            bias: vec![seed; rows],
        };
        SubspaceData {
            decoder: vec![layer(3, 2), layer(6, 3)],
            style: MlpStyle::default(),
            initial_latent: vec![0.5, -0.5],
            training_seconds: 1.5,
            lipschitz_estimate: 2.5,
            losses: vec![3.0, 2.0],
        }
    }

    #[test]
    fn round_trip_and_damage_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = reduced_path(dir.path(), "bar");
        let artifact = ReducedArtifact {
            scene: "bar".into(),
            scene_toml: "name = \"bar\"".into(),
            scene_path: "bar.toml".into(),
            source: "supervised".into(),
            vanilla: subspace(0.0),
            lipschitz: subspace(1.0),
            cubature: vec![CubatureData {
                term: "elastic".into(),
                elements: vec![1, 4],
                weights: vec![2.0, 3.0],
                residual: 1e-3,
            }],
            lambda: 0.25,
            pca: Some(LinearSubspaceData {
                mean: vec![1.0, 2.0, 3.0],
                basis: vec![vec![1.0, 0.0, 0.0], vec![0.0, 1.0, 0.0]],
                initial_latent: vec![0.5, -0.5],
            }),
        };
        artifact.save(&path).unwrap();
        assert_eq!(ReducedArtifact::load(&path).unwrap(), artifact);
        let mut bytes = std::fs::read(&path).unwrap();
        let last = bytes.len() - 1;
        bytes[last] ^= 1;
        std::fs::write(&path, &bytes).unwrap();
        let err = ReducedArtifact::load(&path).unwrap_err().to_string();
        assert!(err.contains(&path.display().to_string()), "{err}");
        let mut wrong = artifact.clone();
        wrong.lipschitz.initial_latent.push(0.0);
        wrong.save(&path).unwrap();
        let err = ReducedArtifact::load(&path).unwrap_err().to_string();
        assert!(err.contains("lipschitz subspace"), "{err}");
        // A decoder of plain ELU layers keeps its style (its three layers would not read as a
        // residual MLP).
        let mut paper = artifact.clone();
        paper.lipschitz.style = MlpStyle::PAPER;
        paper.lipschitz.decoder.insert(1, paper.lipschitz.decoder[0].clone());
        paper.lipschitz.decoder[1].cols = 3;
        paper.lipschitz.decoder[1].weights = vec![0.5; 9];
        paper.save(&path).unwrap();
        let loaded = ReducedArtifact::load(&path).unwrap();
        assert_eq!(loaded.lipschitz.decoder().unwrap().style(), MlpStyle::PAPER);
        let mut short = artifact.clone();
        short.pca.as_mut().unwrap().basis[1].pop();
        short.save(&path).unwrap();
        let err = ReducedArtifact::load(&path).unwrap_err().to_string();
        assert!(err.contains("linear subspace"), "{err}");
    }
}
