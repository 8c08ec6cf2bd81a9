//! The conditions of the stability matrix (docs/design.md, "Methods side by side"): each is a
//! scene (the material ten times stiffer, or the time step halved or doubled at run time) and a
//! boundary-condition sequence in that scene's time step.

use mochi_sim::bc::BcSequence;
use mochi_sim::dataset::{SequencePlan, SpeedPlan};
use mochi_sim::{BuiltScene, Scene};

use crate::error::{TrainerError, TrainerResult};

/// What a condition changes at run time, which the learned integrator cannot take without
/// retraining.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RunTimeChange {
    /// Nothing: only the motion differs.
    None,
    /// The time step multiplied by this factor.
    TimeStep(f64),
    /// Young's modulus multiplied by this factor.
    Stiffness(f64),
}

/// One row of the stability matrix.
#[derive(Clone, Debug)]
pub struct Condition {
    /// Short name (`1.5x speed`, `dt halved`, ...).
    pub name: String,
    /// The scene as the methods see it.
    pub scene: Scene,
    /// The motion, in `scene`'s time step.
    pub bc: BcSequence,
    /// Frames measured against the reference from the start.
    pub measured: usize,
    /// Frames measured again at the end (the long condition: how far the method has drifted
    /// after all its frames); 0 for none. Frames between the two windows are stepped for
    /// stability only.
    pub last_window: usize,
    /// What changes at run time.
    pub change: RunTimeChange,
}

/// How many frames and which conditions a matrix has.
#[derive(Clone, Copy, Debug)]
pub struct MatrixSpan {
    /// Frames of each condition (at the scene's time step).
    pub frames: usize,
    /// Frames of the long condition (its first `frames` are measured).
    pub long_frames: usize,
}

/// The matrix's conditions for `problem`'s scene: in range (the scene's middle training
/// speed), 1.5x and 2x the top training speed and a sudden stop from the top speed (only
/// where a handle's or a run-time collider's motion is sampled from speeds: a scripted
/// motion has one speed), the in-range motion over `long_frames` (measured over its first
/// and its last `frames`), the time step halved and doubled at run time, the material ten
/// times stiffer, and contact when the scene has it (its in-range motion with
/// contact on).
pub fn conditions(problem: &BuiltScene, span: MatrixSpan) -> Vec<Condition> {
    let scene = &problem.scene;
    let seed = scene.dataset.seed.wrapping_mul(7_777).wrapping_add(1);
    let frames = span.frames;
    let at = |level: f64, factor: f64| SpeedPlan {
        pieces: vec![(0, level, factor)],
        steady: None,
    };
    let in_range = problem.sequence(&at(0.5, 1.0), frames, seed);
    let mut out = vec![plain("in range", scene, in_range.clone(), frames)];
    let sampled_speeds = scene.handles.iter().any(|h| h.motion.is_some() && h.script.is_empty())
        || scene.colliders.iter().any(|c| c.motion.is_some());
    if sampled_speeds {
        let fast = |factor| problem.sequence(&at(1.0, factor), frames, seed);
        out.push(plain("1.5x top speed", scene, fast(1.5), frames));
        out.push(plain("2x top speed", scene, fast(2.0), frames));
        let stop = SpeedPlan {
            pieces: vec![(0, 1.0, 1.0), (frames / 2, 1.0, 0.0)],
            steady: None,
        };
        out.push(plain(
            "sudden stop",
            scene,
            problem.sequence(&stop, frames, seed),
            frames,
        ));
    }
    out.push(Condition {
        name: format!("{} frames", span.long_frames),
        scene: scene.clone(),
        bc: problem.sequence(&at(0.5, 1.0), span.long_frames, seed),
        measured: frames,
        last_window: if span.long_frames > frames { frames } else { 0 },
        change: RunTimeChange::None,
    });
    let mut halved = scene.clone();
    halved.dt /= 2.0;
    out.push(Condition {
        name: "dt halved".into(),
        scene: halved,
        bc: in_range.refined(2, scene.dt),
        measured: 2 * frames,
        last_window: 0,
        change: RunTimeChange::TimeStep(0.5),
    });
    let mut doubled = scene.clone();
    doubled.dt *= 2.0;
    out.push(Condition {
        name: "dt doubled".into(),
        scene: doubled,
        bc: in_range.every(2),
        measured: frames / 2,
        last_window: 0,
        change: RunTimeChange::TimeStep(2.0),
    });
    let mut stiff = scene.clone();
    stiff.material.youngs *= 10.0;
    for region in &mut stiff.material.regions {
        region.youngs = region.youngs.map(|e| 10.0 * e);
    }
    out.push(Condition {
        name: "10x stiffer".into(),
        scene: stiff,
        bc: in_range.clone(),
        measured: frames,
        last_window: 0,
        change: RunTimeChange::Stiffness(10.0),
    });
    if scene.contact.is_some() {
        out.push(plain("contact", scene, in_range, frames));
    }
    out
}

/// The conditions named in `only` (each as its file stem, [`super::slug`]: `in-range`,
/// `10000-frames`, `dt-halved`, ...), in the matrix's order; all of them when `only` is empty.
/// A name that is no condition of the scene is refused, naming the ones it has.
pub fn select(all: Vec<Condition>, only: &[String]) -> TrainerResult<Vec<Condition>> {
    if only.is_empty() {
        return Ok(all);
    }
    let names: Vec<String> = all.iter().map(|c| super::slug(&c.name)).collect();
    if let Some(unknown) = only.iter().find(|n| !names.contains(n)) {
        return Err(TrainerError::invalid(format!(
            "--conditions: `{unknown}` is no condition of this scene's matrix (it has {})",
            names.join(", ")
        )));
    }
    Ok(all
        .into_iter()
        .zip(names)
        .filter(|(_, n)| only.contains(n))
        .map(|(c, _)| c)
        .collect())
}

fn plain(name: &str, scene: &Scene, bc: BcSequence, frames: usize) -> Condition {
    Condition {
        name: name.into(),
        scene: scene.clone(),
        bc,
        measured: frames,
        last_window: 0,
        change: RunTimeChange::None,
    }
}

/// The test sequences the chart measures: `count` of the scene's test split, the held-out
/// speeds inside the training range first (test-02, test-03, ...; beyond the range is the
/// stability matrix's part), each over `frames` frames.
pub fn chart_sequences(problem: &BuiltScene, count: usize, frames: usize) -> Vec<(SequencePlan, BcSequence)> {
    let tests: Vec<SequencePlan> = mochi_sim::dataset::plan(&problem.scene.dataset)
        .into_iter()
        .filter(|p| p.split == mochi_sim::dataset::Split::Test)
        .collect();
    let in_range = tests.len().min(2);
    tests[in_range..]
        .iter()
        .chain(&tests[..in_range])
        .take(count)
        .cloned()
        .map(|p| {
            let bc = problem.sequence(&p.speeds, frames, p.seed);
            (p, bc)
        })
        .collect()
}
