//! The trainer's side of the artifact contract (docs/design.md, decision 4): the training
//! section that follows the runtime's payload, its magic, and why a file is refused. Written
//! and read by [`super::file`]; [`super::format3`] reads the older layout into it.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{Method, TrainingSummary};
use crate::learn::network::{DenseLayer, NetworkError};
use mochi_runtime::envelope::EnvelopeError;
use mochi_runtime::LoadError;
use mochi_sim::error::InputError;

/// Magic of the training section (the second section of an artifact).
pub const TRAINING_MAGIC: &[u8; 8] = b"MOCHITRN";
/// Why an artifact could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum ArtifactError {
    /// The model section's envelope was refused.
    #[error("model artifact {0}")]
    Envelope(EnvelopeError),
    /// The training section's envelope was refused.
    #[error("model artifact's training section is missing or {0}")]
    TrainingEnvelope(EnvelopeError),
    /// A section could not be encoded.
    #[error("encoding the artifact's {section}: {source}")]
    Encode {
        /// Which section.
        section: &'static str,
        /// Why.
        source: postcard::Error,
    },
    /// A section's payload could not be decoded.
    #[error("model artifact's {section} is unreadable: {source}")]
    Decode {
        /// Which section.
        section: &'static str,
        /// Why.
        source: postcard::Error,
    },
    /// A field is inconsistent.
    #[error("field `{field}`: {message}")]
    Invalid {
        /// The field.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// What the runtime reads was refused by the runtime.
    #[error("refused by the runtime: {0}")]
    Runtime(#[from] LoadError),
    /// A network could not be rebuilt from its layers.
    #[error(transparent)]
    Network(#[from] NetworkError),
    /// The file could not be written.
    #[error("writing artifact {}: {source}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

impl ArtifactError {
    /// The error as a problem of the input file `source`.
    pub fn in_file(self, source: &Path) -> InputError {
        match self {
            ArtifactError::Invalid { field, message } => InputError::field(source, field, message),
            other => InputError::file(source, other.to_string()),
        }
    }
}

/// What only the trainer reads: the second section of an artifact.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainingSection {
    /// Scene name.
    pub scene: String,
    /// The scene file the model was trained from.
    pub scene_path: String,
    /// Scene TOML text.
    pub scene_toml: String,
    /// How the integrator was trained.
    pub method: Method,
    /// Identity-pose targets of the handle vertices (`encoding.reference`).
    pub reference: Vec<f32>,
    /// Handle names, in signal order.
    pub handle_names: Vec<String>,
    /// Polylines to draw.
    pub polylines: Vec<Vec<u32>>,
    /// PCA mean of the encoded training frames.
    pub pca_mean: Vec<f32>,
    /// PCA components, row-major.
    pub pca_basis: Vec<f32>,
    /// Encoder: encoded state -> latent.
    pub encoder: Vec<DenseLayer>,
    /// How the model was made.
    pub summary: TrainingSummary,
}
