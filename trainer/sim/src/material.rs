//! Materials: constitutive model, Young's modulus, Poisson ratio, density; per element.

use serde::{Deserialize, Serialize};

/// Hyperelastic model of solids, 2D triangles and cloth membranes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum MaterialLaw {
    /// Stable neo-Hookean (Smith et al. 2018).
    #[default]
    StableNeoHookean,
    /// Saint Venant-Kirchhoff.
    Stvk,
}

/// Per-element material parameters (heterogeneous materials are per-element vectors of these).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ElementMaterial {
    /// Young's modulus (Pa).
    pub youngs: f64,
    /// Poisson ratio, in (-1, 0.5).
    pub poisson: f64,
    /// Mass density (kg/m^3; per unit area or length times thickness / cross-section).
    pub density: f64,
}

impl ElementMaterial {
    /// First Lamé parameter (shear modulus) mu = E / (2 (1 + nu)).
    pub fn mu(&self) -> f64 {
        self.youngs / (2.0 * (1.0 + self.poisson))
    }
    /// Second Lamé parameter lambda = E nu / ((1 + nu)(1 - 2 nu)) (3D and plane strain).
    pub fn lambda(&self) -> f64 {
        self.youngs * self.poisson / ((1.0 + self.poisson) * (1.0 - 2.0 * self.poisson))
    }
    /// Plane-stress lambda for thin shells: 2 mu lambda / (lambda + 2 mu) = E nu / (1 - nu^2).
    pub fn lambda_plane_stress(&self) -> f64 {
        self.youngs * self.poisson / (1.0 - self.poisson * self.poisson)
    }
}
