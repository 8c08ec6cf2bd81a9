//! `mochi distill` on the committed tiny model: the distilled model keeps the latent
//! trajectory, decodes close to the original along a motion it was not fitted on, and
//! loads in the runtime.

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
