//! Rollouts of a loaded model on one boundary-condition sequence, the divergence tests of
//! [`super`], and what they measure.

use std::path::Path;
use std::time::Instant;

use mochi_sim::bc::BcSequence;
use mochi_sim::dataset::{self, SequencePlan, Split};
use mochi_sim::measure::{kinetic_energy, mean_and_max_error};
use mochi_sim::trajectory::Trajectory;
use mochi_sim::BuiltScene;

use crate::artifact::Artifact;
use crate::error::{TrainerError, TrainerResult};
use crate::eval::penetration::{Penetration, PenetrationMeter};
use crate::learn::encoding::{collider_inputs, decode_world, pack_signals, Encoding};
use crate::learn::network::{ExportedIntegrator, FrozenDecoder};
use crate::learn::recipe::{Recipe, RodEncoding};
use crate::progress::Reporter;

/// Frames over which accuracy is measured (from the start of each test sequence).
pub const ACCURACY_FRAMES: usize = 1000;
/// Length of the stability rollout.
pub const STABILITY_FRAMES: usize = 10_000;

/// A loaded model ready to roll out.
pub struct LoadedModel {
    /// The artifact.
    pub artifact: Artifact,
    /// Its decoder.
    pub decoder: FrozenDecoder,
    /// Its integrator.
    pub integrator: ExportedIntegrator,
}

impl LoadedModel {
    /// Builds the runnable networks of `artifact`.
    pub fn new(artifact: Artifact) -> TrainerResult<Self> {
        let decoder = artifact.decoder()?;
        let integrator = artifact.integrator()?;
        Ok(LoadedModel {
            artifact,
            decoder,
            integrator,
        })
    }
}

/// Rebuilds the scene an artifact was trained on and checks that the encoding it carries is
/// that scene's.
pub fn rebuild_problem(artifact: &Artifact) -> TrainerResult<(BuiltScene, Encoding)> {
    let recipe = Recipe::parse(&artifact.scene_toml, Path::new(&artifact.scene_path))?;
    let problem = recipe.build()?;
    let encoding = carried_encoding(artifact, &problem)?;
    Ok((problem, encoding))
}

/// The scene's test split in the `dataset` folder beside `file` (a model or a `.reduced`
/// file, as `mochi train` lays them out), simulated first where it is missing.
pub fn test_split(
    problem: &mut BuiltScene,
    file: &Path,
    report: &dyn Reporter,
) -> TrainerResult<Vec<(SequencePlan, Trajectory)>> {
    test_split_in(problem, &dataset_dir(file), report)
}

/// The scene's test split in dataset directory `data_dir`, simulated first by `problem`'s
/// solver where it is missing.
pub fn test_split_in(
    problem: &mut BuiltScene,
    data_dir: &Path,
    report: &dyn Reporter,
) -> TrainerResult<Vec<(SequencePlan, Trajectory)>> {
    dataset::generate(problem, data_dir, Some(Split::Test), false, &report.frames("dataset"))?;
    Ok(dataset::load(problem, data_dir, Split::Test)?)
}

/// The `dataset` folder beside `file`.
pub fn dataset_dir(file: &Path) -> std::path::PathBuf {
    file.parent().unwrap_or(Path::new(".")).join("dataset")
}

/// The encoding `artifact` carries, built for `problem` (its scene): strand bends when it
/// carries chains, positions otherwise (a distilled model may decode the strands of a
/// bend-trained one as positions); an error when it is not that scene's.
pub fn carried_encoding(artifact: &Artifact, problem: &BuiltScene) -> TrainerResult<Encoding> {
    let rods = if artifact.encoding.chains.is_empty() {
        RodEncoding::Positions
    } else {
        RodEncoding::Bends
    };
    let encoding = Encoding::new(problem, rods)?;
    if crate::artifact::EncodingData::new(&encoding) != artifact.encoding {
        return Err(TrainerError::invalid(format!(
            "the artifact's boundary-condition encoding does not match scene `{}` as rebuilt from it",
            artifact.scene
        )));
    }
    Ok(encoding)
}

/// A vertex farther than this from the reference (fraction of the rest diagonal) has drifted
/// off it: the one threshold of [`Divergence::OffReference`], the weight-storage table and
/// the subspace diagnostics.
pub const OFF_REFERENCE: f64 = 0.5;

/// Why a rollout counts as diverged (the tests of the module documentation, in the order
/// they are made).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Divergence {
    /// A latent or a position is not finite.
    NotFinite,
    /// A vertex left the training envelope: the state blew up.
    LeftEnvelope,
    /// The kinetic energy passed 100 times the training maximum.
    KineticEnergy,
    /// A vertex is more than half the diagonal from the reference: the state is finite
    /// and bounded but has drifted from the motion it should follow.
    OffReference,
}

impl Divergence {
    /// A few words for reports.
    pub fn describe(self) -> &'static str {
        match self {
            Divergence::NotFinite => "not finite",
            Divergence::LeftEnvelope => "left the envelope",
            Divergence::KineticEnergy => "kinetic energy over 100x",
            Divergence::OffReference => "half a diagonal off the reference",
        }
    }
}

/// What one rollout measured.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RolloutMetrics {
    /// Mean over frames of the mean vertex error / diagonal.
    pub mean_error: f64,
    /// Max over frames of the max vertex error / diagonal.
    pub max_error: f64,
    /// Kinetic energy summed over the measured frames, ours over the reference's.
    pub kinetic_energy_ratio: f64,
    /// Frames completed before divergence, capped at the rollout length.
    pub stable_frames: usize,
    /// Why the rollout diverged; `None` when it ran its length.
    pub divergence: Option<Divergence>,
    /// Frames before the state blew up (not finite, out of the envelope, or the kinetic
    /// energy cap), capped at the rollout length: a rollout that drifted off the reference
    /// rolls on to measure this.
    pub bounded_frames: usize,
    /// Mean vertex error / diagonal of every measured frame.
    pub error_curve: Vec<f64>,
    /// Seconds per latent step.
    pub step_seconds: f64,
    /// Seconds per full decode (network and world frame).
    pub decode_seconds: f64,
    /// Penetration into the scene's run-time colliders over the stable frames (`None`
    /// without colliders).
    pub penetration: Option<Penetration>,
}

/// Largest norm of an encoded vertex's values (`per_vertex` each): its distance from its
/// origin for positions, its edge's bend for strand bends.
fn max_radius(q: &[f32], per_vertex: usize) -> f64 {
    q.chunks_exact(per_vertex)
        .map(|c| c.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt())
        .fold(0.0, f64::max)
}

/// The trainer's own rollout of `model` over `bc` at `problem`'s time step (the reference the
/// runtime is checked against; a model that takes the frame time steps at that one): from the
/// initial latent, calls `visit(t, z_t, q_t, x_t)` for `t = 1..=frames` with
/// the latent, the decoded encoded state and the world state, until `visit` returns `false`.
/// Returns the seconds spent stepping and decoding.
pub fn roll(
    model: &LoadedModel,
    problem: &BuiltScene,
    encoding: &Encoding,
    bc: &BcSequence,
    frames: usize,
    mut visit: impl FnMut(usize, &[f32], &[f32], &[f64]) -> bool,
) -> TrainerResult<(f64, f64)> {
    let a = &model.artifact;
    let dim = problem.mesh.dim;
    let mut z_prev = a.initial_latent.clone();
    let mut z_prev2 = a.initial_latent.clone();
    let mut signals = [bc.signal(0), bc.signal(0), bc.signal(0)];
    let (mut step_time, mut decode_time) = (0.0, 0.0);
    for t in 1..=frames {
        signals.rotate_right(1);
        signals[0] = bc.signal(t);
        let targets = bc.targets(&problem.handles, t, dim);
        let frame = encoding.frame(&targets)?;
        let states = bc.collider_states(t);
        let clock = Instant::now();
        let colliders = collider_inputs(a.colliders(), &frame, &targets, dim, a.diagonal, &states);
        let q_in = pack_signals(
            &z_prev,
            &z_prev2,
            [&signals[0], &signals[1], &signals[2]],
            &colliders,
            a.timed().then_some(problem.scene.dt),
        );
        let z = model.integrator.step(&q_in)?;
        let mid = Instant::now();
        let q = model.decoder.decode(&z)?;
        let x = decode_world(encoding, &q, &frame, &targets)?;
        step_time += (mid - clock).as_secs_f64();
        decode_time += mid.elapsed().as_secs_f64();
        if !visit(t, &z, &q, &x) {
            break;
        }
        z_prev2 = std::mem::replace(&mut z_prev, z);
    }
    Ok((step_time, decode_time))
}

/// The limits a rollout of `model` must stay inside: the training envelope (a vertex farther
/// from its encoding origin than in any training frame plus half the diagonal) and 100 times
/// the training maximum of the kinetic energy.
struct BlowUpLimits {
    envelope: f64,
    kinetic_energy: f64,
    values_per_vertex: usize,
}

impl BlowUpLimits {
    fn new(model: &LoadedModel, encoding: &Encoding) -> Self {
        let a = &model.artifact;
        BlowUpLimits {
            envelope: a.summary.max_radius + 0.5 * a.diagonal,
            kinetic_energy: 100.0 * a.summary.max_kinetic_energy.max(1e-12),
            values_per_vertex: encoding.values_per_vertex(),
        }
    }

    /// Why the state with latent `z`, decoded encoded state `q`, world state `x` and kinetic
    /// energy `ke` (`None`: not checked) has blown up, if it has.
    fn check(&self, z: &[f32], q: &[f32], x: &[f64], ke: Option<f64>) -> Option<Divergence> {
        if !(z.iter().all(|v| v.is_finite()) && x.iter().all(|v| v.is_finite())) {
            Some(Divergence::NotFinite)
        } else if max_radius(q, self.values_per_vertex) > self.envelope {
            Some(Divergence::LeftEnvelope)
        } else if ke.is_some_and(|ke| ke > self.kinetic_energy) {
            Some(Divergence::KineticEnergy)
        } else {
            None
        }
    }
}

/// The trainer's rollout of `model` over `bc` (world states of frames `1..`) up to the first
/// frame that is not finite or leaves the training envelope (see [`BlowUpLimits`]): the
/// frames on which another implementation of the same model can be expected to agree with it.
pub fn stable_rollout(
    model: &LoadedModel,
    problem: &BuiltScene,
    encoding: &Encoding,
    bc: &BcSequence,
    frames: usize,
) -> TrainerResult<Vec<Vec<f64>>> {
    let limits = BlowUpLimits::new(model, encoding);
    let mut states = Vec::new();
    roll(model, problem, encoding, bc, frames, |_, z, q, x| {
        let stable = limits.check(z, q, x, None).is_none();
        if stable {
            states.push(x.to_vec());
        }
        stable
    })?;
    Ok(states)
}

/// Rolls `model` out over `bc` for `frames` frames from its initial latent, comparing with
/// `reference` where it has frames (at most `accuracy_frames` of them).
pub fn rollout(
    model: &LoadedModel,
    problem: &BuiltScene,
    encoding: &Encoding,
    bc: &BcSequence,
    frames: usize,
    reference: &Trajectory,
    accuracy_frames: usize,
) -> TrainerResult<RolloutMetrics> {
    let a = &model.artifact;
    let dim = problem.mesh.dim;
    let masses = problem.simulator.masses();
    let measured = accuracy_frames.min(reference.num_frames() - 1).min(frames);
    let limits = BlowUpLimits::new(model, encoding);
    let mut x_prev = reference.positions[0].clone();
    let mut metrics = RolloutMetrics {
        stable_frames: frames,
        bounded_frames: frames,
        ..Default::default()
    };
    let (mut ke_ours, mut ke_ref) = (0.0, 0.0);
    let mut rolled = 0;
    let mut meter = PenetrationMeter::new(problem);
    // A rollout that drifts off the reference is diverged, but rolls on to measure how long
    // it stays bounded.
    let (step_time, decode_time) = roll(model, problem, encoding, bc, frames, |t, z, q, x| {
        rolled = t;
        let ke = kinetic_energy(masses, x, &x_prev, a.dt, dim);
        if let Some(reason) = limits.check(z, q, x, Some(ke)) {
            metrics.bounded_frames = t - 1;
            if metrics.divergence.is_none() {
                metrics.stable_frames = t - 1;
                metrics.divergence = Some(reason);
            }
            return false;
        }
        if let Some(meter) = &mut meter {
            let compared = (t <= measured).then(|| (&reference.positions[t][..], a.diagonal));
            meter.frame(x, &bc.collider_poses(t), compared);
        }
        if t <= measured {
            let xr = &reference.positions[t];
            let (mean, max) = mean_and_max_error(x, xr, dim, a.diagonal);
            metrics.error_curve.push(mean);
            metrics.max_error = metrics.max_error.max(max);
            ke_ours += ke;
            ke_ref += kinetic_energy(masses, xr, &reference.positions[t - 1], a.dt, dim);
            if (max > OFF_REFERENCE || !mean.is_finite()) && metrics.divergence.is_none() {
                metrics.stable_frames = t - 1;
                metrics.divergence = Some(Divergence::OffReference);
            }
        }
        x_prev.copy_from_slice(x);
        true
    })?;
    metrics.penetration = meter.map(PenetrationMeter::finish);
    let done = rolled.max(1) as f64;
    metrics.step_seconds = step_time / done;
    metrics.decode_seconds = decode_time / done;
    if metrics.error_curve.len() < measured {
        // Blew up inside the measured window: the error there counts as unbounded. (A
        // rollout that only drifted off the reference was measured to the end.)
        metrics.mean_error = f64::INFINITY;
        metrics.max_error = f64::INFINITY;
        metrics.kinetic_energy_ratio = f64::NAN;
    } else {
        metrics.mean_error = metrics.error_curve.iter().sum::<f64>() / measured.max(1) as f64;
        metrics.kinetic_energy_ratio = if ke_ref > 0.0 { ke_ours / ke_ref } else { f64::NAN };
    }
    Ok(metrics)
}

pub use crate::methods::learned::{collider_states, motions};
