use std::path::Path;

use rand::SeedableRng;

use super::*;
use crate::learn::network::{forward_exported, DenseLayer};
use crate::learn::recipe::{Recipe, RodEncoding};
use crate::progress::Quiet;
use mochi_sim::Scene;

/// A `nx` x 2 cell bar of `2 nx * 2` triangles, 1 by 0.1, as Triangle `.node` and `.ele` text.
fn bar_mesh(nx: usize) -> (String, String) {
    let ny = 2;
    let mut node = format!("{} 2 0 0\n", (nx + 1) * (ny + 1));
    for j in 0..=ny {
        for i in 0..=nx {
            let k = j * (nx + 1) + i;
            node += &format!("{} {} {}\n", k + 1, i as f64 / nx as f64, 0.05 * j as f64);
        }
    }
    let mut ele = format!("{} 3 0\n", 2 * nx * ny);
    let mut count = 0;
    for j in 0..ny {
        for i in 0..nx {
            let a = j * (nx + 1) + i + 1;
            let (b, c, d) = (a + 1, a + nx + 2, a + nx + 1);
            for tri in [[a, b, c], [a, c, d]] {
                count += 1;
                ele += &format!("{count} {} {} {}\n", tri[0], tri[1], tri[2]);
            }
        }
    }
    (node, ele)
}

/// A small bar compressed to 0.8 of its length between clamped ends, as `bistable` is.
const BAR: &str = r#"
name = "tiny-bistable"
[mesh]
type = "file"
path = "bar.node"
[material]
model = "stable-neo-hookean"
youngs = 1e3
poisson = 0.45
density = 10.0
[[handles]]
name = "left"
select = { side = { axis = 0, end = "min" } }
reference_scale = [0.8, 1.0, 1.0]
[[handles]]
name = "right"
select = { side = { axis = 0, end = "max" } }
reference_scale = [0.8, 1.0, 1.0]
"#;

pub(crate) fn tiny_bar(dir: &Path) -> BuiltScene {
    let (node, ele) = bar_mesh(12);
    std::fs::write(dir.join("bar.node"), node).unwrap();
    std::fs::write(dir.join("bar.ele"), ele).unwrap();
    let path = dir.join("bar.toml");
    std::fs::write(&path, BAR).unwrap();
    Scene::load(&path).unwrap().build().unwrap()
}

pub(crate) fn small_settings() -> DataFreeSettings {
    DataFreeSettings {
        latent: 3,
        hidden: 32,
        blocks: 1,
        batch: 16,
        iterations: 150,
        learning_rate: 3e-3,
        ..DataFreeSettings::default()
    }
}

#[test]
fn the_loss_falls_and_the_export_reproduces_the_candle_decoder() {
    let paper = DataFreeSettings {
        blocks: 3,
        style: MlpStyle::PAPER,
        ..small_settings()
    };
    for settings in [small_settings(), paper] {
        loss_falls_and_export_reproduces(settings);
    }
}

fn loss_falls_and_export_reproduces(settings: DataFreeSettings) {
    let dir = tempfile::tempdir().unwrap();
    let problem = tiny_bar(dir.path());
    let encoding = Encoding::new(&problem, RodEncoding::Positions).unwrap();
    let objective = DataFreeObjective::new(&problem, &encoding, settings.sigma).unwrap();
    let model = objective.initial_model(&settings).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let losses = optimise(&objective, &model, &settings, &mut rng, &Quiet).unwrap();
    assert_eq!(losses.len(), settings.iterations);
    let total = |terms: &[(f64, f64)]| terms.iter().map(|(e, r)| e + settings.lambda * r).sum::<f64>() / 20.0;
    let (first, last) = (total(&losses[..20]), total(&losses[losses.len() - 20..]));
    assert!(last < 0.3 * first, "mean loss fell only from {first:.4e} to {last:.4e}");

    // The exported decoder, start state folded into its output bias, is the candle decoder.
    let exported = model.export().unwrap();
    assert_eq!(exported.spec().input, settings.latent);
    assert_eq!(
        (exported.spec().blocks, exported.style()),
        (settings.blocks, settings.style)
    );
    assert_eq!(exported.spec().output, encoding.encoded_len());
    let z = normal_latents(6, settings.latent, &mut rng).unwrap();
    let z = Tensor::cat(
        &[
            Tensor::zeros((1, settings.latent), DType::F32, &Device::Cpu).unwrap(),
            z,
        ],
        0,
    )
    .unwrap();
    let candle = tensor_to_rows(&model.forward(&z).unwrap()).unwrap();
    for (row, expected) in tensor_to_rows(&z).unwrap().iter().zip(&candle) {
        let plain = forward_exported(&exported, row).unwrap();
        let diff = plain
            .iter()
            .zip(expected)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        assert!(diff < 1e-5, "exported decoder differs from candle by {diff}");
    }
    // At z = 0 the trained decoder stays near the start state, but it is not the bare MLP.
    let bare = tensor_to_rows(&model.mlp.forward(&z).unwrap()).unwrap();
    let offset_size = objective.rest.iter().map(|v| v.abs()).fold(0.0, f64::max);
    assert!(offset_size > 0.1);
    assert!((candle[0][0] - bare[0][0] - objective.rest[0] as f32).abs() < 1e-5);
}

/// Replaces weight `index` of layer `layer` of a frozen network by itself plus `delta`.
fn perturbed(mlp: &ExportedMlp, layer: usize, index: usize, delta: f64) -> ExportedMlp {
    let mut layers: Vec<DenseLayer> = mlp.layers().into_iter().cloned().collect();
    let w = &mut layers[layer].weights[index];
    *w = (*w as f64 + delta) as f32;
    ExportedMlp::from_layers(layers).unwrap()
}

#[test]
fn the_surrogate_gradient_is_the_energy_terms_derivative() {
    let dir = tempfile::tempdir().unwrap();
    let problem = tiny_bar(dir.path());
    let encoding = Encoding::new(&problem, RodEncoding::Positions).unwrap();
    let settings = small_settings();
    let objective = DataFreeObjective::new(&problem, &encoding, settings.sigma).unwrap();
    let model = objective.initial_model(&settings).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let z = normal_latents(8, settings.latent, &mut rng).unwrap();
    let terms = objective.batch(&model, &z).unwrap();
    let grads = terms.energy_objective.backward().unwrap();
    let exported = model.export().unwrap();
    let zs: Vec<Vec<f64>> = tensor_to_rows(&z)
        .unwrap()
        .iter()
        .map(|r| r.iter().map(|&v| v as f64).collect())
        .collect();
    let n = encoding.state_len();
    let energy_term = |mlp: &ExportedMlp| -> f64 {
        let (mut x, mut grad, mut dq) = (vec![0.0; n], vec![0.0; n], vec![0.0; encoding.encoded_len()]);
        let total: f64 = zs
            .iter()
            .map(|z| {
                let q = forward_exported(mlp, z).unwrap();
                objective.energy_of(&q, &mut x, &mut grad, &mut dq).unwrap()
            })
            .sum();
        total / zs.len() as f64
    };
    assert!((energy_term(&exported) - terms.energy).abs() < 1e-3 * terms.energy.abs().max(1e-6));
    let params = model.parameters();
    let last_layer = exported.layers().len() - 1;
    for (name, layer) in [("decoder.input.weight", 0), ("decoder.output.weight", last_layer)] {
        let var = &params.iter().find(|(n, _)| n == name).unwrap().1;
        let g = grads
            .get(var.as_tensor())
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1::<f32>()
            .unwrap();
        let index = g.len() / 3;
        let h = 1e-3;
        let fd = (energy_term(&perturbed(&exported, layer, index, h))
            - energy_term(&perturbed(&exported, layer, index, -h)))
            / (2.0 * h);
        let analytic = g[index] as f64;
        assert!(
            fd.abs() > 1e-6,
            "{name}[{index}]: the check needs a gradient, got {fd:e}"
        );
        assert!(
            (fd - analytic).abs() <= 3e-2 * fd.abs(),
            "{name}[{index}]: surrogate {analytic:.6e}, finite difference {fd:.6e}"
        );
    }
}

#[test]
fn invalid_settings_are_errors_that_name_the_setting() {
    let dir = tempfile::tempdir().unwrap();
    let problem = tiny_bar(dir.path());
    let encoding = Encoding::new(&problem, RodEncoding::Positions).unwrap();
    let base = small_settings();
    let cases = [
        ("latent", DataFreeSettings { latent: 0, ..base }),
        ("batch", DataFreeSettings { batch: 1, ..base }),
        ("lambda", DataFreeSettings { lambda: -1.0, ..base }),
        ("sigma", DataFreeSettings { sigma: 0.0, ..base }),
        ("sigma", DataFreeSettings { sigma: -0.1, ..base }),
        (
            "learning_rate",
            DataFreeSettings {
                learning_rate: f64::NAN,
                ..base
            },
        ),
        ("iterations", DataFreeSettings { iterations: 0, ..base }),
        ("hidden", DataFreeSettings { hidden: 0, ..base }),
    ];
    for (setting, settings) in cases {
        let err = train_data_free(&problem, &encoding, &settings, &Quiet)
            .unwrap_err()
            .to_string();
        assert!(err.contains(&format!("`{setting}`")), "{setting}: {err}");
    }
    assert!(base.validate().is_ok() && DataFreeSettings::default().validate().is_ok());
}

/// The bistable scene with the default settings (not run by default; about 20 s): prints the timing and the loss
/// curve, and checks that decoded samples buckle both ways.
#[test]
#[ignore]
fn bistable_learns_both_buckling_branches() {
    let recipe = Recipe::load("bistable").unwrap();
    let problem = recipe.build().unwrap();
    let encoding = Encoding::new(&problem, RodEncoding::Positions).unwrap();
    let settings = DataFreeSettings::default();
    let outcome = train_data_free(&problem, &encoding, &settings, &Quiet).unwrap();
    let n = outcome.losses.len();
    let mean = |t: &[(f64, f64)]| {
        let k = t.len() as f64;
        (
            t.iter().map(|l| l.0).sum::<f64>() / k,
            t.iter().map(|l| l.1).sum::<f64>() / k,
        )
    };
    println!("{} iterations, {:.2} ms each", n, 1e3 * outcome.seconds / n as f64);
    for (from, to) in [(0, 20), (n / 10, n / 10 + 20), (n / 2, n / 2 + 20), (n - 20, n)] {
        let (e, r) = mean(&outcome.losses[from..to]);
        println!(
            "iterations {from}..{to}: energy {e:.4e}, repulsion {r:.4e}, total {:.4e}",
            e + settings.lambda * r
        );
    }
    // The energy term of the buckled static equilibrium, for scale.
    let mut solved = recipe.build().unwrap();
    let objective = DataFreeObjective::new(&problem, &encoding, settings.sigma).unwrap();
    let mut targets = Vec::new();
    problem
        .handles
        .iter()
        .for_each(|h| h.place(&Pose::identity(), 2, &mut targets));
    solved.simulator.solve_static(&targets).unwrap();
    let q = encoding.encode_state(solved.simulator.positions()).unwrap();
    let n = encoding.state_len();
    let (mut x, mut g, mut dq) = (vec![0.0; n], vec![0.0; n], vec![0.0; q.len()]);
    println!(
        "static equilibrium: energy term {:.4e}",
        objective.energy_of(&q, &mut x, &mut g, &mut dq).unwrap()
    );
    // Mid-bar vertical displacement (the mean y of the free vertices near x = 0) of decoded samples.
    let dim = encoding.dim();
    let mid: Vec<usize> = (encoding.free_vertices().iter().enumerate())
        .filter(|(_, &v)| problem.mesh.rest[v * dim].abs() < 0.03)
        .map(|(j, _)| j)
        .collect();
    let mut rng = ChaCha8Rng::seed_from_u64(123);
    let z = tensor_to_rows(&normal_latents(200, settings.latent, &mut rng).unwrap()).unwrap();
    let heights: Vec<f64> = z
        .iter()
        .map(|z| {
            let q = forward_exported(&outcome.decoder, z).unwrap();
            mid.iter().map(|&j| q[j * dim + 1] as f64).sum::<f64>() / mid.len() as f64
        })
        .collect();
    let (up, down) = (
        heights.iter().filter(|&&h| h > 0.02).count(),
        heights.iter().filter(|&&h| h < -0.02).count(),
    );
    let (lo, hi) = heights
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &h| (a.min(h), b.max(h)));
    println!("mid-bar height of 200 samples: min {lo:.3}, max {hi:.3}; {up} above +0.02, {down} below -0.02");
    let mut sorted = heights.clone();
    sorted.sort_by(f64::total_cmp);
    println!(
        "deciles {:?}",
        (0..=10)
            .map(|k| (sorted[(k * 199) / 10] * 1000.0).round() / 1000.0)
            .collect::<Vec<_>>()
    );
    assert!(up > 0 && down > 0, "only one buckling branch appears");
}
