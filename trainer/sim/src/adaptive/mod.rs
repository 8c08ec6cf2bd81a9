//! Adaptive subspace simulation (Trusty et al., "adaptive subspace simulation"): each
//! time-step solve runs in a small reduced model that adapts inside the step, built from a
//! larger set of candidate modes (and nodal enrichment) and updated or downdated by
//! error and progress measures, while the full positions stay the primary state.
//!
//! - [`candidates`]: the candidate bases of a body (rigid, affine and linear modes of the
//!   rest shape) grouped into the blocks the adaptivity queries one at a time.

pub mod candidates;
