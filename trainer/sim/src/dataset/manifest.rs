//! A dataset directory's manifest (`manifest.toml`): which scene made it (its name and a hash of
//! the physical scene and its mesh file), with which solver and mochi version, and every
//! sequence written so far with the time it took. Sequence files carry no timings, so a
//! sequence's bytes depend on nothing but the scene and its plan: made by one process or by
//! many on several machines ([`super::generate`] with a selection), the files are the same.
//!
//! Processes that write sequences into one directory at once (tasks of a distributed run)
//! update the manifest under an exclusive lock on `manifest.lock`, so no record is lost. A
//! directory made from another scene or another version is refused, naming both.

use std::fs::File;
use std::io;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{InputError, SimError};
use crate::scene::{BuiltScene, MeshSpec, SolverSpec};

/// The manifest's file name in a dataset directory.
pub const MANIFEST: &str = "manifest.toml";
/// The lock file beside it.
const LOCK: &str = "manifest.lock";
/// Version of the manifest's layout.
pub const FORMAT: u32 = 1;

/// What a dataset directory holds and how it was made.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Layout version ([`FORMAT`]).
    pub format: u32,
    /// Scene name.
    pub scene: String,
    /// FNV-1a (64-bit, hexadecimal) of the physical scene and its mesh file.
    pub scene_hash: String,
    /// The solver and its settings.
    pub solver: String,
    /// mochi version that simulated it.
    pub mochi: String,
    /// Sequences written, in the order they were finished.
    #[serde(default)]
    pub sequences: Vec<SequenceRecord>,
}

/// One sequence written.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SequenceRecord {
    /// File stem (`train-03`).
    pub name: String,
    /// Frames after the initial one.
    pub frames: usize,
    /// Frame time (s).
    pub dt: f64,
    /// Seed of its motion.
    pub seed: u64,
    /// Wall-clock seconds it took to simulate.
    pub seconds: f64,
    /// Mean solver iterations per step.
    pub iterations: f64,
}

impl Manifest {
    /// The manifest `problem` makes, with no sequence yet.
    pub fn for_scene(problem: &BuiltScene) -> Manifest {
        let scene = &problem.scene;
        Manifest {
            format: FORMAT,
            scene: scene.name.clone(),
            scene_hash: format!("{:016x}", scene_hash(problem)),
            solver: match &scene.solver {
                SolverSpec::FullSpace => scene.solver.label().into(),
                SolverSpec::Adaptive(settings) => format!("{} {settings:?}", scene.solver.label()),
                SolverSpec::Vbd(settings) => format!("{} {settings:?}", scene.solver.label()),
            },
            mochi: env!("CARGO_PKG_VERSION").into(),
            sequences: Vec::new(),
        }
    }

    /// Reads the manifest at `path`; `None` when there is none.
    pub fn read(path: &Path) -> Result<Option<Manifest>, InputError> {
        let text = match std::fs::read_to_string(path) {
            Ok(text) => text,
            Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(InputError::file(path, format!("cannot read: {e}"))),
        };
        toml::from_str(&text)
            .map(Some)
            .map_err(|e| InputError::file(path, format!("not a dataset manifest: {e}")))
    }

    /// `Err` with the reason when this manifest (read from `path`) is not one `expected`'s
    /// scene and version would write.
    fn check_same_origin(&self, expected: &Manifest, path: &Path) -> Result<(), InputError> {
        let origin = |m: &Manifest| {
            format!(
                "scene `{}` (hash {}, {}) with mochi {}, manifest format {}",
                m.scene, m.scene_hash, m.solver, m.mochi, m.format
            )
        };
        let same = self.format == expected.format
            && self.scene_hash == expected.scene_hash
            && self.solver == expected.solver
            && self.mochi == expected.mochi;
        if same {
            Ok(())
        } else {
            Err(InputError::file(
                path,
                format!(
                    "this dataset was made from {}; this run would make it from {}: give another \
                     output directory, or make it anew (`mochi dataset --overwrite`)",
                    origin(self),
                    origin(expected)
                ),
            ))
        }
    }

    /// Whether sequence `name` of `frames` frames at `dt` is recorded as written.
    pub fn has(&self, name: &str, frames: usize, dt: f64) -> bool {
        self.sequences
            .iter()
            .any(|s| s.name == name && s.frames == frames && (s.dt - dt).abs() <= 1e-9 * dt.abs())
    }

    fn write(&self, path: &Path) -> io::Result<()> {
        let text = toml::to_string(self).map_err(io::Error::other)?;
        let partial = path.with_extension("toml.partial");
        std::fs::write(&partial, text).and_then(|()| std::fs::rename(&partial, path))
    }
}

/// The dataset directory `dir` opened for `problem`: its manifest checked against the scene
/// and version (a directory of another origin is refused), or, with `overwrite` or none
/// there, a fresh one (sequence files of a directory without a manifest are not trusted and
/// are made again). Returns the manifest as it now stands.
pub fn open(dir: &Path, problem: &BuiltScene, overwrite: bool) -> Result<Manifest, SimError> {
    let expected = Manifest::for_scene(problem);
    let path = dir.join(MANIFEST);
    with_lock(dir, || {
        let current = if overwrite { None } else { Manifest::read(&path)? };
        match current {
            Some(found) => {
                found.check_same_origin(&expected, &path)?;
                Ok(found)
            }
            None => {
                expected.write(&path).map_err(|source| io_error(&path, source))?;
                Ok(expected.clone())
            }
        }
    })
}

/// Records `sequence` as written in `dir`'s manifest (replacing an earlier record of it);
/// `expected` is the manifest [`open`] returned, whose origin the file must still have.
pub fn record(dir: &Path, expected: &Manifest, sequence: SequenceRecord) -> Result<(), SimError> {
    let path = dir.join(MANIFEST);
    with_lock(dir, || {
        let mut manifest = match Manifest::read(&path)? {
            Some(found) => {
                found.check_same_origin(expected, &path)?;
                found
            }
            None => Manifest {
                sequences: Vec::new(),
                ..expected.clone()
            },
        };
        manifest.sequences.retain(|s| s.name != sequence.name);
        manifest.sequences.push(sequence.clone());
        manifest.write(&path).map_err(|source| io_error(&path, source))
    })
}

/// Runs `f` holding the exclusive lock on `dir`'s manifest.
fn with_lock<T>(dir: &Path, f: impl FnOnce() -> Result<T, SimError>) -> Result<T, SimError> {
    let lock_path = dir.join(LOCK);
    let lock = File::options()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&lock_path)
        .map_err(|source| io_error(&lock_path, source))?;
    lock.lock().map_err(|source| io_error(&lock_path, source))?;
    let result = f();
    let _ = lock.unlock();
    result
}

fn io_error(path: &Path, source: io::Error) -> SimError {
    SimError::Io {
        path: PathBuf::from(path),
        source,
    }
}

/// FNV-1a (64-bit) of the physical scene (its fields, the file it came from left out) and,
/// for a mesh read from a file, that file's bytes.
fn scene_hash(problem: &BuiltScene) -> u64 {
    let mut scene = problem.scene.clone();
    let mesh_file = match &scene.mesh {
        MeshSpec::File { path, .. } => Some(scene.source.parent().unwrap_or(Path::new(".")).join(path)),
        _ => None,
    };
    scene.source = PathBuf::new();
    let mut hash = fnv(0xcbf2_9ce4_8422_2325, format!("{scene:?}").as_bytes());
    if let Some(bytes) = mesh_file.and_then(|p| std::fs::read(p).ok()) {
        hash = fnv(hash, &bytes);
    }
    hash
}

fn fnv(mut hash: u64, bytes: &[u8]) -> u64 {
    for &b in bytes {
        hash ^= u64::from(b);
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
    }
    hash
}
