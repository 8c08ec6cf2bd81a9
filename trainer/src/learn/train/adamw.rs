//! AdamW with its state open to checkpoints (Loshchilov & Hutter: Adam with decoupled weight
//! decay).

use candle_core::backprop::GradStore;
use candle_core::{Tensor, Var};

use super::{TrainError, TrainResult};

/// AdamW settings (Loshchilov & Hutter: Adam with decoupled weight decay).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdamWConfig {
    /// Learning rate (the paper uses 1e-4 for both networks).
    pub lr: f64,
    /// Decay of the first-moment average.
    pub beta1: f64,
    /// Decay of the second-moment average.
    pub beta2: f64,
    /// Added to the root of the second moment.
    pub eps: f64,
    /// Decoupled weight decay per unit learning rate (0 makes this plain Adam).
    pub weight_decay: f64,
}

impl Default for AdamWConfig {
    /// lr 1e-4 (paper), betas (0.9, 0.999), eps 1e-8, no weight decay.
    fn default() -> Self {
        AdamWConfig {
            lr: 1e-4,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            weight_decay: 0.0,
        }
    }
}

/// One parameter and its AdamW moments. The moments are plain vectors and the update is one
/// fused loop over them: about four times faster than composing it from candle tensor ops,
/// each of which allocates a parameter-sized tensor.
#[derive(Debug)]
pub(super) struct Slot {
    pub(super) name: String,
    pub(super) param: Var,
    pub(super) m: Vec<f32>,
    pub(super) v: Vec<f32>,
}

/// AdamW over named candle variables, with its state open to checkpoints.
#[derive(Debug)]
pub struct AdamW {
    config: AdamWConfig,
    pub(super) step: u64,
    pub(super) slots: Vec<Slot>,
}

impl AdamW {
    /// An optimiser for `params` (unique names, f32 variables), with zero moments.
    pub fn new(params: &[(String, Var)], config: AdamWConfig) -> TrainResult<Self> {
        let mut slots: Vec<Slot> = Vec::with_capacity(params.len());
        for (name, var) in params {
            if slots.iter().any(|s| &s.name == name) {
                return Err(TrainError::Invalid(format!("parameter `{name}` is listed twice")));
            }
            if var.dtype() != candle_core::DType::F32 {
                return Err(TrainError::Invalid(format!("parameter `{name}` is not f32")));
            }
            slots.push(Slot {
                name: name.clone(),
                param: var.clone(),
                m: vec![0.0; var.elem_count()],
                v: vec![0.0; var.elem_count()],
            });
        }
        Ok(AdamW { config, step: 0, slots })
    }

    /// Changes the learning rate of the following steps.
    pub fn set_lr(&mut self, lr: f64) {
        self.config.lr = lr;
    }

    /// One update from the gradients of a backward pass (variables without a gradient are left
    /// alone, their moments too):
    /// `m = b1 m + (1-b1) g`, `v = b2 v + (1-b2) g^2`,
    /// `p = p (1 - lr wd) - lr (m / (1-b1^t)) / (sqrt(v / (1-b2^t)) + eps)`.
    pub fn step(&mut self, grads: &GradStore) -> candle_core::Result<()> {
        self.step += 1;
        let AdamWConfig {
            lr,
            beta1,
            beta2,
            eps,
            weight_decay,
        } = self.config;
        let t = i32::try_from(self.step).unwrap_or(i32::MAX);
        let m_scale = (1.0 / (1.0 - beta1.powi(t))) as f32;
        let v_scale = (1.0 / (1.0 - beta2.powi(t))) as f32;
        let decay = (1.0 - lr * weight_decay) as f32;
        let (b1, b2, eps, lr) = (beta1 as f32, beta2 as f32, eps as f32, lr as f32);
        for slot in &mut self.slots {
            let Some(g) = grads.get(slot.param.as_tensor()) else {
                continue;
            };
            let g = g.flatten_all()?.to_vec1::<f32>()?;
            let param = slot.param.as_tensor();
            let mut p = param.flatten_all()?.to_vec1::<f32>()?;
            for (((p, m), v), g) in p.iter_mut().zip(&mut slot.m).zip(&mut slot.v).zip(&g) {
                *m = b1 * *m + (1.0 - b1) * g;
                *v = b2 * *v + (1.0 - b2) * g * g;
                *p = *p * decay - lr * (*m * m_scale) / ((*v * v_scale).sqrt() + eps);
            }
            slot.param.set(&Tensor::from_vec(p, param.shape(), param.device())?)?;
        }
        Ok(())
    }
}
