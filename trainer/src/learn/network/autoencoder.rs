//! The autoencoder (Sec. 3.2, Eq. 2): an encoder [`ResMlp`] and a [`Decoder`] (a residual MLP,
//! or a linear basis after a small one), optionally initialised as the PCA of the data.

use candle_core::{Tensor, Var};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::decoder::{Decoder, DecoderShape, FrozenDecoder};
use super::error::{invalid, ModelResult};
use super::exported::{DenseLayer, ExportedMlp};
use super::layout::{MlpSpec, MlpStyle};
use super::mlp::{random_values, Dense, ResMlp};

/// Sizes of an autoencoder: the encoder is a [`ResMlp`] `input -> latent`; the decoder one
/// `latent -> input` with the same `hidden` width and `blocks` ([`DecoderShape::Mlp`]), or a
/// basis after a smaller one ([`DecoderShape::Basis`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct AutoencoderSpec {
    /// Length of an encoded state (the full-space vector).
    pub input: usize,
    /// Latent size `k`.
    pub latent: usize,
    /// Hidden width of encoder and decoder.
    pub hidden: usize,
    /// Residual blocks in each of encoder and decoder.
    pub blocks: usize,
    /// The decoder's shape.
    #[serde(default)]
    pub shape: DecoderShape,
}

impl AutoencoderSpec {
    /// Sizes of the encoder.
    pub fn encoder(&self) -> MlpSpec {
        MlpSpec {
            input: self.input,
            output: self.latent,
            hidden: self.hidden,
            blocks: self.blocks,
        }
    }

    /// Sizes of the decoder when it is a residual MLP.
    pub fn decoder(&self) -> MlpSpec {
        MlpSpec {
            input: self.latent,
            output: self.input,
            hidden: self.hidden,
            blocks: self.blocks,
        }
    }
}

/// An autoencoder: encoder `E: R^input -> R^k` and decoder `D: R^k -> R^input`.
#[derive(Debug, Clone)]
pub(crate) struct Autoencoder {
    spec: AutoencoderSpec,
    encoder: ResMlp,
    decoder: Decoder,
}

/// A frozen autoencoder.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ExportedAutoencoder {
    /// The encoder, `input -> latent`.
    pub encoder: ExportedMlp,
    /// The decoder, `latent -> input`.
    pub decoder: FrozenDecoder,
}

impl Autoencoder {
    /// A randomly initialised autoencoder (encoder drawn first, then decoder, from `seed`).
    #[cfg(test)]
    pub(crate) fn new(spec: AutoencoderSpec, seed: u64) -> ModelResult<Self> {
        Self::new_styled(spec, MlpStyle::default(), seed)
    }

    /// A randomly initialised autoencoder whose two MLPs have `style` (a [`DecoderShape::Mlp`]
    /// decoder only).
    pub(crate) fn new_styled(spec: AutoencoderSpec, style: MlpStyle, seed: u64) -> ModelResult<Self> {
        if spec.shape != DecoderShape::Mlp {
            return invalid(format!("a random autoencoder has an MLP decoder, not {:?}", spec.shape));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let encoder = ResMlp::new_styled(spec.encoder(), style, &mut rng)?;
        let decoder = Decoder::Mlp(ResMlp::new_styled(spec.decoder(), style, &mut rng)?);
        Ok(Autoencoder { spec, encoder, decoder })
    }

    /// A randomly initialised autoencoder of `style` between the fixed maps of a PCA (`mean`
    /// and the components `basis`, each of `spec.input` values): the encoder's MLP reads
    /// `B^T (x - mean)`, the decoder's writes `y` to `mean + B y` (Lyu et al.'s code with a PCA
    /// basis). Training changes the MLPs, never the maps.
    pub(crate) fn new_projected(
        spec: AutoencoderSpec,
        style: MlpStyle,
        mean: &[f64],
        basis: &[Vec<f64>],
        seed: u64,
    ) -> ModelResult<Self> {
        let (n, modes) = (spec.input, basis.len());
        if modes == 0 || mean.len() != n || basis.iter().any(|b| b.len() != n) {
            return invalid(format!(
                "a projection needs a mean and components of {n} values, got {} and {modes} components",
                mean.len()
            ));
        }
        let inner = AutoencoderSpec { input: modes, ..spec };
        let Autoencoder { encoder, decoder, .. } = Self::new_styled(inner, style, seed)?;
        // B^T x - B^T mean (modes x n) and B y + mean (n x modes).
        let down = DenseLayer {
            rows: modes,
            cols: n,
            weights: basis.iter().flatten().map(|&v| v as f32).collect(),
            bias: basis
                .iter()
                .map(|b| -b.iter().zip(mean).map(|(b, m)| b * m).sum::<f64>() as f32)
                .collect(),
        };
        let up = DenseLayer {
            rows: n,
            cols: modes,
            weights: (0..n).flat_map(|i| basis.iter().map(move |b| b[i] as f32)).collect(),
            bias: mean.iter().map(|&m| m as f32).collect(),
        };
        let Decoder::Mlp(decoder) = decoder else {
            return invalid("a projected autoencoder has an MLP decoder");
        };
        Ok(Autoencoder {
            spec,
            encoder: encoder.with_projections(Some(down), None)?,
            decoder: Decoder::Mlp(decoder.with_projections(None, Some(up))?),
        })
    }

    /// An autoencoder that, at initialisation, is exactly the PCA of the data (Fulton et al.
    /// 2019): `E(x) = B (x - mean)` and `D(z) = mean + B^T z`, where `B` is the first `latent`
    /// rows of `pca_basis` (each of length `input`).
    ///
    /// Embedding (needs `hidden >= 2 * latent`): with `c = B (x - mean)`, the encoder's input
    /// layer puts `c` in hidden units `0..k` and `-c` in units `k..2k` (weights `B`, `-B`,
    /// biases `-B mean`, `B mean`); its remaining units are random rows acting on `x - mean`.
    /// Blocks start as the identity. The output layer reads `swish(c) - swish(-c)`, which is
    /// exactly `c` because `v*sigmoid(v) + v*sigmoid(-v) = v`: columns `0..k` are `I`, columns
    /// `k..2k` are `-I`, the rest and the bias are zero. The decoder mirrors this: its input
    /// layer writes `z` and `-z` to units `0..k` and `k..2k` (random rows after that), and its
    /// output layer has columns `B^T`, `-B^T`, zeros, and bias `mean`. So `D(E(x))` is the PCA
    /// reconstruction up to f32 round-off, while the random units give training room to bend
    /// the subspace; their output weights start at zero and receive gradient at once.
    ///
    /// A basis decoder ([`DecoderShape::Basis`]) is built by [`Decoder::basis_from_pca`]
    /// instead, from the first `modes` components: it also starts as the PCA with `latent`
    /// components.
    pub(crate) fn new_pca_init(
        spec: AutoencoderSpec,
        pca_mean: &[f64],
        pca_basis: &[Vec<f64>],
        seed: u64,
    ) -> ModelResult<Self> {
        let (n, k, hidden) = (spec.input, spec.latent, spec.hidden);
        spec.encoder().check()?;
        if hidden < 2 * k {
            return invalid(format!(
                "PCA initialisation needs hidden width >= 2 * latent ({}), got {hidden}",
                2 * k
            ));
        }
        if pca_mean.len() != n {
            return invalid(format!("PCA mean has length {}, expected {n}", pca_mean.len()));
        }
        if pca_basis.len() < k {
            return invalid(format!(
                "PCA basis has {} vectors, the latent size is {k}",
                pca_basis.len()
            ));
        }
        let basis = &pca_basis[..k];
        if let Some(i) = basis.iter().position(|b| b.len() != n) {
            return invalid(format!(
                "PCA basis vector {i} has length {}, expected {n}",
                basis[i].len()
            ));
        }
        let all_finite = pca_mean.iter().chain(basis.iter().flatten()).all(|v| v.is_finite());
        if !all_finite {
            return invalid("PCA mean or basis holds a non-finite value");
        }

        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        // Encoder input layer: rows +B, -B, then random rows acting on x - mean.
        let (mut w, mut b) = random_values(hidden, n, &mut rng);
        for (r, row) in w.chunks_exact_mut(n).enumerate() {
            if r < 2 * k {
                let sign = if r < k { 1.0 } else { -1.0 };
                let basis_row = &basis[r % k];
                for (dst, &src) in row.iter_mut().zip(basis_row) {
                    *dst = (sign * src) as f32;
                }
                b[r] = 0.0;
            }
            let centre: f64 = row.iter().zip(pca_mean).map(|(&w, &m)| w as f64 * m).sum();
            b[r] = (b[r] as f64 - centre) as f32;
        }
        let enc_input = Dense::from_values(hidden, n, w, b)?;
        let encoder = ResMlp::with_ends(spec.encoder(), MlpStyle::default(), enc_input, &mut rng, |_| {
            let mut w = vec![0.0f32; k * hidden];
            for i in 0..k {
                w[i * hidden + i] = 1.0;
                w[i * hidden + k + i] = -1.0;
            }
            Dense::from_values(k, hidden, w, vec![0.0; k])
        })?;

        if let DecoderShape::Basis { .. } = spec.shape {
            let decoder = Decoder::basis_from_pca(k, spec.shape, pca_mean, pca_basis, &mut rng)?;
            return Ok(Autoencoder { spec, encoder, decoder });
        }
        // Decoder input layer: rows +I, -I (zero bias), then random rows.
        let (mut w, mut b) = random_values(hidden, k, &mut rng);
        for r in 0..2 * k {
            let row = &mut w[r * k..(r + 1) * k];
            row.fill(0.0);
            row[r % k] = if r < k { 1.0 } else { -1.0 };
            b[r] = 0.0;
        }
        let dec_input = Dense::from_values(hidden, k, w, b)?;
        let decoder = ResMlp::with_ends(spec.decoder(), MlpStyle::default(), dec_input, &mut rng, |_| {
            let mut w = vec![0.0f32; n * hidden];
            for (r, row) in w.chunks_exact_mut(hidden).enumerate() {
                for i in 0..k {
                    row[i] = basis[i][r] as f32;
                    row[k + i] = -basis[i][r] as f32;
                }
            }
            let bias = pca_mean.iter().map(|&m| m as f32).collect();
            Dense::from_values(n, hidden, w, bias)
        })?;
        let decoder = Decoder::Mlp(decoder);
        Ok(Autoencoder { spec, encoder, decoder })
    }

    /// A trainable copy of a frozen autoencoder (its own variables: training it leaves the
    /// network it was exported from unchanged).
    pub(crate) fn from_exported(spec: AutoencoderSpec, frozen: &ExportedAutoencoder) -> ModelResult<Self> {
        let encoder = ResMlp::from_exported(&frozen.encoder)?;
        let decoder = Decoder::from_frozen(&frozen.decoder)?;
        let decoder_fits = match (&frozen.decoder, spec.shape) {
            (FrozenDecoder::Mlp(m), DecoderShape::Mlp) => m.spec() == spec.decoder(),
            (FrozenDecoder::Basis { .. }, DecoderShape::Basis { .. }) => {
                frozen.decoder.latent() == spec.latent && frozen.decoder.output() == spec.input
            }
            _ => false,
        };
        if frozen.encoder.spec() != spec.encoder() || !decoder_fits {
            return invalid(format!("the frozen networks do not have the sizes {spec:?}"));
        }
        Ok(Autoencoder { spec, encoder, decoder })
    }

    /// The sizes of this autoencoder.
    pub fn spec(&self) -> AutoencoderSpec {
        self.spec
    }

    /// The decoder network.
    pub(crate) fn decoder(&self) -> &Decoder {
        &self.decoder
    }

    /// Latents of a batch of states: `(batch, input) -> (batch, latent)`.
    pub(crate) fn encode(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        self.encoder.forward(x)
    }

    /// States of a batch of latents: `(batch, latent) -> (batch, input)`.
    pub fn decode(&self, z: &Tensor) -> candle_core::Result<Tensor> {
        self.decoder.forward(z)
    }

    /// `D(E(x))`.
    pub fn reconstruct(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        self.decode(&self.encode(x)?)
    }

    /// The reconstruction loss of Eq. 2 on a batch, as the mean over the batch and the
    /// coordinates of `(D(E(x)) - x)^2` (Eq. 2's sum divided by `batch * input`).
    #[cfg(test)]
    pub(crate) fn reconstruction_loss(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        Autoencoder::reconstruction_loss_of(&self.reconstruct(x)?, x)
    }

    /// [`Autoencoder::reconstruction_loss`] of states `x` already reconstructed as `decoded`.
    pub(crate) fn reconstruction_loss_of(decoded: &Tensor, x: &Tensor) -> candle_core::Result<Tensor> {
        (decoded - x)?.sqr()?.mean_all()
    }

    /// The trainable variables (`encoder.*`, then `decoder.*`).
    pub(crate) fn parameters(&self) -> Vec<(String, Var)> {
        let mut out = self.encoder.parameters("encoder");
        out.extend(self.decoder.parameters("decoder"));
        out
    }

    /// Freezes the current weights.
    pub(crate) fn export(&self) -> ModelResult<ExportedAutoencoder> {
        Ok(ExportedAutoencoder {
            encoder: self.encoder.export()?,
            decoder: self.decoder.export()?,
        })
    }
}

#[cfg(test)]
mod tests {
    use rand::Rng;

    use super::*;
    use crate::learn::network::exported::forward_exported;
    use crate::learn::network::tensor::tensor_to_rows;
    use crate::learn::network::test_support::*;

    #[test]
    fn exported_autoencoder_matches_candle() {
        let spec = AutoencoderSpec {
            input: 30,
            latent: 3,
            hidden: 16,
            blocks: 2,
            shape: DecoderShape::Mlp,
        };
        let ae = Autoencoder::new(spec, 3).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        randomise(&ae.parameters(), 0.3, &mut rng);
        let x = random_rows(8, 30, 1.0, &mut rng);
        let z = ae.encode(&as_tensor(&x)).unwrap();
        let y = tensor_to_rows(&ae.decode(&z).unwrap()).unwrap();
        let z = tensor_to_rows(&z).unwrap();
        let exported = ae.export().unwrap();
        let z_plain: Vec<Vec<f32>> = x
            .iter()
            .map(|x| forward_exported(&exported.encoder, x).unwrap())
            .collect();
        let y_plain: Vec<Vec<f32>> = z.iter().map(|z| exported.decoder.decode(z).unwrap()).collect();
        assert!(max_relative_difference(&z_plain, &z) < 1e-5);
        assert!(max_relative_difference(&y_plain, &y) < 1e-5);
    }

    #[test]
    fn pca_initialised_autoencoder_is_the_pca() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let (n, k) = (30, 3);
        // Data with a dominant 3D linear part, a small remainder, and an offset mean.
        let data: Vec<Vec<f32>> = (0..200)
            .map(|_| {
                let a: [f32; 3] = std::array::from_fn(|_| rng.random_range(-1.0..1.0));
                (0..n)
                    .map(|j| {
                        let jf = j as f32;
                        2.0 + 0.1 * jf
                            + a[0] * (0.3 * jf).sin()
                            + a[1] * (0.2 * jf).cos()
                            + 0.5 * a[2] * (jf / n as f32)
                            + 0.05 * rng.random_range(-1.0f32..1.0)
                    })
                    .collect()
            })
            .collect();
        let (mean, basis) = pca(&data, k);
        let spec = AutoencoderSpec {
            input: n,
            latent: k,
            hidden: 16,
            blocks: 2,
            shape: DecoderShape::Mlp,
        };
        let ae = Autoencoder::new_pca_init(spec, &mean, &basis, 9).unwrap();
        let x = as_tensor(&data);
        let z = tensor_to_rows(&ae.encode(&x).unwrap()).unwrap();
        let y = tensor_to_rows(&ae.reconstruct(&x).unwrap()).unwrap();
        let (z_pca, y_pca): (Vec<Vec<f32>>, Vec<Vec<f32>>) = data
            .iter()
            .map(|x| {
                let c: Vec<f64> = basis
                    .iter()
                    .map(|b| b.iter().zip(x).zip(&mean).map(|((b, &x), m)| b * (x as f64 - m)).sum())
                    .collect();
                let y = (0..n)
                    .map(|j| (mean[j] + (0..k).map(|i| basis[i][j] * c[i]).sum::<f64>()) as f32)
                    .collect();
                (c.iter().map(|&c| c as f32).collect(), y)
            })
            .unzip();
        let dz = max_relative_difference(&z, &z_pca);
        let dy = max_relative_difference(&y, &y_pca);
        assert!(dz < 1e-5 && dy < 1e-5, "latent differs by {dz}, reconstruction by {dy}");
        // And the PCA with 3 components is a good but not perfect reconstruction here.
        let mse = |a: &[Vec<f32>]| {
            a.iter()
                .flatten()
                .zip(data.iter().flatten())
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f32>()
                / (data.len() * n) as f32
        };
        assert!(mse(&y) > 1e-5 && mse(&y) < 2e-3, "PCA error {}", mse(&y));
        let loss = ae.reconstruction_loss(&x).unwrap().to_scalar::<f32>().unwrap();
        assert!(
            (loss - mse(&y_pca)).abs() < 1e-3 * mse(&y_pca),
            "{loss} vs {}",
            mse(&y_pca)
        );
    }

    #[test]
    fn pca_init_rejects_inconsistent_input() {
        let spec = AutoencoderSpec {
            input: 4,
            latent: 2,
            hidden: 4,
            blocks: 1,
            shape: DecoderShape::Mlp,
        };
        let basis = vec![vec![1.0, 0.0, 0.0, 0.0], vec![0.0, 1.0, 0.0, 0.0]];
        let mean = vec![0.0; 4];
        assert!(Autoencoder::new_pca_init(spec, &mean, &basis, 0).is_ok());
        let narrow = AutoencoderSpec { hidden: 3, ..spec };
        let err = Autoencoder::new_pca_init(narrow, &mean, &basis, 0).unwrap_err();
        assert!(err.to_string().contains("hidden width"), "{err}");
        assert!(Autoencoder::new_pca_init(spec, &mean[..3], &basis, 0).is_err());
        assert!(Autoencoder::new_pca_init(spec, &mean, &basis[..1], 0).is_err());
        let short = vec![basis[0].clone(), vec![0.0; 3]];
        assert!(Autoencoder::new_pca_init(spec, &mean, &short, 0).is_err());
        let nan = vec![basis[0].clone(), vec![f64::NAN; 4]];
        assert!(Autoencoder::new_pca_init(spec, &mean, &nan, 0).is_err());
        let empty = AutoencoderSpec { latent: 0, ..spec };
        assert!(Autoencoder::new_pca_init(empty, &mean, &basis, 0).is_err());
    }
}
