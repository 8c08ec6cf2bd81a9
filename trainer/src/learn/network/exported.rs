//! Exported (frozen) networks: plain f32 arrays and a forward pass without candle.

use serde::{Deserialize, Serialize};

use super::error::{invalid, ModelResult};
use super::layout::{MlpSpec, MlpStyle, Real};

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

/// One frozen block: residual, `h + outer(a(inner(h)))`, or a plain hidden layer,
/// `outer(a(h))` (no `inner`).
#[derive(Debug, Clone, PartialEq)]
pub struct ExportedBlock {
    /// First layer of a residual block (hidden × hidden); `None` in a plain one.
    pub inner: Option<DenseLayer>,
    /// Second layer of a residual block, the layer of a plain one (hidden × hidden).
    pub outer: DenseLayer,
}

/// A frozen MLP with the layout of the module documentation; shapes are checked when it is
/// built, so its forward pass cannot index out of bounds.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportedMlp {
    /// The fixed map before the input layer, if any (`style.input_projection`).
    input_projection: Option<DenseLayer>,
    input: DenseLayer,
    blocks: Vec<ExportedBlock>,
    output: DenseLayer,
    /// The fixed map after the output layer, if any (`style.output_projection`).
    output_projection: Option<DenseLayer>,
    style: MlpStyle,
}

impl ExportedMlp {
    /// Builds a residual Swish MLP from the flat layer list `[input, inner_0, outer_0, ...,
    /// inner_{B-1}, outer_{B-1}, output]` (the order of [`ExportedMlp::layers`]), checking
    /// every shape.
    pub(crate) fn from_layers(layers: Vec<DenseLayer>) -> ModelResult<Self> {
        Self::from_styled_layers(layers, MlpStyle::default())
    }

    /// Builds a network of `style` from its flat layer list: as [`ExportedMlp::from_layers`]
    /// for residual blocks, `[input, layer_0, ..., layer_{B-1}, output]` for plain ones, with
    /// the fixed projections first and last where the style has them.
    pub(crate) fn from_styled_layers(mut layers: Vec<DenseLayer>, style: MlpStyle) -> ModelResult<Self> {
        let per_block = style.layers_per_block();
        let fixed = style.projections();
        if layers.len() < 2 + fixed || !(layers.len() - 2 - fixed).is_multiple_of(per_block) {
            return invalid(format!(
                "{} MLP has {} + {per_block}*blocks layers, got {}",
                if style.residual { "a residual" } else { "a plain" },
                2 + fixed,
                layers.len()
            ));
        }
        let output_projection = match style.output_projection {
            true => Some(layers.pop().expect("length checked above")),
            false => None,
        };
        let input_projection = match style.input_projection {
            true => Some(layers.remove(0)),
            false => None,
        };
        for (i, layer) in input_projection.iter().chain(&output_projection).enumerate() {
            layer.check(&format!("projection {i}"))?;
        }
        if let Some(p) = &input_projection {
            if p.rows != layers[0].cols {
                return invalid(format!(
                    "the input projection gives {} values, the input layer takes {}",
                    p.rows, layers[0].cols
                ));
            }
        }
        if let (Some(p), Some(last)) = (&output_projection, layers.last()) {
            if p.cols != last.rows {
                return invalid(format!(
                    "the output projection takes {} values, the output layer gives {}",
                    p.cols, last.rows
                ));
            }
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
        let mut blocks = Vec::with_capacity(rest.len() / per_block);
        let mut layers = rest.into_iter();
        while let Some(first) = layers.next() {
            let block = match style.residual {
                true => ExportedBlock {
                    inner: Some(first),
                    outer: layers.next().expect("length checked above"),
                },
                false => ExportedBlock {
                    inner: None,
                    outer: first,
                },
            };
            blocks.push(block);
        }
        Ok(ExportedMlp {
            input_projection,
            input,
            blocks,
            output,
            output_projection,
            style,
        })
    }

    /// The activation and how the hidden layers are joined.
    pub fn style(&self) -> MlpStyle {
        self.style
    }

    /// The sizes of this network.
    /// The sizes of this network, its inputs and outputs those of the projections where it
    /// has them.
    pub fn spec(&self) -> MlpSpec {
        MlpSpec {
            input: self.input_projection.as_ref().unwrap_or(&self.input).cols,
            output: self.output_projection.as_ref().unwrap_or(&self.output).rows,
            hidden: self.input.rows,
            blocks: self.blocks.len(),
        }
    }

    /// The fixed map before the input layer, if any.
    pub fn input_projection(&self) -> Option<&DenseLayer> {
        self.input_projection.as_ref()
    }

    /// The fixed map after the output layer, if any.
    pub fn output_projection(&self) -> Option<&DenseLayer> {
        self.output_projection.as_ref()
    }

    /// The input layer.
    pub fn input(&self) -> &DenseLayer {
        &self.input
    }

    /// The blocks, in order.
    pub fn blocks(&self) -> &[ExportedBlock] {
        &self.blocks
    }

    /// The output layer.
    pub fn output(&self) -> &DenseLayer {
        &self.output
    }

    /// All layers in evaluation order: the input projection (if any), input, then inner (if
    /// any) and outer of each block, then output and the output projection (if any).
    pub fn layers(&self) -> Vec<&DenseLayer> {
        let mut out: Vec<&DenseLayer> = self.input_projection.iter().collect();
        out.push(&self.input);
        for block in &self.blocks {
            out.extend(&block.inner);
            out.push(&block.outer);
        }
        out.push(&self.output);
        out.extend(&self.output_projection);
        out
    }
}

/// The plain-Rust forward pass of a frozen MLP (the layout of the module documentation); in
/// `f32`, the reference for the runtime's kernels.
pub fn forward_exported<T: Real>(mlp: &ExportedMlp, x: &[T]) -> ModelResult<Vec<T>> {
    if x.len() != mlp.spec().input {
        return invalid(format!(
            "input has {} values, the network takes {}",
            x.len(),
            mlp.spec().input
        ));
    }
    let projected = mlp.input_projection.as_ref().map(|p| {
        let mut c = vec![T::default(); p.rows];
        p.apply(x, &mut c);
        c
    });
    let hidden = mlp.input.rows;
    let mut h = vec![T::default(); hidden];
    mlp.input.apply(projected.as_deref().unwrap_or(x), &mut h);
    let activation = mlp.style.activation;
    let mut a = vec![T::default(); hidden];
    let mut r = vec![T::default(); hidden];
    for block in &mlp.blocks {
        match &block.inner {
            Some(inner) => inner.apply(&h, &mut a),
            None => a.copy_from_slice(&h),
        }
        a.iter_mut().for_each(|v| *v = activation.apply(*v));
        block.outer.apply(&a, &mut r);
        match mlp.style.residual {
            true => h.iter_mut().zip(&r).for_each(|(h, r)| *h += *r),
            false => h.copy_from_slice(&r),
        }
    }
    h.iter_mut().for_each(|v| *v = activation.apply(*v));
    let mut y = vec![T::default(); mlp.output.rows];
    mlp.output.apply(&h, &mut y);
    if let Some(p) = &mlp.output_projection {
        let mut full = vec![T::default(); p.rows];
        p.apply(&y, &mut full);
        return Ok(full);
    }
    Ok(y)
}
