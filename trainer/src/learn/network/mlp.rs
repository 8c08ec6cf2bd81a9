//! The trainable MLP in candle, residual or plain (layout and initialisation in the
//! documentation of [`super`]).

use candle_core::{Device, Tensor, Var};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::error::ModelResult;
use super::exported::{DenseLayer, ExportedMlp};
use super::layout::{Activation, MlpSpec, MlpStyle};

/// A trainable dense layer `y = x W^T + b` on row-major batches `x: (batch, cols)`.
#[derive(Debug, Clone)]
pub(crate) struct Dense {
    weight: Var,
    bias: Var,
}

impl Dense {
    pub(super) fn from_values(rows: usize, cols: usize, weights: Vec<f32>, bias: Vec<f32>) -> ModelResult<Self> {
        Ok(Dense {
            weight: Var::from_vec(weights, (rows, cols), &Device::Cpu)?,
            bias: Var::from_vec(bias, rows, &Device::Cpu)?,
        })
    }

    /// PyTorch's default law: weights and biases uniform in `±1/sqrt(cols)`.
    pub(super) fn random(rows: usize, cols: usize, rng: &mut ChaCha8Rng) -> ModelResult<Self> {
        let (weights, bias) = random_values(rows, cols, rng);
        Self::from_values(rows, cols, weights, bias)
    }

    pub(super) fn zeros(rows: usize, cols: usize) -> ModelResult<Self> {
        Self::from_values(rows, cols, vec![0.0; rows * cols], vec![0.0; rows])
    }

    pub(super) fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        x.matmul(&self.weight.as_tensor().t()?)?
            .broadcast_add(self.bias.as_tensor())
    }

    /// As [`Dense::forward`], with the weights treated as constants: gradients still flow to
    /// `x` but none are computed for the weights.
    pub(super) fn forward_frozen(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        x.matmul(&self.weight.as_tensor().detach().t()?)?
            .broadcast_add(&self.bias.as_tensor().detach())
    }

    /// The weight matrix `(rows, cols)`, a tensor of the autodiff graph.
    pub(super) fn weight(&self) -> &Tensor {
        self.weight.as_tensor()
    }

    /// The bias `(rows)`, a tensor of the autodiff graph.
    pub(super) fn bias(&self) -> &Tensor {
        self.bias.as_tensor()
    }

    pub(super) fn export(&self) -> ModelResult<DenseLayer> {
        let (rows, cols) = self.weight.as_tensor().dims2()?;
        Ok(DenseLayer {
            rows,
            cols,
            weights: self.weight.as_tensor().flatten_all()?.to_vec1::<f32>()?,
            bias: self.bias.as_tensor().to_vec1::<f32>()?,
        })
    }

    pub(super) fn parameters(&self, prefix: &str, out: &mut Vec<(String, Var)>) {
        out.push((format!("{prefix}.weight"), self.weight.clone()));
        out.push((format!("{prefix}.bias"), self.bias.clone()));
    }
}

pub(super) fn random_values(rows: usize, cols: usize, rng: &mut ChaCha8Rng) -> (Vec<f32>, Vec<f32>) {
    let bound = 1.0 / (cols as f32).sqrt();
    let weights = (0..rows * cols).map(|_| rng.random_range(-bound..bound)).collect();
    let bias = (0..rows).map(|_| rng.random_range(-bound..bound)).collect();
    (weights, bias)
}

/// A residual block (`inner` and `outer`) or a plain hidden layer (`outer` alone).
#[derive(Debug, Clone)]
struct Block {
    inner: Option<Dense>,
    outer: Dense,
}

/// A trainable MLP, residual or plain (layout and initialisation in the module documentation).
#[derive(Debug, Clone)]
pub(crate) struct ResMlp {
    /// A fixed map before the input layer (never trained).
    input_projection: Option<Dense>,
    input: Dense,
    blocks: Vec<Block>,
    output: Dense,
    /// A fixed map after the output layer (never trained).
    output_projection: Option<Dense>,
    /// The activation and how the hidden layers are joined (the projections are the fields
    /// above).
    style: MlpStyle,
}

impl ResMlp {
    /// A randomly initialised residual Swish network (identity blocks), drawn from `rng`.
    pub fn new(spec: MlpSpec, rng: &mut ChaCha8Rng) -> ModelResult<Self> {
        Self::new_styled(spec, MlpStyle::default(), rng)
    }

    /// A randomly initialised network of `style`, drawn from `rng`: residual blocks start as the
    /// identity, plain hidden layers with the law of every other layer.
    pub fn new_styled(spec: MlpSpec, style: MlpStyle, rng: &mut ChaCha8Rng) -> ModelResult<Self> {
        spec.check()?;
        let input = Dense::random(spec.hidden, spec.input, rng)?;
        Self::with_ends(spec, style, input, rng, |rng| {
            Dense::random(spec.output, spec.hidden, rng)
        })
    }

    /// Builds a network from given input and output layers, with fresh blocks drawn from `rng`
    /// between them (`output` gets the same generator after the blocks).
    pub(super) fn with_ends(
        spec: MlpSpec,
        style: MlpStyle,
        input: Dense,
        rng: &mut ChaCha8Rng,
        output: impl FnOnce(&mut ChaCha8Rng) -> ModelResult<Dense>,
    ) -> ModelResult<Self> {
        let blocks = (0..spec.blocks)
            .map(|_| {
                Ok(match style.residual {
                    true => Block {
                        inner: Some(Dense::random(spec.hidden, spec.hidden, rng)?),
                        outer: Dense::zeros(spec.hidden, spec.hidden)?,
                    },
                    false => Block {
                        inner: None,
                        outer: Dense::random(spec.hidden, spec.hidden, rng)?,
                    },
                })
            })
            .collect::<ModelResult<Vec<_>>>()?;
        let output = output(rng)?;
        Ok(ResMlp {
            input_projection: None,
            input,
            blocks,
            output,
            output_projection: None,
            style,
        })
    }

    /// This network between fixed linear maps `y = W x + b` (a PCA's projection before it, its
    /// basis after it), which training leaves unchanged.
    pub(crate) fn with_projections(
        mut self,
        input: Option<DenseLayer>,
        output: Option<DenseLayer>,
    ) -> ModelResult<Self> {
        let dense = |l: DenseLayer| Dense::from_values(l.rows, l.cols, l.weights, l.bias);
        self.input_projection = input.map(dense).transpose()?;
        self.output_projection = output.map(dense).transpose()?;
        // Checks the shapes as the frozen network would.
        self.export()?;
        Ok(self)
    }

    /// The candle network with the weights of a frozen one (for comparisons with the runtime).
    pub(crate) fn from_exported(mlp: &ExportedMlp) -> ModelResult<Self> {
        let dense = |l: &DenseLayer| Dense::from_values(l.rows, l.cols, l.weights.clone(), l.bias.clone());
        let blocks = mlp
            .blocks()
            .iter()
            .map(|b| {
                Ok(Block {
                    inner: b.inner.as_ref().map(dense).transpose()?,
                    outer: dense(&b.outer)?,
                })
            })
            .collect::<ModelResult<Vec<_>>>()?;
        Ok(ResMlp {
            input_projection: mlp.input_projection().map(dense).transpose()?,
            input: dense(mlp.input())?,
            blocks,
            output: dense(mlp.output())?,
            output_projection: mlp.output_projection().map(dense).transpose()?,
            style: mlp.style(),
        })
    }

    /// The fixed maps before the input layer and after the output layer, if any.
    pub(super) fn projections(&self) -> (Option<&Dense>, Option<&Dense>) {
        (self.input_projection.as_ref(), self.output_projection.as_ref())
    }

    /// The activation and how the hidden layers are joined.
    pub(crate) fn style(&self) -> MlpStyle {
        MlpStyle {
            input_projection: self.input_projection.is_some(),
            output_projection: self.output_projection.is_some(),
            ..self.style
        }
    }

    /// The input layer.
    pub(super) fn input_layer(&self) -> &Dense {
        &self.input
    }

    /// The `(inner, outer)` layers of each block, in order (`inner` only in residual ones).
    pub(super) fn block_layers(&self) -> impl Iterator<Item = (Option<&Dense>, &Dense)> {
        self.blocks.iter().map(|b| (b.inner.as_ref(), &b.outer))
    }

    /// The output layer.
    pub(super) fn output_layer(&self) -> &Dense {
        &self.output
    }

    /// Runs the network on a batch `x: (batch, input)`, giving `(batch, output)`.
    pub fn forward(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        self.run(x, Dense::forward)
    }

    /// Runs the network with its weights held constant: backpropagation reaches `x` (and what
    /// produced it) without computing weight gradients. Used to push the physics gradient
    /// through the trained decoder into the integrator.
    pub(crate) fn forward_frozen(&self, x: &Tensor) -> candle_core::Result<Tensor> {
        self.run(x, Dense::forward_frozen)
    }

    /// The forward pass with `dense` applying each layer.
    fn run(
        &self,
        x: &Tensor,
        dense: fn(&Dense, &Tensor) -> candle_core::Result<Tensor>,
    ) -> candle_core::Result<Tensor> {
        let mut h = match &self.input_projection {
            Some(p) => dense(&self.input, &p.forward_frozen(x)?)?,
            None => dense(&self.input, x)?,
        };
        for block in &self.blocks {
            let u = match &block.inner {
                Some(inner) => dense(inner, &h)?,
                None => h.clone(),
            };
            let r = dense(&block.outer, &activate(self.style.activation, &u)?)?;
            h = if self.style.residual { (h + r)? } else { r };
        }
        let y = dense(&self.output, &activate(self.style.activation, &h)?)?;
        match &self.output_projection {
            Some(p) => p.forward_frozen(&y),
            None => Ok(y),
        }
    }

    /// The trainable variables, named `{prefix}.input.weight`, `{prefix}.block{j}.inner.bias`,
    /// `{prefix}.output.weight`, ..., in evaluation order.
    pub(crate) fn parameters(&self, prefix: &str) -> Vec<(String, Var)> {
        let mut out = Vec::with_capacity(4 + 4 * self.blocks.len());
        self.input.parameters(&format!("{prefix}.input"), &mut out);
        for (j, block) in self.blocks.iter().enumerate() {
            if let Some(inner) = &block.inner {
                inner.parameters(&format!("{prefix}.block{j}.inner"), &mut out);
            }
            block.outer.parameters(&format!("{prefix}.block{j}.outer"), &mut out);
        }
        self.output.parameters(&format!("{prefix}.output"), &mut out);
        out
    }

    /// Freezes the current weights.
    pub fn export(&self) -> ModelResult<ExportedMlp> {
        let mut layers = Vec::new();
        if let Some(p) = &self.input_projection {
            layers.push(p.export()?);
        }
        layers.push(self.input.export()?);
        for block in &self.blocks {
            if let Some(inner) = &block.inner {
                layers.push(inner.export()?);
            }
            layers.push(block.outer.export()?);
        }
        layers.push(self.output.export()?);
        if let Some(p) = &self.output_projection {
            layers.push(p.export()?);
        }
        ExportedMlp::from_styled_layers(layers, self.style())
    }
}

/// `activation` elementwise on `t`.
pub(super) fn activate(activation: Activation, t: &Tensor) -> candle_core::Result<Tensor> {
    match activation {
        Activation::Swish => t.silu(),
        Activation::Elu => t.elu(1.0),
    }
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;

    use super::*;
    use crate::learn::network::exported::forward_exported;
    use crate::learn::network::tensor::tensor_to_rows;
    use crate::learn::network::test_support::*;
    use crate::learn::network::MlpStyle;

    #[test]
    fn exported_mlp_matches_candle_forward() {
        for style in [MlpStyle::default(), MlpStyle::PAPER, PROJECTED] {
            exported_matches_candle(style);
        }
    }

    fn exported_matches_candle(style: MlpStyle) {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let spec = MlpSpec {
            input: 30,
            output: 5,
            hidden: 24,
            blocks: 3,
        };
        let mlp = styled_network(spec, style, &mut rng);
        randomise(&mlp.parameters("m"), 0.4, &mut rng);
        let x = random_rows(16, 30, 2.0, &mut rng);
        let candle = tensor_to_rows(&mlp.forward(&as_tensor(&x)).unwrap()).unwrap();
        let exported = mlp.export().unwrap();
        assert_eq!((exported.spec(), exported.style()), (spec, style));
        let fixed = style.projections();
        assert_eq!(
            exported.layers().len(),
            2 + fixed + style.layers_per_block() * spec.blocks
        );
        // The candle copy of the frozen network is the same network.
        let copy = ResMlp::from_exported(&exported).unwrap().export().unwrap();
        assert_eq!(copy, exported);
        // Training leaves the projections fixed: they are not among the variables.
        assert_eq!(mlp.parameters("m").len(), 2 * (exported.layers().len() - fixed));
        let layers = exported.layers().into_iter().cloned().collect();
        assert_eq!(ExportedMlp::from_styled_layers(layers, style).unwrap(), exported);
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
}
