//! Dense-layer kernels: the residual MLP forward pass of [`crate::model`], with scratch on the
//! stack (`H` floats per buffer, fixed at compile time).

use crate::model::Layer;

/// `x * sigmoid(x)`.
#[inline]
pub fn swish(x: f32) -> f32 {
    x / (1.0 + libm::expf(-x))
}

/// `w . x` with eight independent accumulators, so the compiler can keep them in SIMD lanes
/// (a single running sum would serialise every addition).
#[inline]
pub fn dot(w: &[f32], x: &[f32]) -> f32 {
    let n = w.len().min(x.len());
    let (w, x) = (&w[..n], &x[..n]);
    let (wc, wt) = w.as_chunks::<8>();
    let (xc, xt) = x.as_chunks::<8>();
    let mut acc = [0.0f32; 8];
    for (a, b) in wc.iter().zip(xc) {
        for i in 0..8 {
            acc[i] += a[i] * b[i];
        }
    }
    let tail: f32 = wt.iter().zip(xt).map(|(a, b)| a * b).sum();
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7])) + tail
}

/// Row `r` of `W` of `layer`.
#[inline]
fn row<'p>(params: &'p [f32], layer: &Layer, r: usize) -> &'p [f32] {
    let cols = layer.cols as usize;
    let start = layer.weights as usize + r * cols;
    params.get(start..start + cols).unwrap_or(&[])
}

#[inline]
fn bias(params: &[f32], layer: &Layer, r: usize) -> f32 {
    params.get(layer.bias as usize + r).copied().unwrap_or(0.0)
}

/// Output `r` of `layer` for input `x`.
#[inline]
pub fn dense_row(params: &[f32], layer: &Layer, x: &[f32], r: usize) -> f32 {
    bias(params, layer, r) + dot(row(params, layer, r), x)
}

/// `y = W x + b` for an input given as consecutive `parts` (their concatenation is `x`).
fn dense_parts(params: &[f32], layer: &Layer, parts: &[&[f32]], y: &mut [f32]) {
    for (r, out) in y.iter_mut().enumerate().take(layer.rows as usize) {
        let w = row(params, layer, r);
        let mut sum = bias(params, layer, r);
        let mut offset = 0;
        for part in parts {
            sum += dot(w.get(offset..).unwrap_or(&[]), part);
            offset += part.len();
        }
        *out = sum;
    }
}

/// The last hidden activation `swish(h)` of a network for the input `parts`, written into
/// `h` (which must hold the hidden width); `scratch` is a second buffer of the same size.
/// The output layer is then applied row by row with [`dense_row`], so a caller can compute
/// only the rows it needs.
pub fn hidden(params: &[f32], layers: &[Layer], parts: &[&[f32]], h: &mut [f32], scratch: &mut [f32]) {
    let Some((input, rest)) = layers.split_first() else {
        return;
    };
    let blocks = rest.split_last().map_or(&[][..], |(_, b)| b);
    let width = (input.rows as usize).min(h.len()).min(scratch.len());
    let (h, a) = (&mut h[..width], &mut scratch[..width]);
    dense_parts(params, input, parts, h);
    for pair in blocks.chunks_exact(2) {
        dense_parts(params, &pair[0], &[h], a);
        a.iter_mut().for_each(|v| *v = swish(*v));
        for (r, hr) in h.iter_mut().enumerate() {
            *hr += dense_row(params, &pair[1], a, r);
        }
    }
    h.iter_mut().for_each(|v| *v = swish(*v));
}

/// Multiply-adds of one forward pass of `layers` (for GFLOP/s reports).
pub fn multiply_adds(layers: &[Layer]) -> usize {
    layers.iter().map(|l| l.rows as usize * l.cols as usize).sum()
}
