//! Dense-layer kernels: the residual MLP forward pass of [`crate::model`], with scratch on the
//! stack (`H` floats per buffer, fixed at compile time).
//!
//! Every layer is a matrix-vector product over contiguous weight rows. The loops are written so
//! the compiler vectorises them (many independent accumulators); on x86-64 with the `std`
//! feature the same loops are also compiled for AVX2 + FMA and chosen at run time when the CPU
//! has them (targets built with those features enabled get them at compile time).

use crate::model::Layer;

/// `x * sigmoid(x)`.
#[inline]
pub fn swish(x: f32) -> f32 {
    x / (1.0 + libm::expf(-x))
}

/// `w . x` with 32 independent accumulators, so that the additions of consecutive elements
/// do not wait for each other (one running sum would serialise them) and fill SIMD lanes.
#[inline(always)]
fn dot_generic(w: &[f32], x: &[f32]) -> f32 {
    let n = w.len().min(x.len());
    let (w, x) = (&w[..n], &x[..n]);
    let (wc, wt) = w.as_chunks::<32>();
    let (xc, xt) = x.as_chunks::<32>();
    let mut acc = [0.0f32; 32];
    for (a, b) in wc.iter().zip(xc) {
        for i in 0..32 {
            acc[i] += a[i] * b[i];
        }
    }
    let mut lanes = [0.0f32; 8];
    for (i, v) in acc.iter().enumerate() {
        lanes[i % 8] += v;
    }
    let tail: f32 = wt.iter().zip(xt).map(|(a, b)| a * b).sum();
    ((lanes[0] + lanes[4]) + (lanes[1] + lanes[5])) + ((lanes[2] + lanes[6]) + (lanes[3] + lanes[7])) + tail
}

/// Row `r` of `W` of `layer`.
#[inline(always)]
fn row<'p>(params: &'p [f32], layer: &Layer, r: usize) -> &'p [f32] {
    let cols = layer.cols as usize;
    let start = layer.weights as usize + r * cols;
    params.get(start..start + cols).unwrap_or(&[])
}

#[inline(always)]
fn bias(params: &[f32], layer: &Layer, r: usize) -> f32 {
    params.get(layer.bias as usize + r).copied().unwrap_or(0.0)
}

/// `out[i] = b[first + i] + W[first + i] . x` for consecutive rows, `x` given as consecutive
/// `parts` (their concatenation).
#[inline(always)]
fn rows_generic(params: &[f32], layer: &Layer, parts: &[&[f32]], first: usize, out: &mut [f32]) {
    let cols = layer.cols as usize;
    let mut done = 0;
    if let [x] = parts {
        if x.len() == cols && cols.is_multiple_of(8) {
            done = rows_blocked(params, layer, x, first, out);
        }
    }
    for (i, o) in out.iter_mut().enumerate().skip(done) {
        let r = first + i;
        let w = row(params, layer, r);
        let mut sum = bias(params, layer, r);
        let mut offset = 0;
        for part in parts {
            sum += dot_generic(w.get(offset..).unwrap_or(&[]), part);
            offset += part.len();
        }
        *o = sum;
    }
}

/// Rows of `layer` four at a time, each with an 8-lane accumulator and `x` loaded once for all
/// four (a matrix-vector product is limited by loads; this halves them). `cols` is a multiple
/// of 8. Returns how many leading rows of `out` were written (a multiple of 4).
#[inline(always)]
fn rows_blocked(params: &[f32], layer: &Layer, x: &[f32], first: usize, out: &mut [f32]) -> usize {
    let (xc, _) = x.as_chunks::<8>();
    let mut done = 0;
    for (block, o) in out.chunks_exact_mut(4).enumerate() {
        let r = first + 4 * block;
        let [w0, w1, w2, w3] = [r, r + 1, r + 2, r + 3].map(|r| row(params, layer, r).as_chunks::<8>().0);
        let mut acc = [[0.0f32; 8]; 4];
        for ((((xv, a), b), c), d) in xc.iter().zip(w0).zip(w1).zip(w2).zip(w3) {
            for l in 0..8 {
                acc[0][l] += a[l] * xv[l];
                acc[1][l] += b[l] * xv[l];
                acc[2][l] += c[l] * xv[l];
                acc[3][l] += d[l] * xv[l];
            }
        }
        for (k, (o, lanes)) in o.iter_mut().zip(&acc).enumerate() {
            let sum = ((lanes[0] + lanes[4]) + (lanes[1] + lanes[5])) + ((lanes[2] + lanes[6]) + (lanes[3] + lanes[7]));
            *o = bias(params, layer, r + k) + sum;
        }
        done += 4;
    }
    done
}

#[cfg(all(feature = "std", target_arch = "x86_64"))]
#[allow(unsafe_code)]
mod x86 {
    use super::*;
    use core::arch::x86_64::*;

    /// Sum of the eight lanes.
    #[target_feature(enable = "avx2,fma")]
    fn lane_sum(v: __m256) -> f32 {
        let quad = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps::<1>(v));
        let pair = _mm_add_ps(quad, _mm_movehl_ps(quad, quad));
        _mm_cvtss_f32(_mm_add_ss(pair, _mm_shuffle_ps::<1>(pair, pair)))
    }

    /// Rows of `layer` eight at a time with FMA into eight 8-lane accumulators (enough
    /// independent chains to cover the FMA latency; `x` is loaded once per eight rows).
    /// `x.len() == cols`, `cols % 8 == 0`. Returns the leading rows of `out` written.
    #[target_feature(enable = "avx2,fma")]
    fn rows_fma(params: &[f32], layer: &Layer, x: &[f32], first: usize, out: &mut [f32]) -> usize {
        let cols = layer.cols as usize;
        let mut done = 0;
        for (block, o) in out.chunks_exact_mut(8).enumerate() {
            let start = layer.weights as usize + (first + 8 * block) * cols;
            let Some(w) = params.get(start..start + 8 * cols) else {
                break;
            };
            let mut acc = [_mm256_setzero_ps(); 8];
            let mut c = 0;
            while c + 8 <= cols {
                // SAFETY: c + 8 <= cols = x.len(), and r * cols + c + 8 <= 8 * cols = w.len()
                // for every row r < 8, so every 8-float load is in bounds.
                unsafe {
                    let xv = _mm256_loadu_ps(x.as_ptr().add(c));
                    for (r, a) in acc.iter_mut().enumerate() {
                        *a = _mm256_fmadd_ps(_mm256_loadu_ps(w.as_ptr().add(r * cols + c)), xv, *a);
                    }
                }
                c += 8;
            }
            for (k, (o, a)) in o.iter_mut().zip(acc).enumerate() {
                *o = bias(params, layer, first + 8 * block + k) + lane_sum(a);
            }
            done += 8;
        }
        for (k, o) in out.iter_mut().enumerate().skip(done) {
            let start = layer.weights as usize + (first + k) * cols;
            let Some(w) = params.get(start..start + cols) else {
                break;
            };
            let mut acc = [_mm256_setzero_ps(); 2];
            let mut c = 0;
            while c + 8 <= cols {
                // SAFETY: c + 8 <= cols = x.len() = w.len().
                unsafe {
                    let a = &mut acc[(c / 8) % 2];
                    *a = _mm256_fmadd_ps(
                        _mm256_loadu_ps(w.as_ptr().add(c)),
                        _mm256_loadu_ps(x.as_ptr().add(c)),
                        *a,
                    );
                }
                c += 8;
            }
            *o = bias(params, layer, first + k) + lane_sum(_mm256_add_ps(acc[0], acc[1]));
            done = k + 1;
        }
        done
    }

    /// Computes what it can with AVX2 + FMA when this CPU has them (detected once by std, then
    /// cached); returns the leading rows of `out` written.
    pub fn rows(params: &[f32], layer: &Layer, x: &[f32], first: usize, out: &mut [f32]) -> usize {
        if x.len() == layer.cols as usize
            && x.len().is_multiple_of(8)
            && std::is_x86_feature_detected!("avx2")
            && std::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU has the features `rows_fma` is compiled for (checked above).
            unsafe { rows_fma(params, layer, x, first, out) }
        } else {
            0
        }
    }
}

/// Rows `first..first + out.len()` of `layer` applied to the concatenation of `parts`.
pub fn dense_rows(params: &[f32], layer: &Layer, parts: &[&[f32]], first: usize, out: &mut [f32]) {
    #[cfg(all(feature = "std", target_arch = "x86_64"))]
    if let [x] = parts {
        let done = x86::rows(params, layer, x, first, out);
        if done > 0 {
            return rows_generic(params, layer, parts, first + done, &mut out[done..]);
        }
    }
    rows_generic(params, layer, parts, first, out)
}

/// The last hidden activation `swish(h)` of a network for the input `parts`, written into
/// `h`; `scratch` holds two more buffers. All three must hold the hidden width. The output
/// layer is then applied with [`dense_rows`], so a caller can compute only the rows it needs.
pub fn hidden(params: &[f32], layers: &[Layer], parts: &[&[f32]], h: &mut [f32], scratch: [&mut [f32]; 2]) {
    let Some((input, rest)) = layers.split_first() else {
        return;
    };
    let blocks = rest.split_last().map_or(&[][..], |(_, b)| b);
    let [a, r] = scratch;
    let width = (input.rows as usize).min(h.len()).min(a.len()).min(r.len());
    let (h, a, r) = (&mut h[..width], &mut a[..width], &mut r[..width]);
    dense_rows(params, input, parts, 0, h);
    for pair in blocks.chunks_exact(2) {
        dense_rows(params, &pair[0], &[h], 0, a);
        a.iter_mut().for_each(|v| *v = swish(*v));
        dense_rows(params, &pair[1], &[a], 0, r);
        h.iter_mut().zip(r.iter()).for_each(|(h, r)| *h += r);
    }
    h.iter_mut().for_each(|v| *v = swish(*v));
}

/// Multiply-adds of one forward pass of `layers` (for GFLOP/s reports).
pub fn multiply_adds(layers: &[Layer]) -> usize {
    layers.iter().map(|l| l.rows as usize * l.cols as usize).sum()
}
