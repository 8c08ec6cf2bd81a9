//! One interface for every way of stepping a scene (docs/design.md, "Methods side by side"):
//! reset to the scene's initial state for a boundary-condition sequence, step to a frame, give
//! the positions of the scene's own mesh, and say what the step cost. Full-space Newton, the
//! adaptive solver, Vertex Block Descent, a coarser mesh, the reduced solver, the learned
//! integrator in the runtime and the peers' recorded runs all implement it, and
//! [`run_sequence`] is the one loop that measures any of them.

use mochi_sim::bc::BcSequence;
use mochi_sim::measure::mean_and_max_error;

use super::clock::Stopwatch;
use crate::error::TrainerResult;

/// What one step cost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepCost {
    /// Seconds of the step (and of the decode to positions, where there is one) on
    /// [`super::clock`], one thread; NaN to let [`run_sequence`] time the whole call.
    pub seconds: f64,
    /// Solver iterations of the step (Newton, VBD sweeps, L-BFGS); NaN where the method has
    /// none.
    pub iterations: f64,
    /// Multiply-adds of the step and decode, where a fixed count means something (the learned
    /// integrator); NaN otherwise.
    pub multiply_adds: f64,
}

impl StepCost {
    /// A step of `seconds` with `iterations` solver iterations.
    pub fn iterated(seconds: f64, iterations: f64) -> Self {
        StepCost {
            seconds,
            iterations,
            multiply_adds: f64::NAN,
        }
    }
}

/// A way of stepping a scene.
pub trait Method {
    /// The family, as charts group it ("full space", "VBD", "learned (runtime)", ...).
    fn family(&self) -> String;
    /// The budget of this instance of the family ("20 iterations", "k=8, int8", ...).
    fn setting(&self) -> String;
    /// Puts the body in the scene's initial state for `bc`.
    fn reset(&mut self, bc: &BcSequence) -> TrainerResult<()>;
    /// Steps to `frame` of `bc` (frames are stepped in order from 1 after a reset).
    fn step(&mut self, bc: &BcSequence, frame: usize) -> TrainerResult<StepCost>;
    /// Positions of the scene's mesh vertices now (flat, `dim` each).
    fn positions(&self) -> &[f64];
}

/// A frame counts as a blow-up when a vertex moved more than this many rest diagonals since
/// the last frame (or a position is not finite, or the step failed).
pub const BLOW_UP_DIAGONALS: f64 = 1.0;

/// One method on one sequence.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SequenceRun {
    /// Per reference, the mean vertex distance / diagonal of every measured frame (frames
    /// `1..=n`, `n` the fewer of the reference's frames and the stable frames).
    pub error_curves: Vec<Vec<f64>>,
    /// Per reference, the largest vertex distance / diagonal over the measured frames.
    pub max_errors: Vec<f64>,
    /// Per reference, the frames it covers (of those asked for): the frames measured.
    pub reference_frames: Vec<usize>,
    /// Frames stepped before a blow-up (all of them when none).
    pub stable_frames: usize,
    /// Frames asked for.
    pub frames: usize,
    /// Why the rollout stopped early, if it did.
    pub failure: Option<String>,
    /// Mean cost per stepped frame.
    pub seconds: f64,
    /// Mean iterations per stepped frame (NaN where the method has none).
    pub iterations: f64,
    /// Multiply-adds per frame (NaN where not counted).
    pub multiply_adds: f64,
}

impl SequenceRun {
    /// Mean over the measured frames of the error against reference `r` (infinite when the
    /// rollout blew up inside the reference's frames).
    pub fn mean_error(&self, r: usize) -> f64 {
        let curve = &self.error_curves[r];
        if self.stable_frames < self.reference_frames[r] {
            return f64::INFINITY;
        }
        curve.iter().sum::<f64>() / curve.len().max(1) as f64
    }

    /// Whether every asked frame was stepped without a blow-up.
    pub fn stable(&self) -> bool {
        self.failure.is_none()
    }
}

/// Steps `method` over frames `1..=frames` of `bc` and measures it against each of
/// `references` (positions of frames `0..`, each as long as it is; frames beyond a reference
/// are stepped for stability only). The positions of a mesh of `dim` coordinates per vertex
/// and rest diagonal `diagonal`. With `keep`, the positions of frames `0..` (up to the first
/// blow-up) are pushed into it, at most `keep.1` of them.
pub fn run_sequence(
    method: &mut dyn Method,
    bc: &BcSequence,
    frames: usize,
    references: &[&[Vec<f64>]],
    dim: usize,
    diagonal: f64,
    mut keep: Option<(&mut Vec<Vec<f64>>, usize)>,
) -> TrainerResult<SequenceRun> {
    let frames = frames.min(bc.frames());
    let mut run = SequenceRun {
        error_curves: vec![Vec::new(); references.len()],
        max_errors: vec![0.0; references.len()],
        reference_frames: references
            .iter()
            .map(|r| frames.min(r.len().saturating_sub(1)))
            .collect(),
        stable_frames: frames,
        frames,
        ..SequenceRun::default()
    };
    method.reset(bc)?;
    let mut last = method.positions().to_vec();
    let mut record = |x: &[f64]| {
        if let Some((kept, most)) = keep.as_mut() {
            if kept.len() < *most {
                kept.push(x.to_vec());
            }
        }
    };
    record(&last);
    let (mut seconds, mut iterations, mut macs) = (0.0, 0.0, 0.0);
    for frame in 1..=frames {
        let clock = Stopwatch::start();
        let cost = method.step(bc, frame);
        let elapsed = clock.seconds();
        let cost = match cost {
            Ok(c) => c,
            Err(e) => {
                run.stable_frames = frame - 1;
                run.failure = Some(format!("frame {frame}: {e}"));
                break;
            }
        };
        // The method's own time where it measured one (a peer's recorded step), the call's
        // otherwise.
        seconds += if cost.seconds.is_finite() {
            cost.seconds
        } else {
            elapsed
        };
        iterations += cost.iterations;
        macs += cost.multiply_adds;
        let x = method.positions();
        let jump = x
            .chunks_exact(dim)
            .zip(last.chunks_exact(dim))
            .map(|(a, b)| a.iter().zip(b).map(|(a, b)| (a - b) * (a - b)).sum::<f64>())
            .fold(0.0f64, |m, d| if d.is_nan() { f64::INFINITY } else { m.max(d) })
            .sqrt();
        if jump > BLOW_UP_DIAGONALS * diagonal {
            run.stable_frames = frame - 1;
            run.failure = Some(format!(
                "frame {frame}: a vertex moved {} in one frame",
                if jump.is_finite() {
                    format!("{:.2} diagonals", jump / diagonal)
                } else {
                    "to a non-finite position".into()
                }
            ));
            break;
        }
        for ((curve, worst), reference) in run.error_curves.iter_mut().zip(&mut run.max_errors).zip(references) {
            if let Some(r) = reference.get(frame) {
                let (mean, max) = mean_and_max_error(x, r, dim, diagonal);
                curve.push(mean);
                *worst = worst.max(max);
            }
        }
        record(x);
        last.copy_from_slice(x);
    }
    let stepped = run.stable_frames.max(1) as f64;
    run.seconds = seconds / stepped;
    run.iterations = iterations / stepped;
    run.multiply_adds = macs / stepped;
    Ok(run)
}
