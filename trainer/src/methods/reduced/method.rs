//! The reduced solver as a [`Method`]: a [`ReducedStepper`] in one decoder's subspace,
//! rebuilt at every reset (the scene's start, settled when the scene starts in static
//! equilibrium), stepping with the energies it is given (the scene's exact ones, or the
//! elastic terms through runtime cubature).

use mochi_sim::bc::BcSequence;
use mochi_sim::energy::StencilEnergy;
use mochi_sim::scene::Start;
use mochi_sim::BuiltScene;

use super::stepper::{ReducedStepper, StepperSettings};
use super::subspace::{DecoderSubspace, SubspaceDecoder};
use crate::error::TrainerResult;
use crate::learn::encoding::Encoding;
use crate::methods::method::{Method, StepCost};

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
        }
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
        Ok(())
    }

    fn step(&mut self, bc: &BcSequence, frame: usize) -> TrainerResult<StepCost> {
        let targets = bc.targets(&self.problem.handles, frame, self.problem.mesh.dim);
        let stepper = self
            .stepper
            .as_mut()
            .ok_or_else(|| crate::error::TrainerError::invalid("reduced solver: stepped before a reset"))?;
        let report = stepper.step(&self.potentials, &targets)?;
        Ok(StepCost::iterated(f64::NAN, report.iterations as f64))
    }

    fn positions(&self) -> &[f64] {
        self.stepper.as_ref().map_or(&[], |s| s.positions())
    }
}
