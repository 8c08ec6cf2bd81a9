//! Diagnostic: implicit Euler restricted to a trained model's latent space (its decoder),
//! rolled out on the scene's test sequences against the full-space reference.
//!
//! ```sh
//! cargo run --release -p mochi-trainer --example latent_rollout -- ARTIFACT.mochi DATASET_DIR [FRAMES] [SEQUENCE,...]
//! ```
//!
//! `SEQUENCE,...` (e.g. `test-00,test-01`) limits the rollout to those test sequences.
//!
//! The counterpart of `pca_rollout` for the autoencoder's nonlinear subspace: each step
//! minimises the potential the integrator is trained on
//! ([`mochi_trainer::learn::loss::PhysicsLoss`]) over the latent `z` of `x = decode(decoder(z))`, by
//! Newton's method in `z`, starting from the encoder's latent of the first reference frame.
//! The decoder runs in `f64` and is differentiated by central differences; the Hessian keeps
//! the decoder's Jacobian fixed at `z` (the decoder's curvature is left out; the line search
//! keeps every step a descent). Where this rollout follows the reference and the trained
//! integrator does not, the integrator is the limit; where this one leaves it too, the
//! latent space is.

mod common;

use common::{rollout, Subspace};
use mochi_trainer::artifact::Artifact;
use mochi_trainer::eval::{rebuild_problem, LoadedModel};
use mochi_trainer::learn::network::{forward_exported, ExportedMlp, FrozenDecoder};
use nalgebra::{DMatrix, DVector};

/// Step of the decoder's central differences, in latent units.
const JACOBIAN_STEP: f64 = 1e-5;

/// A trained model's latent space: `q = decoder(z)`, lifted by its encoder.
struct DecoderSubspace {
    name: String,
    encoder: ExportedMlp,
    decoder: FrozenDecoder,
}

impl Subspace for DecoderSubspace {
    fn describe(&self) -> String {
        format!("the latent space of {} (k={})", self.name, self.decoder.latent())
    }
    fn lower(&self, z: &[f64]) -> anyhow::Result<Vec<f64>> {
        Ok(self.decoder.decode(z)?)
    }
    fn lift(&self, q: &[f64]) -> anyhow::Result<Vec<f64>> {
        Ok(forward_exported(&self.encoder, q)?)
    }
    /// By central differences of the decoder in `f64`.
    fn jacobian(&self, z: &[f64]) -> anyhow::Result<DMatrix<f64>> {
        let mut columns = Vec::with_capacity(z.len());
        for i in 0..z.len() {
            let mut shifted = z.to_vec();
            shifted[i] += JACOBIAN_STEP;
            let plus = self.lower(&shifted)?;
            shifted[i] -= 2.0 * JACOBIAN_STEP;
            let minus = self.lower(&shifted)?;
            let column = plus.iter().zip(&minus).map(|(a, b)| (a - b) / (2.0 * JACOBIAN_STEP));
            columns.push(DVector::from_iterator(plus.len(), column));
        }
        Ok(DMatrix::from_columns(&columns))
    }
}

fn main() -> anyhow::Result<()> {
    mochi_trainer::configure_threads();
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        anyhow::bail!("usage: latent_rollout ARTIFACT.mochi DATASET_DIR [FRAMES] [SEQUENCE,...]");
    }
    let model = LoadedModel::new(Artifact::read(std::path::Path::new(&args[1]))?)?;
    let frames: usize = args.get(3).map_or(Ok(300), |s| s.parse())?;
    let (problem, encoding) = rebuild_problem(&model.artifact)?;
    let subspace = DecoderSubspace {
        name: args[1].clone(),
        encoder: model.artifact.encoder().map_err(anyhow::Error::msg)?,
        decoder: model.decoder.clone(),
    };
    let only: Vec<String> = args
        .get(4)
        .map_or(Vec::new(), |s| s.split(',').map(String::from).collect());
    rollout(
        &problem,
        &encoding,
        &subspace,
        std::path::Path::new(&args[2]),
        frames,
        &only,
    )
}
