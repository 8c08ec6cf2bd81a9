//! Exported (frozen) networks: plain f32 arrays and a forward pass without candle.

use serde::{Deserialize, Serialize};

use super::error::{invalid, ModelResult};
use super::layout::{swish, MlpSpec, Real};

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
    pub(super) fn check(&self, what: &str) -> ModelResult<()> {
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
    pub(super) fn apply<T: Real>(&self, x: &[T], y: &mut [T]) {
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
