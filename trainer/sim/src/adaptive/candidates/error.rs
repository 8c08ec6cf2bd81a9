//! Why a candidate basis could not be built.

use crate::error::InputError;

/// Why a candidate basis could not be built; every message names the value at fault.
#[derive(Debug, thiserror::Error)]
pub enum CandidateError {
    /// The body is malformed (lengths, dimension, masses, vertex indices).
    #[error("invalid body: {0}")]
    InvalidBody(String),
    /// More linear modes were asked for than the body has free degrees of freedom beyond
    /// the rigid modes its stiffness leaves free.
    #[error(
        "asked for {requested} linear modes, but the body has only {available} \
         ({free_dofs} free degrees of freedom, {deflated} of them rigid modes)"
    )]
    TooManyModes {
        /// Linear modes asked for.
        requested: usize,
        /// The most there can be.
        available: usize,
        /// Free (not prescribed) degrees of freedom.
        free_dofs: usize,
        /// Rigid modes left out of the linear modes (a body with no fixed vertex).
        deflated: usize,
    },
    /// `K - sigma M` has no Cholesky factorisation: the rest-shape stiffness is not
    /// positive semi-definite (a rest shape that is not an energy minimum) or the shift is
    /// not below its lowest eigenvalue.
    #[error("the shifted rest-shape stiffness K - ({shift:e}) M is not positive definite")]
    NotPositiveDefinite {
        /// The shift sigma.
        shift: f64,
    },
    /// The eigensolver stopped before every wanted pair met the tolerance.
    #[error(
        "linear modes did not converge in {restarts} restarts: worst relative residual \
         {worst_residual:e} above the tolerance {tolerance:e}"
    )]
    NotConverged {
        /// Restarts taken.
        restarts: usize,
        /// Largest relative residual among the wanted pairs.
        worst_residual: f64,
        /// The tolerance asked for.
        tolerance: f64,
    },
    /// A dense eigen-decomposition (Rayleigh-Ritz) failed to converge.
    #[error("the dense Rayleigh-Ritz eigen-decomposition did not converge")]
    DenseEigen,
    /// A setting is out of range (the message names it).
    #[error("invalid setting: {0}")]
    InvalidSetting(String),
    /// The scene the body comes from is invalid.
    #[error(transparent)]
    Input(#[from] InputError),
}
