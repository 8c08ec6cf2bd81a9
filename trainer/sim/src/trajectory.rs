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
//! | `step_seconds` | float64 | `(frames,)` |
//! | `meta` | unicode | `(m, 2)`: key, value rows |
//! | `obstacle_faces` | uint32 | `(t, 3)`, only for scenes with obstacle meshes |
//! | `obstacle_positions` | float64 | `(frames, o, 3)`, with `obstacle_faces` |
//!
//! Reading accepts compressed archives too (`numpy.savez_compressed`) and checks every
//! array's presence, dtype and shape; errors name the file and the array.

use std::fs::File;
use std::io::{self, BufReader, Cursor, Read};
use std::path::Path;

use npyz::zip::{self, CompressionMethod};
use npyz::{Deserialize, NpyFile};

use crate::error::{InputError, SimError};
use crate::npz::NpzOut;

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
    /// Wall time of each step in seconds (0 for frame 0).
    pub step_seconds: Vec<f64>,
    /// Free-form metadata (seed, speeds, `split` = train/test, ...).
    pub meta: Vec<(String, String)>,
    /// The contact obstacle meshes, frame by frame (scenes with `[[contact.obstacles]]`).
    pub obstacles: Option<ObstacleFrames>,
}

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
        check_len("step_seconds", self.step_seconds.len(), frames)?;
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
        npz.array("step_seconds", &[frames], self.step_seconds.iter().copied())?;
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
        seconds.expect_shape(&[frames as u64])?;
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

// ---------------------------------------------------------------------------------------
// Reading

/// Largest expansion a deflate stream can give (about 1032:1), for a sanity bound on sizes.
const MAX_DEFLATE_RATIO: u64 = 1100;

/// An opened `.npz` archive that reports errors against its path.
struct NpzFile<'p> {
    path: &'p Path,
    zip: zip::ZipArchive<BufReader<File>>,
    file_len: u64,
}

impl<'p> NpzFile<'p> {
    fn open(path: &'p Path) -> Result<Self, InputError> {
        let fail = |e: &dyn std::fmt::Display| InputError::file(path, format!("cannot open as an .npz archive: {e}"));
        let file = File::open(path).map_err(|e| fail(&e))?;
        let file_len = file.metadata().map_err(|e| fail(&e))?.len();
        let zip = zip::ZipArchive::new(BufReader::new(file)).map_err(|e| fail(&e))?;
        Ok(NpzFile { path, zip, file_len })
    }

    /// Whether the archive holds array `name`.
    fn has(&mut self, name: &str) -> bool {
        self.zip.by_name(&format!("{name}.npy")).is_ok()
    }

    /// Reads the whole entry of array `name` (checksum verified) and parses its header.
    fn array(&mut self, name: &'static str) -> Result<NpyArray<'p>, InputError> {
        let path = self.path;
        let err = |msg: String| InputError::field(path, name, msg);
        let mut entry = match self.zip.by_name(&format!("{name}.npy")) {
            Ok(entry) => entry,
            Err(zip::result::ZipError::FileNotFound) => return Err(err("missing".into())),
            Err(e) => return Err(err(format!("unreadable: {e}"))),
        };
        let size = entry.size();
        let packed = entry.compressed_size();
        let bound = match entry.compression() {
            CompressionMethod::Stored => packed,
            _ => packed.saturating_mul(MAX_DEFLATE_RATIO).saturating_add(1024),
        };
        if packed > self.file_len || size > bound {
            return Err(err(format!(
                "corrupt entry sizes ({size} bytes from {packed} packed, file is {} bytes)",
                self.file_len
            )));
        }
        let mut bytes = Vec::new();
        entry
            .by_ref()
            .take(size.saturating_add(1))
            .read_to_end(&mut bytes)
            .map_err(|e| err(format!("corrupt or truncated data: {e}")))?;
        if bytes.len() as u64 != size {
            return Err(err(format!(
                "entry holds {} bytes, its header says {size}",
                bytes.len()
            )));
        }
        NpyArray::parse(path, name, bytes)
    }
}

/// One array of the archive, its bytes in memory and its header checked against them.
struct NpyArray<'p> {
    path: &'p Path,
    name: &'static str,
    shape: Vec<u64>,
    npy: NpyFile<Cursor<Vec<u8>>>,
}

impl<'p> NpyArray<'p> {
    fn parse(path: &'p Path, name: &'static str, bytes: Vec<u8>) -> Result<Self, InputError> {
        let err = |msg: String| InputError::field(path, name, msg);
        let (header_end, shape, count) = pre_check_header(&bytes).map_err(err)?;
        let data_len = (bytes.len() - header_end) as u64;
        let npy = NpyFile::new(Cursor::new(bytes)).map_err(|e| err(format!("bad .npy header: {e}")))?;
        if npy.shape() != shape.as_slice() {
            return Err(err("bad .npy header: unreadable shape".into()));
        }
        let item = npy
            .dtype()
            .num_bytes()
            .ok_or_else(|| err("dtype has no fixed size (pickled objects?)".into()))?;
        let needed = count.checked_mul(item as u64);
        if needed != Some(data_len) {
            return Err(err(format!(
                "shape {shape:?} of {item}-byte items needs {} bytes, the file holds {data_len}",
                needed.map_or("too many".into(), |b| b.to_string())
            )));
        }
        Ok(NpyArray { path, name, shape, npy })
    }

    fn error(&self, msg: String) -> InputError {
        InputError::field(self.path, self.name, msg)
    }

    fn expect_shape(&self, expected: &[u64]) -> Result<(), InputError> {
        if self.shape == expected {
            Ok(())
        } else {
            Err(self.error(format!("shape {:?}, expected {expected:?}", self.shape)))
        }
    }

    /// The shape as `N` axis lengths.
    fn dims<const N: usize>(&self) -> Result<[usize; N], InputError> {
        let mut dims = [0usize; N];
        if self.shape.len() != N {
            return Err(self.error(format!(
                "shape {:?} has {} axes, expected {N}",
                self.shape,
                self.shape.len()
            )));
        }
        for (d, &s) in dims.iter_mut().zip(&self.shape) {
            *d = usize::try_from(s).map_err(|_| self.error(format!("axis length {s} too large")))?;
        }
        Ok(dims)
    }

    fn expect_len(&self, axis: &str, len: usize, expected: usize) -> Result<(), InputError> {
        if len == expected {
            Ok(())
        } else {
            Err(self.error(format!("{len} {axis}, positions has {expected}")))
        }
    }

    /// All elements in storage order, as `T` (`what` names the expected dtype in errors).
    fn into_vec<T: Deserialize>(self, what: &str) -> Result<Vec<T>, InputError> {
        let descr = self.npy.dtype().descr();
        let (path, name) = (self.path, self.name);
        let fortran = self.npy.order() == npyz::Order::Fortran && self.shape.len() > 1;
        if fortran {
            return Err(InputError::field(
                path,
                name,
                "Fortran-ordered arrays are not supported",
            ));
        }
        self.npy
            .into_vec::<T>()
            .map_err(|e| InputError::field(path, name, format!("expected {what} data, found dtype {descr}: {e}")))
    }
}

/// Checks the `.npy` pre-header and shape before `npyz` parses them, so that corrupt
/// lengths cannot make it allocate or overflow. Returns the end of the header, the shape
/// and the element count.
fn pre_check_header(bytes: &[u8]) -> Result<(usize, Vec<u64>, u64), String> {
    const MAGIC: &[u8] = b"\x93NUMPY";
    if bytes.len() < 10 || &bytes[..6] != MAGIC {
        return Err("not a .npy array (no magic)".into());
    }
    let (len, start): (usize, usize) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(format!("unsupported .npy version {v}")),
    };
    let end = start
        .checked_add(len)
        .filter(|&end| end <= bytes.len())
        .ok_or("truncated .npy header")?;
    let text = std::str::from_utf8(&bytes[start..end]).map_err(|_| "header is not text")?;
    let after_key = text
        .find("'shape'")
        .map(|i| &text[i + "'shape'".len()..])
        .ok_or("header has no shape")?;
    let open = after_key.find('(').ok_or("unreadable shape")?;
    let close = after_key.find(')').ok_or("unreadable shape")?;
    if close < open {
        return Err("unreadable shape".into());
    }
    let mut shape = Vec::new();
    let mut count: u64 = 1;
    for axis in after_key[open + 1..close].split(',').map(str::trim) {
        if axis.is_empty() {
            continue;
        }
        let n: u64 = axis
            .trim_end_matches('L')
            .parse()
            .map_err(|_| format!("unreadable shape entry {axis:?}"))?;
        count = count.checked_mul(n).ok_or("shape is too large")?;
        shape.push(n);
    }
    Ok((end, shape, count))
}

#[cfg(test)]
mod tests;
