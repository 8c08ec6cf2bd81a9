//! `mochi distill`: writes a model whose decoder is distilled into a small MLP before a
//! linear basis ([`crate::pipeline::distill`]) and says how closely it follows the original.

use std::path::Path;

use crate::artifact::Artifact;
use crate::error::TrainerResult;
use crate::learn::distill::DistillShape;
use crate::pipeline::distill::{distill_artifact, DistillOptions};

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
