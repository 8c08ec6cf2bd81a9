//! Vertex Block Descent ([`crate::vbd`]) as the simulator's time stepper: the same
//! implicit-Euler incremental potential as Newton's (the inertia term around `x + dt v`, the
//! potentials weighted by `dt^2`), minimised by a fixed number of VBD iterations.

use super::{check_targets, incremental_potential, place_fixed, Simulator, StepError, StepReport, TimeScheme};
use crate::energy::{self, StencilEnergy};
use crate::vbd::{initial_guess, VbdSettings, VertexBlockDescent, WeightedTerm};
use std::fmt;
use std::time::Instant;

/// Why a simulator cannot step with VBD.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VbdUnsupported {
    /// It has IPC contact, which VBD does not handle.
    Contact,
    /// Its time scheme is not implicit Euler.
    Scheme(TimeScheme),
}

impl fmt::Display for VbdUnsupported {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            VbdUnsupported::Contact => write!(
                f,
                "the vbd solver does not handle IPC contact; remove [contact] or use the full-space solver"
            ),
            VbdUnsupported::Scheme(s) => write!(
                f,
                "the vbd solver steps implicit Euler only, not {s:?}; set integrator = \"implicit-euler\""
            ),
        }
    }
}

impl Simulator {
    /// Steps with Vertex Block Descent instead of Newton (static solves, such as a scene's
    /// equilibrium start, still use Newton). Refused with IPC contact and with a time scheme
    /// other than implicit Euler.
    pub fn with_vbd(mut self, settings: VbdSettings) -> Result<Self, VbdUnsupported> {
        if self.contact.is_some() {
            return Err(VbdUnsupported::Contact);
        }
        if self.integrator != TimeScheme::ImplicitEuler {
            return Err(VbdUnsupported::Scheme(self.integrator));
        }
        let mut free = vec![true; self.x.len() / self.dim];
        for &v in &self.fixed_vertices {
            free[v] = false;
        }
        let terms: Vec<&dyn StencilEnergy> = std::iter::once(&self.inertia as &dyn StencilEnergy)
            .chain(self.potentials.iter().map(|p| p.as_ref()))
            .collect();
        self.vbd = Some(VertexBlockDescent::new(settings, self.dim, &terms, &free));
        Ok(self)
    }

    /// The VBD stepper, if attached.
    pub fn vbd(&self) -> Option<&VertexBlockDescent> {
        self.vbd.as_ref()
    }

    /// Each vertex's external acceleration: the force of the constant-force terms (gravity
    /// and loads, the terms named `gravity` and `load`) over its mass; 0 where massless.
    fn external_acceleration(&self) -> Vec<f64> {
        let mut a = vec![0.0; self.x.len()];
        for p in self
            .potentials
            .iter()
            .filter(|p| matches!(p.name(), "gravity" | "load"))
        {
            energy::add_gradient_sequential(p.as_ref(), -1.0, &self.x, &mut a);
        }
        for (ai, &m) in a.chunks_exact_mut(self.dim).zip(self.inertia.masses()) {
            ai.iter_mut().for_each(|c| *c = if m > 0.0 { *c / m } else { 0.0 });
        }
        a
    }

    /// One implicit-Euler step by VBD with the prescribed vertices at `targets`, with
    /// `iterations` sweeps (the settings' count when `None`).
    pub(super) fn step_vbd(&mut self, targets: &[f64], iterations: Option<usize>) -> Result<StepReport, StepError> {
        check_targets(&self.fixed_vertices, self.dim, targets)?;
        let start = Instant::now();
        let h = self.dt;
        let xhat: Vec<f64> = self.x.iter().zip(&self.v).map(|(x, v)| x + h * v).collect();
        self.inertia.set_target(&xhat);
        let a_ext = self.external_acceleration();
        let Some(vbd) = &self.vbd else {
            unreachable!("step_vbd without a VBD stepper");
        };
        let mode = vbd.settings().initial_guess;
        let mut x = initial_guess(mode, self.dim, h, &self.x, &self.v, &self.v_prev, &a_ext);
        place_fixed(&self.fixed_vertices, self.dim, &mut x, targets);
        let weight = h * h;
        let terms: Vec<WeightedTerm> = std::iter::once((&self.inertia as &dyn StencilEnergy, 1.0))
            .chain(self.potentials.iter().map(|p| (p.as_ref(), weight)))
            .collect();
        let frame = self.steps + 1;
        let solve = vbd
            .solve(&terms, &mut x, h * self.length_scale, iterations)
            .map_err(|iteration| StepError::Diverged { frame, iteration })?;
        let objective = incremental_potential(&self.inertia, &self.potentials, 1.0, weight, &x, None);
        let last = solve.step_norms.last().copied().unwrap_or(0.0);
        let report = StepReport {
            iterations: solve.step_norms.len(),
            converged: last < self.settings.tolerance,
            objective,
            step_norms: solve.step_norms,
            ..StepReport::default()
        };
        let v_new: Vec<f64> = x.iter().zip(&self.x).map(|(a, b)| (a - b) / h).collect();
        self.x_prev = std::mem::replace(&mut self.x, x);
        self.v_prev = std::mem::replace(&mut self.v, v_new);
        self.steps += 1;
        Ok(StepReport {
            seconds: start.elapsed().as_secs_f64(),
            ..report
        })
    }

    /// One VBD step with `iterations` sweeps instead of the settings' count (for
    /// convergence studies). Needs [`Simulator::with_vbd`].
    pub fn step_vbd_with(&mut self, targets: &[f64], iterations: usize) -> Result<StepReport, StepError> {
        assert!(self.vbd.is_some(), "step_vbd_with needs with_vbd");
        self.step_vbd(targets, Some(iterations))
    }
}
