//! The `mochi` command line: its subcommands, their arguments and defaults (clap).

use clap::{Parser, Subcommand};
use mochi_trainer::eval;
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "mochi",
    version,
    about = "Soft bodies in real time: simulate, learn, freeze, run"
)]
pub(crate) struct Cli {
    #[command(subcommand)]
    pub(crate) command: Command,
}

#[derive(Subcommand)]
pub(crate) enum Command {
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
    /// A surface asset (glTF, OBJ, STL) in: repaired (welded, oriented outward; holes,
    /// non-manifold edges and self-intersections reported), tetrahedralised by fTetWild
    /// (`scripts/tetwild.sh`), its render mesh embedded in the tets, and a scene for `mochi
    /// train` written beside the tet mesh.
    Mesh {
        /// The asset: `.gltf`, `.glb`, `.obj` or `.stl`.
        asset: PathBuf,
        /// Target tet edge length, in the asset's units (default: 1/20 of the diagonal).
        #[arg(long, conflicts_with = "vertices")]
        edge_length: Option<f64>,
        /// Target number of tet-mesh vertices: up to six mesher runs stop within 20% of it, the
        /// surface envelope widened up to 1.6% of the diagonal where the surface's detail holds
        /// the count up; the closest run is kept.
        #[arg(long)]
        vertices: Option<usize>,
        /// The tet mesh to write (`.mesh`); the scene, render embedding and repaired surface
        /// go beside it. Default: out/assets/NAME/NAME.mesh.
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Mesh an open, non-manifold or self-intersecting surface anyway (fTetWild takes the
        /// inside by winding number) instead of refusing it; the defects are still reported.
        #[arg(long)]
        accept_defects: bool,
        /// The mesher's threads (0: all cores).
        #[arg(long, default_value_t = 0)]
        threads: usize,
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
        /// Make only this sequence (a file stem such as `train-03`; repeat for more). With
        /// several processes on one directory, each its own sequences, the files are the
        /// bytes one process makes (scripts/ray-dataset.sh fans them out over Ray).
        #[arg(long = "sequence", conflicts_with = "shard")]
        sequences: Vec<String>,
        /// Make only shard `I/N` of the plan's sequences (0-based: sequences I, I + N, ...).
        #[arg(long, value_parser = parse_shard)]
        shard: Option<(usize, usize)>,
        /// Make the selected sequences anew, and the manifest, instead of keeping those that
        /// are complete.
        #[arg(long)]
        overwrite: bool,
        /// Print the planned sequences (name, split, frames), one a line, and make nothing.
        #[arg(long)]
        plan: bool,
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
        /// Train only this decoder family instead of the scene's `latent.selection.decoders`:
        /// `linear`, `mlp` or `basis=W` (no distilled decoders are added).
        #[arg(long)]
        decoder: Option<String>,
        /// Train only integrators of this width instead of the scene's
        /// `latent.selection.integrator_widths`.
        #[arg(long)]
        integrator_width: Option<usize>,
        /// Train a model that does not see the scene's run-time colliders (no collider inputs,
        /// no collider barrier in the loss; `latent.collider_inputs = false`), to compare with.
        #[arg(long)]
        without_collider_inputs: bool,
        /// Training frames held in memory at most (bytes, or with K, M, G: `512M`); a larger
        /// training split is written to OUT/frames.f64 and read back in batches. Default 4G.
        #[arg(long)]
        frame_memory: Option<String>,
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
        /// Measure against the test split simulated in full space (`dataset-full-space/`
        /// beside the model, made where missing) when the scene's solver is another (the
        /// adaptive solver made its dataset); the adaptive solver is measured too.
        #[arg(long)]
        full_space_reference: bool,
        /// Instead: step the models (of one body, possibly of different scenes) at these frame
        /// rates on the same motions, against full space at each rate (`rates.md`); e.g.
        /// `30,60,72,90,120,144`.
        #[arg(long, value_delimiter = ',', conflicts_with_all = ["adaptive", "accuracy_frames"])]
        rates: Vec<f64>,
        /// With `--rates`: seconds of motion measured against full space at each rate.
        #[arg(long, default_value_t = 10.0)]
        seconds: f64,
        /// With `--rates`: test sequences used (held-out speeds inside the range first).
        #[arg(long, default_value_t = 2)]
        sequences: usize,
    },
    /// Every method that applies to a scene on one chart (time per frame against error, against
    /// implicit Euler and a time-converged reference) and a stability matrix: full space, a
    /// coarse mesh, the adaptive solver, VBD, the reduced solver, the learned runtime in each
    /// weight storage, and peers' recordings (`scripts/xpbd.sh`). Writes `OUT/SCENE.md`.
    Compare {
        /// Scene name or path (the model's scene when `--model` is given).
        scene: String,
        /// The learned model (`SCENE.mochi`); its supervised twin and the selection's other
        /// candidates (`candidates/`) beside it are added.
        #[arg(long)]
        model: Option<PathBuf>,
        /// The scene's `.reduced` file.
        #[arg(long)]
        reduced: Option<PathBuf>,
        /// Peers' recordings (`DIR/CASE/*.npz`, from `scripts/xpbd.sh`).
        #[arg(long)]
        peers: Option<PathBuf>,
        /// Write the peers' cases (`DIR/CASE.npz`) here.
        #[arg(long)]
        cases: Option<PathBuf>,
        /// Only write the cases (with `--cases`), measure nothing.
        #[arg(long, requires = "cases")]
        cases_only: bool,
        /// Output directory of the page and charts.
        #[arg(long, default_value = "docs/results/methods")]
        out: PathBuf,
        /// Test sequences on the chart (0: no chart, the stability matrix alone).
        #[arg(long, default_value_t = 2)]
        sequences: usize,
        /// Frames of each chart sequence.
        #[arg(long, default_value_t = 150)]
        frames: usize,
        /// Frames of each stability condition (0: no matrix).
        #[arg(long, default_value_t = 300)]
        matrix_frames: usize,
        /// Frames of the long stability condition (measured over its first and its last
        /// `--matrix-frames`).
        #[arg(long, default_value_t = 10_000)]
        long_frames: usize,
        /// Only these stability conditions, comma-separated, by the file stems of their names
        /// (`in-range`, `1-5x-top-speed`, `2x-top-speed`, `sudden-stop`, `10000-frames`,
        /// `dt-halved`, `dt-doubled`, `10x-stiffer`, `contact`); default all.
        #[arg(long, value_delimiter = ',')]
        conditions: Vec<String>,
        /// Most substeps per frame of the time-converged reference.
        #[arg(long, default_value_t = 32)]
        max_substeps: usize,
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
    /// Rewrite artifacts of an older format (2-7) in place in the current one; fields
    /// unchanged (a timed integrator of format 7 keeps reading the latent before the last),
    /// weights too except that values below 2^-40 of their layer's largest weight are written
    /// as zero (the runtime and codegen read formats 5 to the current one).
    Upgrade {
        /// Artifacts (`SCENE.mochi`).
        #[arg(required = true)]
        artifacts: Vec<PathBuf>,
    },
    /// A trained model's rollout as a glTF 2.0 binary (`.glb`) that Blender and engines
    /// open: its render mesh (or drawn surface) on one motion of its scene, one morph target
    /// per frame played by an animation at the model's frame rate.
    Export {
        /// Artifact (`SCENE.mochi`).
        artifact: PathBuf,
        /// Output file (`.glb`); default: beside the artifact, `SCENE.glb`.
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Frames after the first.
        #[arg(long, default_value_t = 120)]
        frames: usize,
        /// Speed level of the sampled handle motion (0: bottom, 1: top of the training range).
        #[arg(long, default_value_t = 0.5)]
        level: f64,
        /// Seed of the sampled motion (default: the scene's dataset seed).
        #[arg(long)]
        seed: Option<u64>,
        /// Weight storage the runtime steps with, as `mochi codegen --weights`.
        #[arg(long, default_value = "f32", value_parser = parse_weights)]
        weights: mochi_runtime::WeightFormat,
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
pub(crate) enum Bench {
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
        /// Step every this many frames of the test motions (the same motions in larger
        /// steps; `--frames` counts the steps taken).
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
        stride: u32,
        /// Solve in single precision, emulated by rounding at each stage (what the subspaces
        /// cost a solver whose numbers are f32, as the paper's is).
        #[arg(long)]
        single: bool,
        /// Step with the paper's solver (L-BFGS as its code runs it: cold, Armijo-only
        /// backtracking by 0.8, 10 pairs, the tolerance on the unscaled objective, an
        /// absolute ftol of 2.2e-9), whatever the scene's `reduced.solver` says.
        #[arg(long)]
        paper: bool,
        /// Gradient tolerance of each step instead of the scene's `reduced.tolerance`.
        #[arg(long)]
        tolerance: Option<f64>,
        /// Also write the table to this markdown file.
        #[arg(long)]
        out: Option<PathBuf>,
    },
}

/// `--weights` values.
fn parse_shard(text: &str) -> std::result::Result<(usize, usize), String> {
    let parsed = text
        .split_once('/')
        .and_then(|(i, n)| Some((i.trim().parse().ok()?, n.trim().parse().ok()?)));
    match parsed {
        Some((i, n)) if n > 0 && i < n => Ok((i, n)),
        _ => Err(format!("`{text}` is not a shard I/N with 0 <= I < N")),
    }
}

fn parse_weights(name: &str) -> std::result::Result<mochi_runtime::WeightFormat, String> {
    mochi_codegen::parse_format(name).ok_or_else(|| format!("`{name}` is not one of f32, f16, int8"))
}
