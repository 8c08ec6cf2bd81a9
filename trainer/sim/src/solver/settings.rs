//! The solver's settings: time integration scheme, Newton's tolerance, iteration cap and
//! Hessian mode.

use serde::{Deserialize, Serialize};

/// Time integration scheme.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum TimeScheme {
    /// First-order implicit (backward) Euler.
    #[default]
    ImplicitEuler,
    /// Second-order backward differentiation formula (first step uses implicit Euler).
    Bdf2,
    /// No inertia: every step is the static equilibrium with the handles at that frame's
    /// targets, starting from the last one (velocities are the differences of consecutive
    /// equilibria over `dt`).
    QuasiStatic,
}

/// Newton solver settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NewtonSettings {
    /// Converged when `max |dx| / (dt * L)` falls below this, with `dx` the Newton step and
    /// `L` the rest bounding-box diagonal (for static solves, `max |dx| / L`).
    pub tolerance: f64,
    /// Newton iterations per step before giving up (the step is still taken).
    pub max_iterations: usize,
    /// Which Hessian Newton uses.
    pub hessian: HessianMode,
}

/// Which Hessian Newton uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum HessianMode {
    /// The exact Hessian when it is positive definite (checked by its Cholesky
    /// factorisation), the per-stencil PSD projection otherwise.
    #[default]
    ExactIfDefinite,
    /// Always project every stencil Hessian to PSD (eigenvalue clamping).
    Projected,
}

impl Default for NewtonSettings {
    fn default() -> Self {
        NewtonSettings {
            tolerance: 1e-4,
            max_iterations: 50,
            hessian: HessianMode::default(),
        }
    }
}
