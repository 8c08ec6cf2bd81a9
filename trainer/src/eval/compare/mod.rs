//! `mochi compare SCENE`: every method that applies to a scene, on one scale (docs/design.md,
//! "Methods side by side"). Each runs through the one interface of
//! [`crate::methods::method`] and the one measuring loop, timed on one thread in one
//! process:
//!
//! - **The chart**: the scene's first test sequences, each method at several budgets
//!   ([`lineup`]), time per frame against mean vertex error (% of the rest diagonal) against
//!   two references: the scene's own implicit Euler at its frame time (full-space Newton,
//!   what the learned models imitate) and a time-converged one (the second-order BDF2 on
//!   the same scene, with the step halved until halving it again moves the positions by
//!   less than [`CONVERGED_CHANGE`] of the diagonal, averaged over vertices, at every
//!   frame).
//! - **The stability matrix** ([`conditions`]): one setting per family under each condition,
//!   each cell its stable frames and mean error against full space under that condition;
//!   a family that cannot take a condition says why.
//!
//! Peers run outside (`scripts/xpbd.sh`) on the cases this command writes (`--cases`), and
//! their recordings come back in with `--peers`.

use std::path::{Path, PathBuf};

use mochi_codegen::{format_name, Options, Quantized};
use mochi_runtime::{OwnedModel, ValidModel, WeightFormat};
use mochi_sim::bc::BcSequence;
use mochi_sim::dataset::SequencePlan;
use mochi_sim::energy::StencilEnergy;
use mochi_sim::{BuiltScene, SolverSpec, TimeScheme};

use crate::artifact::reduced::ReducedArtifact;
use crate::artifact::Artifact;
use crate::error::{fs, Context, TrainerError, TrainerResult};
use crate::eval::reduced::{stepper_settings, with_runtime_cubature};
use crate::learn::encoding::Encoding;
use crate::learn::recipe::Recipe;
use crate::learn::recipe::RodEncoding;
use crate::learn::reduced_spec::{ReducedSpec, SolverChoice, SolverPrecision};
use crate::methods::lipschitz::cubature::cubature_energies;
use crate::methods::method::{run_sequence, SequenceRun};
use crate::methods::reduced::stepper::StepperSettings;
use crate::methods::simulated::Simulated;
use crate::progress::Reporter;

pub mod case;
pub mod conditions;
pub mod lineup;
pub mod matrix;
pub mod page;

use conditions::{MatrixSpan, RunTimeChange};
use lineup::{model_files, Budgets, Entry, LearnedModel, ReducedSubspace, SubspaceMap, Trained, CANDIDATES_FAMILY};

/// The time-converged reference stops halving the step once the positions move by less than
/// this fraction of the rest diagonal (mean over vertices, largest over frames).
pub const CONVERGED_CHANGE: f64 = 1e-3;

/// The Newton tolerance of each stability condition's check run, as a fraction of the scene's
/// ([`matrix::reference_check`]).
pub const CHECK_TOLERANCE: f64 = 1e-3;

/// Options of `mochi compare`.
#[derive(Clone, Debug)]
pub struct CompareOptions {
    /// The learned model (`SCENE.mochi`; its supervised twin beside it and the selection's
    /// other candidates in `candidates/` beside it are added), whose scene is the one
    /// compared. Without it, the scene named on the command line.
    pub model: Option<PathBuf>,
    /// The scene's `.reduced` file, when there is one.
    pub reduced: Option<PathBuf>,
    /// Peers' recordings (`DIR/CASE/*.npz`).
    pub peers: Option<PathBuf>,
    /// Where to write the peers' cases (`DIR/CASE.npz`).
    pub cases: Option<PathBuf>,
    /// Only write the cases (the implicit-Euler references they carry), measure nothing.
    pub cases_only: bool,
    /// Test sequences of the chart (0: no chart, the matrix only).
    pub sequences: usize,
    /// Frames of each chart sequence.
    pub frames: usize,
    /// The stability matrix's frames (`None`: no matrix).
    pub matrix: Option<MatrixSpan>,
    /// Only these conditions of the matrix, by file stem ([`slug`]; empty: all of them).
    pub conditions: Vec<String>,
    /// Most substeps per frame the time-converged reference may take.
    pub max_substeps: usize,
}

/// One method at one budget on the chart, averaged over the sequences.
#[derive(Clone, Debug)]
pub struct ChartPoint {
    /// Family.
    pub family: String,
    /// Budget.
    pub setting: String,
    /// Per sequence.
    pub runs: Vec<SequenceRun>,
}

impl ChartPoint {
    /// Mean seconds per frame over the sequences.
    pub fn seconds(&self) -> f64 {
        self.runs.iter().map(|r| r.seconds).sum::<f64>() / self.runs.len().max(1) as f64
    }
    /// Mean over sequences of the mean error against reference `r` (0: implicit Euler, 1:
    /// time-converged); infinite if one blew up inside the measured frames.
    pub fn error(&self, r: usize) -> f64 {
        self.runs.iter().map(|s| s.mean_error(r)).sum::<f64>() / self.runs.len().max(1) as f64
    }
    /// Mean iterations per frame.
    pub fn iterations(&self) -> f64 {
        self.runs.iter().map(|r| r.iterations).sum::<f64>() / self.runs.len().max(1) as f64
    }
}

/// The time-converged reference of one chart sequence.
#[derive(Clone, Debug)]
pub struct Converged {
    /// Sequence name.
    pub sequence: String,
    /// Substeps per frame of the reference kept.
    pub substeps: usize,
    /// Largest over frames of the mean vertex distance / diagonal between it and the run
    /// with half as many substeps.
    pub change: f64,
    /// Where full space failed on the sequence (the implicit-Euler reference, or a finer
    /// run of the time-converged one): methods are measured over the frames it reached.
    pub failures: Vec<String>,
}

/// One cell of the stability matrix.
#[derive(Clone, Debug)]
pub struct Cell {
    /// Family and budget.
    pub method: String,
    /// What it did: `stable frames / frames, mean error %`, or why it cannot.
    pub text: String,
}

/// One row of the matrix.
#[derive(Clone, Debug)]
pub struct MatrixRow {
    /// The condition.
    pub condition: String,
    /// Frames of the condition, and measured against the reference.
    pub frames: (usize, usize),
    /// Its cells.
    pub cells: Vec<Cell>,
}

/// Everything `mochi compare` measured on a scene.
#[derive(Clone, Debug)]
pub struct Comparison {
    /// The scene.
    pub scene: String,
    /// Vertices of its mesh.
    pub vertices: usize,
    /// The chart's sequences.
    pub sequences: Vec<SequencePlan>,
    /// Frames of each.
    pub frames: usize,
    /// Their time-converged references.
    pub converged: Vec<Converged>,
    /// The chart.
    pub points: Vec<ChartPoint>,
    /// Families that could not run on the chart, and why.
    pub unavailable: Vec<Cell>,
    /// The stability matrix.
    pub matrix: Vec<MatrixRow>,
}

/// Compares every method on the scene of `options.model` (or `scene`, a name or path, when
/// no model is given), on one thread: everything runs in a one-thread pool, so a method's
/// CPU time ([`crate::methods::clock`]) is also what one core takes.
pub fn compare(scene: &str, options: &CompareOptions, report: &dyn Reporter) -> TrainerResult<Comparison> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .map_err(|e| TrainerError::invalid(format!("cannot start a one-thread pool: {e}")))?;
    pool.install(|| compare_on_this_thread(scene, options, report))
}

fn compare_on_this_thread(scene: &str, options: &CompareOptions, report: &dyn Reporter) -> TrainerResult<Comparison> {
    // The learned models, each storage; their scene is the one compared.
    let bytes = match &options.model {
        Some(path) => model_files(path)?,
        None => Vec::new(),
    };
    let recipe = match &options.model {
        Some(path) => {
            let artifact = Artifact::read(path)?;
            Recipe::parse(&artifact.scene_toml, Path::new(&artifact.scene_path))?
        }
        None => Recipe::load(scene)?,
    };
    let problem = recipe.build()?;
    let mut owned: Vec<OwnedModel> = bytes.iter().map(|_| OwnedModel::default()).collect();
    let mut bases = Vec::new();
    for ((_, b, path), o) in bytes.iter().zip(owned.iter_mut()) {
        let model = *o
            .load(b)
            .with_context(|| format!("{}: runtime refused the artifact", path.display()))?
            .model();
        bases.push(model);
    }
    let formats = [WeightFormat::F32, WeightFormat::F16, WeightFormat::Int8];
    let quantized: Vec<(usize, WeightFormat, Quantized)> = bases
        .iter()
        .enumerate()
        .flat_map(|(i, base)| {
            let kept: &[WeightFormat] = if i == 0 { &formats } else { &formats[..1] };
            kept.iter().map(move |&f| {
                let o = Options::weights(f);
                (i, f, Quantized::split(base, o.decoder, o.integrator))
            })
        })
        .collect();
    let mut learned = Vec::new();
    for (i, f, q) in &quantized {
        let base = &bases[*i];
        let (family, path) = (bytes[*i].0, &bytes[*i].2);
        let name = match family {
            CANDIDATES_FAMILY => format!(", {}", path.file_stem().and_then(|n| n.to_str()).unwrap_or("?")),
            _ => String::new(),
        };
        learned.push(LearnedModel {
            family,
            setting: format!("k={}, {}{name}", base.latent, format_name(*f)),
            model: ValidModel::new(q.model(base)).map_err(|e| TrainerError::invalid(format!("{e:?}")))?,
        });
    }
    // The reduced subspaces, with the scene's energies and with runtime cubature.
    let reduced_file = options.reduced.as_ref().map(|p| ReducedArtifact::load(p)).transpose()?;
    let cubatures = match &reduced_file {
        Some(r) => cubature_energies(&problem, &r.cubature)?,
        None => Vec::new(),
    };
    let potentials: Vec<&dyn StencilEnergy> = problem.simulator.potentials().iter().map(|p| p.as_ref()).collect();
    let with_cubature = with_runtime_cubature(&potentials, &cubatures);
    let mut reduced = Vec::new();
    let mut reduced_settings = StepperSettings::default();
    let mut paper_settings = None;
    if let Some(r) = &reduced_file {
        let spec = Recipe::parse(&r.scene_toml, Path::new(&r.scene_path))?
            .reduced
            .unwrap_or_default();
        reduced_settings = stepper_settings(&spec, problem.scene.integrator);
        if spec.solver != SolverChoice::LbfgsPaper {
            let paper = ReducedSpec {
                solver: SolverChoice::LbfgsPaper,
                precision: SolverPrecision::Single,
                ..spec.clone()
            };
            paper_settings = Some(stepper_settings(&paper, problem.scene.integrator));
        }
        if let Some(linear) = &r.pca {
            reduced.push(ReducedSubspace {
                name: "PCA".into(),
                decoder: SubspaceMap::Linear(linear.pca()),
                initial_latent: linear.initial_latent.clone(),
                energies: None,
            });
        }
        for (name, data, cubature) in [
            ("vanilla", &r.vanilla, false),
            ("Lipschitz", &r.lipschitz, false),
            ("vanilla, runtime cubature", &r.vanilla, true),
            ("Lipschitz, runtime cubature", &r.lipschitz, true),
        ] {
            reduced.push(ReducedSubspace {
                name: name.into(),
                decoder: SubspaceMap::Network(Box::new(data.decoder()?)),
                initial_latent: data.initial_latent.clone(),
                energies: cubature.then(|| with_cubature.clone()),
            });
        }
    }
    let trained = Trained {
        learned,
        encoding: match &reduced_file {
            Some(_) => Some(Encoding::new(&problem, RodEncoding::Positions)?),
            None => None,
        },
        reduced,
        reduced_settings,
        paper_settings,
        peers: options.peers.clone(),
        learned_absent: bytes.is_empty().then(|| lineup::absent_learned(&recipe)),
        reduced_absent: reduced_file.is_none().then(|| lineup::absent_reduced(&recipe)),
        peers_absent: options.peers.is_none().then(|| lineup::absent_peers(&recipe)),
    };
    let mut comparison = chart(&problem, &trained, options, report)?;
    if let Some(span) = options.matrix {
        for condition in conditions::select(conditions::conditions(&problem, span), &options.conditions)? {
            let row = matrix::matrix_row(&condition, &trained, options, report)?;
            comparison.matrix.push(row);
        }
    }
    Ok(comparison)
}

/// The chart: every method at every budget on the first test sequences.
fn chart(
    problem: &BuiltScene,
    trained: &Trained,
    options: &CompareOptions,
    report: &dyn Reporter,
) -> TrainerResult<Comparison> {
    let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
    let sequences = conditions::chart_sequences(problem, options.sequences, options.frames);
    let mut comparison = Comparison {
        scene: problem.scene.name.clone(),
        vertices: problem.mesh.num_vertices(),
        sequences: sequences.iter().map(|(p, _)| p.clone()).collect(),
        frames: options.frames,
        converged: Vec::new(),
        points: Vec::new(),
        unavailable: Vec::new(),
        matrix: Vec::new(),
    };
    for (plan, bc) in &sequences {
        let (implicit, implicit_failure) = reference(problem, 1, None, bc, options.frames)?;
        if let (Some(dir), true) = (&options.cases, options.cases_only) {
            fs::create_dir_all(dir)?;
            case::write_case(&dir.join(format!("{}.npz", plan.name)), problem, bc, &implicit)?;
            continue;
        }
        let (converged, info, converged_failure) =
            converged_reference(problem, bc, options.frames, options.max_substeps, &implicit)?;
        report.message(&format!(
            "{} {}: time-converged reference at {} substeps (last halving moved it {:.4}%)",
            problem.scene.name,
            plan.name,
            info.0,
            100.0 * info.1
        ));
        comparison.converged.push(Converged {
            sequence: plan.name.clone(),
            substeps: info.0,
            change: info.1,
            failures: [implicit_failure, converged_failure].into_iter().flatten().collect(),
        });
        if let Some(dir) = &options.cases {
            fs::create_dir_all(dir)?;
            case::write_case(&dir.join(format!("{}.npz", plan.name)), problem, bc, &implicit)?;
        }
        let mut entries = lineup::simulated(&problem.scene, problem, Budgets::Sweep);
        entries.extend(lineup::reduced(trained, problem, RunTimeChange::None));
        entries.extend(lineup::learned(trained, RunTimeChange::None, Budgets::Sweep));
        entries.extend(lineup::peers(trained, &plan.name, problem.mesh.num_vertices(), dim));
        for entry in entries {
            let mut method = match entry {
                Entry::Runs(m) => m,
                Entry::Cannot { family, reason } => {
                    if !comparison.unavailable.iter().any(|c| c.method == family) {
                        comparison.unavailable.push(Cell {
                            method: family,
                            text: reason,
                        });
                    }
                    continue;
                }
            };
            let refs: [&[Vec<f64>]; 2] = [&implicit, &converged];
            let run = run_sequence(method.as_mut(), bc, options.frames, &refs, dim, diagonal, None)?;
            report.message(&format!(
                "{} {}: {} {}: {:.3} ms/frame, error {:.3}% (implicit Euler), {:.3}% (converged){}",
                problem.scene.name,
                plan.name,
                method.family(),
                method.setting(),
                1e3 * run.seconds,
                100.0 * run.mean_error(0),
                100.0 * run.mean_error(1),
                run.failure
                    .as_ref()
                    .map_or(String::new(), |f| format!(", stopped at {f}"))
            ));
            let (family, setting) = (method.family(), method.setting());
            match comparison
                .points
                .iter_mut()
                .find(|p| p.family == family && p.setting == setting)
            {
                Some(p) => p.runs.push(run),
                None => comparison.points.push(ChartPoint {
                    family,
                    setting,
                    runs: vec![run],
                }),
            }
        }
    }
    Ok(comparison)
}

/// Full-space positions of frames `0..=frames` of `bc` with `substeps` steps per frame, by
/// the scene's own time scheme or by `scheme`, up to the frame where full space itself
/// fails, if it does (then also why).
fn reference(
    problem: &BuiltScene,
    substeps: usize,
    scheme: Option<TimeScheme>,
    bc: &BcSequence,
    frames: usize,
) -> TrainerResult<(Vec<Vec<f64>>, Option<String>)> {
    let mut scene = problem.scene.clone();
    scene.solver = SolverSpec::FullSpace;
    if let Some(scheme) = scheme {
        scene.integrator = scheme;
    }
    let mut method = Simulated::new(&scene, substeps, String::new())?;
    let mut kept = Vec::new();
    let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
    let run = run_sequence(
        &mut method,
        bc,
        frames,
        &[],
        dim,
        diagonal,
        Some((&mut kept, frames + 1)),
    )?;
    let failure = run
        .failure
        .map(|f| format!("full space at {substeps} step(s) per frame fails at {f}"));
    Ok((kept, failure))
}

/// Positions of a reference run, its substeps per frame, how far the last halving of its
/// step moved it, and why it stopped early (a finer run failing).
type ConvergedRun = (Vec<Vec<f64>>, (usize, f64), Option<String>);

/// The time-converged reference (module documentation). A quasi-static scene has no time to
/// converge in: its reference is `implicit` itself.
fn converged_reference(
    problem: &BuiltScene,
    bc: &BcSequence,
    frames: usize,
    max_substeps: usize,
    implicit: &[Vec<f64>],
) -> TrainerResult<ConvergedRun> {
    if problem.scene.integrator == TimeScheme::QuasiStatic {
        return Ok((implicit.to_vec(), (1, 0.0), None));
    }
    let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
    let mut substeps = 1;
    let (mut last, mut failure) = reference(problem, substeps, Some(TimeScheme::Bdf2), bc, frames)?;
    let mut change = f64::NAN;
    while failure.is_none() && 2 * substeps <= max_substeps {
        let (next, next_failure) = reference(problem, 2 * substeps, Some(TimeScheme::Bdf2), bc, frames)?;
        if let Some(f) = next_failure {
            // A finer run that fails keeps the coarser, complete one.
            failure = Some(format!("{f}; the reference stays at {substeps}"));
            break;
        }
        substeps *= 2;
        change = next
            .iter()
            .zip(&last)
            .map(|(a, b)| mochi_sim::measure::mean_and_max_error(a, b, dim, diagonal).0)
            .fold(0.0, f64::max);
        last = next;
        if change < CONVERGED_CHANGE {
            break;
        }
    }
    Ok((last, (substeps, change), failure))
}

/// A condition's name as a file stem.
pub fn slug(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '-'
            }
        })
        .collect()
}
