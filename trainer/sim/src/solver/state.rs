//! A simulator's state between steps, to take and restore, so two solvers can step from
//! the same state (e.g. the adaptive solver against full space, step by step).

use super::Simulator;

/// Everything a [`Simulator`] carries from one step to the next.
#[derive(Clone, Debug, PartialEq)]
pub struct SimState {
    x: Vec<f64>,
    v: Vec<f64>,
    x_prev: Vec<f64>,
    v_prev: Vec<f64>,
    steps: usize,
    contact: Option<super::contact::Carried>,
}

impl SimState {
    /// Positions.
    pub fn positions(&self) -> &[f64] {
        &self.x
    }
}

impl Simulator {
    /// The state between steps: positions and velocities (with the previous ones BDF2
    /// uses), the step count, and contact's obstacle positions, collider poses and barrier
    /// stiffness.
    pub fn state(&self) -> SimState {
        SimState {
            x: self.x.clone(),
            v: self.v.clone(),
            x_prev: self.x_prev.clone(),
            v_prev: self.v_prev.clone(),
            steps: self.steps,
            contact: self.contact.as_ref().map(|c| c.carried()),
        }
    }

    /// Continues from `state` (taken from a simulator of the same scene); a state of
    /// another body size is ignored and returns false.
    pub fn set_state(&mut self, state: &SimState) -> bool {
        if state.x.len() != self.x.len() {
            return false;
        }
        self.x.clone_from(&state.x);
        self.v.clone_from(&state.v);
        self.x_prev.clone_from(&state.x_prev);
        self.v_prev.clone_from(&state.v_prev);
        self.steps = state.steps;
        if let (Some(c), Some(carried)) = (&mut self.contact, &state.contact) {
            c.restore(carried.clone());
        }
        true
    }
}
