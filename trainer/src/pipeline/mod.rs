//! `mochi train`: from a scene's training trajectories to a latent model (Li et al. 2025,
//! Sec. 3.2-3.3), as named stages run in order ([`stages`]): dataset (train
//! split), PCA, a decoder per family of `latent.selection` (each with its latent-size
//! selection), a self-supervised integrator per width on each decoder that meets the
//! tolerance, the selection over cost ([`selection`]), the supervised baseline of the kept
//! model, and the artifacts; then, for scenes with a
//! `[reduced]` table, the reduced method's vanilla and Lipschitz-optimised subspaces
//! ([`reduced`]). Each stage's seconds go into the artifacts' training summary.

pub(crate) mod assemble;
pub mod distill;
pub(crate) mod distilled;
pub(crate) mod measure;
pub(crate) mod plain_vanilla;
pub(crate) mod reduced;
pub(crate) mod selection;
pub(crate) mod stages;
pub(crate) mod training_frames;

use std::path::PathBuf;
use std::time::Instant;

use crate::artifact::reduced::ReducedArtifact;
use crate::artifact::{Artifact, CandidateRow, Method};
use crate::error::{TrainerError, TrainerResult};
use crate::learn::recipe::DecoderCandidate;
use crate::learn::recipe::Recipe;
use crate::learn::samples::IntegratorData;
use crate::progress::Reporter;
use crate::report::candidates_table;
use assemble::Trained;
use stages::{StageTimes, Workspace};

/// Where `mochi train` works.
#[derive(Clone, Debug)]
pub struct TrainOptions {
    /// Output directory: `dataset/`, `checkpoints/` and the artifacts go here.
    pub out_dir: PathBuf,
    /// Continue from checkpoints left by an interrupted run.
    pub resume: bool,
    /// Only try this latent size (instead of the scene's candidates).
    pub latent: Option<usize>,
    /// Bytes of training frames held in memory at most; a larger training split is written
    /// to `frames.f64` in `out_dir` and read back in batches (default [`FRAME_MEMORY`]).
    pub frame_memory: u64,
}

/// The default of [`TrainOptions::frame_memory`]: 4 GiB. A fixed budget, not a share of
/// the machine's memory, so that a scene trains the same way on every machine.
pub const FRAME_MEMORY: u64 = 4 << 30;

/// The two artifacts of a training run.
#[derive(Clone, Debug)]
pub struct TrainOutcome {
    /// Self-supervised model.
    pub model: Artifact,
    /// Supervised baseline (same autoencoder).
    pub baseline: Artifact,
    /// Loss per epoch of the self-supervised and the supervised integrator.
    pub losses: (Vec<f64>, Vec<f64>),
    /// Loss per epoch of the kept autoencoder.
    pub autoencoder_losses: Vec<f64>,
    /// The reduced method's subspaces, for scenes with a `[reduced]` table.
    pub reduced: Option<ReducedArtifact>,
}

/// Runs the whole of `mochi train` for `recipe`: dataset (train split, if missing),
/// latent-size selection, autoencoder, both integrators; writes both artifacts into
/// `options.out_dir` (see [`crate::artifact_paths`]). Stages, measured errors and progress
/// go to `report`.
pub fn train_scene(recipe: &Recipe, options: &TrainOptions, report: &dyn Reporter) -> TrainerResult<TrainOutcome> {
    let problem = &mut recipe.build()?;
    let spec = &recipe.latent;
    let work = Workspace {
        dataset: options.out_dir.join("dataset"),
        frames: options.out_dir.join("frames.f64"),
        frame_memory: options.frame_memory,
        checkpoints: options.out_dir.join("checkpoints"),
        resume: options.resume,
        bars: report.bars(),
    };
    let mut times = StageTimes::default();

    report.stage("dataset (train split)");
    let clock = Instant::now();
    if stages::generate_dataset(problem, &work, report)? > 0 {
        times.record("dataset (train split)", clock);
    }
    let frames = stages::encode_training_split(problem, spec, &work, report)?;

    report.stage("pca");
    let clock = Instant::now();
    let sizes: Vec<usize> = options.latent.map_or(spec.sizes.clone(), |k| vec![k]);
    let diagonal = problem.mesh.rest_diagonal();
    let pca = stages::fit_pca(&frames, &sizes, spec.tolerance, diagonal, report)?;
    times.record("pca", clock);

    let decoders = selection::train_decoders(problem, spec, &frames, &pca, &sizes, &work, &mut times, report)?;
    let validation = selection::validation_split(problem, &work, report)?;
    let inputs = measure::SelectionInputs {
        recipe,
        problem,
        frames: &frames,
        validation: &validation,
        work: &work,
        candidates_dir: &options.out_dir.join("candidates"),
    };
    let (candidates, skipped, kept) = selection::train_candidates(&inputs, &decoders, &mut times, report)?;
    let mut rows: Vec<CandidateRow> = candidates.iter().map(|c| c.row.clone()).collect();
    rows.extend(skipped);
    report.message(&candidates_table(&rows));
    let kept = &candidates[kept];
    let selected = &decoders[kept.decoder].selected;

    // The supervised baseline of the kept model (same decoder, same width).
    let colliders = spec.collider_slots(&problem.scene);
    let data = IntegratorData::new(
        problem,
        &frames.encoding,
        &selected.autoencoder,
        &frames.sequences,
        &frames.rows,
        colliders,
    )?;
    let name = format!("integrator ({})", Method::Supervised.label());
    report.stage(&name);
    let clock = Instant::now();
    let baseline = stages::train_integrator(
        problem,
        spec,
        &data,
        &selected.autoencoder,
        Method::Supervised,
        &kept.shape,
        &work,
    )?;
    times.record_resumed(name, clock, baseline.earlier_seconds);

    report.stage("artifacts");
    let trained = Trained {
        recipe,
        problem,
        frames: &frames,
        autoencoder: selected,
        data: &data,
    };
    let integrators = [kept.integrator.clone(), baseline];
    let mut artifacts = assemble::write_artifacts(
        &trained,
        &integrators,
        &times,
        &rows,
        kept.distilled.as_ref(),
        &options.out_dir,
    )?
    .into_iter();
    let (Some(model), Some(baseline)) = (artifacts.next(), artifacts.next()) else {
        unreachable!("two integrators make two artifacts");
    };
    let reduced = match &recipe.reduced {
        Some(spec) => {
            // The reduced method differentiates through a residual MLP decoder.
            let mlp = decoders
                .iter()
                .find(|d| d.family == DecoderCandidate::Mlp)
                .ok_or_else(|| {
                    TrainerError::invalid(format!(
                        "scene `{}`: [reduced] needs `mlp` among latent.selection.decoders",
                        recipe.scene.name
                    ))
                })?;
            let inputs = reduced::ReducedInputs {
                recipe,
                spec,
                problem,
                frames: &frames,
                autoencoder: &mlp.selected,
                times: &times,
                work: &work,
            };
            Some(reduced::train_reduced(&inputs, &options.out_dir, report)?)
        }
        None => None,
    };
    let mut losses = integrators.into_iter().map(|t| t.losses);
    Ok(TrainOutcome {
        model,
        baseline,
        losses: (losses.next().unwrap_or_default(), losses.next().unwrap_or_default()),
        autoencoder_losses: selected.losses.clone(),
        reduced,
    })
}
