//! What each `mochi` subcommand does, on the terminal: load the scene or artifact, call the
//! library, print a summary line and where the output went.

use anyhow::{bail, Context, Result};
use mochi_sim::dataset::{self, SpeedPlan, Split};
use mochi_sim::{Progress, Scene};
use mochi_trainer::eval;
use mochi_trainer::eval::reduced_bench::ReducedBenchOptions;
use mochi_trainer::learn::recipe::DecoderCandidate;
use mochi_trainer::report::render;
use mochi_trainer::{artifact_paths, shipped_scene_names, FramesBar, Recipe};
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::Terminal;

fn default_out(scene: &Scene, file: &str) -> PathBuf {
    Path::new("out").join(&scene.name).join(file)
}

/// `mochi mesh`: the asset's tet mesh, render embedding and scene, and a summary.
pub(crate) fn mesh_asset(
    asset: PathBuf,
    edge_length: Option<f64>,
    vertices: Option<usize>,
    out: Option<PathBuf>,
    accept_defects: bool,
    threads: usize,
) -> Result<()> {
    use mochi_trainer::cli::asset_mesh::{self, MeshOptions, Resolution};
    let resolution = match (edge_length, vertices) {
        (Some(l), _) => Some(Resolution::EdgeLength(l)),
        (None, Some(n)) => Some(Resolution::Vertices(n)),
        (None, None) => None,
    };
    let outcome = asset_mesh::mesh_asset(&MeshOptions {
        asset,
        resolution,
        out,
        accept_defects,
        threads,
        bar: true,
    })?;
    let r = &outcome.repaired.report;
    println!(
        "input: {} render vertices, {} triangles{}",
        outcome.render_size.0,
        outcome.render_size.1,
        if outcome.parts.is_empty() {
            String::new()
        } else {
            format!(", parts {}", outcome.parts.join(", "))
        }
    );
    println!(
        "repair: {} welded vertices; {} degenerate, {} duplicate triangles dropped; {} flipped (orientation); \
         {} component(s); {} hole(s), {} non-manifold edge(s), {} self-intersection(s)",
        r.welded_vertices,
        r.degenerate_triangles,
        r.duplicate_triangles,
        r.flipped_triangles,
        r.components,
        r.holes,
        r.non_manifold_edges,
        r.self_intersections
    );
    for warning in &outcome.repaired.warnings {
        println!("warning: {warning}");
    }
    for run in &outcome.runs {
        println!(
            "fTetWild: edge {:.4e}, envelope {:.1e} -> {} vertices, {} tets in {:.2} s{}",
            run.edge_length,
            run.epsilon,
            run.vertices,
            run.tets,
            run.seconds,
            match run.islands_dropped {
                0 => String::new(),
                n => format!(
                    " ({n} separate piece(s) of {} vertices dropped: nothing holds them to the body)",
                    run.island_vertices
                ),
            }
        );
    }
    println!(
        "tet mesh: {} vertices, {} tets; render vertices at most {:.2e} of the diagonal from their tets; handle: {}",
        outcome.tet_size.0, outcome.tet_size.1, outcome.max_render_distance, outcome.handle
    );
    println!(
        "-> {} (scene), {}, {}, {} in {:.1} s",
        outcome.scene_path.display(),
        outcome.mesh_path.display(),
        outcome.render_path.display(),
        outcome.surface_path.display(),
        outcome.seconds
    );
    Ok(())
}

pub(crate) fn simulate(
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
    let solver = match scene.solver {
        mochi_sim::SolverSpec::Vbd(_) => "VBD",
        _ => "Newton",
    };
    println!(
        "{}: {} frames, {} DOF, {:.2} ms/step, {:.2} {solver} iterations/step -> {}",
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

/// `mochi dataset --plan`: the selected sequences, `NAME SPLIT FRAMES` a line.
pub(crate) fn print_dataset_plan(name: &str, selection: &dataset::Selection) -> Result<()> {
    let scene = Recipe::load(name)?.scene;
    let plans = selection
        .pick(dataset::plan(&scene.dataset))
        .map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
    for p in plans {
        println!("{} {} {}", p.name, p.split.as_str(), p.frames(&scene.dataset, scene.dt));
    }
    Ok(())
}

pub(crate) fn make_dataset(
    name: &str,
    out: Option<PathBuf>,
    selection: &dataset::Selection,
    overwrite: bool,
) -> Result<()> {
    let scene = Recipe::load(name)?.scene;
    let mut problem = scene.build()?;
    print_warnings(&problem.warnings);
    let dir = out.unwrap_or_else(|| default_out(&scene, "dataset"));
    let selected = selection
        .pick(dataset::plan(&scene.dataset))
        .map_err(|e| anyhow::anyhow!("{name}: {e}"))?;
    let report = dataset::generate_selected(
        &mut problem,
        &dir,
        selection,
        overwrite,
        &FramesBar::new("dataset", true),
    )?;
    let count = |s: Split| selected.iter().filter(|p| p.split == s).count();
    let steps = if report.step_seconds.is_empty() {
        String::new()
    } else {
        format!(
            "; {:.2} ms/step, {:.2} Newton iterations/step",
            1e3 * mean(&report.step_seconds),
            mean(&report.newton_iterations)
        )
    };
    println!(
        "{}: {} train sequences of {} frames + {} test sequences of {} frames ({} simulated, {} already complete) in {:.1} s{steps} -> {}",
        scene.name,
        count(Split::Train),
        scene.dataset.frames_of(Split::Train),
        count(Split::Test),
        scene.dataset.frames_of(Split::Test),
        report.sequences,
        selected.len() - report.sequences,
        report.seconds,
        dir.display()
    );
    if let Some(closest) = report.collider_min_distance {
        println!(
            "{}: closest approach of a surface vertex to a collider {closest:.3e} m ({})",
            scene.name,
            if closest > 0.0 { "no penetration" } else { "PENETRATED" }
        );
    }
    Ok(())
}

/// `--decoder`: `linear`, `mlp` or `basis=W`.
fn decoder_candidate(text: &str) -> Result<DecoderCandidate> {
    Ok(match text {
        "linear" => DecoderCandidate::Linear,
        "mlp" => DecoderCandidate::Mlp,
        _ => match text.strip_prefix("basis=").map(str::parse::<usize>) {
            Some(Ok(width)) if width > 0 => DecoderCandidate::Basis(width),
            _ => bail!("--decoder {text}: expected `linear`, `mlp` or `basis=W` (W at least 1)"),
        },
    })
}

/// `mochi train`'s choices beyond the scene, its output and `--resume`.
pub(crate) struct TrainFlags<'a> {
    pub(crate) latent: Option<usize>,
    pub(crate) decoder: Option<&'a str>,
    pub(crate) integrator_width: Option<usize>,
    pub(crate) without_collider_inputs: bool,
    pub(crate) frame_memory: Option<&'a str>,
}

/// `--frame-memory`: bytes, or a number with `K`, `M` or `G` (powers of 1024; `KiB`, `MB`
/// and the like read alike).
fn byte_count(text: &str) -> Result<u64> {
    let trimmed = text.trim().trim_end_matches(['B', 'b']).trim_end_matches('i');
    let (number, unit) = match trimmed.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => (&trimmed[..i], c.to_ascii_uppercase()),
        _ => (trimmed, ' '),
    };
    let scale: u64 = match unit {
        ' ' => 1,
        'K' => 1 << 10,
        'M' => 1 << 20,
        'G' => 1 << 30,
        _ => bail!("--frame-memory {text}: unknown unit `{unit}` (use K, M or G)"),
    };
    match number.trim().parse::<f64>() {
        Ok(n) if n.is_finite() && n >= 0.0 => Ok((n * scale as f64) as u64),
        _ => bail!("--frame-memory {text}: expected a size such as 512M, 4G or 0"),
    }
}

pub(crate) fn train_scene(name: &str, out: Option<PathBuf>, resume: bool, flags: &TrainFlags<'_>) -> Result<()> {
    let TrainFlags {
        latent: latent_size,
        decoder,
        integrator_width,
        without_collider_inputs,
        frame_memory,
    } = *flags;
    let frame_memory = frame_memory
        .map(byte_count)
        .transpose()?
        .unwrap_or(mochi_trainer::FRAME_MEMORY);
    let mut recipe = Recipe::load(name)?;
    if without_collider_inputs {
        if recipe.scene.colliders.is_empty() {
            bail!("--without-collider-inputs: scene `{name}` has no [[colliders]]");
        }
        recipe.latent.collider_inputs = false;
    }
    if latent_size == Some(0) {
        bail!("--latent must be at least 1");
    }
    // A narrowed selection is written into the artifacts' scene, so they say what was trained.
    let selection = &mut recipe.latent.selection;
    if let Some(text) = decoder {
        selection.decoders = vec![decoder_candidate(text)?];
        selection.distill.modes.clear();
    }
    if let Some(width) = integrator_width {
        if width == 0 {
            bail!("--integrator-width must be at least 1");
        }
        selection.integrator_widths = vec![width];
    }
    let scene = &recipe.scene;
    print_warnings(&scene.region_warnings(&scene.build_mesh()?));
    let out_dir = out.unwrap_or_else(|| Path::new("out").join(&scene.name));
    let options = mochi_trainer::TrainOptions {
        out_dir: out_dir.clone(),
        resume,
        latent: latent_size,
        frame_memory,
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
    if let Some(peak) = mochi_trainer::learn::frame_rows::peak_resident_bytes() {
        println!("  peak memory {:.0} MiB", peak as f64 / (1024.0 * 1024.0));
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

pub(crate) fn eval_models(
    artifacts: &[PathBuf],
    out: Option<PathBuf>,
    frames: usize,
    accuracy_frames: usize,
    adaptive: bool,
    full_space_reference: bool,
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
        full_space_reference,
    };
    mochi_trainer::evaluate(artifacts, &options, &Terminal)?;
    let report = std::fs::read_to_string(out_dir.join("report.md"))?;
    println!("\n{report}\ncharts and report -> {}", out_dir.display());
    Ok(())
}

pub(crate) fn eval_rates(
    artifacts: &[PathBuf],
    out: Option<PathBuf>,
    rates: Vec<f64>,
    seconds: f64,
    frames: usize,
    sequences: usize,
) -> Result<()> {
    if frames == 0 || sequences == 0 {
        bail!("--frames and --sequences must be at least 1");
    }
    let out_dir = out.unwrap_or_else(|| artifacts[0].parent().unwrap_or(Path::new(".")).join("eval"));
    let options = mochi_trainer::eval::rates::RatesOptions {
        rates,
        seconds,
        stability_frames: frames,
        sequences,
        out_dir: out_dir.clone(),
    };
    mochi_trainer::eval::rates::evaluate_rates(artifacts, &options, &Terminal)?;
    let report = std::fs::read_to_string(out_dir.join("rates.md"))?;
    println!("\n{report}\nchart and page -> {}", out_dir.display());
    Ok(())
}

pub(crate) fn compare(scene: &str, out: PathBuf, options: mochi_trainer::eval::compare::CompareOptions) -> Result<()> {
    if options.frames == 0 {
        bail!("--frames must be at least 1");
    }
    if options.sequences == 0 && options.matrix.is_none() {
        bail!("--sequences 0 (no chart) needs the stability matrix (--matrix-frames at least 1)");
    }
    if !options.conditions.is_empty() && options.matrix.is_none() {
        bail!("--conditions needs the stability matrix (--matrix-frames at least 1)");
    }
    let comparison = mochi_trainer::eval::compare::compare(scene, &options, &Terminal)?;
    if options.cases_only {
        println!(
            "cases -> {}",
            options.cases.as_deref().unwrap_or(Path::new(".")).display()
        );
        return Ok(());
    }
    let command = format!("mochi {}", std::env::args().skip(1).collect::<Vec<_>>().join(" "));
    mochi_trainer::eval::compare::page::write(&out, &comparison, &command)?;
    println!(
        "page and charts -> {}",
        out.join(format!("{}.md", comparison.scene)).display()
    );
    Ok(())
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

pub(crate) fn bench_sim(
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

pub(crate) fn bench_runtime(
    artifacts: &[PathBuf],
    frames: usize,
    out: Option<PathBuf>,
    weights: &[mochi_runtime::WeightFormat],
) -> Result<()> {
    // Both sides run on one thread: candle reads its thread count from the environment.
    single_threaded()?;
    let timings = mochi_trainer::eval::runtime_bench::bench(artifacts, frames, weights)?;
    let table = mochi_trainer::eval::runtime_bench::table(&timings);
    print_table(&table, out)
}

pub(crate) fn bench_reduced(path: &Path, options: &ReducedBenchOptions, out: Option<PathBuf>) -> Result<()> {
    single_threaded()?;
    let timings = eval::reduced_bench::bench(path, options, &Terminal)?;
    let scene = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let table = eval::reduced_bench::table(&scene, options, &timings);
    print_table(&table, out)
}

/// Prints a bench's markdown table, and writes it to `out` when given.
fn print_table(table: &str, out: Option<PathBuf>) -> Result<()> {
    println!("{table}");
    if let Some(out) = out {
        std::fs::write(&out, table).with_context(|| format!("writing {}", out.display()))?;
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

pub(crate) fn demo(name: &str, out: Option<PathBuf>, frames: usize, retrain: bool) -> Result<()> {
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

/// `mochi export`: the model's rollout as a `.glb`, and a summary.
pub(crate) fn export(
    artifact: &Path,
    out: Option<PathBuf>,
    frames: usize,
    level: f64,
    seed: Option<u64>,
    weights: mochi_runtime::WeightFormat,
) -> Result<()> {
    use mochi_trainer::export::{self, ExportOptions, ExportedMesh};
    let options = ExportOptions {
        frames,
        level,
        seed,
        weights,
    };
    let animation = export::roll_out(artifact, &options)?;
    let out = out.unwrap_or_else(|| artifact.with_extension("glb"));
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let bytes = export::glb::write(&animation, &out)?;
    println!(
        "{} -> {}: {} {} vertices, {} triangles, {} frames at {:.0} Hz ({} morph targets), {:.1} MiB{}",
        artifact.display(),
        out.display(),
        match animation.mesh {
            ExportedMesh::Render => "render mesh,",
            ExportedMesh::Surface => "simulation surface,",
        },
        animation.vertices(),
        animation.triangles.len() / 3,
        animation.frames(),
        1.0 / animation.dt,
        animation.frames() - 1,
        bytes as f64 / (1 << 20) as f64,
        if animation.pushed_out > 0 {
            format!(", {} vertex moves out of colliders", animation.pushed_out)
        } else {
            String::new()
        }
    );
    Ok(())
}
