//! Diagnostic: implicit Euler restricted to the PCA subspace of a scene's training frames,
//! rolled out on the scene's test sequences against the full-space reference.
//!
//! ```sh
//! cargo run --release -p mochi-trainer --example pca_rollout -- SCENE K DATASET_DIR [FRAMES]
//! ```
//!
//! Each step minimises the same incremental potential the latent integrator is trained on
//! ([`PhysicsLoss`]: inertia, the scene's energies, the handle penalty for cloth and solids)
//! over the latent `z` of `x = decode(mean + B z)` (the BC-relative encoding of `mochi train`
//! with its first `K` principal components `B`), by Newton's method in `z`: the reduced
//! gradient `B^T R^T dE/dx`, the reduced Hessian by central differences of it, eigenvalues
//! taken in absolute value, backtracking line search. It answers whether a subspace can carry
//! a scene's dynamics at all, apart from whether a network can learn to step in it: on `rods`
//! the self-supervised integrator fails while this solve follows the reference closely.
//! The dataset (both splits) is generated in `DATASET_DIR` if missing.

mod common;

use common::subspace_from_args;
use mochi_trainer::dataset::{self, Split};
use mochi_trainer::eval::vertex_errors;
use mochi_trainer::loss::{PhysicsLoss, PAPER_BC_WEIGHT};
use mochi_trainer::mesh::Elements;
use nalgebra::{DMatrix, DVector};

/// Newton iterations per frame at most.
const MAX_ITERATIONS: usize = 30;

fn main() -> anyhow::Result<()> {
    let (problem, encoding, pca, k, dir, frames) = subspace_from_args("pca_rollout")?;
    let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
    // Rod roots are placed exactly by the decoding; other bodies get the training penalty.
    let penalty = (!matches!(problem.mesh.elements, Elements::Rods(_))).then_some(PAPER_BC_WEIGHT);
    let mut loss = PhysicsLoss::new(&problem.scene, &problem.mesh, &problem.handles, penalty)?;
    println!("{}: PCA k={k} of the training frames", problem.scene.name);
    for (plan, reference) in dataset::load(&problem, &dir, Split::Test)? {
        let n = frames.min(reference.num_frames() - 1);
        let decode = |z: &[f64], t: usize| -> anyhow::Result<Vec<f64>> {
            let targets = encoding.handle_targets(&reference.positions[t])?;
            Ok(encoding.decode(&pca.reconstruct(z)?, &targets)?)
        };
        let z0 = pca.project(&encoding.encode_state(&reference.positions[0])?)?;
        let mut latents = vec![z0.clone(), z0.clone()];
        let mut states = vec![decode(&z0, 0)?, decode(&z0, 0)?];
        let mut errors = Vec::with_capacity(n);
        // The best the subspace can do: each reference frame projected onto it.
        let mut projection_error = 0.0;
        let mut iterations = 0;
        for t in 1..=n {
            let targets = encoding.handle_targets(&reference.positions[t])?;
            let frame = encoding.frame(&targets)?;
            let (prev, prev2) = (&states[t], &states[t - 1]);
            let mut grad = vec![0.0; encoding.state_len()];
            // Value and reduced gradient B^T R^T dE/dx at z.
            let mut reduced = |z: &[f64]| -> anyhow::Result<(f64, DVector<f64>)> {
                let q = pca.reconstruct(z)?;
                let x = encoding.decode(&q, &targets)?;
                let value = loss.value_and_gradient(&x, prev, prev2, &targets, &mut grad);
                let mut local = vec![0.0; encoding.encoded_len()];
                encoding.encode_gradient(&q, &grad, &frame, 1.0, &mut local)?;
                let gz = pca.basis.iter().map(|b| b.iter().zip(&local).map(|(a, c)| a * c).sum());
                Ok((value, DVector::from_iterator(k, gz)))
            };
            let (a, b) = (&latents[t], &latents[t - 1]);
            let mut z: Vec<f64> = a.iter().zip(b).map(|(a, b)| 2.0 * a - b).collect();
            for _ in 0..MAX_ITERATIONS {
                iterations += 1;
                let (value, g) = reduced(&z)?;
                let h = 1e-6 * diagonal;
                let mut hessian = DMatrix::zeros(k, k);
                for i in 0..k {
                    let mut shifted = z.clone();
                    shifted[i] += h;
                    let (_, plus) = reduced(&shifted)?;
                    shifted[i] -= 2.0 * h;
                    let (_, minus) = reduced(&shifted)?;
                    hessian.set_column(i, &((plus - minus) / (2.0 * h)));
                }
                let eigen = ((&hessian + hessian.transpose()) * 0.5).symmetric_eigen();
                let mut direction = DVector::zeros(k);
                for (lambda, v) in eigen.eigenvalues.iter().zip(eigen.eigenvectors.column_iter()) {
                    direction -= v * (v.dot(&g) / lambda.abs().max(1e-12));
                }
                let slope = g.dot(&direction);
                let mut alpha = 1.0;
                loop {
                    let trial: Vec<f64> = z.iter().zip(direction.iter()).map(|(z, d)| z + alpha * d).collect();
                    if reduced(&trial)?.0 <= value + 1e-4 * alpha * slope || alpha < 1e-8 {
                        z = trial;
                        break;
                    }
                    alpha *= 0.5;
                }
                if alpha * direction.norm() < 1e-9 * diagonal {
                    break;
                }
            }
            let x = decode(&z, t)?;
            let mean_error = |x: &[f64]| {
                vertex_errors(x, &reference.positions[t], dim, diagonal).sum::<f64>()
                    / problem.mesh.num_vertices() as f64
            };
            errors.push(mean_error(&x));
            let projected = decode(&pca.project(&encoding.encode_state(&reference.positions[t])?)?, t)?;
            projection_error += mean_error(&projected) / n as f64;
            latents.push(z);
            states.push(x);
        }
        let samples: Vec<String> = [1, 10, 30, 100, 300, 1000]
            .iter()
            .filter(|&&f| f <= errors.len())
            .map(|&f| format!("{f}: {:.3}", 100.0 * errors[f - 1]))
            .collect();
        println!(
            "{} ({}): mean vertex error {:.3}% of the diagonal over {n} frames, max of frame means {:.3}%, \
             {:.1} Newton iterations per frame; by frame (%) {}; reference frames projected onto \
             the subspace: mean error {:.3}%",
            plan.name,
            plan.description,
            100.0 * errors.iter().sum::<f64>() / n as f64,
            100.0 * errors.iter().copied().fold(0.0, f64::max),
            iterations as f64 / n as f64,
            samples.join(", "),
            100.0 * projection_error
        );
    }
    Ok(())
}
