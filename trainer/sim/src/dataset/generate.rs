//! Making a dataset's sequences: all of them, a split, named ones or a shard, skipping those
//! already complete, each written whole and recorded in the directory's [`super::manifest`].

use std::path::Path;
use std::time::Instant;

use super::{closest_collider_approach, manifest, plan, same_time, sequence_path, SequencePlan, Split};
use crate::error::{InputError, SimError};
use crate::progress::Progress;
use crate::scene::BuiltScene;
use crate::trajectory::Trajectory;

/// What [`generate`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GenerateReport {
    /// Sequences simulated (those already on disk are not counted).
    pub sequences: usize,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// Seconds per full-space step, over all simulated frames.
    pub step_seconds: Vec<f64>,
    /// Newton iterations per step.
    pub newton_iterations: Vec<f64>,
    /// The smallest signed distance of a surface vertex to an analytic collider over every
    /// simulated frame (negative: a penetration depth); `None` without colliders.
    pub collider_min_distance: Option<f64>,
}

/// Which of a dataset's sequences to make.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Selection {
    /// Every sequence of the plan.
    All,
    /// Those of one split.
    Split(Split),
    /// Those named (file stems such as `train-03`).
    Names(Vec<String>),
    /// Shard `index` of `count` (0-based): the plan's sequences `index`, `index + count`, ...
    Shard {
        /// This shard.
        index: usize,
        /// Shards in all.
        count: usize,
    },
}

impl Selection {
    /// The planned sequences it takes, in plan order; `Err` naming what it asks for that the
    /// plan does not have.
    pub fn pick(&self, plans: Vec<SequencePlan>) -> Result<Vec<SequencePlan>, String> {
        Ok(match self {
            Selection::All => plans,
            Selection::Split(split) => plans.into_iter().filter(|p| p.split == *split).collect(),
            Selection::Names(names) => {
                if let Some(missing) = names.iter().find(|n| !plans.iter().any(|p| &p.name == *n)) {
                    let known: Vec<&str> = plans.iter().map(|p| p.name.as_str()).collect();
                    return Err(format!(
                        "the dataset plans no sequence `{missing}` (it has {})",
                        known.join(", ")
                    ));
                }
                plans.into_iter().filter(|p| names.contains(&p.name)).collect()
            }
            Selection::Shard { index, count } => {
                if *count == 0 || index >= count {
                    return Err(format!("shard {index} of {count}: expected 0 <= index < count"));
                }
                plans.into_iter().skip(*index).step_by(*count).collect()
            }
        })
    }
}

/// Simulates the sequences of `problem`'s dataset (only those of `split` when given) into
/// `dir`, skipping those already complete unless `overwrite` (see [`generate_selected`]).
pub fn generate(
    problem: &mut BuiltScene,
    dir: &Path,
    split: Option<Split>,
    overwrite: bool,
    progress: &dyn Progress,
) -> Result<GenerateReport, SimError> {
    let selection = split.map_or(Selection::All, Selection::Split);
    generate_selected(problem, dir, &selection, overwrite, progress)
}

/// Simulates the `selection` of `problem`'s dataset into `dir`. A sequence already there is
/// skipped when the directory's [`manifest`] records it and its file reads back whole with
/// the planned frames (checked, not just present); `overwrite` makes every selected one anew.
/// Each sequence is written whole or not at all, without timings (its bytes depend only on
/// the scene and its plan), and recorded in the manifest with its time as soon as it is
/// done, so a run killed mid-sequence resumes at that sequence. A directory made from
/// another scene or mochi version is refused.
pub fn generate_selected(
    problem: &mut BuiltScene,
    dir: &Path,
    selection: &Selection,
    overwrite: bool,
    progress: &dyn Progress,
) -> Result<GenerateReport, SimError> {
    std::fs::create_dir_all(dir).map_err(|source| SimError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let spec = problem.scene.dataset;
    let scene_dt = problem.scene.dt;
    let made = manifest::open(dir, problem, overwrite)?;
    let complete = |p: &SequencePlan| {
        let frames = p.frames(&spec, scene_dt);
        made.has(&p.name, frames, p.dt.unwrap_or(scene_dt)) && is_current(&sequence_path(dir, p), frames, p.dt)
    };
    let todo: Vec<SequencePlan> = selection
        .pick(plan(&spec))
        .map_err(|e| InputError::field(&problem.scene.source, "dataset", e))?
        .into_iter()
        .filter(|p| overwrite || !complete(p))
        .collect();
    let total: usize = todo.iter().map(|p| p.frames(&spec, scene_dt)).sum();
    let name = problem.scene.name.clone();
    progress.start(total as u64);
    let start = Instant::now();
    let mut report = GenerateReport::default();
    for plan in &todo {
        progress.message(&format!("{name} {}", plan.name));
        let begun = Instant::now();
        let seq = problem.plan_sequence(plan, plan.frames(&spec, scene_dt));
        // A sequence at another frame time is simulated by the scene built with that step.
        let mut rebuilt = problem.at_frame_time(plan.dt)?;
        let simulator = rebuilt.as_mut().unwrap_or(problem);
        let mut traj = simulator.run(&seq, progress).map_err(|source| SimError::Step {
            scene: name.clone(),
            sequence: plan.name.clone(),
            source,
        })?;
        traj.meta.push(("split".into(), plan.split.as_str().into()));
        traj.meta.push(("sequence".into(), plan.description.clone()));
        traj.meta.push(("seed".into(), plan.seed.to_string()));
        let step_seconds = std::mem::take(&mut traj.step_seconds);
        let path = sequence_path(dir, plan);
        // A partial file of this process's own: a retried task may run beside a worker that
        // was given up on but still writes the same sequence (the same bytes).
        let partial = path.with_extension(format!("npz.{}.partial", std::process::id()));
        traj.write_npz(&partial)?;
        std::fs::rename(&partial, &path).map_err(|source| SimError::Io {
            path: path.clone(),
            source,
        })?;
        let iterations = &traj.newton_iterations[1..];
        manifest::record(
            dir,
            &made,
            manifest::SequenceRecord {
                name: plan.name.clone(),
                frames: traj.num_frames() - 1,
                dt: traj.dt,
                seed: plan.seed,
                seconds: begun.elapsed().as_secs_f64(),
                iterations: iterations.iter().map(|&i| f64::from(i)).sum::<f64>() / iterations.len().max(1) as f64,
            },
        )?;
        let surface = problem.simulator.collider_barrier().map(|b| b.vertices().to_vec());
        if let Some(closest) = surface.and_then(|v| closest_collider_approach(&traj, &v)) {
            report.collider_min_distance = Some(report.collider_min_distance.map_or(closest, |m| m.min(closest)));
        }
        report.step_seconds.extend_from_slice(&step_seconds[1..]);
        report
            .newton_iterations
            .extend(traj.newton_iterations[1..].iter().map(|&i| i as f64));
        report.sequences += 1;
    }
    progress.finish();
    report.seconds = start.elapsed().as_secs_f64();
    Ok(report)
}

/// Whether `path` holds a readable trajectory of `frames` frames (after the initial one) at
/// the frame time `dt` (`None`: any; the scene's own is checked on load).
fn is_current(path: &Path, frames: usize, dt: Option<f64>) -> bool {
    path.exists()
        && Trajectory::read_npz(path)
            .is_ok_and(|t| t.num_frames() == frames + 1 && dt.is_none_or(|dt| same_time(t.dt, dt)))
}
