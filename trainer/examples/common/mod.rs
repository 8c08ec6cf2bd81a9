//! What the subspace diagnostics (`pca_rollout`, `latent_rollout`, `sensitivity`) share:
//! their arguments `SCENE K DATASET_DIR [FRAMES]`, the PCA subspace of the scene's training
//! frames, Newton's method in a subspace and the report of a rollout.
#![allow(dead_code)] // each example uses a part

use mochi_trainer::dataset::{self, Split};
use mochi_trainer::encoding::Encoding;
use mochi_trainer::latent::encode_sequences;
use mochi_trainer::pca::Pca;
use mochi_trainer::scene::{Problem, Scene};
use nalgebra::{DMatrix, DVector};
use std::path::PathBuf;

/// Reads `SCENE K DATASET_DIR [FRAMES]` (300 frames by default) from the command line of
/// `example`, generates the dataset in `DATASET_DIR` if missing and fits the subspace.
/// Returns the built scene, its boundary-relative encoding, the subspace, `K`, the dataset
/// directory and the frames of each test sequence to roll out.
pub fn subspace_from_args(example: &str) -> anyhow::Result<(Problem, Encoding, Pca, usize, PathBuf, usize)> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 4 {
        anyhow::bail!("usage: {example} SCENE K DATASET_DIR [FRAMES]");
    }
    let mut problem = Scene::load(&args[1])?.build()?;
    let k: usize = args[2].parse()?;
    let dir = PathBuf::from(&args[3]);
    let frames: usize = args.get(4).map_or(Ok(300), |s| s.parse())?;
    dataset::generate(&mut problem, &dir, None, false, true)?;
    let encoding = Encoding::new(&problem)?;
    let train = dataset::load(&problem, &dir, Split::Train)?
        .into_iter()
        .map(|(_, t)| t)
        .collect();
    let encoded: Vec<Vec<f64>> = encode_sequences(&encoding, train)?
        .into_iter()
        .flat_map(|s| s.encoded)
        .collect();
    let pca = Pca::fit(&encoded, k)?;
    Ok((problem, encoding, pca, k, dir, frames))
}

/// A subspace that implicit Euler can be solved in: the incremental potential of one step
/// as a function of the subspace coordinates `z`.
pub trait StepObjective {
    /// The potential at `z` and its gradient in `z`.
    fn value_gradient(&mut self, z: &[f64]) -> anyhow::Result<(f64, DVector<f64>)>;

    /// The potential at `z` alone (the line search's); by default from [`Self::value_gradient`].
    fn value(&mut self, z: &[f64]) -> anyhow::Result<f64> {
        Ok(self.value_gradient(z)?.0)
    }

    /// The Hessian in `z`; by default central differences of the gradient with step `h`.
    fn hessian(&mut self, z: &[f64], h: f64) -> anyhow::Result<DMatrix<f64>> {
        let k = z.len();
        let mut hessian = DMatrix::zeros(k, k);
        for i in 0..k {
            let mut shifted = z.to_vec();
            shifted[i] += h;
            let (_, plus) = self.value_gradient(&shifted)?;
            shifted[i] -= 2.0 * h;
            let (_, minus) = self.value_gradient(&shifted)?;
            hessian.set_column(i, &((plus - minus) / (2.0 * h)));
        }
        Ok(hessian)
    }
}

/// Newton iterations per frame at most.
const MAX_ITERATIONS: usize = 30;

/// Minimises `objective` from `z` by Newton's method (the Hessian symmetrised, its
/// eigenvalues taken in absolute value) with backtracking line search, until a step moves
/// less than `1e-9 * diagonal`. Returns the minimiser and the iterations taken.
pub fn newton(objective: &mut impl StepObjective, mut z: Vec<f64>, diagonal: f64) -> anyhow::Result<(Vec<f64>, usize)> {
    let k = z.len();
    for iteration in 1..=MAX_ITERATIONS {
        let (value, g) = objective.value_gradient(&z)?;
        let hessian = objective.hessian(&z, 1e-6 * diagonal)?;
        let eigen = ((&hessian + hessian.transpose()) * 0.5).symmetric_eigen();
        let mut direction = DVector::zeros(k);
        for (lambda, v) in eigen.eigenvalues.iter().zip(eigen.eigenvectors.column_iter()) {
            direction -= v * (v.dot(&g) / lambda.abs().max(1e-12));
        }
        let slope = g.dot(&direction);
        let mut alpha = 1.0;
        loop {
            let trial: Vec<f64> = z.iter().zip(direction.iter()).map(|(z, d)| z + alpha * d).collect();
            if objective.value(&trial)? <= value + 1e-4 * alpha * slope || alpha < 1e-8 {
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

/// Prints one test sequence's summary: mean and largest frame-mean vertex error (fractions
/// of the diagonal, one per frame), samples of the curve, Newton iterations per frame, and
/// the mean error of the reference frames mapped into the subspace and back.
pub fn report(name: &str, description: &str, errors: &[f64], iterations: usize, round_trip_error: f64) {
    let n = errors.len().max(1);
    let samples: Vec<String> = [1, 10, 30, 100, 300, 1000]
        .iter()
        .filter(|&&f| f <= errors.len())
        .map(|&f| format!("{f}: {:.3}", 100.0 * errors[f - 1]))
        .collect();
    println!(
        "{name} ({description}): mean vertex error {:.3}% of the diagonal over {n} frames, max of frame means {:.3}%, \
         {:.1} Newton iterations per frame; by frame (%) {}; reference frames mapped into the \
         subspace and back: mean error {:.3}%",
        100.0 * errors.iter().sum::<f64>() / n as f64,
        100.0 * errors.iter().copied().fold(0.0, f64::max),
        iterations as f64 / n as f64,
        samples.join(", "),
        100.0 * round_trip_error
    );
}
