//! The reduced method end to end on a tiny scene: `mochi train` with a `[reduced]` table
//! writes both subspaces and their cubature, `mochi eval` steps them on the test sequences
//! (every step converged, projections measured), and `mochi bench reduced` times them.

use mochi_sim::energy::StencilEnergy;
use mochi_sim::measure::mean_and_max_error;
use mochi_sim::SpeedPlan;
use mochi_trainer::artifact::reduced::{reduced_path, ReducedArtifact};
use mochi_trainer::eval::reduced::{step_sequence, stepper_settings};
use mochi_trainer::eval::reduced_bench::{self, ReducedBenchOptions};
use mochi_trainer::learn::encoding::Encoding;
use mochi_trainer::learn::recipe::RodEncoding;
use mochi_trainer::methods::reduced::optimize::Exit;
use mochi_trainer::methods::reduced::rounding::Rounding;
use mochi_trainer::methods::reduced::stepper::ReducedStepper;
use mochi_trainer::methods::reduced::subspace::DecoderSubspace;
use mochi_trainer::{artifact_paths, evaluate, train_scene, EvalOptions, Quiet, Recipe, TrainOptions};

/// The tiny cantilever of the latent tests, asking for the reduced method with a short
/// Lipschitz optimisation.
const TINY: &str = include_str!("../sim/tests/fixtures/tiny-train.toml");
const REDUCED: &str = "\n[reduced]\nsubspace = \"supervised\"\nlipschitz_epochs = 3\nsamples = 4\ncubature = 40\n";

/// Trains the tiny scene with `extra` appended to its `[reduced]` table into `dir/out`.
fn train_tiny(dir: &std::path::Path, extra: &str) -> (Recipe, std::path::PathBuf, mochi_trainer::TrainOutcome) {
    let path = dir.join("tiny.toml");
    // The reduced method's vanilla subspace is the MLP decoder; the selection tries only it here.
    let mlp_only = "\n[latent.selection]\ndecoders = [\"mlp\"]\n";
    std::fs::write(&path, format!("{TINY}{REDUCED}{extra}{mlp_only}")).unwrap();
    let recipe = Recipe::load(path.to_str().unwrap()).unwrap();
    let out = dir.join("out");
    let options = TrainOptions {
        out_dir: out.clone(),
        resume: false,
        latent: None,
        frame_memory: mochi_trainer::FRAME_MEMORY,
    };
    let outcome = train_scene(&recipe, &options, &Quiet).unwrap();
    (recipe, out, outcome)
}

#[test]
fn tiny_scene_trains_evaluates_and_benches_the_reduced_method() {
    let dir = tempfile::tempdir().unwrap();
    let (recipe, out, outcome) = train_tiny(dir.path(), "");

    // Both subspaces share the kept autoencoder's latent size, the Lipschitz one differs
    // from the vanilla one, and the file on disk is what the stage returned.
    let reduced = outcome.reduced.expect("a [reduced] scene writes its subspaces");
    assert_eq!(reduced.source, "supervised");
    let k = outcome.model.latent as usize;
    assert_eq!(reduced.vanilla.initial_latent.len(), k);
    assert_eq!(reduced.lipschitz.initial_latent.len(), k);
    let linear = reduced
        .pca
        .as_ref()
        .expect("a supervised subspace keeps the PCA of its frames");
    assert_eq!((linear.basis.len(), linear.initial_latent.len()), (k, k));
    assert!(reduced.lipschitz.training_seconds >= reduced.vanilla.training_seconds);
    assert!(!reduced.cubature.is_empty() && reduced.lambda > 0.0);
    let file = reduced_path(&out, "tiny");
    assert_eq!(ReducedArtifact::load(&file).unwrap(), reduced);

    // The evaluation's rollout (through the methods' one measuring loop) is the stepper's own
    // loop: the same states, hence the same errors, bit for bit, and the same exits.
    let mut problem = recipe.build().unwrap();
    let bc = problem.sequence(&SpeedPlan::constant(1.0), 30, 5);
    let reference = problem.run(&bc, &mochi_sim::Silent).unwrap();
    let encoding = Encoding::new(&problem, RodEncoding::Positions).unwrap();
    let settings = stepper_settings(&recipe.reduced.clone().unwrap(), problem.scene.integrator);
    let potentials: Vec<&dyn StencilEnergy> = problem.simulator.potentials().iter().map(|p| p.as_ref()).collect();
    let mut visited = Vec::new();
    let metrics = step_sequence(
        &reduced.lipschitz,
        &problem,
        &encoding,
        &settings,
        &potentials,
        &bc,
        Some(&reference),
        30,
        &mut visited,
    )
    .unwrap();
    let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
    let targets = |t: usize| bc.targets(&problem.handles, t, dim);
    let decoder = reduced.lipschitz.decoder().unwrap();
    let subspace = DecoderSubspace::new(&decoder, &encoding, &targets(0)).unwrap();
    let masses = problem.simulator.masses().to_vec();
    let mut stepper =
        ReducedStepper::new(subspace, encoding.clone(), masses, diagonal, problem.scene.dt, settings).unwrap();
    stepper.reset(&reduced.lipschitz.initial_latent, &targets(0)).unwrap();
    let mut iterations = 0;
    for t in 1..=30 {
        let step = stepper.step(&potentials, &targets(t)).unwrap();
        assert_eq!(step.exit, Exit::Converged);
        iterations += step.iterations;
        let (mean, _) = mean_and_max_error(stepper.positions(), &reference.positions[t], dim, diagonal);
        assert_eq!(metrics.error_curve[t - 1], mean, "frame {t}");
    }
    assert_eq!(metrics.stable_frames, 30);
    assert_eq!(metrics.iterations, iterations as f64 / 30.0);
    assert_eq!(metrics.exits.count(Exit::Converged), 30);
    assert_eq!(visited.len(), 3, "every tenth frame's latent");
    assert!(!metrics.convergence.is_empty(), "the tenth step's objective history");

    // Evaluation adds the four reduced runs; every step converges, the exact-energy runs
    // project the reference, and the report has the section and the projection check.
    let (model_path, _) = artifact_paths(&out, "tiny");
    let eval = EvalOptions {
        out_dir: dir.path().join("eval"),
        stability_frames: 100,
        accuracy_frames: 60,
        adaptive: false,
        full_space_reference: false,
    };
    evaluate(std::slice::from_ref(&model_path), &eval, &Quiet).unwrap();
    let report = std::fs::read_to_string(dir.path().join("eval/report.md")).unwrap();
    let section = &report[report.find("## Reduced-order solver").expect("reduced section")..];
    let rows: Vec<Vec<&str>> = section
        .lines()
        .filter(|l| l.starts_with("| vanilla") || l.starts_with("| Lipschitz"))
        .map(|l| l.split('|').map(str::trim).collect())
        .collect();
    assert_eq!(rows.len(), 4 * 2, "four runs on two test sequences: {section}");
    for cells in &rows {
        let mean: f64 = cells[3].parse().unwrap();
        assert!(mean.is_finite() && mean < 50.0, "percent of the diagonal: {cells:?}");
        assert_eq!(cells[8], "100 / 0 / 0 / 0", "every step converged: {cells:?}");
        assert_eq!(cells[9], "60", "{cells:?}");
        let cubature = cells[1].contains("cubature");
        assert_eq!(
            cells[5] == "-",
            cubature,
            "projections for the exact runs only: {cells:?}"
        );
        if !cubature {
            // The closest state of a subspace is no farther from the reference than the
            // solver's state (both are states of that subspace), up to the projection's
            // own tolerance.
            let projection: f64 = cells[5].parse().unwrap();
            assert!(projection <= mean + 1e-3, "{cells:?}");
        }
    }
    assert!(section.contains("Projection check"), "{section}");

    // `mochi compare` runs the PCA and both trained subspaces, with the scene's solver and with the paper's, and
    // with runtime cubature.
    let compared = mochi_trainer::eval::compare::compare(
        "tiny",
        &mochi_trainer::eval::compare::CompareOptions {
            model: Some(model_path.clone()),
            reduced: Some(file.clone()),
            peers: None,
            cases: None,
            cases_only: false,
            sequences: 1,
            frames: 8,
            matrix: None,
            conditions: Vec::new(),
            max_substeps: 2,
        },
        &Quiet,
    )
    .unwrap();
    for family in [
        "reduced, PCA",
        "reduced, PCA, paper's solver",
        "reduced, vanilla",
        "reduced, Lipschitz",
        "reduced, vanilla, paper's solver",
        "reduced, Lipschitz, paper's solver",
        "reduced, Lipschitz, runtime cubature",
    ] {
        let point = compared.points.iter().find(|p| p.family == family);
        let point = point.unwrap_or_else(|| panic!("{family} missing"));
        assert!(
            point.error(0).is_finite() && point.error(0) < 0.5,
            "{family}: {}",
            point.error(0)
        );
    }
    assert!(dir.path().join("eval/convergence.png").is_file());

    // The bench steps the same four runs without a reference.
    let options = ReducedBenchOptions {
        frames: 20,
        ..ReducedBenchOptions::default()
    };
    let timings = reduced_bench::bench(&file, &options, &Quiet).unwrap();
    assert_eq!(timings.len(), 4);
    for t in &timings {
        assert!(t.ms_per_step > 0.0 && t.iterations > 0.0, "{t:?}");
        assert!(t.evaluations >= t.iterations, "{t:?}");
        assert_eq!(t.converged(), 1.0, "{t:?}");
        assert_eq!(t.exit_shares, [1.0, 0.0, 0.0, 0.0], "{t:?}");
        // Every step converged: a converged step's evaluations are all of them.
        assert!(
            (t.exit_evaluations[0] - t.evaluations).abs() <= 1e-9 * t.evaluations,
            "{t:?}"
        );
        assert!(t.exit_evaluations[1..].iter().all(|e| e.is_nan()), "{t:?}");
        // Converged steps stop at the tolerance or below it.
        assert!(t.exit_gradient >= 0.0 && t.exit_gradient <= 1e-5, "{t:?}");
        assert!(t.lipschitz.is_finite() && t.lipschitz > 0.0, "{t:?}");
        assert!(t.spread.is_finite() && t.spread > 0.0, "{t:?}");
        assert!(t.condition.is_finite() && t.condition >= 1.0, "{t:?}");
    }
    let table = reduced_bench::table("tiny", &options, &timings);
    // Each vanilla row is its own baseline; the Lipschitz rows are timed against them (a
    // Lipschitz row may also read 1.00x when the two run equally fast).
    for baseline in ["| vanilla |", "| vanilla, runtime cubature |"] {
        let row = table.lines().find(|l| l.starts_with(baseline)).expect("vanilla rows");
        assert!(row.contains("| 1.00x |"), "{table}");
    }
    // Cold solves (the paper's) take at least as many evaluations as warm ones on a whole
    // rollout, where every step after the first inherits curvature.
    let cold = ReducedBenchOptions { cold: true, ..options };
    let cold = reduced_bench::bench(&file, &cold, &Quiet).unwrap();
    for (w, c) in timings.iter().zip(&cold) {
        assert_eq!(c.converged(), 1.0, "{c:?}");
        assert!(c.evaluations >= w.evaluations, "cold {c:?} warm {w:?}");
    }
    // Every third frame: the same motions in three times larger steps, each solve starting
    // farther from its answer.
    let strided = ReducedBenchOptions { stride: 3, ..options };
    let table = reduced_bench::table(
        "tiny",
        &strided,
        &reduced_bench::bench(&file, &strided, &Quiet).unwrap(),
    );
    assert!(table.contains("20 steps of 3 frames each"), "{table}");
    // Emulated single precision: the same runs, every step ending in one of the exits.
    let single = ReducedBenchOptions {
        rounding: Rounding::Single,
        ..options
    };
    let single_timings = reduced_bench::bench(&file, &single, &Quiet).unwrap();
    for t in &single_timings {
        assert!(t.ms_per_step > 0.0 && t.evaluations >= t.iterations, "{t:?}");
        assert!((0.0..=1.0).contains(&t.converged()), "{t:?}");
        assert!((t.exit_shares.iter().sum::<f64>() - 1.0).abs() < 1e-12, "{t:?}");
        // The evaluations of each exit's steps, weighed by its share, are all of them.
        let by_exit: f64 = (0..4)
            .filter(|&k| t.exit_shares[k] > 0.0)
            .map(|k| t.exit_shares[k] * t.exit_evaluations[k])
            .sum();
        assert!((by_exit - t.evaluations).abs() <= 1e-9 * t.evaluations, "{t:?}");
    }
    let table = reduced_bench::table("tiny", &single, &single_timings);
    assert!(table.contains("in single precision (emulated)"), "{table}");
    // Below 10 frames no latent is kept for Lip: the table says so instead of printing 0.
    let short = ReducedBenchOptions { frames: 5, ..options };
    let table = reduced_bench::table("tiny", &short, &reduced_bench::bench(&file, &short, &Quiet).unwrap());
    assert!(table.contains("| - | - | - | - |"), "{table}");
    assert!(table.contains("run 10 frames or more"), "{table}");
    let none = ReducedBenchOptions { stride: 0, ..options };
    assert!(reduced_bench::bench(&file, &none, &Quiet).is_err());
}

#[test]
fn a_scene_file_that_seeds_a_supervised_subspace_is_refused_but_a_stored_recipe_reads() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("seeded.toml");
    let text = format!("{TINY}{REDUCED}seed = 3\n");
    std::fs::write(&path, &text).unwrap();
    let err = Recipe::load(path.to_str().unwrap()).unwrap_err().to_string();
    assert!(err.contains("reduced.seed") && err.contains("seeded.toml"), "{err}");
    // The recipes in artifacts of earlier builds carry `seed = 0` on supervised scenes.
    let stored = Recipe::parse(&text, &path).unwrap();
    assert_eq!(stored.reduced.unwrap().seed, Some(3));
}

/// The paper code's vanilla: plain ELU layers between the fixed maps of a PCA. Both subspaces
/// keep the PCA's maps exactly (the Lipschitz optimisation trains the layers between them), the
/// file reads back what was trained, and the solver converges in the projected subspace.
#[test]
fn the_paper_shaped_vanilla_keeps_its_pca_through_the_lipschitz_optimisation() {
    let dir = tempfile::tempdir().unwrap();
    let paper = "vanilla = \"plain-mlp\"\nplain_hidden = 24\nplain_blocks = 1\nplain_activation = \"elu\"\n\
                 plain_residual = false\nplain_epochs = 20\nplain_pca = 1e-3\n";
    let (recipe, out, outcome) = train_tiny(dir.path(), paper);
    let reduced = outcome.reduced.unwrap();
    assert_eq!(ReducedArtifact::load(&reduced_path(&out, "tiny")).unwrap(), reduced);
    let (vanilla, ours) = (reduced.vanilla.decoder().unwrap(), reduced.lipschitz.decoder().unwrap());
    for decoder in [&vanilla, &ours] {
        let style = decoder.style();
        assert!(style.output_projection && !style.residual, "{style:?}");
        assert_eq!(decoder.spec().blocks, 1);
    }
    let basis = vanilla.output_projection().unwrap();
    assert!(
        basis.cols < basis.rows,
        "{} components of {} values",
        basis.cols,
        basis.rows
    );
    assert_eq!(ours.output_projection().unwrap(), basis);
    assert_ne!(ours.output(), vanilla.output(), "the optimisation trains the layers");

    let problem = recipe.build().unwrap();
    let bc = problem.sequence(&SpeedPlan::constant(1.0), 10, 5);
    let encoding = Encoding::new(&problem, RodEncoding::Positions).unwrap();
    let settings = stepper_settings(&recipe.reduced.clone().unwrap(), problem.scene.integrator);
    let potentials: Vec<&dyn StencilEnergy> = problem.simulator.potentials().iter().map(|p| p.as_ref()).collect();
    let targets = |t: usize| bc.targets(&problem.handles, t, problem.mesh.dim);
    let subspace = DecoderSubspace::new(&ours, &encoding, &targets(0)).unwrap();
    let masses = problem.simulator.masses().to_vec();
    let diagonal = problem.mesh.rest_diagonal();
    let mut stepper =
        ReducedStepper::new(subspace, encoding.clone(), masses, diagonal, problem.scene.dt, settings).unwrap();
    stepper.reset(&reduced.lipschitz.initial_latent, &targets(0)).unwrap();
    for t in 1..=10 {
        assert_eq!(
            stepper.step(&potentials, &targets(t)).unwrap().exit,
            Exit::Converged,
            "frame {t}"
        );
    }

    // A PCA for a vanilla that is not the plain autoencoder would be ignored: refused.
    let ignored = dir.path().join("ignored.toml");
    std::fs::write(&ignored, format!("{TINY}{REDUCED}plain_pca = 1e-3\n")).unwrap();
    let err = Recipe::load(ignored.to_str().unwrap()).unwrap_err().to_string();
    assert!(
        err.contains("reduced.plain_pca") && err.contains("ignored.toml"),
        "{err}"
    );
}
