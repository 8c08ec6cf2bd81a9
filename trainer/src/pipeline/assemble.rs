//! The artifact of a trained model: everything the runtime and codegen need, assembled from
//! the scene, the encoding, the networks and the training summary.

use crate::artifact::{Artifact, ArtifactError, EncodingData, HandleData, Method, TrainingSummary};
use crate::error::TrainerResult;
use crate::learn::encoding::Encoding;
use crate::learn::network::{Autoencoder, LatentIntegrator};
use crate::learn::pca::Pca;
use crate::learn::recipe::Recipe;
use crate::learn::samples::IntegratorData;
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
        integrator: integrator.export()?.mlp().layers().into_iter().cloned().collect(),
        summary,
    };
    artifact.validate().map_err(|(field, message)| ArtifactError::Invalid {
        field,
        message: format!("built an invalid artifact: {message}"),
    })?;
    Ok(artifact)
}
