//! PCA of frames read in passes ([`FrameRows`] on disk): the randomized range finder with
//! power iterations (Halko, Martinsson and Tropp 2011, Algorithms 4.3 and 5.1), each product
//! with the data one pass over the frames that holds a block of them at a time. Memory is
//! `dims x (k + oversampling)` whatever the number of frames; [`Pca::fit`] (a thin SVD of
//! every frame at once) stays the method when the frames fit in memory.
//!
//! Passes: the mean; `Y = A Ω` (`A` the mean-centred `dims x frames` data, `Ω` uniform in `[-1, 1]`,
//! drawn per frame from the seed so it is never stored); `power` times `Y = A (Aᵀ Q)` with
//! `Q` an orthonormal basis of the last `Y` (both products in the same pass, frame by
//! frame: `Σ_j c_j (c_jᵀ Q)`); then `B Bᵀ = Σ_j (Qᵀ c_j)(Qᵀ c_j)ᵀ`, whose eigenvectors rotate
//! `Q` onto the components and whose eigenvalues are the squared singular values. The total
//! sum of squares comes with the last pass, so the error of every size is exact given the
//! leading singular values.

use faer::{Mat, Side};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::learn::frame_rows::{FrameRows, Rows};
use crate::learn::pca::{orient, Pca, PcaError};

/// Frames per block of a pass.
const BLOCK: usize = 64;

/// How the passes run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StreamedSettings {
    /// Columns beyond the wanted components (default 10).
    pub oversampling: usize,
    /// Power iterations (default 2): each sharpens the leading components by the ratio of
    /// the singular values past the sketch to theirs.
    pub power: usize,
    /// Seed of `Ω`.
    pub seed: u64,
}

impl Default for StreamedSettings {
    fn default() -> Self {
        StreamedSettings {
            oversampling: 10,
            power: 2,
            seed: 0,
        }
    }
}

/// A PCA fitted in passes, and the total sum of squares of the centred frames.
#[derive(Clone, Debug, PartialEq)]
pub struct StreamedPca {
    /// Mean, `k` components and the `k + oversampling` leading singular values (fewer
    /// when there are fewer frames or dimensions).
    pub pca: Pca,
    /// `Σ_j |x_j - mean|²` over every frame.
    pub total_squares: f64,
}

impl StreamedPca {
    /// Residual sum of squares with the `k` leading components (Eckart-Young), from the
    /// sketched singular values; 0 past them.
    pub fn residual_squares(&self, k: usize) -> f64 {
        let kept: f64 = self.pca.singular_values.iter().take(k).map(|s| s * s).sum();
        (self.total_squares - kept).max(0.0)
    }
}

impl Pca {
    /// The mean and `k` leading components of `rows` (finite, of one width), read in
    /// passes of [`BLOCK`] frames (see the module docs).
    pub fn fit_streamed(rows: &FrameRows, k: usize, settings: &StreamedSettings) -> Result<StreamedPca, PcaError> {
        let (dims, count) = (rows.width(), rows.count());
        if count == 0 || dims == 0 {
            return Err(PcaError::NoData("no frames"));
        }
        let max = dims.min(count);
        if k > max {
            return Err(PcaError::TooManyComponents { k, max });
        }
        let sketch = (k + settings.oversampling).min(max);
        let mean = mean_of(rows, dims)?;
        // Y = A Ω, Ω's row j drawn from the seed and j alone.
        let mut y = Mat::<f64>::zeros(dims, sketch);
        pass(rows, &mean, |c, j| {
            let mut rng = ChaCha8Rng::seed_from_u64(settings.seed);
            rng.set_stream(j as u64);
            for col in 0..sketch {
                let w: f64 = rng.random_range(-1.0..1.0);
                y.col_mut(col).iter_mut().zip(c).for_each(|(y, c)| *y += w * c);
            }
        })?;
        for _ in 0..settings.power {
            let q = orthonormal(&y);
            y.fill(0.0);
            pass(rows, &mean, |c, _| {
                let coefficients = project(&q, c);
                for (col, a) in coefficients.iter().enumerate() {
                    y.col_mut(col).iter_mut().zip(c).for_each(|(y, c)| *y += a * c);
                }
            })?;
        }
        let q = orthonormal(&y);
        let width = q.ncols();
        let mut gram = Mat::<f64>::zeros(width, width);
        let mut total_squares = 0.0;
        pass(rows, &mean, |c, _| {
            total_squares += c.iter().map(|v| v * v).sum::<f64>();
            let p = project(&q, c);
            for a in 0..width {
                for b in 0..=a {
                    gram[(a, b)] += p[a] * p[b];
                }
            }
        })?;
        let eigen = gram
            .self_adjoint_eigen(Side::Lower)
            .map_err(|e| PcaError::Svd(format!("{e:?}")))?;
        let (u, s) = (eigen.U(), eigen.S());
        // Eigenvalues ascend: the components are the columns from the last.
        let order: Vec<usize> = (0..width).rev().collect();
        let singular_values: Vec<f64> = order.iter().map(|&j| s[j].max(0.0).sqrt()).collect();
        let basis = order
            .iter()
            .take(k)
            .map(|&j| {
                let mut c = vec![0.0; dims];
                for a in 0..width {
                    let w = u[(a, j)];
                    c.iter_mut().zip(q.col(a).iter()).for_each(|(c, q)| *c += w * q);
                }
                orient(&mut c);
                c
            })
            .collect();
        Ok(StreamedPca {
            pca: Pca {
                mean,
                basis,
                singular_values,
            },
            total_squares,
        })
    }
}

/// The mean frame, one pass.
fn mean_of(rows: &FrameRows, dims: usize) -> Result<Vec<f64>, PcaError> {
    let mut mean = vec![0.0; dims];
    rows.for_each_block(BLOCK, |first, block| {
        for (i, frame) in block.chunks_exact(dims).enumerate() {
            if !frame.iter().all(|v| v.is_finite()) {
                return Err(PcaError::NotFinite { frame: first + i });
            }
            mean.iter_mut().zip(frame).for_each(|(m, x)| *m += x);
        }
        Ok(())
    })?;
    let count = rows.count() as f64;
    mean.iter_mut().for_each(|m| *m /= count);
    Ok(mean)
}

/// Calls `each(centred frame, frame index)` on every frame, in order.
fn pass(rows: &FrameRows, mean: &[f64], mut each: impl FnMut(&[f64], usize)) -> Result<(), PcaError> {
    let dims = mean.len();
    let mut centred = vec![0.0; dims];
    rows.for_each_block(BLOCK, |first, block| {
        for (i, frame) in block.chunks_exact(dims).enumerate() {
            centred
                .iter_mut()
                .zip(frame.iter().zip(mean))
                .for_each(|(c, (x, m))| *c = x - m);
            each(&centred, first + i);
        }
        Ok::<(), PcaError>(())
    })
}

/// `Qᵀ c`.
fn project(q: &Mat<f64>, c: &[f64]) -> Vec<f64> {
    (0..q.ncols())
        .map(|a| q.col(a).iter().zip(c).map(|(q, c)| q * c).sum())
        .collect()
}

/// An orthonormal basis of `y`'s columns (thin QR).
fn orthonormal(y: &Mat<f64>) -> Mat<f64> {
    y.qr().compute_thin_Q()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::frame_rows::RowWriter;

    /// Frames with a decaying spectrum: a mean plus six directions of falling scale and a
    /// little noise.
    fn frames(count: usize, dims: usize) -> Vec<Vec<f64>> {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let directions: Vec<Vec<f64>> = (0..6)
            .map(|d| (0..dims).map(|i| ((i * (d + 2)) as f64 * 0.37).sin()).collect())
            .collect();
        (0..count)
            .map(|_| {
                let mut x: Vec<f64> = (0..dims).map(|i| 1.0 + i as f64 * 0.01).collect();
                for (d, dir) in directions.iter().enumerate() {
                    let a: f64 = rng.random_range(-1.0..1.0);
                    let scale = 3f64.powi(-(d as i32));
                    x.iter_mut().zip(dir).for_each(|(x, v)| *x += a * scale * v);
                }
                for x in x.iter_mut() {
                    let n: f64 = rng.random_range(-1.0..1.0);
                    *x += 1e-4 * n;
                }
                x
            })
            .collect()
    }

    fn on_disk(dir: &std::path::Path, frames: &[Vec<f64>]) -> FrameRows {
        let mut writer = RowWriter::create(&dir.join("frames.f64"), frames[0].len()).unwrap();
        for f in frames {
            writer.push(f).unwrap();
        }
        FrameRows::Disk(writer.finish().unwrap())
    }

    #[test]
    fn passes_over_a_file_give_the_thin_svd_s_components() {
        let data = frames(300, 90);
        let dir = tempfile::tempdir().unwrap();
        let rows = on_disk(dir.path(), &data);
        let exact = Pca::fit(&data, 4).unwrap();
        let streamed = Pca::fit_streamed(&rows, 4, &StreamedSettings::default()).unwrap();
        for (a, b) in exact.mean.iter().zip(&streamed.pca.mean) {
            assert!((a - b).abs() < 1e-12);
        }
        for (j, (a, b)) in exact.basis.iter().zip(&streamed.pca.basis).enumerate() {
            let dot: f64 = a.iter().zip(b).map(|(a, b)| a * b).sum();
            assert!((dot - 1.0).abs() < 1e-8, "component {j}: cos {dot}");
            let (sa, sb) = (exact.singular_values[j], streamed.pca.singular_values[j]);
            assert!((sa - sb).abs() < 1e-8 * sa, "singular value {j}: {sa} against {sb}");
        }
        let total: f64 = exact.singular_values.iter().map(|s| s * s).sum();
        assert!((streamed.total_squares - total).abs() < 1e-10 * total);
        let tail: f64 = exact.singular_values[4..].iter().map(|s| s * s).sum();
        assert!((streamed.residual_squares(4) - tail).abs() < 1e-6 * tail.max(1e-300) + 1e-12 * total);
    }

    #[test]
    fn bad_frames_and_sizes_are_named() {
        let mut data = frames(20, 12);
        let dir = tempfile::tempdir().unwrap();
        let rows = on_disk(dir.path(), &data);
        let err = Pca::fit_streamed(&rows, 13, &StreamedSettings::default()).unwrap_err();
        assert_eq!(err, PcaError::TooManyComponents { k: 13, max: 12 });
        data[7][3] = f64::NAN;
        let dir = tempfile::tempdir().unwrap();
        let rows = on_disk(dir.path(), &data);
        let err = Pca::fit_streamed(&rows, 2, &StreamedSettings::default()).unwrap_err();
        assert_eq!(err, PcaError::NotFinite { frame: 7 });
    }
}
