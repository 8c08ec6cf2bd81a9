//! Hyperelastic tetrahedra: stable neo-Hookean or StVK energy of a volumetric solid,
//! `sum_e V_e Psi(F_e)` with `F = Ds Dm^-1`.
//!
//! Stable neo-Hookean is `mu/2 (I_C - 3) - mu (J - 1) + (lambda + mu)/2 (J - 1)^2` (its
//! linearisation is linear elasticity with the material's `mu`, `lambda`), StVK is
//! `mu E:E + lambda/2 tr(E)^2`; both are written once for 2D and 3D in `energy/simplex.rs`.

use super::simplex::{Names, SimplexElastic};
use super::{Local, StencilEnergy, Want};
use crate::error::InputError;
use crate::material::{ElementMaterial, MaterialLaw};

/// Elastic energy of a tet mesh; one stencil (4 vertices, 12 local dofs) per tet.
pub struct TetElastic {
    solid: SimplexElastic<3, 9>,
}

impl TetElastic {
    /// Builds the energy of `tets` over the flat 3D rest positions `rest`, with one
    /// material for all tets or one per tet. Rejects bad materials, out-of-range vertex
    /// indices and degenerate or inverted rest tets, naming `source` and the field or tet.
    pub fn new(
        model: MaterialLaw,
        rest: &[f64],
        tets: &[[usize; 4]],
        materials: &[ElementMaterial],
        source: &std::path::Path,
    ) -> Result<Self, InputError> {
        let names = Names {
            element: "tet",
            measure: "volume",
        };
        let solid = SimplexElastic::new(model, rest, tets, materials, source, names)?;
        Ok(TetElastic { solid })
    }

    /// Rest volume of each tet (positive).
    pub fn rest_volumes(&self) -> &[f64] {
        self.solid.rest_measures()
    }
}

/// Signed volume of the tet `p`, positive when `(p1 - p0) . ((p2 - p0) x (p3 - p0)) > 0`.
pub fn signed_volume(p: [[f64; 3]; 4]) -> f64 {
    super::simplex::signed_measure(&p)
}

impl StencilEnergy for TetElastic {
    fn name(&self) -> &'static str {
        "elastic"
    }

    fn dim(&self) -> usize {
        3
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

    /// A generic, well-shaped, positively oriented tet.
    const REST: [f64; 12] = [
        0.1, -0.2, 0.0, //
        1.2, 0.1, 0.2, //
        0.2, 1.1, -0.1, //
        0.1, 0.3, 0.9,
    ];

    fn material(youngs: f64) -> ElementMaterial {
        ElementMaterial {
            youngs,
            poisson: 0.35,
            density: 1000.0,
        }
    }

    fn single(model: MaterialLaw) -> TetElastic {
        TetElastic::new(model, &REST, &[[0, 1, 2, 3]], &[material(100.0)], Path::new("t")).unwrap()
    }

    fn rng() -> ChaCha8Rng {
        ChaCha8Rng::seed_from_u64(7)
    }

    #[test]
    fn volumes_match_the_determinant_formula() {
        let unit = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        assert!((signed_volume(unit) - 1.0 / 6.0).abs() < 1e-15);
        let flipped = [unit[0], unit[2], unit[1], unit[3]];
        assert!((signed_volume(flipped) + 1.0 / 6.0).abs() < 1e-15);
        let tet = single(MaterialLaw::Stvk);
        let p = [0, 1, 2, 3].map(|a| [REST[3 * a], REST[3 * a + 1], REST[3 * a + 2]]);
        assert_eq!(tet.rest_volumes(), &[signed_volume(p)]);
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
    fn small_strains_match_linear_elasticity() {
        let m = material(100.0);
        for model in MODELS {
            let tet = single(model);
            let volume = tet.rest_volumes()[0];
            checks::assert_linear_limit(&tet, &REST, volume, m.mu(), m.lambda(), &mut rng());
        }
    }

    /// Two tets sharing a face, their vertices moved independently.
    fn two_tets(model: MaterialLaw, materials: &[ElementMaterial]) -> (TetElastic, Vec<f64>) {
        let mut rest = REST.to_vec();
        rest.extend([1.0, 1.0, 0.6]);
        let tets = [[0, 1, 2, 3], [1, 2, 3, 4]];
        let tet = TetElastic::new(model, &rest, &tets, materials, Path::new("t")).unwrap();
        let mut r = rng();
        let x = rest.iter().map(|c| c + r.random_range(-0.3..0.3)).collect();
        (tet, x)
    }

    #[test]
    fn mesh_stencils_match_finite_differences() {
        for model in MODELS {
            let (tet, x) = two_tets(model, &[material(100.0)]);
            assert_eq!(tet.stencil(1), &[1, 2, 3, 4]);
            assert_all_stencils(&tet, &x, 1e-6, 1e-7);
        }
    }

    #[test]
    fn heterogeneous_materials_scale_element_energies() {
        for model in MODELS {
            let (uniform, x) = two_tets(model, &[material(100.0)]);
            let (mixed, _) = two_tets(model, &[material(100.0), material(700.0)]);
            let mut out = Local::default();
            let mut xl = [0.0; 12];
            for (s, factor) in [(0, 1.0), (1, 7.0)] {
                crate::energy::gather(&uniform, s, &x, &mut xl);
                let base = uniform.eval(s, &xl, Want::Value, &mut out);
                let scaled = mixed.eval(s, &xl, Want::Value, &mut out);
                assert!(base > 0.0);
                assert!((scaled - factor * base).abs() <= 1e-12 * scaled, "tet {s}");
            }
        }
    }

    fn error(rest: &[f64], tets: &[[usize; 4]], materials: &[ElementMaterial]) -> InputError {
        let result = TetElastic::new(MaterialLaw::StableNeoHookean, rest, tets, materials, Path::new("m"));
        let error = result.err().expect("input should be rejected");
        eprintln!("{error}");
        error
    }

    #[test]
    fn bad_elements_are_rejected_by_index() {
        let m = [material(1.0)];
        // Vertex 4 is the midpoint of edge 0-1, so tet 1 is flat.
        let mut flat = REST.to_vec();
        flat.extend((0..3).map(|i| 0.5 * (REST[i] + REST[3 + i])));
        let e = error(&flat, &[[0, 1, 2, 3], [0, 1, 4, 3]], &m);
        assert_eq!(e.location, Location::Element(1));
        assert!(e.message.contains("degenerate tet") && e.message.contains("rest volume"));

        let e = error(&REST, &[[0, 1, 2, 3], [0, 2, 1, 3]], &m);
        assert_eq!(e.location, Location::Element(1));
        assert!(e.message.contains("inverted tet") && e.message.contains("rest volume -"));

        let e = error(&REST, &[[0, 1, 2, 3], [0, 1, 2, 3], [0, 1, 2, 9]], &m);
        assert_eq!(e.location, Location::Element(2));
        assert!(e.message.contains("index 9"));
    }

    #[test]
    fn bad_materials_are_rejected_by_field() {
        let tets = [[0, 1, 2, 3], [0, 1, 2, 3], [0, 1, 2, 3]];
        let e = error(&REST, &tets, &[material(1.0), material(2.0)]);
        assert_eq!(e.location, Location::Field("materials".into()));
        assert!(e.message.contains("got 2"));

        let nan = ElementMaterial {
            poisson: f64::NAN,
            ..material(1.0)
        };
        let e = error(&REST, &tets, &[material(1.0), material(1.0), nan]);
        assert_eq!(e.location, Location::Field("materials[2].poisson".into()));
        let e = error(&REST, &tets, &[material(f64::INFINITY)]);
        assert_eq!(e.location, Location::Field("materials[0].youngs".into()));

        for (youngs, poisson, field) in [(0.0, 0.3, "youngs"), (1.0, 0.5, "poisson"), (1.0, -1.0, "poisson")] {
            let bad = ElementMaterial {
                poisson,
                ..material(youngs)
            };
            let e = error(&REST, &tets, &[bad]);
            assert_eq!(e.location, Location::Field(format!("materials[0].{field}")));
        }
    }
}
