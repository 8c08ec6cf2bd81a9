//! The Lipschitz loss's gradient against a finite difference of the loss in one weight, and
//! its independence of the thread count; the cubature of a decoder's subspace against the
//! full energy on held-out samples.

use mochi_sim::energy::StencilEnergy;
use nalgebra::DMatrix;
use rand::SeedableRng;

use super::cubature::fit_subspace_cubature;
use super::loss::{
    latent_spread, lipschitz_estimate, lipschitz_loss, median_condition, LatentSample, LipschitzBatch, LipschitzTerm,
};
use crate::learn::network::test_support::randomise;
use crate::learn::network::{forward_exported, DenseLayer, ExportedMlp};
use crate::learn::samples::fixtures::{tiny_beam, TinyBeam};

/// `mlp` with weight `index` of layer `layer` (evaluation order) moved by `delta`.
fn nudged(mlp: &ExportedMlp, layer: usize, index: usize, delta: f32) -> ExportedMlp {
    let mut layers: Vec<DenseLayer> = mlp.layers().into_iter().cloned().collect();
    layers[layer].weights[index] += delta;
    ExportedMlp::from_layers(layers).unwrap()
}

/// The tiny beam with its decoder's residual block made visibly nonlinear.
fn nonlinear_beam() -> TinyBeam {
    let beam = tiny_beam();
    let params = beam.ae.parameters();
    let decoder_params: Vec<_> = params
        .iter()
        .filter(|(n, _)| n.starts_with("decoder.block"))
        .cloned()
        .collect();
    randomise(&decoder_params, 0.3, &mut rand_chacha::ChaCha8Rng::seed_from_u64(5));
    beam
}

/// Latents of four frames of the beam's first sequence under `encoder`, spread apart.
fn encoded_samples(beam: &TinyBeam, encoder: &ExportedMlp) -> Vec<LatentSample> {
    let seq = &beam.sequences[0];
    [2, 5, 8, 11]
        .iter()
        .enumerate()
        .map(|(k, &t)| {
            let q: Vec<f32> = seq.encoded[t].iter().map(|&v| v as f32).collect();
            let z = forward_exported(encoder, &q).unwrap();
            LatentSample {
                z: z.iter()
                    .enumerate()
                    .map(|(i, &v)| v as f64 + 0.1 * ((i + k) % 3) as f64)
                    .collect(),
                targets: seq.targets[t].clone(),
            }
        })
        .collect()
}

/// The Lipschitz term of the beam's own potentials.
fn beam_term<'a>(beam: &'a TinyBeam, potentials: &'a [&'a dyn StencilEnergy]) -> LipschitzTerm<'a> {
    LipschitzTerm {
        encoding: &beam.encoding,
        potentials,
        scale: 1e-3,
        diagonal: beam.problem.mesh.rest_diagonal(),
    }
}

/// The loss and surrogate of the beam's trainable decoder (frozen as `frozen`) at `samples`,
/// and the subspace Hessians there.
fn batch_and_hessians(
    term: &LipschitzTerm<'_>,
    beam: &TinyBeam,
    frozen: &ExportedMlp,
    samples: &[LatentSample],
) -> (LipschitzBatch, Vec<DMatrix<f64>>) {
    let batch = term
        .batch(beam.ae.decoder().as_mlp().unwrap(), None, frozen, samples)
        .unwrap();
    (batch, term.hessians(frozen, samples).unwrap())
}

#[test]
fn the_loss_and_its_surrogate_do_not_depend_on_the_thread_count() {
    let beam = nonlinear_beam();
    let exported = beam.ae.export().unwrap();
    let samples = encoded_samples(&beam, &exported.encoder);
    let potentials: Vec<&dyn StencilEnergy> = beam.problem.simulator.potentials().iter().map(|p| p.as_ref()).collect();
    let term = beam_term(&beam, &potentials);
    let on_threads = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| {
            let (batch, hessians) = batch_and_hessians(&term, &beam, exported.decoder.as_mlp().unwrap(), &samples);
            (batch.loss, batch.surrogate.to_scalar::<f32>().unwrap(), hessians)
        })
    };
    let one = on_threads(1);
    assert!(one.0 > 0.0 && one.1 != 0.0);
    for threads in [2, 3] {
        assert_eq!(on_threads(threads), one, "{threads} threads");
    }
}

#[test]
fn lip_times_spread_cubed_and_the_condition_ignore_the_latent_scale() {
    // Stretching the latent by a = 4 (a power of two: the scaled weights and latents are
    // exact), f(z / a) at a z, leaves the decoded states and the solves as they were.
    let a = 4.0;
    let beam = nonlinear_beam();
    let exported = beam.ae.export().unwrap();
    let decoder = exported.decoder.as_mlp().unwrap();
    let samples = encoded_samples(&beam, &exported.encoder);
    let mut layers: Vec<DenseLayer> = decoder.layers().into_iter().cloned().collect();
    layers[0].weights.iter_mut().for_each(|w| *w /= a as f32);
    let stretched = ExportedMlp::from_layers(layers).unwrap();
    let stretched_samples: Vec<LatentSample> = samples
        .iter()
        .map(|s| LatentSample {
            z: s.z.iter().map(|v| a * v).collect(),
            targets: s.targets.clone(),
        })
        .collect();
    let potentials: Vec<&dyn StencilEnergy> = beam.problem.simulator.potentials().iter().map(|p| p.as_ref()).collect();
    let term = beam_term(&beam, &potentials);
    let measures = |decoder: &ExportedMlp, samples: &[LatentSample]| {
        let hessians = term.hessians(decoder, samples).unwrap();
        (
            lipschitz_estimate(&hessians, samples),
            latent_spread(samples),
            median_condition(&hessians),
        )
    };
    let (lip, spread, condition) = measures(decoder, &samples);
    let (lip_a, spread_a, condition_a) = measures(&stretched, &stretched_samples);
    let close = |x: f64, y: f64| (x - y).abs() <= 1e-9 * x.abs().max(y.abs());
    assert!(lip > 0.0 && spread > 0.0 && condition >= 1.0);
    assert!(close(spread_a, a * spread), "spread {spread} -> {spread_a}");
    assert!(close(lip_a, lip / a.powi(3)), "Lip {lip} -> {lip_a}");
    assert!(close(lip_a * spread_a.powi(3), lip * spread.powi(3)));
    assert!(close(condition_a, condition), "condition {condition} -> {condition_a}");
    // The median of max |l| / min |l|: 4, 1 and 3 (an indefinite matrix counts by magnitudes).
    let conditions =
        [[1.0, 4.0], [2.0, 2.0], [-3.0, 1.0]].map(|d| DMatrix::from_diagonal(&nalgebra::DVector::from_row_slice(&d)));
    assert_eq!(median_condition(&conditions), 3.0);
}

#[test]
fn the_loss_gradient_matches_a_finite_difference_in_one_weight() {
    let beam = nonlinear_beam();
    let exported = beam.ae.export().unwrap();
    let params = beam.ae.parameters();
    let samples = encoded_samples(&beam, &exported.encoder);
    let potentials: Vec<&dyn StencilEnergy> = beam.problem.simulator.potentials().iter().map(|p| p.as_ref()).collect();
    let term = beam_term(&beam, &potentials);
    let (batch, hessians) = batch_and_hessians(&term, &beam, exported.decoder.as_mlp().unwrap(), &samples);
    assert_eq!(batch.loss, lipschitz_loss(&hessians, &samples));
    assert!(batch.loss > 0.0);
    let grads = batch.surrogate.backward().unwrap();
    // One weight of the first block's inner layer and one of the output layer.
    for (name, layer, index) in [("decoder.block0.inner.weight", 1, 7), ("decoder.output.weight", 3, 40)] {
        let var = &params.iter().find(|(n, _)| n == name).unwrap().1;
        let analytic = grads
            .get(var.as_tensor())
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap()[index] as f64;
        let delta = 1e-3f32;
        let loss_at = |d: f32| {
            let mlp = nudged(exported.decoder.as_mlp().unwrap(), layer, index, d);
            lipschitz_loss(&term.hessians(&mlp, &samples).unwrap(), &samples)
        };
        let fd = (loss_at(delta) - loss_at(-delta)) / (2.0 * delta as f64);
        assert!(
            (analytic - fd).abs() <= 2e-2 * fd.abs().max(1e-3 * batch.loss),
            "{name}[{index}]: surrogate gradient {analytic} vs finite difference {fd}"
        );
    }
    // Eq. 7 bounds every pair's quotient, so it is at least the root of the mean of squares.
    assert!(lipschitz_estimate(&hessians, &samples) >= batch.loss.sqrt());
}

#[test]
fn the_cubature_reproduces_energy_and_reduced_force_on_held_out_samples() {
    use crate::methods::reduced::objective::{ObjectiveBuffers, ReducedObjective};
    use crate::methods::reduced::optimize::Objective;
    use crate::methods::reduced::subspace::DecoderSubspace;
    use mochi_sim::cubature::{CubatureEnergy, CubatureSettings};

    let beam = nonlinear_beam();
    let exported = beam.ae.export().unwrap();
    let seq = &beam.sequences[0];
    let sample = |t: usize, shift: f64| {
        let q: Vec<f32> = seq.encoded[t].iter().map(|&v| v as f32).collect();
        let z = forward_exported(&exported.encoder, &q).unwrap();
        LatentSample {
            z: z.iter()
                .enumerate()
                .map(|(i, &v)| v as f64 + shift * (i as f64 - 1.0))
                .collect(),
            targets: seq.targets[t].clone(),
        }
    };
    let training: Vec<LatentSample> = (0..12).flat_map(|t| [sample(t, 0.0), sample(t, 0.05)]).collect();
    let held_out: Vec<LatentSample> = (0..12).map(|t| sample(t, 0.025)).collect();
    let elastic = beam.problem.simulator.potentials()[0].as_ref();
    let settings = CubatureSettings {
        max_elements: 24,
        tolerance: 1e-4,
        ..CubatureSettings::default()
    };
    let (cubature, fit) = fit_subspace_cubature(
        exported.decoder.as_mlp().unwrap(),
        &beam.encoding,
        elastic,
        &training,
        &settings,
    )
    .unwrap();
    assert!(
        cubature.elements.len() < elastic.len(),
        "{} of {}",
        cubature.elements.len(),
        elastic.len()
    );
    assert!(fit.relative_residual < 1e-2, "{fit:?}");
    let approx = CubatureEnergy::new(elastic, cubature).unwrap();
    let full: [&dyn StencilEnergy; 1] = [elastic];
    let cub: [&dyn StencilEnergy; 1] = [&approx];
    let mut subspace =
        DecoderSubspace::new(exported.decoder.as_mlp().unwrap(), &beam.encoding, &held_out[0].targets).unwrap();
    let r = subspace.latent_len();
    let mut buffers = ObjectiveBuffers::new(subspace.state_len(), r);
    let (mut worst_energy, mut worst_force) = (0.0f64, 0.0f64);
    for s in &held_out {
        subspace.set_frame(&beam.encoding.frame(&s.targets).unwrap(), &s.targets);
        let mut evaluate = |potentials: &[&dyn StencilEnergy]| {
            let mut objective = ReducedObjective::new(&mut subspace, potentials, None, 1.0, &mut buffers);
            let mut grad = vec![0.0; r];
            let value = objective.gradient(&s.z, &mut grad);
            (value, grad)
        };
        let (e_full, g_full) = evaluate(&full);
        let (e_cub, g_cub) = evaluate(&cub);
        let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
        let diff: Vec<f64> = g_full.iter().zip(&g_cub).map(|(a, b)| a - b).collect();
        worst_energy = worst_energy.max((e_full - e_cub).abs() / e_full.abs());
        worst_force = worst_force.max(norm(&diff) / norm(&g_full));
    }
    assert!(worst_energy < 2e-2, "energy off by {worst_energy:e}");
    assert!(worst_force < 5e-2, "reduced force off by {worst_force:e}");
}

#[test]
fn a_tiny_data_free_lipschitz_optimisation_lowers_the_lipschitz_loss() {
    use super::train::{optimise_data_free, LipschitzSettings};
    use crate::learn::datafree::tests::{small_settings, tiny_bar};
    use crate::learn::datafree::{normal_latents, train_data_free_model, DataFreeObjective};
    use crate::learn::encoding::Encoding;
    use crate::learn::network::tensor_to_rows;
    use crate::learn::recipe::RodEncoding;
    use crate::progress::Quiet;

    let dir = tempfile::tempdir().unwrap();
    let problem = tiny_bar(dir.path());
    let encoding = Encoding::new(&problem, RodEncoding::Positions).unwrap();
    let settings = small_settings();
    let objective = DataFreeObjective::new(&problem, &encoding, settings.sigma).unwrap();
    let (model, vanilla) = train_data_free_model(&objective, &settings, &Quiet).unwrap();
    let elastic: Vec<&dyn StencilEnergy> = vec![problem.simulator.potentials()[0].as_ref()];
    let mass: f64 = problem.simulator.masses().iter().sum();
    let diagonal = problem.mesh.rest_diagonal();
    let term = LipschitzTerm {
        encoding: &encoding,
        potentials: &elastic,
        scale: crate::methods::reduced::stepper::objective_scale(mass, diagonal, problem.scene.dt),
        diagonal,
    };
    let z = normal_latents(24, settings.latent, &mut rand_chacha::ChaCha8Rng::seed_from_u64(9)).unwrap();
    let held_out: Vec<LatentSample> = tensor_to_rows(&z)
        .unwrap()
        .into_iter()
        .map(|row| LatentSample {
            z: row.iter().map(|&v| v as f64).collect(),
            targets: objective.targets().to_vec(),
        })
        .collect();
    let loss_of = |decoder: &ExportedMlp| lipschitz_loss(&term.hessians(decoder, &held_out).unwrap(), &held_out);
    let before = loss_of(&vanilla.decoder);
    let lip = LipschitzSettings {
        weight: 1.0,
        samples: 8,
        floor: 0.0,
        lambda: None,
        local: 0.0,
        resample: 0,
    };
    let (losses, lambda) = optimise_data_free(&objective, &model, &settings, &term, &lip, 60, &Quiet).unwrap();
    assert_eq!(losses.len(), 60);
    assert!(lambda > 0.0);
    let after = loss_of(&model.export().unwrap());
    assert!(
        after < 0.7 * before,
        "Lipschitz loss on held-out samples {before:.3e} -> {after:.3e}"
    );
}

/// A Monte Carlo cubature keeps `size` distinct elements at weight `len / size` (all of them
/// at weight 1 when `size` covers the term), and its subspace Hessians average to the exact
/// ones over draws: the sampled Lipschitz loss differentiates an unbiased estimate.
#[test]
fn sampled_cubature_hessians_average_to_the_exact_ones() {
    use super::cubature::{elastic_terms, sampled_cubature};
    let beam = nonlinear_beam();
    let exported = beam.ae.export().unwrap();
    let decoder = exported.decoder.as_mlp().unwrap();
    let seq = &beam.sequences[0];
    let samples: Vec<LatentSample> = [3, 9]
        .iter()
        .map(|&t| {
            let q: Vec<f32> = seq.encoded[t].iter().map(|&v| v as f32).collect();
            let z = forward_exported(&exported.encoder, &q).unwrap();
            LatentSample {
                z: z.iter().map(|&v| v as f64).collect(),
                targets: seq.targets[t].clone(),
            }
        })
        .collect();
    let all: Vec<&dyn StencilEnergy> = beam.problem.simulator.potentials().iter().map(|p| p.as_ref()).collect();
    let elastic = elastic_terms(&all);
    let hessians = |potentials: &[&dyn StencilEnergy]| {
        let term = LipschitzTerm {
            encoding: &beam.encoding,
            potentials,
            scale: 1e-3,
            diagonal: beam.problem.mesh.rest_diagonal(),
        };
        term.hessians(decoder, &samples).unwrap()
    };
    let exact = hessians(&elastic);

    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let len = elastic[0].len();
    let size = len / 4;
    let whole = sampled_cubature(&elastic, len + 5, &mut rng).unwrap();
    assert_eq!(whole[0].cubature().elements, (0..len).collect::<Vec<_>>());
    assert!(whole[0].cubature().weights.iter().all(|&w| w == 1.0));

    let draws = 400;
    let mut mean = vec![nalgebra::DMatrix::<f64>::zeros(exact[0].nrows(), exact[0].ncols()); samples.len()];
    for _ in 0..draws {
        let drawn = sampled_cubature(&elastic, size, &mut rng).unwrap();
        let rule = drawn[0].cubature();
        assert_eq!(rule.elements.len(), size);
        assert!(rule.elements.windows(2).all(|w| w[0] < w[1]), "distinct, sorted");
        assert!(rule.weights.iter().all(|&w| w == len as f64 / size as f64));
        let potentials: Vec<&dyn StencilEnergy> = drawn.iter().map(|e| e as &dyn StencilEnergy).collect();
        for (m, h) in mean.iter_mut().zip(hessians(&potentials)) {
            *m += h / draws as f64;
        }
    }
    for (m, h) in mean.iter().zip(&exact) {
        let relative = (m - h).norm() / h.norm();
        assert!(
            relative < 0.05,
            "mean of {draws} draws {relative:.3e} from the exact Hessian"
        );
    }
}
