//! The per-subdomain elastic subspace Hessian: exact evaluations against a dense projection
//! of the assembled Hessian, the exact/approximated split, and the secant updates.

use faer::Mat;
use nalgebra::{DMatrix, DVector};

use super::fixtures::{random_matrix, random_vector, rng, rubber_beam};
use crate::adaptive::elastic_subspace::ElasticSubspace;
use crate::adaptive::oracle::WeightedTerm;
use crate::adaptive::partition::Partition;
use crate::dofs::{free_dof_index, NOT_FREE};
use crate::energy::{self, tet::TetElastic, StencilEnergy};

struct Case {
    elastic: TetElastic,
    partition: Partition,
    free_index: Vec<usize>,
    /// Candidate columns over every dof.
    modes: Mat<f64>,
    rest: Vec<f64>,
}

/// A 6 x 2 x 2 rubber beam in 5 subdomains, its vertices at `x = 0` prescribed, and 7
/// random candidate columns.
fn case() -> Case {
    let (mesh, elastic) = rubber_beam([6, 2, 2]);
    let fixed: Vec<usize> = (0..mesh.num_vertices()).filter(|&v| mesh.rest[3 * v] == 0.0).collect();
    let (free_index, _) = free_dof_index(3, mesh.rest.len(), &fixed);
    let mut rng = rng(3);
    Case {
        partition: Partition::new(&mesh, 5).unwrap(),
        modes: {
            let m = random_matrix(mesh.rest.len(), 7, &mut rng);
            Mat::from_fn(m.nrows(), m.ncols(), |r, c| 0.1 * m[(r, c)])
        },
        elastic,
        free_index,
        rest: mesh.rest.clone(),
    }
}

impl Case {
    fn subspace(&self) -> ElasticSubspace {
        let e = &self.elastic;
        let stencils = vec![(0..e.len()).map(|s| e.stencil(s).to_vec()).collect()];
        let p = &self.partition;
        ElasticSubspace::new(3, stencils, p.vertex_subdomains(), p.num_subdomains())
    }

    /// The columns over the free dofs (zero rows on the prescribed ones).
    fn basis(&self, columns: &[usize]) -> DMatrix<f64> {
        DMatrix::from_fn(self.rest.len(), columns.len(), |r, j| {
            if self.free_index[r] == NOT_FREE {
                0.0
            } else {
                self.modes[(r, columns[j])]
            }
        })
    }

    /// The dense Hessian (each stencil's projected to positive semi-definite, as the
    /// evaluations do) and gradient of the listed stencils at `x`.
    fn dense(&self, stencils: &[usize], x: &[f64]) -> (DMatrix<f64>, DVector<f64>) {
        let n = x.len();
        let (mut h, mut g) = (DMatrix::zeros(n, n), DVector::zeros(n));
        energy::for_each_hessian_of(&self.elastic, Some(stencils), x, true, |s, _, local| {
            let verts = self.elastic.stencil(s);
            let k = verts.len() * 3;
            for r in 0..k {
                let gr = verts[r / 3] * 3 + r % 3;
                g[gr] += local.grad[r];
                for c in 0..k {
                    h[(gr, verts[c / 3] * 3 + c % 3)] += local.hess[r * k + c];
                }
            }
        });
        (h, g)
    }

    /// A bent and perturbed state.
    fn deformed(&self, seed: u64) -> Vec<f64> {
        let mut rng = rng(seed);
        let noise = random_vector(self.rest.len(), &mut rng);
        self.rest
            .chunks_exact(3)
            .flat_map(|p| [p[0], p[1], p[2] + 0.03 * p[0] * p[0]])
            .zip(noise)
            .map(|(x, r)| x + 0.01 * r)
            .collect()
    }
}

fn relative(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).norm() / b.norm()
}

#[test]
fn an_exact_evaluation_is_the_projection_of_the_assembled_hessian() {
    let case = case();
    let mut subspace = case.subspace();
    let columns = [0, 2, 3, 6];
    let x = case.deformed(1);
    let weight = 0.3;
    let terms = [WeightedTerm {
        energy: &case.elastic,
        weight,
    }];
    let coefficients = vec![0.0; case.modes.ncols()];
    subspace.prepare(&terms, &x, &case.modes, &case.free_index, &columns, &coefficients);
    let all: Vec<usize> = (0..case.elastic.len()).collect();
    let (h, _) = case.dense(&all, &x);
    let w = case.basis(&columns);
    let expected = w.transpose() * &h * &w * weight;
    let sum = subspace.approximated_sum(&columns).unwrap();
    assert!(relative(&sum, &expected) < 1e-12, "{}", relative(&sum, &expected));
    assert!(subspace.approximated_sum(&[0, 2]).is_none(), "other columns");
    assert_eq!(subspace.stats().evaluations, 1);
    assert!(subspace.exact_stencils(0).is_empty());

    // Enriching a vertex makes exact every subdomain with a stencil touching it: those
    // stencils leave the approximated sum, and are listed for the simulator.
    let far = (0..case.rest.len() / 3)
        .max_by(|&a, &b| case.rest[3 * a].total_cmp(&case.rest[3 * b]))
        .unwrap();
    let mut enriched = vec![false; case.rest.len() / 3];
    enriched[far] = true;
    subspace.set_enriched(&enriched);
    let exact = subspace.exact_stencils(0);
    assert_eq!(subspace.newly_exact_stencils(0), exact);
    assert!(exact.iter().any(|&s| case.elastic.stencil(s).contains(&far)));
    for s in 0..case.elastic.len() {
        if case.elastic.stencil(s).contains(&far) {
            assert!(exact.contains(&s), "stencil {s} touches the enriched vertex");
        }
    }
    let exact_count = subspace.exact_subdomains().iter().filter(|&&e| e).count();
    assert!(exact_count >= 1 && exact_count < case.partition.num_subdomains());
    subspace.take_newly_exact();
    assert!(subspace.newly_exact_stencils(0).is_empty());
    let approximated: Vec<usize> = all.iter().copied().filter(|s| !exact.contains(s)).collect();
    let (h_approx, _) = case.dense(&approximated, &x);
    let expected = w.transpose() * &h_approx * &w * weight;
    let sum = subspace.approximated_sum(&columns).unwrap();
    assert!(relative(&sum, &expected) < 1e-12, "{}", relative(&sum, &expected));
}

#[test]
fn each_later_iterate_updates_the_approximations_by_its_secant_pair() {
    let case = case();
    let mut subspace = case.subspace();
    let columns = [1, 2, 4, 5, 6];
    let weight = 2.0;
    let terms = [WeightedTerm {
        energy: &case.elastic,
        weight,
    }];
    let x0 = case.deformed(2);
    let mut coefficients = vec![0.0; case.modes.ncols()];
    subspace.prepare(&terms, &x0, &case.modes, &case.free_index, &columns, &coefficients);
    let before = subspace.approximated_sum(&columns).unwrap();
    // A modal step of the active columns (the others' coefficients must not matter).
    let s = DVector::from_vec(vec![0.02, -0.01, 0.015, 0.01, -0.02]);
    for (&c, v) in columns.iter().zip(s.iter()) {
        coefficients[c] = *v;
    }
    coefficients[0] = 5.0;
    let w = case.basis(&columns);
    let x1: Vec<f64> = (DVector::from_column_slice(&x0) + &w * &s).as_slice().to_vec();
    subspace.prepare(&terms, &x1, &case.modes, &case.free_index, &columns, &coefficients);
    let stats = subspace.stats();
    assert_eq!(stats.evaluations, 1, "no new exact evaluation");
    // A small step from a mildly bent state: every subdomain's curvature is positive.
    assert_eq!(stats.updates, case.partition.num_subdomains(), "{stats:?}");
    assert_eq!(stats.skipped, 0, "{stats:?}");
    let after = subspace.approximated_sum(&columns).unwrap();
    assert!(relative(&after, &before) > 1e-8, "the update changed nothing");
    // Every subdomain's secant condition holds, so their sum's does.
    let all: Vec<usize> = (0..case.elastic.len()).collect();
    let (_, g0) = case.dense(&all, &x0);
    let (_, g1) = case.dense(&all, &x1);
    let y = w.transpose() * (g1 - g0) * weight;
    let hs = &after * &s;
    assert!((&hs - &y).norm() < 1e-9 * y.norm(), "{hs} vs {y}");
    // Other columns start again from exact values.
    subspace.prepare(&terms, &x1, &case.modes, &case.free_index, &columns[1..], &coefficients);
    assert_eq!(subspace.stats().evaluations, 2);
    assert!(subspace.is_current(&columns[1..]) && !subspace.is_current(&columns));
    subspace.begin_step();
    assert!(!subspace.is_current(&columns[1..]));
    assert_eq!(subspace.stats().evaluations, 0);
}
