//! An axis-aligned box in a scene's coordinates (a body's box mesh, a selection, a collider's
//! region of aim points): below the scene and the boundary conditions, which both use it.

use serde::{Deserialize, Serialize};

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxSpec {
    /// Lower corner.
    pub min: [f64; 3],
    /// Upper corner.
    pub max: [f64; 3],
}

impl BoxSpec {
    pub(crate) fn contains(&self, p: [f64; 3]) -> bool {
        (0..3).all(|i| p[i] >= self.min[i] && p[i] <= self.max[i])
    }
}
