//! `mochi distill`: writes a model whose decoder is distilled into a small MLP before a
//! linear basis ([`crate::pipeline::distill`]), and optionally its integrator into a narrower
//! one, and says how closely it follows the original.

use std::path::Path;

use crate::artifact::Artifact;
use crate::error::{TrainerError, TrainerResult};
use crate::learn::distill::DistillShape;
use crate::learn::distill_integrator::IntegratorDistillShape;
use crate::pipeline::distill::{distill_artifact, distill_artifact_integrator, DistillOptions};

/// What `mochi distill` replaces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DistillChoice {
    /// Distil the decoder into this shape (`None`: keep it).
    pub decoder: Option<DistillShape>,
    /// Distil the integrator into this shape, after the decoder (`None`: keep it).
    pub integrator: Option<IntegratorDistillShape>,
    /// Frames of each rollout over a training motion, for every fit (`None`: the scene's
    /// dataset frames).
    pub frames: Option<usize>,
    /// Fit the decoder to rod strands as positions ([`DistillOptions::strand_positions`]).
    pub strand_positions: bool,
}

/// Distils what `choice` names of the artifact at `path`, each fit trained for `epochs`
/// epochs, and writes the model to `out`; says how closely each part follows the original.
pub fn run(path: &Path, out: &Path, choice: DistillChoice, epochs: usize) -> TrainerResult<()> {
    if choice.decoder.is_none() && choice.integrator.is_none() {
        return Err(TrainerError::invalid(
            "nothing to distil: the decoder is kept and no integrator width is given (--integrator)",
        ));
    }
    let mut artifact = Artifact::read(path)?;
    let options = DistillOptions {
        epochs,
        frames: choice.frames,
        strand_positions: choice.strand_positions,
        progress: true,
        ..DistillOptions::default()
    };
    if let Some(shape) = choice.decoder {
        let outcome = distill_artifact(
            &artifact,
            &DistillOptions {
                shape,
                ..options.clone()
            },
        )?;
        let last = outcome.distilled.losses.last().copied().unwrap_or(f64::NAN);
        let DistillShape { modes, hidden, blocks } = shape;
        let plural = if blocks == 1 { "" } else { "s" };
        println!(
            "{} -> {}: decoder of {modes} modes after an MLP of width {hidden} ({blocks} block{plural}), fitted on {} rollout latents (last loss {last:.3e}); on {} held-out latents the RMS vertex distance to the original decoder is {:.3e} of the diagonal ({:.3e} from the basis alone)",
            path.display(),
            out.display(),
            outcome.latents.0,
            outcome.latents.1,
            outcome.fit_error,
            outcome.basis_error,
        );
        if let Some(rms) = outcome.encoder_error {
            println!("rod strands now decoded as positions; the encoder fitted to them is {rms:.3e} (RMS) from the held-out latents");
        }
        artifact = outcome.artifact;
    }
    if let Some(shape) = choice.integrator {
        let (student, distilled) = distill_artifact_integrator(&artifact, shape, &options)?;
        println!(
            "{} -> {}: integrator of width {} ({} blocks) distilled on {} rollout inputs over {} rounds (last losses {:?})",
            path.display(),
            out.display(),
            shape.hidden,
            shape.blocks,
            distilled.inputs,
            shape.rounds,
            distilled.losses,
        );
        artifact = student;
    }
    artifact.write(out)?;
    Ok(())
}
