//! Datasets: boundary-condition sequences sampled from a scene's motion ranges, simulated
//! in full space and written as trajectories. Training speeds are evenly spaced over the
//! scene's ranges; test speeds are held out between them, beyond the top of the range,
//! and include a sudden speed drop. Handles and analytic colliders ([`colliders`]) move at
//! the same speed levels.

mod colliders;
mod generate;
pub mod manifest;
pub use colliders::closest_collider_approach;
pub use generate::{generate, generate_selected, GenerateReport, Selection};

use crate::bc::{self, BcSequence, Track};
use crate::error::InputError;
use crate::progress::Progress;
pub use crate::scene::Split;
use crate::scene::{BuiltScene, DatasetSpec, Start};
use crate::solver::{StepError, StepReport};
use crate::trajectory::{ObstacleFrames, Trajectory};
use rand::Rng;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// How fast the handles move over a sequence: from each `start_frame`, speeds are the
/// scene's speeds at `level` (0 bottom, 1 top of the training range) times `factor`; and
/// in what rhythm (segment lengths random, or all one length).
#[derive(Clone, Debug, PartialEq)]
pub struct SpeedPlan {
    /// `(start_frame, level, factor)`, sorted by start frame, the first at frame 0.
    pub pieces: Vec<(usize, f64, f64)>,
    /// `None`: segment lengths drawn at random from the motion's `segment_frames`.
    /// `Some(s)`: every segment lasts one length, the fraction `s` (0 shortest, 1 longest)
    /// of the way through that range (a steady rhythm).
    pub steady: Option<f64>,
}

impl SpeedPlan {
    /// One constant level.
    pub fn constant(level: f64) -> Self {
        SpeedPlan {
            pieces: vec![(0, level, 1.0)],
            steady: None,
        }
    }
    /// The `(level, factor)` in force at `frame`.
    pub fn at(&self, frame: usize) -> (f64, f64) {
        let piece = self
            .pieces
            .iter()
            .rev()
            .find(|p| p.0 <= frame)
            .unwrap_or(&self.pieces[0]);
        (piece.1, piece.2)
    }
}

/// One sequence of a dataset.
#[derive(Clone, Debug, PartialEq)]
pub struct SequencePlan {
    /// File stem, e.g. `train-03`.
    pub name: String,
    /// Train or test.
    pub split: Split,
    /// What is special about it, for reports.
    pub description: String,
    /// Speeds over time.
    pub speeds: SpeedPlan,
    /// Seed of its directions and segment lengths.
    pub seed: u64,
    /// Its frame time when it is not the scene's `dt` (a dataset over a range of frame rates,
    /// `dataset.frame_rates`).
    pub dt: Option<f64>,
}

impl SequencePlan {
    /// Its frames after the initial one: its split's frames of the scene's `dt`
    /// ([`DatasetSpec::frames_of`]), and at another frame time as many as cover the same
    /// seconds of motion (120 frames per second: four times those of 30).
    pub fn frames(&self, spec: &DatasetSpec, scene_dt: f64) -> usize {
        let frames = spec.frames_of(self.split);
        match self.dt {
            Some(dt) => (frames as f64 * scene_dt / dt).round().max(1.0) as usize,
            None => frames,
        }
    }
}

/// Frames between the speed draws of a `dataset.varied` training sequence.
pub const VARIED_PIECE_FRAMES: usize = 30;

/// Added to a varied sequence's seed for its speed draws, so they do not repeat the draws
/// of its directions and segment lengths.
const VARIED_SEED_OFFSET: u64 = 0x5eed;

/// The train, test and validation sequences of a dataset.
pub fn plan(spec: &DatasetSpec) -> Vec<SequencePlan> {
    let mut plans = Vec::new();
    let n = spec.train;
    // The k-th of `count` points spread evenly over [0, 1] (the middle for one).
    let spread = |k: usize, count: usize| if count == 1 { 0.5 } else { k as f64 / (count - 1) as f64 };
    // The seed of the k-th training sequence.
    let train_seed = |k: usize| spec.seed.wrapping_mul(1000).wrapping_add(k as u64);
    let train_plan = |k: usize, description: String, speeds: SpeedPlan| SequencePlan {
        name: format!("train-{k:02}"),
        split: Split::Train,
        description,
        speeds,
        seed: train_seed(k),
        dt: None,
    };
    for k in 0..n {
        let level = spread(k, n);
        plans.push(train_plan(
            k,
            format!("speed level {level:.2}"),
            SpeedPlan::constant(level),
        ));
    }
    for j in 0..spec.steady {
        let share = spread(j, spec.steady);
        plans.push(train_plan(
            n + j,
            format!("speed level 1.00, steady segments {share:.2} of the way through their range"),
            SpeedPlan {
                pieces: vec![(0, 1.0, 1.0)],
                steady: Some(share),
            },
        ));
    }
    for j in 0..spec.varied {
        let k = n + spec.steady + j;
        let rng = &mut bc::rng(train_seed(k).wrapping_add(VARIED_SEED_OFFSET));
        let pieces = (0..spec.frames.max(1))
            .step_by(VARIED_PIECE_FRAMES)
            .map(|frame| (frame, rng.random_range(0.0..=1.0), 1.0))
            .collect();
        plans.push(train_plan(
            k,
            format!("speed level drawn anew every {VARIED_PIECE_FRAMES} frames"),
            SpeedPlan { pieces, steady: None },
        ));
    }
    let half = spec.frames_of(Split::Test) / 2;
    let mut tests = Vec::new();
    if spec.test >= 1 {
        tests.push((
            format!("sudden drop from {:.2}x the top speed to a tenth of it", spec.beyond),
            SpeedPlan {
                pieces: vec![(0, 1.0, spec.beyond), (half, 1.0, spec.beyond / 10.0)],
                steady: None,
            },
        ));
    }
    if spec.test >= 2 {
        tests.push((
            format!("{:.2}x the top training speed", spec.beyond),
            SpeedPlan {
                pieces: vec![(0, 1.0, spec.beyond)],
                steady: None,
            },
        ));
    }
    let held_out = spec.test.saturating_sub(2);
    for j in 0..held_out {
        // Midpoints between training levels (or evenly inside the range for one level).
        let level = if n >= 2 {
            let gap = ((j * (n - 1)) / held_out.max(1)).min(n - 2);
            (spread(gap, n) + spread(gap + 1, n)) / 2.0
        } else {
            (j as f64 + 0.5) / held_out as f64
        };
        tests.push((format!("held-out speed level {level:.2}"), SpeedPlan::constant(level)));
    }
    for (k, (description, speeds)) in tests.into_iter().enumerate() {
        plans.push(SequencePlan {
            name: format!("test-{k:02}"),
            split: Split::Test,
            description,
            speeds,
            seed: spec.seed.wrapping_mul(1000).wrapping_add(500 + k as u64),
            dt: None,
        });
    }
    // Validation levels split the training range in `validation + 1` equal parts (1/3 and 2/3
    // for two): between the training levels and apart from the held-out test levels.
    for k in 0..spec.validation {
        let level = (k + 1) as f64 / (spec.validation + 1) as f64;
        plans.push(SequencePlan {
            name: format!("validation-{k:02}"),
            split: Split::Validation,
            description: format!("validation speed level {level:.2}"),
            speeds: SpeedPlan::constant(level),
            seed: spec.seed.wrapping_mul(1000).wrapping_add(700 + k as u64),
            dt: None,
        });
    }
    if let Some((shortest, longest)) = spec.frame_times() {
        spread_frame_times(&mut plans, spec.seed, shortest, longest);
    }
    plans
}

/// Gives the training and validation sequences of `plans` frame times spread geometrically
/// from `longest` to `shortest` (each split on its own), in an order shuffled by `seed`, and
/// names the rate in each description.
fn spread_frame_times(plans: &mut [SequencePlan], seed: u64, shortest: f64, longest: f64) {
    for split in [Split::Train, Split::Validation] {
        let members: Vec<usize> = (0..plans.len()).filter(|&i| plans[i].split == split).collect();
        let n = members.len();
        let mut order: Vec<usize> = (0..n).collect();
        let rng = &mut bc::rng(seed.wrapping_add(0xd7 + split as u64));
        // Fisher-Yates with the crate's seeded generator (no extra dependency for one shuffle).
        for i in (1..n).rev() {
            order.swap(i, rng.random_range(0..=i));
        }
        for (slot, &i) in order.iter().zip(&members) {
            let share = if n == 1 { 0.5 } else { *slot as f64 / (n - 1) as f64 };
            let dt = longest * (shortest / longest).powf(share);
            let plan = &mut plans[i];
            plan.dt = Some(dt);
            plan.description = format!("{}, {:.1} frames per second", plan.description, 1.0 / dt);
        }
    }
}

impl BuiltScene {
    /// This scene built with the time step `dt`, when `dt` is given and is not its own
    /// (`None`: step this one).
    pub fn at_frame_time(&self, dt: Option<f64>) -> Result<Option<BuiltScene>, InputError> {
        match dt {
            Some(dt) if dt != self.scene.dt => {
                let mut scene = self.scene.clone();
                scene.dt = dt;
                scene.build().map(Some)
            }
            _ => Ok(None),
        }
    }

    /// The boundary conditions of `plan` over `frames` frames at its frame time: the scene's
    /// motion sampled at `dt` ([`Self::sequence`]) and, for a plan at another frame time, the
    /// same motion seen at that one ([`BcSequence::resampled`]).
    pub fn plan_sequence(&self, plan: &SequencePlan, frames: usize) -> BcSequence {
        let dt = self.scene.dt;
        match plan.dt {
            Some(new_dt) if new_dt != dt => {
                let base = (frames as f64 * new_dt / dt).ceil() as usize + 1;
                self.sequence(&plan.speeds, base, plan.seed)
                    .resampled(dt, new_dt, frames)
            }
            _ => self.sequence(&plan.speeds, frames, plan.seed),
        }
    }

    /// The boundary conditions of a sequence: scripted handles follow their script;
    /// handles with a motion sample it with the plan's speeds; others stay put; colliders
    /// follow paths drawn from the seed (see [`BuiltScene::collider_tracks`]).
    pub fn sequence(&self, speeds: &SpeedPlan, frames: usize, seed: u64) -> BcSequence {
        let dt = self.scene.dt;
        let tracks = self
            .scene
            .handles
            .iter()
            .enumerate()
            .map(|(k, spec)| {
                let segments = if !spec.script.is_empty() {
                    spec.script.clone()
                } else if let Some(motion) = &spec.motion {
                    let at = |frame: usize| {
                        let (level, factor) = speeds.at(frame);
                        let (lin, ang) = motion.speeds_at(level);
                        (lin * factor, ang * factor)
                    };
                    let rng = &mut bc::rng(seed.wrapping_add(7919 * k as u64));
                    match speeds.steady {
                        Some(share) => motion.steady(share).sample(frames, &at, rng),
                        None => motion.sample(frames, &at, rng),
                    }
                } else {
                    Vec::new()
                };
                Track::from_segments(&segments, frames, dt)
            })
            .collect();
        let mut seq = BcSequence {
            tracks,
            frames,
            colliders: Vec::new(),
        };
        let handles: Vec<[f64; 3]> = seq
            .targets(&self.handles, 0, self.mesh.dim)
            .chunks(self.mesh.dim)
            .map(|p| [0, 1, 2].map(|i| p.get(i).copied().unwrap_or(0.0)))
            .collect();
        seq.colliders = self.collider_tracks(speeds, frames, seed, &handles);
        seq
    }

    /// Simulates `seq` from the scene's initial state and records the trajectory.
    pub fn run(&mut self, seq: &BcSequence, progress: &dyn Progress) -> Result<Trajectory, StepError> {
        self.run_reporting(seq, progress, &mut |_| {})
    }

    /// [`Self::run`], handing each step's solver report to `on_step` (benchmarks read
    /// where the time went).
    pub fn run_reporting(
        &mut self,
        seq: &BcSequence,
        progress: &dyn Progress,
        on_step: &mut dyn FnMut(&StepReport),
    ) -> Result<Trajectory, StepError> {
        let mut traj = self.start(seq)?;
        for frame in 1..=seq.frames() {
            let report = self.advance(seq, frame, &mut traj)?;
            on_step(&report);
            progress.advance(1);
        }
        Ok(traj)
    }

    /// Puts the simulator in the scene's initial state for `seq` (at rest, thrown, or in
    /// static equilibrium) and returns the trajectory's first frame.
    pub fn start(&mut self, seq: &BcSequence) -> Result<Trajectory, StepError> {
        let dim = self.mesh.dim;
        self.simulator.start_over();
        self.simulator.reset(&self.mesh.rest.clone());
        self.place_colliders(seq)?;
        let targets0 = seq.targets(&self.handles, 0, dim);
        if self.scene.start == Start::Static {
            self.simulator.solve_static(&targets0)?;
        } else {
            let mut x0 = self.mesh.rest.clone();
            for (i, &v) in self.simulator.fixed_vertices().iter().enumerate() {
                x0[v * dim..(v + 1) * dim].copy_from_slice(&targets0[i * dim..(i + 1) * dim]);
            }
            match self.scene.initial_velocity {
                // Thrown: positions one step back along the velocity give it.
                Some(v) => {
                    let dt = self.simulator.dt();
                    let back: Vec<f64> = x0.iter().enumerate().map(|(k, c)| c - dt * v[k % dim]).collect();
                    self.simulator.restart(&x0, &back);
                }
                None => self.simulator.reset(&x0),
            }
        }
        let energies = self.simulator.energies();
        let mut traj = Trajectory {
            scene: self.scene.name.clone(),
            dt: self.scene.dt,
            dim,
            positions: vec![self.simulator.positions().to_vec()],
            bc_signal: vec![seq.signal(0)],
            energy_names: energies.iter().map(|(n, _)| n.to_string()).collect(),
            energies: vec![energies.iter().map(|(_, e)| *e).collect()],
            newton_iterations: vec![0],
            step_seconds: vec![0.0],
            obstacles: self.simulator.obstacle_faces().map(|faces| ObstacleFrames {
                faces,
                positions: vec![self.simulator.obstacle_positions().unwrap_or_default().to_vec()],
            }),
            meta: vec![
                (
                    "handles".into(),
                    self.handles
                        .iter()
                        .map(|h| h.name.as_str())
                        .collect::<Vec<_>>()
                        .join(","),
                ),
                (
                    "bc_signal_layout".into(),
                    "per handle: velocity(3), angular_velocity(3), translation(3), rotation_vector(3)".into(),
                ),
            ],
            colliders: self.collider_frames(seq),
        };
        traj.meta.extend(self.collider_meta());
        Ok(traj)
    }

    /// Steps to `frame` of `seq`: the run-time colliders sent to their poses there, the
    /// handles to their targets. Every stepping of a sequence goes through here, so no caller
    /// leaves the colliders where [`Self::start`] placed them.
    pub fn step_to(&mut self, seq: &BcSequence, frame: usize) -> Result<StepReport, StepError> {
        self.move_colliders(seq, frame)?;
        self.simulator.step(&seq.targets(&self.handles, frame, self.mesh.dim))
    }

    /// Steps to `frame` of `seq` and appends it to `traj`.
    pub fn advance(&mut self, seq: &BcSequence, frame: usize, traj: &mut Trajectory) -> Result<StepReport, StepError> {
        let start = Instant::now();
        let report = self.step_to(seq, frame)?;
        let seconds = start.elapsed().as_secs_f64();
        traj.positions.push(self.simulator.positions().to_vec());
        traj.bc_signal.push(seq.signal(frame));
        traj.energies
            .push(self.simulator.energies().iter().map(|(_, e)| *e).collect());
        traj.newton_iterations.push(report.iterations as u32);
        traj.step_seconds.push(seconds);
        if let (Some(o), Some(at)) = (&mut traj.obstacles, self.simulator.obstacle_positions()) {
            o.positions.push(at.to_vec());
        }
        self.record_colliders(seq, frame, traj);
        Ok(report)
    }
}

/// The file of sequence `plan` in dataset directory `dir`.
pub fn sequence_path(dir: &Path, plan: &SequencePlan) -> PathBuf {
    dir.join(format!("{}.npz", plan.name))
}

/// Whether two frame times are the same (up to the rounding of their text in a file).
pub(crate) fn same_time(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * b.abs()
}

/// Reads the sequences of `split` of `problem`'s dataset from `dir`, in plan order, checking
/// that each belongs to the scene and has the planned length.
pub fn load(problem: &BuiltScene, dir: &Path, split: Split) -> Result<Vec<(SequencePlan, Trajectory)>, InputError> {
    let mut out = Vec::new();
    load_each(problem, dir, split, |plan, traj| {
        out.push((plan, traj));
        Ok::<(), InputError>(())
    })?;
    Ok(out)
}

/// The files of the sequences of `split` in `dir`, in plan order (whether or not they exist).
pub fn split_paths(problem: &BuiltScene, dir: &Path, split: Split) -> Vec<PathBuf> {
    plan(&problem.scene.dataset)
        .iter()
        .filter(|p| p.split == split)
        .map(|p| sequence_path(dir, p))
        .collect()
}

/// [`load`] one sequence at a time: reads and checks each sequence of `split` in plan order
/// and hands it to `each`, holding one in memory at a time.
pub fn load_each<E: From<InputError>>(
    problem: &BuiltScene,
    dir: &Path,
    split: Split,
    mut each: impl FnMut(SequencePlan, Trajectory) -> Result<(), E>,
) -> Result<(), E> {
    for plan in plan(&problem.scene.dataset).into_iter().filter(|p| p.split == split) {
        let traj = load_checked(problem, dir, &plan)?;
        each(plan, traj)?;
    }
    Ok(())
}

/// Reads sequence `plan` from `dir`, checking that it belongs to the scene and has the
/// planned length.
fn load_checked(problem: &BuiltScene, dir: &Path, plan: &SequencePlan) -> Result<Trajectory, InputError> {
    let spec = problem.scene.dataset;
    {
        let path = sequence_path(dir, plan);
        if !path.exists() {
            return Err(InputError::file(
                &path,
                format!(
                    "missing; generate it with `mochi dataset {}`",
                    problem.scene.source.display()
                ),
            ));
        }
        let traj = Trajectory::read_npz(&path)?;
        let frames = plan.frames(&spec, problem.scene.dt);
        if traj.num_frames() != frames + 1 || traj.dim != problem.mesh.dim {
            return Err(InputError::file(
                &path,
                format!(
                    "holds {} frames of {}D states; the scene plans {} frames of {}D (regenerate with `mochi dataset`)",
                    traj.num_frames(),
                    traj.dim,
                    frames + 1,
                    problem.mesh.dim
                ),
            ));
        }
        let dt = plan.dt.unwrap_or(problem.scene.dt);
        if !same_time(traj.dt, dt) {
            return Err(InputError::field(
                &path,
                "dt",
                format!(
                    "holds frames {} s apart; the scene plans this sequence at {} s (regenerate with `mochi dataset`)",
                    traj.dt, dt
                ),
            ));
        }
        if traj.positions[0].len() != problem.mesh.rest.len() {
            return Err(InputError::field(
                &path,
                "positions",
                format!(
                    "states have {} values, the scene's mesh has {}",
                    traj.positions[0].len(),
                    problem.mesh.rest.len()
                ),
            ));
        }
        Ok(traj)
    }
}

#[cfg(test)]
mod tests;
