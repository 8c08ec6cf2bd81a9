//! Networks of the latent space (paper Sec. 3.2-3.3): a residual MLP, the autoencoder built from
//! two of them, and the latent integrator. They live in candle, in f32, on the CPU
//! (docs/design.md, decision 2), and export to plain dense layers for codegen (decision 4).
//!
//! # Residual MLP layout
//!
//! Every network here is a [`ResMlp`] with sizes [`MlpSpec`] `{ input, output, hidden, blocks }`.
//! For one input vector `x` (length `input`) it computes
//!
//! ```text
//! h   = W_in x + b_in                              W_in: hidden × input
//! for each block j in 0..blocks:
//!     h = h + W_out_j swish(W_in_j h + b_in_j) + b_out_j     both hidden × hidden
//! y   = W_o swish(h) + b_o                          W_o: output × hidden
//! ```
//!
//! with `swish(v) = v * sigmoid(v) = v / (1 + exp(-v))` applied elementwise. That is all: dense
//! layers, additions and Swish, so the runtime can run it without candle. The exported form
//! ([`ExportedMlp`]) keeps exactly this structure: an input layer, `blocks` pairs
//! `(inner, outer)`, and an output layer. Batch normalisation (allowed by the paper) is not
//! used: with Adam, identity-initialised residual blocks and explicit input normalisation it is
//! not needed, and leaving it out keeps the PCA initialisation exact (see
//! [`Autoencoder::new_pca_init`]) and the export free of train/eval modes.
//!
//! # Initialisation
//!
//! Dense layers start with PyTorch's default uniform law `U(-1/sqrt(cols), 1/sqrt(cols))` for
//! weights and biases, drawn from a seeded ChaCha8 generator (so a seed fixes the network). The
//! outer layer of every residual block starts at zero, so each block is the identity at
//! initialisation; its gradient is not zero, so it learns from the first step.

use candle_core::{DType, Device, Tensor, Var};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Errors building, running or exporting a network.
#[derive(Debug, thiserror::Error)]
pub enum NetworkError {
    /// A size or value given to a constructor or an exported forward pass does not fit.
    #[error("{0}")]
    Invalid(String),
    /// candle failed.
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
}

/// Result of this module's functions.
pub type ModelResult<T> = Result<T, NetworkError>;

fn invalid<T>(message: impl Into<String>) -> ModelResult<T> {
    Err(NetworkError::Invalid(message.into()))
}

/// `v * sigmoid(v)`, written as candle writes its `silu` (`v / (1 + exp(-v))`).
pub(crate) fn swish<T: Real>(v: T) -> T {
    v / (T::from_f32(1.0) + (-v).exp())
}

/// The number types the plain-Rust forward pass ([`forward_exported`]) runs in: `f32`, the
/// reference for the runtime's kernels, and `f64`, for diagnostics that differentiate a
/// frozen decoder by finite differences.
pub trait Real:
    Copy
    + Default
    + std::ops::Add<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
    + std::ops::Neg<Output = Self>
    + std::ops::AddAssign
    + std::iter::Sum
{
    /// A weight or bias in this type.
    fn from_f32(v: f32) -> Self;
    /// `e^self`.
    fn exp(self) -> Self;
}

impl Real for f32 {
    fn from_f32(v: f32) -> Self {
        v
    }
    fn exp(self) -> Self {
        f32::exp(self)
    }
}

impl Real for f64 {
    fn from_f32(v: f32) -> Self {
        v as f64
    }
    fn exp(self) -> Self {
        f64::exp(self)
    }
}

// ---------------------------------------------------------------------------------------------
// Exported (frozen) networks: plain f32 arrays and a forward pass without candle.
// ---------------------------------------------------------------------------------------------

/// One frozen dense layer `y = W x + b`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DenseLayer {
    /// Output size (rows of `W`).
    pub rows: usize,
    /// Input size (columns of `W`).
    pub cols: usize,
    /// `W`, row-major: `weights[r * cols + c]`.
    pub weights: Vec<f32>,
    /// `b`, length `rows`.
    pub bias: Vec<f32>,
}

impl DenseLayer {
    fn check(&self, what: &str) -> ModelResult<()> {
        if self.rows == 0 || self.cols == 0 {
            return invalid(format!("{what}: empty layer {}x{}", self.rows, self.cols));
        }
        if self.weights.len() != self.rows * self.cols || self.bias.len() != self.rows {
            return invalid(format!(
                "{what}: {}x{} layer holds {} weights and {} biases",
                self.rows,
                self.cols,
                self.weights.len(),
                self.bias.len()
            ));
        }
        Ok(())
    }

    /// Writes `W x + b` into `y` (`x.len() == cols`, `y.len() == rows`, checked by callers).
    fn apply<T: Real>(&self, x: &[T], y: &mut [T]) {
        for (r, out) in y.iter_mut().enumerate() {
            let row = &self.weights[r * self.cols..(r + 1) * self.cols];
            *out = T::from_f32(self.bias[r]) + row.iter().zip(x).map(|(&w, &v)| T::from_f32(w) * v).sum::<T>();
        }
    }
}

/// One frozen residual block: `h + outer(swish(inner(h)))`.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportedBlock {
    /// First layer of the block (hidden × hidden).
    pub inner: DenseLayer,
    /// Second layer of the block (hidden × hidden).
    pub outer: DenseLayer,
}

/// A frozen residual MLP with the layout of the module documentation; shapes are checked when
/// it is built, so its forward pass cannot index out of bounds.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportedMlp {
    input: DenseLayer,
    blocks: Vec<ExportedBlock>,
    output: DenseLayer,
}

impl ExportedMlp {
    /// Builds from the flat layer list `[input, inner_0, outer_0, ..., inner_{B-1},
    /// outer_{B-1}, output]` (the order of [`ExportedMlp::layers`]), checking every shape.
    pub(crate) fn from_layers(layers: Vec<DenseLayer>) -> ModelResult<Self> {
        if layers.len() < 2 || !layers.len().is_multiple_of(2) {
            return invalid(format!("a residual MLP has 2 + 2*blocks layers, got {}", layers.len()));
        }
        for (i, layer) in layers.iter().enumerate() {
            layer.check(&format!("layer {i}"))?;
        }
        let hidden = layers[0].rows;
        let last = layers.len() - 1;
        for (i, layer) in layers.iter().enumerate().skip(1) {
            let rows_ok = i == last || layer.rows == hidden;
            if layer.cols != hidden || !rows_ok {
                return invalid(format!(
                    "layer {i} is {}x{}, but the hidden width is {hidden}",
                    layer.rows, layer.cols
                ));
            }
        }
        let mut iter = layers.into_iter();
        let input = iter.next().expect("length checked above");
        let mut rest: Vec<DenseLayer> = iter.collect();
        let output = rest.pop().expect("length checked above");
        let mut blocks = Vec::with_capacity(rest.len() / 2);
        let mut pairs = rest.into_iter();
        while let (Some(inner), Some(outer)) = (pairs.next(), pairs.next()) {
            blocks.push(ExportedBlock { inner, outer });
        }
        Ok(ExportedMlp { input, blocks, output })
    }

    /// The sizes of this network.
    pub fn spec(&self) -> MlpSpec {
        MlpSpec {
            input: self.input.cols,
            output: self.output.rows,
            hidden: self.input.rows,
            blocks: self.blocks.len(),
        }
    }

    /// The input layer.
    pub fn input(&self) -> &DenseLayer {
        &self.input
    }

    /// The residual blocks, in order.
    pub fn blocks(&self) -> &[ExportedBlock] {
        &self.blocks
    }

    /// The output layer.
    pub fn output(&self) -> &DenseLayer {
        &self.output
    }

    /// All layers in evaluation order: input, then inner and outer of each block, then output.
    pub fn layers(&self) -> Vec<&DenseLayer> {
        let mut out = vec![&self.input];
        for block in &self.blocks {
            out.push(&block.inner);
            out.push(&block.outer);
        }
        out.push(&self.output);
        out
    }
}

/// The plain-Rust forward pass of a frozen residual MLP (the layout of the module
/// documentation); in `f32`, the reference for the runtime's kernels.
pub fn forward_exported<T: Real>(mlp: &ExportedMlp, x: &[T]) -> ModelResult<Vec<T>> {
    if x.len() != mlp.input.cols {
        return invalid(format!(
            "input has {} values, the network takes {}",
            x.len(),
            mlp.input.cols
        ));
    }
    let hidden = mlp.input.rows;
    let mut h = vec![T::default(); hidden];
    mlp.input.apply(x, &mut h);
    let mut a = vec![T::default(); hidden];
    let mut r = vec![T::default(); hidden];
    for block in &mlp.blocks {
        block.inner.apply(&h, &mut a);
        a.iter_mut().for_each(|v| *v = swish(*v));
        block.outer.apply(&a, &mut r);
        h.iter_mut().zip(&r).for_each(|(h, r)| *h += *r);
    }
    h.iter_mut().for_each(|v| *v = swish(*v));
    let mut y = vec![T::default(); mlp.output.rows];
    mlp.output.apply(&h, &mut y);
    Ok(y)
}

// ---------------------------------------------------------------------------------------------
// Trainable networks in candle.
// ---------------------------------------------------------------------------------------------

/// Sizes of a residual MLP (layout in the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct MlpSpec {
    /// Input features.
    pub input: usize,
    /// Output features.
    pub output: usize,
    /// Width of the residual stream and of every block.
    pub hidden: usize,
    /// Number of residual blocks (0 gives a one-hidden-layer MLP).
    pub blocks: usize,
}

impl MlpSpec {
    fn check(&self) -> ModelResult<()> {
        if self.input == 0 || self.output == 0 || self.hidden == 0 {
            return invalid(format!("network sizes must be positive: {self:?}"));
        }
        Ok(())
    }
}

/// A trainable dense layer `y = x W^T + b` on row-major batches `x: (batch, cols)`.
#[derive(Debug, Clone)]
struct Dense {
    weight: Var,
    bias: Var,
}

impl Dense {
    fn from_values(rows: usize, cols: usize, weights: Vec<f32>, bias: Vec<f32>) -> ModelResult<Self> {
        Ok(Dense {
            weight: Var::from_vec(weights, (rows, cols), &Device::Cpu)?,
            bias: Var::from_vec(bias, rows, &Device::Cpu)?,
        })
    }

    /// PyTorch's default law: weights and biases uniform in `±1/sqrt(cols)`.
    fn random(rows: usize, cols: usize, rng: &mut ChaCha8Rng) -> ModelResult<Self> {
        let (weights, bias) = random_values(rows, cols, rng);
        Self::from_values(rows, cols, weights, bias)
    }

    fn zeros(rows: usize, cols: usize) -> ModelResult<Self> {
        Self::from_values(rows, cols, vec![0.0; rows * cols], vec![0.0; rows])
    }

    fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        x.matmul(&self.weight.as_tensor().t()?)?
            .broadcast_add(self.bias.as_tensor())
    }

    /// As [`Dense::forward`], with the weights treated as constants: gradients still flow to
    /// `x` but none are computed for the weights.
    fn forward_frozen(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        x.matmul(&self.weight.as_tensor().detach().t()?)?
            .broadcast_add(&self.bias.as_tensor().detach())
    }

    fn export(&self) -> ModelResult<DenseLayer> {
        let (rows, cols) = self.weight.as_tensor().dims2()?;
        Ok(DenseLayer {
            rows,
            cols,
            weights: self.weight.as_tensor().flatten_all()?.to_vec1::<f32>()?,
            bias: self.bias.as_tensor().to_vec1::<f32>()?,
        })
    }

    fn parameters(&self, prefix: &str, out: &mut Vec<(String, Var)>) {
        out.push((format!("{prefix}.weight"), self.weight.clone()));
        out.push((format!("{prefix}.bias"), self.bias.clone()));
    }
}

fn random_values(rows: usize, cols: usize, rng: &mut ChaCha8Rng) -> (Vec<f32>, Vec<f32>) {
    let bound = 1.0 / (cols as f32).sqrt();
    let weights = (0..rows * cols).map(|_| rng.random_range(-bound..bound)).collect();
    let bias = (0..rows).map(|_| rng.random_range(-bound..bound)).collect();
    (weights, bias)
}

#[derive(Debug, Clone)]
struct Block {
    inner: Dense,
    outer: Dense,
}

/// A trainable residual MLP (layout and initialisation in the module documentation).
#[derive(Debug, Clone)]
pub(crate) struct ResMlp {
    input: Dense,
    blocks: Vec<Block>,
    output: Dense,
}

impl ResMlp {
    /// A randomly initialised network (identity blocks), drawn from `rng`.
    pub fn new(spec: MlpSpec, rng: &mut ChaCha8Rng) -> ModelResult<Self> {
        spec.check()?;
        let input = Dense::random(spec.hidden, spec.input, rng)?;
        Self::with_ends(spec, input, rng, |rng| Dense::random(spec.output, spec.hidden, rng))
    }

    /// Builds a network from given input and output layers, with fresh identity blocks drawn
    /// from `rng` between them (`output` gets the same generator after the blocks).
    fn with_ends(
        spec: MlpSpec,
        input: Dense,
        rng: &mut ChaCha8Rng,
        output: impl FnOnce(&mut ChaCha8Rng) -> ModelResult<Dense>,
    ) -> ModelResult<Self> {
        let blocks = (0..spec.blocks)
            .map(|_| {
                Ok(Block {
                    inner: Dense::random(spec.hidden, spec.hidden, rng)?,
                    outer: Dense::zeros(spec.hidden, spec.hidden)?,
                })
            })
            .collect::<ModelResult<Vec<_>>>()?;
        let output = output(rng)?;
        Ok(ResMlp { input, blocks, output })
    }

    /// The candle network with the weights of a frozen one (for comparisons with the runtime).
    pub(crate) fn from_exported(mlp: &ExportedMlp) -> ModelResult<Self> {
        let dense = |l: &DenseLayer| Dense::from_values(l.rows, l.cols, l.weights.clone(), l.bias.clone());
        let blocks = mlp
            .blocks()
            .iter()
            .map(|b| {
                Ok(Block {
                    inner: dense(&b.inner)?,
                    outer: dense(&b.outer)?,
                })
            })
            .collect::<ModelResult<Vec<_>>>()?;
        Ok(ResMlp {
            input: dense(mlp.input())?,
            blocks,
            output: dense(mlp.output())?,
        })
    }

    /// Runs the network on a batch `x: (batch, input)`, giving `(batch, output)`.
    pub fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let mut h = self.input.forward(x)?;
        for block in &self.blocks {
            let r = block.outer.forward(&block.inner.forward(&h)?.silu()?)?;
            h = (h + r)?;
        }
        self.output.forward(&h.silu()?)
    }

    /// Runs the network with its weights held constant: backpropagation reaches `x` (and what
    /// produced it) without computing weight gradients. Used to push the physics gradient
    /// through the trained decoder into the integrator.
    pub(crate) fn forward_frozen(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        let mut h = self.input.forward_frozen(x)?;
        for block in &self.blocks {
            let r = block.outer.forward_frozen(&block.inner.forward_frozen(&h)?.silu()?)?;
            h = (h + r)?;
        }
        self.output.forward_frozen(&h.silu()?)
    }

    /// The trainable variables, named `{prefix}.input.weight`, `{prefix}.block{j}.inner.bias`,
    /// `{prefix}.output.weight`, ..., in evaluation order.
    pub(crate) fn parameters(&self, prefix: &str) -> Vec<(String, Var)> {
        let mut out = Vec::with_capacity(4 + 4 * self.blocks.len());
        self.input.parameters(&format!("{prefix}.input"), &mut out);
        for (j, block) in self.blocks.iter().enumerate() {
            block.inner.parameters(&format!("{prefix}.block{j}.inner"), &mut out);
            block.outer.parameters(&format!("{prefix}.block{j}.outer"), &mut out);
        }
        self.output.parameters(&format!("{prefix}.output"), &mut out);
        out
    }

    /// Freezes the current weights.
    pub fn export(&self) -> ModelResult<ExportedMlp> {
        let mut layers = vec![self.input.export()?];
        for block in &self.blocks {
            layers.push(block.inner.export()?);
            layers.push(block.outer.export()?);
        }
        layers.push(self.output.export()?);
        ExportedMlp::from_layers(layers)
    }
}

// ---------------------------------------------------------------------------------------------
// Autoencoder (Sec. 3.2, Eq. 2).
// ---------------------------------------------------------------------------------------------

/// Sizes of a symmetric autoencoder: the encoder is a [`ResMlp`] `input -> latent`, the
/// decoder one `latent -> input`, both with the same `hidden` width and `blocks`.
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

    /// Sizes of the decoder.
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
    decoder: ResMlp,
}

/// A frozen autoencoder.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ExportedAutoencoder {
    /// The encoder, `input -> latent`.
    pub encoder: ExportedMlp,
    /// The decoder, `latent -> input`.
    pub decoder: ExportedMlp,
}

impl Autoencoder {
    /// A randomly initialised autoencoder (encoder drawn first, then decoder, from `seed`).
    #[cfg(test)]
    pub fn new(spec: AutoencoderSpec, seed: u64) -> ModelResult<Self> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let encoder = ResMlp::new(spec.encoder(), &mut rng)?;
        let decoder = ResMlp::new(spec.decoder(), &mut rng)?;
        Ok(Autoencoder { spec, encoder, decoder })
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
        let encoder = ResMlp::with_ends(spec.encoder(), enc_input, &mut rng, |_| {
            let mut w = vec![0.0f32; k * hidden];
            for i in 0..k {
                w[i * hidden + i] = 1.0;
                w[i * hidden + k + i] = -1.0;
            }
            Dense::from_values(k, hidden, w, vec![0.0; k])
        })?;

        // Decoder input layer: rows +I, -I (zero bias), then random rows.
        let (mut w, mut b) = random_values(hidden, k, &mut rng);
        for r in 0..2 * k {
            let row = &mut w[r * k..(r + 1) * k];
            row.fill(0.0);
            row[r % k] = if r < k { 1.0 } else { -1.0 };
            b[r] = 0.0;
        }
        let dec_input = Dense::from_values(hidden, k, w, b)?;
        let decoder = ResMlp::with_ends(spec.decoder(), dec_input, &mut rng, |_| {
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
        Ok(Autoencoder { spec, encoder, decoder })
    }

    /// The sizes of this autoencoder.
    pub fn spec(&self) -> AutoencoderSpec {
        self.spec
    }

    /// The decoder network.
    pub fn decoder(&self) -> &ResMlp {
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
    pub fn export(&self) -> ModelResult<ExportedAutoencoder> {
        Ok(ExportedAutoencoder {
            encoder: self.encoder.export()?,
            decoder: self.decoder.export()?,
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Latent integrator (Sec. 3.3, Eq. 3).
// ---------------------------------------------------------------------------------------------

/// Sizes of the latent integrator `z_t = I(z_{t-1}, z_{t-2}, p_t, p_{t-1}, p_{t-2})`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub(crate) struct IntegratorSpec {
    /// Latent size `k`.
    pub latent: usize,
    /// Size of one boundary-condition vector `p_t` (may be 0).
    pub bc: usize,
    /// Hidden width of the MLP.
    pub hidden: usize,
    /// Residual blocks of the MLP.
    pub blocks: usize,
}

impl IntegratorSpec {
    /// Length of the packed input `q = [z_{t-1}, z_{t-2}, p_t, p_{t-1}, p_{t-2}]`.
    pub fn input(&self) -> usize {
        2 * self.latent + 3 * self.bc
    }

    fn mlp(&self) -> MlpSpec {
        MlpSpec {
            input: self.input(),
            output: self.latent,
            hidden: self.hidden,
            blocks: self.blocks,
        }
    }
}

/// Per-feature affine normalisation `(v - mean) / std`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Normalisation {
    /// Feature means.
    pub mean: Vec<f32>,
    /// Feature standard deviations (all positive).
    pub std: Vec<f32>,
}

impl Normalisation {
    /// Standard deviations at or below this are replaced by 1 (constant features are then only
    /// centred, not blown up).
    pub(crate) const MIN_STD: f32 = 1e-8;

    /// Mean and standard deviation of each column of `rows` (all rows the same length).
    pub fn fit(rows: &[Vec<f32>]) -> ModelResult<Self> {
        let Some(first) = rows.first() else {
            return invalid("cannot fit a normalisation to no samples");
        };
        let dim = first.len();
        if let Some(i) = rows.iter().position(|r| r.len() != dim) {
            return invalid(format!("sample {i} has {} features, sample 0 has {dim}", rows[i].len()));
        }
        let count = rows.len() as f64;
        let mut mean = vec![0.0f64; dim];
        for row in rows {
            mean.iter_mut().zip(row).for_each(|(m, &v)| *m += v as f64 / count);
        }
        let mut var = vec![0.0f64; dim];
        for row in rows {
            for ((s, &v), m) in var.iter_mut().zip(row).zip(&mean) {
                *s += (v as f64 - m).powi(2) / count;
            }
        }
        let std = var
            .iter()
            .map(|v| match v.sqrt() as f32 {
                s if s > Self::MIN_STD => s,
                _ => 1.0,
            })
            .collect();
        let mean = mean.iter().map(|&m| m as f32).collect();
        Normalisation::new(mean, std)
    }

    /// A normalisation from given statistics (equal lengths, finite, positive `std`).
    pub fn new(mean: Vec<f32>, std: Vec<f32>) -> ModelResult<Self> {
        if mean.len() != std.len() {
            return invalid(format!("{} means but {} standard deviations", mean.len(), std.len()));
        }
        let finite = mean.iter().chain(&std).all(|v| v.is_finite());
        if !finite || std.iter().any(|&s| s <= 0.0) {
            return invalid("normalisation statistics must be finite with positive deviations");
        }
        Ok(Normalisation { mean, std })
    }

    /// The identity normalisation of `dim` features.
    #[cfg(test)]
    pub(crate) fn identity(dim: usize) -> Self {
        Normalisation {
            mean: vec![0.0; dim],
            std: vec![1.0; dim],
        }
    }

    fn tensors(&self) -> candle_core::Result<(Tensor, Tensor)> {
        let n = self.mean.len();
        Ok((
            Tensor::from_slice(&self.mean, (1, n), &Device::Cpu)?,
            Tensor::from_slice(&self.std, (1, n), &Device::Cpu)?,
        ))
    }
}

/// The latent integrator (Eq. 3): a [`ResMlp`] over the packed input
/// `q = [z_{t-1}, z_{t-2}, p_t, p_{t-1}, p_{t-2}]` that predicts the latent *increment*:
///
/// ```text
/// z_t = z_{t-1} + out.mean + out.std * mlp((q - in.mean) / in.std)
/// ```
///
/// Predicting `z_t - z_{t-1}` rather than `z_t` keeps the identity (a body at rest) free for
/// the network and lets the output normalisation be the statistics of per-frame latent
/// motion, which are much smaller than those of the latents themselves; the network's relative
/// error then becomes a small absolute error per step. The normalisations are constants (not
/// trained); on export they are folded into the first and last dense layers.
#[derive(Debug, Clone)]
pub(crate) struct LatentIntegrator {
    spec: IntegratorSpec,
    mlp: ResMlp,
    input_norm: Normalisation,
    increment_norm: Normalisation,
    input_mean: Tensor,
    input_std: Tensor,
    increment_mean: Tensor,
    increment_std: Tensor,
}

/// A frozen integrator: `z_t = q[..latent] + mlp(q)` with the normalisations folded into
/// `mlp`'s first and last layers.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportedIntegrator {
    latent: usize,
    mlp: ExportedMlp,
}

impl ExportedIntegrator {
    /// Checks that `mlp` maps a packed input whose first `latent` values are `z_{t-1}` to a
    /// `latent`-sized increment.
    pub fn new(latent: usize, mlp: ExportedMlp) -> ModelResult<Self> {
        let spec = mlp.spec();
        if spec.output != latent || spec.input < 2 * latent {
            return invalid(format!("integrator network {spec:?} does not fit latent size {latent}"));
        }
        Ok(ExportedIntegrator { latent, mlp })
    }

    /// Latent size.
    pub fn latent(&self) -> usize {
        self.latent
    }

    /// The network (normalisation folded in).
    pub(crate) fn mlp(&self) -> &ExportedMlp {
        &self.mlp
    }

    /// One step from a packed input `q`.
    pub fn step(&self, q: &[f32]) -> ModelResult<Vec<f32>> {
        let mut z = forward_exported(&self.mlp, q)?;
        z.iter_mut().zip(&q[..self.latent]).for_each(|(z, prev)| *z += prev);
        Ok(z)
    }
}

impl LatentIntegrator {
    /// A randomly initialised integrator. `input_norm` normalises the packed input (length
    /// [`IntegratorSpec::input`]), `increment_norm` de-normalises the predicted
    /// `z_t - z_{t-1}` (length `latent`); fit both to training data with
    /// [`Normalisation::fit`].
    pub fn new(
        spec: IntegratorSpec,
        input_norm: Normalisation,
        increment_norm: Normalisation,
        seed: u64,
    ) -> ModelResult<Self> {
        if input_norm.mean.len() != spec.input() || increment_norm.mean.len() != spec.latent {
            return invalid(format!(
                "normalisations of sizes {} and {} do not fit an integrator with input {} and latent {}",
                input_norm.mean.len(),
                increment_norm.mean.len(),
                spec.input(),
                spec.latent
            ));
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mlp = ResMlp::new(spec.mlp(), &mut rng)?;
        let (input_mean, input_std) = input_norm.tensors()?;
        let (increment_mean, increment_std) = increment_norm.tensors()?;
        Ok(LatentIntegrator {
            spec,
            mlp,
            input_norm,
            increment_norm,
            input_mean,
            input_std,
            increment_mean,
            increment_std,
        })
    }

    /// Packs `[z_{t-1}, z_{t-2}, p_t, p_{t-1}, p_{t-2}]` (each `(batch, ·)`) into `q`.
    #[cfg(test)]
    pub(crate) fn pack(
        z_prev: &Tensor,
        z_prev2: &Tensor,
        p_t: &Tensor,
        p_prev: &Tensor,
        p_prev2: &Tensor,
    ) -> candle_core::Result<Tensor> {
        Tensor::cat(&[z_prev, z_prev2, p_t, p_prev, p_prev2], 1)
    }

    /// `z_t` for a batch of packed inputs `q: (batch, input)`.
    pub fn forward(&self, q: &Tensor) -> candle_core::Result<Tensor> {
        let normalised = q.broadcast_sub(&self.input_mean)?.broadcast_div(&self.input_std)?;
        let increment = self
            .mlp
            .forward(&normalised)?
            .broadcast_mul(&self.increment_std)?
            .broadcast_add(&self.increment_mean)?;
        q.narrow(1, 0, self.spec.latent)? + increment
    }

    /// The trainable variables (`integrator.*`).
    pub(crate) fn parameters(&self) -> Vec<(String, Var)> {
        self.mlp.parameters("integrator")
    }

    /// Freezes the current weights, folding the input normalisation into the first layer
    /// (`W' = W diag(1/std)`, `b' = b - W (mean/std)`) and the output one into the last
    /// (`W' = diag(std) W`, `b' = std * b + mean`).
    pub fn export(&self) -> ModelResult<ExportedIntegrator> {
        let mlp = self.mlp.export()?;
        let mut layers: Vec<DenseLayer> = mlp.layers().into_iter().cloned().collect();
        let first = &mut layers[0];
        let Normalisation { mean, std } = &self.input_norm;
        for r in 0..first.rows {
            let row = &mut first.weights[r * first.cols..(r + 1) * first.cols];
            let mut shift = 0.0f64;
            for ((w, &m), &s) in row.iter_mut().zip(mean).zip(std) {
                shift += *w as f64 * m as f64 / s as f64;
                *w = (*w as f64 / s as f64) as f32;
            }
            first.bias[r] = (first.bias[r] as f64 - shift) as f32;
        }
        let last = layers.last_mut().expect("an MLP has at least two layers");
        let Normalisation { mean, std } = &self.increment_norm;
        for r in 0..last.rows {
            let s = std[r] as f64;
            let row = &mut last.weights[r * last.cols..(r + 1) * last.cols];
            row.iter_mut().for_each(|w| *w = (*w as f64 * s) as f32);
            last.bias[r] = (last.bias[r] as f64 * s + mean[r] as f64) as f32;
        }
        ExportedIntegrator::new(self.spec.latent, ExportedMlp::from_layers(layers)?)
    }
}

/// A `(rows.len(), dim)` f32 tensor from equal-length rows (`dim` when `rows` is empty).
pub(crate) fn rows_to_tensor(rows: &[&[f32]], dim: usize) -> ModelResult<Tensor> {
    let mut flat = Vec::with_capacity(rows.len() * dim);
    for (i, row) in rows.iter().enumerate() {
        if row.len() != dim {
            return invalid(format!("row {i} has {} values, expected {dim}", row.len()));
        }
        flat.extend_from_slice(row);
    }
    Ok(Tensor::from_vec(flat, (rows.len(), dim), &Device::Cpu)?)
}

/// The rows of a `(batch, n)` f32 tensor.
pub(crate) fn tensor_to_rows(t: &Tensor) -> candle_core::Result<Vec<Vec<f32>>> {
    t.to_dtype(DType::F32)?.to_vec2::<f32>()
}

/// Helpers shared by the tests of this module and of `train`.
#[cfg(test)]
pub(crate) mod test_support {
    use super::*;
    use nalgebra::DMatrix;

    /// Sets every variable to uniform values in `±scale`, so no layer is left at zero.
    pub(crate) fn randomise(params: &[(String, Var)], scale: f32, rng: &mut ChaCha8Rng) {
        for (_, var) in params {
            let shape = var.as_tensor().shape().clone();
            let values: Vec<f32> = (0..shape.elem_count())
                .map(|_| rng.random_range(-scale..scale))
                .collect();
            var.set(&Tensor::from_vec(values, shape, &Device::Cpu).unwrap())
                .unwrap();
        }
    }

    pub(crate) fn random_rows(count: usize, dim: usize, scale: f32, rng: &mut ChaCha8Rng) -> Vec<Vec<f32>> {
        (0..count)
            .map(|_| (0..dim).map(|_| rng.random_range(-scale..scale)).collect())
            .collect()
    }

    pub(crate) fn as_tensor(rows: &[Vec<f32>]) -> Tensor {
        let refs: Vec<&[f32]> = rows.iter().map(Vec::as_slice).collect();
        rows_to_tensor(&refs, rows[0].len()).unwrap()
    }

    /// Largest |a - b| relative to the largest |b| (which must not be zero).
    pub(crate) fn max_relative_difference(a: &[Vec<f32>], b: &[Vec<f32>]) -> f32 {
        let scale = b.iter().flatten().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(scale > 0.0, "comparison against all zeros");
        let diff = a
            .iter()
            .flatten()
            .zip(b.iter().flatten())
            .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
        diff / scale
    }

    /// Mean and the first `k` principal directions (rows) of `data`, by SVD.
    pub(crate) fn pca(data: &[Vec<f32>], k: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
        let (m, n) = (data.len(), data[0].len());
        let x = DMatrix::from_fn(m, n, |i, j| data[i][j] as f64);
        let mean: Vec<f64> = (0..n).map(|j| x.column(j).mean()).collect();
        let centred = DMatrix::from_fn(m, n, |i, j| x[(i, j)] - mean[j]);
        let svd = centred.svd(false, true);
        let v_t = svd.v_t.unwrap();
        let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
        order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
        let basis = order[..k]
            .iter()
            .map(|&i| v_t.row(i).iter().copied().collect())
            .collect();
        (mean, basis)
    }

    /// `count` samples of a 2D nonlinear manifold embedded in `dim` dimensions: parameters
    /// `(u, v)` uniform in `[-1, 1]^2` pass through 8 nonlinear features and a fixed random
    /// linear map; each coordinate is then centred, so the data has zero mean.
    pub(crate) fn manifold_data(count: usize, dim: usize, seed: u64) -> Vec<Vec<f32>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let map = random_rows(dim, 8, 1.0, &mut rng);
        let pi = std::f32::consts::PI;
        let mut data: Vec<Vec<f32>> = (0..count)
            .map(|_| {
                let (u, v) = (rng.random_range(-1.0f32..1.0), rng.random_range(-1.0f32..1.0));
                let features = [
                    u,
                    v,
                    u * u,
                    v * v,
                    u * v,
                    (pi * u).sin(),
                    (pi * v).cos(),
                    (pi * (u + v)).sin(),
                ];
                map.iter()
                    .map(|row| row.iter().zip(&features).map(|(a, f)| a * f).sum())
                    .collect()
            })
            .collect();
        for j in 0..dim {
            let mean = data.iter().map(|x| x[j]).sum::<f32>() / count as f32;
            data.iter_mut().for_each(|x| x[j] -= mean);
        }
        data
    }

    /// Mean squared error of the PCA reconstruction `mean + B^T B (x - mean)`.
    pub(crate) fn pca_reconstruction_error(data: &[Vec<f32>], mean: &[f64], basis: &[Vec<f64>]) -> f64 {
        let mut total = 0.0;
        for x in data {
            let c: Vec<f64> = basis
                .iter()
                .map(|b| b.iter().zip(x).zip(mean).map(|((b, &x), m)| b * (x as f64 - m)).sum())
                .collect();
            for (j, &xj) in x.iter().enumerate() {
                let y = mean[j] + basis.iter().zip(&c).map(|(b, c)| b[j] * c).sum::<f64>();
                total += (y - xj as f64).powi(2);
            }
        }
        total / (data.len() * data[0].len()) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::test_support::*;
    use super::*;

    #[test]
    fn exported_mlp_matches_candle_forward() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let spec = MlpSpec {
            input: 30,
            output: 5,
            hidden: 24,
            blocks: 3,
        };
        let mlp = ResMlp::new(spec, &mut rng).unwrap();
        randomise(&mlp.parameters("m"), 0.4, &mut rng);
        let x = random_rows(16, 30, 2.0, &mut rng);
        let candle = tensor_to_rows(&mlp.forward(&as_tensor(&x)).unwrap()).unwrap();
        let exported = mlp.export().unwrap();
        assert_eq!(exported.spec(), spec);
        assert_eq!(exported.layers().len(), 2 + 2 * spec.blocks);
        let plain: Vec<Vec<f32>> = x.iter().map(|x| forward_exported(&exported, x).unwrap()).collect();
        let diff = max_relative_difference(&plain, &candle);
        assert!(diff < 1e-5, "exported forward differs from candle by {diff}");
        // The outputs are not trivially small, so the comparison means something.
        assert!(candle.iter().flatten().any(|v| v.abs() > 0.1));
        // In f64 (the diagnostics' decoder) the same network gives the same outputs.
        let wide: Vec<Vec<f32>> = x
            .iter()
            .map(|x| {
                let x: Vec<f64> = x.iter().map(|&v| v as f64).collect();
                forward_exported(&exported, &x)
                    .unwrap()
                    .iter()
                    .map(|&v| v as f32)
                    .collect()
            })
            .collect();
        let diff = max_relative_difference(&wide, &plain);
        assert!(diff < 1e-5, "f64 forward differs from f32 by {diff}");
    }

    #[test]
    fn exported_autoencoder_matches_candle() {
        let spec = AutoencoderSpec {
            input: 30,
            latent: 3,
            hidden: 16,
            blocks: 2,
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
        let y_plain: Vec<Vec<f32>> = z
            .iter()
            .map(|z| forward_exported(&exported.decoder, z).unwrap())
            .collect();
        assert!(max_relative_difference(&z_plain, &z) < 1e-5);
        assert!(max_relative_difference(&y_plain, &y) < 1e-5);
    }

    #[test]
    fn exported_integrator_folds_normalisation() {
        let spec = IntegratorSpec {
            latent: 4,
            bc: 3,
            hidden: 32,
            blocks: 2,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        // Features of very different scales, as latents and boundary velocities are.
        let inputs: Vec<Vec<f32>> = random_rows(64, spec.input(), 1.0, &mut rng)
            .into_iter()
            .map(|row| {
                row.iter()
                    .enumerate()
                    .map(|(i, v)| v * (1 + i) as f32 + i as f32)
                    .collect()
            })
            .collect();
        let increments: Vec<Vec<f32>> = random_rows(64, spec.latent, 0.01, &mut rng)
            .into_iter()
            .map(|row| row.iter().map(|v| v + 0.003).collect())
            .collect();
        let input_norm = Normalisation::fit(&inputs).unwrap();
        let increment_norm = Normalisation::fit(&increments).unwrap();
        let integrator = LatentIntegrator::new(spec, input_norm, increment_norm, 6).unwrap();
        randomise(&integrator.parameters(), 0.3, &mut rng);
        let q = &inputs[..10];
        let candle = tensor_to_rows(&integrator.forward(&as_tensor(q)).unwrap()).unwrap();
        let exported = integrator.export().unwrap();
        // The increment z_t - z_{t-1} is much smaller than z, so compare it on its own: candle's
        // (from the network and the normalisation tensors) against the folded export.
        let normalised = as_tensor(q)
            .broadcast_sub(&integrator.input_mean)
            .and_then(|t| t.broadcast_div(&integrator.input_std))
            .unwrap();
        let increment = integrator
            .mlp
            .forward(&normalised)
            .and_then(|t| t.broadcast_mul(&integrator.increment_std))
            .and_then(|t| t.broadcast_add(&integrator.increment_mean))
            .unwrap();
        let increment = tensor_to_rows(&increment).unwrap();
        let folded: Vec<Vec<f32>> = q.iter().map(|q| forward_exported(exported.mlp(), q).unwrap()).collect();
        let diff = max_relative_difference(&folded, &increment);
        assert!(diff < 1e-5, "exported integrator differs by {diff}");
        // The increments live on the scale of the increment normalisation (std ~0.006).
        let largest = increment.iter().flatten().fold(0.0f32, |m, v| m.max(v.abs()));
        assert!(largest > 1e-3 && largest < 0.5, "largest increment {largest}");
        // A step adds the increment to z_{t-1}, in candle and in the export.
        for (((q, z), dz), folded) in q.iter().zip(&candle).zip(&increment).zip(&folded) {
            let step = exported.step(q).unwrap();
            for i in 0..spec.latent {
                assert_eq!(step[i], q[i] + folded[i]);
                assert!((z[i] - (q[i] + dz[i])).abs() <= 1e-6 * q[i].abs().max(1.0));
            }
        }
    }

    #[test]
    fn integrator_pack_orders_inputs() {
        let t = |v: &[f32]| Tensor::from_slice(v, (1, v.len()), &Device::Cpu).unwrap();
        let q = LatentIntegrator::pack(&t(&[1., 2.]), &t(&[3., 4.]), &t(&[5.]), &t(&[6.]), &t(&[7.])).unwrap();
        assert_eq!(tensor_to_rows(&q).unwrap(), vec![vec![1., 2., 3., 4., 5., 6., 7.]]);
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

    #[test]
    fn malformed_exports_are_rejected() {
        let layer = |rows: usize, cols: usize| DenseLayer {
            rows,
            cols,
            weights: vec![0.5; rows * cols],
            bias: vec![0.1; rows],
        };
        let mlp = ExportedMlp::from_layers(vec![layer(4, 3), layer(4, 4), layer(4, 4), layer(2, 4)]).unwrap();
        assert_eq!(mlp.blocks().len(), 1);
        assert!(forward_exported(&mlp, &[1.0, 2.0]).is_err());
        assert_eq!(forward_exported(&mlp, &[1.0, 2.0, 3.0]).unwrap().len(), 2);
        assert!(ExportedMlp::from_layers(vec![layer(4, 3)]).is_err());
        assert!(ExportedMlp::from_layers(vec![layer(4, 3), layer(4, 4), layer(2, 4)]).is_err());
        assert!(ExportedMlp::from_layers(vec![layer(4, 3), layer(2, 5)]).is_err());
        assert!(ExportedMlp::from_layers(vec![layer(4, 3), layer(3, 4), layer(4, 4), layer(2, 4)]).is_err());
        let mut bad = layer(2, 4);
        bad.weights.pop();
        assert!(ExportedMlp::from_layers(vec![layer(4, 3), bad]).is_err());
        let integrator = ExportedMlp::from_layers(vec![layer(4, 3), layer(2, 4)]).unwrap();
        assert!(ExportedIntegrator::new(2, integrator).is_err());
    }

    #[test]
    fn normalisation_fit_handles_constant_features() {
        let rows = vec![vec![1.0, 5.0], vec![3.0, 5.0]];
        let norm = Normalisation::fit(&rows).unwrap();
        assert_eq!(norm.mean, vec![2.0, 5.0]);
        assert_eq!(norm.std, vec![1.0, 1.0]);
        assert!(Normalisation::fit(&[]).is_err());
        assert!(Normalisation::fit(&[vec![1.0], vec![1.0, 2.0]]).is_err());
        assert!(Normalisation::new(vec![0.0], vec![0.0]).is_err());
        let spec = IntegratorSpec {
            latent: 2,
            bc: 1,
            hidden: 8,
            blocks: 0,
        };
        let wrong = LatentIntegrator::new(spec, Normalisation::identity(6), Normalisation::identity(2), 0);
        assert!(wrong.is_err());
    }

    #[test]
    fn swish_matches_candle_silu() {
        let values = [-90.0f32, -5.0, -0.5, 0.0, 1e-3, 0.7, 4.0, 60.0];
        let t = Tensor::from_slice(&values, values.len(), &Device::Cpu).unwrap();
        let candle = t.silu().unwrap().to_vec1::<f32>().unwrap();
        for (v, c) in values.iter().zip(candle) {
            assert_eq!(swish(*v), c);
        }
    }
}
