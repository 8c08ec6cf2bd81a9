//! Reading artifacts of format 3, which kept the triangles to draw (over full-mesh vertices)
//! in the training section; format 4 holds them in the model section, over the drawn vertices,
//! where the runtime reads them (`mochi_runtime::Model::surface_triangles`).
//!
//! A format-3 model section is a format-4 payload without its last field, the triangles, so
//! one `0x00` byte (an empty list) completes it; the triangles come from the old training
//! section.

use serde::{Deserialize, Serialize};

use super::section::{ArtifactError, TrainingSection, TRAINING_MAGIC};
use super::{Artifact, Method, TrainingSummary, MAGIC};
use crate::learn::network::DenseLayer;
use mochi_runtime::envelope;
use mochi_runtime::payload::Payload;

/// The format read here.
pub const VERSION: u32 = 3;

/// The training section of format 3: [`TrainingSection`] with the triangles to draw.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainingSectionV3 {
    /// See [`TrainingSection::scene`].
    pub scene: String,
    /// See [`TrainingSection::scene_path`].
    pub scene_path: String,
    /// See [`TrainingSection::scene_toml`].
    pub scene_toml: String,
    /// See [`TrainingSection::method`].
    pub method: Method,
    /// See [`TrainingSection::reference`].
    pub reference: Vec<f32>,
    /// See [`TrainingSection::handle_names`].
    pub handle_names: Vec<String>,
    /// Triangles to draw, full-mesh vertex indices.
    pub surface_triangles: Vec<[u32; 3]>,
    /// See [`TrainingSection::polylines`].
    pub polylines: Vec<Vec<u32>>,
    /// See [`TrainingSection::pca_mean`].
    pub pca_mean: Vec<f32>,
    /// See [`TrainingSection::pca_basis`].
    pub pca_basis: Vec<f32>,
    /// See [`TrainingSection::encoder`].
    pub encoder: Vec<DenseLayer>,
    /// See [`TrainingSection::summary`].
    pub summary: TrainingSummary,
}

impl TrainingSectionV3 {
    /// The section as format 4 holds it, and the triangles.
    fn split(self) -> (TrainingSection, Vec<[u32; 3]>) {
        let section = TrainingSection {
            scene: self.scene,
            scene_path: self.scene_path,
            scene_toml: self.scene_toml,
            method: self.method,
            reference: self.reference,
            handle_names: self.handle_names,
            polylines: self.polylines,
            pca_mean: self.pca_mean,
            pca_basis: self.pca_basis,
            encoder: self.encoder,
            summary: self.summary,
        };
        (section, self.surface_triangles)
    }
}

/// The artifact in the format-3 `bytes` (not validated yet).
pub fn parse(bytes: &[u8]) -> Result<Artifact, ArtifactError> {
    let (model, rest) = envelope::split(bytes, MAGIC, VERSION).map_err(ArtifactError::Envelope)?;
    let training = envelope::open(rest, TRAINING_MAGIC, VERSION).map_err(ArtifactError::TrainingEnvelope)?;
    // Format 4 appended the triangles (an empty list here), format 5 `decoder_basis` (false).
    let mut payload = model.to_vec();
    payload.extend([0, 0]);
    let payload = Payload::decode(&payload).map_err(|source| ArtifactError::Decode {
        section: "model section",
        source,
    })?;
    // Format 5 appended the training summary's `candidates` (an empty list here).
    let mut training = training.to_vec();
    training.push(0);
    let training: TrainingSectionV3 = postcard::from_bytes(&training).map_err(|source| ArtifactError::Decode {
        section: "training section",
        source,
    })?;
    let (training, triangles) = training.split();
    let mut artifact = Artifact::from_sections(payload, training)?;
    artifact.surface_triangles = triangles;
    Ok(artifact)
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use mochi_runtime::{EnvelopeError, LoadError};

    /// `artifact` in format 3, as the trainer wrote it before format 4.
    fn to_bytes(artifact: &Artifact) -> Result<Vec<u8>, ArtifactError> {
        let (mut payload, t) = artifact.sections()?;
        payload.surface_triangles.clear();
        let mut model = payload.encode().map_err(|source| ArtifactError::Encode {
            section: "model section",
            source,
        })?;
        // The empty list of triangles, which format 3 did not have.
        assert_eq!(model.pop(), Some(0));
        let training = TrainingSectionV3 {
            scene: t.scene,
            scene_path: t.scene_path,
            scene_toml: t.scene_toml,
            method: t.method,
            reference: t.reference,
            handle_names: t.handle_names,
            surface_triangles: artifact.surface_triangles.clone(),
            polylines: t.polylines,
            pca_mean: t.pca_mean,
            pca_basis: t.pca_basis,
            encoder: t.encoder,
            summary: t.summary,
        };
        let training = postcard::to_allocvec(&training).map_err(|source| ArtifactError::Encode {
            section: "training section",
            source,
        })?;
        let mut bytes = envelope::wrap(MAGIC, VERSION, &model);
        bytes.extend(envelope::wrap(TRAINING_MAGIC, VERSION, &training));
        Ok(bytes)
    }

    #[test]
    fn format_3_is_read_with_its_triangles_and_refused_by_the_runtime() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/artifacts/tiny.mochi");
        let artifact = Artifact::read(&path).unwrap();
        assert!(!artifact.surface_triangles.is_empty());
        let old = to_bytes(&artifact).unwrap();
        assert_eq!(Artifact::parse(&old).unwrap(), artifact);
        assert_eq!(
            mochi_runtime::OwnedModel::default().load(&old).unwrap_err(),
            LoadError::Envelope(EnvelopeError::Version {
                found: VERSION,
                expected: mochi_runtime::ARTIFACT_VERSION
            })
        );
    }
}
