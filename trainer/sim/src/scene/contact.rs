//! The scene's `[contact]` table: IPC contact (barrier, lagged friction, CCD-filtered line
//! search; `docs/design.md`, decision 8) and the static obstacle meshes it acts against.
//!
//! ```toml
//! [contact]
//! dhat = 1e-3        # barrier activation distance (m), default 1e-3
//! friction = 0.5     # Coulomb coefficient, default 0 (frictionless)
//! epsv = 1e-3        # friction smoothing velocity (m/s), default 1e-3
//! self = false       # self-contact of the body, default false
//!
//! [[contact.obstacles]]
//! type = "box"       # a box's 12 outward triangles
//! min = [-1.0, -0.1, -1.0]
//! max = [1.0, 0.0, 1.0]
//! rotation = [0.0, 0.0, 0.1]  # optional: rotation vector (rad) about the box's centre
//!
//! [[contact.obstacles]]
//! type = "file"      # a triangle mesh (OBJ), moved by `offset` after `scale`
//! path = "ground.obj"
//! # optional scripted motion, on any obstacle: [time (s), dx, dy, dz] translations,
//! # linear in between, held before the first and after the last
//! keyframes = [[0.0, 0.0, 0.0, 0.0], [1.0, 0.0, -0.05, 0.0]]
//! ```
//!
//! Without a `[contact]` table the body has no IPC contact (the analytic `obstacles` and
//! their penalty still work either way).

use crate::contact::surface::triangle_edges;
use crate::contact::ContactSurface;
use crate::error::InputError;
use crate::mesh::{self, Elements};
use crate::solver::{ContactConfig, ContactObstacle, ContactSettings};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The `[contact]` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactSpec {
    /// Barrier activation distance (m).
    #[serde(default = "default_dhat")]
    pub dhat: f64,
    /// Coulomb friction coefficient.
    #[serde(default)]
    pub friction: f64,
    /// Friction smoothing velocity (m/s).
    #[serde(default = "default_epsv")]
    pub epsv: f64,
    /// Whether the body contacts itself.
    #[serde(rename = "self", default)]
    pub self_contact: bool,
    /// Static obstacle meshes.
    #[serde(default)]
    pub obstacles: Vec<ObstacleMesh>,
}

fn default_dhat() -> f64 {
    ContactSettings::default().dhat
}
fn default_epsv() -> f64 {
    ContactSettings::default().epsv
}

/// A static obstacle mesh.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ObstacleMesh {
    /// An axis-aligned box, as its 12 outward-facing triangles.
    Box {
        /// Lower corner.
        min: [f64; 3],
        /// Upper corner.
        max: [f64; 3],
        /// Rotation about the box's centre, as a rotation vector (axis times angle in
        /// radians); default none.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        rotation: Option<[f64; 3]>,
        /// Scripted translation `[time, dx, dy, dz]` (default none: static).
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        keyframes: Vec<[f64; 4]>,
    },
    /// A triangle mesh file (OBJ).
    File {
        /// Path, relative to the scene file.
        path: PathBuf,
        /// Uniform scale applied first (default 1).
        #[serde(default = "one")]
        scale: f64,
        /// Translation applied after the scale.
        #[serde(default)]
        offset: [f64; 3],
        /// Scripted translation `[time, dx, dy, dz]` (default none: static).
        #[serde(default, skip_serializing_if = "Vec::is_empty")]
        keyframes: Vec<[f64; 4]>,
    },
}

fn one() -> f64 {
    1.0
}

impl ContactSpec {
    /// The solver's parameters.
    pub fn settings(&self) -> ContactSettings {
        ContactSettings {
            dhat: self.dhat,
            friction: self.friction,
            epsv: self.epsv,
            self_contact: self.self_contact,
        }
    }

    /// Checks ranges; errors name the field (`contact.dhat`, `contact.obstacles[1].max`).
    pub fn validate(&self) -> Result<(), (String, String)> {
        self.settings()
            .validate()
            .map_err(|(f, msg)| (format!("contact.{f}"), msg))?;
        for (k, o) in self.obstacles.iter().enumerate() {
            let field = |f: &str| format!("contact.obstacles[{k}].{f}");
            check_keyframes(o.keyframes()).map_err(|msg| (field("keyframes"), msg))?;
            match o {
                ObstacleMesh::Box { min, max, rotation, .. } => {
                    if rotation.is_some_and(|r| !r.iter().all(|c| c.is_finite())) {
                        return Err((field("rotation"), "must be finite".into()));
                    }
                    if !min.iter().chain(max).all(|c| c.is_finite()) {
                        return Err((field("min"), "corners must be finite".into()));
                    }
                    if !(0..3).all(|i| min[i] < max[i]) {
                        return Err((field("max"), "must exceed min along every axis".into()));
                    }
                }
                ObstacleMesh::File { scale, offset, .. } => {
                    if !(scale.is_finite() && *scale > 0.0) {
                        return Err((field("scale"), format!("must be positive and finite, got {scale}")));
                    }
                    if !offset.iter().all(|c| c.is_finite()) {
                        return Err((field("offset"), "must be finite".into()));
                    }
                }
            }
        }
        Ok(())
    }

    /// The solver's contact configuration for a body with surface `surface`; mesh paths
    /// resolve against `scene_file`'s directory.
    pub fn build(&self, surface: ContactSurface, scene_file: &Path) -> Result<ContactConfig, InputError> {
        if surface.dim != 3 && !self.obstacles.is_empty() {
            return Err(InputError::field(
                scene_file,
                "contact.obstacles",
                "obstacle meshes need a 3D body",
            ));
        }
        let obstacles = self
            .obstacles
            .iter()
            .enumerate()
            .map(|(k, o)| o.build(scene_file, &format!("contact.obstacles[{k}]")))
            .collect::<Result<_, _>>()?;
        Ok(ContactConfig {
            settings: self.settings(),
            surface,
            obstacles,
            colliders: Vec::new(),
        })
    }
}

/// Keyframe times must be finite and increasing, offsets finite.
fn check_keyframes(keyframes: &[[f64; 4]]) -> Result<(), String> {
    if let Some(k) = keyframes.iter().position(|f| !f.iter().all(|c| c.is_finite())) {
        return Err(format!("keyframe {k} is not finite"));
    }
    if let Some(k) = keyframes.windows(2).position(|w| w[1][0] <= w[0][0]) {
        return Err(format!("keyframe {} must come after keyframe {k} in time", k + 1));
    }
    Ok(())
}

impl ObstacleMesh {
    /// The scripted motion (empty: static).
    pub fn keyframes(&self) -> &[[f64; 4]] {
        match self {
            ObstacleMesh::Box { keyframes, .. } | ObstacleMesh::File { keyframes, .. } => keyframes,
        }
    }

    fn build(&self, scene_file: &Path, field: &str) -> Result<ContactObstacle, InputError> {
        let (positions, faces) = match self {
            ObstacleMesh::Box { min, max, rotation, .. } => {
                let (mut positions, faces) = box_triangles(*min, *max);
                if let Some(r) = rotation {
                    let rot = nalgebra::Rotation3::new(nalgebra::Vector3::from(*r));
                    let c = nalgebra::Vector3::from([0, 1, 2].map(|i| 0.5 * (min[i] + max[i])));
                    for p in positions.chunks_mut(3) {
                        let q = rot * (nalgebra::Vector3::new(p[0], p[1], p[2]) - c) + c;
                        p.copy_from_slice(q.as_slice());
                    }
                }
                (positions, faces)
            }
            ObstacleMesh::File {
                path, scale, offset, ..
            } => {
                let full = scene_file.parent().unwrap_or(Path::new(".")).join(path);
                let mesh = mesh::io::load(&full, mesh::io::MeshKind::Cloth)?;
                let Elements::Shell(tris) = mesh.elements else {
                    return Err(InputError::field(scene_file, field, "needs a triangle mesh"));
                };
                let positions = mesh
                    .rest
                    .chunks(3)
                    .flat_map(|p| [0, 1, 2].map(|i| scale * p[i] + offset[i]))
                    .collect();
                (positions, tris)
            }
        };
        let mut vertices: Vec<usize> = faces.iter().flatten().copied().collect();
        vertices.sort_unstable();
        vertices.dedup();
        Ok(ContactObstacle {
            surface: ContactSurface {
                dim: 3,
                vertices,
                edges: triangle_edges(&faces),
                faces,
            },
            positions,
            keyframes: self.keyframes().to_vec(),
        })
    }
}

/// The 8 corners and 12 outward triangles of the box `[min, max]`.
pub fn box_triangles(min: [f64; 3], max: [f64; 3]) -> (Vec<f64>, Vec<[usize; 3]>) {
    // Corner k has coordinate i at max when bit i of k is set.
    let positions = (0..8)
        .flat_map(|k: usize| [0, 1, 2].map(|i| if k >> i & 1 == 1 { max[i] } else { min[i] }))
        .collect();
    // Each face as a counter-clockwise quad seen from outside.
    let quads = [
        [0, 4, 6, 2], // x = min
        [1, 3, 7, 5], // x = max
        [0, 1, 5, 4], // y = min
        [2, 6, 7, 3], // y = max
        [0, 2, 3, 1], // z = min
        [4, 5, 7, 6], // z = max
    ];
    let faces = quads
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .collect();
    (positions, faces)
}
