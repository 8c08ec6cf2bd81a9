//! The Schur-complement solver against dense solves of the assembled block system, its
//! edge cases and errors, and the full-space baselines.

use nalgebra::{Cholesky, DMatrix};

use super::fixtures::{
    dense_direction, full_csc, lower_csc, random_matrix, random_sparse_spd, random_spd, random_vector, relative_error,
    rng, tet_hessian,
};
use crate::adaptive::full_space::{cholesky_direction, pcg_direction};
use crate::adaptive::partition::Partition;
use crate::adaptive::pcg::PcgSettings;
use crate::adaptive::schur::{AdaptiveSystem, Coupling};
use crate::adaptive::SolveError;

/// The assembled block matrix `[[H_q, C], [C^T, H_x]]`.
fn assemble(h_q: &DMatrix<f64>, c: &DMatrix<f64>, h_x: &DMatrix<f64>) -> DMatrix<f64> {
    let (a, n) = (h_q.nrows(), h_x.nrows());
    let mut k = DMatrix::zeros(a + n, a + n);
    k.view_mut((0, 0), (a, a)).copy_from(h_q);
    k.view_mut((0, a), (a, n)).copy_from(c);
    k.view_mut((a, 0), (n, a)).copy_from(&c.transpose());
    k.view_mut((a, a), (n, n)).copy_from(h_x);
    k
}

/// A random block system: SPD `H_q` (`a x a`), sparse SPD `H_x` over `nodes` nodes, and a
/// coupling small enough to keep the whole matrix SPD; with gradients.
struct RandomSystem {
    h_q: DMatrix<f64>,
    c: DMatrix<f64>,
    h_x: DMatrix<f64>,
    g_q: Vec<f64>,
    g_x: Vec<f64>,
}

fn random_system(a: usize, nodes: usize, seed: u64) -> RandomSystem {
    let mut rng = rng(seed);
    let h_q = random_spd(a, a as f64, &mut rng);
    let h_x = random_sparse_spd(nodes, 0.5, &mut rng);
    let mut c = random_matrix(a, 3 * nodes, &mut rng) * 0.3;
    // Only some nodes couple to the subspace, as with enriched vertices next to it.
    for node in 0..nodes {
        if node % 3 == 0 {
            c.columns_mut(3 * node, 3).fill(0.0);
        }
    }
    let g_q = random_vector(a, &mut rng);
    let g_x = random_vector(3 * nodes, &mut rng);
    RandomSystem { h_q, c, h_x, g_q, g_x }
}

/// Solves `system` with a dense coupling and checks it against the dense solve.
fn check_against_dense(s: &RandomSystem, tolerance: f64, max_error: f64) -> usize {
    let h_x = lower_csc(&s.h_x);
    let system = AdaptiveSystem {
        h_q: &s.h_q,
        coupling: Coupling::Dense(&s.c),
        h_x: h_x.as_ref(),
        g_q: &s.g_q,
        g_x: &s.g_x,
    };
    let settings = PcgSettings {
        tolerance,
        ..PcgSettings::default()
    };
    let solution = system.solve(&settings).expect("SPD system");
    assert!(solution.report.converged);
    assert!(
        solution.report.relative_residual <= 2.0 * tolerance,
        "{:?}",
        solution.report
    );
    let g: Vec<f64> = s.g_q.iter().chain(&s.g_x).copied().collect();
    let want = dense_direction(&assemble(&s.h_q, &s.c, &s.h_x), &g);
    let got: Vec<f64> = solution.d_q.iter().chain(&solution.d_x).copied().collect();
    let err = relative_error(&got, &want);
    assert!(err < max_error, "relative error {err:e} at tolerance {tolerance:e}");
    solution.report.iterations
}

#[test]
fn schur_solve_matches_a_dense_solve_of_the_block_system() {
    for seed in 0..4 {
        let s = random_system(8, 30, seed);
        let loose = check_against_dense(&s, 1e-5, 1e-4);
        let tight = check_against_dense(&s, 1e-11, 1e-9);
        assert!(
            tight > loose,
            "a tighter tolerance takes more iterations ({tight} vs {loose})"
        );
    }
}

#[test]
fn sparse_and_dense_couplings_give_the_same_solution() {
    let s = random_system(6, 25, 7);
    let h_x = lower_csc(&s.h_x);
    let c_sparse = full_csc(&s.c);
    let settings = PcgSettings::default();
    let solve = |coupling| {
        AdaptiveSystem {
            h_q: &s.h_q,
            coupling,
            h_x: h_x.as_ref(),
            g_q: &s.g_q,
            g_x: &s.g_x,
        }
        .solve(&settings)
        .expect("SPD system")
    };
    let dense = solve(Coupling::Dense(&s.c));
    let sparse = solve(Coupling::Sparse(c_sparse.as_ref()));
    assert_eq!(dense.report.iterations, sparse.report.iterations);
    assert!(relative_error(&sparse.d_x, &dense.d_x) < 1e-12);
    assert!(relative_error(&sparse.d_q, &dense.d_q) < 1e-12);
}

#[test]
fn preconditioner_blocks_are_the_schur_complements_diagonal_blocks() {
    let s = random_system(5, 12, 3);
    let h_x = lower_csc(&s.h_x);
    let system = AdaptiveSystem {
        h_q: &s.h_q,
        coupling: Coupling::Dense(&s.c),
        h_x: h_x.as_ref(),
        g_q: &s.g_q,
        g_x: &s.g_x,
    };
    let chol = Cholesky::new(s.h_q.clone()).expect("SPD");
    let blocks = system.schur_diagonal_blocks(&chol, 3);
    let schur = &s.h_x - s.c.transpose() * s.h_q.clone().try_inverse().expect("invertible") * &s.c;
    for k in 0..12 {
        for i in 0..3 {
            for j in 0..3 {
                let want = schur[(3 * k + i, 3 * k + j)];
                let got = blocks[9 * k + 3 * i + j];
                assert!(
                    (got - want).abs() < 1e-10 * want.abs().max(1.0),
                    "block {k} ({i}, {j}): {got} vs {want}"
                );
            }
        }
    }
}

#[test]
fn no_enriched_vertices_solve_the_subspace_system_alone() {
    let s = random_system(7, 1, 11);
    let empty_hx = lower_csc(&DMatrix::zeros(0, 0));
    let c = DMatrix::zeros(7, 0);
    let solution = AdaptiveSystem {
        h_q: &s.h_q,
        coupling: Coupling::Dense(&c),
        h_x: empty_hx.as_ref(),
        g_q: &s.g_q,
        g_x: &[],
    }
    .solve(&PcgSettings::default())
    .expect("SPD H_q");
    assert!(solution.d_x.is_empty());
    assert_eq!(solution.report.iterations, 0);
    assert!(relative_error(&solution.d_q, &dense_direction(&s.h_q, &s.g_q)) < 1e-12);
}

#[test]
fn no_subspace_coordinates_solve_the_vertex_system_alone() {
    let s = random_system(1, 20, 12);
    let h_q = DMatrix::zeros(0, 0);
    let c = DMatrix::zeros(0, 60);
    let h_x = lower_csc(&s.h_x);
    let settings = PcgSettings {
        tolerance: 1e-12,
        ..PcgSettings::default()
    };
    let solution = AdaptiveSystem {
        h_q: &h_q,
        coupling: Coupling::Dense(&c),
        h_x: h_x.as_ref(),
        g_q: &[],
        g_x: &s.g_x,
    }
    .solve(&settings)
    .expect("SPD H_x");
    assert!(solution.d_q.is_empty());
    assert!(solution.report.converged);
    assert!(relative_error(&solution.d_x, &dense_direction(&s.h_x, &s.g_x)) < 1e-10);
}

#[test]
fn an_indefinite_subspace_hessian_is_an_error() {
    let s = random_system(4, 10, 13);
    let h_x = lower_csc(&s.h_x);
    let mut h_q = s.h_q.clone();
    h_q[(2, 2)] = -1.0;
    let mut nan = s.h_q.clone();
    nan[(0, 1)] = f64::NAN;
    for (h_q, want) in [
        (h_q, SolveError::NotPositiveDefinite("H_q")),
        (nan, SolveError::NonFinite("H_q")),
    ] {
        let result = AdaptiveSystem {
            h_q: &h_q,
            coupling: Coupling::Dense(&s.c),
            h_x: h_x.as_ref(),
            g_q: &s.g_q,
            g_x: &s.g_x,
        }
        .solve(&PcgSettings::default());
        let err = result.expect_err("bad H_q");
        assert_eq!(err, want);
        assert!(err.to_string().contains("H_q"), "{err}");
    }
}

/// Whether an error is the one expected.
type ErrorCheck = fn(&SolveError) -> bool;

#[test]
fn an_indefinite_vertex_block_and_bad_shapes_are_errors() {
    let s = random_system(4, 10, 14);
    let settings = PcgSettings::default();
    let mut indefinite = s.h_x.clone();
    for i in 0..30 {
        indefinite[(i, i)] -= 40.0;
    }
    let bad = lower_csc(&indefinite);
    let good = lower_csc(&s.h_x);
    let upper = full_csc(&s.h_x);
    let short_g = vec![0.0; 29];
    let wrong_c = DMatrix::zeros(4, 27);
    let cases: [(_, &DMatrix<f64>, &[f64], ErrorCheck); 4] = [
        (bad.as_ref(), &s.c, &s.g_x, |e| {
            matches!(
                e,
                SolveError::PreconditionerBlock { .. } | SolveError::Indefinite { .. }
            )
        }),
        (upper.as_ref(), &s.c, &s.g_x, |e| {
            matches!(e, SolveError::UpperEntry { matrix: "H_x", .. })
        }),
        (good.as_ref(), &s.c, &short_g, |e| {
            matches!(e, SolveError::Dimension { what: "g_x", .. })
        }),
        (good.as_ref(), &wrong_c, &s.g_x, |e| {
            matches!(e, SolveError::Dimension { what: "C", .. })
        }),
    ];
    for (h_x, c, g_x, expected) in cases {
        let err = AdaptiveSystem {
            h_q: &s.h_q,
            coupling: Coupling::Dense(c),
            h_x,
            g_q: &s.g_q,
            g_x,
        }
        .solve(&settings)
        .expect_err("bad system");
        assert!(expected(&err), "unexpected error: {err}");
    }
}

#[test]
fn reaching_the_iteration_cap_is_reported() {
    let s = random_system(6, 30, 15);
    let h_x = lower_csc(&s.h_x);
    let settings = PcgSettings {
        tolerance: 1e-12,
        max_iterations: Some(3),
        ..PcgSettings::default()
    };
    let solution = AdaptiveSystem {
        h_q: &s.h_q,
        coupling: Coupling::Dense(&s.c),
        h_x: h_x.as_ref(),
        g_q: &s.g_q,
        g_x: &s.g_x,
    }
    .solve(&settings)
    .expect("a capped solve still returns its iterate");
    assert!(!solution.report.converged);
    assert_eq!(solution.report.iterations, 3);
    assert!(solution.report.relative_residual > 1e-12);
    assert!(solution.report.relative_residual < 1.0);
}

/// The adaptive system of a tet beam's Hessian: the vertices of one METIS subdomain are
/// enriched, the rest move with 12 affine modes (masked to the unenriched vertices).
#[test]
fn tet_beam_system_matches_dense_and_full_space_baselines() {
    let (mesh, h) = tet_hessian([8, 2, 2], 21);
    let n = mesh.num_vertices();
    let partition = Partition::new(&mesh, 4).expect("partition");
    let enriched = partition.vertices(3).to_vec();
    let mut is_enriched = vec![false; n];
    enriched.iter().for_each(|&v| is_enriched[v] = true);
    let modal: Vec<usize> = (0..n).filter(|&v| !is_enriched[v]).collect();
    // Masked affine basis over the unenriched vertices: B[3v + i, 4i + j] = (p_v, 1)[j].
    let mut b = DMatrix::zeros(3 * n, 12);
    for &v in &modal {
        let p = [mesh.rest[3 * v], mesh.rest[3 * v + 1], mesh.rest[3 * v + 2], 1.0];
        for i in 0..3 {
            for (j, pj) in p.iter().enumerate() {
                b[(3 * v + i, 4 * i + j)] = *pj;
            }
        }
    }
    let mut s_x = DMatrix::zeros(3 * n, 3 * enriched.len());
    for (k, &v) in enriched.iter().enumerate() {
        for i in 0..3 {
            s_x[(3 * v + i, 3 * k + i)] = 1.0;
        }
    }
    let h_q = b.transpose() * &h * &b;
    let c = b.transpose() * &h * &s_x;
    let h_x = s_x.transpose() * &h * &s_x;
    let mut rng = rng(22);
    let g = random_vector(3 * n, &mut rng);
    let g_q = (b.transpose() * nalgebra::DVector::from_column_slice(&g))
        .as_slice()
        .to_vec();
    let g_x = (s_x.transpose() * nalgebra::DVector::from_column_slice(&g))
        .as_slice()
        .to_vec();
    let want = dense_direction(&assemble(&h_q, &c, &h_x), &[g_q.clone(), g_x.clone()].concat());
    let h_x_csc = lower_csc(&h_x);
    let c_csc = full_csc(&c);
    assert!(c_csc.val().len() < c.len() / 2, "the coupling is sparse");
    for coupling in [Coupling::Dense(&c), Coupling::Sparse(c_csc.as_ref())] {
        let solution = AdaptiveSystem {
            h_q: &h_q,
            coupling,
            h_x: h_x_csc.as_ref(),
            g_q: &g_q,
            g_x: &g_x,
        }
        .solve(&PcgSettings::default())
        .expect("SPD system");
        assert!(solution.report.converged);
        let got = [solution.d_q, solution.d_x].concat();
        let err = relative_error(&got, &want);
        assert!(err < 1e-4, "relative error {err:e}");
    }

    // The full-space baselines on the whole Hessian.
    let full = lower_csc(&h);
    let dense = dense_direction(&h, &g);
    let direct = cholesky_direction(full.as_ref(), &g).expect("SPD Hessian");
    assert!(relative_error(&direct, &dense) < 1e-10);
    let (iterative, report) = pcg_direction(full.as_ref(), &g, &PcgSettings::default()).expect("SPD Hessian");
    assert!(report.converged && report.relative_residual <= 2e-5, "{report:?}");
    assert!(relative_error(&iterative, &dense) < 1e-4);
    assert!(relative_error(&iterative, &direct) < 1e-4);
}

#[test]
fn full_space_baselines_agree_on_random_systems_and_reject_indefinite_ones() {
    let mut rng = rng(31);
    let h = random_sparse_spd(40, 0.2, &mut rng);
    let g = random_vector(120, &mut rng);
    let dense = dense_direction(&h, &g);
    let csc = lower_csc(&h);
    let direct = cholesky_direction(csc.as_ref(), &g).expect("SPD");
    assert!(relative_error(&direct, &dense) < 1e-12);
    for (tolerance, max_error) in [(1e-5, 1e-4), (1e-11, 1e-9)] {
        let settings = PcgSettings {
            tolerance,
            ..PcgSettings::default()
        };
        let (iterative, report) = pcg_direction(csc.as_ref(), &g, &settings).expect("SPD");
        assert!(report.converged);
        assert!(relative_error(&iterative, &dense) < max_error);
    }
    let mut indefinite = h.clone();
    indefinite[(5, 5)] = -1.0;
    let bad = lower_csc(&indefinite);
    assert_eq!(
        cholesky_direction(bad.as_ref(), &g).expect_err("indefinite"),
        SolveError::NotPositiveDefinite("H")
    );
    assert!(pcg_direction(bad.as_ref(), &g, &PcgSettings::default()).is_err());
    let empty = lower_csc(&DMatrix::zeros(0, 0));
    assert!(cholesky_direction(empty.as_ref(), &[]).expect("empty").is_empty());
}
