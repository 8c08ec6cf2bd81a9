//! Diagnostic: implicit Euler restricted to the PCA subspace of a scene's training frames,
//! rolled out on the scene's test sequences against the full-space reference.
//!
//! ```sh
//! cargo run --release -p mochi-trainer --example pca_rollout -- SCENE K DATASET_DIR [FRAMES] [SEQUENCE,...]
//! ```
//!
//! Each step minimises the same incremental potential the latent integrator is trained on
//! ([`mochi_trainer::learn::loss::PhysicsLoss`]: inertia, the scene's energies, the handle penalty
//! for cloth and solids) over the latent `z` of `x = decode(mean + B z)` (the BC-relative
//! encoding of `mochi train` with its first `K` principal components `B`), by Newton's
//! method in `z`: the reduced
//! gradient `B^T R^T dE/dx`, the reduced Hessian `B^T` times central differences of the
//! encoded gradient, eigenvalues taken in absolute value, backtracking line search (the
//! loop shared with `latent_rollout`, in `common`). It answers whether a subspace can carry
//! a scene's dynamics at all, apart from whether a network can learn to step in it: on `rods`
//! the self-supervised integrator fails while this solve follows the reference closely.
//! The dataset (both splits) is generated in `DATASET_DIR` if missing.

mod common;

use common::{rollout, subspace_from_args, Subspace};
use mochi_trainer::learn::pca::Pca;
use nalgebra::{DMatrix, DVector};

/// The first `K` principal components of the training frames: `q = mean + B z`.
struct PcaSubspace(Pca);

impl Subspace for PcaSubspace {
    fn describe(&self) -> String {
        format!("PCA k={} of the training frames", self.0.num_components())
    }
    fn lower(&self, z: &[f64]) -> anyhow::Result<Vec<f64>> {
        Ok(self.0.reconstruct(z)?)
    }
    fn lift(&self, q: &[f64]) -> anyhow::Result<Vec<f64>> {
        Ok(self.0.project(q)?)
    }
    fn jacobian(&self, _: &[f64]) -> anyhow::Result<DMatrix<f64>> {
        let columns: Vec<DVector<f64>> = self.0.basis.iter().map(|b| DVector::from_column_slice(b)).collect();
        Ok(DMatrix::from_columns(&columns))
    }
}

fn main() -> anyhow::Result<()> {
    mochi_trainer::configure_threads();
    let (args, pca) = subspace_from_args("pca_rollout")?;
    rollout(
        &args.problem,
        &args.encoding,
        &PcaSubspace(pca),
        &args.dir,
        args.frames,
        &args.only,
    )
}
