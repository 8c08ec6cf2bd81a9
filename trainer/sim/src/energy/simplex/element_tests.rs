//! Tests of [`SimplexElastic`] run for both instances, tets ([`TET`]) and 2D triangles
//! ([`TRIANGLE`]): finite-difference derivatives, rest and rigid-motion invariance,
//! projection, the linear limit, per-element materials and the input errors.

use std::path::Path;

use nalgebra::SMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{checks, DeformationGradient, SimplexElastic};
use crate::energy::fd::assert_all_stencils;
use crate::energy::{gather, Local, StencilEnergy, Want};
use crate::error::{InputError, Location};
use crate::material::{ElementMaterial, MaterialLaw};

const MODELS: [MaterialLaw; 2] = [MaterialLaw::StableNeoHookean, MaterialLaw::Stvk];

/// A test element of `V` vertices and a second one sharing a facet with it.
pub struct Case<const V: usize> {
    /// A generic, well-shaped, positively oriented element (vertices `0..V`), flat.
    pub rest: &'static [f64],
    /// The extra vertex (number `V`) of the second element.
    extra: &'static [f64],
    /// The two elements sharing a facet.
    pair: [[usize; V]; 2],
    /// Poisson ratio of the test material.
    poisson: f64,
    /// Random seed.
    seed: u64,
}

/// A tet and a second one sharing a face.
pub const TET: Case<4> = Case {
    rest: &[
        0.1, -0.2, 0.0, //
        1.2, 0.1, 0.2, //
        0.2, 1.1, -0.1, //
        0.1, 0.3, 0.9,
    ],
    extra: &[1.0, 1.0, 0.6],
    pair: [[0, 1, 2, 3], [1, 2, 3, 4]],
    poisson: 0.35,
    seed: 7,
};

/// A counter-clockwise triangle and a second one sharing an edge.
pub const TRIANGLE: Case<3> = Case {
    rest: &[0.1, -0.2, 1.2, 0.1, 0.3, 0.9],
    extra: &[1.3, 1.0],
    pair: [[0, 1, 2], [1, 3, 2]],
    poisson: 0.4,
    seed: 11,
};

impl<const V: usize> Case<V> {
    fn material(&self, youngs: f64) -> ElementMaterial {
        ElementMaterial {
            youngs,
            poisson: self.poisson,
            density: 1000.0,
        }
    }

    fn rng(&self) -> ChaCha8Rng {
        ChaCha8Rng::seed_from_u64(self.seed)
    }
}

/// Runs the generic check `$f` for tets and for triangles.
macro_rules! both {
    ($f:ident) => {
        $f::<3, 9, 4>(&TET);
        $f::<2, 4, 3>(&TRIANGLE);
    };
}

/// The energy of the single element `case.rest`.
pub fn single<const D: usize, const N: usize, const V: usize>(
    case: &Case<V>,
    model: MaterialLaw,
) -> SimplexElastic<D, N>
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    let elements: [[usize; V]; 1] = [std::array::from_fn(|a| a)];
    SimplexElastic::new(model, case.rest, &elements, &[case.material(100.0)], Path::new("t")).unwrap()
}

/// The energy of `case`'s two elements, and their vertices moved independently.
fn pair<const D: usize, const N: usize, const V: usize>(
    case: &Case<V>,
    model: MaterialLaw,
    materials: &[ElementMaterial],
) -> (SimplexElastic<D, N>, Vec<f64>)
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    let rest = [case.rest, case.extra].concat();
    let energy = SimplexElastic::new(model, &rest, &case.pair, materials, Path::new("t")).unwrap();
    let mut r = case.rng();
    let x = rest.iter().map(|c| c + r.random_range(-0.3..0.3)).collect();
    (energy, x)
}

fn derivatives<const D: usize, const N: usize, const V: usize>(case: &Case<V>)
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    for model in MODELS {
        let energy = single::<D, N, V>(case, model);
        let (g, h) = checks::max_fd_errors(&energy, case.rest, 400, 1e-6, &mut case.rng());
        eprintln!("{D}D {model:?}: max relative FD error: gradient {g:.2e}, Hessian {h:.2e}");
        assert!(g < 1e-7 && h < 1e-7, "{D}D {model:?}: gradient {g:e}, Hessian {h:e}");
    }
}

#[test]
fn derivatives_match_finite_differences() {
    both!(derivatives);
}

fn invariance<const D: usize, const N: usize, const V: usize>(case: &Case<V>)
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    for model in MODELS {
        let energy = single::<D, N, V>(case, model);
        checks::assert_rest_and_rigid_invariance(&energy, case.rest, 100.0, &mut case.rng());
    }
}

#[test]
fn zero_at_rest_and_invariant_under_rigid_motion() {
    both!(invariance);
}

fn projection<const D: usize, const N: usize, const V: usize>(case: &Case<V>)
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    for model in MODELS {
        checks::assert_projection(&single::<D, N, V>(case, model), case.rest, &mut case.rng());
    }
}

#[test]
fn projected_hessian_is_psd_and_exact_where_already_psd() {
    both!(projection);
}

fn linear_limit<const D: usize, const N: usize, const V: usize>(case: &Case<V>)
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    let m = case.material(100.0);
    for model in MODELS {
        let energy = single::<D, N, V>(case, model);
        let measure = energy.rest_measures()[0];
        checks::assert_linear_limit(&energy, case.rest, measure, m.mu(), m.lambda(), &mut case.rng());
    }
}

/// In 2D the limit is plane-strain linear elasticity.
#[test]
fn small_strains_match_linear_elasticity() {
    both!(linear_limit);
}

fn mesh_stencils<const D: usize, const N: usize, const V: usize>(case: &Case<V>)
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    for model in MODELS {
        let (energy, x) = pair::<D, N, V>(case, model, &[case.material(100.0)]);
        assert_eq!(energy.stencil(1), &case.pair[1]);
        assert_all_stencils(&energy, &x, 1e-6, 1e-7);
    }
}

#[test]
fn mesh_stencils_match_finite_differences() {
    both!(mesh_stencils);
}

fn heterogeneous<const D: usize, const N: usize, const V: usize>(case: &Case<V>)
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    for model in MODELS {
        let (uniform, x) = pair::<D, N, V>(case, model, &[case.material(100.0)]);
        let (mixed, _) = pair::<D, N, V>(case, model, &[case.material(100.0), case.material(700.0)]);
        let mut out = Local::default();
        let mut xl = [0.0; 12];
        for (s, factor) in [(0, 1.0), (1, 7.0)] {
            let n = gather(&uniform, s, &x, &mut xl);
            let base = uniform.eval(s, &xl[..n], Want::Value, &mut out);
            let scaled = mixed.eval(s, &xl[..n], Want::Value, &mut out);
            assert!(base > 0.0);
            assert!((scaled - factor * base).abs() <= 1e-12 * scaled, "{D}D element {s}");
        }
    }
}

#[test]
fn heterogeneous_materials_scale_element_energies() {
    both!(heterogeneous);
}

/// The error of building the energy of `elements` over `rest`.
fn error<const D: usize, const N: usize, const V: usize>(
    rest: &[f64],
    elements: &[[usize; V]],
    materials: &[ElementMaterial],
) -> InputError
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    let model = MaterialLaw::StableNeoHookean;
    let result = SimplexElastic::<D, N>::new(model, rest, elements, materials, Path::new("m"));
    let error = result.err().expect("input should be rejected");
    eprintln!("{error}");
    error
}

fn bad_elements<const D: usize, const N: usize, const V: usize>(case: &Case<V>)
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    let (element, measure) = if D == 3 {
        ("tet", "volume")
    } else {
        ("triangle", "area")
    };
    let m = [case.material(1.0)];
    let first: [usize; V] = std::array::from_fn(|a| a);
    // Vertex V is the midpoint of edge 0-1, so element 1 (vertex 2 replaced by it) is flat.
    let mut flat = case.rest.to_vec();
    flat.extend((0..D).map(|i| 0.5 * (case.rest[i] + case.rest[D + i])));
    let mut flattened = first;
    flattened[2] = V;
    let e = error::<D, N, V>(&flat, &[first, flattened], &m);
    assert_eq!(e.location, Location::Element(1));
    assert!(e.message.contains(&format!("degenerate {element}")) && e.message.contains(&format!("rest {measure}")));

    let mut inverted = first;
    inverted.swap(1, 2);
    let e = error::<D, N, V>(case.rest, &[first, inverted], &m);
    assert_eq!(e.location, Location::Element(1));
    assert!(e.message.contains(&format!("inverted {element}")) && e.message.contains(&format!("rest {measure} -")));

    let mut outside = first;
    outside[V - 1] = 9;
    let e = error::<D, N, V>(case.rest, &[first, first, outside], &m);
    assert_eq!(e.location, Location::Element(2));
    assert!(e.message.contains("index 9"));

    let e = error::<D, N, V>(&case.rest[..case.rest.len() - 1], &[first], &m);
    assert_eq!(e.location, Location::Field("rest".into()));
}

#[test]
fn bad_elements_are_rejected_by_index() {
    both!(bad_elements);
}

fn bad_materials<const D: usize, const N: usize, const V: usize>(case: &Case<V>)
where
    SMatrix<f64, D, D>: DeformationGradient<D, N>,
{
    let material = |youngs| case.material(youngs);
    let first: [usize; V] = std::array::from_fn(|a| a);
    let elements = [first; 3];
    let rest = case.rest;
    let e = error::<D, N, V>(rest, &elements, &[material(1.0), material(2.0)]);
    assert_eq!(e.location, Location::Field("materials".into()));
    assert!(e.message.contains("got 2"));
    let e = error::<D, N, V>(rest, &elements, &[material(1.0); 4]);
    assert!(e.message.contains("got 4"));
    let e = error::<D, N, V>(rest, &elements, &[]);
    assert_eq!(e.location, Location::Field("materials".into()));

    let nan_poisson = ElementMaterial {
        poisson: f64::NAN,
        ..material(1.0)
    };
    let e = error::<D, N, V>(rest, &elements, &[material(1.0), material(1.0), nan_poisson]);
    assert_eq!(e.location, Location::Field("materials[2].poisson".into()));
    let e = error::<D, N, V>(rest, &elements, &[material(1.0), material(f64::NAN), material(1.0)]);
    assert_eq!(e.location, Location::Field("materials[1].youngs".into()));
    let e = error::<D, N, V>(rest, &elements, &[material(f64::INFINITY)]);
    assert_eq!(e.location, Location::Field("materials[0].youngs".into()));
    let nan_density = ElementMaterial {
        density: f64::NAN,
        ..material(1.0)
    };
    let e = error::<D, N, V>(rest, &elements, &[nan_density]);
    assert_eq!(e.location, Location::Field("materials[0].density".into()));

    for (youngs, poisson, field) in [(0.0, 0.3, "youngs"), (1.0, 0.5, "poisson"), (1.0, -1.0, "poisson")] {
        let bad = ElementMaterial {
            poisson,
            ..material(youngs)
        };
        let e = error::<D, N, V>(rest, &elements, &[bad]);
        assert_eq!(e.location, Location::Field(format!("materials[0].{field}")));
    }
}

#[test]
fn bad_materials_are_rejected_by_field() {
    both!(bad_materials);
}
