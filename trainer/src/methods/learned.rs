//! The learned integrator as the runtime steps it (`mochi-runtime`'s instance, one thread):
//! a [`Method`] over a validated model in any weight storage. Its cost is the runtime's step
//! and full decode, and its multiply-adds are the networks' (plus a strand walk for
//! bend-encoded rods).

use mochi_runtime::collider::ColliderState;
use mochi_runtime::{AnyInstance, HandleMotion, ValidModel, SIGNAL_PER_HANDLE};
use mochi_sim::bc::BcSequence;

use super::method::{Method, StepCost};
use crate::error::{TrainerError, TrainerResult};
use crate::learn::encoding::collider_state;

/// A model stepped by the runtime.
pub struct LearnedRuntime<'m> {
    family: String,
    setting: String,
    model: &'m ValidModel<'m>,
    body: AnyInstance,
    dt: f32,
    multiply_adds: f64,
    x32: Vec<f32>,
    x: Vec<f64>,
}

impl<'m> LearnedRuntime<'m> {
    /// `model` in the runtime, reported as `family` at `setting` (e.g. "k=8, int8").
    pub fn new(model: &'m ValidModel<'m>, family: &str, setting: String) -> TrainerResult<Self> {
        let m = model.model();
        let body = AnyInstance::new(model).map_err(|e| TrainerError::invalid(format!("runtime instance: {e:?}")))?;
        Ok(LearnedRuntime {
            family: family.into(),
            setting,
            multiply_adds: (mochi_runtime::network::multiply_adds(m.integrator)
                + mochi_runtime::network::multiply_adds(m.decoder)
                + m.walk_multiply_adds()) as f64,
            model,
            body,
            dt: m.dt,
            x32: vec![0.0; m.state_len()],
            x: vec![0.0; m.state_len()],
        })
    }

    /// The same, stepping frames of `dt` seconds (a model that takes the frame time as an
    /// input, `mochi_runtime::Model::timed`; any other refuses every step at another).
    pub fn at_frame_time(mut self, dt: f64) -> Self {
        self.dt = dt as f32;
        self
    }

    fn decode(&mut self) -> TrainerResult<()> {
        self.body
            .decode_into(self.model, &mut self.x32)
            .map_err(|e| TrainerError::invalid(format!("runtime decode refused: {e:?}")))?;
        self.x.iter_mut().zip(&self.x32).for_each(|(x, &v)| *x = v as f64);
        Ok(())
    }
}

impl Method for LearnedRuntime<'_> {
    fn family(&self) -> String {
        self.family.clone()
    }

    fn setting(&self) -> String {
        self.setting.clone()
    }

    fn reset(&mut self, _bc: &BcSequence) -> TrainerResult<()> {
        self.body =
            AnyInstance::new(self.model).map_err(|e| TrainerError::invalid(format!("runtime instance: {e:?}")))?;
        self.decode()
    }

    fn step(&mut self, bc: &BcSequence, frame: usize) -> TrainerResult<StepCost> {
        let motion = motions(bc, frame);
        let colliders = collider_states(bc, frame, self.model.model().colliders());
        let clock = super::clock::Stopwatch::start();
        self.body
            .step_with(self.model, &motion, &colliders, self.dt)
            .map_err(|e| TrainerError::invalid(format!("runtime step refused: {e:?}")))?;
        self.body
            .decode_into(self.model, &mut self.x32)
            .map_err(|e| TrainerError::invalid(format!("runtime decode refused: {e:?}")))?;
        let seconds = clock.seconds();
        self.x.iter_mut().zip(&self.x32).for_each(|(x, &v)| *x = v as f64);
        Ok(StepCost {
            seconds,
            iterations: f64::NAN,
            multiply_adds: self.multiply_adds,
        })
    }

    fn positions(&self) -> &[f64] {
        &self.x
    }
}

/// The handle motions of frame `t` of `bc`, as the runtime takes them.
pub fn motions(bc: &BcSequence, t: usize) -> Vec<HandleMotion> {
    bc.signal(t)
        .chunks_exact(SIGNAL_PER_HANDLE)
        .map(|c| {
            let mut s = [0.0f32; SIGNAL_PER_HANDLE];
            s.iter_mut().zip(c).for_each(|(s, &v)| *s = v as f32);
            HandleMotion::from_signal(&s)
        })
        .collect()
}

/// The states of the first `slots` colliders of `bc` at frame `t`, as the runtime takes them.
pub fn collider_states(bc: &BcSequence, t: usize, slots: usize) -> Vec<ColliderState> {
    let states = bc.collider_states(t);
    states
        .chunks_exact(mochi_sim::bc::colliders::STATE_PER_COLLIDER)
        .take(slots)
        .map(collider_state)
        .collect()
}
