//! Data-free learning of a nonlinear subspace (Sharp et al. 2023, "Data-Free Learning of
//! Reduced-Order Kinematics"; the objective of Lyu et al. 2024, Eq. 4): a decoder
//! `f: z (latent values) -> q` (an encoded state) trained from the scene's energies alone, with
//! no simulated data, to minimise
//!
//! ```text
//! L = E_{z ~ N(0, I)} [ P(x(f(z))) / E_ref ]
//!   + lambda E_{z1, z2 ~ N(0, I)} [ log( d(f(z1), f(z2)) / (sigma D |z1 - z2|) )^2 ]
//! ```
//!
//! - `q` holds the free vertices in the boundary-condition frame of the scene's start (the
//!   handles at their frame-0 targets, [`Encoding`]); `x(q)` decodes it with the handles there.
//! - `P` is the sum of the scene's potentials (elastic, gravity, loads, collision: everything the
//!   simulator minimises except inertia). It reaches candle through the surrogate
//!   `sum(q * stopgrad(dP/dq)) / E_ref` (docs/design.md, decision 2): the simulator evaluates
//!   `dP/dx` in f64, one sample per thread, and [`Encoding::encode_gradient`] pulls it back to
//!   `q`.
//! - `E_ref = Y V`, the scene's Young's modulus times the body's rest volume (total lumped mass
//!   over density): the energy of a unit strain, so `P / E_ref` is of the order of half the
//!   squared strain whatever the units and the stiffness of the scene.
//! - `d` is the mass-weighted RMS distance `sqrt(sum_j m_j |q1_j - q2_j|^2 / sum_j m_j)` over
//!   the free vertices (lumped masses), and `D` the diagonal of the rest bounding box, so the
//!   repulsion asks latent distance 1 to move the body by `sigma` diagonals on average. Pairs are
//!   all ordered pairs of a minibatch.
//!
//! The decoder is a residual MLP ([`crate::learn::network`]) plus a constant: `f(z) = q_rest +
//! MLP(z)`, `q_rest` the rest shape encoded in the start's frame (the free vertices where the
//! mesh puts them, the handles at their start targets). The rest shape, not a `start = "static"`
//! equilibrium, is the constant because it keeps the symmetry of the scene: from the buckled
//! equilibrium of `bistable` nearly every sample stays in that one well, from the rest shape the
//! decoder learns both. The constant is folded into the output bias on export, so the frozen
//! decoder is a plain [`ExportedMlp`]. The output layer starts scaled by `sigma D`, so the
//! untrained decoder moves the body by a fraction of that length instead of by the unit-size
//! offsets of the default initialisation, which would invert elements.

use std::time::Instant;

use candle_core::backprop::GradStore;
use candle_core::{DType, Device, Tensor, Var};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::learn::encoding::{Encoding, EncodingError, Frame};
use crate::learn::network::{tensor_to_rows, ExportedMlp, MlpSpec, MlpStyle, NetworkError, ResMlp};
use crate::learn::train::{AdamW, AdamWConfig, TrainError};
use crate::progress::{EpochsBar, Reporter};
use mochi_sim::bc::Pose;
use mochi_sim::energy::add_gradient_sequential;
use mochi_sim::{BuiltScene, StencilEnergy};

#[cfg(test)]
pub(crate) mod tests;

/// Why a data-free training could not run.
#[derive(Debug, thiserror::Error)]
pub enum DataFreeError {
    /// A setting or the scene does not allow it (the message says which).
    #[error("{0}")]
    Invalid(String),
    /// candle failed.
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
    /// A network could not be built or exported.
    #[error(transparent)]
    Network(#[from] NetworkError),
    /// A state could not be encoded or decoded.
    #[error(transparent)]
    Encoding(#[from] EncodingError),
    /// The optimiser could not be set up.
    #[error(transparent)]
    Train(#[from] TrainError),
}

impl DataFreeError {
    fn invalid(message: String) -> Self {
        DataFreeError::Invalid(message)
    }
}

/// Result of this module's functions.
pub type DataFreeResult<T> = Result<T, DataFreeError>;

/// Settings of a data-free training run; [`Default`] gives the documented defaults.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DataFreeSettings {
    /// Latent dimension `r` (default 8).
    pub latent: usize,
    /// Width of the decoder's residual stream (default 128).
    pub hidden: usize,
    /// Blocks of the decoder (default 2).
    pub blocks: usize,
    /// Its activation and how its hidden layers are joined (default: residual Swish blocks).
    pub style: MlpStyle,
    /// Latent samples per iteration, at least 2: the repulsion uses all their pairs (default 32).
    pub batch: usize,
    /// Optimiser steps (default 2000).
    pub iterations: usize,
    /// Adam's learning rate (default 1e-3).
    pub learning_rate: f64,
    /// Repulsion length per unit latent distance, in diagonals of the rest bounding box
    /// (default 0.05: with `r = 8` two samples lie about 4 apart, so typical pairs differ by
    /// 0.2 diagonals, the size of a buckling or a large bend, not of a crushed element).
    pub sigma: f64,
    /// Weight of the repulsion term (default 0.1). Sharp et al. use about 1; on `bistable`
    /// (2000 iterations, the other defaults) 1 and 0.1 both give both buckling branches, 0.1
    /// at a third of the energy, while 0.01 lets the energy win and every sample stays near
    /// the straight compressed bar.
    pub lambda: f64,
    /// Seed of the decoder's initialisation and of the latent samples (default 0).
    pub seed: u64,
}

impl Default for DataFreeSettings {
    fn default() -> Self {
        DataFreeSettings {
            latent: 8,
            hidden: 128,
            blocks: 2,
            style: MlpStyle::default(),
            batch: 32,
            iterations: 2000,
            learning_rate: 1e-3,
            sigma: 0.05,
            lambda: 0.1,
            seed: 0,
        }
    }
}

impl DataFreeSettings {
    /// Checks every setting, naming the first one out of range.
    pub fn validate(&self) -> DataFreeResult<()> {
        let positive = |name: &str, value: usize| -> DataFreeResult<()> {
            if value == 0 {
                return Err(DataFreeError::invalid(format!(
                    "data-free setting `{name}` must be at least 1 (got 0)"
                )));
            }
            Ok(())
        };
        positive("latent", self.latent)?;
        positive("hidden", self.hidden)?;
        positive("iterations", self.iterations)?;
        if self.batch < 2 {
            return Err(DataFreeError::invalid(format!(
                "data-free setting `batch` must be at least 2: the repulsion term needs pairs (got {})",
                self.batch
            )));
        }
        if !(self.learning_rate.is_finite() && self.learning_rate > 0.0) {
            return Err(DataFreeError::invalid(format!(
                "data-free setting `learning_rate` must be positive and finite (got {})",
                self.learning_rate
            )));
        }
        if !(self.sigma.is_finite() && self.sigma > 0.0) {
            return Err(DataFreeError::invalid(format!(
                "data-free setting `sigma` must be positive and finite (got {})",
                self.sigma
            )));
        }
        if !(self.lambda.is_finite() && self.lambda >= 0.0) {
            return Err(DataFreeError::invalid(format!(
                "data-free setting `lambda` must be non-negative and finite (got {})",
                self.lambda
            )));
        }
        Ok(())
    }
}

/// What [`train_data_free`] returns.
#[derive(Debug, Clone)]
pub struct DataFreeOutcome {
    /// The trained decoder, `z -> q` in the start's boundary-condition frame, with `q_rest`
    /// folded into its output bias.
    pub decoder: ExportedMlp,
    /// Per iteration, the energy term and the (unweighted) repulsion term of the minibatch;
    /// the loss is `energy + lambda * repulsion`.
    pub losses: Vec<(f64, f64)>,
    /// Wall-clock seconds of the training loop.
    pub seconds: f64,
}

/// The trainable decoder `z -> q_rest + MLP(z)`.
#[derive(Debug, Clone)]
pub(crate) struct DataFreeModel {
    /// The residual MLP; training changes its weights in place.
    pub(crate) mlp: ResMlp,
    /// `q_rest` as f32 values.
    offset: Vec<f32>,
    /// `q_rest` as a `(1, n)` tensor.
    offset_row: Tensor,
}

impl DataFreeModel {
    /// A decoder with the `latent` inputs and network of `settings` around `offset`, its
    /// output layer scaled by `output_scale` (see the module documentation), drawn from
    /// `settings.seed`.
    pub(crate) fn new(settings: &DataFreeSettings, offset: Vec<f32>, output_scale: f64) -> DataFreeResult<Self> {
        let spec = MlpSpec {
            input: settings.latent,
            output: offset.len(),
            hidden: settings.hidden,
            blocks: settings.blocks,
        };
        let mlp = ResMlp::new_styled(spec, settings.style, &mut ChaCha8Rng::seed_from_u64(settings.seed))?;
        for (name, var) in mlp.parameters("decoder") {
            if name.starts_with("decoder.output.") {
                var.set(&(var.as_tensor() * output_scale)?)?;
            }
        }
        let offset_row = Tensor::from_slice(&offset, (1, offset.len()), &Device::Cpu)?;
        Ok(DataFreeModel {
            mlp,
            offset,
            offset_row,
        })
    }

    /// The decoded states `(batch, n)` of latent rows `z: (batch, latent)`.
    pub(crate) fn forward(&self, z: &Tensor) -> candle_core::Result<Tensor> {
        self.mlp.forward(z)?.broadcast_add(&self.offset_row)
    }

    /// `q_rest` as a `(1, n)` tensor: the decoder's constant output.
    pub(crate) fn offset_row(&self) -> &Tensor {
        &self.offset_row
    }

    /// The trainable variables, named `decoder.input.weight`, ... (see [`ResMlp::parameters`]).
    pub(crate) fn parameters(&self) -> Vec<(String, Var)> {
        self.mlp.parameters("decoder")
    }

    /// The frozen decoder, `q_rest` added to the output bias.
    pub(crate) fn export(&self) -> DataFreeResult<ExportedMlp> {
        let plain = self.mlp.export()?;
        let mut layers: Vec<_> = plain.layers().into_iter().cloned().collect();
        if let Some(output) = layers.last_mut() {
            output.bias.iter_mut().zip(&self.offset).for_each(|(b, o)| *b += o);
        }
        Ok(ExportedMlp::from_styled_layers(layers, plain.style())?)
    }
}

/// The two terms of the objective on one minibatch.
#[derive(Debug)]
pub(crate) struct BatchTerms {
    /// Scalar whose weight gradient is the energy term's: the surrogate
    /// `mean_i sum_j q_ij stopgrad(dP/dq_ij) / E_ref`.
    pub(crate) energy_objective: Tensor,
    /// The repulsion term as a differentiable scalar (unweighted).
    pub(crate) repulsion_objective: Tensor,
    /// The energy term's value: the mean of `P(x) / E_ref`.
    pub(crate) energy: f64,
    /// The repulsion term's value.
    pub(crate) repulsion: f64,
}

impl BatchTerms {
    /// `energy_objective + lambda * repulsion_objective`, the scalar to backpropagate.
    pub(crate) fn objective(&self, lambda: f64) -> candle_core::Result<Tensor> {
        &self.energy_objective + (&self.repulsion_objective * lambda)?
    }
}

/// The data-free objective of one scene: its potentials, the start's frame and the scales.
pub(crate) struct DataFreeObjective<'a> {
    encoding: &'a Encoding,
    potentials: &'a [Box<dyn StencilEnergy>],
    frame: Frame,
    targets: Vec<f64>,
    /// The encoded rest shape `q_rest` (the decoder's constant).
    pub(crate) rest: Vec<f64>,
    /// `E_ref` (module documentation).
    pub(crate) energy_scale: f64,
    /// `sigma D`: the repulsion length per unit latent distance.
    pub(crate) length: f64,
    /// `m_j / sum m` per encoded value (the free vertices' lumped masses).
    weights: Tensor,
}

impl<'a> DataFreeObjective<'a> {
    /// The objective of `problem`'s body encoded by `encoding`, with repulsion length `sigma`
    /// diagonals per unit latent distance.
    pub(crate) fn new(problem: &'a BuiltScene, encoding: &'a Encoding, sigma: f64) -> DataFreeResult<Self> {
        let dim = problem.mesh.dim;
        if encoding.state_len() != problem.mesh.rest.len() || encoding.dim() != dim {
            return Err(DataFreeError::invalid(
                "the encoding does not belong to this scene's mesh".into(),
            ));
        }
        let mut targets = Vec::with_capacity(encoding.reference().len());
        for h in &problem.handles {
            h.place(&Pose::identity(), dim, &mut targets);
        }
        let frame = encoding
            .frame(&targets)
            .map_err(|e| DataFreeError::invalid(format!("frame of the start's handle targets: {e}")))?;
        let rest = encoding.encode(&problem.mesh.rest, &frame)?;
        let potentials = problem.simulator.potentials();

        let masses = problem.simulator.masses();
        let density = problem.scene.material.density;
        let energy_scale = problem.scene.material.youngs * masses.iter().sum::<f64>() / density;
        if !(energy_scale.is_finite() && energy_scale > 0.0) {
            return Err(DataFreeError::invalid(format!("the energy scale (Young's modulus times rest volume) is {energy_scale}: the body has no stiffness or no volume")));
        }
        let per_vertex = encoding.encoded_len() / encoding.free_vertices().len().max(1);
        let free_mass: f64 = encoding.free_vertices().iter().map(|&v| masses[v]).sum();
        if !free_mass.is_finite() || free_mass <= 0.0 {
            return Err(DataFreeError::invalid(
                "the free vertices have no mass: there is nothing to learn".into(),
            ));
        }
        let weights: Vec<f32> = encoding
            .free_vertices()
            .iter()
            .flat_map(|&v| std::iter::repeat_n((masses[v] / free_mass) as f32, per_vertex))
            .collect();
        let n = weights.len();
        Ok(DataFreeObjective {
            encoding,
            potentials,
            frame,
            targets,
            rest,
            energy_scale,
            length: sigma * problem.mesh.rest_diagonal(),
            weights: Tensor::from_vec(weights, (1, n), &Device::Cpu)?,
        })
    }

    /// The handle targets of the start (the frame the decoder's states are encoded in).
    pub(crate) fn targets(&self) -> &[f64] {
        &self.targets
    }

    /// The untrained decoder of `settings` around the rest shape.
    pub(crate) fn initial_model(&self, settings: &DataFreeSettings) -> DataFreeResult<DataFreeModel> {
        let offset = self.rest.iter().map(|&v| v as f32).collect();
        DataFreeModel::new(settings, offset, self.length)
    }

    /// `P(x(q)) / E_ref` and its gradient with respect to `q`, in f64.
    pub(crate) fn energy_of(&self, q: &[f64], x: &mut [f64], grad: &mut [f64], dq: &mut [f64]) -> DataFreeResult<f64> {
        self.encoding.decode_into(q, &self.frame, &self.targets, x)?;
        let value = total_potential(self.potentials, x, grad);
        self.encoding
            .encode_gradient(q, grad, &self.frame, self.energy_scale, dq)?;
        Ok(value / self.energy_scale)
    }

    /// Both terms of the objective for latent rows `z: (batch, latent)`.
    pub(crate) fn batch(&self, model: &DataFreeModel, z: &Tensor) -> DataFreeResult<BatchTerms> {
        let q = model.forward(z)?;
        let rows = tensor_to_rows(&q)?;
        let (m, n) = (rows.len(), self.rest.len());
        if m < 2 {
            return Err(DataFreeError::invalid(format!(
                "a data-free minibatch needs at least 2 samples, got {m}"
            )));
        }
        let state_len = self.encoding.state_len();
        let parts: Vec<DataFreeResult<(f64, Vec<f32>)>> = rows
            .par_iter()
            .map_init(
                || (vec![0.0; n], vec![0.0; state_len], vec![0.0; state_len], vec![0.0; n]),
                |(q64, x, grad, dq), row| {
                    q64.iter_mut().zip(row).for_each(|(a, &b)| *a = b as f64);
                    let value = self.energy_of(q64, x, grad, dq)?;
                    Ok((value, dq.iter().map(|&g| g as f32).collect()))
                },
            )
            .collect();
        let mut energy = 0.0;
        let mut g = Vec::with_capacity(m * n);
        for part in parts {
            let (value, dq) = part?;
            energy += value;
            g.extend(dq);
        }
        let g = Tensor::from_vec(g, (m, n), &Device::Cpu)?;
        let energy_objective = ((&q * g)?.sum_all()? / m as f64)?;
        let repulsion_objective = self.repulsion(&q, z)?;
        let repulsion = repulsion_objective.to_dtype(DType::F64)?.to_scalar::<f64>()?;
        Ok(BatchTerms {
            energy_objective,
            repulsion_objective,
            energy: energy / m as f64,
            repulsion,
        })
    }

    /// `mean over pairs i != j of log(d(q_i, q_j) / (sigma D |z_i - z_j|))^2`, the squared
    /// distances taken from the Gram matrix of the mass-weighted, batch-centred rows (one
    /// matrix product instead of a difference per pair).
    fn repulsion(&self, q: &Tensor, z: &Tensor) -> DataFreeResult<Tensor> {
        let zs = tensor_to_rows(z)?;
        let m = zs.len();
        let mut target = vec![0.0f32; m * m];
        let mut mask = vec![0.0f32; m * m];
        for i in 0..m {
            for j in 0..m {
                if i != j {
                    let dz: f64 = zs[i].iter().zip(&zs[j]).map(|(a, b)| ((a - b) as f64).powi(2)).sum();
                    // log(sigma D |dz|), floored so that equal samples give a finite term.
                    target[i * m + j] = (self.length * dz.sqrt()).max(1e-30).ln() as f32;
                    mask[i * m + j] = 1.0;
                }
            }
        }
        let target = Tensor::from_vec(target, (m, m), &Device::Cpu)?;
        let mask = Tensor::from_vec(mask, (m, m), &Device::Cpu)?;
        let centred = q.broadcast_sub(&q.mean_keepdim(0)?)?;
        let weighted = centred.broadcast_mul(&self.weights.sqrt()?)?;
        let norms = weighted.sqr()?.sum_keepdim(1)?;
        let gram = weighted.matmul(&weighted.t()?)?;
        let squared = (norms.broadcast_add(&norms.t()?)? - (gram * 2.0)?)?.relu()?;
        // Floor the squared distance far below the repulsion length so the log stays finite.
        let floor = (1e-6 * self.length).powi(2);
        let log_distance = ((squared + floor)?.log()? * 0.5)?;
        let terms = ((log_distance - target)?.sqr()? * mask)?;
        Ok((terms.sum_all()? / (m * (m - 1)) as f64)?)
    }

    /// The terms of one minibatch and the weight gradients of `energy + lambda * repulsion`.
    pub(crate) fn gradients(
        &self,
        model: &DataFreeModel,
        z: &Tensor,
        lambda: f64,
    ) -> DataFreeResult<(BatchTerms, GradStore)> {
        let terms = self.batch(model, z)?;
        let grads = terms.objective(lambda)?.backward()?;
        Ok((terms, grads))
    }
}

/// Sum of `potentials` at `x`; their gradient is written into `grad`.
fn total_potential(potentials: &[Box<dyn StencilEnergy>], x: &[f64], grad: &mut [f64]) -> f64 {
    grad.fill(0.0);
    potentials
        .iter()
        .map(|p| add_gradient_sequential(p.as_ref(), 1.0, x, grad))
        .sum()
}

/// `rows * cols` standard normal samples (Box-Muller) as a `(rows, cols)` tensor.
pub(crate) fn normal_latents(rows: usize, cols: usize, rng: &mut ChaCha8Rng) -> candle_core::Result<Tensor> {
    let values = (0..rows * cols)
        .map(|_| {
            let u: f64 = 1.0 - rng.random::<f64>();
            let v: f64 = rng.random::<f64>();
            ((-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()) as f32
        })
        .collect();
    Tensor::from_vec(values, (rows, cols), &Device::Cpu)
}

/// Runs `settings.iterations` Adam steps on `model`, latents drawn from `rng`; returns the terms
/// of every iteration.
pub(crate) fn optimise(
    objective: &DataFreeObjective<'_>,
    model: &DataFreeModel,
    settings: &DataFreeSettings,
    rng: &mut ChaCha8Rng,
    reporter: &dyn Reporter,
) -> DataFreeResult<Vec<(f64, f64)>> {
    let config = AdamWConfig {
        lr: settings.learning_rate,
        ..AdamWConfig::default()
    };
    let mut optimizer = AdamW::new(&model.parameters(), config)?;
    let bar = EpochsBar::new("data-free", settings.iterations, 0, reporter.bars());
    let mut losses = Vec::with_capacity(settings.iterations);
    for iteration in 0..settings.iterations {
        let z = normal_latents(settings.batch, settings.latent, rng)?;
        let (terms, grads) = objective.gradients(model, &z, settings.lambda)?;
        let total = terms.energy + settings.lambda * terms.repulsion;
        if !total.is_finite() {
            return Err(DataFreeError::invalid(format!(
                "data-free loss is not finite at iteration {iteration} (energy term {}, repulsion term {})",
                terms.energy, terms.repulsion
            )));
        }
        optimizer.step(&grads)?;
        losses.push((terms.energy, terms.repulsion));
        bar.epoch(total);
    }
    bar.finish();
    Ok(losses)
}

/// Trains a data-free decoder for `problem`'s body, encoded by `encoding` (module
/// documentation), reporting progress to `reporter`.
pub fn train_data_free(
    problem: &BuiltScene,
    encoding: &Encoding,
    settings: &DataFreeSettings,
    reporter: &dyn Reporter,
) -> DataFreeResult<DataFreeOutcome> {
    let objective = DataFreeObjective::new(problem, encoding, settings.sigma)?;
    Ok(train_data_free_model(&objective, settings, reporter)?.1)
}

/// As [`train_data_free`] with the objective given, also returning the trainable decoder (a
/// Lipschitz optimisation continues from it).
pub(crate) fn train_data_free_model(
    objective: &DataFreeObjective<'_>,
    settings: &DataFreeSettings,
    reporter: &dyn Reporter,
) -> DataFreeResult<(DataFreeModel, DataFreeOutcome)> {
    settings.validate()?;
    reporter.stage("data-free subspace");
    let model = objective.initial_model(settings)?;
    let mut rng = ChaCha8Rng::seed_from_u64(settings.seed);
    rng.set_stream(1);
    let start = Instant::now();
    let losses = optimise(objective, &model, settings, &mut rng, reporter)?;
    let seconds = start.elapsed().as_secs_f64();
    if let (Some(first), Some(last)) = (losses.first(), losses.last()) {
        reporter.message(&format!(
            "data-free subspace: {} iterations in {seconds:.1} s; energy term {:.3e} -> {:.3e}, repulsion term {:.3e} -> {:.3e}",
            losses.len(),
            first.0,
            last.0,
            first.1,
            last.1
        ));
    }
    let outcome = DataFreeOutcome {
        decoder: model.export()?,
        losses,
        seconds,
    };
    Ok((model, outcome))
}
