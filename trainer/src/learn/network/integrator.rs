//! The latent integrator (Sec. 3.3, Eq. 3) and the normalisation of its inputs and outputs.

use candle_core::{Device, Tensor, Var};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::error::{invalid, ModelResult};
use super::exported::{forward_exported, DenseLayer, ExportedMlp};
use super::layout::MlpSpec;
use super::mlp::ResMlp;

/// Sizes of the latent integrator `z_t = I(z_{t-1}, z_{t-2}, p_t, p_{t-1}, p_{t-2})`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub(crate) struct IntegratorSpec {
    /// Latent size `k`.
    pub latent: usize,
    /// Size of one boundary-condition vector `p_t` (may be 0).
    pub bc: usize,
    /// Hidden width of the MLP.
    pub hidden: usize,
    /// Residual blocks of the MLP.
    pub blocks: usize,
    /// Run-time collider slots whose inputs (`mochi_runtime::collider::FEATURES_PER_COLLIDER`
    /// each) follow the signals. Absent in checkpoints written before it existed: 0.
    #[serde(default)]
    pub colliders: usize,
    /// Whether the frame time `dt` follows the signals in the input (a model trained over a
    /// range of frame rates). Absent in checkpoints written before it existed: `false`.
    #[serde(default)]
    pub timed: bool,
    /// For a timed integrator, the frame time its increments are scaled to (the scene's `dt`):
    /// a step adds `dt / reference_dt` times the network's increment, so the network predicts
    /// a latent velocity of one scale at every rate.
    #[serde(default)]
    pub reference_dt: f64,
    /// Whether a timed integrator's network reads the previous latent's change per frame of
    /// `reference_dt`, `(z_{t-1} - z_{t-2}) reference_dt / dt`, in place of `z_{t-2}`
    /// ([`rate_row`]): the same quantity at every frame rate, where `z_{t-2}` alone leaves the
    /// network to divide by the frame time. Absent in checkpoints written before it existed:
    /// `false`.
    #[serde(default)]
    pub rate_input: bool,
}

impl IntegratorSpec {
    /// Length of the packed input `q = [z_{t-1}, z_{t-2}, p_t, p_{t-1}, p_{t-2}]`, then the
    /// collider slots' inputs, then `dt` when [`IntegratorSpec::timed`].
    pub fn input(&self) -> usize {
        2 * self.latent
            + 3 * self.bc
            + mochi_runtime::collider::FEATURES_PER_COLLIDER * self.colliders
            + usize::from(self.timed)
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

/// Turns a timed integrator's packed input `row` (its last number the frame time `dt`) into
/// what a network with a rate input reads ([`IntegratorSpec::rate_input`]): the previous
/// latent's change per frame of `reference_dt`, `(z_{t-1} - z_{t-2}) reference_dt / dt`, in
/// place of `z_{t-2}`. The runtime's `Instance` reads the same.
pub fn rate_row(row: &mut [f32], latent: usize, reference_dt: f64) {
    let Some(&dt) = row.last() else { return };
    let scale = (reference_dt / dt as f64) as f32;
    for i in 0..latent {
        row[latent + i] = (row[i] - row[latent + i]) * scale;
    }
}

/// `rows` (packed inputs) as the network reads them: with a rate input at `reference_dt`
/// ([`rate_row`]), or as they are (`None`). The input normalisation is fitted to these.
pub fn network_inputs(rows: &[Vec<f32>], latent: usize, reference_dt: Option<f64>) -> Vec<Vec<f32>> {
    rows.iter()
        .map(|r| {
            let mut r = r.clone();
            if let Some(reference) = reference_dt {
                rate_row(&mut r, latent, reference);
            }
            r
        })
        .collect()
}

/// A frozen integrator: `z_t = q[..latent] + mlp(q)` with the normalisations folded into
/// `mlp`'s first and last layers (for a timed one, `+ (dt / reference_dt) mlp(q)`, `dt` the
/// input's last number).
#[derive(Debug, Clone, PartialEq)]
pub struct ExportedIntegrator {
    latent: usize,
    mlp: ExportedMlp,
    reference_dt: Option<f64>,
    rate_input: bool,
}

impl ExportedIntegrator {
    /// Checks that `mlp` maps a packed input whose first `latent` values are `z_{t-1}` to a
    /// `latent`-sized increment.
    pub fn new(latent: usize, mlp: ExportedMlp) -> ModelResult<Self> {
        let spec = mlp.spec();
        if spec.output != latent || spec.input < 2 * latent {
            return invalid(format!("integrator network {spec:?} does not fit latent size {latent}"));
        }
        Ok(ExportedIntegrator {
            latent,
            mlp,
            reference_dt: None,
            rate_input: false,
        })
    }

    /// The same network as a timed integrator whose increments scale with `dt / reference_dt`.
    pub fn timed_at(mut self, reference_dt: f64) -> Self {
        self.reference_dt = Some(reference_dt);
        self
    }

    /// The same timed network reading the previous latent's change per reference frame in
    /// place of `z_{t-2}` ([`IntegratorSpec::rate_input`]); an untimed one is returned as is.
    pub fn with_rate_input(mut self) -> Self {
        self.rate_input = self.reference_dt.is_some();
        self
    }

    /// Whether the network reads the previous latent's change per reference frame
    /// ([`ExportedIntegrator::with_rate_input`]).
    pub fn rate_input(&self) -> bool {
        self.rate_input
    }

    /// The frame time a timed integrator's increments are scaled to (`None`: untimed).
    pub fn reference_dt(&self) -> Option<f64> {
        self.reference_dt
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
        let mut z = match (self.reference_dt, self.rate_input) {
            (Some(reference), true) => {
                let mut rated = q.to_vec();
                rate_row(&mut rated, self.latent, reference);
                forward_exported(&self.mlp, &rated)?
            }
            _ => forward_exported(&self.mlp, q)?,
        };
        if let (Some(reference), Some(&dt)) = (self.reference_dt, q.last()) {
            let scale = (dt as f64 / reference) as f32;
            z.iter_mut().for_each(|v| *v *= scale);
        }
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
        let rated = match self.spec.rate_input {
            true => {
                let k = self.spec.latent;
                let n = self.spec.input();
                let dt = q.narrow(1, n - 1, 1)?;
                let change = (q.narrow(1, 0, k)? - q.narrow(1, k, k)?)?
                    .broadcast_mul(&dt.recip()?.affine(self.spec.reference_dt, 0.0)?)?;
                Tensor::cat(&[q.narrow(1, 0, k)?, change, q.narrow(1, 2 * k, n - 2 * k)?], 1)?
            }
            false => q.clone(),
        };
        let normalised = rated.broadcast_sub(&self.input_mean)?.broadcast_div(&self.input_std)?;
        let increment = self
            .mlp
            .forward(&normalised)?
            .broadcast_mul(&self.increment_std)?
            .broadcast_add(&self.increment_mean)?;
        let increment = match self.spec.timed {
            // The frame time is the last input: the increment scales with it.
            true => {
                let dt = q.narrow(1, self.spec.input() - 1, 1)?;
                increment.broadcast_mul(&dt.affine(1.0 / self.spec.reference_dt, 0.0)?)?
            }
            false => increment,
        };
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
        let exported = ExportedIntegrator::new(self.spec.latent, ExportedMlp::from_layers(layers)?)?;
        Ok(match (self.spec.timed, self.spec.rate_input) {
            (true, true) => exported.timed_at(self.spec.reference_dt).with_rate_input(),
            (true, false) => exported.timed_at(self.spec.reference_dt),
            (false, _) => exported,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::network::tensor::tensor_to_rows;
    use crate::learn::network::test_support::*;

    #[test]
    fn exported_integrator_folds_normalisation() {
        let spec = IntegratorSpec {
            latent: 4,
            bc: 3,
            hidden: 32,
            blocks: 2,
            colliders: 0,
            timed: false,
            reference_dt: 0.0,
            rate_input: false,
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
    fn a_timed_integrator_scales_its_increment_with_the_frame_time_in_candle_and_export() {
        for rate_input in [false, true] {
            timed_integrator_agrees_in_candle_and_export(rate_input);
        }
    }

    /// A timed integrator (reading the latent before the last, or its change per reference
    /// frame): candle's forward and the exported step agree, and the exported step is the
    /// previous latent plus `dt / reference_dt` times the network's output on what it reads.
    fn timed_integrator_agrees_in_candle_and_export(rate_input: bool) {
        let spec = IntegratorSpec {
            latent: 3,
            bc: 2,
            hidden: 16,
            blocks: 1,
            colliders: 0,
            timed: true,
            reference_dt: 1.0 / 30.0,
            rate_input,
        };
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut inputs = random_rows(8, spec.input(), 1.0, &mut rng);
        for (row, dt) in inputs
            .iter_mut()
            .zip([1.0 / 30.0, 1.0 / 60.0, 1.0 / 120.0, 1.0 / 24.0].iter().cycle())
        {
            *row.last_mut().unwrap() = *dt as f32;
        }
        let read = network_inputs(&inputs, 3, rate_input.then_some(1.0 / 30.0));
        let norm = Normalisation::fit(&read).unwrap();
        let integrator = LatentIntegrator::new(spec, norm, Normalisation::identity(3), 4).unwrap();
        randomise(&integrator.parameters(), 0.3, &mut rng);
        let candle = tensor_to_rows(&integrator.forward(&as_tensor(&inputs)).unwrap()).unwrap();
        let exported = integrator.export().unwrap();
        assert_eq!(exported.reference_dt(), Some(1.0 / 30.0));
        assert_eq!(exported.rate_input(), rate_input);
        for ((q, r), z) in inputs.iter().zip(&read).zip(&candle) {
            let step = exported.step(q).unwrap();
            let scale = *q.last().unwrap() * 30.0;
            if rate_input {
                // What the network reads: the change of the latent per frame of 1/30 s.
                for i in 0..3 {
                    let change = (q[i] - q[3 + i]) / scale;
                    assert!((r[3 + i] - change).abs() <= 1e-5 * change.abs().max(1.0));
                }
            }
            let unscaled = forward_exported(exported.mlp(), r).unwrap();
            for i in 0..3 {
                assert!(
                    (step[i] - z[i]).abs() <= 1e-5 * z[i].abs().max(1.0),
                    "{} vs {}",
                    step[i],
                    z[i]
                );
                assert!((step[i] - (q[i] + scale * unscaled[i])).abs() <= 1e-6 * step[i].abs().max(1.0));
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
            colliders: 0,
            timed: false,
            reference_dt: 0.0,
            rate_input: false,
        };
        let wrong = LatentIntegrator::new(spec, Normalisation::identity(6), Normalisation::identity(2), 0);
        assert!(wrong.is_err());
    }
}
