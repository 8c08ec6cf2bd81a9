//! Hyperelastic triangles of a planar solid in plane strain: stable neo-Hookean or StVK
//! energy `sum_e A_e Psi(F_e)` per unit thickness, with the 2x2 `F = Ds Dm^-1`.
//!
//! Stable neo-Hookean is `mu/2 (I_C - 2) - mu (J - 1) + (lambda + mu)/2 (J - 1)^2` (its
//! linearisation is plane-strain linear elasticity with the material's `mu`, `lambda`),
//! StVK is `mu E:E + lambda/2 tr(E)^2`; both are written once for 2D and 3D in
//! `energy/simplex.rs`.

use super::simplex::{Names, SimplexElastic};
use super::{Local, StencilEnergy, Want};
use crate::error::InputError;
use crate::material::{ElementMaterial, MaterialLaw};

/// Elastic energy of a 2D triangle mesh; one stencil (3 vertices, 6 local dofs) per
/// triangle.
pub struct Tri2dElastic {
    solid: SimplexElastic<2, 4>,
}

impl Tri2dElastic {
    /// Builds the energy of `tris` over the flat 2D rest positions `rest`, with one
    /// material for all triangles or one per triangle (plane-strain Lamé parameters).
    /// Rejects bad materials, out-of-range vertex indices and degenerate or inverted
    /// (clockwise) rest triangles, naming `source` and the field or triangle.
    pub fn new(
        model: MaterialLaw,
        rest: &[f64],
        tris: &[[usize; 3]],
        materials: &[ElementMaterial],
        source: &std::path::Path,
    ) -> Result<Self, InputError> {
        let names = Names {
            element: "triangle",
            measure: "area",
        };
        let solid = SimplexElastic::new(model, rest, tris, materials, source, names)?;
        Ok(Tri2dElastic { solid })
    }

    /// Rest area of each triangle (positive).
    pub fn rest_areas(&self) -> &[f64] {
        self.solid.rest_measures()
    }
}

/// Signed area of the triangle `p`, positive when its vertices are counter-clockwise.
pub fn signed_area(p: [[f64; 2]; 3]) -> f64 {
    super::simplex::signed_measure(&p)
}

impl StencilEnergy for Tri2dElastic {
    fn name(&self) -> &'static str {
        "elastic"
    }

    fn dim(&self) -> usize {
        2
    }

    fn len(&self) -> usize {
        self.solid.len()
    }

    fn stencil(&self, s: usize) -> &[usize] {
        self.solid.stencil(s)
    }

    fn eval(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        self.solid.eval(s, x, want, out)
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::energy::fd::assert_all_stencils;
    use crate::energy::simplex::checks;
    use crate::error::Location;

    const MODELS: [MaterialLaw; 2] = [MaterialLaw::StableNeoHookean, MaterialLaw::Stvk];

    /// A generic, well-shaped, counter-clockwise triangle.
    const REST: [f64; 6] = [0.1, -0.2, 1.2, 0.1, 0.3, 0.9];

    fn material(youngs: f64) -> ElementMaterial {
        ElementMaterial {
            youngs,
            poisson: 0.4,
            density: 1000.0,
        }
    }

    fn single(model: MaterialLaw) -> Tri2dElastic {
        Tri2dElastic::new(model, &REST, &[[0, 1, 2]], &[material(100.0)], Path::new("t")).unwrap()
    }

    fn rng() -> ChaCha8Rng {
        ChaCha8Rng::seed_from_u64(11)
    }

    #[test]
    fn areas_match_the_cross_product_formula() {
        let unit = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
        assert!((signed_area(unit) - 0.5).abs() < 1e-15);
        assert!((signed_area([unit[0], unit[2], unit[1]]) + 0.5).abs() < 1e-15);
        let tri = single(MaterialLaw::Stvk);
        let p = [0, 1, 2].map(|a| [REST[2 * a], REST[2 * a + 1]]);
        assert_eq!(tri.rest_areas(), &[signed_area(p)]);
    }

    #[test]
    fn derivatives_match_finite_differences() {
        for model in MODELS {
            let (g, h) = checks::max_fd_errors(&single(model), &REST, 400, 1e-6, &mut rng());
            eprintln!("{model:?}: max relative FD error: gradient {g:.2e}, Hessian {h:.2e}");
            assert!(g < 1e-7 && h < 1e-7, "{model:?}: gradient {g:e}, Hessian {h:e}");
        }
    }

    #[test]
    fn zero_at_rest_and_invariant_under_rigid_motion() {
        for model in MODELS {
            checks::assert_rest_and_rigid_invariance(&single(model), &REST, 100.0, &mut rng());
        }
    }

    #[test]
    fn projected_hessian_is_psd_and_exact_where_already_psd() {
        for model in MODELS {
            checks::assert_projection(&single(model), &REST, &mut rng());
        }
    }

    #[test]
    fn small_strains_match_plane_strain_linear_elasticity() {
        let m = material(100.0);
        for model in MODELS {
            let tri = single(model);
            let area = tri.rest_areas()[0];
            checks::assert_linear_limit(&tri, &REST, area, m.mu(), m.lambda(), &mut rng());
        }
    }

    /// Two triangles sharing an edge, their vertices moved independently.
    fn two_tris(model: MaterialLaw, materials: &[ElementMaterial]) -> (Tri2dElastic, Vec<f64>) {
        let mut rest = REST.to_vec();
        rest.extend([1.3, 1.0]);
        let tris = [[0, 1, 2], [1, 3, 2]];
        let tri = Tri2dElastic::new(model, &rest, &tris, materials, Path::new("t")).unwrap();
        let mut r = rng();
        let x = rest.iter().map(|c| c + r.random_range(-0.3..0.3)).collect();
        (tri, x)
    }

    #[test]
    fn mesh_stencils_match_finite_differences() {
        for model in MODELS {
            let (tri, x) = two_tris(model, &[material(100.0)]);
            assert_eq!(tri.stencil(1), &[1, 3, 2]);
            assert_all_stencils(&tri, &x, 1e-6, 1e-7);
        }
    }

    #[test]
    fn heterogeneous_materials_scale_element_energies() {
        for model in MODELS {
            let (uniform, x) = two_tris(model, &[material(100.0)]);
            let (mixed, _) = two_tris(model, &[material(100.0), material(700.0)]);
            let mut out = Local::default();
            let mut xl = [0.0; 12];
            for (s, factor) in [(0, 1.0), (1, 7.0)] {
                let n = crate::energy::gather(&uniform, s, &x, &mut xl);
                let base = uniform.eval(s, &xl[..n], Want::Value, &mut out);
                let scaled = mixed.eval(s, &xl[..n], Want::Value, &mut out);
                assert!(base > 0.0);
                assert!((scaled - factor * base).abs() <= 1e-12 * scaled, "triangle {s}");
            }
        }
    }

    fn error(rest: &[f64], tris: &[[usize; 3]], materials: &[ElementMaterial]) -> InputError {
        let result = Tri2dElastic::new(MaterialLaw::StableNeoHookean, rest, tris, materials, Path::new("m"));
        let error = result.err().expect("input should be rejected");
        eprintln!("{error}");
        error
    }

    #[test]
    fn bad_elements_are_rejected_by_index() {
        let m = [material(1.0)];
        // Vertex 3 is the midpoint of edge 0-1, so triangle 1 is flat.
        let mut flat = REST.to_vec();
        flat.extend((0..2).map(|i| 0.5 * (REST[i] + REST[2 + i])));
        let e = error(&flat, &[[0, 1, 2], [0, 1, 3]], &m);
        assert_eq!(e.location, Location::Element(1));
        assert!(e.message.contains("degenerate triangle") && e.message.contains("rest area"));

        let e = error(&REST, &[[0, 1, 2], [0, 2, 1]], &m);
        assert_eq!(e.location, Location::Element(1));
        assert!(e.message.contains("inverted triangle") && e.message.contains("rest area -"));

        let e = error(&REST, &[[0, 1, 2], [3, 1, 2]], &m);
        assert_eq!(e.location, Location::Element(1));
        assert!(e.message.contains("index 3"));

        let e = error(&REST[..5], &[[0, 1, 2]], &m);
        assert_eq!(e.location, Location::Field("rest".into()));
    }

    #[test]
    fn bad_materials_are_rejected_by_field() {
        let tris = [[0, 1, 2], [0, 1, 2]];
        let e = error(&REST, &tris, &[material(1.0); 3]);
        assert_eq!(e.location, Location::Field("materials".into()));
        assert!(e.message.contains("got 3"));
        let e = error(&REST, &tris, &[]);
        assert_eq!(e.location, Location::Field("materials".into()));

        let nan = material(f64::NAN);
        let e = error(&REST, &tris, &[material(1.0), nan]);
        assert_eq!(e.location, Location::Field("materials[1].youngs".into()));
        let e = error(
            &REST,
            &tris,
            &[ElementMaterial {
                density: f64::NAN,
                ..material(1.0)
            }],
        );
        assert_eq!(e.location, Location::Field("materials[0].density".into()));
    }
}
