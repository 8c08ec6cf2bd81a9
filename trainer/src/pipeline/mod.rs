//! `mochi train`: from a scene's training trajectories to a latent model (Li et al. 2025,
//! Sec. 3.2-3.3), as named stages run in order ([`stages`]): dataset (train
//! split), PCA, an autoencoder per candidate size (size selection), the self-supervised
//! integrator, the supervised baseline, and the artifacts; then, for scenes with a
//! `[reduced]` table, the reduced method's vanilla and Lipschitz-optimised subspaces
//! ([`reduced`]). Each stage's seconds go into the artifacts' training summary.

pub(crate) mod assemble;
pub(crate) mod reduced;
pub(crate) mod stages;

use std::path::PathBuf;
use std::time::Instant;

use crate::artifact::reduced::ReducedArtifact;
use crate::artifact::{Artifact, Method};
use crate::error::TrainerResult;
use crate::learn::recipe::Recipe;
use crate::learn::samples::IntegratorData;
use crate::progress::Reporter;
use stages::{StageTimes, Trained, Workspace};

/// Where `mochi train` works.
#[derive(Clone, Debug)]
pub struct TrainOptions {
    /// Output directory: `dataset/`, `checkpoints/` and the artifacts go here.
    pub out_dir: PathBuf,
    /// Continue from checkpoints left by an interrupted run.
    pub resume: bool,
    /// Only try this latent size (instead of the scene's candidates).
    pub latent: Option<usize>,
}

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
    let frames = stages::encode_training_split(problem, spec, &work)?;

    report.stage("pca");
    let clock = Instant::now();
    let sizes: Vec<usize> = options.latent.map_or(spec.sizes.clone(), |k| vec![k]);
    let diagonal = problem.mesh.rest_diagonal();
    let pca = stages::fit_pca(&frames, &sizes, spec.tolerance, diagonal, report)?;
    times.record("pca", clock);

    let selected = stages::select_autoencoder(problem, spec, &frames, &pca, &sizes, &work, &mut times, report)?;

    let data = IntegratorData::new(problem, &frames.encoding, &selected.autoencoder, &frames.sequences)?;
    let mut integrators = Vec::new();
    for method in [Method::SelfSupervised, Method::Supervised] {
        let name = format!("integrator ({})", method.label());
        report.stage(&name);
        let clock = Instant::now();
        let trained = stages::train_integrator(problem, spec, &data, &selected.autoencoder, method, &work)?;
        times.record_resumed(name, clock, trained.earlier_seconds);
        integrators.push(trained);
    }

    report.stage("artifacts");
    let trained = Trained {
        recipe,
        problem,
        frames: &frames,
        autoencoder: &selected,
        data: &data,
    };
    let mut artifacts = stages::write_artifacts(&trained, &integrators, &times, &options.out_dir)?.into_iter();
    let (Some(model), Some(baseline)) = (artifacts.next(), artifacts.next()) else {
        unreachable!("two integrators make two artifacts");
    };
    let reduced = match &recipe.reduced {
        Some(spec) => {
            let inputs = reduced::ReducedInputs {
                recipe,
                spec,
                problem,
                frames: &frames,
                autoencoder: &selected,
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
        autoencoder_losses: selected.losses,
        reduced,
    })
}
