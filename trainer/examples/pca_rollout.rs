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

use common::{newton, report, subspace_from_args, StepObjective};
use mochi_trainer::dataset::{self, Split};
use mochi_trainer::encoding::{Encoding, Frame};
use mochi_trainer::eval::vertex_errors;
use mochi_trainer::loss::{PhysicsLoss, PAPER_BC_WEIGHT};
use mochi_trainer::mesh::Elements;
use mochi_trainer::pca::Pca;
use nalgebra::DVector;

/// One step's potential over the PCA coordinates: `x = decode(mean + B z)`.
struct PcaStep<'a> {
    loss: &'a mut PhysicsLoss,
    encoding: &'a Encoding,
    pca: &'a Pca,
    frame: Frame,
    targets: Vec<f64>,
    prev: &'a [f64],
    prev2: &'a [f64],
}

impl StepObjective for PcaStep<'_> {
    /// The value and the reduced gradient `B^T R^T dE/dx`.
    fn value_gradient(&mut self, z: &[f64]) -> anyhow::Result<(f64, DVector<f64>)> {
        let q = self.pca.reconstruct(z)?;
        let x = self.encoding.decode(&q, &self.targets)?;
        let mut grad = vec![0.0; self.encoding.state_len()];
        let value = self
            .loss
            .value_and_gradient(&x, self.prev, self.prev2, &self.targets, &mut grad);
        let mut local = vec![0.0; self.encoding.encoded_len()];
        self.encoding.encode_gradient(&q, &grad, &self.frame, 1.0, &mut local)?;
        let gz = self
            .pca
            .basis
            .iter()
            .map(|b| b.iter().zip(&local).map(|(a, c)| a * c).sum());
        Ok((value, DVector::from_iterator(z.len(), gz)))
    }
}

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
            let mut step = PcaStep {
                loss: &mut loss,
                encoding: &encoding,
                pca: &pca,
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
        report(&plan.name, &plan.description, &errors, iterations, projection_error);
    }
    Ok(())
}
