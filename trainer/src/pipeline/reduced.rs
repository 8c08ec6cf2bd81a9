//! `mochi train`'s reduced-method stage (scenes with a `[reduced]` table; Lyu et al. 2024):
//! the vanilla subspace (the kept autoencoder's decoder, the plain autoencoder of
//! [`super::plain_vanilla`], or a data-free decoder), a cubature
//! of every elastic term fitted on it, the Lipschitz-optimised subspace (Eq. 10), and the
//! `.reduced` file that `mochi eval` steps both in.

use std::time::Instant;

use mochi_sim::cubature::{CubatureEnergy, CubatureSettings};
use mochi_sim::StencilEnergy;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::plain_vanilla::{plain_style, plain_tag, train_plain_vanilla};
use super::stages::{SelectedAutoencoder, StageTimes, TrainingFrames, Workspace, BLOCK};
use crate::artifact::reduced::{reduced_path, CubatureData, LinearSubspaceData, ReducedArtifact, SubspaceData};
use crate::error::{TrainerError, TrainerResult};
use crate::learn::datafree::{normal_latents, train_data_free_model, DataFreeObjective, DataFreeSettings};
use crate::learn::encoding::Encoding;
use crate::learn::frame_rows::Rows;
use crate::learn::network::{forward_exported, tensor_to_rows, Autoencoder, ExportedMlp};
use crate::learn::recipe::Recipe;
use crate::learn::reduced_spec::{LipschitzEnergy, ReducedSpec, SubspaceSource, VanillaNetwork};
use crate::learn::train::{self, AdamWConfig, CheckpointConfig, TrainConfig};
use crate::methods::lipschitz::cubature::{cubature_energies, elastic_terms, fit_subspace_cubature, ELASTIC_TERMS};
use crate::methods::lipschitz::loss::{lipschitz_estimate, LatentSample, LipschitzTerm};
use crate::methods::lipschitz::train::{optimise_data_free, optimise_supervised, LipschitzSettings};
use crate::methods::reduced::stepper::scene_objective_scale;
use crate::progress::Reporter;
use mochi_sim::BuiltScene;

/// Latent samples the cubature is fitted on.
const CUBATURE_SAMPLES: usize = 64;

/// What the stage starts from.
pub(crate) struct ReducedInputs<'a> {
    pub(crate) recipe: &'a Recipe,
    pub(crate) spec: &'a ReducedSpec,
    pub(crate) problem: &'a BuiltScene,
    pub(crate) frames: &'a TrainingFrames,
    pub(crate) autoencoder: &'a SelectedAutoencoder,
    pub(crate) times: &'a StageTimes,
    pub(crate) work: &'a Workspace,
}

/// Fits a cubature of every elastic term to `decoder`'s subspace on `samples`.
fn fit_cubatures(
    problem: &BuiltScene,
    encoding: &Encoding,
    decoder: &ExportedMlp,
    samples: &[LatentSample],
    size: usize,
) -> TrainerResult<Vec<CubatureData>> {
    let settings = CubatureSettings {
        max_elements: size,
        ..CubatureSettings::default()
    };
    let mut out = Vec::new();
    for energy in problem.simulator.potentials() {
        if !ELASTIC_TERMS.contains(&energy.name()) {
            continue;
        }
        let (cubature, fit) = fit_subspace_cubature(decoder, encoding, energy.as_ref(), samples, &settings)?;
        out.push(CubatureData {
            term: energy.name().to_string(),
            elements: cubature.elements,
            weights: cubature.weights,
            residual: fit.relative_residual,
        });
    }
    Ok(out)
}

/// The potentials the Lipschitz loss differentiates: the cubature energies `energies`, or
/// every element of `problem`'s elastic terms when `spec` asks for the exact energy (or
/// draws from them per minibatch).
fn lipschitz_potentials<'a>(
    spec: &ReducedSpec,
    problem: &'a BuiltScene,
    energies: &'a [CubatureEnergy<'a>],
) -> Vec<&'a dyn StencilEnergy> {
    match spec.lipschitz_energy {
        LipschitzEnergy::Cubature => energies.iter().map(|e| e as &dyn StencilEnergy).collect(),
        LipschitzEnergy::Exact | LipschitzEnergy::Sampled => {
            let all: Vec<&dyn StencilEnergy> = problem.simulator.potentials().iter().map(|p| p.as_ref()).collect();
            elastic_terms(&all)
        }
    }
}

/// The Lipschitz term of `problem`'s body on `potentials`.
fn lipschitz_term<'a>(
    problem: &BuiltScene,
    encoding: &'a Encoding,
    potentials: &'a [&'a dyn StencilEnergy],
) -> LipschitzTerm<'a> {
    LipschitzTerm {
        encoding,
        potentials,
        scale: scene_objective_scale(problem),
        diagonal: problem.mesh.rest_diagonal(),
    }
}

/// Runs the stage and writes `<scene>.reduced` into `out_dir`.
pub(crate) fn train_reduced(
    inputs: &ReducedInputs<'_>,
    out_dir: &std::path::Path,
    report: &dyn Reporter,
) -> TrainerResult<ReducedArtifact> {
    let artifact = match inputs.spec.subspace {
        SubspaceSource::Supervised => supervised(inputs, report)?,
        SubspaceSource::DataFree => data_free(inputs, report)?,
    };
    artifact.save(&reduced_path(out_dir, &inputs.recipe.scene.name))?;
    report.message(&format!(
        "reduced subspaces: Lip[d2P/dz2] vanilla {:.3e}, Lipschitz-optimised {:.3e}; training {:.0} s / {:.0} s",
        artifact.vanilla.lipschitz_estimate,
        artifact.lipschitz.lipschitz_estimate,
        artifact.vanilla.training_seconds,
        artifact.lipschitz.training_seconds
    ));
    Ok(artifact)
}

/// The scene's name, its recipe as TOML and the file it was read from.
fn header(recipe: &Recipe) -> TrainerResult<(String, String, String)> {
    Ok((
        recipe.scene.name.clone(),
        recipe.to_toml()?,
        recipe.scene.source.display().to_string(),
    ))
}

/// The latents of every `step`-th training frame under `encoder`, with their handle targets.
fn encoded_samples(frames: &TrainingFrames, encoder: &ExportedMlp, step: usize) -> TrainerResult<Vec<LatentSample>> {
    let targets: Vec<&Vec<f64>> = frames.sequences.iter().flat_map(|s| s.targets.iter()).collect();
    targets
        .into_iter()
        .enumerate()
        .step_by(step.max(1))
        .map(|(i, t)| {
            let mut q = Vec::with_capacity(frames.rows.width());
            frames.rows.gather_f32(&[i], &mut q)?;
            let z = forward_exported(encoder, &q)?;
            Ok(LatentSample {
                z: z.iter().map(|&v| v as f64).collect(),
                targets: t.clone(),
            })
        })
        .collect()
}

fn supervised(inputs: &ReducedInputs<'_>, report: &dyn Reporter) -> TrainerResult<ReducedArtifact> {
    let (problem, frames, spec) = (inputs.problem, inputs.frames, inputs.spec);
    let encoding = &frames.encoding;
    let net = &inputs.recipe.latent.autoencoder;
    let kept = &inputs.autoencoder.autoencoder;
    let k = kept.spec().latent;
    let plain = match spec.vanilla {
        VanillaNetwork::Autoencoder => None,
        VanillaNetwork::PlainMlp => {
            report.stage(&format!("reduced: plain vanilla k={k}"));
            let seed = inputs.recipe.latent.seed;
            let scale = (encoding.values_per_vertex(), problem.mesh.rest_diagonal());
            let trained = train_plain_vanilla(spec, &frames.rows, k, net.batch, seed, inputs.work, scale)?;
            if let Some((modes, error)) = trained.projection {
                report.message(&format!(
                    "plain vanilla: between a PCA of {modes} components (RMS vertex error / diagonal {error:.2e})"
                ));
            }
            let error = train::mean_reconstruction_error(&trained.autoencoder, &frames.rows, BLOCK)?;
            report.message(&format!(
                "plain vanilla: RMS vertex error / diagonal {:.2e} after {} epochs ({:.0} s)",
                (error * encoding.values_per_vertex() as f64).sqrt() / problem.mesh.rest_diagonal(),
                spec.plain_epochs,
                trained.seconds
            ));
            Some(trained)
        }
    };
    let (vanilla_model, vanilla_losses, vanilla_seconds, lipschitz_lr, tag) = match &plain {
        None => (
            kept,
            inputs.autoencoder.losses.clone(),
            inputs
                .times
                .0
                .iter()
                .find(|(name, _)| name == &format!("autoencoder k={k}"))
                .map_or(0.0, |(_, s)| *s),
            net.final_learning_rate,
            String::new(),
        ),
        Some(p) => (
            &p.autoencoder,
            p.losses.clone(),
            p.seconds,
            spec.plain_final_learning_rate,
            format!("plain-{}-", plain_tag(spec)),
        ),
    };
    let vanilla_ae = vanilla_model.export()?;
    let vanilla_decoder = vanilla_ae.decoder.as_mlp()?;

    report.stage("reduced: cubature");
    let step = (frames.rows.count() / CUBATURE_SAMPLES).max(1);
    let samples = encoded_samples(frames, &vanilla_ae.encoder, step)?;
    let cubatures = fit_cubatures(problem, encoding, vanilla_decoder, &samples, spec.cubature)?;

    report.stage("reduced: Lipschitz optimisation");
    let clock = Instant::now();
    let optimised = Autoencoder::from_exported(vanilla_model.spec(), &vanilla_ae)?;
    let targets: Vec<Vec<f64>> = frames
        .sequences
        .iter()
        .flat_map(|s| s.targets.iter().cloned())
        .collect();
    // Runs with other Lipschitz settings get their own checkpoints (the loss is not part of
    // a checkpoint's identity).
    let name = format!(
        "lipschitz-{tag}k{k}-w{:?}-s{}-c{}{}{}",
        spec.lipschitz,
        spec.samples,
        spec.cubature,
        spec.lipschitz_learning_rate
            .map_or(String::new(), |lr| format!("-lr{lr:?}")),
        if spec.lipschitz_local > 0.0 {
            format!("-local{:?}", spec.lipschitz_local)
        } else {
            String::new()
        }
    ) + match spec.lipschitz_energy {
        LipschitzEnergy::Cubature => "",
        LipschitzEnergy::Exact => "-exact",
        LipschitzEnergy::Sampled => "-sampled",
    };
    let tolerance = inputs.recipe.latent.tolerance * problem.mesh.rest_diagonal();
    let mut settings = LipschitzSettings {
        weight: spec.lipschitz,
        samples: spec.samples,
        // The per-coordinate mean square of a reconstruction at the tolerance.
        floor: tolerance * tolerance / problem.mesh.dim as f64,
        lambda: None,
        local: spec.lipschitz_local,
        resample: match spec.lipschitz_energy {
            LipschitzEnergy::Sampled => spec.cubature,
            _ => 0,
        },
    };
    let rounds = spec.cubature_refits + 1;
    let (mut losses, mut earlier_seconds, mut start) = (Vec::new(), 0.0, None);
    let mut round_cubatures = cubatures.clone();
    for round in 0..rounds {
        if round > 0 {
            let current = optimised.export()?;
            let samples = encoded_samples(frames, &current.encoder, step)?;
            round_cubatures = fit_cubatures(problem, encoding, current.decoder.as_mlp()?, &samples, spec.cubature)?;
        }
        let energies = cubature_energies(problem, &round_cubatures)?;
        let potentials = lipschitz_potentials(spec, problem, &energies);
        let config = TrainConfig {
            name: if rounds > 1 {
                format!("{name}-round{round}of{rounds}")
            } else {
                name.clone()
            },
            // The epochs spread over the rounds, the first ones taking the remainder.
            epochs: spec.lipschitz_epochs / rounds + usize::from(round < spec.lipschitz_epochs % rounds),
            batch_size: net.batch.max(spec.samples),
            seed: 7,
            optimizer: AdamWConfig {
                lr: spec.lipschitz_learning_rate.unwrap_or(lipschitz_lr.max(1e-5)),
                ..AdamWConfig::default()
            },
            final_lr: None,
            warmup_step: None,
            checkpoint: Some(CheckpointConfig {
                dir: inputs.work.checkpoints.clone(),
                every: 5,
            }),
            progress: inputs.work.bars,
        };
        let run = optimise_supervised(
            &optimised,
            &frames.rows,
            &targets,
            &lipschitz_term(problem, encoding, &potentials),
            &settings,
            &config,
            inputs.work.resume,
        )?;
        settings.lambda = Some(run.lambda);
        start.get_or_insert(run.start);
        losses.extend(run.train.losses);
        earlier_seconds += run.train.earlier_seconds;
    }
    let lambda = settings.lambda.unwrap_or(0.0);
    let start = start.unwrap_or((0.0, 0.0));
    let lipschitz_seconds = clock.elapsed().as_secs_f64() + earlier_seconds;
    report.message(&format!(
        "Lipschitz optimisation: reconstruction {:.3e} and Lipschitz loss {:.3e} at the vanilla start, lambda {:.3e}",
        start.0, start.1, lambda
    ));
    let energies = cubature_energies(problem, &cubatures)?;
    let potentials = lipschitz_potentials(spec, problem, &energies);
    let term = lipschitz_term(problem, encoding, &potentials);
    let ours = optimised.export()?;

    // Lip on every third training frame (the evaluation measures it on the test split).
    let vanilla_samples = encoded_samples(frames, &vanilla_ae.encoder, 3)?;
    let our_samples = encoded_samples(frames, &ours.encoder, 3)?;
    let lip = |decoder: &ExportedMlp, samples: &[LatentSample]| -> TrainerResult<f64> {
        Ok(lipschitz_estimate(&term.hessians(decoder, samples)?, samples))
    };
    // Every sequence starts from the scene's start state: its latent starts every rollout.
    if frames.rows.count() == 0 {
        return Err(TrainerError::invalid("the training split has no frames"));
    }
    let mut start = Vec::with_capacity(frames.rows.width());
    frames.rows.gather_f32(&[0], &mut start)?;
    let initial = |encoder: &ExportedMlp| -> TrainerResult<Vec<f64>> {
        Ok(forward_exported(encoder, &start)?.iter().map(|&v| v as f64).collect())
    };
    let (scene, scene_toml, scene_path) = header(inputs.recipe)?;
    Ok(ReducedArtifact {
        scene,
        scene_toml,
        scene_path,
        source: "supervised".into(),
        vanilla: SubspaceData {
            decoder: vanilla_ae.decoder.layers().into_iter().cloned().collect(),
            style: vanilla_decoder.style(),
            initial_latent: initial(&vanilla_ae.encoder)?,
            training_seconds: vanilla_seconds,
            lipschitz_estimate: lip(vanilla_decoder, &vanilla_samples)?,
            losses: vanilla_losses,
        },
        lipschitz: SubspaceData {
            decoder: ours.decoder.layers().into_iter().cloned().collect(),
            style: ours.decoder.as_mlp()?.style(),
            initial_latent: initial(&ours.encoder)?,
            training_seconds: vanilla_seconds + lipschitz_seconds,
            lipschitz_estimate: lip(ours.decoder.as_mlp()?, &our_samples)?,
            losses,
        },
        cubature: cubatures,
        lambda,
        pca: Some(linear_subspace(inputs, k)?),
    })
}

/// The PCA of the training frames at latent size `k`, the linear subspace compared with the
/// trained ones.
fn linear_subspace(inputs: &ReducedInputs<'_>, k: usize) -> TrainerResult<LinearSubspaceData> {
    let fitted = &inputs.autoencoder.pca;
    let pca = fitted.clone().truncated(k.min(fitted.num_components()))?;
    if inputs.frames.rows.count() == 0 {
        return Err(TrainerError::invalid("the training split has no frames"));
    }
    Ok(LinearSubspaceData::new(&pca, &inputs.frames.rows.row_f64(0)?)?)
}

fn data_free(inputs: &ReducedInputs<'_>, report: &dyn Reporter) -> TrainerResult<ReducedArtifact> {
    let (problem, spec) = (inputs.problem, inputs.spec);
    let encoding = &inputs.frames.encoding;
    let mut settings = DataFreeSettings {
        latent: spec.latent,
        iterations: spec.data_free_iterations,
        seed: spec.seed.unwrap_or(0),
        ..DataFreeSettings::default()
    };
    if spec.vanilla == VanillaNetwork::PlainMlp {
        settings.hidden = spec.plain_hidden;
        settings.blocks = spec.plain_blocks;
        settings.style = plain_style(spec);
    }
    let objective = DataFreeObjective::new(problem, encoding, settings.sigma)?;
    let (model, vanilla) = train_data_free_model(&objective, &settings, report)?;

    report.stage("reduced: cubature");
    let mut rng = ChaCha8Rng::seed_from_u64(settings.seed);
    rng.set_stream(3);
    let gaussian = |count: usize, rng: &mut ChaCha8Rng| -> TrainerResult<Vec<LatentSample>> {
        let z = normal_latents(count, settings.latent, rng)?;
        Ok(tensor_to_rows(&z)?
            .into_iter()
            .map(|row| LatentSample {
                z: row.iter().map(|&v| v as f64).collect(),
                targets: objective.targets().to_vec(),
            })
            .collect())
    };
    let samples = gaussian(CUBATURE_SAMPLES, &mut rng)?;
    let cubatures = fit_cubatures(problem, encoding, &vanilla.decoder, &samples, spec.cubature)?;
    let energies = cubature_energies(problem, &cubatures)?;
    let potentials = lipschitz_potentials(spec, problem, &energies);
    let term = lipschitz_term(problem, encoding, &potentials);

    report.stage("reduced: Lipschitz optimisation");
    let clock = Instant::now();
    let lip_settings = LipschitzSettings {
        weight: spec.lipschitz,
        samples: spec.samples,
        floor: 0.0,
        lambda: None,
        local: 0.0,
        resample: 0,
    };
    let lipschitz_stage = DataFreeSettings {
        learning_rate: spec.lipschitz_learning_rate.unwrap_or(settings.learning_rate),
        ..settings
    };
    let (losses, lambda) = optimise_data_free(
        &objective,
        &model,
        &lipschitz_stage,
        &term,
        &lip_settings,
        spec.lipschitz_epochs,
        report,
    )?;
    let lipschitz_seconds = clock.elapsed().as_secs_f64();
    let ours = model.export()?;
    let held_out = gaussian(64, &mut rng)?;
    let lip = |decoder: &ExportedMlp| -> TrainerResult<f64> {
        Ok(lipschitz_estimate(&term.hessians(decoder, &held_out)?, &held_out))
    };
    let (scene, scene_toml, scene_path) = header(inputs.recipe)?;
    let vanilla_losses = vanilla.losses.iter().map(|(e, r)| e + settings.lambda * r).collect();
    Ok(ReducedArtifact {
        scene,
        scene_toml,
        scene_path,
        source: "data-free".into(),
        vanilla: SubspaceData {
            decoder: vanilla.decoder.layers().into_iter().cloned().collect(),
            style: vanilla.decoder.style(),
            initial_latent: vec![0.0; spec.latent],
            training_seconds: vanilla.seconds,
            lipschitz_estimate: lip(&vanilla.decoder)?,
            losses: vanilla_losses,
        },
        lipschitz: SubspaceData {
            decoder: ours.layers().into_iter().cloned().collect(),
            style: ours.style(),
            initial_latent: vec![0.0; spec.latent],
            training_seconds: vanilla.seconds + lipschitz_seconds,
            lipschitz_estimate: lip(&ours)?,
            losses,
        },
        cubature: cubatures,
        lambda,
        pca: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::datafree::tests::tiny_bar;

    /// The Lipschitz loss sees the cubature's elements, or with `lipschitz_energy = "exact"`
    /// every element of the scene's elastic terms.
    #[test]
    fn the_exact_lipschitz_energy_takes_every_elastic_element() {
        let dir = tempfile::tempdir().unwrap();
        let problem = tiny_bar(dir.path());
        let cubature = [CubatureData {
            term: "elastic".into(),
            elements: vec![0, 3],
            weights: vec![1.0, 2.0],
            residual: 0.0,
        }];
        let energies = cubature_energies(&problem, &cubature).unwrap();
        let elastic = problem
            .simulator
            .potentials()
            .iter()
            .find(|p| p.name() == "elastic")
            .unwrap();
        let mut spec = ReducedSpec::default();
        let with_cubature = lipschitz_potentials(&spec, &problem, &energies);
        assert_eq!(with_cubature.len(), 1);
        assert_eq!(with_cubature[0].len(), 2);
        spec.lipschitz_energy = LipschitzEnergy::Exact;
        let exact = lipschitz_potentials(&spec, &problem, &energies);
        let names: Vec<&str> = exact.iter().map(|p| p.name()).collect();
        assert_eq!(names, ["elastic"], "gravity and the other terms are not regularised");
        assert!(exact[0].len() > 2 && exact[0].len() == elastic.len());
    }
}
