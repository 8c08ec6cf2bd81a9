//! A dense layer in `f64` and the products [`super::Mlp64`] builds its derivatives from.

use super::super::exported::DenseLayer;
use super::wide;

/// A dense layer `a ↦ W a + b` in `f64`, `W` row-major.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Dense64 {
    pub(super) rows: usize,
    pub(super) cols: usize,
    pub(super) weights: Vec<f64>,
    pub(super) bias: Vec<f64>,
}

impl Dense64 {
    pub(super) fn new(layer: &DenseLayer) -> Self {
        Dense64 {
            rows: layer.rows,
            cols: layer.cols,
            weights: layer.weights.iter().map(|&w| w as f64).collect(),
            bias: layer.bias.iter().map(|&b| b as f64).collect(),
        }
    }

    pub(super) fn row(&self, i: usize) -> &[f64] {
        &self.weights[i * self.cols..(i + 1) * self.cols]
    }

    /// Calls `sink(i, W_i · x)` for every row `i`.
    #[inline]
    pub(super) fn matvec(&self, x: &[f64], sink: impl FnMut(usize, f64)) {
        wide::matvec(self, x, sink)
    }

    /// [`Dense64::matvec`] as built, for whichever CPU runs it.
    #[inline(always)]
    pub(super) fn matvec_portable(&self, x: &[f64], mut sink: impl FnMut(usize, f64)) {
        for i in 0..self.rows {
            sink(i, dot(self.row(i), x));
        }
    }

    /// The layer with tangents: `value = W a + b` and `out = W t` for tangents `t` (`cols ×
    /// count`, row-major; `out`: `rows × count`), or with `add` (a residual addition) `value +=
    /// W a + b` and `out += W t`. `W` is read once, row by row: each row gives its value, then
    /// accumulates `W_ij t_j` over `j` in blocks of up to 8 directions held in registers.
    pub(super) fn with_tangents(&self, a: &[f64], t: &[f64], value: &mut [f64], out: &mut [f64], add: bool) {
        wide::with_tangents(self, a, t, value, out, add)
    }

    /// [`Dense64::with_tangents`] as built.
    #[inline(always)]
    pub(super) fn with_tangents_portable(&self, a: &[f64], t: &[f64], value: &mut [f64], out: &mut [f64], add: bool) {
        let count = t.len() / self.cols;
        for (i, o) in out.chunks_exact_mut(count).enumerate() {
            let row = self.row(i);
            let v = self.bias[i] + dot(row, a);
            if add {
                value[i] += v;
            } else {
                value[i] = v;
                o.fill(0.0);
            }
            let mut k = 0;
            while k + 8 <= count {
                accumulate::<8>(row, t, k, o);
                k += 8;
            }
            if k + 4 <= count {
                accumulate::<4>(row, t, k, o);
                k += 4;
            }
            for k in k..count {
                accumulate::<1>(row, t, k, o);
            }
        }
    }

    /// `out += Wᵀ v` for `v`: `rows × count` and `out`: `cols × count` (row-major).
    pub(super) fn add_transposed(&self, v: &[f64], out: &mut [f64]) {
        wide::add_transposed(self, v, out)
    }

    /// [`Dense64::add_transposed`] as built.
    #[inline(always)]
    pub(super) fn add_transposed_portable(&self, v: &[f64], out: &mut [f64]) {
        let count = v.len() / self.rows;
        for (row, vi) in self.weights.chunks_exact(self.cols).zip(v.chunks_exact(count)) {
            if count == 1 {
                out.iter_mut().zip(row).for_each(|(o, &w)| *o += w * vi[0]);
                continue;
            }
            for (&w, oj) in row.iter().zip(out.chunks_exact_mut(count)) {
                oj.iter_mut().zip(vi).for_each(|(o, &v)| *o += w * v);
            }
        }
    }
}

/// `o[k..k + L] += Σ_j row_j t_j[k..k + L]` for the rows `t_j` of `t` (`row.len() × o.len()`).
#[inline(always)]
fn accumulate<const L: usize>(row: &[f64], t: &[f64], k: usize, o: &mut [f64]) {
    let mut acc = [0.0; L];
    for (&w, tj) in row.iter().zip(t.chunks_exact(o.len())) {
        let tj = &tj[k..k + L];
        for l in 0..L {
            acc[l] += w * tj[l];
        }
    }
    o[k..k + L].iter_mut().zip(acc).for_each(|(o, a)| *o += a);
}

/// `a · b`, in four interleaved sums so that it vectorises.
#[inline(always)]
pub(super) fn dot(a: &[f64], b: &[f64]) -> f64 {
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let tail: f64 = ca.remainder().iter().zip(cb.remainder()).map(|(x, y)| x * y).sum();
    let mut acc = [0.0; 4];
    for (x, y) in ca.zip(cb) {
        for l in 0..4 {
            acc[l] += x[l] * y[l];
        }
    }
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}
