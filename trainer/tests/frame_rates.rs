//! The frame time as an input of the integrator, end to end on the tiny cantilever: a timed
//! model (the tiny model with a frame-time column added to its integrator's input layer) agrees
//! between the trainer's rollout and the runtime at frame rates inside and outside its trained
//! range, steps exactly as the model it came from when that column is zero, and
//! `mochi eval --rates` measures it at every rate while a model of one frame time says that it
//! needs retraining at the others.

use std::path::{Path, PathBuf};

use mochi_runtime::OwnedModel;
use mochi_sim::{BuiltScene, SpeedPlan};
use mochi_trainer::eval::rates::{evaluate_rates, RateCell, RatesOptions};
use mochi_trainer::eval::{carried_encoding, roll, LoadedModel};
use mochi_trainer::methods::learned::LearnedRuntime;
use mochi_trainer::methods::method::Method;
use mochi_trainer::{train_scene, Artifact, Quiet, Recipe, TrainOptions};

fn tiny_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/artifacts/tiny.mochi")
}

/// The tiny model with a frame-time input: one more column in the integrator's input layer,
/// `weight` times a small pattern per hidden unit, trained (nominally) over 30-120 Hz.
fn timed(a: &Artifact, weight: f32) -> Artifact {
    let mut t = a.clone();
    let first = &mut t.integrator[0];
    let cols = first.cols;
    let mut weights = Vec::with_capacity(first.rows * (cols + 1));
    for r in 0..first.rows {
        weights.extend_from_slice(&first.weights[r * cols..(r + 1) * cols]);
        weights.push(weight * ((r % 7) as f32 - 3.0));
    }
    first.weights = weights;
    first.cols = cols + 1;
    t.dt_range = [1.0 / 120.0, 1.0 / 30.0];
    t
}

/// A timed model `a` rewritten to read the last latent's change per frame of its `dt`,
/// `r = (z_{t-1} - z_{t-2}) dt_a / dt`, in place of `z_{t-2}`: `W1 z_{t-1} + W2 z_{t-2}` is
/// `(W1 + W2) z_{t-1} - W2 r` at its own frame time, the same network there.
fn reading_the_rate(mut a: Artifact) -> Artifact {
    let k = a.latent as usize;
    let first = &mut a.integrator[0];
    for row in first.weights.chunks_mut(first.cols) {
        for i in 0..k {
            row[i] += row[k + i];
            row[k + i] = -row[k + i];
        }
    }
    a.rate_input = true;
    a
}

/// The tiny scene built with a time step of `dt`.
fn scene_at(a: &Artifact, dt: f64) -> BuiltScene {
    let mut scene = Recipe::parse(&a.scene_toml, Path::new(&a.scene_path)).unwrap().scene;
    scene.dt = dt;
    scene.build().unwrap()
}

#[test]
fn a_timed_model_agrees_between_the_trainer_and_the_runtime_at_every_rate() {
    // Reading the latent before the last (format 7) and its change per frame (`rate_input`).
    for rate_input in [false, true] {
        timed_model_agrees_at_every_rate(rate_input);
    }
}

fn timed_model_agrees_at_every_rate(rate_input: bool) {
    let tiny = Artifact::read(&tiny_path()).unwrap();
    let mut model = timed(&tiny, 2.0);
    if rate_input {
        model = reading_the_rate(model);
    }
    let bytes = model.to_bytes().unwrap();
    // It is a valid artifact, read back as written.
    assert_eq!(Artifact::parse(&bytes).unwrap(), model);
    let mut storage = OwnedModel::default();
    let valid = storage.load(&bytes).unwrap();
    assert!(valid.model().timed());
    assert_eq!(valid.model().rate_input, rate_input);
    let loaded = LoadedModel::new(model.clone()).unwrap();
    let frames = 300;
    let mut finals = Vec::new();
    for rate in [24.0, 30.0, 72.0, 120.0, 144.0] {
        let dt = 1.0 / rate;
        let problem = scene_at(&model, dt);
        let encoding = carried_encoding(&model, &problem).unwrap();
        let bc = problem.sequence(&SpeedPlan::constant(0.3), frames, 5);
        // The trainer's rollout up to where its latent leaves the range the runtime clamps to
        // (the trained range widened by `RANGE_MARGIN` of its width on each side).
        let inside = |z: &[f32]| {
            z.iter()
                .zip(&model.latent_min)
                .zip(&model.latent_max)
                .all(|((v, lo), hi)| {
                    let margin = mochi_runtime::RANGE_MARGIN * (hi - lo);
                    *v >= lo - margin && *v <= hi + margin
                })
        };
        let mut trainer = Vec::new();
        roll(&loaded, &problem, &encoding, &bc, frames, |_, z, _, x| {
            let keep = inside(z);
            if keep {
                trainer.push(x.to_vec());
            }
            keep
        })
        .unwrap();
        assert!(trainer.len() >= 25, "{rate} Hz: only {} frames in range", trainer.len());
        let mut runtime = LearnedRuntime::new(&valid, "learned", String::new())
            .unwrap()
            .at_frame_time(dt);
        runtime.reset(&bc).unwrap();
        let diagonal = problem.mesh.rest_diagonal();
        for (t, x) in trainer.iter().enumerate() {
            runtime.step(&bc, t + 1).unwrap();
            let gap = runtime
                .positions()
                .iter()
                .zip(x)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            assert!(gap <= 1e-5 * diagonal, "{rate} Hz, frame {}: {gap:e}", t + 1);
        }
        finals.push(trainer[24].clone());
    }
    // The frame time is read: the same motion at other rates is elsewhere after 25 frames.
    assert!(finals.windows(2).all(|w| w[0] != w[1]));
}

#[test]
fn a_zero_frame_time_column_steps_exactly_as_the_untimed_model() {
    let tiny = Artifact::read(&tiny_path()).unwrap();
    let (a, b) = (
        LoadedModel::new(tiny.clone()).unwrap(),
        LoadedModel::new(timed(&tiny, 0.0)).unwrap(),
    );
    let problem = scene_at(&tiny, tiny.dt);
    let encoding = carried_encoding(&tiny, &problem).unwrap();
    let bc = problem.sequence(&SpeedPlan::constant(0.8), 100, 5);
    let run = |m: &LoadedModel| {
        let mut out = Vec::new();
        roll(m, &problem, &encoding, &bc, 100, |_, z, _, _| {
            out.push(z.to_vec());
            true
        })
        .unwrap();
        out
    };
    assert_eq!(run(&a), run(&b));
}

#[test]
fn eval_at_rates_measures_a_timed_model_everywhere_and_a_fixed_one_at_its_own_rate() {
    let dir = tempfile::tempdir().unwrap();
    let tiny = Artifact::read(&tiny_path()).unwrap();
    let (fixed, flexible) = (dir.path().join("tiny.mochi"), dir.path().join("tiny-rates.mochi"));
    tiny.write(&fixed).unwrap();
    timed(&tiny, 0.0).write(&flexible).unwrap();
    let options = RatesOptions {
        rates: vec![30.0, 60.0],
        seconds: 1.0,
        stability_frames: 60,
        sequences: 1,
        out_dir: dir.path().join("eval"),
    };
    let report = evaluate_rates(&[fixed, flexible], &options, &Quiet).unwrap();
    assert_eq!(report.models.len(), 2);
    let [(r30, at30), (r60, at60)] = &report.rows[..] else {
        panic!("two rates");
    };
    assert_eq!((*r30, *r60), (30.0, 60.0));
    let error = |c: &RateCell| c.mean_of(|m| m.mean_error);
    // At its own rate the fixed model is measured, and the timed copy (its time column zero)
    // gives the same numbers; at 60 Hz only the timed one steps.
    assert!(matches!(at30[0], RateCell::Measured(_)) && error(&at30[0]).is_finite());
    assert_eq!(error(&at30[0]), error(&at30[1]));
    assert!(matches!(&at60[0], RateCell::Cannot(why) if why.contains("needs retraining")));
    // (Its time column is zero: it steps 60 Hz frames as 30 Hz ones and drifts, as measured.)
    match &at60[1] {
        RateCell::Measured(m) => assert!(m.len() == 1 && m[0].mean_error.is_finite() && m[0].stable_frames > 0),
        RateCell::Cannot(why) => panic!("the timed model did not step at 60 Hz: {why}"),
    }
    let page = std::fs::read_to_string(dir.path().join("eval/rates.md")).unwrap();
    assert!(page.contains("| 60 |") && page.contains("needs retraining"), "{page}");
    assert!(dir.path().join("eval/rates.png").is_file());
    // A model of another body is refused naming it.
    let other = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/artifacts/strands.mochi");
    let err = evaluate_rates(&[tiny_path(), other], &options, &Quiet)
        .unwrap_err()
        .to_string();
    assert!(err.contains("strands.mochi") && err.contains("another body"), "{err}");
}

#[test]
fn a_scene_over_frame_rates_trains_a_timed_model_that_steps_at_every_rate() {
    let dir = tempfile::tempdir().unwrap();
    // The tiny training scene over 30-60 frames per second, one latent size and decoder.
    let tiny = include_str!("../sim/tests/fixtures/tiny-train.toml")
        .replace("[dataset]\n", "[dataset]\nframe_rates = [30.0, 60.0]\n")
        .replace("sizes = [2, 4, 8]", "sizes = [4]")
        + "\n[latent.selection]\ndecoders = [\"mlp\"]\n";
    let path = dir.path().join("tiny-rates.toml");
    std::fs::write(&path, &tiny).unwrap();
    let recipe = Recipe::load(path.to_str().unwrap()).unwrap();
    let options = TrainOptions {
        out_dir: dir.path().join("out"),
        resume: false,
        latent: None,
        frame_memory: mochi_trainer::FRAME_MEMORY,
    };
    let outcome = train_scene(&recipe, &options, &Quiet).unwrap();
    for model in [&outcome.model, &outcome.baseline] {
        assert!(model.timed(), "{:?}", model.method);
        assert!((model.dt_range[0] - 1.0 / 60.0).abs() < 1e-12 && (model.dt_range[1] - 1.0 / 30.0).abs() < 1e-12);
    }
    // The training sequences were simulated at their own frame times.
    let rates: Vec<f64> = std::fs::read_dir(dir.path().join("out/dataset"))
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("train-")))
        .map(|p| (1.0 / mochi_sim::trajectory::Trajectory::read_npz(&p).unwrap().dt).round())
        .collect();
    assert!(rates.contains(&30.0) && rates.contains(&60.0), "{rates:?}");
    let model = dir.path().join("out/tiny.mochi");
    let eval = RatesOptions {
        rates: vec![30.0, 45.0, 60.0],
        seconds: 1.0,
        stability_frames: 120,
        sequences: 1,
        out_dir: dir.path().join("eval"),
    };
    let report = evaluate_rates(&[model], &eval, &Quiet).unwrap();
    assert_eq!(report.models.len(), 2, "the model and its supervised twin");
    for (rate, cells) in &report.rows {
        for cell in cells {
            match cell {
                RateCell::Measured(m) => assert!(m[0].mean_error.is_finite(), "{rate} Hz"),
                RateCell::Cannot(why) => panic!("{rate} Hz: {why}"),
            }
        }
    }
}
