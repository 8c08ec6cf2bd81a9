//! `mochi bench runtime`: per-frame cost of the no_std runtime (step + full decode, step +
//! surface decode, one thread) against candle's batch-1 forward of the same weights measured
//! in the same process, with achieved GFLOP/s, weight and instance-state bytes, and the
//! runtime's largest disagreement with the trainer's own rollout.
//!
//! The runtime's instance sizes are compile-time constants; here artifacts arrive at run
//! time, so the benchmark is instantiated for every latent size up to 16 and one or two
//! handles, with hidden scratch of 128 floats, or [`MAX_HIDDEN`] for wider models.

use std::path::{Path, PathBuf};
use std::time::Instant;

use candle_core::{Device, Tensor};
use mochi_codegen::{format_name, Options, Quantized};
use mochi_runtime::collider::{push_out, slot_collider, Collider, ColliderState, FEATURES_PER_COLLIDER};
use mochi_runtime::{HandleMotion, Instance, OwnedModel, Stepped, ValidModel, WeightFormat};

use crate::artifact::Artifact;
use crate::error::{bail, Context, TrainerResult as Result};
use crate::eval::rollout::{collider_states, motions};
use crate::eval::{self, LoadedModel};
use crate::learn::encoding::pack_signals;
use crate::learn::network::{Decoder, ResMlp};
use mochi_sim::dataset::{self, Split};
use mochi_sim::measure::vertex_errors;

/// Widest hidden layer the benchmark's instances can run.
pub(crate) const MAX_HIDDEN: usize = 512;
/// The benchmark's scratch for models no wider than this (the right-sized ones).
const NARROW_HIDDEN: usize = 128;

/// What one artifact measured.
#[derive(Clone, Debug)]
pub struct RuntimeTiming {
    /// Artifact file.
    pub path: PathBuf,
    /// Weight storage of the runtime model (`--weights`).
    pub weights: WeightFormat,
    /// Scene name.
    pub scene: String,
    /// Latent size.
    pub latent: usize,
    /// Numbers in a full state.
    pub state_len: usize,
    /// Numbers in a surface-only state.
    pub surface_len: usize,
    /// Seconds per frame: runtime step + full decode.
    pub full: f64,
    /// Seconds per frame: runtime step + surface decode.
    pub surface: f64,
    /// Run-time collider slots the model reads (stepped with the test sequence's colliders).
    pub colliders: usize,
    /// Seconds per frame of `collider::push_out` of the decoded surface (what is drawn; 0
    /// without colliders).
    pub push_out: f64,
    /// Render vertices of the model's render mesh (0 without one).
    pub render_vertices: usize,
    /// Seconds per frame: runtime step + render decode (full decode, render positions and
    /// normals; 0 without a render mesh).
    pub render: f64,
    /// Seconds per frame: candle batch-1 integrator + decoder forward.
    pub candle: f64,
    /// Multiply-adds of one integrator + full decoder forward.
    pub multiply_adds: usize,
    /// Bytes of weights and biases.
    pub weight_bytes: usize,
    /// Bytes of one instance.
    pub state_bytes: usize,
    /// Largest vertex distance / diagonal from the trainer's rollout over the compared frames.
    pub disagreement: f64,
    /// Frames compared (see [`agreement`]).
    pub compared_frames: usize,
}

impl RuntimeTiming {
    /// Candle's time over the runtime's (step + full decode).
    pub(crate) fn speedup(&self) -> f64 {
        self.candle / self.full
    }
    /// Achieved GFLOP/s of step + full decode (2 FLOPs per multiply-add).
    pub(crate) fn gflops(&self) -> f64 {
        2.0 * self.multiply_adds as f64 / self.full / 1e9
    }
}

/// Best seconds per call of `f` over 5 rounds of `calls` calls (after a warm-up round).
fn seconds_per_call(calls: usize, mut f: impl FnMut(usize)) -> f64 {
    let mut best = f64::INFINITY;
    for round in 0..6 {
        let clock = Instant::now();
        for i in 0..calls {
            f(i);
        }
        if round > 0 {
            best = best.min(clock.elapsed().as_secs_f64() / calls as f64);
        }
    }
    best
}

/// Benchmarks every artifact over `frames` frames of its scene's first test sequence, with
/// the runtime's weights stored in each of `storages` (as `mochi codegen --weights` would).
pub fn bench(paths: &[PathBuf], frames: usize, storages: &[WeightFormat]) -> Result<Vec<RuntimeTiming>> {
    let mut all = Vec::new();
    for p in paths {
        all.extend(bench_one(p, frames.max(1), storages)?);
    }
    Ok(all)
}

fn bench_one(path: &Path, frames: usize, storages: &[WeightFormat]) -> Result<Vec<RuntimeTiming>> {
    let bytes = crate::error::fs::read(path)?;
    let artifact = Artifact::from_bytes(&bytes, path)?;
    bench_artifact(&artifact, &bytes, path, frames, storages)
}

/// [`bench`] of one artifact held in memory (`bytes` its file, `path` its name in reports).
pub(crate) fn bench_artifact(
    artifact: &Artifact,
    bytes: &[u8],
    path: &Path,
    frames: usize,
    storages: &[WeightFormat],
) -> Result<Vec<RuntimeTiming>> {
    let mut storage = OwnedModel::default();
    let model = storage
        .load(bytes)
        .with_context(|| format!("{}: runtime refused the artifact", path.display()))?;
    let m = model.model();
    if m.hidden() > MAX_HIDDEN {
        bail!(
            "{}: hidden width {} is over the benchmark's {MAX_HIDDEN}",
            path.display(),
            m.hidden()
        );
    }
    let (problem, encoding) = eval::rebuild_problem(artifact)?;
    let plan = dataset::plan(&problem.scene.dataset)
        .into_iter()
        .find(|p| p.split == Split::Test)
        .context("the scene has no test sequence")?;
    let bc = problem.sequence(&plan.speeds, frames, plan.seed);
    let script: Vec<ScriptFrame> = (1..=frames)
        .map(|t| ScriptFrame {
            motions: motions(&bc, t),
            colliders: collider_states(&bc, t, m.colliders()),
        })
        .collect();

    let trainer = LoadedModel::new(artifact.clone())?;
    let reference = eval::stable_rollout(&trainer, &problem, &encoding, &bc, frames)?;

    let k = m.latent as usize;
    let s = m.bc_len as usize;
    let candle = candle_seconds(&trainer, &script, k)?;
    let mut timings = Vec::new();
    for &weights in storages {
        let options = Options::weights(weights);
        let stored = Quantized::split(m, options.decoder, options.integrator);
        // `f32` as the runtime loads it (on x86-64 a decoder's narrow output layer column by
        // column), the other storages as code generation writes them.
        let restored = match weights {
            WeightFormat::F32 => *m,
            _ => stored.model(m),
        };
        let model = ValidModel::new(restored)
            .with_context(|| format!("{}: with {} weights", path.display(), format_name(weights)))?;
        let run = Run {
            model: &model,
            script: &script,
            reference: &reference,
            diagonal: artifact.diagonal,
        };
        let measured = run_for_sizes(k, s, m.hidden(), &run)?;
        timings.push(RuntimeTiming {
            path: path.to_path_buf(),
            weights,
            scene: artifact.scene.clone(),
            latent: k,
            state_len: m.state_len(),
            surface_len: m.surface_len(),
            full: measured.full,
            surface: measured.surface,
            colliders: m.colliders(),
            push_out: measured.push_out,
            render_vertices: m.render_vertices(),
            render: measured.render,
            candle,
            // A bend-encoded model's decode also walks every strand, a step per vertex.
            multiply_adds: mochi_runtime::network::multiply_adds(m.integrator)
                + mochi_runtime::network::multiply_adds(m.decoder)
                + m.walk_multiply_adds(),
            weight_bytes: model.model().weight_bytes(),
            state_bytes: measured.state_bytes,
            disagreement: measured.disagreement,
            compared_frames: measured.compared,
        });
    }
    Ok(timings)
}

/// One frame of the benchmark's motion: the handles' motions and the colliders' states.
pub struct ScriptFrame {
    /// Per handle.
    pub motions: Vec<HandleMotion>,
    /// Per collider slot of the model.
    pub colliders: Vec<ColliderState>,
}

impl ScriptFrame {
    /// One runtime step of `body` with this frame's handles and colliders.
    fn step<const K: usize, const S: usize, const H: usize>(
        &self,
        body: &mut Instance<K, S, H>,
        model: &ValidModel,
    ) -> std::result::Result<Stepped, mochi_runtime::StepError> {
        body.step_with(model, &self.motions, &self.colliders, model.model().dt)
    }
}

/// What the runtime rollout needs.
struct Run<'a> {
    model: &'a ValidModel<'a>,
    script: &'a [ScriptFrame],
    reference: &'a [Vec<f64>],
    diagonal: f64,
}

struct Measured {
    full: f64,
    surface: f64,
    push_out: f64,
    render: f64,
    state_bytes: usize,
    disagreement: f64,
    compared: usize,
}

/// Largest vertex distance / diagonal between the runtime's rollout of `model` over `script`
/// and the trainer's states `reference` (one per frame, see [`eval::stable_rollout`]), over the
/// frames before the reference ends or the runtime first clamps or holds a latent (its
/// documented departures from the trainer); and how many frames were compared.
pub fn agreement<const K: usize, const S: usize, const H: usize>(
    model: &ValidModel,
    script: &[ScriptFrame],
    reference: &[Vec<f64>],
    diagonal: f64,
) -> Result<(f64, usize)> {
    let m = model.model();
    let mut body = Instance::<K, S, H>::new(model)?;
    let mut x = vec![0.0f32; m.state_len()];
    let (mut worst, mut compared) = (0.0f64, 0);
    for (bc, r) in script.iter().zip(reference) {
        if bc.step(&mut body, model)? != Stepped::Ok {
            break;
        }
        body.decode_into(model, &mut x)?;
        worst = vertex_errors(&x, r, m.dim(), diagonal).fold(worst, f64::max);
        compared += 1;
    }
    Ok((worst, compared))
}

fn measure<const K: usize, const S: usize, const H: usize>(run: &Run) -> Result<Measured> {
    let model = run.model;
    let m = model.model();
    let fresh = || Instance::<K, S, H>::new(model);
    let (disagreement, compared) = agreement::<K, S, H>(model, run.script, run.reference, run.diagonal)?;
    let mut x = vec![0.0f32; m.state_len()];
    let frames = run.script.len();
    let mut body = fresh()?;
    let full = seconds_per_call(frames, |i| {
        let _ = run.script[i % frames].step(&mut body, model);
        let _ = body.decode_into(model, &mut x);
    });
    let mut body = fresh()?;
    let mut surface_x = vec![0.0f32; m.surface_len()];
    let surface = seconds_per_call(frames, |i| {
        let _ = run.script[i % frames].step(&mut body, model);
        let _ = body.decode_surface_into(model, &mut surface_x);
    });
    let push_out = match m.colliders() {
        0 => 0.0,
        _ => {
            let posed = |states: &[ColliderState]| -> Vec<Collider> {
                states
                    .iter()
                    .enumerate()
                    .filter_map(|(slot, s)| slot_collider(m, slot, s))
                    .collect()
            };
            let shapes: Vec<Collider> = (0..frames).flat_map(|i| posed(&run.script[i].colliders)).collect();
            let per_frame = shapes.len() / frames.max(1);
            seconds_per_call(frames, |i| {
                let _ = push_out(
                    &mut surface_x,
                    m.dim(),
                    &shapes[i * per_frame..(i + 1) * per_frame],
                    0.0,
                );
            })
        }
    };
    let render = match m.has_render() {
        false => 0.0,
        true => {
            let mut body = fresh()?;
            let (mut positions, mut normals) = (vec![0.0f32; m.render_len()], vec![0.0f32; m.render_len()]);
            seconds_per_call(frames, |i| {
                let _ = run.script[i % frames].step(&mut body, model);
                let _ = body.decode_render_into(model, &mut x, &mut positions, &mut normals);
            })
        }
    };
    Ok(Measured {
        full,
        surface,
        push_out,
        render,
        state_bytes: std::mem::size_of::<Instance<K, S, H>>(),
        disagreement,
        compared,
    })
}

/// `measure::<K, S, H>` for the artifact's latent size and signal length, with the narrowest
/// hidden scratch `H` that holds the model's widest layer (a generated module's `HIDDEN` is
/// that width: scratch it does not need would only be zeroed every frame).
fn run_for_sizes(k: usize, s: usize, hidden: usize, run: &Run) -> Result<Measured> {
    macro_rules! sizes {
        ($($k:literal)*) => {
            match (k, s, hidden <= NARROW_HIDDEN) {
                $(($k, 0, true) => measure::<$k, 0, NARROW_HIDDEN>(run),)*
                $(($k, 12, true) => measure::<$k, 12, NARROW_HIDDEN>(run),)*
                $(($k, 24, true) => measure::<$k, 24, NARROW_HIDDEN>(run),)*
                $(($k, 0, false) => measure::<$k, 0, MAX_HIDDEN>(run),)*
                $(($k, 12, false) => measure::<$k, 12, MAX_HIDDEN>(run),)*
                $(($k, 24, false) => measure::<$k, 24, MAX_HIDDEN>(run),)*
                _ => bail!("the benchmark runs latent sizes 1-16 with no, one or two handles, not latent {k} with {s} signal numbers"),
            }
        };
    }
    sizes!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16)
}

/// Seconds per frame of candle's batch-1 forward of the integrator and the decoder (weights
/// from the same artifact), rolling out the same script; the frame transform is left out, so
/// candle does less work than the runtime here.
fn candle_seconds(trainer: &LoadedModel, script: &[ScriptFrame], k: usize) -> Result<f64> {
    let integrator = ResMlp::from_exported(trainer.integrator.mlp())?;
    let decoder = Decoder::from_frozen(&trainer.decoder)?;
    let signal = |i: usize| -> Vec<f64> {
        script[i]
            .motions
            .iter()
            .flat_map(|m| m.signal())
            .map(f64::from)
            .collect()
    };
    // Collider inputs of the right length (candle's cost does not depend on their values).
    let colliders = vec![0.0f32; FEATURES_PER_COLLIDER * trainer.artifact.colliders()];
    // A timed model steps at its own frame time here.
    let dt = trainer.artifact.timed().then_some(trainer.artifact.dt);
    let initial = trainer.artifact.initial_latent.clone();
    let (mut z, mut z_prev) = (initial.clone(), initial);
    let zero = vec![0.0f64; signal(0).len()];
    let (mut p1, mut p2) = (zero.clone(), zero);
    let mut failed = None;
    let frames = script.len();
    let seconds = seconds_per_call(frames, |i| {
        let p0 = signal(i % frames);
        let input = pack_signals(&z, &z_prev, [&p0, &p1, &p2], &colliders, dt);
        let result = (|| -> candle_core::Result<Vec<f32>> {
            let x = Tensor::from_slice(&input, (1, input.len()), &Device::Cpu)?;
            let increment = integrator.forward(&x)?;
            let z_t = (increment + Tensor::from_slice(&z, (1, k), &Device::Cpu)?)?;
            let q = decoder.forward(&z_t)?;
            let _decoded: Vec<f32> = q.flatten_all()?.to_vec1()?;
            z_t.flatten_all()?.to_vec1()
        })();
        match result {
            Ok(next) => {
                z_prev = std::mem::replace(&mut z, next);
                p2 = std::mem::replace(&mut p1, p0);
            }
            Err(e) => failed = Some(e),
        }
    });
    if let Some(e) = failed {
        bail!("candle forward failed: {e}");
    }
    Ok(seconds)
}

/// The benchmark table (markdown).
pub fn table(timings: &[RuntimeTiming]) -> String {
    let mut s = format!(
        "Runtime kernels on this CPU: `f32` {:?} (`mochi_runtime::network::fast`), `f16` canonical sum, int8 integer sum.\n\n",
        mochi_runtime::network::fast::width()
    );
    s += "| artifact | weights | latent | colliders | step + full decode | step + surface decode | push-out | step + render decode | candle batch-1 | runtime speed-up | GFLOP/s | weights | instance state | max disagreement (frames) |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n";
    for t in timings {
        let push = match t.colliders {
            0 => "-".to_string(),
            _ => format!("{:.1} µs", 1e6 * t.push_out),
        };
        let render = match t.render_vertices {
            0 => "-".to_string(),
            n => format!("{:.1} µs ({n} vertices)", 1e6 * t.render),
        };
        s += &format!(
            "| {} | {} | {} | {} | {:.1} µs | {:.1} µs | {push} | {render} | {:.1} µs | {:.1}x | {:.2} | {:.1} KiB | {} B | {:.1e} ({}) |\n",
            t.path
                .file_name()
                .map_or(t.scene.clone(), |n| n.to_string_lossy().into_owned()),
            format_name(t.weights),
            t.latent,
            t.colliders,
            1e6 * t.full,
            1e6 * t.surface,
            1e6 * t.candle,
            t.speedup(),
            t.gflops(),
            t.weight_bytes as f64 / 1024.0,
            t.state_bytes,
            t.disagreement,
            t.compared_frames
        );
    }
    s
}
