//! Model artifacts (`SCENE.mochi`): everything the runtime needs to step and decode a trained
//! model, as data, and what the trainer keeps beside it (docs/design.md, decision 4). The file
//! ([`file`]) is written through the runtime's envelope (magic, format version, length,
//! CRC-32) and payload schema, so corrupt, truncated or foreign files are refused before
//! parsing, and every shape is validated after it.
//!
//! Networks are stored as flat lists of dense layers in the order of
//! [`ExportedMlp::layers`]: `[input, inner_0, outer_0, ..., output]`, with
//! `h = input(x); h += outer_j(swish(inner_j(h))); y = output(swish(h))`. Normalisations are
//! folded into the first and last layers. The integrator predicts the increment
//! `z_t - z_{t-1}` from `[z_{t-1}, z_{t-2}, p_t, p_{t-1}, p_{t-2}]`.

pub mod file;
mod format3;
pub mod reduced;
pub mod render;
pub mod section;

use serde::{Deserialize, Serialize};

use crate::learn::encoding::{Encoding, Origins};
use crate::learn::network::{DenseLayer, ExportedIntegrator, ExportedMlp, FrozenDecoder, NetworkError};

pub use mochi_runtime::artifact::{FORMAT_VERSION, MAGIC};
/// One rod strand of the bend encoding (see [`crate::learn::encoding::Chain`]): the runtime's
/// record, stored as is.
pub use mochi_runtime::payload::ChainData;
/// The render mesh embedded in the simulation mesh: the runtime's record, stored as is.
pub use mochi_runtime::payload::RenderData;
pub use section::{ArtifactError, TrainingSection, TRAINING_MAGIC};

/// How an artifact's integrator was trained.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Method {
    /// On the full-space incremental potential of the decoded state (Eq. 4-6), with the
    /// supervised objective added where the scene's `latent.data_weight` is positive.
    SelfSupervised,
    /// L2 on ground-truth latents (the baseline).
    Supervised,
}

impl Method {
    /// Name used in reports and charts.
    pub fn label(self) -> &'static str {
        match self {
            Method::SelfSupervised => "self-supervised",
            Method::Supervised => "supervised",
        }
    }
}

/// How full states are encoded relative to the boundary conditions (see [`Encoding`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EncodingData {
    /// Whether the handles' best-fit rotation is removed.
    pub rotates: bool,
    /// Prescribed vertices, in handle-target order.
    pub handle_vertices: Vec<u32>,
    /// Their identity-pose targets (`dim` per vertex), the reference of the rotation fit.
    pub reference: Vec<f32>,
    /// Encoded vertices, in encoded order.
    pub free_vertices: Vec<u32>,
    /// Per encoded vertex, the index of its origin.
    pub origin_of: Vec<u32>,
    /// Empty: one origin, the centroid of the handle targets. Otherwise, per rod strand, the
    /// slot of its root among the handle vertices.
    pub root_slots: Vec<u32>,
    /// Empty: encoded vertices are positions. Otherwise the rod strands, encoded by their
    /// bends ([`crate::learn::encoding::Encoding::with_strand_bends`]), two numbers per vertex.
    pub chains: Vec<ChainData>,
}

impl EncodingData {
    /// The data of `encoding`.
    pub fn new(encoding: &Encoding) -> Self {
        let u32s = |v: &[usize]| v.iter().map(|&i| i as u32).collect();
        EncodingData {
            rotates: encoding.rotates(),
            handle_vertices: u32s(encoding.handle_vertices()),
            reference: encoding.reference().iter().map(|&v| v as f32).collect(),
            free_vertices: u32s(encoding.free_vertices()),
            origin_of: u32s(encoding.origin_of()),
            root_slots: match encoding.origins() {
                Origins::HandleCentroid => Vec::new(),
                Origins::StrandRoots { root_slots } => u32s(root_slots),
            },
            chains: encoding
                .chains()
                .iter()
                .map(|c| ChainData {
                    parent: c.parent.map(|s| s as u32),
                    rest_normal: [0, 1, 2].map(|i| c.rest_normal[i] as f32),
                    slots: u32s(&c.slots),
                    lengths: c.lengths.iter().map(|&l| l as f32).collect(),
                })
                .collect(),
        }
    }
}

/// A handle: prescribed vertices moved rigidly about a pivot.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HandleData {
    /// Name from the scene.
    pub name: String,
    /// Prescribed vertices.
    pub vertices: Vec<u32>,
    /// Their identity-pose positions, 3 per vertex.
    pub reference: Vec<f32>,
    /// Rotation pivot at the identity pose.
    pub pivot: [f32; 3],
}

/// One latent size tried while choosing the latent space.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SizeTrial {
    /// Latent size.
    pub size: u32,
    /// RMS vertex error / diagonal of PCA with this many components on the training frames.
    pub pca_error: f64,
    /// The same for the trained autoencoder; `None` when it was not trained (PCA far off).
    pub autoencoder_error: Option<f64>,
}

/// How the model was made: sizes tried, time per stage, final losses.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainingSummary {
    /// Reconstruction tolerance of the scene.
    pub tolerance: f64,
    /// Every size tried, ascending.
    pub trials: Vec<SizeTrial>,
    /// Wall-clock seconds per stage, in order (`dataset`, `autoencoder k=..`, ...).
    pub stage_seconds: Vec<(String, f64)>,
    /// Mean loss of the integrator's last epoch.
    pub final_loss: f64,
    /// Training samples of the integrator (clean ones; noise doubles them).
    pub samples: u64,
    /// Largest distance of a vertex from its encoding origin over the training frames
    /// (evaluation counts a rollout as diverged beyond this plus half the diagonal).
    pub max_radius: f64,
    /// Largest kinetic energy over the training frames.
    pub max_kinetic_energy: f64,
    /// Every model tried by the selection over cost, in the order tried (empty for artifacts
    /// of format 4 and older). Last, so that an older training section followed by one `0x00`
    /// byte (an empty list) reads as this one.
    pub candidates: Vec<CandidateRow>,
}

/// One model `mochi train` tried while selecting over cost (`latent.selection`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CandidateRow {
    /// Decoder family: `linear`, `mlp + basis`, `mlp` or `distilled` (a basis decoder fitted
    /// to an `mlp` candidate's decoder, with that candidate's integrator).
    pub decoder: String,
    /// Latent size.
    pub latent: u32,
    /// Columns of the decoder's basis (0 for a residual MLP decoder).
    pub modes: u32,
    /// Hidden width of the decoder's MLP (0 for a linear decoder).
    pub decoder_width: u32,
    /// Hidden width of the integrator (0: none trained, the decoder missed the tolerance).
    pub integrator_width: u32,
    /// RMS vertex error / diagonal of the decoder's reconstruction of the training frames
    /// (a distilled decoder's: of the frames encoded by its teacher's encoder).
    pub reconstruction: f64,
    /// Mean over the validation sequences of the rollout's mean vertex error / diagonal
    /// (infinite when a rollout diverged inside its window or none was run).
    pub validation_error: f64,
    /// Fewest frames any validation rollout ran before diverging.
    pub stable_frames: u64,
    /// Frames of each validation rollout.
    pub validation_frames: u64,
    /// Per weight storage (`f32`, `f16`, `int8`): bytes of weights and microseconds per frame
    /// (runtime step + full decode, one thread) measured while training.
    pub storages: Vec<(String, u64, f64)>,
    /// Multiply-adds per frame (integrator + full decode, with a bend-encoded model's strand
    /// walk, [`mochi_runtime::Model::walk_multiply_adds`]).
    pub multiply_adds: u64,
    /// Microseconds per frame of candle's batch-1 forward of the same networks.
    pub candle_microseconds: f64,
    /// Whether this is the model kept.
    pub kept: bool,
}

/// A trained model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Artifact {
    /// Scene name.
    pub scene: String,
    /// The scene file it was trained from, and its text (evaluation rebuilds the scene).
    pub scene_path: String,
    /// Scene TOML text.
    pub scene_toml: String,
    /// How the integrator was trained.
    pub method: Method,
    /// Time step in seconds.
    pub dt: f64,
    /// Coordinates per vertex (2 or 3).
    pub dim: u32,
    /// Vertices of the full mesh.
    pub num_vertices: u32,
    /// Rest positions, `dim` per vertex.
    pub rest: Vec<f32>,
    /// Rest bounding-box diagonal (the unit of every reported error).
    pub diagonal: f64,
    /// State encoding relative to the boundary conditions.
    pub encoding: EncodingData,
    /// Handles, in boundary-condition signal order.
    pub handles: Vec<HandleData>,
    /// Boundary-condition signal numbers per frame (12 per handle).
    pub bc_len: u32,
    /// Vertices that are drawn (surface of a tet mesh, all otherwise), ascending.
    pub surface_vertices: Vec<u32>,
    /// Triangles to draw (full-mesh vertex indices, all of them drawn vertices); empty for
    /// rods. The model section holds them over the drawn vertices.
    pub surface_triangles: Vec<[u32; 3]>,
    /// Polylines to draw for rods (full-mesh vertex indices).
    pub polylines: Vec<Vec<u32>>,
    /// Latent size.
    pub latent: u32,
    /// Latent of the scene's initial state.
    pub initial_latent: Vec<f32>,
    /// Per latent coordinate, the smallest and largest value in the training data.
    pub latent_min: Vec<f32>,
    /// See `latent_min`.
    pub latent_max: Vec<f32>,
    /// PCA of the encoded training frames: mean (encoded length) ...
    pub pca_mean: Vec<f32>,
    /// ... and `latent` components, row-major (`latent x encoded length`).
    pub pca_basis: Vec<f32>,
    /// Encoder: encoded state -> latent.
    pub encoder: Vec<DenseLayer>,
    /// Decoder: latent -> encoded state.
    pub decoder: Vec<DenseLayer>,
    /// Whether the decoder's last layer is a linear basis ([`FrozenDecoder`]).
    pub decoder_basis: bool,
    /// Integrator: packed input -> latent increment.
    pub integrator: Vec<DenseLayer>,
    /// Shortest and longest frame time the integrator was trained at when it takes the frame
    /// time as an input (`[0, 0]`: one frame time, `dt`); see `mochi_runtime::Model::dt_max`.
    pub dt_range: [f64; 2],
    /// The run-time collider slots the integrator reads, a shape row `[code, a, b, c]` each
    /// (`mochi_runtime::Model::collider_shapes`); empty for a model without collider inputs.
    pub collider_shapes: Vec<f32>,
    /// The render mesh riding on the simulation mesh, from the scene's `mesh.render` (all
    /// lists empty without one); see `mochi_runtime::render`.
    pub render: RenderData,
    /// Whether the timed integrator reads the previous latent's change per frame of `dt` in
    /// place of `z_{t-2}` (`mochi_runtime::Model::rate_input`; what `mochi train` makes of
    /// every timed model since format 8).
    pub rate_input: bool,
    /// How it was made.
    pub summary: TrainingSummary,
}

impl Artifact {
    /// Whether the integrator takes the frame time as an input (packed after the signals).
    pub fn timed(&self) -> bool {
        self.dt_range[1] > 0.0
    }

    /// Number of run-time collider slots the integrator reads.
    pub fn colliders(&self) -> usize {
        self.collider_shapes.len() / mochi_runtime::collider::SHAPE_ROW
    }

    /// Length of an encoded state (`dim` per encoded vertex, 2 with strand bends).
    pub fn encoded_len(&self) -> usize {
        let per_vertex = if self.encoding.chains.is_empty() {
            self.dim as usize
        } else {
            2
        };
        self.encoding.free_vertices.len() * per_vertex
    }

    /// The encoder as a runnable network.
    pub fn encoder(&self) -> Result<ExportedMlp, NetworkError> {
        ExportedMlp::from_layers(self.encoder.clone())
    }

    /// The decoder as a runnable network.
    pub fn decoder(&self) -> Result<FrozenDecoder, NetworkError> {
        FrozenDecoder::from_layers(self.decoder.clone(), self.decoder_basis)
    }

    /// The integrator as a runnable network.
    pub fn integrator(&self) -> Result<ExportedIntegrator, NetworkError> {
        let mlp = ExportedMlp::from_layers(self.integrator.clone())?;
        let exported = ExportedIntegrator::new(self.latent as usize, mlp)?;
        Ok(match (self.timed(), self.rate_input) {
            (true, true) => exported.timed_at(self.dt).with_rate_input(),
            (true, false) => exported.timed_at(self.dt),
            (false, _) => exported,
        })
    }

    /// Checks every size and index, and that all numbers are finite; returns the offending
    /// field and a message.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let err = |field: &str, msg: String| Err((field.to_string(), msg));
        let dim = self.dim as usize;
        let n = self.num_vertices as usize;
        let k = self.latent as usize;
        if !(dim == 2 || dim == 3) {
            return err("dim", format!("must be 2 or 3, got {dim}"));
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.dt) || !positive(self.diagonal) {
            return err("dt", "time step and diagonal must be positive".into());
        }
        let [lo, hi] = self.dt_range;
        if !(lo == 0.0 && hi == 0.0 || positive(lo) && positive(hi) && lo <= hi) {
            return err(
                "dt_range",
                format!("must be [0, 0] or 0 < shortest <= longest frame time, got [{lo}, {hi}]"),
            );
        }
        if self.rate_input && !self.timed() {
            return err(
                "rate_input",
                "only an integrator that takes the frame time reads the latent's rate".into(),
            );
        }
        if self.rest.len() != n * dim {
            return err(
                "rest",
                format!("{} values for {n} vertices of dimension {dim}", self.rest.len()),
            );
        }
        let in_range = |v: &[u32]| v.iter().all(|&i| (i as usize) < n);
        let e = &self.encoding;
        if !in_range(&e.handle_vertices) || !in_range(&e.free_vertices) {
            return err("encoding", "vertex index out of range".into());
        }
        if e.handle_vertices.len() + e.free_vertices.len() != n {
            return err("encoding", "handle and free vertices do not partition the mesh".into());
        }
        if e.reference.len() != e.handle_vertices.len() * dim || e.origin_of.len() != e.free_vertices.len() {
            return err("encoding", "reference or origin table has the wrong length".into());
        }
        let origins = if e.root_slots.is_empty() { 1 } else { e.root_slots.len() };
        if e.origin_of.iter().any(|&o| o as usize >= origins)
            || e.root_slots.iter().any(|&s| s as usize >= e.handle_vertices.len())
        {
            return err("encoding", "origin index out of range".into());
        }
        if !e.chains.is_empty() {
            let mut covered = vec![false; e.free_vertices.len()];
            for c in &e.chains {
                let parents_ok =
                    c.parent.iter().all(|&s| (s as usize) < e.handle_vertices.len()) && c.parent[0] != c.parent[1];
                let lengths_ok =
                    c.lengths.len() == c.slots.len() && c.lengths.iter().all(|l| l.is_finite() && *l > 0.0);
                let normal_ok = (c.rest_normal.iter().map(|v| v * v).sum::<f32>() - 1.0).abs() < 1e-4;
                if !(parents_ok && lengths_ok && normal_ok && dim == 3) {
                    return err(
                        "encoding.chains",
                        "a strand's parent, lengths or rest normal is invalid".into(),
                    );
                }
                for &j in &c.slots {
                    match covered.get_mut(j as usize) {
                        Some(seen @ false) => *seen = true,
                        _ => {
                            return err(
                                "encoding.chains",
                                format!("encoded vertex {j} is out of range or on two strands"),
                            )
                        }
                    }
                }
            }
            if covered.contains(&false) {
                return err("encoding.chains", "some encoded vertex lies on no strand".into());
            }
        }
        let handle_count: usize = self.handles.iter().map(|h| h.vertices.len()).sum();
        if handle_count != e.handle_vertices.len()
            || self.handles.iter().any(|h| h.reference.len() != 3 * h.vertices.len())
        {
            return err("handles", "handle vertices disagree with the encoding".into());
        }
        if self.bc_len as usize != mochi_sim::bc::SIGNAL_PER_HANDLE * self.handles.len() {
            return err("bc_len", format!("{} for {} handles", self.bc_len, self.handles.len()));
        }
        if !in_range(&self.surface_vertices)
            || self.surface_triangles.iter().any(|t| !in_range(t))
            || self.polylines.iter().any(|p| !in_range(p))
        {
            return err("surface_vertices", "vertex index out of range".into());
        }
        let drawn = |v: &u32| self.surface_vertices.binary_search(v).is_ok();
        if let Some(v) = self.surface_triangles.iter().flatten().find(|v| !drawn(v)) {
            return err("surface_triangles", format!("vertex {v} is not a drawn vertex"));
        }
        let encoded = self.encoded_len();
        for (field, v, len) in [
            ("initial_latent", &self.initial_latent, k),
            ("latent_min", &self.latent_min, k),
            ("latent_max", &self.latent_max, k),
            ("pca_mean", &self.pca_mean, encoded),
            ("pca_basis", &self.pca_basis, k * encoded),
        ] {
            if v.len() != len {
                return err(field, format!("has {} values, expected {len}", v.len()));
            }
        }
        let nets = [
            ("encoder", &self.encoder, encoded, k),
            ("decoder", &self.decoder, k, encoded),
            (
                "integrator",
                &self.integrator,
                2 * k
                    + 3 * self.bc_len as usize
                    + mochi_runtime::collider::FEATURES_PER_COLLIDER * self.colliders()
                    + usize::from(self.timed()),
                k,
            ),
        ];
        for (field, layers, input, output) in nets {
            let wrong = |e: NetworkError| (field.to_string(), e.to_string());
            let (from, to) = if field == "decoder" {
                let decoder = FrozenDecoder::from_layers(layers.clone(), self.decoder_basis).map_err(wrong)?;
                (decoder.latent(), decoder.output())
            } else {
                let spec = ExportedMlp::from_layers(layers.clone()).map_err(wrong)?.spec();
                (spec.input, spec.output)
            };
            if from != input || to != output {
                return err(field, format!("maps {from} -> {to}, expected {input} -> {output}"));
            }
        }
        let all_finite = [&self.rest, &self.initial_latent, &self.pca_mean, &self.pca_basis]
            .into_iter()
            .flatten()
            .chain(
                self.encoder
                    .iter()
                    .chain(&self.decoder)
                    .chain(&self.integrator)
                    .flat_map(|l| l.weights.iter().chain(&l.bias)),
            )
            .all(|v| v.is_finite());
        if !all_finite {
            return err("weights", "hold a non-finite value".into());
        }
        Ok(())
    }
}
