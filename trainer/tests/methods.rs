//! The one interface for a method (`methods::method`) on the tiny cantilever: the simulator
//! through it is the simulator, substeps converge, the coarse mesh's handles follow the
//! scene's, the learned runtime through it gives `mochi eval`'s storage numbers, a peer's
//! recording replays, and `mochi compare` runs every family into its page.

use std::path::PathBuf;

use mochi_runtime::{AnyInstance, OwnedModel, ValidModel};
use mochi_sim::dataset::{self, Split};
use mochi_sim::measure::mean_and_max_error;
use mochi_sim::npz::NpzOut;
use mochi_sim::SpeedPlan;
use mochi_trainer::eval::compare::conditions::{self, MatrixSpan};
use mochi_trainer::eval::compare::matrix::reference_check;
use mochi_trainer::eval::compare::{compare, page, CompareOptions};
use mochi_trainer::eval::storage;
use mochi_trainer::methods::learned::{motions, LearnedRuntime};
use mochi_trainer::methods::method::{run_sequence, Method};
use mochi_trainer::methods::peer::PeerRecording;
use mochi_trainer::methods::simulated::Simulated;
use mochi_trainer::{Artifact, Quiet, Recipe};

fn artifacts() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/artifacts")
}

fn tiny() -> Recipe {
    let artifact = Artifact::read(&artifacts().join("tiny.mochi")).unwrap();
    Recipe::parse(&artifact.scene_toml, std::path::Path::new(&artifact.scene_path)).unwrap()
}

#[test]
fn the_simulator_through_the_interface_is_the_simulator() {
    // One thread: the energies' parallel sums follow the threads, so only then are two runs
    // the same bits.
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    pool.install(|| {
        let mut problem = tiny().build().unwrap();
        let bc = problem.sequence(&SpeedPlan::constant(0.8), 30, 5);
        let direct = problem.run(&bc, &mochi_sim::Silent).unwrap();
        let mut method = Simulated::new(&problem.scene, 1, "").unwrap();
        let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
        let mut kept = Vec::new();
        let run = run_sequence(
            &mut method,
            &bc,
            30,
            &[&direct.positions],
            dim,
            diagonal,
            Some((&mut kept, 31)),
        )
        .unwrap();
        assert!(
            kept == direct.positions,
            "the interface's positions differ from the simulator's"
        );
        assert!(run.stable() && run.stable_frames == 30);
        assert!(run.error_curves[0].iter().all(|&e| e == 0.0));
        assert!(run.iterations >= 1.0 && run.seconds > 0.0);
    });
}

/// With a run-time collider, the interface moves it as the simulator's own run does: the
/// full-space method's positions are the dataset's, and the ball presses the block.
#[test]
fn the_simulator_through_the_interface_moves_the_run_time_colliders() {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    pool.install(|| {
        let scene = artifacts().join("tiny-poke.toml");
        let mut problem = Recipe::load(scene.to_str().unwrap()).unwrap().build().unwrap();
        let frames = 40;
        let bc = problem.sequence(&SpeedPlan::constant(1.0), frames, 2);
        let direct = problem.run(&bc, &mochi_sim::Silent).unwrap();
        let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
        let mut kept = Vec::new();
        for substeps in [1, 2] {
            let mut method = Simulated::new(&problem.scene, substeps, "").unwrap();
            kept.clear();
            run_sequence(
                &mut method,
                &bc,
                frames,
                &[],
                dim,
                diagonal,
                Some((&mut kept, frames + 1)),
            )
            .unwrap();
            if substeps == 1 {
                assert!(
                    kept == direct.positions,
                    "the interface's positions differ from the simulator's"
                );
            }
            // The ball comes down onto the block's top face (rest height 6 cm) and presses it.
            let lowest_top = kept
                .iter()
                .flat_map(|x| x.chunks(dim).zip(problem.mesh.rest.chunks(dim)))
                .filter(|(_, rest)| rest[1] > 0.06 - 1e-9)
                .map(|(p, _)| p[1])
                .fold(f64::INFINITY, f64::min);
            assert!(
                lowest_top < 0.06 - 3e-3,
                "{substeps} substep(s): the top sank to {lowest_top} only"
            );
        }
    });
}

#[test]
fn substeps_converge_and_the_coarse_mesh_follows_the_handles() {
    let problem = tiny().build().unwrap();
    let bc = problem.sequence(&SpeedPlan::constant(1.0), 20, 3);
    let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
    let positions = |k: usize| {
        let mut m = Simulated::new(&problem.scene, k, "").unwrap();
        let mut kept = Vec::new();
        run_sequence(&mut m, &bc, 20, &[], dim, diagonal, Some((&mut kept, 21))).unwrap();
        kept
    };
    let (one, two, eight) = (positions(1), positions(2), positions(8));
    let gap = |a: &[Vec<f64>], b: &[Vec<f64>]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| mean_and_max_error(x, y, dim, diagonal).0)
            .fold(0.0, f64::max)
    };
    // Implicit Euler is first order: halving the step about halves the distance to a much
    // finer one.
    let (coarse_gap, fine_gap) = (gap(&one, &eight), gap(&two, &eight));
    assert!(fine_gap < 0.7 * coarse_gap, "{fine_gap} vs {coarse_gap}");
    assert!(coarse_gap > 0.0);

    let mut coarse = Simulated::coarse(&problem.scene, &problem).unwrap();
    assert!(coarse.problem().mesh.num_vertices() < problem.mesh.num_vertices());
    coarse.reset(&bc).unwrap();
    let handles: Vec<usize> = problem.handles.iter().flat_map(|h| h.vertices.clone()).collect();
    for frame in 1..=20 {
        coarse.step(&bc, frame).unwrap();
        let targets = bc.targets(&problem.handles, frame, dim);
        for (i, &v) in handles.iter().enumerate() {
            for c in 0..dim {
                let d = coarse.positions()[dim * v + c] - targets[dim * i + c];
                assert!(d.abs() < 1e-12 * diagonal.max(1.0), "frame {frame} vertex {v}: {d}");
            }
        }
    }
}

#[test]
fn the_learned_runtime_through_the_interface_gives_evals_storage_numbers() {
    let mut problem = tiny().build().unwrap();
    let dir = tempfile::tempdir().unwrap();
    dataset::generate(&mut problem, dir.path(), Some(Split::Test), false, &mochi_sim::Silent).unwrap();
    let tests = dataset::load(&problem, dir.path(), Split::Test).unwrap();
    let path = artifacts().join("tiny.mochi");
    let bytes = std::fs::read(&path).unwrap();
    let frames = 50;
    let reports = storage::evaluate(&bytes, &path, &problem, &tests, frames).unwrap();

    // The runtime stepped directly, as an engine would: step, decode, measure.
    let mut owned = OwnedModel::default();
    let model: ValidModel = owned.load(&bytes).unwrap();
    let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
    let mut mean = 0.0;
    for (plan, reference) in &tests {
        let measured = frames.min(reference.num_frames() - 1);
        let bc = problem.sequence(&plan.speeds, measured, plan.seed);
        let mut body = AnyInstance::new(&model).unwrap();
        let mut x = vec![0.0f32; model.model().state_len()];
        let mut sum = 0.0;
        for t in 1..=measured {
            body.step(&model, &motions(&bc, t)).unwrap();
            body.decode_into(&model, &mut x).unwrap();
            let x: Vec<f64> = x.iter().map(|&v| v as f64).collect();
            sum += mean_and_max_error(&x, &reference.positions[t], dim, diagonal).0;
        }
        mean += sum / measured as f64 / tests.len() as f64;
    }
    // The storage evaluation measures with the model's own diagonal (f32), this loop with the
    // mesh's: the same numbers to rounding.
    let want = reports[0].mean_error;
    assert!((mean - want).abs() <= 1e-6 * want, "{mean} vs {want}");
    // ... and the interface's loop reports the runtime's cost.
    let mut method = LearnedRuntime::new(&model, "learned (runtime)", "f32".into()).unwrap();
    let (plan, reference) = &tests[0];
    let bc = problem.sequence(&plan.speeds, frames, plan.seed);
    let run = run_sequence(&mut method, &bc, frames, &[&reference.positions], dim, diagonal, None).unwrap();
    assert!(run.multiply_adds > 0.0 && run.stable());
}

#[test]
fn compare_runs_every_family_and_replays_a_peer() {
    let dir = tempfile::tempdir().unwrap();
    let cases = dir.path().join("cases");
    let peers = dir.path().join("peers");
    let base = CompareOptions {
        model: Some(artifacts().join("tiny.mochi")),
        reduced: None,
        peers: None,
        cases: Some(cases.clone()),
        cases_only: false,
        sequences: 1,
        frames: 12,
        matrix: None,
        conditions: Vec::new(),
        max_substeps: 4,
    };
    let first = compare("tiny", &base, &Quiet).unwrap();
    assert!(cases.join("test-02.npz").is_file());
    // A family that cannot run says why instead of leaving the chart.
    let reduced = first.unavailable.iter().find(|c| c.method == "reduced").unwrap();
    assert!(reduced.text.contains("no `[reduced]` table"), "{}", reduced.text);
    // A "peer" that recorded the implicit-Euler reference itself: error 0, its own times.
    let problem = tiny().build().unwrap();
    let full = first
        .points
        .iter()
        .find(|p| p.family == "full space" && p.setting.starts_with('1'))
        .unwrap();
    assert!(full.error(0) < 1e-12);
    let mut simulated = Simulated::new(&problem.scene, 1, "").unwrap();
    let bc = mochi_trainer::eval::compare::conditions::chart_sequences(&problem, 1, 12)
        .remove(0)
        .1;
    let mut kept = Vec::new();
    let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
    // On one thread, as `compare` runs: the energies' parallel sums follow the threads.
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    pool.install(|| run_sequence(&mut simulated, &bc, 12, &[], dim, diagonal, Some((&mut kept, 13))))
        .unwrap();
    std::fs::create_dir_all(peers.join("test-02")).unwrap();
    let recording = peers.join("test-02/xpbd-s1-i1.npz");
    let mut npz = NpzOut::create(&recording).unwrap();
    let n = problem.mesh.num_vertices() as u64;
    npz.array("positions", &[13, n, 3], kept.iter().flatten().copied())
        .unwrap();
    npz.array("step_seconds", &[12], [2e-3; 12]).unwrap();
    npz.array("substeps", &[], [1i64]).unwrap();
    npz.array("iterations", &[], [1i64]).unwrap();
    npz.finish().unwrap();
    assert_eq!(
        PeerRecording::read(&recording, "XPBD (pypbd)", n as usize, dim)
            .unwrap()
            .frames(),
        12
    );

    // The selection's other candidates beside the model chart as budgets of their own family
    // (f32); a copy of the kept model among them is not charted twice.
    let models = dir.path().join("model");
    std::fs::create_dir_all(models.join("candidates")).unwrap();
    std::fs::copy(artifacts().join("tiny.mochi"), models.join("tiny.mochi")).unwrap();
    std::fs::copy(artifacts().join("tiny.mochi"), models.join("candidates/same.mochi")).unwrap();
    let mut other = Artifact::read(&artifacts().join("tiny.mochi")).unwrap();
    other.integrator.last_mut().unwrap().bias[0] += 1e-3;
    other.write(&models.join("candidates/other.mochi")).unwrap();

    let options = CompareOptions {
        model: Some(models.join("tiny.mochi")),
        peers: Some(peers),
        cases: None,
        matrix: Some(MatrixSpan {
            frames: 8,
            long_frames: 16,
        }),
        ..base
    };
    let c = compare("tiny", &options, &Quiet).unwrap();
    for family in [
        "full space",
        "coarse mesh",
        "adaptive",
        "VBD",
        "learned (runtime)",
        "XPBD (pypbd)",
    ] {
        assert!(c.points.iter().any(|p| p.family == family), "{family} missing");
    }
    let peer = c.points.iter().find(|p| p.family == "XPBD (pypbd)").unwrap();
    assert!(peer.error(0) < 1e-12);
    assert!((peer.seconds() - 2e-3).abs() < 1e-15);
    let learned = c.points.iter().filter(|p| p.family == "learned (runtime)").count();
    assert_eq!(learned, 3, "f32, f16 and int8");
    let others: Vec<&str> = c
        .points
        .iter()
        .filter(|p| p.family == "learned (runtime), other candidates")
        .map(|p| p.setting.as_str())
        .collect();
    assert_eq!(others.len(), 1, "the other candidate, once: {others:?}");
    assert!(others[0].ends_with("f32, other"), "{others:?}");
    assert!(c.points.iter().all(|p| p.runs.iter().all(|r| r.stable())));
    // Nine conditions but contact (tiny has none); the learned model says what it cannot take.
    assert_eq!(c.matrix.len(), 8);
    let halved = c.matrix.iter().find(|r| r.condition == "dt halved").unwrap();
    assert_eq!(halved.frames.0, 16);
    for row in &c.matrix {
        let full = &row.cells[0];
        // The long row's check reads over its last window as over its first.
        let check = if row.frames.0 > row.frames.1 {
            "(the reference; tolerance / 1000: 0.000% (frames 1-8), 0.000% (frames 9-16))"
        } else {
            "(the reference; tolerance / 1000: 0.000%)"
        };
        assert!(
            full.method == "full space" && full.text.contains(check),
            "{}: {}",
            row.condition,
            full.text
        );
    }
    assert!(halved
        .cells
        .iter()
        .any(|cell| cell.method.starts_with("learned") && cell.text.starts_with("needs retraining")));
    page::write(dir.path(), &c, "mochi compare tiny").unwrap();
    let text = std::fs::read_to_string(dir.path().join("tiny.md")).unwrap();
    assert!(text.contains("## Stability matrix") && text.contains("XPBD (pypbd)"));
    assert!(dir.path().join("tiny/speed-accuracy-converged.png").is_file());
}

/// The matrix's check of its reference: full space at a tighter Newton tolerance stays within
/// round-off of the tiny cantilever's reference, and the check is read per frame over the
/// reference's frames: a reference moved by 1% of the diagonal on its last four frames reads
/// 0% over the first window and 1% over the last.
#[test]
fn the_matrix_measures_how_far_a_tighter_tolerance_moves_its_reference() {
    let problem = tiny().build().unwrap();
    let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
    let bc = problem.sequence(&SpeedPlan::constant(0.8), 12, 5);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let mut reference = Vec::new();
    let mut full = Simulated::new(&problem.scene, 1, "").unwrap();
    pool.install(|| run_sequence(&mut full, &bc, 12, &[], dim, diagonal, Some((&mut reference, 13))))
        .unwrap();
    let check = pool
        .install(|| reference_check(&problem.scene, &bc, &reference, dim, diagonal))
        .unwrap();
    assert_eq!(check.error_curves[0].len(), 12);
    assert!(check.mean_error(0) < 1e-6, "{}", check.mean_error(0));
    assert_eq!(
        page::window_errors(&check, 4, 4),
        "0.000% (frames 1-4), 0.000% (frames 9-12)"
    );
    assert_eq!(page::window_errors(&check, 4, 0), "0.000%");
    let moved: Vec<Vec<f64>> = reference
        .iter()
        .enumerate()
        .map(|(f, x)| {
            let mut x = x.clone();
            if f > 8 {
                x.iter_mut().step_by(dim).for_each(|v| *v += 0.01 * diagonal);
            }
            x
        })
        .collect();
    let check = pool
        .install(|| reference_check(&problem.scene, &bc, &moved, dim, diagonal))
        .unwrap();
    assert!(
        (check.error_curves[0][11] - 0.01).abs() < 1e-4,
        "{:?}",
        check.error_curves[0]
    );
    assert_eq!(
        page::window_errors(&check, 4, 4),
        "0.000% (frames 1-4), 1.000% (frames 9-12)"
    );
    // Over the first frames only, as a short condition's check reads.
    let check = pool
        .install(|| reference_check(&problem.scene, &bc, &moved[..=4], dim, diagonal))
        .unwrap();
    assert_eq!(check.error_curves[0].len(), 4);
    assert_eq!(page::window_errors(&check, 4, 0), "0.000%");
}

/// `mochi eval --adaptive` steps through the interface: its errors, iterations and enriched
/// share are those of the adaptive solver stepped directly (one thread, the same bits).
#[test]
fn eval_of_the_adaptive_solver_gives_the_direct_numbers() {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    pool.install(|| {
        let problem = tiny().build().unwrap();
        let plan = dataset::plan(&problem.scene.dataset)
            .into_iter()
            .find(|p| p.split == Split::Test)
            .unwrap();
        let bc = problem.sequence(&plan.speeds, 25, plan.seed);
        let mut full = problem.scene.clone().build().unwrap();
        let reference = full.run(&bc, &mochi_sim::Silent).unwrap();
        let (_, rows) = mochi_trainer::eval::adaptive::evaluate_adaptive(
            &problem,
            &[(plan.clone(), reference.clone())],
            std::slice::from_ref(&bc),
            25,
            &Quiet,
        )
        .unwrap();

        let mut scene = problem.scene.clone();
        scene.solver = mochi_sim::SolverSpec::Adaptive(mochi_sim::AdaptiveSettings::default());
        let mut adaptive = scene.build().unwrap();
        let mut traj = adaptive.start(&bc).unwrap();
        let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
        let (mut mean, mut max, mut iterations, mut enriched) = (0.0, 0.0f64, 0.0, 0.0);
        for frame in 1..=25 {
            let step = adaptive.advance(&bc, frame, &mut traj).unwrap();
            let (m, x) = mean_and_max_error(&traj.positions[frame], &reference.positions[frame], dim, diagonal);
            mean += m / 25.0;
            max = max.max(x);
            iterations += step.iterations as f64 / 25.0;
            let a = step.adaptive.unwrap();
            enriched += a.enriched_vertices as f64 / a.free_vertices.max(1) as f64 / 25.0;
        }
        let got = &rows[0].1;
        assert!(
            (got.mean_error - mean).abs() <= 1e-12 * mean.max(1e-300),
            "{} vs {mean}",
            got.mean_error
        );
        assert_eq!(got.max_error, max);
        assert!((got.iterations - iterations).abs() < 1e-12);
        assert!((got.enriched - enriched).abs() < 1e-12);
        assert!(mean > 0.0);
    });
}

/// `--sequences 0 --conditions 16-frames`: the long condition alone, each running method
/// measured over its first frames and again over its last; the last window is the mean error
/// of the runtime stepped directly against full space over those frames.
#[test]
fn the_long_condition_alone_is_measured_at_both_ends() {
    let span = MatrixSpan {
        frames: 6,
        long_frames: 16,
    };
    let options = CompareOptions {
        model: Some(artifacts().join("tiny.mochi")),
        reduced: None,
        peers: None,
        cases: None,
        cases_only: false,
        sequences: 0,
        frames: 6,
        matrix: Some(span),
        conditions: vec!["16-frames".into()],
        max_substeps: 2,
    };
    let c = compare("tiny", &options, &Quiet).unwrap();
    assert!(c.points.is_empty() && c.sequences.is_empty(), "no chart");
    assert_eq!(c.matrix.len(), 1);
    let row = &c.matrix[0];
    assert_eq!((row.condition.as_str(), row.frames), ("16 frames", (16, 6)));
    let cell = row
        .cells
        .iter()
        .find(|cell| cell.method == "learned (runtime) k=4, f32")
        .unwrap_or_else(|| panic!("{:?}", row.cells));
    let (head, last) = cell.text.split_once(" (frames 1-6), ").expect(&cell.text);
    assert!(
        head.starts_with("16 / 16, ") && last.ends_with(" (frames 11-16)"),
        "{}",
        cell.text
    );
    let last: f64 = last.trim_end_matches("% (frames 11-16)").parse().unwrap();
    assert_eq!(
        row.cells[0].text,
        "16 / 16 (the reference; tolerance / 1000: 0.000% (frames 1-6), 0.000% (frames 11-16))"
    );

    let problem = tiny().build().unwrap();
    let long = conditions::conditions(&problem, span)
        .into_iter()
        .find(|c| c.name == "16 frames")
        .unwrap();
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap();
    let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
    let mut reference = Vec::new();
    let mut full = Simulated::new(&problem.scene, 1, "").unwrap();
    pool.install(|| run_sequence(&mut full, &long.bc, 16, &[], dim, diagonal, Some((&mut reference, 17))))
        .unwrap();
    let bytes = std::fs::read(artifacts().join("tiny.mochi")).unwrap();
    let mut owned = OwnedModel::default();
    let model: ValidModel = owned.load(&bytes).unwrap();
    let mut method = LearnedRuntime::new(&model, "learned (runtime)", "f32".into()).unwrap();
    let run = run_sequence(&mut method, &long.bc, 16, &[&reference], dim, diagonal, None).unwrap();
    let want = 100.0 * run.error_curves[0][10..].iter().sum::<f64>() / 6.0;
    assert!((last - want).abs() <= 5e-4 + 1e-3 * want, "{last} vs {want:.5}");
    assert!(want > 0.0);

    // The page of a matrix alone, and a condition the scene does not have refused by name.
    let dir = tempfile::tempdir().unwrap();
    page::write(dir.path(), &c, "mochi compare tiny --sequences 0").unwrap();
    let text = std::fs::read_to_string(dir.path().join("tiny.md")).unwrap();
    assert!(text.starts_with("# tiny: stability matrix") && text.contains("| 16 frames |"));
    // Its peer case alone, into a folder not there yet.
    let cases = dir.path().join("new/cases");
    let only_cases = CompareOptions {
        cases: Some(cases.clone()),
        cases_only: true,
        ..options.clone()
    };
    compare("tiny", &only_cases, &Quiet).unwrap();
    assert!(cases.join("16-frames.npz").is_file());
    let wrong = CompareOptions {
        conditions: vec!["contact".into()],
        ..options
    };
    let e = compare("tiny", &wrong, &Quiet).unwrap_err().to_string();
    assert!(
        e.contains("`contact`") && e.contains("16-frames") && e.contains("dt-halved"),
        "{e}"
    );
}
