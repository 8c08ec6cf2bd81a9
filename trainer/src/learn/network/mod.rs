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
//! # Styles
//!
//! That layout is the default [`MlpStyle`], the only one the runtime runs. The reduced
//! method's baseline subspace can reproduce the networks of Lyu et al.'s code instead: ELU
//! (`v` for `v > 0`, `e^v - 1` otherwise) for Swish, plain hidden layers `h = W_j a(h) + b_j`
//! (one layer a block, no residual addition: `blocks = 1` gives two hidden layers), and fixed
//! linear maps around the trained layers (a PCA's projection `B^T (x - mean)` before the input
//! layer, its basis `mean + B y` after the output layer), which are part of the network but not
//! of its variables. A frozen network keeps its style; its flat layer list is read with it.
//!
//! # Initialisation
//!
//! Dense layers start with PyTorch's default uniform law `U(-1/sqrt(cols), 1/sqrt(cols))` for
//! weights and biases, drawn from a seeded ChaCha8 generator (so a seed fixes the network). The
//! outer layer of every residual block starts at zero, so each block is the identity at
//! initialisation; its gradient is not zero, so it learns from the first step.
//!
//! # Files
//!
//! `error`: what can go wrong; `layout`: the sizes of an MLP, its style and activations;
//! `exported`: frozen networks and their plain-Rust forward pass; `mlp`: the trainable
//! residual MLP in candle; `autoencoder` and `integrator`: the two networks built from it;
//! `decoder`: a residual MLP or a linear basis after a small one, frozen and trainable;
//! `tensor`: rows to and from candle tensors; `derivatives`: a frozen network in `f64` with exact
//! Jacobians and second derivatives; `jet`: derivatives along directions inside candle's graph.

mod autoencoder;
mod decoder;
pub mod derivatives;
pub mod error;
mod exported;
mod integrator;
pub(crate) mod jet;
mod layout;
mod mlp;
mod tensor;
#[cfg(test)]
pub(crate) mod test_support;

pub(crate) use autoencoder::{Autoencoder, AutoencoderSpec};
pub(crate) use decoder::Decoder;
pub use decoder::{DecoderShape, FrozenDecoder};
pub use error::{ModelResult, NetworkError};
pub use exported::{forward_exported, DenseLayer, ExportedBlock, ExportedMlp};
pub use integrator::{network_inputs, rate_row, ExportedIntegrator};
pub(crate) use integrator::{IntegratorSpec, LatentIntegrator, Normalisation};
pub use layout::{Activation, MlpSpec, MlpStyle, Real};
pub(crate) use mlp::ResMlp;
pub(crate) use tensor::{rows_to_tensor, tensor_to_rows};
