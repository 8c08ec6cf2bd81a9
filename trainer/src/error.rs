//! The trainer library's errors: one enum, [`TrainerError`], that wraps the typed errors of
//! the simulator and of every trainer module, names the file of a failed read or write, and
//! adds what the library was doing when a call failed (`Context`).

use std::path::{Path, PathBuf};

use mochi_sim::{InputError, SimError};

use crate::learn::encoding::EncodingError;
use crate::learn::network::NetworkError;
use crate::learn::pca::PcaError;
use crate::learn::train::TrainError;

/// Errors of the trainer's library calls (`mochi train`, `mochi eval`, `mochi demo`, charts
/// and renders).
#[derive(Debug, thiserror::Error)]
pub enum TrainerError {
    /// A problem with an input file or value (a scene, a dataset, an artifact).
    #[error(transparent)]
    Input(#[from] InputError),
    /// The simulator failed (generating a dataset).
    #[error(transparent)]
    Sim(#[from] SimError),
    /// A full-space step failed.
    #[error(transparent)]
    Step(#[from] mochi_sim::solver::StepError),
    /// candle failed.
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
    /// A network could not be built, run or exported.
    #[error(transparent)]
    Network(#[from] NetworkError),
    /// A state could not be encoded or decoded.
    #[error(transparent)]
    Encoding(#[from] EncodingError),
    /// The PCA failed.
    #[error(transparent)]
    Pca(#[from] PcaError),
    /// The integrator's samples could not be made.
    #[error(transparent)]
    Samples(#[from] crate::learn::samples::SamplesError),
    /// A training run failed.
    #[error(transparent)]
    Train(#[from] TrainError),
    /// A data-free subspace could not be trained.
    #[error(transparent)]
    DataFree(#[from] crate::learn::datafree::DataFreeError),
    /// Code generation failed.
    #[error(transparent)]
    Codegen(#[from] mochi_codegen::CodegenError),
    /// Reading or writing a file failed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// The training frames could not be read back from the file they were written to
    /// (the message names it).
    #[error("reading the training frames back: {0}")]
    FrameRead(#[from] std::io::Error),
    /// A value the library computed or was given does not fit (the message says which).
    #[error("{0}")]
    Invalid(String),
    /// The runtime refused a model, or a runtime step or decode failed.
    #[error(transparent)]
    Runtime(Box<dyn std::error::Error + Send + Sync>),
    /// Drawing a chart or a preview failed.
    #[error("{0}")]
    Drawing(String),
    /// A recipe could not be written as TOML.
    #[error(transparent)]
    Toml(#[from] toml::ser::Error),
    /// Formatting text failed.
    #[error(transparent)]
    Format(#[from] std::fmt::Error),
    /// A call failed while the library was doing `context` (the message includes the
    /// error's own, so it is not repeated as a source).
    #[error("{context}: {error}")]
    Context {
        /// What the library was doing.
        context: String,
        /// Why it failed.
        error: Box<TrainerError>,
    },
    /// An artifact could not be written, read or assembled.
    #[error(transparent)]
    Artifact(#[from] crate::artifact::ArtifactError),
}

impl TrainerError {
    /// A failed read or write of `path`.
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        TrainerError::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    /// A value that does not fit, described by `message`.
    pub(crate) fn invalid(message: impl Into<String>) -> Self {
        TrainerError::Invalid(message.into())
    }
}

impl<E: std::error::Error + Send + Sync> From<plotters::drawing::DrawingAreaErrorKind<E>> for TrainerError {
    fn from(error: plotters::drawing::DrawingAreaErrorKind<E>) -> Self {
        TrainerError::Drawing(error.to_string())
    }
}

/// Result of the trainer's library calls.
pub type TrainerResult<T> = Result<T, TrainerError>;

/// Adds what the library was doing to an error, as [`TrainerError::Context`] (and turns a
/// missing value into a [`TrainerError::Invalid`] that says what was missing).
pub(crate) trait Context<T> {
    /// The error of `self`, if any, within `context`.
    fn context(self, context: &str) -> TrainerResult<T>;
    /// The error of `self`, if any, within `context()`.
    fn with_context(self, context: impl FnOnce() -> String) -> TrainerResult<T>;
}

impl<T, E: Into<TrainerError>> Context<T> for Result<T, E> {
    fn context(self, context: &str) -> TrainerResult<T> {
        self.with_context(|| context.to_string())
    }
    fn with_context(self, context: impl FnOnce() -> String) -> TrainerResult<T> {
        self.map_err(|e| TrainerError::Context {
            context: context(),
            error: Box::new(e.into()),
        })
    }
}

impl<T> Context<T> for Option<T> {
    fn context(self, context: &str) -> TrainerResult<T> {
        self.ok_or_else(|| TrainerError::invalid(context))
    }
    fn with_context(self, context: impl FnOnce() -> String) -> TrainerResult<T> {
        self.ok_or_else(|| TrainerError::Invalid(context()))
    }
}

/// Returns a [`TrainerError::Invalid`] with a `format!` message from the enclosing function.
macro_rules! bail {
    ($($message:tt)*) => {
        return Err($crate::error::TrainerError::Invalid(format!($($message)*)))
    };
}
pub(crate) use bail;

/// Errors of the runtime ([`mochi_runtime`]) the library checks its models with.
macro_rules! runtime_errors {
    ($($error:ty),*) => {$(
        impl From<$error> for TrainerError {
            fn from(error: $error) -> Self {
                TrainerError::Runtime(Box::new(error))
            }
        }
    )*};
}
runtime_errors!(
    mochi_runtime::LoadError,
    mochi_runtime::ModelError,
    mochi_runtime::SizeError,
    mochi_runtime::StepError,
    mochi_runtime::DecodeError
);

/// `std::fs` calls that name their path in the error.
pub(crate) mod fs {
    use super::{TrainerError, TrainerResult};
    use std::path::Path;

    /// [`std::fs::create_dir_all`].
    pub(crate) fn create_dir_all(path: &Path) -> TrainerResult<()> {
        std::fs::create_dir_all(path).map_err(|e| TrainerError::io(path, e))
    }

    /// [`std::fs::read`].
    pub(crate) fn read(path: &Path) -> TrainerResult<Vec<u8>> {
        std::fs::read(path).map_err(|e| TrainerError::io(path, e))
    }

    /// [`std::fs::write`].
    pub(crate) fn write(path: &Path, contents: impl AsRef<[u8]>) -> TrainerResult<()> {
        std::fs::write(path, contents).map_err(|e| TrainerError::io(path, e))
    }
}
