//! Reduced-method files of version 2: the layout of [`super::reduced`] before a decoder's style
//! was stored. Every decoder of such a file is a residual Swish MLP, so it reads as a current
//! file with the default style.

use serde::{Deserialize, Serialize};

use super::reduced::{CubatureData, LinearSubspaceData, ReducedArtifact, SubspaceData};
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
    use super::*;
    use crate::artifact::reduced::{reduced_path, REDUCED_MAGIC};
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
