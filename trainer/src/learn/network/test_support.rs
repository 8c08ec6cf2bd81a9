//! Helpers shared by the tests of this module and of `train`.

use candle_core::{Device, Tensor, Var};
use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::tensor::rows_to_tensor;

/// Sets every variable to uniform values in `±scale`, so no layer is left at zero.
pub(crate) fn randomise(params: &[(String, Var)], scale: f32, rng: &mut ChaCha8Rng) {
    for (_, var) in params {
        let shape = var.as_tensor().shape().clone();
        let values: Vec<f32> = (0..shape.elem_count())
            .map(|_| rng.random_range(-scale..scale))
            .collect();
        var.set(&Tensor::from_vec(values, shape, &Device::Cpu).unwrap())
            .unwrap();
    }
}

pub(crate) fn random_rows(count: usize, dim: usize, scale: f32, rng: &mut ChaCha8Rng) -> Vec<Vec<f32>> {
    (0..count)
        .map(|_| (0..dim).map(|_| rng.random_range(-scale..scale)).collect())
        .collect()
}

pub(crate) fn as_tensor(rows: &[Vec<f32>]) -> Tensor {
    let refs: Vec<&[f32]> = rows.iter().map(Vec::as_slice).collect();
    rows_to_tensor(&refs, rows[0].len()).unwrap()
}

/// Largest |a - b| relative to the largest |b| (which must not be zero).
pub(crate) fn max_relative_difference(a: &[Vec<f32>], b: &[Vec<f32>]) -> f32 {
    let scale = b.iter().flatten().fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(scale > 0.0, "comparison against all zeros");
    let diff = a
        .iter()
        .flatten()
        .zip(b.iter().flatten())
        .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
    diff / scale
}

/// Mean and the first `k` principal directions (rows) of `data`, by SVD.
pub(crate) fn pca(data: &[Vec<f32>], k: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
    let (m, n) = (data.len(), data[0].len());
    let x = DMatrix::from_fn(m, n, |i, j| data[i][j] as f64);
    let mean: Vec<f64> = (0..n).map(|j| x.column(j).mean()).collect();
    let centred = DMatrix::from_fn(m, n, |i, j| x[(i, j)] - mean[j]);
    let svd = centred.svd(false, true);
    let v_t = svd.v_t.unwrap();
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&a, &b| svd.singular_values[b].total_cmp(&svd.singular_values[a]));
    let basis = order[..k]
        .iter()
        .map(|&i| v_t.row(i).iter().copied().collect())
        .collect();
    (mean, basis)
}

/// `count` samples of a 2D nonlinear manifold embedded in `dim` dimensions: parameters
/// `(u, v)` uniform in `[-1, 1]^2` pass through 8 nonlinear features and a fixed random
/// linear map; each coordinate is then centred, so the data has zero mean.
pub(crate) fn manifold_data(count: usize, dim: usize, seed: u64) -> Vec<Vec<f32>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let map = random_rows(dim, 8, 1.0, &mut rng);
    let pi = std::f32::consts::PI;
    let mut data: Vec<Vec<f32>> = (0..count)
        .map(|_| {
            let (u, v) = (rng.random_range(-1.0f32..1.0), rng.random_range(-1.0f32..1.0));
            let features = [
                u,
                v,
                u * u,
                v * v,
                u * v,
                (pi * u).sin(),
                (pi * v).cos(),
                (pi * (u + v)).sin(),
            ];
            map.iter()
                .map(|row| row.iter().zip(&features).map(|(a, f)| a * f).sum())
                .collect()
        })
        .collect();
    for j in 0..dim {
        let mean = data.iter().map(|x| x[j]).sum::<f32>() / count as f32;
        data.iter_mut().for_each(|x| x[j] -= mean);
    }
    data
}

/// Mean squared error of the PCA reconstruction `mean + B^T B (x - mean)`.
pub(crate) fn pca_reconstruction_error(data: &[Vec<f32>], mean: &[f64], basis: &[Vec<f64>]) -> f64 {
    let mut total = 0.0;
    for x in data {
        let c: Vec<f64> = basis
            .iter()
            .map(|b| b.iter().zip(x).zip(mean).map(|((b, &x), m)| b * (x as f64 - m)).sum())
            .collect();
        for (j, &xj) in x.iter().enumerate() {
            let y = mean[j] + basis.iter().zip(&c).map(|(b, c)| b[j] * c).sum::<f64>();
            total += (y - xj as f64).powi(2);
        }
    }
    total / (data.len() * data[0].len()) as f64
}

/// The residual Swish networks, the paper code's plain ELU ones, and those between fixed
/// projections: the checks of every network's derivatives run on each.
pub(crate) const STYLES: [super::MlpStyle; 3] = [super::MlpStyle::DEFAULT, super::MlpStyle::PAPER, PROJECTED];

/// The paper code's plain ELU layers between fixed random projections, as a PCA-projected
/// autoencoder network has them.
pub(crate) const PROJECTED: super::MlpStyle = super::MlpStyle {
    input_projection: true,
    output_projection: true,
    ..super::MlpStyle::PAPER
};

/// A random network of `spec`'s outer sizes and `style`: the trainable layers between random
/// projections where the style has them (`spec.input` to 3 values before, 6 values to
/// `spec.output` after), the trainable weights drawn from `rng` as [`super::ResMlp::new_styled`]
/// draws them.
pub(crate) fn styled_network(spec: super::MlpSpec, style: super::MlpStyle, rng: &mut ChaCha8Rng) -> super::ResMlp {
    let core = super::MlpSpec {
        input: if style.input_projection { 3 } else { spec.input },
        output: if style.output_projection { 6 } else { spec.output },
        ..spec
    };
    let mlp = super::ResMlp::new_styled(core, style, rng).unwrap();
    let mut layer = |rows: usize, cols: usize| super::DenseLayer {
        rows,
        cols,
        weights: (0..rows * cols).map(|_| rng.random_range(-0.6..0.6)).collect(),
        bias: (0..rows).map(|_| rng.random_range(-0.3..0.3)).collect(),
    };
    let input = style.input_projection.then(|| layer(3, spec.input));
    let output = style.output_projection.then(|| layer(spec.output, 6));
    mlp.with_projections(input, output).unwrap()
}
