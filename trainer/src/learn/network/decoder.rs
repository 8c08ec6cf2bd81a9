//! Decoders: a residual MLP (the layout of [`super`]), or a linear basis of `m` modes after a
//! small residual MLP (Li et al. 2025's narrow layer before the output; none for a linear
//! decoder such as a PCA basis). The basis decoder computes
//!
//! ```text
//! f = [z; 0] + g(z)        g: residual MLP latent -> m (none: f = z, m = latent)
//! y = B f + b              B: output × m
//! ```
//!
//! exactly as the runtime does (`mochi_runtime::Model::decoder_basis`). Initialised from a PCA
//! (`B` the first `m` components, `b` the mean, `g`'s output layer zero), it starts as the
//! PCA with `latent` components, and `g` learns to fill in the other `m - latent` from the
//! latent.

use candle_core::{Tensor, Var};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::error::{invalid, ModelResult};
use super::exported::{forward_exported, DenseLayer, ExportedMlp};
use super::layout::{MlpSpec, MlpStyle, Real};
use super::mlp::{Dense, ResMlp};

/// The shape of a decoder.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum DecoderShape {
    /// A residual MLP with the autoencoder's hidden width and blocks.
    #[default]
    Mlp,
    /// A basis of `modes` columns after a residual MLP of width `hidden` with `blocks`
    /// blocks (`hidden = 0`: no MLP, a linear decoder with `modes` equal to the latent size).
    Basis {
        /// Columns of the basis `m`.
        modes: usize,
        /// Width of the MLP before the basis (0: none).
        hidden: usize,
        /// Its residual blocks.
        blocks: usize,
    },
}

impl DecoderShape {
    /// Checks the shape against the latent size.
    pub(crate) fn check(&self, latent: usize) -> ModelResult<()> {
        match *self {
            DecoderShape::Mlp => Ok(()),
            DecoderShape::Basis { modes, hidden, .. } => {
                if modes < latent || (hidden == 0 && modes != latent) {
                    return invalid(format!(
                        "a basis of {modes} modes cannot decode a latent of {latent} (linear: as many modes as the latent; with an MLP: at least as many)"
                    ));
                }
                Ok(())
            }
        }
    }

    /// Short name for tables: `mlp`, `linear`, `basis`.
    pub fn family(&self) -> &'static str {
        match self {
            DecoderShape::Mlp => "mlp",
            DecoderShape::Basis { hidden: 0, .. } => "linear",
            DecoderShape::Basis { .. } => "mlp + basis",
        }
    }
}

/// A frozen decoder.
#[derive(Debug, Clone, PartialEq)]
pub enum FrozenDecoder {
    /// A residual MLP.
    Mlp(ExportedMlp),
    /// A basis after an optional residual MLP (see the module docs).
    Basis {
        /// The MLP `g` (latent -> modes), if any.
        mlp: Option<ExportedMlp>,
        /// The basis `B` and offset `b`.
        basis: DenseLayer,
    },
}

impl FrozenDecoder {
    /// The style of its MLP (the default where it has none).
    pub fn style(&self) -> MlpStyle {
        match self {
            FrozenDecoder::Mlp(m) => m.style(),
            FrozenDecoder::Basis { mlp, .. } => mlp.as_ref().map_or_else(MlpStyle::default, |m| m.style()),
        }
    }

    /// Builds from the artifact's flat layer list and its `decoder_basis` flag, checking every
    /// shape.
    pub fn from_layers(mut layers: Vec<DenseLayer>, basis: bool) -> ModelResult<Self> {
        if !basis {
            return Ok(FrozenDecoder::Mlp(ExportedMlp::from_layers(layers)?));
        }
        let Some(last) = layers.pop() else {
            return invalid("a basis decoder needs at least its basis layer");
        };
        last.check("basis")?;
        let mlp = if layers.is_empty() {
            None
        } else {
            let mlp = ExportedMlp::from_layers(layers)?;
            if mlp.spec().output != last.cols {
                return invalid(format!(
                    "the MLP before the basis writes {} features, the basis reads {}",
                    mlp.spec().output,
                    last.cols
                ));
            }
            Some(mlp)
        };
        let latent = mlp.as_ref().map_or(last.cols, |m| m.spec().input);
        if latent > last.cols {
            return invalid(format!("a latent of {latent} for a basis of {} modes", last.cols));
        }
        Ok(FrozenDecoder::Basis { mlp, basis: last })
    }

    /// Whether the last layer is a basis (the artifact's `decoder_basis`).
    pub fn is_basis(&self) -> bool {
        matches!(self, FrozenDecoder::Basis { .. })
    }

    /// Latent size.
    pub fn latent(&self) -> usize {
        match self {
            FrozenDecoder::Mlp(m) => m.spec().input,
            FrozenDecoder::Basis { mlp, basis } => mlp.as_ref().map_or(basis.cols, |m| m.spec().input),
        }
    }

    /// Length of the decoded state.
    pub fn output(&self) -> usize {
        match self {
            FrozenDecoder::Mlp(m) => m.spec().output,
            FrozenDecoder::Basis { basis, .. } => basis.rows,
        }
    }

    /// All layers in evaluation order (the artifact's list).
    pub fn layers(&self) -> Vec<&DenseLayer> {
        match self {
            FrozenDecoder::Mlp(m) => m.layers(),
            FrozenDecoder::Basis { mlp, basis } => {
                let mut out = mlp.as_ref().map_or_else(Vec::new, |m| m.layers());
                out.push(basis);
                out
            }
        }
    }

    /// The residual MLP, for methods that differentiate through one (the reduced solver).
    pub fn as_mlp(&self) -> ModelResult<&ExportedMlp> {
        match self {
            FrozenDecoder::Mlp(m) => Ok(m),
            FrozenDecoder::Basis { .. } => {
                invalid("this decoder ends in a linear basis; the reduced method needs a residual MLP decoder")
            }
        }
    }

    /// The plain-Rust forward pass (the reference for the runtime's kernels).
    pub fn decode<T: Real>(&self, z: &[T]) -> ModelResult<Vec<T>> {
        match self {
            FrozenDecoder::Mlp(m) => forward_exported(m, z),
            FrozenDecoder::Basis { mlp, basis } => {
                let mut f = match mlp {
                    Some(m) => forward_exported(m, z)?,
                    None => vec![T::default(); basis.cols],
                };
                if z.len() > f.len() {
                    return invalid(format!("latent of {} values for {} modes", z.len(), f.len()));
                }
                f.iter_mut().zip(z).for_each(|(f, &z)| *f += z);
                let mut y = vec![T::default(); basis.rows];
                basis.apply(&f, &mut y);
                Ok(y)
            }
        }
    }
}

/// A trainable decoder in candle.
#[derive(Debug, Clone)]
pub(crate) enum Decoder {
    /// A residual MLP.
    Mlp(ResMlp),
    /// A basis after an optional residual MLP.
    Basis {
        /// The MLP `g`, if any.
        mlp: Option<ResMlp>,
        /// The basis `B` and offset `b`.
        basis: Dense,
        /// Latent size.
        latent: usize,
    },
}

impl Decoder {
    /// A basis decoder that starts as the PCA with `latent` components: `B` the first `modes`
    /// vectors of `pca_basis` (each of length `output`), `b` the mean, `g` (width `hidden`,
    /// `blocks` blocks, none when `hidden = 0`) with a zero output layer.
    pub(crate) fn basis_from_pca(
        latent: usize,
        shape: DecoderShape,
        pca_mean: &[f64],
        pca_basis: &[Vec<f64>],
        rng: &mut ChaCha8Rng,
    ) -> ModelResult<Self> {
        let DecoderShape::Basis { modes, hidden, blocks } = shape else {
            return invalid("basis_from_pca needs a basis shape");
        };
        shape.check(latent)?;
        let n = pca_mean.len();
        if pca_basis.len() < modes || pca_basis[..modes].iter().any(|b| b.len() != n) {
            return invalid(format!(
                "a basis of {modes} modes needs {modes} PCA vectors of length {n}, got {}",
                pca_basis.len()
            ));
        }
        let mut w = vec![0.0f32; n * modes];
        for (r, row) in w.chunks_exact_mut(modes).enumerate() {
            for (i, v) in row.iter_mut().enumerate() {
                *v = pca_basis[i][r] as f32;
            }
        }
        let basis = Dense::from_values(n, modes, w, pca_mean.iter().map(|&m| m as f32).collect())?;
        let mlp = if hidden == 0 {
            None
        } else {
            let spec = MlpSpec {
                input: latent,
                output: modes,
                hidden,
                blocks,
            };
            let input = Dense::random(hidden, latent, rng)?;
            Some(ResMlp::with_ends(spec, MlpStyle::default(), input, rng, |_| {
                Dense::zeros(modes, hidden)
            })?)
        };
        Ok(Decoder::Basis { mlp, basis, latent })
    }

    /// The trainable copy of a frozen decoder.
    pub(crate) fn from_frozen(frozen: &FrozenDecoder) -> ModelResult<Self> {
        Ok(match frozen {
            FrozenDecoder::Mlp(m) => Decoder::Mlp(ResMlp::from_exported(m)?),
            FrozenDecoder::Basis { mlp, basis } => Decoder::Basis {
                mlp: mlp.as_ref().map(ResMlp::from_exported).transpose()?,
                basis: Dense::from_values(basis.rows, basis.cols, basis.weights.clone(), basis.bias.clone())?,
                latent: frozen.latent(),
            },
        })
    }

    /// The residual MLP, for methods that differentiate through one (the reduced method).
    pub(crate) fn as_mlp(&self) -> ModelResult<&ResMlp> {
        match self {
            Decoder::Mlp(m) => Ok(m),
            Decoder::Basis { .. } => {
                invalid("this decoder ends in a linear basis; the reduced method needs a residual MLP decoder")
            }
        }
    }

    /// States of a batch of latents: `(batch, latent) -> (batch, output)`.
    pub(crate) fn forward(&self, z: &Tensor) -> candle_core::Result<Tensor> {
        self.run(z, false)
    }

    /// As [`Decoder::forward`] with the weights held constant (gradients reach `z` only).
    pub(crate) fn forward_frozen(&self, z: &Tensor) -> candle_core::Result<Tensor> {
        self.run(z, true)
    }

    fn run(&self, z: &Tensor, frozen: bool) -> candle_core::Result<Tensor> {
        match self {
            Decoder::Mlp(m) if frozen => m.forward_frozen(z),
            Decoder::Mlp(m) => m.forward(z),
            Decoder::Basis { mlp, basis, latent } => {
                let modes = basis.weight().dims2()?.1;
                let mut f = z.pad_with_zeros(1, 0, modes - latent)?;
                if let Some(g) = mlp {
                    f = (f + if frozen { g.forward_frozen(z)? } else { g.forward(z)? })?;
                }
                if frozen {
                    basis.forward_frozen(&f)
                } else {
                    basis.forward(&f)
                }
            }
        }
    }

    /// The trainable variables, named `{prefix}.*`.
    pub(crate) fn parameters(&self, prefix: &str) -> Vec<(String, Var)> {
        match self {
            Decoder::Mlp(m) => m.parameters(prefix),
            Decoder::Basis { mlp, basis, .. } => {
                let mut out = mlp
                    .as_ref()
                    .map_or_else(Vec::new, |g| g.parameters(&format!("{prefix}.mlp")));
                basis.parameters(&format!("{prefix}.basis"), &mut out);
                out
            }
        }
    }

    /// Freezes the current weights.
    pub(crate) fn export(&self) -> ModelResult<FrozenDecoder> {
        Ok(match self {
            Decoder::Mlp(m) => FrozenDecoder::Mlp(m.export()?),
            Decoder::Basis { mlp, basis, .. } => FrozenDecoder::Basis {
                mlp: mlp.as_ref().map(ResMlp::export).transpose()?,
                basis: basis.export()?,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;

    use super::*;
    use crate::learn::network::tensor::tensor_to_rows;
    use crate::learn::network::test_support::*;

    /// An orthonormal-ish basis of `m` vectors of length `n` and a mean.
    fn pca_like(n: usize, m: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
        let mean = (0..n).map(|j| 0.1 * j as f64).collect();
        let basis = (0..m)
            .map(|i| {
                (0..n)
                    .map(|j| ((i + 1) as f64 * 0.37 * j as f64).sin() / (n as f64).sqrt())
                    .collect()
            })
            .collect();
        (mean, basis)
    }

    #[test]
    fn basis_decoders_start_as_the_pca_and_export_what_candle_computes() {
        let (n, k) = (20, 2);
        let (mean, basis) = pca_like(n, 4);
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let z = random_rows(6, k, 1.0, &mut rng);
        for shape in [
            DecoderShape::Basis {
                modes: 2,
                hidden: 0,
                blocks: 0,
            },
            DecoderShape::Basis {
                modes: 4,
                hidden: 8,
                blocks: 1,
            },
        ] {
            let decoder = Decoder::basis_from_pca(k, shape, &mean, &basis, &mut rng).unwrap();
            // At initialisation: the PCA with `k` components.
            let y = tensor_to_rows(&decoder.forward(&as_tensor(&z)).unwrap()).unwrap();
            let pca: Vec<Vec<f32>> = z
                .iter()
                .map(|z| {
                    (0..n)
                        .map(|j| (mean[j] + (0..k).map(|i| basis[i][j] * z[i] as f64).sum::<f64>()) as f32)
                        .collect()
                })
                .collect();
            assert!(max_relative_difference(&y, &pca) < 1e-5, "{shape:?}");
            // Trained away from it, the frozen forward pass still computes what candle does.
            randomise(&decoder.parameters("d"), 0.3, &mut rng);
            let y = tensor_to_rows(&decoder.forward(&as_tensor(&z)).unwrap()).unwrap();
            assert!(
                max_relative_difference(&y, &pca) > 1e-2,
                "{shape:?}: randomise changed nothing"
            );
            let frozen = decoder.export().unwrap();
            assert!(frozen.is_basis());
            let plain: Vec<Vec<f32>> = z.iter().map(|z| frozen.decode(z).unwrap()).collect();
            assert!(max_relative_difference(&plain, &y) < 1e-5, "{shape:?}");
            let layers = frozen.layers().into_iter().cloned().collect();
            assert_eq!(FrozenDecoder::from_layers(layers, true).unwrap(), frozen);
            assert!(frozen.as_mlp().is_err());
        }
    }

    #[test]
    fn basis_shapes_that_cannot_decode_the_latent_are_refused() {
        let (mean, basis) = pca_like(10, 3);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let linear = |modes| DecoderShape::Basis {
            modes,
            hidden: 0,
            blocks: 0,
        };
        assert!(Decoder::basis_from_pca(2, linear(3), &mean, &basis, &mut rng).is_err());
        assert!(Decoder::basis_from_pca(4, linear(4), &mean, &basis, &mut rng).is_err());
        let narrow = DecoderShape::Basis {
            modes: 1,
            hidden: 4,
            blocks: 0,
        };
        assert!(Decoder::basis_from_pca(2, narrow, &mean, &basis, &mut rng).is_err());
        let layer = |rows, cols| DenseLayer {
            rows,
            cols,
            weights: vec![0.5; rows * cols],
            bias: vec![0.0; rows],
        };
        assert!(FrozenDecoder::from_layers(vec![], true).is_err());
        assert!(FrozenDecoder::from_layers(vec![layer(4, 3), layer(2, 4), layer(10, 3)], true).is_err());
        assert!(FrozenDecoder::from_layers(vec![layer(4, 3), layer(3, 4), layer(10, 3)], true).is_ok());
    }
}
