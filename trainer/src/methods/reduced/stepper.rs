//! The reduced method as a stepper: one solve of Eq. 2 per frame, warm-started at the last
//! latent, with the handles placed by the boundary-condition script.
//!
//! With warm starts (the default), L-BFGS begins each step from the previous step's
//! curvature pairs; [`ReducedStepper::reset`] forgets them.
//!
//! Dynamic scenes step implicit Euler inside the subspace (`xhat = x_t + dt v_t`, velocities
//! from consecutive decoded states); quasi-static scenes minimise the potential alone each
//! frame. The objective is scaled by `dt^2 / (M L^2)` (`M` the total mass, `L` the rest
//! diagonal), so the gradient tolerance is unit-free: a step ends once the remaining
//! generalised force moves the body by a tolerance's fraction of its diagonal per step.
//!
//! [`ReducedSolver::PaperLbfgs`] runs the paper's solver ([`super::paper`]) on the paper
//! code's own objective, Eq. 2 times `dt^2` (`1/2 |x - xhat|_M^2 + dt^2 P`; `dt^2 P` for
//! quasi-statics), so its tolerance and its absolute `ftol` apply to the raw objective as
//! there, in the scene's units.

use mochi_sim::energy::StencilEnergy;
use mochi_sim::BuiltScene;

use super::lbfgs::{lbfgs, LbfgsWorkspace};
use super::newton::{newton, NewtonWorkspace};
use super::objective::{InertiaTerm, ObjectiveBuffers, ReducedObjective};
use super::optimize::{SolveReport, SolveSettings};
use super::paper::paper_lbfgs;
use super::subspace::DecoderSubspace;
use crate::error::{TrainerError, TrainerResult};
use crate::learn::encoding::Encoding;

/// The scale `dt^2 / (M L^2)` of the reduced objective (module documentation) for a body of
/// total mass `mass` and rest diagonal `diagonal`.
pub fn objective_scale(mass: f64, diagonal: f64, dt: f64) -> f64 {
    dt * dt / (mass * diagonal * diagonal)
}

/// Which optimiser solves each step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReducedSolver {
    /// L-BFGS with line search (the paper's choice for every result).
    Lbfgs,
    /// Newton on the PSD-projected reduced Hessian, with line search.
    Newton,
    /// L-BFGS as the paper's code runs it ([`super::paper`]), on the unscaled objective
    /// (module documentation).
    PaperLbfgs,
}

impl ReducedSolver {
    /// A name for reports.
    pub fn name(self) -> &'static str {
        match self {
            ReducedSolver::Lbfgs => "L-BFGS",
            ReducedSolver::Newton => "Newton",
            ReducedSolver::PaperLbfgs => "L-BFGS (the paper's)",
        }
    }
}

/// How a [`ReducedStepper`] steps.
#[derive(Clone, Debug)]
pub struct StepperSettings {
    /// The optimiser (default L-BFGS).
    pub solver: ReducedSolver,
    /// Its exits (defaults: the paper's, tolerance 1e-5 on the scaled gradient).
    pub solve: SolveSettings,
    /// Minimise the potential alone each frame (quasi-static) instead of implicit Euler
    /// (default false).
    pub quasi_static: bool,
    /// Keep each step's objective after every iteration in its report (default false).
    pub record_history: bool,
}

impl Default for StepperSettings {
    fn default() -> Self {
        StepperSettings {
            solver: ReducedSolver::Lbfgs,
            solve: SolveSettings::default(),
            quasi_static: false,
            record_history: false,
        }
    }
}

/// A body stepped by the reduced solver in a decoder's subspace.
pub struct ReducedStepper {
    subspace: DecoderSubspace,
    encoding: Encoding,
    inertia: InertiaTerm,
    settings: StepperSettings,
    dt: f64,
    scale: f64,
    z: Vec<f64>,
    x: Vec<f64>,
    v: Vec<f64>,
    xhat: Vec<f64>,
    buffers: ObjectiveBuffers,
    lbfgs: LbfgsWorkspace,
    newton: NewtonWorkspace,
}

impl ReducedStepper {
    /// A stepper in `subspace` (built with `encoding`), for a body of vertex `masses`, rest
    /// diagonal `diagonal` and time step `dt`, starting at rest at latent `z0` with the
    /// handles at `targets`.
    pub fn new(
        subspace: DecoderSubspace,
        encoding: Encoding,
        masses: Vec<f64>,
        diagonal: f64,
        dt: f64,
        settings: StepperSettings,
    ) -> TrainerResult<Self> {
        let total_mass: f64 = masses.iter().sum();
        if !(total_mass > 0.0 && diagonal > 0.0 && dt > 0.0) {
            return Err(TrainerError::invalid(format!(
                "reduced solver: needs a positive total mass ({total_mass}), diagonal ({diagonal}) and time step ({dt})"
            )));
        }
        let n = subspace.state_len();
        let r = subspace.latent_len();
        Ok(ReducedStepper {
            inertia: InertiaTerm::new(subspace.dim(), masses, dt),
            encoding,
            dt,
            scale: match settings.solver {
                ReducedSolver::PaperLbfgs => dt * dt,
                _ => objective_scale(total_mass, diagonal, dt),
            },
            z: vec![0.0; r],
            x: vec![0.0; n],
            v: vec![0.0; n],
            xhat: vec![0.0; n],
            buffers: ObjectiveBuffers::new(n, r),
            lbfgs: LbfgsWorkspace::new(r, settings.solve.memory),
            newton: NewtonWorkspace::new(r),
            settings,
            subspace,
        })
    }

    /// The scale of the objective (module documentation): `dt^2 / (M L^2)`, or `dt^2` for
    /// the paper's solver.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// Puts the body at rest at latent `z` with the handles at `targets`.
    pub fn reset(&mut self, z: &[f64], targets: &[f64]) -> TrainerResult<()> {
        if z.len() != self.z.len() {
            return Err(TrainerError::invalid(format!(
                "reduced solver: a latent of {} values for a subspace of {}",
                z.len(),
                self.z.len()
            )));
        }
        self.place_handles(targets)?;
        self.z.copy_from_slice(z);
        self.subspace.positions(&self.z, &mut self.x)?;
        self.v.fill(0.0);
        self.lbfgs.forget();
        Ok(())
    }

    /// Solves the static problem (the potential alone) with the handles at `targets`, from
    /// the current latent, and puts the body at rest there.
    pub fn settle(&mut self, potentials: &[&dyn StencilEnergy], targets: &[f64]) -> TrainerResult<SolveReport> {
        self.place_handles(targets)?;
        let report = self.solve(potentials, false)?;
        self.subspace.positions(&self.z, &mut self.x)?;
        self.v.fill(0.0);
        Ok(report)
    }

    /// Advances one frame with the handles at `targets`.
    pub fn step(&mut self, potentials: &[&dyn StencilEnergy], targets: &[f64]) -> TrainerResult<SolveReport> {
        self.place_handles(targets)?;
        let dynamic = !self.settings.quasi_static;
        if dynamic {
            for ((p, x), v) in self.xhat.iter_mut().zip(&self.x).zip(&self.v) {
                *p = x + self.dt * v;
            }
            self.inertia.set_prediction(&self.xhat);
        }
        let report = self.solve(potentials, dynamic)?;
        // The new state and velocity; `xhat` holds the old state meanwhile.
        self.xhat.copy_from_slice(&self.x);
        self.subspace.positions(&self.z, &mut self.x)?;
        for ((v, x), old) in self.v.iter_mut().zip(&self.x).zip(&self.xhat) {
            *v = (x - old) / self.dt;
        }
        Ok(report)
    }

    /// As [`ReducedStepper::step`], keeping the objective after every iteration in the
    /// report whatever the settings say.
    pub fn step_recorded(&mut self, potentials: &[&dyn StencilEnergy], targets: &[f64]) -> TrainerResult<SolveReport> {
        let keep = std::mem::replace(&mut self.settings.record_history, true);
        let report = self.step(potentials, targets);
        self.settings.record_history = keep;
        report
    }

    /// The current latent.
    pub fn latent(&self) -> &[f64] {
        &self.z
    }

    /// The current world state.
    pub fn positions(&self) -> &[f64] {
        &self.x
    }

    fn place_handles(&mut self, targets: &[f64]) -> TrainerResult<()> {
        let frame = self.encoding.frame(targets)?;
        self.subspace.set_frame(&frame, targets);
        Ok(())
    }

    fn solve(&mut self, potentials: &[&dyn StencilEnergy], dynamic: bool) -> TrainerResult<SolveReport> {
        let inertia = dynamic.then_some(&self.inertia);
        let mut objective =
            ReducedObjective::new(&mut self.subspace, potentials, inertia, self.scale, &mut self.buffers)
                .with_rounding(self.settings.solve.rounding);
        let record = self.settings.record_history;
        let report = match self.settings.solver {
            ReducedSolver::Lbfgs => lbfgs(
                &mut objective,
                &mut self.z,
                &self.settings.solve,
                &mut self.lbfgs,
                record,
            ),
            ReducedSolver::Newton => newton(
                &mut objective,
                &mut self.z,
                &self.settings.solve,
                &mut self.newton,
                record,
            ),
            ReducedSolver::PaperLbfgs => paper_lbfgs(
                &mut objective,
                &mut self.z,
                &self.settings.solve,
                &mut self.lbfgs,
                record,
            ),
        };
        if !self.z.iter().all(|v| v.is_finite()) {
            return Err(TrainerError::invalid("reduced solver: the latent is no longer finite"));
        }
        Ok(report)
    }
}

/// The reduced solver's objective scale for `problem`'s body.
pub(crate) fn scene_objective_scale(problem: &BuiltScene) -> f64 {
    let mass: f64 = problem.simulator.masses().iter().sum();
    objective_scale(mass, problem.mesh.rest_diagonal(), problem.scene.dt)
}
