//! The tables of a scene file below the top level: mesh, material, regions, handles, loads,
//! collision and dataset sampling, each with its defaults.

use crate::bc::{MotionSpec, Segment};
use crate::material::MaterialLaw;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Where the geometry comes from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum MeshSpec {
    /// Tetrahedral grid of a box.
    Box {
        /// Lower corner.
        min: [f64; 3],
        /// Upper corner.
        max: [f64; 3],
        /// Cells per axis (6 tets per cell).
        cells: [usize; 3],
    },
    /// Tet mesh of a ball.
    Ball {
        /// Centre.
        center: [f64; 3],
        /// Radius.
        radius: f64,
        /// Grid cells across the diameter (default 6).
        #[serde(default = "default_ball_cells")]
        cells: usize,
    },
    /// Triangulated cloth grid.
    ClothGrid {
        /// Side lengths along the two axes.
        size: [f64; 2],
        /// Vertices along the two axes.
        verts: [usize; 2],
        /// Corner position.
        #[serde(default)]
        origin: [f64; 3],
        /// The two in-plane axes.
        #[serde(default = "default_cloth_axes")]
        axes: [[f64; 3]; 2],
    },
    /// A group of straight rods hanging from roots on a grid.
    Rods {
        /// Number of rods.
        count: usize,
        /// Vertices per rod.
        verts_per_rod: usize,
        /// Rod length.
        length: f64,
        /// Distance between neighbouring roots.
        spacing: f64,
        /// Direction from root to tip.
        #[serde(default = "default_rod_direction")]
        direction: [f64; 3],
        /// Centre of the root grid.
        #[serde(default)]
        origin: [f64; 3],
    },
    /// A mesh file: MEDIT `.mesh`, TetGen/Triangle `.node` (+ `.ele`), or `.obj`.
    File {
        /// Path, relative to the scene file.
        path: PathBuf,
        /// Centre on the bounding box and divide by the largest extent first.
        #[serde(default)]
        normalize: bool,
        /// Per-axis scale applied after normalisation.
        #[serde(default)]
        scale: Option<Vec<f64>>,
        /// How to read an OBJ file (`cloth` or `rods`); ignored for other formats.
        #[serde(default)]
        kind: Option<String>,
        /// A render mesh riding on this tet mesh: the `NAME.render.npz` that `mochi mesh`
        /// writes beside it, relative to the scene file; a trained model then carries it and
        /// the runtime decodes it. None by default.
        #[serde(default)]
        render: Option<PathBuf>,
    },
    /// Several bodies of one kind in one scene (`parts = [{ type = "box", ... }, ...]`),
    /// never joined by an element; they meet through contact (`[contact] self = true`).
    Parts {
        /// The bodies, each any of the other mesh types.
        parts: Vec<MeshSpec>,
    },
}

impl MeshSpec {
    /// Whether this mesh, or any of its parts, is of the kind `is` picks.
    pub fn any(&self, is: &dyn Fn(&MeshSpec) -> bool) -> bool {
        match self {
            MeshSpec::Parts { parts } => parts.iter().any(|p| p.any(is)),
            other => is(other),
        }
    }

    /// The same body with about half the cells along each axis (at least one; rods and cloth
    /// keep their end vertices): the coarse-mesh method of `mochi compare`. `None` for a mesh
    /// read from a file, which has no resolution to change.
    pub fn coarsened(&self) -> Option<MeshSpec> {
        let half = |cells: usize| cells.div_ceil(2).max(1);
        Some(match self {
            MeshSpec::Box { min, max, cells } => MeshSpec::Box {
                min: *min,
                max: *max,
                cells: cells.map(half),
            },
            MeshSpec::Ball { center, radius, cells } => MeshSpec::Ball {
                center: *center,
                radius: *radius,
                cells: half(*cells),
            },
            MeshSpec::ClothGrid {
                size,
                verts,
                origin,
                axes,
            } => MeshSpec::ClothGrid {
                size: *size,
                verts: verts.map(|v| half(v.saturating_sub(1)) + 1),
                origin: *origin,
                axes: *axes,
            },
            MeshSpec::Rods {
                count,
                verts_per_rod,
                length,
                spacing,
                direction,
                origin,
            } => MeshSpec::Rods {
                count: *count,
                verts_per_rod: half(verts_per_rod.saturating_sub(1)) + 1,
                length: *length,
                spacing: *spacing,
                direction: *direction,
                origin: *origin,
            },
            MeshSpec::File { .. } => return None,
            MeshSpec::Parts { parts } => MeshSpec::Parts {
                parts: parts.iter().map(MeshSpec::coarsened).collect::<Option<_>>()?,
            },
        })
    }
}

fn default_ball_cells() -> usize {
    6
}
fn default_cloth_axes() -> [[f64; 3]; 2] {
    [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
}
fn default_rod_direction() -> [f64; 3] {
    [0.0, -1.0, 0.0]
}

/// Material of the body, optionally varying by region.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    /// Constitutive model of solids and membranes.
    #[serde(default)]
    pub model: MaterialLaw,
    /// Young's modulus (Pa).
    pub youngs: f64,
    /// Poisson ratio.
    pub poisson: f64,
    /// Density (kg / m^3).
    pub density: f64,
    /// Cloth thickness (m); required for cloth.
    #[serde(default)]
    pub thickness: Option<f64>,
    /// Rod radius (m); required for rods.
    #[serde(default)]
    pub radius: Option<f64>,
    /// Regions overriding parameters for the elements they select (by centroid in a box or
    /// by mesh file attribute), applied in order.
    #[serde(default)]
    pub regions: Vec<RegionSpec>,
}

/// A region of different material (heterogeneous bodies).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionSpec {
    /// Box the element centroids must lie in (exactly one of `box` and `attribute`).
    #[serde(rename = "box", default, skip_serializing_if = "Option::is_none")]
    pub bounds: Option<BoxSpec>,
    /// Element attribute from the mesh file (a TetGen / Triangle `.ele` region attribute or a
    /// MEDIT element reference) of the elements it takes (exactly one of `box` and `attribute`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attribute: Option<i64>,
    /// Young's modulus override.
    #[serde(default)]
    pub youngs: Option<f64>,
    /// Poisson ratio override.
    #[serde(default)]
    pub poisson: Option<f64>,
    /// Density override.
    #[serde(default)]
    pub density: Option<f64>,
}

pub use crate::mesh::BoxSpec;

/// Which vertices a handle or load acts on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum Selection {
    /// Vertices inside a box.
    Box(BoxSpec),
    /// Explicit 0-based vertex indices.
    Indices(Vec<usize>),
    /// The first `n` vertices of every rod.
    RodRoots(usize),
    /// The rest vertex nearest to each point.
    Nearest(Vec<[f64; 3]>),
    /// Vertices within `tolerance` (relative to the extent) of one end of an axis.
    Side {
        /// Axis 0, 1 or 2.
        axis: usize,
        /// `min` or `max`.
        end: End,
        /// Relative tolerance (default 1e-3).
        #[serde(default = "default_side_tolerance")]
        tolerance: f64,
    },
}

fn default_side_tolerance() -> f64 {
    1e-3
}

/// One end of an axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum End {
    /// Smallest coordinate.
    Min,
    /// Largest coordinate.
    Max,
}

/// A handle: prescribed vertices moved rigidly.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandleSpec {
    /// Name.
    pub name: String,
    /// The vertices.
    pub select: Selection,
    /// Per-axis scale of the handle's reference placement about the centre of the mesh's
    /// rest bounding box (e.g. to compress a bar between its two clamped ends).
    #[serde(default)]
    pub reference_scale: Option<[f64; 3]>,
    /// Rotation pivot (default: centroid of the selected rest vertices).
    #[serde(default)]
    pub pivot: Option<[f64; 3]>,
    /// How sampled sequences move it (absent: it stays put).
    #[serde(default)]
    pub motion: Option<MotionSpec>,
    /// A fixed script used instead of sampling when present.
    #[serde(default)]
    pub script: Vec<Segment>,
}

/// A constant force spread over selected vertices.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoadSpec {
    /// The vertices.
    pub select: Selection,
    /// Total force (N).
    pub force: [f64; 3],
}

/// Collision energy parameters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CollisionSpec {
    /// Stiffness (acceleration scale per unit penetration squared).
    pub stiffness: f64,
    /// Distance at which the energy starts acting.
    pub margin: f64,
}

impl Default for CollisionSpec {
    fn default() -> Self {
        CollisionSpec {
            stiffness: 1e5,
            margin: 0.01,
        }
    }
}

/// Train or test.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    /// Used for training.
    Train,
    /// Held out for evaluation.
    Test,
    /// Held out from training, for choosing between trained candidates (`mochi train`'s
    /// model selection); never used by evaluation.
    Validation,
}

impl Split {
    /// Lower-case name.
    pub fn as_str(self) -> &'static str {
        match self {
            Split::Train => "train",
            Split::Test => "test",
            Split::Validation => "validation",
        }
    }
}

/// Initial state.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Start {
    /// The rest shape, at rest.
    #[default]
    Rest,
    /// Static equilibrium with the handles at their frame-0 placement.
    Static,
}

/// How `mochi dataset` samples sequences.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DatasetSpec {
    /// Training sequences (speed levels evenly spaced over the training range).
    pub train: usize,
    /// Test sequences (held-out speeds between training levels, speeds beyond the range,
    /// and a sudden speed change).
    pub test: usize,
    /// Frames per sequence.
    pub frames: usize,
    /// Random seed.
    pub seed: u64,
    /// Largest test speed as a multiple of the top of the training range.
    pub beyond: f64,
    /// Frames per test sequence (default: `frames`); evaluation measures accuracy over these.
    pub test_frames: Option<usize>,
    /// Extra training sequences at the top training speed in a steady rhythm: all segments
    /// of one sequence last one length, the lengths spread evenly over each motion's
    /// `segment_frames`. Meant to drive a swinging body near its resonance; on `cloth-line`
    /// the swings grew little, but the latent space of these frames follows the fast test
    /// motions far better (docs/notes/2026-11-24-steady-rhythm-training.md). Default 0.
    pub steady: usize,
    /// Extra training sequences whose speed level is drawn anew, uniformly over the training
    /// range, every `dataset::VARIED_PIECE_FRAMES` frames: fast and slow motions in
    /// one sequence, so the training states include a body still swinging from a fast
    /// motion while its handles move slowly. Default 0.
    pub varied: usize,
    /// Validation sequences (held-out constant speed levels, `frames` long each), made by
    /// `mochi train` for its model selection. Default 2.
    pub validation: usize,
    /// `[lowest, highest]` frame rate (frames per second) of the training and validation
    /// sequences, for a learned integrator that takes the frame time as an input and serves a
    /// host's own frame rate (72, 90, 120 Hz on a headset): the sequences' rates spread
    /// geometrically over the range (in an order shuffled by the seed, so that rates and speed
    /// levels do not go together), each sequence the scene's motion at that rate over the same
    /// seconds (`frames` of `dt`: 120 frames per second gives four times the frames of 30),
    /// simulated with a time step of one frame. Test sequences stay at the
    /// scene's own `dt` (`mochi eval --rates` measures others). Default none: every sequence at
    /// `dt`.
    pub frame_rates: Option<[f64; 2]>,
}

impl Default for DatasetSpec {
    fn default() -> Self {
        DatasetSpec {
            train: 6,
            test: 4,
            frames: 120,
            seed: 1,
            beyond: 1.5,
            test_frames: None,
            steady: 0,
            varied: 0,
            validation: 2,
            frame_rates: None,
        }
    }
}

impl DatasetSpec {
    /// The `(shortest, longest)` frame time of the training sequences, when they span a range
    /// of frame rates ([`DatasetSpec::frame_rates`]).
    pub fn frame_times(&self) -> Option<(f64, f64)> {
        self.frame_rates.map(|[lo, hi]| (1.0 / hi, 1.0 / lo))
    }

    /// Frames of a sequence of `split`.
    pub fn frames_of(&self, split: Split) -> usize {
        match split {
            Split::Train | Split::Validation => self.frames,
            Split::Test => self.test_frames.unwrap_or(self.frames),
        }
    }
}
