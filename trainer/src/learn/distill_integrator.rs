//! Integrator distillation: a narrower latent integrator fitted to reproduce a trained one's
//! steps on the packed inputs its rollouts visit, by dataset aggregation: the student is
//! fitted to the teacher's steps on the teacher's rollout inputs, then rolled out itself, the
//! inputs it reaches labelled with the teacher's steps and added, and fitted again, so it
//! learns to come back from its own errors (a rollout compounds them).

use candle_core::{Device, Tensor};

use super::network::{network_inputs, ExportedIntegrator, IntegratorSpec, LatentIntegrator, Normalisation};
use super::train::{self, BatchLoss, TrainConfig, TrainError, TrainResult};

/// The shape and schedule of a distilled integrator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IntegratorDistillShape {
    /// Hidden width of the student.
    pub hidden: usize,
    /// Its residual blocks.
    pub blocks: usize,
    /// Rounds of rollouts by the student after the first fit (0: teacher inputs only).
    pub rounds: usize,
}

/// One step of an integrator from a packed input (the teacher's or the student's).
pub type Step<'a> = dyn Fn(&[f32]) -> TrainResult<Vec<f32>> + 'a;

/// A distilled integrator and its losses.
#[derive(Debug, Clone)]
pub struct DistilledIntegrator {
    /// The student.
    pub integrator: ExportedIntegrator,
    /// Mean loss of the last epoch of each fit (squared step error over the teacher's
    /// increment spread).
    pub losses: Vec<f64>,
    /// Packed inputs fitted on, in all.
    pub inputs: usize,
}

/// Distils `teacher` into an integrator of `shape`. `rollout(step)` rolls a stepping function
/// over the training motions and returns the packed inputs it met; `config` sets each fit.
/// The teacher reads `bc` boundary-condition numbers per signal and `colliders` collider
/// slots (and the frame time when it is timed).
pub fn distill_integrator(
    teacher: &ExportedIntegrator,
    (bc, colliders): (usize, usize),
    shape: IntegratorDistillShape,
    config: &TrainConfig,
    mut rollout: impl FnMut(&Step) -> TrainResult<Vec<Vec<f32>>>,
) -> TrainResult<DistilledIntegrator> {
    let k = teacher.latent();
    let teach = |q: &[f32]| teacher.step(q).map_err(|e| TrainError::Invalid(e.to_string()));
    let mut inputs = rollout(&teach)?;
    let Some(width) = inputs.first().map(Vec::len) else {
        return Err(TrainError::Invalid("the teacher's rollouts visited no input".into()));
    };
    let timed = teacher.reference_dt().is_some();
    let layout = IntegratorSpec {
        latent: k,
        bc,
        hidden: shape.hidden,
        blocks: shape.blocks,
        colliders,
        timed,
        reference_dt: teacher.reference_dt().unwrap_or(0.0),
        rate_input: teacher.rate_input(),
    };
    if width != layout.input() || width != teacher.mlp().spec().input {
        return Err(TrainError::Invalid(format!(
            "packed inputs of {width} values for latent size {k}, {bc} signal numbers and {colliders} collider slots"
        )));
    }
    // A timed teacher's increments scale with the frame time (the input's last number); the
    // student's normalisation is fitted at the reference frame time, as its own training's.
    let reference = teacher.reference_dt();
    let increments = |qs: &[Vec<f32>]| -> TrainResult<Vec<Vec<f32>>> {
        qs.iter()
            .map(|q| {
                let scale = match (reference, q.last()) {
                    (Some(r), Some(&dt)) => (dt as f64 / r) as f32,
                    _ => 1.0,
                };
                Ok(teach(q)?.iter().zip(q).map(|(z, p)| (z - p) / scale).collect())
            })
            .collect()
    };
    let read = network_inputs(&inputs, k, reference.filter(|_| teacher.rate_input()));
    let input_norm = Normalisation::fit(&read).map_err(|e| TrainError::Invalid(e.to_string()))?;
    let increment_norm = Normalisation::fit(&increments(&inputs)?).map_err(|e| TrainError::Invalid(e.to_string()))?;
    let spec = layout;
    let inverse: Vec<f32> = increment_norm.std.iter().map(|s| 1.0 / s).collect();
    let inverse = Tensor::from_vec(inverse, (1, k), &Device::Cpu)?;
    let student = LatentIntegrator::new(spec, input_norm, increment_norm, config.seed)
        .map_err(|e| TrainError::Invalid(e.to_string()))?;
    let mut losses = Vec::new();
    for round in 0..=shape.rounds {
        if round > 0 {
            let current = student.export().map_err(|e| TrainError::Invalid(e.to_string()))?;
            let step = |q: &[f32]| current.step(q).map_err(|e| TrainError::Invalid(e.to_string()));
            inputs.extend(rollout(&step)?);
        }
        let rows: Vec<Vec<f32>> = inputs
            .iter()
            .map(|q| {
                let mut row = q.clone();
                row.extend(teach(q)?);
                Ok(row)
            })
            .collect::<TrainResult<_>>()?;
        let round_config = TrainConfig {
            name: format!("{}-round-{round}", config.name),
            ..config.clone()
        };
        let report = train::train(&student.parameters(), &rows, &round_config, false, |batch, _| {
            let q = batch.inputs.narrow(1, 0, width)?;
            let target = batch.inputs.narrow(1, width, k)?;
            BatchLoss::new(
                (student.forward(&q)? - target)?
                    .broadcast_mul(&inverse)?
                    .sqr()?
                    .mean_all()?,
            )
        })?;
        losses.push(report.losses.last().copied().unwrap_or(f64::NAN));
    }
    Ok(DistilledIntegrator {
        integrator: student.export().map_err(|e| TrainError::Invalid(e.to_string()))?,
        losses,
        inputs: inputs.len(),
    })
}
