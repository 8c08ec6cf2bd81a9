//! Hyperelastic triangles of a planar solid in plane strain: stable neo-Hookean or StVK
//! energy `sum_e A_e Psi(F_e)` per unit thickness, with the 2x2 `F = Ds Dm^-1`.
//!
//! Stable neo-Hookean is `mu/2 (I_C - 2) - mu (J - 1) + (lambda + mu)/2 (J - 1)^2` (its
//! linearisation is plane-strain linear elasticity with the material's `mu`, `lambda`),
//! StVK is `mu E:E + lambda/2 tr(E)^2`; the element is written once for 2D and 3D in
//! `energy/simplex.rs`.

use super::simplex::SimplexElastic;

/// Elastic energy of a 2D triangle mesh; one stencil (3 vertices, 6 local dofs) per
/// triangle. Built by `Tri2dElastic::new(model, rest, tris, materials, source)`
/// ([`SimplexElastic::new`]); rest triangles must be counter-clockwise.
pub type Tri2dElastic = SimplexElastic<2, 4>;

impl Tri2dElastic {
    /// Rest area of each triangle (positive).
    pub fn rest_areas(&self) -> &[f64] {
        self.rest_measures()
    }
}

/// Signed area of the triangle `p`, positive when its vertices are counter-clockwise.
pub(crate) fn signed_area(p: [[f64; 2]; 3]) -> f64 {
    super::simplex::signed_measure(&p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::simplex::element_tests::{single, TRIANGLE};
    use crate::material::MaterialLaw;

    #[test]
    fn areas_match_the_cross_product_formula() {
        let unit = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
        assert!((signed_area(unit) - 0.5).abs() < 1e-15);
        assert!((signed_area([unit[0], unit[2], unit[1]]) + 0.5).abs() < 1e-15);
        let tri: Tri2dElastic = single(&TRIANGLE, MaterialLaw::Stvk);
        let r = TRIANGLE.rest;
        let p = [0, 1, 2].map(|a| [r[2 * a], r[2 * a + 1]]);
        assert_eq!(tri.rest_areas(), &[signed_area(p)]);
    }
}
