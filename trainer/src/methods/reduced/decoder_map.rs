//! The decoder of a reduced subspace, `q = D(z)` in the encoded layout: a trained network
//! (vanilla and Lipschitz-optimised subspaces), or the linear map of a PCA, `q = mean + B z`
//! (the classic linear subspace). Both give the value, the exact Jacobian, the gradient
//! pulled back through the map and the map's second derivatives, which are zero for the
//! linear one.

use crate::learn::network::derivatives::{check_len, Mlp64, Mlp64Workspace};
use crate::learn::network::{ExportedMlp, ModelResult};
use crate::learn::pca::Pca;

/// A subspace's decoder, as the caller holds it.
#[derive(Clone, Copy, Debug)]
pub enum SubspaceDecoder<'a> {
    /// A trained network.
    Network(&'a ExportedMlp),
    /// A PCA: its mean and components.
    Linear(&'a Pca),
}

impl<'a> From<&'a ExportedMlp> for SubspaceDecoder<'a> {
    fn from(mlp: &'a ExportedMlp) -> Self {
        SubspaceDecoder::Network(mlp)
    }
}

impl<'a> From<&'a Pca> for SubspaceDecoder<'a> {
    fn from(pca: &'a Pca) -> Self {
        SubspaceDecoder::Linear(pca)
    }
}

/// The decoder in `f64` with the buffers its derivatives need.
#[derive(Clone)]
pub(super) enum DecoderMap {
    Network { mlp: Mlp64, workspace: Box<Mlp64Workspace> },
    Linear(LinearMap),
}

/// `q = mean + B z`, `B` stored row-major (`outputs x r`).
#[derive(Clone)]
pub(super) struct LinearMap {
    mean: Vec<f64>,
    rows: Vec<f64>,
    latent: usize,
}

impl DecoderMap {
    pub(super) fn new(decoder: SubspaceDecoder<'_>) -> Self {
        match decoder {
            SubspaceDecoder::Network(exported) => {
                let mlp = Mlp64::new(exported);
                let workspace = Box::new(Mlp64Workspace::new(&mlp));
                DecoderMap::Network { mlp, workspace }
            }
            SubspaceDecoder::Linear(pca) => {
                let (n, r) = (pca.mean.len(), pca.basis.len());
                let mut rows = vec![0.0; n * r];
                for (k, component) in pca.basis.iter().enumerate() {
                    for (i, &b) in component.iter().enumerate().take(n) {
                        rows[i * r + k] = b;
                    }
                }
                DecoderMap::Linear(LinearMap {
                    mean: pca.mean.clone(),
                    rows,
                    latent: r,
                })
            }
        }
    }

    pub(super) fn input_len(&self) -> usize {
        match self {
            DecoderMap::Network { mlp, .. } => mlp.input_len(),
            DecoderMap::Linear(l) => l.latent,
        }
    }

    pub(super) fn output_len(&self) -> usize {
        match self {
            DecoderMap::Network { mlp, .. } => mlp.output_len(),
            DecoderMap::Linear(l) => l.mean.len(),
        }
    }

    /// `q = D(z)`.
    pub(super) fn value(&mut self, z: &[f64], q: &mut [f64]) -> ModelResult<()> {
        match self {
            DecoderMap::Network { mlp, workspace } => mlp.value(z, q, workspace),
            DecoderMap::Linear(l) => l.value(z, q),
        }
    }

    /// `q = D(z)` and `dq/dz` (`outputs x r`, row-major).
    pub(super) fn jacobian(&mut self, z: &[f64], q: &mut [f64], jac: &mut [f64]) -> ModelResult<()> {
        match self {
            DecoderMap::Network { mlp, workspace } => mlp.jacobian(z, q, jac, workspace),
            DecoderMap::Linear(l) => {
                check_len("Jacobian", jac.len(), l.rows.len())?;
                jac.copy_from_slice(&l.rows);
                l.value(z, q)
            }
        }
    }

    /// `(dq/dz)^T w`; `after_value`: the last call was [`DecoderMap::value`] at `z`, whose
    /// hidden pass a network reuses.
    pub(super) fn pulled_back(&mut self, z: &[f64], w: &[f64], out: &mut [f64], after_value: bool) -> ModelResult<()> {
        match self {
            DecoderMap::Network { mlp, workspace } if after_value => mlp.pulled_back_after_value(w, out, workspace),
            DecoderMap::Network { mlp, workspace } => mlp.pulled_back(z, w, out, workspace),
            DecoderMap::Linear(l) => {
                check_len("weights", w.len(), l.mean.len())?;
                check_len("output", out.len(), l.latent)?;
                out.fill(0.0);
                for (row, &wi) in l.rows.chunks_exact(l.latent).zip(w) {
                    out.iter_mut().zip(row).for_each(|(o, &b)| *o += wi * b);
                }
                Ok(())
            }
        }
    }

    /// `sum_i w_i d^2 q_i / dz^2` (`r x r`, row-major).
    pub(super) fn contracted_hessian(&mut self, z: &[f64], w: &[f64], out: &mut [f64]) -> ModelResult<()> {
        match self {
            DecoderMap::Network { mlp, workspace } => mlp.contracted_hessian(z, w, out, workspace),
            DecoderMap::Linear(_) => {
                out.fill(0.0);
                Ok(())
            }
        }
    }

    /// `d^2/dt^2 D(z + t v)` at `t = 0`.
    pub(super) fn second_directional(&mut self, z: &[f64], v: &[f64], out: &mut [f64]) -> ModelResult<()> {
        match self {
            DecoderMap::Network { mlp, workspace } => mlp.second_directional(z, v, out, workspace),
            DecoderMap::Linear(_) => {
                out.fill(0.0);
                Ok(())
            }
        }
    }
}

impl LinearMap {
    fn value(&self, z: &[f64], q: &mut [f64]) -> ModelResult<()> {
        check_len("input", z.len(), self.latent)?;
        check_len("output", q.len(), self.mean.len())?;
        for ((qi, &m), row) in q.iter_mut().zip(&self.mean).zip(self.rows.chunks_exact(self.latent)) {
            *qi = m + row.iter().zip(z).map(|(b, z)| b * z).sum::<f64>();
        }
        Ok(())
    }
}
