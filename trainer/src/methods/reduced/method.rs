//! The reduced solver as a [`Method`]: a [`ReducedStepper`] in one decoder's subspace,
//! rebuilt at every reset (the scene's start, settled when the scene starts in static
//! equilibrium), stepping with the energies it is given (the scene's exact ones, or the
//! elastic terms through runtime cubature). Beyond a step's cost it keeps a [`SolveLog`] of the
//! sequence: how the solves ended, the convergence of one step, the latents it visited.

use mochi_sim::bc::BcSequence;
use mochi_sim::energy::StencilEnergy;
use mochi_sim::scene::Start;
use mochi_sim::BuiltScene;

use super::optimize::ExitCounts;
use super::stepper::{ReducedStepper, StepperSettings};
use super::subspace::{DecoderSubspace, SubspaceDecoder};
use crate::error::TrainerResult;
use crate::learn::encoding::Encoding;
use crate::methods::lipschitz::loss::LatentSample;
use crate::methods::method::{Method, StepCost};

/// The frame whose solve keeps the objective after every iteration (the convergence chart).
pub const CONVERGENCE_FRAME: usize = 10;
/// Every how many frames the latent is kept in [`SolveLog::visited`].
pub const VISITED_EVERY: usize = 10;

/// What the solves of one sequence did, beyond each step's [`StepCost`].
#[derive(Clone, Debug, Default)]
pub struct SolveLog {
    /// How the solves ended.
    pub exits: ExitCounts,
    /// Objective evaluations, line-search trials included, over all steps.
    pub evaluations: usize,
    /// Sum over steps of the gradient's infinity norm where each solve stopped.
    pub exit_gradients: f64,
    /// The objective after each iteration of frame [`CONVERGENCE_FRAME`]'s solve.
    pub convergence: Vec<f64>,
    /// The latent and handle targets of every [`VISITED_EVERY`]-th frame.
    pub visited: Vec<LatentSample>,
}

/// One subspace stepped by the reduced solver.
pub struct ReducedMethod<'a> {
    family: String,
    setting: String,
    problem: &'a BuiltScene,
    decoder: SubspaceDecoder<'a>,
    initial_latent: &'a [f64],
    encoding: &'a Encoding,
    potentials: Vec<&'a dyn StencilEnergy>,
    settings: StepperSettings,
    dt: f64,
    stepper: Option<ReducedStepper>,
    log: SolveLog,
}

impl<'a> ReducedMethod<'a> {
    /// The subspace of `decoder` (built with `encoding`, starting at `initial_latent`) on
    /// `problem`'s body with `potentials`, time step `dt` (the scene's, or another one at run
    /// time), reported as `family` at `setting`.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        family: String,
        setting: String,
        problem: &'a BuiltScene,
        decoder: impl Into<SubspaceDecoder<'a>>,
        initial_latent: &'a [f64],
        encoding: &'a Encoding,
        potentials: Vec<&'a dyn StencilEnergy>,
        settings: StepperSettings,
        dt: f64,
    ) -> Self {
        ReducedMethod {
            family,
            setting,
            problem,
            decoder: decoder.into(),
            initial_latent,
            encoding,
            potentials,
            settings,
            dt,
            stepper: None,
            log: SolveLog::default(),
        }
    }

    /// What the solves since the last reset did.
    pub fn log(&self) -> &SolveLog {
        &self.log
    }

    /// The stepper of the current sequence (after a reset).
    pub fn stepper(&self) -> Option<&ReducedStepper> {
        self.stepper.as_ref()
    }
}

impl Method for ReducedMethod<'_> {
    fn family(&self) -> String {
        self.family.clone()
    }

    fn setting(&self) -> String {
        self.setting.clone()
    }

    fn reset(&mut self, bc: &BcSequence) -> TrainerResult<()> {
        let dim = self.problem.mesh.dim;
        let targets0 = bc.targets(&self.problem.handles, 0, dim);
        let subspace = DecoderSubspace::new(self.decoder, self.encoding, &targets0)?;
        let mut stepper = ReducedStepper::new(
            subspace,
            self.encoding.clone(),
            self.problem.simulator.masses().to_vec(),
            self.problem.mesh.rest_diagonal(),
            self.dt,
            self.settings.clone(),
        )?;
        stepper.reset(self.initial_latent, &targets0)?;
        if self.problem.scene.start == Start::Static {
            stepper.settle(&self.potentials, &targets0)?;
        }
        self.stepper = Some(stepper);
        self.log = SolveLog::default();
        Ok(())
    }

    fn step(&mut self, bc: &BcSequence, frame: usize) -> TrainerResult<StepCost> {
        let targets = bc.targets(&self.problem.handles, frame, self.problem.mesh.dim);
        let stepper = self
            .stepper
            .as_mut()
            .ok_or_else(|| crate::error::TrainerError::invalid("reduced solver: stepped before a reset"))?;
        let report = if frame == CONVERGENCE_FRAME {
            stepper.step_recorded(&self.potentials, &targets)?
        } else {
            stepper.step(&self.potentials, &targets)?
        };
        let log = &mut self.log;
        log.exits.add(&report);
        log.evaluations += report.evaluations;
        log.exit_gradients += report.gradient_norm;
        if frame == CONVERGENCE_FRAME {
            log.convergence.clone_from(&report.history);
        }
        if frame.is_multiple_of(VISITED_EVERY) {
            log.visited.push(LatentSample {
                z: stepper.latent().to_vec(),
                targets,
            });
        }
        Ok(StepCost::iterated(f64::NAN, report.iterations as f64))
    }

    fn positions(&self) -> &[f64] {
        self.stepper.as_ref().map_or(&[], |s| s.positions())
    }
}
