//! Prescribed (Dirichlet) vertices: their targets checked, and placed in a state.

use crate::error::StepError;

/// Checks the prescribed vertices' targets: `dim` finite numbers per vertex of `fixed`.
pub(crate) fn check_targets(fixed: &[usize], dim: usize, targets: &[f64]) -> Result<(), StepError> {
    let expected = fixed.len() * dim;
    if targets.len() != expected {
        return Err(StepError::BoundaryLength {
            expected,
            got: targets.len(),
        });
    }
    if let Some(k) = targets.iter().position(|t| !t.is_finite()) {
        return Err(StepError::NonFiniteBoundary {
            vertex: fixed[k / dim],
            value: targets[k],
        });
    }
    Ok(())
}

/// Places the prescribed vertices `fixed` of `x` at their `targets`.
pub(crate) fn place_fixed(fixed: &[usize], dim: usize, x: &mut [f64], targets: &[f64]) {
    for (i, &v) in fixed.iter().enumerate() {
        x[v * dim..(v + 1) * dim].copy_from_slice(&targets[i * dim..(i + 1) * dim]);
    }
}
