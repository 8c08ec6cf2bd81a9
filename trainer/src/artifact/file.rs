//! The artifact file (docs/design.md, decision 4), written and read through the runtime's
//! envelope and payload schema:
//!
//! ```text
//! section 1: envelope(MOCHIMDL, FORMAT_VERSION, postcard(mochi_runtime::payload::Payload))
//! section 2: envelope(MOCHITRN, FORMAT_VERSION, postcard(TrainingSection))
//! ```
//!
//! The first section is exactly what the runtime reads (and all a device needs); the second
//! holds what only the trainer reads. Files of format 2 (one section, the whole [`Artifact`]
//! in postcard), 3 (the triangles to draw in the training section, [`super::format3`]) and 4
//! (no `decoder_basis`: the payload ends before it), 5 (no `dt_range`, `collider_shapes`) and 6 (no
//! `render`) are still read; `mochi upgrade` rewrites
//! them in the current format.

use std::path::Path;

use super::section::{ArtifactError, TrainingSection, TRAINING_MAGIC};
use super::{format3, Artifact, EncodingData, HandleData};
use crate::learn::network::DenseLayer;
use mochi_runtime::artifact::{FORMAT_VERSION, MAGIC};
use mochi_runtime::envelope;
use mochi_runtime::payload::{HandleData as RuntimeHandle, LayerData, Payload};
use mochi_sim::error::InputError;

/// The last format with the whole artifact in one section, still read.
const SINGLE_SECTION_VERSION: u32 = 2;
/// The last format without `decoder_basis` (every decoder a residual MLP), still read.
const MLP_DECODER_VERSION: u32 = 4;
/// The last format whose models step at one frame time and take no colliders (no `dt_range`,
/// no `collider_shapes`).
const ONE_FRAME_TIME_VERSION: u32 = 5;
/// The last format without the render mesh (`render`).
const NO_RENDER_VERSION: u32 = 6;
/// The last format whose timed integrators read `z_{t-2}` (no `rate_input`).
const NO_RATE_INPUT_VERSION: u32 = 7;

/// Weights and biases smaller than this fraction (`2^-40`) of their layer's largest weight are
/// written as zero.
const NEGLIGIBLE: f32 = 1.0 / (1u64 << 40) as f32;

/// The runtime's copy of a layer, its negligible values zero ([`NEGLIGIBLE`]): a basis fitted
/// to motion that never leaves a plane has rows for the other direction made of rounding
/// noise down to subnormal numbers, and every product with one is computed in microcode on
/// x86 (a swinging `rods` model spent a fifth of its frame there). `2^-40` of the largest
/// weight is far below what `f32` resolves in a sum that includes it.
fn layer_data(l: &DenseLayer) -> LayerData {
    let largest = l.weights.iter().fold(0.0f32, |m, w| m.max(w.abs()));
    let keep = |v: &f32| if v.abs() < NEGLIGIBLE * largest { 0.0 } else { *v };
    LayerData {
        rows: l.rows as u64,
        cols: l.cols as u64,
        weights: l.weights.iter().map(keep).collect(),
        bias: l.bias.iter().map(keep).collect(),
    }
}

fn dense_layer(l: LayerData) -> Result<DenseLayer, ArtifactError> {
    let size = |v: u64| {
        usize::try_from(v).map_err(|_| ArtifactError::Invalid {
            field: "layers".into(),
            message: format!("size {v} does not fit this machine"),
        })
    };
    Ok(DenseLayer {
        rows: size(l.rows)?,
        cols: size(l.cols)?,
        weights: l.weights,
        bias: l.bias,
    })
}

impl Artifact {
    /// The triangles to draw over the drawn vertices (three indices into `surface_vertices`
    /// each), as the model section holds them.
    fn drawn_triangles(&self) -> Result<Vec<u32>, ArtifactError> {
        let drawn = |v: u32| {
            self.surface_vertices
                .binary_search(&v)
                .map(|i| i as u32)
                .map_err(|_| ArtifactError::Invalid {
                    field: "surface_triangles".into(),
                    message: format!("vertex {v} is not a drawn vertex"),
                })
        };
        self.surface_triangles.iter().flatten().map(|&v| drawn(v)).collect()
    }

    /// The artifact as its two sections' contents.
    pub fn sections(&self) -> Result<(Payload, TrainingSection), ArtifactError> {
        let e = &self.encoding;
        let payload = Payload {
            dt: self.dt,
            dim: self.dim,
            num_vertices: self.num_vertices,
            rest: self.rest.clone(),
            diagonal: self.diagonal,
            rotates: e.rotates,
            handle_vertices: e.handle_vertices.clone(),
            free_vertices: e.free_vertices.clone(),
            origin_of: e.origin_of.clone(),
            root_slots: e.root_slots.clone(),
            chains: e.chains.clone(),
            handles: self
                .handles
                .iter()
                .map(|h| RuntimeHandle {
                    vertices: h.vertices.clone(),
                    reference: h.reference.clone(),
                    pivot: h.pivot,
                })
                .collect(),
            bc_len: self.bc_len,
            surface_vertices: self.surface_vertices.clone(),
            latent: self.latent,
            initial_latent: self.initial_latent.clone(),
            latent_min: self.latent_min.clone(),
            latent_max: self.latent_max.clone(),
            decoder: self.decoder.iter().map(layer_data).collect(),
            integrator: self.integrator.iter().map(layer_data).collect(),
            surface_triangles: self.drawn_triangles()?,
            decoder_basis: self.decoder_basis,
            dt_range: self.dt_range,
            collider_shapes: self.collider_shapes.clone(),
            render: self.render.clone(),
            rate_input: self.rate_input,
        };
        let training = TrainingSection {
            scene: self.scene.clone(),
            scene_path: self.scene_path.clone(),
            scene_toml: self.scene_toml.clone(),
            method: self.method,
            reference: e.reference.clone(),
            handle_names: self.handles.iter().map(|h| h.name.clone()).collect(),
            polylines: self.polylines.clone(),
            pca_mean: self.pca_mean.clone(),
            pca_basis: self.pca_basis.clone(),
            encoder: self.encoder.clone(),
            summary: self.summary.clone(),
        };
        Ok((payload, training))
    }

    /// The artifact of two sections' contents.
    pub fn from_sections(p: Payload, t: TrainingSection) -> Result<Artifact, ArtifactError> {
        if t.handle_names.len() != p.handles.len() {
            return Err(ArtifactError::Invalid {
                field: "handle_names".into(),
                message: format!("{} names for {} handles", t.handle_names.len(), p.handles.len()),
            });
        }
        let layers = |v: Vec<LayerData>| v.into_iter().map(dense_layer).collect::<Result<Vec<_>, _>>();
        let triangles = p.surface_triangles.chunks(3);
        if triangles.len() * 3 != p.surface_triangles.len() {
            return Err(ArtifactError::Invalid {
                field: "surface_triangles".into(),
                message: format!("{} indices, not whole triangles", p.surface_triangles.len()),
            });
        }
        let mesh_vertex = |i: &u32| {
            p.surface_vertices
                .get(*i as usize)
                .copied()
                .ok_or(ArtifactError::Invalid {
                    field: "surface_triangles".into(),
                    message: format!("index {i} beyond the {} drawn vertices", p.surface_vertices.len()),
                })
        };
        let surface_triangles = triangles
            .map(|t| Ok([mesh_vertex(&t[0])?, mesh_vertex(&t[1])?, mesh_vertex(&t[2])?]))
            .collect::<Result<Vec<_>, ArtifactError>>()?;
        Ok(Artifact {
            scene: t.scene,
            scene_path: t.scene_path,
            scene_toml: t.scene_toml,
            method: t.method,
            dt: p.dt,
            dim: p.dim,
            num_vertices: p.num_vertices,
            rest: p.rest,
            diagonal: p.diagonal,
            encoding: EncodingData {
                rotates: p.rotates,
                handle_vertices: p.handle_vertices,
                reference: t.reference,
                free_vertices: p.free_vertices,
                origin_of: p.origin_of,
                root_slots: p.root_slots,
                chains: p.chains,
            },
            handles: p
                .handles
                .into_iter()
                .zip(t.handle_names)
                .map(|(h, name)| HandleData {
                    name,
                    vertices: h.vertices,
                    reference: h.reference,
                    pivot: h.pivot,
                })
                .collect(),
            bc_len: p.bc_len,
            surface_vertices: p.surface_vertices,
            surface_triangles,
            polylines: t.polylines,
            latent: p.latent,
            initial_latent: p.initial_latent,
            latent_min: p.latent_min,
            latent_max: p.latent_max,
            pca_mean: t.pca_mean,
            pca_basis: t.pca_basis,
            encoder: t.encoder,
            decoder: layers(p.decoder)?,
            decoder_basis: p.decoder_basis,
            integrator: layers(p.integrator)?,
            dt_range: p.dt_range,
            collider_shapes: p.collider_shapes,
            render: p.render,
            rate_input: p.rate_input,
            summary: t.summary,
        })
    }

    /// The artifact as bytes: the model section, then the training section.
    pub fn to_bytes(&self) -> Result<Vec<u8>, ArtifactError> {
        let (payload, training) = self.sections()?;
        let mut bytes = payload.to_section().map_err(|source| ArtifactError::Encode {
            section: "model section",
            source,
        })?;
        let training = postcard::to_allocvec(&training).map_err(|source| ArtifactError::Encode {
            section: "training section",
            source,
        })?;
        bytes.extend(envelope::wrap(TRAINING_MAGIC, FORMAT_VERSION, &training));
        Ok(bytes)
    }

    /// Parses and validates an artifact (format [`FORMAT_VERSION`], 7, 6, 5, 4, 3 or 2), and checks that
    /// the runtime accepts what it reads of it.
    pub fn parse(bytes: &[u8]) -> Result<Artifact, ArtifactError> {
        let decode = |section| move |source| ArtifactError::Decode { section, source };
        let header = envelope::Header::parse(bytes);
        let old = |version| bytes.starts_with(MAGIC) && header.map(|h| h.version) == Ok(version);
        let artifact = if old(SINGLE_SECTION_VERSION) {
            let payload = envelope::open(bytes, MAGIC, SINGLE_SECTION_VERSION).map_err(ArtifactError::Envelope)?;
            postcard::from_bytes(payload).map_err(decode("payload"))?
        } else if old(format3::VERSION) {
            format3::parse(bytes)?
        } else {
            let version = if old(MLP_DECODER_VERSION) {
                MLP_DECODER_VERSION
            } else if old(ONE_FRAME_TIME_VERSION) {
                ONE_FRAME_TIME_VERSION
            } else if old(NO_RENDER_VERSION) {
                NO_RENDER_VERSION
            } else if old(NO_RATE_INPUT_VERSION) {
                NO_RATE_INPUT_VERSION
            } else {
                FORMAT_VERSION
            };
            let (model, rest) = envelope::split(bytes, MAGIC, version).map_err(ArtifactError::Envelope)?;
            let training = envelope::open(rest, TRAINING_MAGIC, version).map_err(ArtifactError::TrainingEnvelope)?;
            let (mut model, mut training) = (model.to_vec(), training.to_vec());
            if version == MLP_DECODER_VERSION {
                // Format 5 appended `decoder_basis` (false) and the summary's `candidates`
                // (an empty list).
                model.push(0);
                training.push(0);
            }
            if version <= ONE_FRAME_TIME_VERSION {
                // Format 6 appended `dt_range` ([0, 0]: one frame time; two f64 of 8 bytes)
                // and `collider_shapes` (none: an empty list, one byte).
                model.extend([0; 17]);
            }
            if version <= NO_RENDER_VERSION {
                // Format 7 appended the render mesh (none: four empty lists, a byte each).
                model.extend([0; 4]);
            }
            if version <= NO_RATE_INPUT_VERSION {
                // Format 8 appended `rate_input` (false: a timed integrator reads `z_{t-2}`).
                model.push(0);
            }
            Artifact::from_sections(
                Payload::decode(&model).map_err(decode("model section"))?,
                postcard::from_bytes(&training).map_err(decode("training section"))?,
            )?
        };
        artifact
            .validate()
            .map_err(|(field, message)| ArtifactError::Invalid { field, message })?;
        // What the runtime will read must pass the runtime's own checks too.
        let mut runtime = mochi_runtime::OwnedModel::default();
        if header.map(|h| h.version) == Ok(FORMAT_VERSION) {
            runtime.load(bytes)?;
        } else {
            runtime.load(&artifact.to_bytes()?)?;
        }
        Ok(artifact)
    }

    /// Parses and validates an artifact; `source` names it in errors.
    pub fn from_bytes(bytes: &[u8], source: &Path) -> Result<Artifact, InputError> {
        Artifact::parse(bytes).map_err(|e| e.in_file(source))
    }

    /// Writes the artifact atomically.
    pub fn write(&self, path: &Path) -> Result<(), ArtifactError> {
        let bytes = self.to_bytes()?;
        crate::learn::train::write_atomically(path, &bytes).map_err(|source| ArtifactError::Write {
            path: path.to_path_buf(),
            source,
        })
    }

    /// Reads and validates an artifact file.
    pub fn read(path: &Path) -> Result<Artifact, InputError> {
        let bytes = std::fs::read(path).map_err(|e| InputError::file(path, format!("cannot read: {e}")))?;
        Artifact::from_bytes(&bytes, path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mochi_runtime::envelope::EnvelopeError;
    use mochi_runtime::LoadError;

    #[test]
    fn negligible_weights_are_written_as_zero_and_the_rest_unchanged() {
        let layer = DenseLayer {
            rows: 2,
            cols: 3,
            weights: vec![0.5, -3.0e-39, 1.0e-13, -2.0, 1.0e-11, f32::NAN],
            bias: vec![1.0e-30, 0.25],
        };
        let written = layer_data(&layer);
        assert_eq!(&written.weights[..5], &[0.5, 0.0, 0.0, -2.0, 1.0e-11]);
        assert!(written.weights[5].is_nan());
        assert_eq!(written.bias, vec![0.0, 0.25]);
    }

    fn tiny() -> (Vec<u8>, Artifact) {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/artifacts/tiny.mochi");
        let bytes = std::fs::read(&path).unwrap();
        let artifact = Artifact::parse(&bytes).unwrap();
        (bytes, artifact)
    }

    #[test]
    fn artifact_bytes_round_trip_and_the_first_section_is_the_runtime_payload() {
        let (bytes, artifact) = tiny();
        assert_eq!(artifact.to_bytes().unwrap(), bytes);
        let (payload, training) = artifact.sections().unwrap();
        let first = mochi_runtime::artifact::payload(&bytes).unwrap();
        assert_eq!(Payload::decode(first).unwrap(), payload);
        assert_eq!(Artifact::from_sections(payload, training).unwrap(), artifact);
    }

    #[test]
    fn artifact_of_format_2_is_still_read() {
        let (_, artifact) = tiny();
        let old = envelope::wrap(MAGIC, 2, &postcard::to_allocvec(&artifact).unwrap());
        assert_eq!(Artifact::parse(&old).unwrap(), artifact);
        let err = mochi_runtime::OwnedModel::default().load(&old).unwrap_err();
        assert_eq!(
            err,
            LoadError::Envelope(EnvelopeError::Version {
                found: 2,
                expected: FORMAT_VERSION
            })
        );
    }

    /// The committed tiny artifact written in the older format `version`, whose model section
    /// ends `shorter` bytes before this format's, read by the trainer (the same artifact) and
    /// loaded by the runtime.
    fn older(version: u32, shorter: usize) -> mochi_runtime::OwnedModel {
        let (bytes, artifact) = tiny();
        let (model, rest) = envelope::split(&bytes, MAGIC, FORMAT_VERSION).unwrap();
        let training = envelope::open(rest, TRAINING_MAGIC, FORMAT_VERSION).unwrap();
        let mut old = envelope::wrap(MAGIC, version, &model[..model.len() - shorter]);
        old.extend(envelope::wrap(TRAINING_MAGIC, version, training));
        assert_eq!(Artifact::parse(&old).unwrap(), artifact, "format {version}");
        let mut runtime = mochi_runtime::OwnedModel::default();
        runtime.load(&old).unwrap();
        runtime
    }

    #[test]
    fn artifacts_of_formats_5_6_and_7_are_still_read_by_the_trainer_and_the_runtime() {
        // Format 5 is format 8 without the model section's last fields (`dt_range`, 16 bytes,
        // an empty `collider_shapes`, 1 byte, no render mesh, 4 bytes, and `rate_input`, 1).
        assert_eq!(older(ONE_FRAME_TIME_VERSION, 22).model().unwrap().model().dt_max, 0.0);
        // Format 6 is format 8 without the render mesh (four empty lists, 4 bytes) and
        // `rate_input` (1 byte).
        assert!(!older(NO_RENDER_VERSION, 5).model().unwrap().model().has_render());
        // Format 7 is format 8 without `rate_input` (1 byte, `false`).
        assert!(!older(NO_RATE_INPUT_VERSION, 1).model().unwrap().model().rate_input);
    }

    #[test]
    fn artifact_without_its_training_section_is_refused_by_the_trainer_only() {
        let (bytes, _) = tiny();
        let (model, _) = envelope::split(&bytes, MAGIC, FORMAT_VERSION).unwrap();
        let first = &bytes[..envelope::HEADER_LEN + model.len()];
        assert!(mochi_runtime::OwnedModel::default().load(first).is_ok());
        let err = Artifact::parse(first).unwrap_err().to_string();
        assert!(err.contains("training section"), "{err}");
        let mut damaged = bytes.clone();
        *damaged.last_mut().unwrap() ^= 1;
        assert!(matches!(
            Artifact::parse(&damaged),
            Err(ArtifactError::TrainingEnvelope(EnvelopeError::Corrupt))
        ));
    }
}
