//! Tests of the non-negative least-squares solver, the greedy fit, the input errors and,
//! on a 2D neo-Hookean mesh in a nonlinear subspace, the accuracy of the fitted cubature on
//! held-out samples.

use std::path::Path;

use nalgebra::{DMatrix, DVector};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::nnls::nnls;
use super::*;
use crate::energy::tri2d::Tri2dElastic;
use crate::energy::{add_gradient_sequential, gather, value, MAX_DOF};
use crate::material::{ElementMaterial, MaterialLaw};

/// A standard normal sample (Box-Muller).
fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u: f64 = rng.random_range(f64::EPSILON..1.0);
    let v: f64 = rng.random();
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

fn random_matrix(rows: usize, cols: usize, rng: &mut ChaCha8Rng) -> DMatrix<f64> {
    DMatrix::from_fn(rows, cols, |_, _| normal(rng))
}

#[test]
fn nnls_equals_least_squares_when_that_is_non_negative() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let c = random_matrix(30, 8, &mut rng);
    let truth = DVector::from_fn(8, |_, _| rng.random_range(0.5..2.0));
    let noise = DVector::from_fn(30, |_, _| 1e-3 * normal(&mut rng));
    let d = &c * &truth + noise;
    let unconstrained = c.clone().svd(true, true).solve(&d, 1e-14).unwrap();
    assert!(unconstrained.iter().all(|&v| v > 0.0));
    for start in [None, Some(DVector::from_element(8, 1.0))] {
        let x = nnls(&c, &d, start.as_ref());
        assert!((&x - &unconstrained).amax() < 1e-12, "{x} vs {unconstrained}");
    }
}

#[test]
fn nnls_satisfies_the_kkt_conditions() {
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    for (rows, cols) in [(20, 12), (10, 25)] {
        let c = random_matrix(rows, cols, &mut rng);
        let d = DVector::from_fn(rows, |_, _| normal(&mut rng));
        let cold = nnls(&c, &d, None);
        let warm = nnls(&c, &d, Some(&DVector::from_element(cols, 0.3)));
        for x in [&cold, &warm] {
            // Gradient of 1/2 ||c x - d||^2.
            let gradient = c.tr_mul(&(&c * x - &d));
            let scale = c.amax() * d.norm();
            let (mut zeros, mut positives) = (0, 0);
            for j in 0..cols {
                assert!(x[j] >= 0.0);
                if x[j] == 0.0 {
                    zeros += 1;
                    assert!(
                        gradient[j] >= -1e-10 * scale,
                        "gradient {} on a zero weight",
                        gradient[j]
                    );
                } else {
                    positives += 1;
                    assert!(
                        gradient[j].abs() <= 1e-10 * scale,
                        "gradient {} on a positive weight",
                        gradient[j]
                    );
                }
            }
            assert!(
                zeros > 0 && positives > 0,
                "{zeros} zero and {positives} positive weights"
            );
        }
        // Both are minimisers: equal residuals, and equal weights where the minimiser is
        // unique (independent columns).
        let residual = |x: &DVector<f64>| (&c * x - &d).norm();
        assert!((residual(&cold) - residual(&warm)).abs() < 1e-10 * d.norm());
        if rows > cols {
            assert!((&cold - &warm).amax() < 1e-10);
        }
    }
}

/// A `rows x (3 + 2 pairs)` matrix whose row sums are the sum of its first three columns:
/// the other columns come in pairs `c, -c`.
fn three_generators(rows: usize, pairs: usize, rng: &mut ChaCha8Rng) -> ColumnMatrix {
    let cols = 3 + 2 * pairs;
    let mut a = ColumnMatrix::zeros(rows, cols);
    for e in 0..3 + pairs {
        let column: Vec<f64> = (0..rows).map(|_| normal(rng)).collect();
        a.column_mut(e).copy_from_slice(&column);
        if e >= 3 {
            a.column_mut(e + pairs)
                .iter_mut()
                .zip(&column)
                .for_each(|(o, v)| *o = -v);
        }
    }
    a
}

#[test]
fn greedy_fit_recovers_a_sparse_non_negative_combination() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let a = three_generators(60, 100, &mut rng);
    let settings = CubatureSettings {
        tolerance: 1e-10,
        ..Default::default()
    };
    let (cubature, fit) = fit_cubature(&a, &settings).unwrap();
    assert_eq!(cubature.elements, vec![0, 1, 2]);
    cubature
        .weights
        .iter()
        .for_each(|w| assert!((w - 1.0).abs() < 1e-12, "{w}"));
    assert!(fit.relative_residual < 1e-12);
    assert_eq!(fit.iterations, 3);
}

#[test]
fn greedy_fit_with_random_candidates_is_deterministic_and_converges() {
    let mut rng = ChaCha8Rng::seed_from_u64(4);
    let a = three_generators(40, 150, &mut rng);
    let settings = CubatureSettings {
        tolerance: 1e-8,
        candidates: 20,
        seed: 9,
        ..Default::default()
    };
    let (cubature, fit) = fit_cubature(&a, &settings).unwrap();
    assert!(fit.relative_residual <= 1e-8, "{fit:?}");
    assert!(cubature.elements.len() <= 40);
    assert!(cubature.elements.windows(2).all(|p| p[0] < p[1]));
    assert!(cubature.weights.iter().all(|&w| w > 0.0));
    assert_eq!(fit_cubature(&a, &settings).unwrap(), (cubature, fit));
}

#[test]
fn the_size_limit_is_respected() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let a = ColumnMatrix::from_columns(30, 200, |_, c| c.iter_mut().for_each(|v| *v = normal(&mut rng)));
    let settings = CubatureSettings {
        max_elements: 7,
        tolerance: 0.0,
        ..Default::default()
    };
    let (cubature, fit) = fit_cubature(&a, &settings).unwrap();
    assert!(cubature.elements.len() <= 7);
    assert!(fit.relative_residual > 0.0 && fit.relative_residual < 1.0);
}

#[test]
fn bad_input_is_an_error() {
    let settings = CubatureSettings::default();
    assert_eq!(
        ColumnMatrix::from_column_major(2, 3, vec![1.0; 5]),
        Err(CubatureError::Shape {
            rows: 2,
            cols: 3,
            len: 5
        })
    );
    let empty = ColumnMatrix::zeros(0, 4);
    assert_eq!(
        fit_cubature(&empty, &settings),
        Err(CubatureError::Empty { rows: 0, cols: 4 })
    );
    let mut a = ColumnMatrix::from_column_major(2, 2, vec![1.0, 2.0, 3.0, 4.0]).unwrap();
    for (field, bad) in [
        (
            "max_elements",
            CubatureSettings {
                max_elements: 0,
                ..Default::default()
            },
        ),
        (
            "candidates",
            CubatureSettings {
                candidates: 0,
                ..Default::default()
            },
        ),
        (
            "tolerance",
            CubatureSettings {
                tolerance: f64::NAN,
                ..Default::default()
            },
        ),
        (
            "tolerance",
            CubatureSettings {
                tolerance: -1.0,
                ..Default::default()
            },
        ),
    ] {
        assert!(matches!(fit_cubature(&a, &bad), Err(CubatureError::Settings { field: f, .. }) if f == field));
    }
    a.column_mut(1)[0] = f64::INFINITY;
    assert!(matches!(
        fit_cubature(&a, &settings),
        Err(CubatureError::NonFinite { row: 0, column: 1, .. })
    ));
    let cancelling = ColumnMatrix::from_column_major(2, 2, vec![1.0, -2.0, -1.0, 2.0]).unwrap();
    assert_eq!(fit_cubature(&cancelling, &settings), Err(CubatureError::ZeroTarget));

    let (energy, _) = grid(3, 2);
    let rule = |elements: Vec<usize>, weights: Vec<f64>| Cubature { elements, weights };
    assert!(matches!(
        CubatureEnergy::new(&energy, rule(vec![0, 1], vec![1.0])),
        Err(CubatureError::Length {
            elements: 2,
            weights: 1
        })
    ));
    assert!(matches!(
        CubatureEnergy::new(&energy, rule(vec![0, 12], vec![1.0, 1.0])),
        Err(CubatureError::ElementRange {
            element: 12,
            stencils: 12
        })
    ));
    assert!(matches!(
        CubatureEnergy::new(&energy, rule(vec![0, 1], vec![1.0, -0.5])),
        Err(CubatureError::Weight { index: 1, .. })
    ));
    assert!(CubatureEnergy::new(&energy, rule(vec![0, 11], vec![1.0, 0.0])).is_ok());
}

/// Stable neo-Hookean triangles on an `nx x ny` grid over `[0, 2] x [0, 1]`, two
/// counter-clockwise triangles per cell; returns the energy and the rest positions.
fn grid(nx: usize, ny: usize) -> (Tri2dElastic, Vec<f64>) {
    let id = |i: usize, j: usize| j * (nx + 1) + i;
    let mut rest = Vec::new();
    for j in 0..=ny {
        for i in 0..=nx {
            rest.extend([2.0 * i as f64 / nx as f64, j as f64 / ny as f64]);
        }
    }
    let mut tris = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    let material = ElementMaterial {
        youngs: 1e4,
        poisson: 0.4,
        density: 1.0,
    };
    let energy = Tri2dElastic::new(
        MaterialLaw::StableNeoHookean,
        &rest,
        &tris,
        &[material],
        Path::new("<grid>"),
    )
    .expect("valid grid");
    (energy, rest)
}

/// The subspace `x = X0 + U z + V (z o z)` with smooth random fields `U`, `V` (sums of
/// cosine modes of the rest coordinates, each column scaled to unit largest entry).
struct Subspace {
    rest: Vec<f64>,
    u: DMatrix<f64>,
    v: DMatrix<f64>,
}

impl Subspace {
    fn new(rest: Vec<f64>, r: usize, rng: &mut ChaCha8Rng) -> Self {
        let n = rest.len();
        let field = |rng: &mut ChaCha8Rng| {
            let mut m = DMatrix::zeros(n, r);
            for k in 0..r {
                for i in 0..2 {
                    for a in 0..3_usize {
                        for b in 0..3 {
                            let c = normal(rng) / (1 + a + b).pow(2) as f64;
                            for p in 0..n / 2 {
                                let (px, py) = (rest[2 * p], rest[2 * p + 1]);
                                let mode = (std::f64::consts::PI * a as f64 * px / 2.0).cos()
                                    * (std::f64::consts::PI * b as f64 * py).cos();
                                m[(2 * p + i, k)] += c * mode;
                            }
                        }
                    }
                }
                let largest = m.column(k).amax();
                m.column_mut(k).scale_mut(1.0 / largest);
            }
            m
        };
        let u = field(rng);
        let v = field(rng);
        Subspace { rest, u, v }
    }

    fn position(&self, z: &DVector<f64>) -> Vec<f64> {
        let x = DVector::from_column_slice(&self.rest) + &self.u * z + &self.v * z.component_mul(z);
        x.as_slice().to_vec()
    }

    /// `J = U + 2 V diag(z)`.
    fn jacobian(&self, z: &DVector<f64>) -> DMatrix<f64> {
        let mut j = self.u.clone();
        for k in 0..z.len() {
            j.column_mut(k).axpy(2.0 * z[k], &self.v.column(k), 1.0);
        }
        j
    }
}

/// Smallest ratio of deformed to rest triangle area.
fn smallest_area_ratio(energy: &Tri2dElastic, rest: &[f64], x: &[f64]) -> f64 {
    let area = |p: &[f64], s: usize| {
        let t = energy.stencil(s);
        crate::energy::tri2d::signed_area([0, 1, 2].map(|a| [p[2 * t[a]], p[2 * t[a] + 1]]))
    };
    (0..energy.len())
        .map(|s| area(x, s) / area(rest, s))
        .fold(f64::INFINITY, f64::min)
}

/// Per element: the energy and the reduced gradient `J^T grad P_e`, written into `column`
/// (`1 + r` entries).
fn element_rows(energy: &dyn StencilEnergy, s: usize, x: &[f64], j: &DMatrix<f64>, column: &mut [f64]) {
    let mut local = [0.0; MAX_DOF];
    let mut out = Local::default();
    let n = gather(energy, s, x, &mut local);
    column[0] = energy.eval(s, &local[..n], Want::Gradient, &mut out);
    for k in 0..j.ncols() {
        column[1 + k] = energy
            .stencil(s)
            .iter()
            .enumerate()
            .map(|(a, &v)| (0..2).map(|i| j[(2 * v + i, k)] * out.grad[2 * a + i]).sum::<f64>())
            .sum();
    }
}

/// On a 24 x 12 grid (576 stable neo-Hookean triangles), in a quadratic subspace with
/// `r = 5`, a cubature fitted with the default settings on 40 samples `z ~ N(0, 0.06^2)`
/// (triangle areas shrink to 0.56 of their rest area at most, none inverts) reproduces, on
/// 20 held-out samples, the energy and the reduced gradient `J^T grad P`. Measured: 28
/// elements (1/20 of the mesh) after 33 greedy steps, training residual 9.4e-4, held-out
/// energy error at most 3.7e-3 relative and reduced-gradient error at most 2.9e-3 relative
/// to its norm; the test allows 1e-2 and 5e-2, and at most a quarter of the elements.
#[test]
fn cubature_reproduces_held_out_energy_and_reduced_forces() {
    let (energy, rest) = grid(24, 12);
    let r = 5;
    let scale = 0.06;
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    let subspace = Subspace::new(rest.clone(), r, &mut rng);
    let sample = |rng: &mut ChaCha8Rng| DVector::from_fn(r, |_, _| scale * normal(rng));
    let training: Vec<DVector<f64>> = (0..40).map(|_| sample(&mut rng)).collect();
    let held_out: Vec<DVector<f64>> = (0..20).map(|_| sample(&mut rng)).collect();

    let rows = 1 + r;
    let mut a = ColumnMatrix::zeros(rows * training.len(), energy.len());
    let mut smallest = f64::INFINITY;
    for (i, z) in training.iter().enumerate() {
        let x = subspace.position(z);
        let j = subspace.jacobian(z);
        smallest = smallest.min(smallest_area_ratio(&energy, &rest, &x));
        for s in 0..energy.len() {
            element_rows(&energy, s, &x, &j, &mut a.column_mut(s)[rows * i..rows * (i + 1)]);
        }
    }
    // Each sample's energy row and force rows divided by the norms of their targets.
    let sums = a.row_sums();
    for i in 0..training.len() {
        let energy_norm = sums[rows * i].abs();
        let force_norm = sums[rows * i + 1..rows * (i + 1)]
            .iter()
            .map(|v| v * v)
            .sum::<f64>()
            .sqrt();
        for s in 0..energy.len() {
            let column = a.column_mut(s);
            column[rows * i] /= energy_norm;
            column[rows * i + 1..rows * (i + 1)]
                .iter_mut()
                .for_each(|v| *v /= force_norm);
        }
    }
    let (cubature, fit) = fit_cubature(&a, &CubatureSettings::default()).unwrap();
    let cubature_energy = CubatureEnergy::new(&energy, cubature.clone()).unwrap();
    let selected = cubature.elements.len();
    eprintln!("smallest area ratio {smallest:.3}, {selected} elements, {fit:?}");
    assert!(smallest > 0.5, "{smallest}");
    assert!(fit.relative_residual <= 1e-3);
    assert!(selected < energy.len() / 4, "{selected} of {} elements", energy.len());

    let (mut worst_energy, mut worst_gradient) = (0.0_f64, 0.0_f64);
    for z in &held_out {
        let x = subspace.position(z);
        let j = subspace.jacobian(z);
        let reduced = |e: &dyn StencilEnergy| {
            let mut g = vec![0.0; x.len()];
            let p = add_gradient_sequential(e, 1.0, &x, &mut g);
            (p, j.tr_mul(&DVector::from_vec(g)))
        };
        let (full, full_gradient) = reduced(&energy);
        let (approx, approx_gradient) = reduced(&cubature_energy);
        worst_energy = worst_energy.max((approx - full).abs() / full.abs());
        worst_gradient = worst_gradient.max((&approx_gradient - &full_gradient).norm() / full_gradient.norm());

        // The wrapped energy is exactly the weighted sum of the selected element energies.
        let mut direct = 0.0;
        let mut column = vec![0.0; 1 + r];
        for (&e, &w) in cubature.elements.iter().zip(&cubature.weights) {
            element_rows(&energy, e, &x, &j, &mut column);
            direct += w * column[0];
        }
        let total = value(&cubature_energy, &x);
        assert!((total - direct).abs() <= 1e-12 * direct.abs(), "{total} vs {direct}");
        assert!((approx - direct).abs() <= 1e-12 * direct.abs());
    }
    eprintln!("held out: energy error {worst_energy:.2e}, reduced gradient error {worst_gradient:.2e}");
    assert!(worst_energy < 1e-2, "{worst_energy}");
    assert!(worst_gradient < 5e-2, "{worst_gradient}");
}

#[test]
fn cubature_energy_scales_each_stencil_by_its_weight() {
    let (energy, rest) = grid(3, 2);
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let x: Vec<f64> = rest.iter().map(|p| p + 0.05 * normal(&mut rng)).collect();
    let cubature = Cubature {
        elements: vec![2, 5, 9],
        weights: vec![0.5, 3.0, 1.25],
    };
    let wrapped = CubatureEnergy::new(&energy, cubature.clone()).unwrap();
    assert_eq!((wrapped.len(), wrapped.dim(), wrapped.name()), (3, 2, energy.name()));
    for project in [false, true] {
        let want = Want::Hessian { project };
        for (s, (&e, &w)) in cubature.elements.iter().zip(&cubature.weights).enumerate() {
            assert_eq!(wrapped.stencil(s), energy.stencil(e));
            let mut local = [0.0; MAX_DOF];
            let n = gather(&energy, e, &x, &mut local);
            let (mut inner, mut outer) = (Local::default(), Local::default());
            let v = energy.eval(e, &local[..n], want, &mut inner);
            let scaled = wrapped.eval(s, &local[..n], want, &mut outer);
            assert_eq!(scaled, w * v);
            (0..n).for_each(|k| assert_eq!(outer.grad[k], w * inner.grad[k]));
            (0..n * n).for_each(|k| assert_eq!(outer.hess[k], w * inner.hess[k]));
        }
    }
}
