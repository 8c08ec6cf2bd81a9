//! Diagnostic: implicit Euler restricted to a trained model's latent space (its decoder),
//! rolled out on the scene's test sequences against the full-space reference.
//!
//! ```sh
//! cargo run --release -p mochi-trainer --example latent_rollout -- ARTIFACT.mochi DATASET_DIR [FRAMES]
//! ```
//!
//! The counterpart of `pca_rollout` for the autoencoder's nonlinear subspace: each step
//! minimises the potential the integrator is trained on ([`PhysicsLoss`]) over the latent
//! `z` of `x = decode(decoder(z))`, by Newton's method in `z`, starting from the encoder's
//! latent of the first reference frame. The decoder runs in `f64` and is differentiated by
//! central differences; the Hessian keeps the decoder's Jacobian fixed at `z` (the decoder's
//! curvature is left out; the line search keeps every step a descent). Where this rollout
//! follows the reference and the trained integrator does not, the integrator is the limit;
//! where this one leaves it too, the latent space is.

mod common;

use common::{newton, report, StepObjective};
use mochi_trainer::artifact::Artifact;
use mochi_trainer::dataset::{self, Split};
use mochi_trainer::encoding::{Encoding, Frame};
use mochi_trainer::eval::{rebuild_problem, vertex_errors, LoadedModel};
use mochi_trainer::loss::{PhysicsLoss, PAPER_BC_WEIGHT};
use mochi_trainer::mesh::Elements;
use mochi_trainer::model::{forward_exported, ExportedMlp};
use nalgebra::{DMatrix, DVector};

/// Step of the decoder's central differences, in latent units.
const JACOBIAN_STEP: f64 = 1e-5;

/// One step's potential over the latent of a frozen decoder.
struct LatentStep<'a> {
    loss: &'a mut PhysicsLoss,
    encoding: &'a Encoding,
    decoder: &'a ExportedMlp,
    frame: Frame,
    targets: Vec<f64>,
    prev: &'a [f64],
    prev2: &'a [f64],
}

impl LatentStep<'_> {
    /// The potential at the decoding of `q` and its gradient in the encoded coordinates.
    fn encoded_gradient(&mut self, q: &[f64]) -> anyhow::Result<(f64, Vec<f64>)> {
        let x = self.encoding.decode(q, &self.targets)?;
        let mut grad = vec![0.0; self.encoding.state_len()];
        let value = self
            .loss
            .value_and_gradient(&x, self.prev, self.prev2, &self.targets, &mut grad);
        let mut local = vec![0.0; self.encoding.encoded_len()];
        self.encoding.encode_gradient(q, &grad, &self.frame, 1.0, &mut local)?;
        Ok((value, local))
    }

    /// The decoder's Jacobian at `z` (encoded coordinates x latent), by central differences.
    fn jacobian(&self, z: &[f64]) -> anyhow::Result<DMatrix<f64>> {
        let mut columns = Vec::with_capacity(z.len());
        for i in 0..z.len() {
            let mut shifted = z.to_vec();
            shifted[i] += JACOBIAN_STEP;
            let plus = forward_exported(self.decoder, &shifted)?;
            shifted[i] -= 2.0 * JACOBIAN_STEP;
            let minus = forward_exported(self.decoder, &shifted)?;
            let column = plus.iter().zip(&minus).map(|(a, b)| (a - b) / (2.0 * JACOBIAN_STEP));
            columns.push(DVector::from_iterator(plus.len(), column));
        }
        Ok(DMatrix::from_columns(&columns))
    }
}

impl StepObjective for LatentStep<'_> {
    fn value_gradient(&mut self, z: &[f64]) -> anyhow::Result<(f64, DVector<f64>)> {
        let (value, local) = self.encoded_gradient(&forward_exported(self.decoder, z)?)?;
        Ok((value, self.jacobian(z)?.tr_mul(&DVector::from_vec(local))))
    }

    fn value(&mut self, z: &[f64]) -> anyhow::Result<f64> {
        Ok(self.encoded_gradient(&forward_exported(self.decoder, z)?)?.0)
    }

    /// `J^T (G(z + h e_i) - G(z - h e_i)) / 2h` with the Jacobian `J` taken at `z`.
    fn hessian(&mut self, z: &[f64], h: f64) -> anyhow::Result<DMatrix<f64>> {
        let jacobian = self.jacobian(z)?;
        let mut hessian = DMatrix::zeros(z.len(), z.len());
        for i in 0..z.len() {
            let mut shifted = z.to_vec();
            shifted[i] += h;
            let (_, plus) = self.encoded_gradient(&forward_exported(self.decoder, &shifted)?)?;
            shifted[i] -= 2.0 * h;
            let (_, minus) = self.encoded_gradient(&forward_exported(self.decoder, &shifted)?)?;
            let difference =
                DVector::from_iterator(plus.len(), plus.iter().zip(&minus).map(|(a, b)| (a - b) / (2.0 * h)));
            hessian.set_column(i, &jacobian.tr_mul(&difference));
        }
        Ok(hessian)
    }
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        anyhow::bail!("usage: latent_rollout ARTIFACT.mochi DATASET_DIR [FRAMES]");
    }
    let model = LoadedModel::new(Artifact::read(std::path::Path::new(&args[1]))?)?;
    let dir = std::path::PathBuf::from(&args[2]);
    let frames: usize = args.get(3).map_or(Ok(300), |s| s.parse())?;
    let a = &model.artifact;
    let (problem, encoding) = rebuild_problem(a)?;
    let encoder = a.encoder().map_err(anyhow::Error::msg)?;
    let (dim, diagonal) = (problem.mesh.dim, a.diagonal);
    let penalty = (!matches!(problem.mesh.elements, Elements::Rods(_))).then_some(PAPER_BC_WEIGHT);
    let mut loss = PhysicsLoss::new(&problem.scene, &problem.mesh, &problem.handles, penalty)?;
    let encode =
        |x: &[f64]| -> anyhow::Result<Vec<f64>> { Ok(forward_exported(&encoder, &encoding.encode_state(x)?)?) };
    println!(
        "{}: the latent space of {} (k={})",
        problem.scene.name,
        args[1],
        model.integrator.latent()
    );
    for (plan, reference) in dataset::load(&problem, &dir, Split::Test)? {
        let n = frames.min(reference.num_frames() - 1);
        let decode = |z: &[f64], t: usize| -> anyhow::Result<Vec<f64>> {
            let targets = encoding.handle_targets(&reference.positions[t])?;
            Ok(encoding.decode(&forward_exported(&model.decoder, z)?, &targets)?)
        };
        let z0 = encode(&reference.positions[0])?;
        let mut latents = vec![z0.clone(), z0.clone()];
        let mut states = vec![decode(&z0, 0)?, decode(&z0, 0)?];
        let mut errors = Vec::with_capacity(n);
        let mut round_trip_error = 0.0;
        let mut iterations = 0;
        for t in 1..=n {
            let targets = encoding.handle_targets(&reference.positions[t])?;
            let mut step = LatentStep {
                loss: &mut loss,
                encoding: &encoding,
                decoder: &model.decoder,
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
            round_trip_error += mean_error(&decode(&encode(&reference.positions[t])?, t)?) / n as f64;
            latents.push(z);
            states.push(x);
        }
        report(&plan.name, &plan.description, &errors, iterations, round_trip_error);
    }
    Ok(())
}
