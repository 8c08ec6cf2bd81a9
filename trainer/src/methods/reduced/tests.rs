//! The reduced objective's derivatives against finite differences of its value, and the
//! stepper's solves, on the tiny beam with its PCA-initialised decoder (a nonlinear map: the
//! residual blocks and Swish sit between the PCA layers).

use mochi_sim::energy::StencilEnergy;

use super::objective::{InertiaTerm, ObjectiveBuffers, ReducedObjective};
use super::optimize::{Exit, Objective, SolveSettings};
use super::rounding::Rounding;
use super::stepper::{ReducedSolver, ReducedStepper, StepperSettings};
use super::subspace::DecoderSubspace;
use crate::learn::network::test_support::randomise;
use crate::learn::samples::fixtures::{tiny_beam, TinyBeam};

/// The beam's decoder with its residual block made visibly nonlinear, the handles at frame
/// `frame`'s targets, and the latent of that frame.
fn subspace_at(beam: &mut TinyBeam, frame: usize) -> (DecoderSubspace, Vec<f64>) {
    let params = beam.ae.parameters();
    let block: Vec<_> = params
        .into_iter()
        .filter(|(n, _)| n.starts_with("decoder.block"))
        .collect();
    let mut rng = rand_chacha::ChaCha8Rng::from_seed_u64(3);
    randomise(&block, 0.3, &mut rng);
    let exported = beam.ae.export().unwrap();
    let targets = beam.sequences[0].targets[frame].clone();
    let subspace = DecoderSubspace::new(exported.decoder.as_mlp().unwrap(), &beam.encoding, &targets).unwrap();
    let q: Vec<f32> = beam.sequences[0].encoded[frame].iter().map(|&v| v as f32).collect();
    let z = crate::learn::network::forward_exported(&exported.encoder, &q).unwrap();
    (subspace, z.iter().map(|&v| v as f64).collect())
}

trait SeedU64 {
    fn from_seed_u64(seed: u64) -> Self;
}
impl SeedU64 for rand_chacha::ChaCha8Rng {
    fn from_seed_u64(seed: u64) -> Self {
        rand::SeedableRng::seed_from_u64(seed)
    }
}

fn potentials(beam: &TinyBeam) -> Vec<&dyn StencilEnergy> {
    beam.problem.simulator.potentials().iter().map(|p| p.as_ref()).collect()
}

/// The relative difference of two vectors, against the larger norm.
fn relative(a: &[f64], b: &[f64]) -> f64 {
    let diff: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>().sqrt();
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    diff / norm(a).max(norm(b)).max(1e-300)
}

#[test]
fn reduced_gradient_and_hessian_match_finite_differences() {
    let mut beam = tiny_beam();
    let (mut subspace, z0) = subspace_at(&mut beam, 6);
    let z: Vec<f64> = z0
        .iter()
        .enumerate()
        .map(|(i, v)| v + 0.05 * (i as f64 + 1.0))
        .collect();
    let r = z.len();
    let masses = beam.problem.simulator.masses().to_vec();
    let mut inertia = InertiaTerm::new(3, masses, beam.problem.scene.dt);
    // A prediction off the subspace, so the inertia term pulls.
    let prediction: Vec<f64> = beam.sequences[0].trajectory.positions[7]
        .iter()
        .map(|v| v + 1e-3)
        .collect();
    inertia.set_prediction(&prediction);
    let pots = potentials(&beam);
    let mut buffers = ObjectiveBuffers::new(subspace.state_len(), r);
    let mut objective = ReducedObjective::new(&mut subspace, &pots, Some(&inertia), 1e-3, &mut buffers);

    let mut grad = vec![0.0; r];
    let mut hess = vec![0.0; r * r];
    let value = objective.exact_hessian(&z, &mut grad, &mut hess).unwrap();
    assert!((value - objective.value(&z)).abs() <= 1e-12 * value.abs());
    let eps = 1e-5;
    let mut fd_grad = vec![0.0; r];
    let mut fd_hess = vec![0.0; r * r];
    for a in 0..r {
        let mut zp = z.clone();
        let mut zm = z.clone();
        zp[a] += eps;
        zm[a] -= eps;
        fd_grad[a] = (objective.value(&zp) - objective.value(&zm)) / (2.0 * eps);
        let (mut gp, mut gm) = (vec![0.0; r], vec![0.0; r]);
        objective.gradient(&zp, &mut gp);
        objective.gradient(&zm, &mut gm);
        for b in 0..r {
            fd_hess[b * r + a] = (gp[b] - gm[b]) / (2.0 * eps);
        }
    }
    let mut g2 = vec![0.0; r];
    objective.gradient(&z, &mut g2);
    assert!(
        relative(&grad, &g2) < 1e-12,
        "exact_hessian and gradient agree on the gradient"
    );
    assert!(relative(&grad, &fd_grad) < 1e-6, "gradient {grad:?} vs {fd_grad:?}");
    assert!(relative(&hess, &fd_hess) < 1e-5, "Hessian {hess:?} vs {fd_hess:?}");
    for a in 0..r {
        for b in 0..r {
            assert!((hess[a * r + b] - hess[b * r + a]).abs() <= 1e-9 * hess[a * r + a].abs().max(1.0));
        }
    }

    // Newton's Hessian is the PSD-projected Gauss-Newton part: symmetric, PSD, and not the
    // exact Hessian (the decoder's curvature term is left out).
    let mut psd = vec![0.0; r * r];
    objective.hessian(&z, &mut g2, &mut psd);
    let m = nalgebra::DMatrix::from_row_slice(r, r, &psd);
    let eig = m.clone().symmetric_eigen().eigenvalues;
    let top = eig.iter().copied().fold(0.0, f64::max);
    assert!(eig.iter().all(|&l| l >= -1e-10 * top), "PSD: {eig:?}");
    assert!(relative(&psd, &hess) > 1e-8);
}

fn stepper(beam: &mut TinyBeam, solver: ReducedSolver, quasi_static: bool) -> (ReducedStepper, Vec<f64>) {
    let (subspace, z0) = subspace_at(beam, 0);
    let settings = StepperSettings {
        solver,
        solve: SolveSettings {
            tolerance: 1e-8,
            ..SolveSettings::default()
        },
        quasi_static,
        record_history: true,
    };
    let masses = beam.problem.simulator.masses().to_vec();
    let diagonal = beam.problem.mesh.rest_diagonal();
    let dt = beam.problem.scene.dt;
    let stepper = ReducedStepper::new(subspace, beam.encoding.clone(), masses, diagonal, dt, settings).unwrap();
    (stepper, z0)
}

#[test]
fn single_precision_rounds_every_call_alike_and_stays_near_double() {
    let mut beam = tiny_beam();
    let (mut subspace, z0) = subspace_at(&mut beam, 6);
    let z: Vec<f64> = z0.iter().map(|v| v + 0.05).collect();
    let r = z.len();
    let masses = beam.problem.simulator.masses().to_vec();
    let mut inertia = InertiaTerm::new(3, masses, beam.problem.scene.dt);
    inertia.set_prediction(&beam.sequences[0].trajectory.positions[7]);
    let pots = potentials(&beam);
    let mut buffers = ObjectiveBuffers::new(subspace.state_len(), r);
    let (mut grad, mut hess) = (vec![0.0; r], vec![0.0; r * r]);
    let mut double = ReducedObjective::new(&mut subspace, &pots, Some(&inertia), 1e-3, &mut buffers);
    let value = double.gradient(&z, &mut grad);
    let mut single = double.with_rounding(Rounding::Single);
    let mut grad_single = vec![0.0; r];
    let value_single = single.gradient(&z, &mut grad_single);
    let is_f32 = |v: f64| v as f32 as f64 == v;
    // Every number a solver compares is an f32, the same from each kind of call (Newton
    // compares the E of its Hessian calls with that of its line search's value calls).
    assert!(is_f32(value_single) && grad_single.iter().all(|&g| is_f32(g)));
    assert_eq!(single.value(&z), value_single);
    let mut grad_hessian = vec![0.0; r];
    assert_eq!(single.hessian(&z, &mut grad_hessian, &mut hess), value_single);
    assert_eq!(grad_hessian, grad_single);
    // ... and close to double precision, yet not equal to it.
    assert!(
        (value_single - value).abs() <= 1e-6 * value.abs(),
        "{value_single} vs {value}"
    );
    assert!(relative(&grad_single, &grad) < 1e-3, "{grad_single:?} vs {grad:?}");
    assert_ne!(grad_single, grad);
}

#[test]
fn lbfgs_and_newton_steps_converge_to_the_same_state() {
    let mut beam = tiny_beam();
    let mut ends = Vec::new();
    for solver in [ReducedSolver::Lbfgs, ReducedSolver::Newton] {
        let (mut stepper, z0) = stepper(&mut beam, solver, false);
        let targets = |t: usize| beam.sequences[0].targets[t].clone();
        stepper.reset(&z0, &targets(0)).unwrap();
        let pots = potentials(&beam);
        for t in 1..=4 {
            let report = stepper.step(&pots, &targets(t)).unwrap();
            assert_eq!(report.exit, Exit::Converged, "{} step {t}: {report:?}", solver.name());
            assert!(report.gradient_norm <= 1e-8);
            assert_eq!(report.history.len(), report.iterations + 1);
            assert!(
                report.history.windows(2).all(|w| w[1] <= w[0] + 1e-12 * w[0].abs()),
                "{report:?}"
            );
        }
        ends.push(stepper.positions().to_vec());
    }
    let diagonal = beam.problem.mesh.rest_diagonal();
    let diff = ends[0]
        .iter()
        .zip(&ends[1])
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(diff < 1e-5 * diagonal, "L-BFGS and Newton differ by {diff}");
}

#[test]
fn a_static_settle_lowers_the_potential_to_a_stationary_point() {
    let mut beam = tiny_beam();
    let (mut stepper, z0) = stepper(&mut beam, ReducedSolver::Newton, true);
    let targets = beam.sequences[0].targets[0].clone();
    // Start from a latent off the equilibrium.
    let start: Vec<f64> = z0.iter().map(|v| v + 0.2).collect();
    stepper.reset(&start, &targets).unwrap();
    let pots = potentials(&beam);
    let energy = |x: &[f64]| pots.iter().map(|p| mochi_sim::energy::value(*p, x)).sum::<f64>();
    let before = energy(stepper.positions());
    let report = stepper.settle(&pots, &targets).unwrap();
    assert_eq!(report.exit, Exit::Converged, "{report:?}");
    assert!(energy(stepper.positions()) < before);
}

#[test]
fn a_gradient_after_positions_reuses_the_hidden_pass_only_where_it_holds() {
    let mut beam = tiny_beam();
    let (mut subspace, z) = subspace_at(&mut beam, 6);
    let (n, r) = (subspace.state_len(), z.len());
    let other: Vec<f64> = z.iter().map(|v| v + 0.2).collect();
    let g: Vec<f64> = (0..n).map(|i| ((i % 5) as f64 - 2.0) * 0.1).collect();
    // Each gradient as a fresh subspace computes it (its hidden pass from scratch).
    let fresh = |at: &[f64]| {
        let mut out = vec![0.0; r];
        subspace_at(&mut tiny_beam(), 6).0.gradient(at, &g, &mut out).unwrap();
        out
    };
    let (at_z, at_other) = (fresh(&z), fresh(&other));
    assert_ne!(at_z, at_other);
    let (mut x, mut out) = (vec![0.0; n], vec![0.0; r]);
    // At the latent just decoded (the objective's gradient call): reused, the same bits.
    subspace.positions(&z, &mut x).unwrap();
    subspace.gradient(&z, &g, &mut out).unwrap();
    assert_eq!(out, at_z);
    // At another latent, or after another decoder call overwrote the pass: computed anew.
    subspace.gradient(&other, &g, &mut out).unwrap();
    assert_eq!(out, at_other);
    subspace.gradient(&z, &g, &mut out).unwrap();
    assert_eq!(out, at_z);
    subspace.positions(&z, &mut x).unwrap();
    let mut curvature = vec![0.0; r * r];
    subspace.contracted_hessian(&other, &g, &mut curvature).unwrap();
    subspace.gradient(&z, &g, &mut out).unwrap();
    assert_eq!(out, at_z);
    subspace.positions(&z, &mut x).unwrap();
    subspace.second_directional(&other, &other, &mut x).unwrap();
    subspace.gradient(&z, &g, &mut out).unwrap();
    assert_eq!(out, at_z);
    subspace.positions(&z, &mut x).unwrap();
    let mut jac = vec![0.0; n * r];
    subspace.positions_and_jacobian(&other, &mut x, &mut jac).unwrap();
    subspace.gradient(&z, &g, &mut out).unwrap();
    assert_eq!(out, at_z);
}

#[test]
fn wrong_sizes_are_refused() {
    let mut beam = tiny_beam();
    let (mut stepper, z0) = stepper(&mut beam, ReducedSolver::Lbfgs, false);
    let targets = beam.sequences[0].targets[0].clone();
    assert!(stepper.reset(&z0[..1], &targets).is_err());
    assert!(stepper.reset(&z0, &targets[1..]).is_err());
    let exported = beam.ae.export().unwrap();
    // The encoder maps states to latents: as a subspace map its sizes do not fit.
    let err = DecoderSubspace::new(&exported.encoder, &beam.encoding, &targets)
        .err()
        .unwrap();
    assert!(err.to_string().contains("decoder gives"), "{err}");
}

#[test]
fn projection_gradient_matches_finite_differences_and_recovers_decoded_states() {
    use super::projection::{project, ProjectionObjective};
    let mut beam = tiny_beam();
    let (mut subspace, z0) = subspace_at(&mut beam, 6);
    let r = z0.len();
    let masses = beam.problem.simulator.masses().to_vec();
    let diagonal = beam.problem.mesh.rest_diagonal();
    // A state on the subspace, at a latent away from the encoded frame's.
    let z_true: Vec<f64> = z0.iter().enumerate().map(|(i, v)| v + 0.1 * (i as f64 - 1.0)).collect();
    let mut on = vec![0.0; subspace.state_len()];
    subspace.positions(&z_true, &mut on).unwrap();
    let off: Vec<f64> = on
        .iter()
        .enumerate()
        .map(|(i, v)| v + 1e-3 * ((i % 7) as f64 - 3.0))
        .collect();

    let mut objective = ProjectionObjective::new(&mut subspace, &masses, diagonal, &off).unwrap();
    let mut grad = vec![0.0; r];
    let value = objective.gradient(&z0, &mut grad);
    assert!(value > 0.0);
    let eps = 1e-6;
    let fd: Vec<f64> = (0..r)
        .map(|a| {
            let (mut zp, mut zm) = (z0.clone(), z0.clone());
            zp[a] += eps;
            zm[a] -= eps;
            (objective.value(&zp) - objective.value(&zm)) / (2.0 * eps)
        })
        .collect();
    assert!(relative(&grad, &fd) < 1e-6, "gradient {grad:?} vs {fd:?}");
    let mut hess = vec![0.0; r * r];
    objective.hessian(&z0, &mut grad, &mut hess);
    assert!(
        (0..r).all(|a| hess[a * r + a] >= 0.0),
        "Gauss-Newton diagonal is non-negative"
    );

    // From the encoded frame's latent, the projection finds the state it was decoded from.
    let mut z = z0.clone();
    let mut x = vec![0.0; on.len()];
    let report = project(&mut subspace, &masses, diagonal, &on, &mut z, &mut x).unwrap();
    assert_eq!(report.exit, Exit::Converged, "{report:?}");
    let worst = x.iter().zip(&on).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(worst < 1e-6 * diagonal, "recovered within {worst:e}");
    // Wrong sizes are errors, not panics.
    assert!(ProjectionObjective::new(&mut subspace, &masses[1..], diagonal, &on).is_err());
}

/// The PCA subspace with every direction of the encoded state: a linear map onto the whole
/// space of free vertices.
fn whole_space(beam: &TinyBeam) -> crate::learn::pca::Pca {
    let n = beam.encoding.encoded_len();
    crate::learn::pca::Pca {
        mean: vec![0.0; n],
        basis: (0..n)
            .map(|i| (0..n).map(|j| f64::from(u8::from(i == j))).collect())
            .collect(),
        singular_values: Vec::new(),
    }
}

#[test]
fn a_linear_subspace_has_the_derivatives_of_finite_differences_and_no_curvature() {
    let beam = tiny_beam();
    let frames = &beam.sequences[0].encoded;
    let pca = crate::learn::pca::Pca::fit(frames, 3).unwrap();
    let targets = beam.sequences[0].targets[5].clone();
    let mut subspace = DecoderSubspace::new(&pca, &beam.encoding, &targets).unwrap();
    let (n, r) = (subspace.state_len(), subspace.latent_len());
    assert_eq!(r, 3);
    let z = pca.project(&frames[5]).unwrap();
    let (mut x, mut jac) = (vec![0.0; n], vec![0.0; n * r]);
    subspace.positions_and_jacobian(&z, &mut x, &mut jac).unwrap();
    // Frame 5 lies close to the 3-component PCA of the sequence it is part of.
    let world = &beam.sequences[0].trajectory.positions[5];
    let diagonal = beam.problem.mesh.rest_diagonal();
    let off = x.iter().zip(world).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(off < 0.05 * diagonal, "{off}");
    let eps = 1e-6;
    for a in 0..r {
        let (mut zp, mut zm) = (z.clone(), z.clone());
        zp[a] += eps;
        zm[a] -= eps;
        let (mut xp, mut xm) = (vec![0.0; n], vec![0.0; n]);
        subspace.positions(&zp, &mut xp).unwrap();
        subspace.positions(&zm, &mut xm).unwrap();
        let fd: Vec<f64> = xp.iter().zip(&xm).map(|(p, m)| (p - m) / (2.0 * eps)).collect();
        let column: Vec<f64> = (0..n).map(|i| jac[i * r + a]).collect();
        assert!(relative(&column, &fd) < 1e-8, "column {a}");
    }
    let g: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
    let (mut pulled, mut curvature, mut second) = (vec![0.0; r], vec![1.0; r * r], vec![1.0; n]);
    subspace.gradient(&z, &g, &mut pulled).unwrap();
    let by_jacobian: Vec<f64> = (0..r).map(|a| (0..n).map(|i| jac[i * r + a] * g[i]).sum()).collect();
    assert!(relative(&pulled, &by_jacobian) < 1e-12);
    subspace.contracted_hessian(&z, &g, &mut curvature).unwrap();
    subspace.second_directional(&z, &[1.0, -1.0, 0.5], &mut second).unwrap();
    assert!(curvature.iter().chain(&second).all(|&v| v == 0.0));
    assert!(subspace.positions(&[0.0; 2], &mut x).is_err());
}

#[test]
fn a_linear_subspace_of_the_whole_space_steps_as_the_full_space_solver() {
    let beam = tiny_beam();
    let whole = whole_space(&beam);
    let targets = |t: usize| beam.sequences[0].targets[t].clone();
    let subspace = DecoderSubspace::new(&whole, &beam.encoding, &targets(0)).unwrap();
    let settings = StepperSettings {
        solver: ReducedSolver::Newton,
        solve: SolveSettings {
            tolerance: 1e-10,
            ..SolveSettings::default()
        },
        quasi_static: false,
        record_history: false,
    };
    let masses = beam.problem.simulator.masses().to_vec();
    let diagonal = beam.problem.mesh.rest_diagonal();
    let mut stepper = ReducedStepper::new(
        subspace,
        beam.encoding.clone(),
        masses,
        diagonal,
        beam.problem.scene.dt,
        settings,
    )
    .unwrap();
    stepper.reset(&beam.sequences[0].encoded[0], &targets(0)).unwrap();
    let pots = potentials(&beam);
    for t in 1..=4 {
        stepper.step(&pots, &targets(t)).unwrap();
        let reference = &beam.sequences[0].trajectory.positions[t];
        let off = stepper
            .positions()
            .iter()
            .zip(reference)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(off < 1e-6 * diagonal, "frame {t}: {off}");
    }
}
