//! The `mochi` command-line tool.

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use mochi_trainer::dataset::{self, SpeedPlan, Split};
use mochi_trainer::render;
use mochi_trainer::scene::{shipped_scene_names, Scene};
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
    },
}

fn main() {
    // Assembly runs in parallel (rayon); the sparse factorisation runs sequentially: at these
    // sizes on small machines faer's parallel factorisation spends more time synchronising
    // than it saves (beam: 80 -> 61 ms/step on 2 cores, `mochi bench sim beam`).
    faer::set_global_parallelism(faer::Par::Seq);
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
        Command::Bench {
            what: Bench::Sim { scenes, frames },
        } => bench_sim(scenes, frames),
        Command::Scenes => {
            for name in shipped_scene_names() {
                let scene = Scene::load(&name)?;
                println!("{name:10} {}", scene.description);
            }
            Ok(())
        }
    }
}

fn progress_bar(len: u64, message: String) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{msg:24} [{bar:40}] {pos}/{len} frames, {elapsed} (eta {eta})")
            .expect("valid progress template")
            .progress_chars("=> "),
    );
    bar.set_message(message);
    bar
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
    let scene = Scene::load(name)?;
    let mut problem = scene.build()?;
    let seq = problem.sequence(&SpeedPlan::constant(level), frames, seed.unwrap_or(scene.dataset.seed));
    let bar = progress_bar(frames as u64, format!("simulate {}", scene.name));
    let traj = problem
        .run(&seq, Some(&bar))
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
    if let Some(dir) = obj {
        render::write_obj_sequence(&dir, &scene.name, &problem.mesh, &traj.positions, obj_every.max(1))?;
        println!("OBJ sequence -> {}", dir.display());
    }
    if !png_frames.is_empty() {
        if let Some(&bad) = png_frames.iter().find(|&&f| f > frames) {
            bail!("--png-frames: frame {bad} is past the last frame {frames}");
        }
        let shown: Vec<&[f64]> = png_frames.iter().map(|&f| traj.positions[f].as_slice()).collect();
        let png = out.with_extension("png");
        let opts = render::RenderOptions {
            title: format!("{}: frames {:?}", scene.name, png_frames),
            highlight: problem.simulator.fixed_vertices().to_vec(),
            ..Default::default()
        };
        render::render_png(&png, &problem.mesh, &shown, &opts)?;
        println!("preview -> {}", png.display());
    }
    Ok(())
}

fn make_dataset(name: &str, out: Option<PathBuf>) -> Result<()> {
    let scene = Scene::load(name)?;
    let mut problem = scene.build()?;
    let dir = out.unwrap_or_else(|| default_out(&scene, "dataset"));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    let plans = dataset::plan(&scene.dataset);
    let frames = scene.dataset.frames;
    let bar = progress_bar((plans.len() * frames) as u64, format!("dataset {}", scene.name));
    let start = Instant::now();
    let mut step_seconds = Vec::new();
    let mut iterations = Vec::new();
    for plan in &plans {
        bar.set_message(format!("{} {}", scene.name, plan.name));
        let seq = problem.sequence(&plan.speeds, frames, plan.seed);
        let mut traj = problem
            .run(&seq, Some(&bar))
            .with_context(|| format!("simulating {} of `{}`", plan.name, scene.name))?;
        traj.meta.push(("split".into(), plan.split.as_str().into()));
        traj.meta.push(("sequence".into(), plan.description.clone()));
        traj.meta.push(("seed".into(), plan.seed.to_string()));
        traj.write_npz(&dir.join(format!("{}.npz", plan.name)))?;
        step_seconds.extend_from_slice(&traj.step_seconds[1..]);
        iterations.extend(traj.newton_iterations[1..].iter().map(|&i| i as f64));
    }
    bar.finish();
    let count = |s: Split| plans.iter().filter(|p| p.split == s).count();
    println!(
        "{}: {} train + {} test sequences of {} frames in {:.1} s; {:.2} ms/step, {:.2} Newton iterations/step -> {}",
        scene.name,
        count(Split::Train),
        count(Split::Test),
        frames,
        start.elapsed().as_secs_f64(),
        1e3 * mean(&step_seconds),
        mean(&iterations),
        dir.display()
    );
    Ok(())
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn bench_sim(scenes: Vec<String>, frames: usize) -> Result<()> {
    let scenes = if scenes.is_empty() {
        shipped_scene_names()
    } else {
        scenes
    };
    println!(
        "{:10} {:>8} {:>10} {:>12} {:>10}",
        "scene", "DOF", "ms/step", "Newton it.", "max it."
    );
    for name in scenes {
        let scene = Scene::load(&name)?;
        let mut problem = scene.build()?;
        let seq = problem.sequence(&SpeedPlan::constant(0.5), frames, scene.dataset.seed);
        let traj = problem
            .run(&seq, None)
            .with_context(|| format!("simulating `{name}`"))?;
        let iters: Vec<f64> = traj.newton_iterations[1..].iter().map(|&i| i as f64).collect();
        println!(
            "{:10} {:>8} {:>10.2} {:>12.2} {:>10}",
            scene.name,
            problem.simulator.num_free_dofs(),
            1e3 * mean(&traj.step_seconds[1..]),
            mean(&iters),
            iters.iter().fold(0.0f64, |m, &i| m.max(i))
        );
    }
    Ok(())
}
