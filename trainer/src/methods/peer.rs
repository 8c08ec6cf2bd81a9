//! A peer's recorded run as a [`Method`]: peers (XPBD from Bender's PositionBasedDynamics)
//! run from their own packages by project scripts (`scripts/xpbd.sh`), on a case that
//! `mochi export-case` wrote for one test sequence, and record every frame's positions and
//! the time each frame took on one core. Replaying the recording puts the peer through the
//! same measuring loop as every other method; its cost is the time it recorded.
//!
//! A recording is an `.npz` with `positions` (frames + 1, vertices, 3; float64; NaN after a
//! run that diverged), `step_seconds` (frames; float64, wall time) and optionally
//! `cpu_seconds` (frames; the thread's CPU time, the cost used when present, as
//! [`super::clock`] times every other method), `substeps` and `iterations` (0-d integers).

use std::path::Path;

use mochi_sim::bc::BcSequence;
use mochi_sim::npz::NpzFile;

use super::method::{Method, StepCost};
use crate::error::{TrainerError, TrainerResult};

/// A recorded run of a peer on one sequence.
#[derive(Clone, Debug)]
pub struct PeerRecording {
    family: String,
    setting: String,
    positions: Vec<Vec<f64>>,
    step_seconds: Vec<f64>,
    frame: usize,
}

impl PeerRecording {
    /// Reads the recording at `path`, for a mesh of `vertices` vertices of `dim` coordinates
    /// (2-D meshes are recorded with z = 0 and given back without it).
    pub fn read(path: &Path, family: &str, vertices: usize, dim: usize) -> TrainerResult<Self> {
        let mut npz = NpzFile::open(path)?;
        let positions = npz.array("positions")?;
        let [frames, n, width] = positions.dims::<3>()?;
        if n != vertices || width != 3 || frames == 0 {
            return Err(positions
                .error(format!(
                    "has shape ({frames}, {n}, {width}); the scene's mesh needs (frames + 1, {vertices}, 3)"
                ))
                .into());
        }
        let flat = positions.into_vec::<f64>("float64")?;
        let positions = flat
            .chunks_exact(n * 3)
            .map(|f| f.chunks_exact(3).flat_map(|p| p[..dim].to_vec()).collect())
            .collect();
        let name = if npz.has("cpu_seconds") {
            "cpu_seconds"
        } else {
            "step_seconds"
        };
        let seconds = npz.array(name)?;
        seconds.expect_shape(&[frames as u64 - 1])?;
        let step_seconds = seconds.into_vec::<f64>("float64")?;
        let substeps = scalar(&mut npz, "substeps")?;
        let iterations = scalar(&mut npz, "iterations")?;
        Ok(PeerRecording {
            family: family.into(),
            setting: format!("{substeps} substeps x {iterations} iterations"),
            positions,
            step_seconds,
            frame: 0,
        })
    }

    /// Frames recorded after the first.
    pub fn frames(&self) -> usize {
        self.positions.len() - 1
    }
}

fn scalar(npz: &mut NpzFile, name: &'static str) -> TrainerResult<i64> {
    let a = npz.array(name)?;
    a.expect_shape(&[])?;
    Ok(a.into_vec::<i64>("int64")?[0])
}

impl Method for PeerRecording {
    fn family(&self) -> String {
        self.family.clone()
    }

    fn setting(&self) -> String {
        self.setting.clone()
    }

    fn reset(&mut self, _bc: &BcSequence) -> TrainerResult<()> {
        self.frame = 0;
        Ok(())
    }

    fn step(&mut self, _bc: &BcSequence, frame: usize) -> TrainerResult<StepCost> {
        let seconds = *self
            .step_seconds
            .get(frame - 1)
            .ok_or_else(|| TrainerError::invalid(format!("{}: recorded {} frames only", self.family, self.frames())))?;
        self.frame = frame;
        Ok(StepCost::iterated(seconds, f64::NAN))
    }

    fn positions(&self) -> &[f64] {
        &self.positions[self.frame]
    }
}
