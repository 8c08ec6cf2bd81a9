//! The `mochi` command-line tool.

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use mochi_sim::dataset::{self, SpeedPlan, Split};
use mochi_sim::{Progress, Scene};
use mochi_trainer::eval;
use mochi_trainer::report::render;
use mochi_trainer::{artifact_paths, shipped_scene_names, FramesBar, Recipe, Reporter};
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Parser)]
#[command(
    name = "mochi",
    version,
    about = "Soft bodies in real time: simulate, learn, freeze, run"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The whole path on one scene: train (or reuse), generate code, compile it against the
    /// runtime, run it on a held-out script and compare with the full-space solver.
    Demo {
        /// Scene name or path.
        #[arg(default_value = "beam")]
        scene: String,
        /// Output directory; default out/SCENE.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Frames of the runtime rollout compared with the full-space solver.
        #[arg(long, default_value_t = 300)]
        frames: usize,
        /// Train again even when the artifact exists.
        #[arg(long)]
        retrain: bool,
    },
    /// Simulate one boundary-condition sequence of a scene in full space.
    Simulate {
        /// Scene name (shipped: see `mochi scenes`) or path to a scene TOML file.
        scene: String,
        /// Frames to simulate after the initial one.
        #[arg(long, default_value_t = 120)]
        frames: usize,
        /// Output trajectory (.npz); default out/SCENE/simulate.npz.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Speed level of sampled handle motions (0: bottom, 1: top of the training range).
        #[arg(long, default_value_t = 0.5)]
        level: f64,
        /// Seed of the sampled motion (default: the scene's dataset seed).
        #[arg(long)]
        seed: Option<u64>,
        /// Also write surface OBJ files of every k-th frame into this directory.
        #[arg(long)]
        obj: Option<PathBuf>,
        /// Frame stride of the OBJ sequence.
        #[arg(long, default_value_t = 1)]
        obj_every: usize,
        /// Also write a PNG preview of these frames (comma separated).
        #[arg(long, value_delimiter = ',')]
        png_frames: Vec<usize>,
    },
    /// Generate the train and test trajectories of a scene.
    Dataset {
        /// Scene name or path.
        scene: String,
        /// Output directory; default out/SCENE/dataset.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Train a latent model: dataset (if missing), autoencoder, integrators, artifact.
    Train {
        /// Scene name or path.
        scene: String,
        /// Output directory; default out/SCENE.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Continue from the checkpoints of an interrupted run.
        #[arg(long)]
        resume: bool,
        /// Train only this latent size instead of choosing among the scene's candidates.
        #[arg(long)]
        latent: Option<usize>,
    },
    /// Evaluate trained models on the held-out test sequences (with their supervised baselines).
    Eval {
        /// Artifacts (`SCENE.mochi`) of one scene; `SCENE.supervised.mochi` beside each is added.
        #[arg(required = true)]
        artifacts: Vec<PathBuf>,
        /// Output directory for report.md and charts; default: eval/ beside the first artifact.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Frames of the stability rollout.
        #[arg(long, default_value_t = eval::STABILITY_FRAMES)]
        frames: usize,
        /// Frames of accuracy measurement at the start of each test sequence.
        #[arg(long, default_value_t = eval::ACCURACY_FRAMES)]
        accuracy_frames: usize,
        /// Also step the test sequences with the adaptive subspace solver (always for
        /// scenes whose `[solver]` is adaptive).
        #[arg(long)]
        adaptive: bool,
    },
    /// Replace a model's decoder by a cheaper one fitted to it (a small MLP before a linear
    /// basis) on the latents its own rollouts over the scene's training motions visit; the
    /// integrator is kept, so the latent trajectories do not change. With `--integrator W`
    /// the integrator is then distilled into width `W` too (its own rollouts added to the fit
    /// for `--rounds` rounds).
    Distill {
        /// Artifact (`SCENE.mochi`).
        artifact: PathBuf,
        /// Output artifact.
        #[arg(long)]
        out: PathBuf,
        /// Columns of the basis (at least the latent size).
        #[arg(long, default_value_t = 8)]
        modes: usize,
        /// Width of the MLP before the basis.
        #[arg(long, default_value_t = 32)]
        hidden: usize,
        /// Residual blocks of that MLP.
        #[arg(long, default_value_t = 1)]
        blocks: usize,
        /// Training epochs over the latents.
        #[arg(long, default_value_t = 300)]
        epochs: usize,
        /// Also distil the integrator into this hidden width (0: keep it).
        #[arg(long, default_value_t = 0)]
        integrator: usize,
        /// Residual blocks of the distilled integrator.
        #[arg(long, default_value_t = 2)]
        integrator_blocks: usize,
        /// Rollouts of the distilled integrator whose inputs are added to its fit.
        #[arg(long, default_value_t = 3)]
        rounds: usize,
        /// Keep the decoder (distil only the integrator).
        #[arg(long)]
        keep_decoder: bool,
        /// Fit the decoder to rod strands as positions when the model encodes them by their
        /// bends: the decode then skips the strand walk (the fit wants many more epochs than
        /// the default: rods takes 12,000).
        #[arg(long)]
        strand_positions: bool,
        /// Frames of each rollout over a training motion, for every fit (default: the scene's
        /// dataset frames).
        #[arg(long)]
        frames: Option<usize>,
    },
    /// Freeze an artifact into a Rust module of static arrays for the runtime.
    Codegen {
        /// Artifact (`SCENE.mochi`).
        artifact: PathBuf,
        /// Output Rust file.
        #[arg(short, long)]
        out: PathBuf,
        /// Weight storage: f32, f16 or int8 (per-row scales; the integrator stays f16);
        /// `mochi eval` reports what each costs in accuracy.
        #[arg(long, default_value = "f32", value_parser = parse_weights)]
        weights: mochi_runtime::WeightFormat,
    },
    /// Rewrite artifacts of an older format (2, 3) in place in the current one; fields
    /// unchanged, weights too except that values below 2^-40 of their layer's largest weight
    /// are written as zero (the runtime and codegen read only the current format).
    Upgrade {
        /// Artifacts (`SCENE.mochi`).
        #[arg(required = true)]
        artifacts: Vec<PathBuf>,
    },
    /// Write an artifact's networks as the runtime runs them, with the runtime's rollout of
    /// the targets' reference script, to a numpy `.npz` archive (for `scripts/bench-jax.sh`).
    ExportWeights {
        /// Artifact (`SCENE.mochi`).
        artifact: PathBuf,
        /// Output archive (`.npz`).
        #[arg(long)]
        out: PathBuf,
        /// Frames of the reference script.
        #[arg(long, default_value_t = 1000)]
        frames: usize,
        /// Weight storage, as `mochi codegen --weights`.
        #[arg(long, default_value = "f32", value_parser = parse_weights)]
        weights: mochi_runtime::WeightFormat,
    },
    /// Timings.
    Bench {
        #[command(subcommand)]
        what: Bench,
    },
    /// List the shipped scenes.
    Scenes,
}

#[derive(Subcommand)]
enum Bench {
    /// Full-space simulator: ms per step and Newton iterations per scene.
    Sim {
        /// Scenes (default: all shipped).
        scenes: Vec<String>,
        /// Frames per scene.
        #[arg(long, default_value_t = 60)]
        frames: usize,
        /// For adaptive scenes: also step full space from each adaptive state and report
        /// the per-step difference.
        #[arg(long)]
        per_step: bool,
        /// For adaptive scenes: time the model's Schur-complement PCG, faer's sparse
        /// Cholesky and block-Jacobi PCG on the largest Newton system met (its checks cost
        /// time inside the timed steps).
        #[arg(long)]
        linear_solvers: bool,
        /// For adaptive scenes: run the comparison for each of `--values` of this setting
        /// (error, youngs, downdate) and chart it.
        #[arg(long)]
        sweep: Option<String>,
        /// The swept values, comma-separated.
        #[arg(long, value_delimiter = ',')]
        values: Vec<f64>,
        /// Directory for the adaptive tables and sweep charts.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// The no_std runtime (one thread) against candle's batch-1 forward of the same weights.
    Runtime {
        /// Artifacts (`SCENE.mochi`).
        #[arg(required = true)]
        artifacts: Vec<PathBuf>,
        /// Frames per timing round (the first test sequence of each scene).
        #[arg(long, default_value_t = 1000)]
        frames: usize,
        /// Also write the table to this markdown file.
        #[arg(long)]
        out: Option<PathBuf>,
        /// Weight storages to time, comma-separated (f32, f16, int8).
        #[arg(long, default_value = "f32", value_delimiter = ',', value_parser = parse_weights)]
        weights: Vec<mochi_runtime::WeightFormat>,
    },
    /// The reduced-order solver in each subspace of a `.reduced` file (written by `mochi
    /// train` for scenes with a `[reduced]` table), against the vanilla subspace.
    Reduced {
        /// The scene's `SCENE.reduced`.
        reduced: PathBuf,
        /// Frames of each test motion.
        #[arg(long, default_value_t = 300)]
        frames: usize,
        /// Start every step's L-BFGS from steepest descent, whatever the scene's
        /// `reduced.warm_start` says (the paper's solver).
        #[arg(long)]
        cold: bool,
        /// Also write the table to this markdown file.
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

/// `--weights` values.
fn parse_weights(name: &str) -> std::result::Result<mochi_runtime::WeightFormat, String> {
    mochi_codegen::parse_format(name).ok_or_else(|| format!("`{name}` is not one of f32, f16, int8"))
}

/// Reports on the terminal: stages and messages as lines on stdout, progress as bars.
struct Terminal;

impl Reporter for Terminal {
    fn stage(&self, name: &str) {
        println!("== {name}");
    }
    fn message(&self, text: &str) {
        println!("{text}");
    }
    fn bars(&self) -> bool {
        true
    }
}

fn main() {
    mochi_trainer::configure_threads();
    if let Err(e) = run(Cli::parse()) {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Simulate {
            scene,
            frames,
            out,
            level,
            seed,
            obj,
            obj_every,
            png_frames,
        } => simulate(&scene, frames, out, level, seed, obj, obj_every, &png_frames),
        Command::Dataset { scene, out } => make_dataset(&scene, out),
        Command::Demo {
            scene,
            out,
            frames,
            retrain,
        } => demo(&scene, out, frames, retrain),
        Command::Train {
            scene,
            out,
            resume,
            latent,
        } => train_scene(&scene, out, resume, latent),
        Command::Eval {
            artifacts,
            out,
            frames,
            accuracy_frames,
            adaptive,
        } => eval_models(&artifacts, out, frames, accuracy_frames, adaptive),
        Command::Distill {
            artifact,
            out,
            modes,
            hidden,
            blocks,
            epochs,
            integrator,
            integrator_blocks,
            rounds,
            keep_decoder,
            strand_positions,
            frames,
        } => Ok(mochi_trainer::cli::distill::run(
            &artifact,
            &out,
            mochi_trainer::cli::distill::DistillChoice {
                decoder: (!keep_decoder).then_some(mochi_trainer::learn::distill::DistillShape {
                    modes,
                    hidden,
                    blocks,
                }),
                integrator: (integrator > 0).then_some(
                    mochi_trainer::learn::distill_integrator::IntegratorDistillShape {
                        hidden: integrator,
                        blocks: integrator_blocks,
                        rounds,
                    },
                ),
                frames,
                strand_positions,
            },
            epochs,
        )?),
        Command::Codegen { artifact, out, weights } => {
            mochi_codegen::generate_file_with(&artifact, &out, &mochi_codegen::Options::weights(weights))?;
            println!(
                "{} -> {} ({} weights)",
                artifact.display(),
                out.display(),
                mochi_codegen::format_name(weights)
            );
            Ok(())
        }
        Command::Upgrade { artifacts } => {
            for path in artifacts {
                let artifact = mochi_trainer::artifact::Artifact::read(&path)?;
                artifact.write(&path)?;
                println!("{}: format {}", path.display(), mochi_trainer::artifact::FORMAT_VERSION);
            }
            Ok(())
        }
        Command::ExportWeights {
            artifact,
            out,
            frames,
            weights,
        } => {
            let e = eval::network_export::export(&artifact, &out, frames, weights)?;
            println!(
                "{} -> {}: latent {}, signal {}, hidden {}, {} integrator and {} decoder layers, {} frames ({} clamped or held)",
                artifact.display(),
                out.display(),
                e.latent,
                e.signal,
                e.hidden,
                e.layers[0],
                e.layers[1],
                e.frames,
                e.departures
            );
            Ok(())
        }
        Command::Bench {
            what:
                Bench::Sim {
                    scenes,
                    frames,
                    per_step,
                    linear_solvers,
                    sweep,
                    values,
                    out,
                },
        } => bench_sim(scenes, frames, per_step, linear_solvers, sweep, values, out),
        Command::Bench {
            what:
                Bench::Runtime {
                    artifacts,
                    frames,
                    out,
                    weights,
                },
        } => bench_runtime(&artifacts, frames, out, &weights),
        Command::Bench {
            what:
                Bench::Reduced {
                    reduced,
                    frames,
                    cold,
                    out,
                },
        } => bench_reduced(&reduced, frames, cold, out),
        Command::Scenes => {
            for name in shipped_scene_names() {
                let scene = Recipe::load(&name)?.scene;
                println!("{name:10} {}", scene.description);
            }
            Ok(())
        }
    }
}

fn default_out(scene: &Scene, file: &str) -> PathBuf {
    Path::new("out").join(&scene.name).join(file)
}

fn simulate(
    name: &str,
    frames: usize,
    out: Option<PathBuf>,
    level: f64,
    seed: Option<u64>,
    obj: Option<PathBuf>,
    obj_every: usize,
    png_frames: &[usize],
) -> Result<()> {
    if !level.is_finite() || level < 0.0 {
        bail!("--level must be a non-negative number, got {level}");
    }
    let scene = Recipe::load(name)?.scene;
    let mut problem = scene.build()?;
    print_warnings(&problem.warnings);
    let seq = problem.sequence(&SpeedPlan::constant(level), frames, seed.unwrap_or(scene.dataset.seed));
    let bar = FramesBar::new(&format!("simulate {}", scene.name), true);
    bar.start(frames as u64);
    // The adaptive solver's enriched vertices per frame, which previews mark.
    let mut enriched = vec![Vec::new()];
    let traj = problem
        .run_reporting(&seq, &bar, &mut |r| {
            enriched.push(r.adaptive.as_ref().map(|a| a.enriched.clone()).unwrap_or_default())
        })
        .with_context(|| format!("simulating scene `{}`", scene.name))?;
    bar.finish();
    let out = out.unwrap_or_else(|| default_out(&scene, "simulate.npz"));
    if let Some(dir) = out.parent() {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    traj.write_npz(&out)?;
    let steps = &traj.step_seconds[1..];
    let iters = &traj.newton_iterations[1..];
    println!(
        "{}: {} frames, {} DOF, {:.2} ms/step, {:.2} Newton iterations/step -> {}",
        scene.name,
        frames,
        problem.mesh.rest.len(),
        1e3 * steps.iter().sum::<f64>() / steps.len().max(1) as f64,
        iters.iter().sum::<u32>() as f64 / iters.len().max(1) as f64,
        out.display()
    );
    // With obstacle meshes, OBJ files and previews show them next to the body's surface.
    let view = traj
        .obstacles
        .as_ref()
        .and_then(|o| mochi_trainer::report::scene_view::with_obstacles(&problem.mesh, &traj.positions, o));
    let (shown_mesh, shown_frames) = match &view {
        Some((mesh, frames)) => (mesh, frames),
        None => (&problem.mesh, &traj.positions),
    };
    if let Some(dir) = obj {
        render::write_obj_sequence(&dir, &scene.name, shown_mesh, shown_frames, obj_every.max(1))?;
        println!("OBJ sequence -> {}", dir.display());
    }
    if !png_frames.is_empty() {
        if let Some(&bad) = png_frames.iter().find(|&&f| f > frames) {
            bail!("--png-frames: frame {bad} is past the last frame {frames}");
        }
        let shown: Vec<&[f64]> = png_frames.iter().map(|&f| shown_frames[f].as_slice()).collect();
        let png = out.with_extension("png");
        let opts = render::RenderOptions {
            title: format!("{}: frames {:?}", scene.name, png_frames),
            highlight: problem.simulator.fixed_vertices().to_vec(),
            marked: png_frames.iter().map(|&f| enriched[f].clone()).collect(),
            framed_vertices: Some(problem.mesh.num_vertices()),
            ..Default::default()
        };
        render::render_png(&png, shown_mesh, &shown, &opts)?;
        println!("preview -> {}", png.display());
    }
    Ok(())
}

/// Prints each of the scene's warnings on one line of stderr.
fn print_warnings(warnings: &[String]) {
    for warning in warnings {
        eprintln!("warning: {warning}");
    }
}

fn make_dataset(name: &str, out: Option<PathBuf>) -> Result<()> {
    let scene = Recipe::load(name)?.scene;
    let mut problem = scene.build()?;
    print_warnings(&problem.warnings);
    let dir = out.unwrap_or_else(|| default_out(&scene, "dataset"));
    let report = dataset::generate(&mut problem, &dir, None, true, &FramesBar::new("dataset", true))?;
    let plans = dataset::plan(&scene.dataset);
    let count = |s: Split| plans.iter().filter(|p| p.split == s).count();
    println!(
        "{}: {} train sequences of {} frames + {} test sequences of {} frames in {:.1} s; {:.2} ms/step, {:.2} Newton iterations/step -> {}",
        scene.name,
        count(Split::Train),
        scene.dataset.frames_of(Split::Train),
        count(Split::Test),
        scene.dataset.frames_of(Split::Test),
        report.seconds,
        1e3 * mean(&report.step_seconds),
        mean(&report.newton_iterations),
        dir.display()
    );
    Ok(())
}

fn train_scene(name: &str, out: Option<PathBuf>, resume: bool, latent_size: Option<usize>) -> Result<()> {
    let recipe = Recipe::load(name)?;
    let scene = &recipe.scene;
    if latent_size == Some(0) {
        bail!("--latent must be at least 1");
    }
    print_warnings(&scene.region_warnings(&scene.build_mesh()?));
    let out_dir = out.unwrap_or_else(|| Path::new("out").join(&scene.name));
    let options = mochi_trainer::TrainOptions {
        out_dir: out_dir.clone(),
        resume,
        latent: latent_size,
    };
    let start = Instant::now();
    let outcome = mochi_trainer::train_scene(&recipe, &options, &Terminal)?;
    let summary = &outcome.model.summary;
    println!("\n{}: latent size {}", scene.name, outcome.model.latent);
    for t in &summary.trials {
        let ae = t
            .autoencoder_error
            .map_or("not trained".to_string(), |e| format!("{e:.2e}"));
        println!(
            "  size {:2}: PCA error {:.2e}, autoencoder error {ae}",
            t.size, t.pca_error
        );
    }
    for (stage, seconds) in &summary.stage_seconds {
        println!("  {stage:32} {seconds:8.1} s");
    }
    let (model, baseline) = artifact_paths(&out_dir, &scene.name);
    println!(
        "  total {:.1} s -> {} and {}",
        start.elapsed().as_secs_f64(),
        model.display(),
        baseline.display()
    );
    Ok(())
}

fn eval_models(
    artifacts: &[PathBuf],
    out: Option<PathBuf>,
    frames: usize,
    accuracy_frames: usize,
    adaptive: bool,
) -> Result<()> {
    if frames == 0 || accuracy_frames == 0 {
        bail!("--frames and --accuracy-frames must be at least 1");
    }
    let out_dir = out.unwrap_or_else(|| artifacts[0].parent().unwrap_or(Path::new(".")).join("eval"));
    let options = mochi_trainer::EvalOptions {
        out_dir: out_dir.clone(),
        stability_frames: frames,
        accuracy_frames,
        adaptive,
    };
    mochi_trainer::evaluate(artifacts, &options, &Terminal)?;
    let report = std::fs::read_to_string(out_dir.join("report.md"))?;
    println!("\n{report}\ncharts and report -> {}", out_dir.display());
    Ok(())
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn bench_sim(
    scenes: Vec<String>,
    frames: usize,
    per_step: bool,
    linear_solvers: bool,
    sweep: Option<String>,
    values: Vec<f64>,
    out: Option<PathBuf>,
) -> Result<()> {
    let scenes = if scenes.is_empty() {
        shipped_scene_names()
    } else {
        scenes
    };
    let scenes = scenes
        .iter()
        .map(|name| Ok(Recipe::load(name)?.scene))
        .collect::<Result<Vec<_>>>()?;
    let options = eval::sim_bench::SimBenchOptions {
        frames,
        per_step,
        linear_solvers,
        sweep: sweep
            .as_deref()
            .map(eval::adaptive_bench::SweepKey::parse)
            .transpose()
            .map_err(anyhow::Error::msg)?,
        values,
        out,
    };
    eval::sim_bench::bench(&scenes, &options, &mut |line| eprintln!("{line}"))?;
    Ok(())
}

fn bench_runtime(
    artifacts: &[PathBuf],
    frames: usize,
    out: Option<PathBuf>,
    weights: &[mochi_runtime::WeightFormat],
) -> Result<()> {
    // Both sides run on one thread: candle reads its thread count from the environment.
    single_threaded()?;
    let timings = mochi_trainer::eval::runtime_bench::bench(artifacts, frames, weights)?;
    let table = mochi_trainer::eval::runtime_bench::table(&timings);
    println!("{table}");
    if let Some(out) = out {
        std::fs::write(&out, &table).with_context(|| format!("writing {}", out.display()))?;
        println!("-> {}", out.display());
    }
    Ok(())
}

fn bench_reduced(path: &Path, frames: usize, cold: bool, out: Option<PathBuf>) -> Result<()> {
    single_threaded()?;
    let timings = mochi_trainer::eval::reduced_bench::bench(path, frames, cold, &Terminal)?;
    let scene = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let table = mochi_trainer::eval::reduced_bench::table(&scene, frames, cold, &timings);
    println!("{table}");
    if let Some(out) = out {
        std::fs::write(&out, &table).with_context(|| format!("writing {}", out.display()))?;
        println!("-> {}", out.display());
    }
    Ok(())
}

/// Re-runs this command with one thread when the thread variable is not set to 1 (candle and
/// the solvers read it from the environment); returns only when it already is.
fn single_threaded() -> Result<()> {
    if std::env::var(mochi_trainer::THREADS_VAR).as_deref() != Ok("1") {
        let status = std::process::Command::new(std::env::current_exe()?)
            .args(std::env::args_os().skip(1))
            .env(mochi_trainer::THREADS_VAR, "1")
            .status()?;
        std::process::exit(status.code().unwrap_or(1));
    }
    Ok(())
}

fn demo(name: &str, out: Option<PathBuf>, frames: usize, retrain: bool) -> Result<()> {
    let scene = Recipe::load(name)?.scene;
    let out_dir = out.unwrap_or_else(|| Path::new("out").join(&scene.name));
    let start = Instant::now();
    let options = mochi_trainer::DemoOptions {
        scene: name.to_string(),
        out_dir: out_dir.clone(),
        frames,
        retrain,
    };
    let report = mochi_trainer::run_demo(&options, &Terminal)?;
    println!("\n{}", std::fs::read_to_string(out_dir.join("report.md"))?);
    println!(
        "{}: mean error {:.3}% of the diagonal, {:.1} µs/frame in the runtime vs {:.1} ms/frame full space; total {:.0} s -> {}",
        scene.name,
        100.0 * report.mean_error,
        1e6 * report.runtime_seconds,
        1e3 * report.full_space_seconds,
        start.elapsed().as_secs_f64(),
        out_dir.join("report.md").display()
    );
    Ok(())
}
