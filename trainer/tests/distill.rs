//! `mochi distill` on the committed tiny model: the distilled model keeps the latent
//! trajectory, decodes close to the original along a motion it was not fitted on, and
//! loads in the runtime; a distilled narrower integrator rolls that motion close to the
//! original.

use std::path::Path;

use mochi_runtime::OwnedModel;
use mochi_sim::dataset::SpeedPlan;
use mochi_trainer::eval::rollout::{rebuild_problem, roll, LoadedModel};
use mochi_trainer::learn::distill::DistillShape;
use mochi_trainer::pipeline::distill::{distill_artifact, DistillOptions, DistillOutcome};
use mochi_trainer::Artifact;

fn distill(original: &Artifact, epochs: usize) -> DistillOutcome {
    let options = DistillOptions {
        shape: DistillShape {
            modes: 6,
            hidden: 16,
            blocks: 1,
        },
        epochs,
        ..DistillOptions::default()
    };
    distill_artifact(original, &options).unwrap()
}

/// Latents and world positions of `artifact`'s rollout over 60 frames of a motion at speed
/// level 0.8 with a seed none of the training sequences has.
fn rollout(artifact: &Artifact) -> Vec<(Vec<f32>, Vec<f64>)> {
    let (problem, encoding) = rebuild_problem(artifact).unwrap();
    let bc = problem.sequence(&SpeedPlan::constant(0.8), 60, 12345);
    let model = LoadedModel::new(artifact.clone()).unwrap();
    let mut frames = Vec::new();
    roll(&model, &problem, &encoding, &bc, 60, |_, z, _, x| {
        frames.push((z.to_vec(), x.to_vec()));
        true
    })
    .unwrap();
    frames
}

/// The mean vertex distance between two rollouts over the diagonal, checking that their
/// latents are the same.
fn mean_distance(a: &[(Vec<f32>, Vec<f64>)], b: &[(Vec<f32>, Vec<f64>)], dim: usize, diagonal: f64) -> f64 {
    let (mut sum, mut count) = (0.0, 0usize);
    for ((za, xa), (zb, xb)) in a.iter().zip(b) {
        assert_eq!(za, zb, "the integrator and its latents are unchanged");
        for (pa, pb) in xa.chunks_exact(dim).zip(xb.chunks_exact(dim)) {
            sum += pa.iter().zip(pb).map(|(p, q)| (p - q).powi(2)).sum::<f64>().sqrt() / diagonal;
            count += 1;
        }
    }
    sum / count as f64
}

#[test]
fn a_distilled_model_keeps_the_latents_and_follows_the_original_decoder() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/artifacts/tiny.mochi");
    let original = Artifact::read(&path).unwrap();
    let outcome = distill(&original, 200);
    let distilled = &outcome.artifact;
    assert!(distilled.decoder_basis);
    assert_eq!(distilled.integrator, original.integrator);
    assert!(outcome.basis_error <= outcome.fit_error + 1e-12);
    assert!(outcome.fit_error < 5e-3, "fit {}", outcome.fit_error);
    let losses = &outcome.distilled.losses;
    assert!(*losses.last().unwrap() < 0.1 * losses[0], "{losses:?}");

    let dim = original.dim as usize;
    let reference = rollout(&original);
    assert_eq!(reference.len(), 60);
    let trained = mean_distance(&reference, &rollout(distilled), dim, original.diagonal);
    let untrained = mean_distance(
        &reference,
        &rollout(&distill(&original, 0).artifact),
        dim,
        original.diagonal,
    );
    assert!(trained < 1e-2, "mean vertex distance {trained} of the diagonal");
    assert!(trained < 0.5 * untrained, "trained {trained}, untrained {untrained}");

    // The runtime reads it.
    let bytes = distilled.to_bytes().unwrap();
    let mut storage = OwnedModel::default();
    storage.load(&bytes).unwrap();
}

/// The committed four-strand model (strands encoded by their bends) distilled with its
/// strands as positions: the artifact carries the positions encoding (no chains, the PCA,
/// encoder and envelope in it), keeps the latents, decodes close to the original along an
/// unseen motion, and loads in the runtime without a strand walk.
#[test]
fn strands_distilled_as_positions_follow_the_bends() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/artifacts/strands.mochi");
    let original = Artifact::read(&path).unwrap();
    assert!(!original.encoding.chains.is_empty());
    let options = DistillOptions {
        shape: DistillShape {
            modes: 8,
            hidden: 32,
            blocks: 1,
        },
        epochs: 6000,
        strand_positions: true,
        ..DistillOptions::default()
    };
    let outcome = distill_artifact(&original, &options).unwrap();
    let distilled = &outcome.artifact;
    assert!(distilled.encoding.chains.is_empty());
    assert_eq!(distilled.encoding.free_vertices, original.encoding.free_vertices);
    assert_eq!(distilled.encoded_len(), 3 * original.encoding.free_vertices.len());
    assert!(distilled.summary.max_radius > 0.0);
    let encoder_error = outcome.encoder_error.expect("the encoding changed");
    let latent_spread = original
        .latent_min
        .iter()
        .zip(&original.latent_max)
        .map(|(a, b)| b - a)
        .fold(0.0f32, f32::max) as f64;
    // Measured: the fit 3.3e-3 of the diagonal, the encoder 1.5e-3 of the widest latent range.
    assert!(outcome.fit_error < 6e-3, "fit {}", outcome.fit_error);
    assert!(
        encoder_error < 1e-2 * latent_spread,
        "encoder {encoder_error} of {latent_spread}"
    );
    // The file round-trips, so every check of the reader holds (PCA and encoder lengths).
    let bytes = distilled.to_bytes().unwrap();
    assert_eq!(
        &Artifact::from_bytes(&bytes, Path::new("strands-positions.mochi")).unwrap(),
        distilled
    );

    let dim = original.dim as usize;
    let distance = mean_distance(&rollout(&original), &rollout(distilled), dim, original.diagonal);
    // Measured: 2.8e-3 of the diagonal.
    assert!(distance < 6e-3, "mean vertex distance {distance} of the diagonal");

    let mut storage = OwnedModel::default();
    let model = storage.load(&bytes).unwrap();
    assert!(!model.model().bends());
}

/// The mean vertex distance between two rollouts over the diagonal (latents free to differ).
fn mean_position_distance(a: &[(Vec<f32>, Vec<f64>)], b: &[(Vec<f32>, Vec<f64>)], dim: usize, diagonal: f64) -> f64 {
    let (mut sum, mut count) = (0.0, 0usize);
    for ((_, xa), (_, xb)) in a.iter().zip(b) {
        for (pa, pb) in xa.chunks_exact(dim).zip(xb.chunks_exact(dim)) {
            sum += pa.iter().zip(pb).map(|(p, q)| (p - q).powi(2)).sum::<f64>().sqrt() / diagonal;
            count += 1;
        }
    }
    sum / count.max(1) as f64
}

/// A narrower integrator distilled from the committed tiny model's (width 32 -> 16) rolls an
/// unseen motion close to the original, far closer than before its fit, with fewer
/// multiply-adds; the rounds of its own rollouts lower the fit's loss; the runtime reads it.
#[test]
fn a_distilled_integrator_follows_the_original_on_an_unseen_motion() {
    use mochi_trainer::learn::distill_integrator::IntegratorDistillShape;
    use mochi_trainer::pipeline::distill::distill_artifact_integrator;

    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/artifacts/tiny.mochi");
    let original = Artifact::read(&path).unwrap();
    let shape = |rounds| IntegratorDistillShape {
        hidden: 16,
        blocks: 1,
        rounds,
    };
    // Rollouts four times as long as the scene's training sequences: more states to fit.
    let options = |epochs| DistillOptions {
        epochs,
        frames: Some(160),
        ..DistillOptions::default()
    };
    let (student, distilled) = distill_artifact_integrator(&original, shape(3), &options(300)).unwrap();
    assert_eq!(distilled.losses.len(), 4);
    assert!(distilled.losses[3] < distilled.losses[0], "{:?}", distilled.losses);
    let macs = |a: &Artifact| a.integrator.iter().map(|l| l.rows * l.cols).sum::<usize>();
    assert!(
        macs(&student) < macs(&original) / 2,
        "{} vs {}",
        macs(&student),
        macs(&original)
    );
    assert_eq!(student.decoder, original.decoder);

    let dim = original.dim as usize;
    let reference = rollout(&original);
    let fitted = mean_position_distance(&reference, &rollout(&student), dim, original.diagonal);
    let (untrained, _) = distill_artifact_integrator(&original, shape(0), &options(0)).unwrap();
    let before = mean_position_distance(&reference, &rollout(&untrained), dim, original.diagonal);
    // Measured: 2.8% of the diagonal after the fit, 23% before it.
    assert!(fitted < 4e-2, "mean vertex distance {fitted} of the diagonal");
    assert!(fitted < 0.25 * before, "fitted {fitted}, before the fit {before}");

    let bytes = student.to_bytes().unwrap();
    let mut storage = OwnedModel::default();
    storage.load(&bytes).unwrap();
}

/// Rollouts of no frames give nothing to fit: an error that says so, not a panic.
#[test]
fn an_integrator_with_nothing_to_fit_is_refused() {
    use mochi_trainer::learn::distill_integrator::IntegratorDistillShape;
    use mochi_trainer::pipeline::distill::distill_artifact_integrator;

    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/artifacts/tiny.mochi");
    let original = Artifact::read(&path).unwrap();
    let shape = IntegratorDistillShape {
        hidden: 8,
        blocks: 1,
        rounds: 1,
    };
    let options = DistillOptions {
        frames: Some(0),
        ..DistillOptions::default()
    };
    let error = distill_artifact_integrator(&original, shape, &options).unwrap_err();
    assert!(error.to_string().contains("visited no input"), "{error}");
}

/// `mochi train` on the four-strand scene with `strand_positions`: the candidate's decoder is
/// also distilled into positions, measured like every candidate and written beside them; the
/// model, if the rule keeps that candidate, carries the positions encoding.
#[test]
fn training_with_strand_positions_distils_candidates_into_positions() {
    use mochi_trainer::{train_scene, Quiet, Recipe, TrainOptions};
    let dir = tempfile::tempdir().unwrap();
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/artifacts/strands.toml");
    let extra = "\n[latent.selection]\ndecoders = [\"mlp\"]\n\n[latent.selection.distill]\nmodes = [8]\nepochs = 1500\nstrand_positions = true\n";
    let path = dir.path().join("strands.toml");
    std::fs::write(&path, std::fs::read_to_string(&scene).unwrap() + extra).unwrap();
    let recipe = Recipe::load(path.to_str().unwrap()).unwrap();
    let options = TrainOptions {
        out_dir: dir.path().join("out"),
        resume: false,
        latent: None,
        frame_memory: mochi_trainer::FRAME_MEMORY,
    };
    let outcome = train_scene(&recipe, &options, &Quiet).unwrap();
    let rows = &outcome.model.summary.candidates;
    let table = mochi_trainer::report::candidates_table(rows);
    let distilled = rows.iter().find(|r| r.decoder == "distilled").expect(&table);
    assert_eq!(distilled.modes, 8, "{table}");
    assert!(
        distilled.validation_frames > 0 && distilled.storages.len() == 3,
        "{table}"
    );
    assert!(distilled.reconstruction.is_finite(), "{table}");
    let written = Artifact::read(&dir.path().join("out/candidates/strands-mlp-distilled-m8.mochi")).unwrap();
    assert!(written.encoding.chains.is_empty());
    assert_eq!(written.encoded_len(), 3 * written.encoding.free_vertices.len());
    let kept = rows.iter().find(|r| r.kept).unwrap();
    assert_eq!(
        outcome.model.encoding.chains.is_empty(),
        kept.decoder == "distilled",
        "{table}"
    );
    let bytes = outcome.model.to_bytes().unwrap();
    OwnedModel::default().load(&bytes).unwrap();
}
