//! What the subspace diagnostics (`pca_rollout`, `swing_rollout`, `latent_rollout`, `sensitivity`) share:
//! their arguments `SCENE K DATASET_DIR [FRAMES] [SEQUENCE,...]`, the PCA subspace of the scene's training
//! frames, Newton's method in a subspace and the report of a rollout.
#![allow(dead_code)] // `sensitivity` uses only the subspace

use mochi_sim::dataset::{self, Split};
use mochi_sim::measure::mean_and_max_error;
use mochi_sim::mesh::Elements;
use mochi_sim::trajectory::Trajectory;
use mochi_sim::BuiltScene;
use mochi_trainer::eval::OFF_REFERENCE;
use mochi_trainer::learn::encoding::{Encoding, Frame};
use mochi_trainer::learn::loss::PhysicsLoss;
use mochi_trainer::learn::pca::Pca;
use mochi_trainer::learn::recipe::{Recipe, PAPER_BC_WEIGHT};
use mochi_trainer::learn::sequences::encode_sequences;
use mochi_trainer::progress::FramesBar;
use nalgebra::{DMatrix, DVector};
use std::path::{Path, PathBuf};

/// Reads `SCENE K DATASET_DIR [FRAMES] [SEQUENCE,...]` (300 frames and every test sequence
/// by default) from the command line of `example`, generates the dataset in `DATASET_DIR`
/// if missing and fits the `K`-dimensional PCA subspace of its training frames.
pub fn subspace_from_args(example: &str) -> anyhow::Result<(DiagnosticArgs, Pca)> {
    let args = DiagnosticArgs::parse(example)?;
    let pca = Pca::fit(&args.encoded, args.k)?;
    Ok((args, pca))
}

/// What [`subspace_from_args`] reads and prepares, with the encoded training frames in place
/// of their PCA (for subspaces built otherwise).
pub struct DiagnosticArgs {
    /// The built scene.
    pub problem: BuiltScene,
    /// Its boundary-relative encoding.
    pub encoding: Encoding,
    /// Every training frame, encoded.
    pub encoded: Vec<Vec<f64>>,
    /// The subspace size `K`.
    pub k: usize,
    /// The dataset directory.
    pub dir: PathBuf,
    /// Frames of each test sequence to roll out.
    pub frames: usize,
    /// The test sequences to roll out (e.g. `test-00`); empty for all of them.
    pub only: Vec<String>,
}

impl DiagnosticArgs {
    /// Reads `SCENE K DATASET_DIR [FRAMES] [SEQUENCE,...]` from the command line of
    /// `example` and generates the dataset if missing.
    pub fn parse(example: &str) -> anyhow::Result<Self> {
        let args: Vec<String> = std::env::args().collect();
        if args.len() < 4 {
            anyhow::bail!("usage: {example} SCENE K DATASET_DIR [FRAMES] [SEQUENCE,...]");
        }
        let recipe = Recipe::load(&args[1])?;
        let mut problem = recipe.build()?;
        let k: usize = args[2].parse()?;
        let dir = PathBuf::from(&args[3]);
        let frames: usize = args.get(4).map_or(Ok(300), |s| s.parse())?;
        let only = args
            .get(5)
            .map_or(Vec::new(), |s| s.split(',').map(String::from).collect());
        dataset::generate(&mut problem, &dir, None, false, &FramesBar::new("dataset", true))?;
        let encoding = Encoding::new(&problem, recipe.latent.rods)?;
        let train = dataset::load(&problem, &dir, Split::Train)?
            .into_iter()
            .map(|(_, t)| t)
            .collect();
        let encoded = encode_sequences(&encoding, train)?
            .into_iter()
            .flat_map(|s| s.encoded)
            .collect();
        Ok(DiagnosticArgs {
            problem,
            encoding,
            encoded,
            k,
            dir,
            frames,
            only,
        })
    }
}

/// A subspace of the encoded vectors that implicit Euler can be solved in.
pub trait Subspace {
    /// A short description for the report's first line.
    fn describe(&self) -> String;
    /// The encoded vector of subspace coordinates `z`.
    fn lower(&self, z: &[f64]) -> anyhow::Result<Vec<f64>>;
    /// The subspace coordinates of (or nearest to) the encoded vector `q`.
    fn lift(&self, q: &[f64]) -> anyhow::Result<Vec<f64>>;
    /// `d lower / d z` at `z` (encoded coordinates x subspace coordinates).
    fn jacobian(&self, z: &[f64]) -> anyhow::Result<DMatrix<f64>>;
}

/// One implicit Euler step's potential ([`PhysicsLoss`]) over the coordinates of a subspace.
struct Step<'a, S: Subspace> {
    subspace: &'a S,
    loss: &'a mut PhysicsLoss,
    encoding: &'a Encoding,
    frame: Frame,
    targets: Vec<f64>,
    prev: &'a [f64],
    prev2: &'a [f64],
}

impl<S: Subspace> Step<'_, S> {
    /// The potential at `z` and its gradient in the encoded coordinates.
    fn encoded_gradient(&mut self, z: &[f64]) -> anyhow::Result<(f64, DVector<f64>)> {
        let q = self.subspace.lower(z)?;
        let x = self.encoding.decode(&q, &self.targets)?;
        let mut grad = vec![0.0; self.encoding.state_len()];
        let value = self
            .loss
            .value_and_gradient(&x, self.prev, self.prev2, &self.targets, &mut grad);
        let mut local = vec![0.0; self.encoding.encoded_len()];
        self.encoding.encode_gradient(&q, &grad, &self.frame, 1.0, &mut local)?;
        Ok((value, DVector::from_vec(local)))
    }

    /// The potential at `z` and its gradient `J^T dE/dq`.
    fn value_gradient(&mut self, z: &[f64]) -> anyhow::Result<(f64, DVector<f64>)> {
        let (value, local) = self.encoded_gradient(z)?;
        Ok((value, self.subspace.jacobian(z)?.tr_mul(&local)))
    }

    /// `J^T (dE/dq (z + h e_i) - dE/dq (z - h e_i)) / 2h` with the Jacobian `J` taken at `z`:
    /// the exact Hessian for a linear subspace; for a decoder, its curvature is left out.
    fn hessian(&mut self, z: &[f64], h: f64) -> anyhow::Result<DMatrix<f64>> {
        let jacobian = self.subspace.jacobian(z)?;
        let mut hessian = DMatrix::zeros(z.len(), z.len());
        for i in 0..z.len() {
            let mut shifted = z.to_vec();
            shifted[i] += h;
            let (_, plus) = self.encoded_gradient(&shifted)?;
            shifted[i] -= 2.0 * h;
            let (_, minus) = self.encoded_gradient(&shifted)?;
            hessian.set_column(i, &jacobian.tr_mul(&((plus - minus) / (2.0 * h))));
        }
        Ok(hessian)
    }
}

/// Newton iterations per frame at most.
const MAX_ITERATIONS: usize = 30;

/// Minimises one step's potential from `z` by Newton's method (the Hessian symmetrised, its
/// eigenvalues taken in absolute value) with backtracking line search, until a step moves
/// less than `1e-9 * diagonal`. Returns the minimiser and the iterations taken.
fn newton<S: Subspace>(step: &mut Step<'_, S>, mut z: Vec<f64>, diagonal: f64) -> anyhow::Result<(Vec<f64>, usize)> {
    let k = z.len();
    for iteration in 1..=MAX_ITERATIONS {
        let (value, g) = step.value_gradient(&z)?;
        let hessian = step.hessian(&z, 1e-6 * diagonal)?;
        let eigen = ((&hessian + hessian.transpose()) * 0.5).symmetric_eigen();
        let mut direction = DVector::zeros(k);
        for (lambda, v) in eigen.eigenvalues.iter().zip(eigen.eigenvectors.column_iter()) {
            direction -= v * (v.dot(&g) / lambda.abs().max(1e-12));
        }
        let slope = g.dot(&direction);
        let mut alpha = 1.0;
        loop {
            let trial: Vec<f64> = z.iter().zip(direction.iter()).map(|(z, d)| z + alpha * d).collect();
            if step.encoded_gradient(&trial)?.0 <= value + 1e-4 * alpha * slope || alpha < 1e-8 {
                z = trial;
                break;
            }
            alpha *= 0.5;
        }
        if alpha * direction.norm() < 1e-9 * diagonal {
            return Ok((z, iteration));
        }
    }
    Ok((z, MAX_ITERATIONS))
}

/// Rolls implicit Euler restricted to `subspace` out on every test sequence in `dir` (at
/// most `frames` frames each), starting from the first reference frame lifted into the
/// subspace, and prints per sequence: mean and largest frame-mean vertex error (% of the
/// rest diagonal), samples of the curve, Newton iterations per frame, and the mean error of
/// the reference frames lifted into the subspace and lowered back (the best it can do).
pub fn rollout(
    problem: &BuiltScene,
    encoding: &Encoding,
    subspace: &impl Subspace,
    dir: &Path,
    frames: usize,
    only: &[String],
) -> anyhow::Result<()> {
    let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
    // Rod roots are placed exactly by the decoding; other bodies get the training penalty.
    let penalty = (!matches!(problem.mesh.elements, Elements::Rods(_))).then_some(PAPER_BC_WEIGHT);
    let mut loss = PhysicsLoss::new(&problem.scene, &problem.mesh, &problem.handles, penalty)?;
    println!("{}: {}", problem.scene.name, subspace.describe());
    for (plan, reference) in test_sequences(problem, dir, only)? {
        let n = frames.min(reference.num_frames() - 1);
        let decode = |z: &[f64], t: usize| -> anyhow::Result<Vec<f64>> {
            let targets = encoding.handle_targets(&reference.positions[t])?;
            Ok(encoding.decode(&subspace.lower(z)?, &targets)?)
        };
        let lifted = |t: usize| subspace.lift(&encoding.encode_state(&reference.positions[t])?);
        let z0 = lifted(0)?;
        let mut latents = vec![z0.clone(), z0.clone()];
        let mut states = vec![decode(&z0, 0)?, decode(&z0, 0)?];
        let mut errors = Vec::with_capacity(n);
        let mut round_trip_error = 0.0;
        let mut iterations = 0;
        // The first frame `mochi eval` would count as diverged (a vertex half a diagonal off).
        let mut first_over_half = None;
        for t in 1..=n {
            let targets = encoding.handle_targets(&reference.positions[t])?;
            let mut step = Step {
                subspace,
                loss: &mut loss,
                encoding,
                frame: encoding.frame(&targets)?,
                targets,
                prev: &states[t],
                prev2: &states[t - 1],
            };
            let start: Vec<f64> = latents[t]
                .iter()
                .zip(&latents[t - 1])
                .map(|(a, b)| 2.0 * a - b)
                .collect();
            let (z, taken) = newton(&mut step, start, diagonal)?;
            iterations += taken;
            let x = decode(&z, t)?;
            let error = |x: &[f64]| mean_and_max_error(x, &reference.positions[t], dim, diagonal);
            let (mean, max_error) = error(&x);
            errors.push(mean);
            if max_error > OFF_REFERENCE && first_over_half.is_none() {
                first_over_half = Some(t);
            }
            round_trip_error += error(&decode(&lifted(t)?, t)?).0 / n as f64;
            latents.push(z);
            states.push(x);
        }
        println!(
            "{} ({}): mean vertex error {:.3}% of the diagonal over {n} frames, max of frame means {:.3}%, \
             first vertex half a diagonal off at frame {}, {:.1} Newton iterations per frame; by frame (%) {}; \
             reference frames lifted into the subspace and back: mean error {:.3}%",
            plan.name,
            plan.description,
            100.0 * errors.iter().sum::<f64>() / n as f64,
            100.0 * errors.iter().copied().fold(0.0, f64::max),
            first_over_half.map_or("none".to_string(), |t| t.to_string()),
            iterations as f64 / n as f64,
            curve_samples(&errors, 3),
            100.0 * round_trip_error
        );
    }
    Ok(())
}

/// The test sequences in `dir` named in `only` (all of them when it is empty), with their
/// plans; a name that is not there is an error.
pub fn test_sequences(
    problem: &BuiltScene,
    dir: &Path,
    only: &[String],
) -> anyhow::Result<Vec<(dataset::SequencePlan, Trajectory)>> {
    let sequences = dataset::load(problem, dir, Split::Test)?;
    for name in only {
        if !sequences.iter().any(|(plan, _)| &plan.name == name) {
            anyhow::bail!("{}: no test sequence named {name}", dir.display());
        }
    }
    Ok(sequences
        .into_iter()
        .filter(|(plan, _)| only.is_empty() || only.contains(&plan.name))
        .collect())
}

/// Samples of an error curve (fractions of the diagonal, frame 1 first) at frames 1, 10, 30,
/// 100, 300 and 1000 as `frame: percent` with `decimals` decimals, comma-separated.
pub fn curve_samples(errors: &[f64], decimals: usize) -> String {
    [1, 10, 30, 100, 300, 1000]
        .iter()
        .filter(|&&f| f <= errors.len())
        .map(|&f| format!("{f}: {:.decimals$}", 100.0 * errors[f - 1]))
        .collect::<Vec<_>>()
        .join(", ")
}
