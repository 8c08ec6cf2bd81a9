//! Hyperelastic tetrahedra: stable neo-Hookean or StVK energy of a volumetric solid,
//! `sum_e V_e Psi(F_e)` with `F = Ds Dm^-1`.
//!
//! Stable neo-Hookean is `mu/2 (I_C - 3) - mu (J - 1) + (lambda + mu)/2 (J - 1)^2` (its
//! linearisation is linear elasticity with the material's `mu`, `lambda`), StVK is
//! `mu E:E + lambda/2 tr(E)^2`; the element is written once for 2D and 3D in
//! `energy/simplex.rs`.

use super::simplex::SimplexElastic;

/// Elastic energy of a tet mesh; one stencil (4 vertices, 12 local dofs) per tet. Built by
/// `TetElastic::new(model, rest, tets, materials, source)` ([`SimplexElastic::new`]).
pub type TetElastic = SimplexElastic<3, 9>;

impl TetElastic {
    /// Rest volume of each tet (positive).
    pub fn rest_volumes(&self) -> &[f64] {
        self.rest_measures()
    }
}

/// Signed volume of the tet `p`, positive when `(p1 - p0) . ((p2 - p0) x (p3 - p0)) > 0`.
pub(crate) fn signed_volume(p: [[f64; 3]; 4]) -> f64 {
    super::simplex::signed_measure(&p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::simplex::element_tests::{single, TET};
    use crate::material::MaterialLaw;

    #[test]
    fn volumes_match_the_determinant_formula() {
        let unit = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!((signed_volume(unit) - 1.0 / 6.0).abs() < 1e-15);
        let flipped = [unit[0], unit[2], unit[1], unit[3]];
        assert!((signed_volume(flipped) + 1.0 / 6.0).abs() < 1e-15);
        let tet: TetElastic = single(&TET, MaterialLaw::Stvk);
        let r = TET.rest;
        let p = [0, 1, 2, 3].map(|a| [r[3 * a], r[3 * a + 1], r[3 * a + 2]]);
        assert_eq!(tet.rest_volumes(), &[signed_volume(p)]);
    }
}
