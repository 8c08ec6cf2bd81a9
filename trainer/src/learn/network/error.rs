//! Errors building, running or exporting a network.

/// Errors building, running or exporting a network.
#[derive(Debug, thiserror::Error)]
pub enum NetworkError {
    /// A size or value given to a constructor or an exported forward pass does not fit.
    #[error("{0}")]
    Invalid(String),
    /// candle failed.
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
}

/// Result of this module's functions.
pub type ModelResult<T> = Result<T, NetworkError>;

pub(super) fn invalid<T>(message: impl Into<String>) -> ModelResult<T> {
    Err(NetworkError::Invalid(message.into()))
}
