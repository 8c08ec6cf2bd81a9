//! Simulated sequences and their numpy `.npz` files.
//!
//! A [`Trajectory`] is written as an uncompressed `.npz` archive that `numpy.load` opens
//! without `allow_pickle` (strings are fixed-width unicode arrays):
//!
//! | array | dtype | shape |
//! |---|---|---|
//! | `format_version` | uint32 | `()` |
//! | `scene` | unicode | `()` |
//! | `dt` | float64 | `()` |
//! | `positions` | float64 | `(frames, n, dim)` |
//! | `bc_signal` | float64 | `(frames, p)` |
//! | `energy_names` | unicode | `(k,)` |
//! | `energies` | float64 | `(frames, k)` |
//! | `newton_iterations` | uint32 | `(frames,)` |
//! | `step_seconds` | float64 | `(frames,)`, or `(0,)` where timings are not kept (dataset sequences: their bytes depend on nothing but the scene and the plan; the times are in the dataset's manifest) |
//! | `meta` | unicode | `(m, 2)`: key, value rows |
//! | `obstacle_faces` | uint32 | `(t, 3)`, only for scenes with obstacle meshes |
//! | `obstacle_positions` | float64 | `(frames, o, 3)`, with `obstacle_faces` |
//! | `collider_names` | unicode | `(K,)`, only for scenes with `[[colliders]]` |
//! | `collider_shapes` | float64 | `(K, 4)`, with `collider_names` |
//! | `collider_states` | float64 | `(frames, K, 12)`, with `collider_names` |
//!
//! A collider's shape row is `[code, a, b, c]`: sphere `[0, radius, 0, 0]`, capsule
//! `[1, radius, half_length, 0]` (its segment along the local y axis), box
//! `[2, hx, hy, hz]` (half side lengths). Its state row at a frame is its pose and velocity:
//! centre (3), rotation vector (3, local to world), linear velocity (3) and angular velocity
//! (3) over the step that ends at the frame (zero at frame 0); the metadata entry
//! `collider_layout` says the same. Files written before colliders existed have none of
//! these arrays and read as trajectories without colliders.
//!
//! Reading accepts compressed archives too (`numpy.savez_compressed`) and checks every
//! array's presence, dtype and shape; errors name the file and the array.

use std::io;
use std::path::Path;

use crate::error::{InputError, SimError};
use crate::npz::{NpzFile, NpzOut};

/// Version number stored in `format_version`; bumped when the layout changes.
pub const FORMAT_VERSION: u32 = 1;

/// One simulated sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    /// Scene name.
    pub scene: String,
    /// Time step in seconds.
    pub dt: f64,
    /// Coordinates per vertex: 2 or 3.
    pub dim: usize,
    /// Frames x (n * dim) vertex positions; frame 0 is the initial state.
    pub positions: Vec<Vec<f64>>,
    /// Frames x p boundary-condition signal per frame (e.g. handle velocity); p may be 0.
    pub bc_signal: Vec<Vec<f64>>,
    /// Names of the energy terms, e.g. `["inertia", "elastic", "gravity"]`.
    pub energy_names: Vec<String>,
    /// Frames x `energy_names.len()` energy values.
    pub energies: Vec<Vec<f64>>,
    /// Newton iterations per frame (0 for frame 0).
    pub newton_iterations: Vec<u32>,
    /// Wall time of each step in seconds (0 for frame 0); empty where timings are not kept.
    pub step_seconds: Vec<f64>,
    /// Free-form metadata (seed, speeds, `split` = train/test, ...).
    pub meta: Vec<(String, String)>,
    /// The contact obstacle meshes, frame by frame (scenes with `[[contact.obstacles]]`).
    pub obstacles: Option<ObstacleFrames>,
    /// The analytic colliders, frame by frame (scenes with `[[colliders]]`).
    pub colliders: Option<ColliderFrames>,
}

/// Analytic colliders over a sequence: their names, shapes, and poses and velocities at
/// every frame (the layout of the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct ColliderFrames {
    /// Names, in the scene's order.
    pub names: Vec<String>,
    /// Shape rows `[code, a, b, c]` ([`crate::contact::ColliderShape::parameters`]).
    pub shapes: Vec<[f64; 4]>,
    /// Frames x (K * 12) states: per collider centre, rotation vector, velocity, angular
    /// velocity.
    pub states: Vec<Vec<f64>>,
}

impl ColliderFrames {
    /// The colliders (shapes at their poses) at `frame`; rows that are not shapes are left
    /// out (a validated trajectory has none).
    pub fn colliders_at(&self, frame: usize) -> Vec<crate::contact::Collider> {
        self.shapes
            .iter()
            .zip(self.states[frame].chunks(COLLIDER_STATE))
            .filter_map(|(row, s)| {
                Some(crate::contact::Collider {
                    shape: crate::contact::ColliderShape::from_parameters(*row)?,
                    pose: crate::contact::ColliderPose::new([s[0], s[1], s[2]], [s[3], s[4], s[5]]),
                })
            })
            .collect()
    }
}

/// Numbers per collider in a `collider_states` row.
pub const COLLIDER_STATE: usize = crate::bc::colliders::STATE_PER_COLLIDER;

/// The `collider_layout` metadata entry.
pub const COLLIDER_LAYOUT: &str = "collider_shapes rows: [code, a, b, c] with sphere [0, radius, 0, 0], \
     capsule [1, radius, half_length (along local y), 0], box [2, hx, hy, hz]; collider_states per collider: \
     center(3), rotation_vector(3), velocity(3), angular_velocity(3)";

/// Contact obstacle meshes over a sequence: their triangles, and their vertices at every
/// frame (scripted obstacles move).
#[derive(Clone, Debug, PartialEq)]
pub struct ObstacleFrames {
    /// Triangles over the obstacle vertices.
    pub faces: Vec<[u32; 3]>,
    /// Frames x (o * 3) obstacle vertex positions.
    pub positions: Vec<Vec<f64>>,
}

impl Trajectory {
    /// Number of frames, including the initial state.
    pub fn num_frames(&self) -> usize {
        self.positions.len()
    }

    /// Number of vertices per frame (0 if there are no frames or `dim` is 0).
    pub fn num_vertices(&self) -> usize {
        match (self.positions.first(), self.dim) {
            (Some(frame), d) if d > 0 => frame.len() / d,
            _ => 0,
        }
    }

    /// The value of the first metadata entry named `key`.
    pub fn meta_value(&self, key: &str) -> Option<&str> {
        self.meta.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str())
    }

    /// Checks that lengths are consistent and values finite; the message names the field.
    pub fn validate(&self) -> Result<(), String> {
        self.check().map_err(|(field, msg)| format!("{field}: {msg}"))
    }

    /// Like [`Self::validate`], with the field and the message apart.
    fn check(&self) -> Result<(), (&'static str, String)> {
        if self.dim != 2 && self.dim != 3 {
            return Err(("positions", format!("dim must be 2 or 3, not {}", self.dim)));
        }
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return Err(("dt", format!("must be finite and positive, not {}", self.dt)));
        }
        let frames = self.positions.len();
        if frames == 0 {
            return Err(("positions", "no frames (frame 0 is the initial state)".into()));
        }
        let width = self.positions[0].len();
        if width == 0 || !width.is_multiple_of(self.dim) {
            return Err((
                "positions",
                format!(
                    "frame 0 has {width} values, not a positive multiple of dim {}",
                    self.dim
                ),
            ));
        }
        check_table("positions", &self.positions, frames, width)?;
        let p = self.bc_signal.first().map_or(0, Vec::len);
        check_table("bc_signal", &self.bc_signal, frames, p)?;
        check_table("energies", &self.energies, frames, self.energy_names.len())?;
        check_len("newton_iterations", self.newton_iterations.len(), frames)?;
        if !self.step_seconds.is_empty() {
            check_len("step_seconds", self.step_seconds.len(), frames)?;
        }
        if let Some(i) = self.step_seconds.iter().position(|s| !(s.is_finite() && *s >= 0.0)) {
            return Err((
                "step_seconds",
                format!("frame {i}: {} is not a finite, non-negative time", self.step_seconds[i]),
            ));
        }
        if let Some(o) = &self.obstacles {
            let width = o.positions.first().map_or(0, Vec::len);
            check_table("obstacle_positions", &o.positions, frames, width)?;
            if !width.is_multiple_of(3) {
                return Err((
                    "obstacle_positions",
                    format!("{width} values per frame, not a multiple of 3"),
                ));
            }
            if let Some(f) = o.faces.iter().find(|f| f.iter().any(|&v| v as usize >= width / 3)) {
                return Err((
                    "obstacle_faces",
                    format!("face {f:?} refers past the {} vertices", width / 3),
                ));
            }
        }
        if let Some(c) = &self.colliders {
            let k = c.names.len();
            if c.shapes.len() != k {
                return Err(("collider_shapes", format!("{} rows for {k} colliders", c.shapes.len())));
            }
            if let Some(row) = c.shapes.iter().find(|r| {
                crate::contact::ColliderShape::from_parameters(**r).is_none() || !r.iter().all(|v| v.is_finite())
            }) {
                return Err(("collider_shapes", format!("{row:?} is not a shape row")));
            }
            check_table("collider_states", &c.states, frames, k * COLLIDER_STATE)?;
            for name in &c.names {
                check_text("collider_names", name)?;
            }
        }
        check_text("scene", &self.scene)?;
        for name in &self.energy_names {
            check_text("energy_names", name)?;
        }
        for (key, value) in &self.meta {
            if key.is_empty() {
                return Err(("meta", "empty key".into()));
            }
            check_text("meta", key)?;
            check_text("meta", value)?;
        }
        Ok(())
    }

    /// Writes the trajectory as an uncompressed `.npz` archive (see the module docs).
    pub fn write_npz(&self, path: &Path) -> Result<(), SimError> {
        self.check()
            .map_err(|(field, msg)| InputError::field(path, field, format!("invalid trajectory: {msg}")))?;
        self.write_arrays(path).map_err(|source| SimError::Io {
            path: path.to_path_buf(),
            source,
        })
    }

    fn write_arrays(&self, path: &Path) -> io::Result<()> {
        let frames = self.num_frames() as u64;
        let n = self.num_vertices() as u64;
        let p = self.bc_signal[0].len() as u64;
        let k = self.energy_names.len() as u64;
        let mut npz = NpzOut::create(path)?;
        npz.array("format_version", &[], [FORMAT_VERSION])?;
        npz.strings("scene", &[], [self.scene.as_str()])?;
        npz.array("dt", &[], [self.dt])?;
        npz.array(
            "positions",
            &[frames, n, self.dim as u64],
            self.positions.iter().flatten().copied(),
        )?;
        npz.array("bc_signal", &[frames, p], self.bc_signal.iter().flatten().copied())?;
        npz.strings("energy_names", &[k], self.energy_names.iter().map(String::as_str))?;
        npz.array("energies", &[frames, k], self.energies.iter().flatten().copied())?;
        npz.array("newton_iterations", &[frames], self.newton_iterations.iter().copied())?;
        npz.array(
            "step_seconds",
            &[self.step_seconds.len() as u64],
            self.step_seconds.iter().copied(),
        )?;
        npz.strings(
            "meta",
            &[self.meta.len() as u64, 2],
            self.meta.iter().flat_map(|(k, v)| [k.as_str(), v.as_str()]),
        )?;
        if let Some(o) = &self.obstacles {
            let count = o.positions.first().map_or(0, Vec::len) as u64 / 3;
            npz.array(
                "obstacle_faces",
                &[o.faces.len() as u64, 3],
                o.faces.iter().flatten().copied(),
            )?;
            npz.array(
                "obstacle_positions",
                &[frames, count, 3],
                o.positions.iter().flatten().copied(),
            )?;
        }
        if let Some(c) = &self.colliders {
            let k = c.names.len() as u64;
            npz.strings("collider_names", &[k], c.names.iter().map(String::as_str))?;
            npz.array("collider_shapes", &[k, 4], c.shapes.iter().flatten().copied())?;
            npz.array(
                "collider_states",
                &[frames, k, COLLIDER_STATE as u64],
                c.states.iter().flatten().copied(),
            )?;
        }
        npz.finish()
    }

    /// Reads a trajectory written by [`Self::write_npz`] (or by numpy in the same layout).
    pub fn read_npz(path: &Path) -> Result<Self, InputError> {
        let mut npz = NpzFile::open(path)?;

        let version = npz.array("format_version")?;
        version.expect_shape(&[])?;
        let version = version.into_vec::<u32>("uint32")?[0];
        if version != FORMAT_VERSION {
            return Err(InputError::field(
                path,
                "format_version",
                format!("version {version} is not supported (expected {FORMAT_VERSION})"),
            ));
        }

        let scene = npz.array("scene")?;
        scene.expect_shape(&[])?;
        let scene = scene.into_vec::<String>("unicode string")?.remove(0);

        let dt = npz.array("dt")?;
        dt.expect_shape(&[])?;
        let dt = dt.into_vec::<f64>("float64")?[0];

        let positions = npz.array("positions")?;
        let [frames, n, dim] = positions.dims::<3>()?;
        if dim != 2 && dim != 3 {
            return Err(positions.error(format!("last axis is {dim}, not 2 or 3")));
        }
        let positions = rows(positions.into_vec::<f64>("float64")?, frames, n * dim);

        let bc_signal = npz.array("bc_signal")?;
        let [bc_frames, p] = bc_signal.dims::<2>()?;
        bc_signal.expect_len("frames", bc_frames, frames)?;
        let bc_signal = rows(bc_signal.into_vec::<f64>("float64")?, frames, p);

        let energy_names = npz.array("energy_names")?;
        let [k] = energy_names.dims::<1>()?;
        let energy_names = energy_names.into_vec::<String>("unicode string")?;

        let energies = npz.array("energies")?;
        energies.expect_shape(&[frames as u64, k as u64])?;
        let energies = rows(energies.into_vec::<f64>("float64")?, frames, k);

        let newton = npz.array("newton_iterations")?;
        newton.expect_shape(&[frames as u64])?;
        let newton_iterations = newton.into_vec::<u32>("uint32")?;

        let seconds = npz.array("step_seconds")?;
        if seconds.dims::<1>()? != [0] {
            seconds.expect_shape(&[frames as u64])?;
        }
        let step_seconds = seconds.into_vec::<f64>("float64")?;

        let meta = npz.array("meta")?;
        let [entries, columns] = meta.dims::<2>()?;
        if columns != 2 {
            return Err(meta.error(format!("has {columns} columns, not 2 (key, value)")));
        }
        let meta = rows(meta.into_vec::<String>("unicode string")?, entries, 2)
            .into_iter()
            .map(|mut row| {
                let value = row.pop().unwrap_or_default();
                (row.pop().unwrap_or_default(), value)
            })
            .collect();

        let obstacles = if npz.has("obstacle_faces") {
            let faces = npz.array("obstacle_faces")?;
            let [t, three] = faces.dims::<2>()?;
            if three != 3 {
                return Err(faces.error(format!("has {three} columns, not 3")));
            }
            let faces = faces.into_vec::<u32>("uint32")?;
            let faces = (0..t)
                .map(|k| [faces[3 * k], faces[3 * k + 1], faces[3 * k + 2]])
                .collect();
            let positions = npz.array("obstacle_positions")?;
            let [o_frames, count, three] = positions.dims::<3>()?;
            positions.expect_len("frames", o_frames, frames)?;
            if three != 3 {
                return Err(positions.error(format!("last axis is {three}, not 3")));
            }
            let positions = rows(positions.into_vec::<f64>("float64")?, frames, count * 3);
            Some(ObstacleFrames { faces, positions })
        } else {
            None
        };

        let colliders = if npz.has("collider_names") {
            let names = npz.array("collider_names")?;
            let [k] = names.dims::<1>()?;
            let names = names.into_vec::<String>("unicode string")?;
            let shapes = npz.array("collider_shapes")?;
            shapes.expect_shape(&[k as u64, 4])?;
            let shapes = shapes.into_vec::<f64>("float64")?;
            let shapes = shapes.chunks(4).map(|r| [r[0], r[1], r[2], r[3]]).collect();
            let states = npz.array("collider_states")?;
            states.expect_shape(&[frames as u64, k as u64, COLLIDER_STATE as u64])?;
            let states = rows(states.into_vec::<f64>("float64")?, frames, k * COLLIDER_STATE);
            Some(ColliderFrames { names, shapes, states })
        } else {
            None
        };

        let trajectory = Trajectory {
            scene,
            dt,
            dim,
            positions,
            bc_signal,
            energy_names,
            energies,
            newton_iterations,
            step_seconds,
            meta,
            obstacles,
            colliders,
        };
        trajectory
            .check()
            .map_err(|(field, msg)| InputError::field(path, field, msg))?;
        Ok(trajectory)
    }
}

fn check_len(field: &'static str, len: usize, frames: usize) -> Result<(), (&'static str, String)> {
    if len == frames {
        Ok(())
    } else {
        Err((field, format!("{len} frames, positions has {frames}")))
    }
}

/// Checks a frames x `width` table of finite values.
fn check_table(
    field: &'static str,
    table: &[Vec<f64>],
    frames: usize,
    width: usize,
) -> Result<(), (&'static str, String)> {
    check_len(field, table.len(), frames)?;
    for (f, row) in table.iter().enumerate() {
        if row.len() != width {
            return Err((field, format!("frame {f} has {} values, expected {width}", row.len())));
        }
        if let Some(i) = row.iter().position(|v| !v.is_finite()) {
            return Err((field, format!("frame {f}, entry {i} is {}", row[i])));
        }
    }
    Ok(())
}

/// Strings are stored as NUL-padded unicode, so they cannot hold NUL themselves.
fn check_text(field: &'static str, text: &str) -> Result<(), (&'static str, String)> {
    if text.contains('\0') {
        Err((field, format!("{text:?} contains a NUL character")))
    } else {
        Ok(())
    }
}

/// Splits a flat vector into `count` rows of `width` (empty rows when `width` is 0).
fn rows<T: Clone>(flat: Vec<T>, count: usize, width: usize) -> Vec<Vec<T>> {
    if width == 0 {
        vec![Vec::new(); count]
    } else {
        flat.chunks(width).map(<[T]>::to_vec).collect()
    }
}

#[cfg(test)]
mod tests;
