//! `mochi distill`: writes a model whose decoder is distilled into a small MLP before a
//! linear basis ([`crate::pipeline::distill`]), and optionally its integrator into a narrower
//! one, and says how closely it follows the original.

use std::path::Path;

use crate::artifact::Artifact;
use crate::error::TrainerResult;
use crate::learn::distill::DistillShape;
use crate::learn::distill_integrator::IntegratorDistillShape;
use crate::pipeline::distill::{distill_artifact, distill_artifact_integrator, DistillOptions};

/// What `mochi distill` replaces besides (or instead of) the decoder.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IntegratorChoice {
    /// Keep the decoder as it is (distil only the integrator).
    pub keep_decoder: bool,
    /// Distil the integrator into this shape (`None`: keep it).
    pub integrator: Option<IntegratorDistillShape>,
    /// Frames of each rollout of the integrator's fit (`None`: the scene's dataset frames).
    pub frames: Option<usize>,
}

/// [`run`], then the integrator as `choice` says.
pub fn run_with(
    path: &Path,
    out: &Path,
    shape: DistillShape,
    epochs: usize,
    choice: IntegratorChoice,
) -> TrainerResult<()> {
    let temporary = out.with_extension("decoder.mochi");
    let source = if choice.keep_decoder {
        path.to_path_buf()
    } else {
        run(path, &temporary, shape.modes, shape.hidden, shape.blocks, epochs)?;
        temporary.clone()
    };
    let Some(integrator) = choice.integrator else {
        if !choice.keep_decoder {
            std::fs::rename(&temporary, out).map_err(|e| crate::error::TrainerError::io(out, e))?;
        }
        return Ok(());
    };
    let artifact = Artifact::read(&source)?;
    let options = DistillOptions {
        epochs,
        frames: choice.frames,
        progress: true,
        ..DistillOptions::default()
    };
    let (student, distilled) = distill_artifact_integrator(&artifact, integrator, &options)?;
    student.write(out)?;
    if !choice.keep_decoder {
        let _ = std::fs::remove_file(&temporary);
    }
    println!(
        "{} -> {}: integrator of width {} ({} blocks) distilled on {} rollout inputs over {} rounds (last losses {:?})",
        source.display(),
        out.display(),
        integrator.hidden,
        integrator.blocks,
        distilled.inputs,
        integrator.rounds,
        distilled.losses,
    );
    Ok(())
}

/// Distils the decoder of the artifact at `path` into `modes` basis columns after an MLP of
/// width `hidden` with `blocks` blocks, trained for `epochs` epochs; writes the model to `out`.
pub fn run(path: &Path, out: &Path, modes: usize, hidden: usize, blocks: usize, epochs: usize) -> TrainerResult<()> {
    let artifact = Artifact::read(path)?;
    let options = DistillOptions {
        shape: DistillShape { modes, hidden, blocks },
        epochs,
        progress: true,
        ..DistillOptions::default()
    };
    let outcome = distill_artifact(&artifact, &options)?;
    outcome.artifact.write(out)?;
    let last = outcome.distilled.losses.last().copied().unwrap_or(f64::NAN);
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
    Ok(())
}
