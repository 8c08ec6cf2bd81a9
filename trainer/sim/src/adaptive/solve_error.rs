//! Why a linear solve of the adaptive solver failed.

/// Why a linear solve failed. Solves never panic on bad matrices; they return one of these.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolveError {
    /// Operands whose sizes do not fit together.
    #[error("{what}: expected {expected}, got {got}")]
    Dimension {
        /// Which operand.
        what: &'static str,
        /// The size it must have.
        expected: String,
        /// The size it has.
        got: String,
    },
    /// A symmetric sparse matrix given as its lower triangle stores an entry above the
    /// diagonal.
    #[error("{matrix} stores entry ({row}, {col}) above the diagonal; pass its lower triangle only")]
    UpperEntry {
        /// Which matrix.
        matrix: &'static str,
        /// Row of the entry.
        row: usize,
        /// Column of the entry.
        col: usize,
    },
    /// An input holds NaN or an infinity.
    #[error("{0} holds a non-finite value")]
    NonFinite(&'static str),
    /// A matrix that must be symmetric positive definite is not (its Cholesky
    /// factorisation failed).
    #[error("{0} is not symmetric positive definite: its Cholesky factorisation failed")]
    NotPositiveDefinite(&'static str),
    /// A diagonal block of the preconditioned matrix is not positive definite.
    #[error("diagonal block {block} of {matrix} is not positive definite")]
    PreconditionerBlock {
        /// Which matrix.
        matrix: &'static str,
        /// Index of the block.
        block: usize,
    },
    /// Conjugate gradients met a direction of non-positive curvature: the operator is not
    /// positive definite.
    #[error("conjugate gradients on {matrix} found non-positive curvature {curvature:e} at iteration {iteration}: the operator is not positive definite")]
    Indefinite {
        /// Which operator.
        matrix: &'static str,
        /// Iteration at which it happened.
        iteration: usize,
        /// The curvature `p·Ap` found.
        curvature: f64,
    },
}

/// A `Dimension` error.
pub(crate) fn dimension(what: &'static str, expected: impl ToString, got: impl ToString) -> SolveError {
    SolveError::Dimension {
        what,
        expected: expected.to_string(),
        got: got.to_string(),
    }
}
