//! Errors of the inputs of an [`Encoding`](super::Encoding).

/// Something wrong with the inputs of an [`Encoding`](super::Encoding).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum EncodingError {
    /// A vector has the wrong length.
    #[error("{what}: expected {expected} values, found {found}")]
    Length {
        /// Which input.
        what: &'static str,
        /// Length the encoding needs.
        expected: usize,
        /// Length given.
        found: usize,
    },
    /// The handles do not describe prescribed vertices of the mesh.
    #[error("handle `{handle}`: {message}")]
    BadHandle {
        /// Handle name.
        handle: String,
        /// What is wrong.
        message: String,
    },
    /// A point of the rotation fit holds a NaN or infinity.
    #[error("the points of the rotation fit hold a non-finite value")]
    NotFinite,
    /// The SVD of the rotation fit did not converge.
    #[error("the SVD of the rotation fit did not converge: {0}")]
    NoConvergence(String),
    /// Rotation was asked for, but the handle vertices cannot determine one (3D needs
    /// them to span a plane, 2D a line).
    #[error("the {count} handle vertices span {span} dimension(s), too few to fix a rotation")]
    DegenerateHandles {
        /// Number of handle vertices.
        count: usize,
        /// Dimension of the affine space they span (0: a point, 1: a line).
        span: usize,
    },
}

pub(super) fn check_len(what: &'static str, expected: usize, found: usize) -> Result<(), EncodingError> {
    if expected == found {
        Ok(())
    } else {
        Err(EncodingError::Length { what, expected, found })
    }
}
