//! The artifact of a trained model: everything the runtime and codegen need, assembled from
//! the scene, the encoding, the networks and the training summary; and stage 5 of
//! `mochi train`, which writes the model and its supervised baseline.

use std::path::{Path, PathBuf};

use crate::artifact::{Artifact, ArtifactError, CandidateRow, EncodingData, HandleData, Method, TrainingSummary};
use crate::error::{TrainerError, TrainerResult};
use crate::learn::encoding::Encoding;
use crate::learn::network::{Autoencoder, LatentIntegrator, MlpStyle};
use crate::learn::pca::Pca;
use crate::learn::recipe::Recipe;
use crate::learn::samples::IntegratorData;
use crate::pipeline::distill::adopt_decoder;
use crate::pipeline::stages::{SelectedAutoencoder, StageTimes, TrainedIntegrator, TrainingFrames};
use mochi_sim::mesh::Elements;
use mochi_sim::BuiltScene;

/// Assembles the artifact of a trained model; `pca` is the PCA of the encoded training
/// frames the autoencoder was initialised with.
pub fn build_artifact(
    recipe: &Recipe,
    problem: &BuiltScene,
    encoding: &Encoding,
    ae: &Autoencoder,
    integrator: &LatentIntegrator,
    data: &IntegratorData<'_>,
    pca: &Pca,
    method: Method,
    summary: TrainingSummary,
) -> TrainerResult<Artifact> {
    let exported = ae.export()?;
    let exported_integrator = integrator.export()?;
    let styles = [
        exported.encoder.style(),
        exported.decoder.style(),
        exported_integrator.mlp().style(),
    ];
    if let Some(style) = styles.iter().find(|s| **s != MlpStyle::default()) {
        return Err(TrainerError::invalid(format!(
            "the runtime runs residual Swish MLPs, not {style:?}"
        )));
    }
    let k = data.latent;
    let f32s = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let u32s = |v: &[usize]| v.iter().map(|&x| x as u32).collect::<Vec<u32>>();
    let x0 = &data.sequences[0].trajectory.positions[0];
    let q0: Vec<f32> = encoding.encode_state(x0)?.iter().map(|&v| v as f32).collect();
    let initial_latent = crate::learn::network::forward_exported(&exported.encoder, &q0)?;
    let mut pca_basis: Vec<f32> = pca.basis.iter().flat_map(|b| f32s(b)).collect();
    pca_basis.resize(k * encoding.encoded_len(), 0.0);
    let polylines = match &problem.mesh.elements {
        Elements::Rods(rods) => rods.iter().map(|r| u32s(r)).collect(),
        _ => Vec::new(),
    };
    let handles = problem
        .handles
        .iter()
        .map(|h| HandleData {
            name: h.name.clone(),
            vertices: u32s(&h.vertices),
            reference: h.reference.iter().flatten().map(|&v| v as f32).collect(),
            pivot: h.pivot.map(|v| v as f32),
        })
        .collect();
    let artifact = Artifact {
        scene: problem.scene.name.clone(),
        scene_path: problem.scene.source.display().to_string(),
        scene_toml: recipe.to_toml()?,
        method,
        dt: problem.scene.dt,
        dim: problem.mesh.dim as u32,
        num_vertices: problem.mesh.num_vertices() as u32,
        rest: f32s(&problem.mesh.rest),
        diagonal: problem.mesh.rest_diagonal(),
        encoding: EncodingData::new(encoding),
        handles,
        bc_len: data.bc_len as u32,
        surface_vertices: u32s(&problem.mesh.surface_vertices()),
        surface_triangles: problem
            .mesh
            .surface_triangles()
            .iter()
            .map(|t| t.map(|v| v as u32))
            .collect(),
        polylines,
        latent: k as u32,
        initial_latent,
        latent_min: data.latent_range.0.clone(),
        latent_max: data.latent_range.1.clone(),
        pca_mean: f32s(&pca.mean),
        pca_basis,
        encoder: exported.encoder.layers().into_iter().cloned().collect(),
        decoder: exported.decoder.layers().into_iter().cloned().collect(),
        decoder_basis: exported.decoder.is_basis(),
        integrator: exported_integrator.mlp().layers().into_iter().cloned().collect(),
        rate_input: exported_integrator.rate_input(),
        dt_range: problem
            .scene
            .dataset
            .frame_times()
            .map_or([0.0; 2], |(shortest, longest)| [shortest, longest]),
        collider_shapes: collider_shape_rows(problem, data.colliders),
        render: crate::artifact::render::render_data(problem)?,
        summary,
    };
    artifact.validate().map_err(|(field, message)| ArtifactError::Invalid {
        field,
        message: format!("built an invalid artifact: {message}"),
    })?;
    Ok(artifact)
}

/// The shape rows `[code, a, b, c]` of the first `slots` colliders of `problem` (the
/// integrator's collider slots).
fn collider_shape_rows(problem: &BuiltScene, slots: usize) -> Vec<f32> {
    let shapes = problem
        .simulator
        .collider_barrier()
        .map(|b| b.shapes())
        .unwrap_or_default();
    shapes
        .iter()
        .take(slots)
        .flat_map(|s| s.parameters().map(|v| v as f32))
        .collect()
}

/// Everything the artifacts are made of.
pub(crate) struct Trained<'a> {
    /// The recipe trained.
    pub(crate) recipe: &'a Recipe,
    /// Its scene, built.
    pub(crate) problem: &'a BuiltScene,
    /// The encoded training split.
    pub(crate) frames: &'a TrainingFrames,
    /// The kept autoencoder.
    pub(crate) autoencoder: &'a SelectedAutoencoder,
    /// The integrator's training set.
    pub(crate) data: &'a IntegratorData<'a>,
}

/// The training summary of a model (no candidates table): sizes tried, stage times so far,
/// the integrator's last loss, and the training envelope.
pub(crate) fn summary(trained: &Trained<'_>, integrator: &TrainedIntegrator, times: &StageTimes) -> TrainingSummary {
    let (frames, selected) = (trained.frames, trained.autoencoder);
    let (max_radius, max_kinetic_energy) = (frames.max_radius, frames.max_kinetic_energy);
    TrainingSummary {
        tolerance: trained.recipe.latent.tolerance,
        trials: selected.trials.clone(),
        stage_seconds: times.0.clone(),
        final_loss: integrator.losses.last().copied().unwrap_or(f64::NAN),
        samples: trained.data.inputs.len() as u64,
        max_radius,
        max_kinetic_energy,
        candidates: Vec::new(),
    }
}

/// Stage 5: one artifact per trained integrator, each with the training summary (`times`
/// so far), written into `out_dir` (the first as the model, the second as its supervised
/// baseline); returns them in order. The model takes the decoder of `distilled` when the
/// selection kept a distilled candidate; the baseline keeps the autoencoder's.
pub(crate) fn write_artifacts(
    trained: &Trained<'_>,
    integrators: &[TrainedIntegrator],
    times: &StageTimes,
    candidates: &[CandidateRow],
    distilled: Option<&Artifact>,
    out_dir: &Path,
) -> TrainerResult<Vec<Artifact>> {
    let mut artifacts: Vec<Artifact> = Vec::new();
    for trained_integrator in integrators {
        let summary = TrainingSummary {
            candidates: candidates.to_vec(),
            ..summary(trained, trained_integrator, times)
        };
        artifacts.push(build_artifact(
            trained.recipe,
            trained.problem,
            &trained.frames.encoding,
            &trained.autoencoder.autoencoder,
            &trained_integrator.integrator,
            trained.data,
            &trained.autoencoder.pca,
            trained_integrator.method,
            summary,
        )?);
    }
    if let (Some(model), Some(distilled)) = (artifacts.first_mut(), distilled) {
        adopt_decoder(model, distilled);
    }
    let (model_path, baseline_path) = artifact_paths(out_dir, &trained.problem.scene.name);
    for (artifact, path) in artifacts.iter().zip([model_path, baseline_path]) {
        artifact.write(&path)?;
    }
    Ok(artifacts)
}

/// The artifact paths of a scene in `out_dir`: the model and its supervised baseline.
pub fn artifact_paths(out_dir: &Path, scene: &str) -> (PathBuf, PathBuf) {
    (
        out_dir.join(format!("{scene}.mochi")),
        out_dir.join(format!("{scene}.supervised.mochi")),
    )
}
