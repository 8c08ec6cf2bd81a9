//! The frame of a state: the rotation `R` (the best-fit rotation of the handles) and the
//! origins `o` of the encoded vertices (see the documentation of [`super`]).

use faer::Mat;
use nalgebra::{DMatrix, Matrix3, Vector3};

use mochi_sim::scene::HandleSpec;

use super::error::{check_len, EncodingError};
use super::strands::ChainStart;

/// Spread of the handle points along a principal direction, relative to the largest, below
/// which that direction counts as absent.
const DEGENERATE_SPREAD: f64 = 1e-10;

/// Where the origins `o_v` of the encoded vertices come from.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Origins {
    /// One origin for every vertex: the centroid of the current handle targets (the
    /// origin is 0 when there are no handles).
    HandleCentroid,
    /// One origin per rod strand: the target of its root vertex. `root_slots[s]` is the
    /// position of strand `s`'s root in the handle-target list.
    StrandRoots {
        /// Per strand, the index of its root among the handle vertices.
        root_slots: Vec<usize>,
    },
}

/// The frame of one state: rotation and origins (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// `R`; the identity when the handles do not rotate (upper-left 2x2 used in 2D).
    pub rotation: Matrix3<f64>,
    /// The origins, indexed by [`Encoding::origin_of`](super::Encoding::origin_of) (z = 0 in 2D).
    pub origins: Vec<Vector3<f64>>,
    /// Per strand, where its chain starts (empty unless strands are encoded by bends).
    pub chains: Vec<ChainStart>,
}

/// Whether any handle can rotate: it has a script with a non-zero angular velocity, or a
/// sampled motion that can pick a rotating segment (rotation axes, and either no
/// translation directions or a positive `rotation_share`).
pub(crate) fn handles_rotate(handles: &[HandleSpec]) -> bool {
    handles.iter().any(|h| {
        let scripted = h.script.iter().any(|s| s.angular_velocity.iter().any(|w| *w != 0.0));
        let sampled = h
            .motion
            .as_ref()
            .is_some_and(|m| !m.rotation_axes.is_empty() && (m.directions.is_empty() || m.rotation_share > 0.0));
        scripted || sampled
    })
}

/// The proper rotation `R` (det +1) minimising `sum |R (p_i - p̄) - (q_i - q̄)|^2` (Kabsch)
/// between point sets `reference` (p) and `current` (q), `dim` (2 or 3) numbers per point.
/// A 2D rotation is returned in the upper-left block of a 3x3 matrix.
///
/// The SVD is faer's: nalgebra 0.35's SVD returned singular vectors off by 4e-3 for the
/// nearly repeated singular values of a symmetric handle (the 4 x 4 grid of rod roots),
/// where faer's is accurate to round-off.
pub(crate) fn best_fit_rotation(reference: &[f64], current: &[f64], dim: usize) -> Result<Matrix3<f64>, EncodingError> {
    if !(dim == 2 || dim == 3) {
        return Err(EncodingError::Length {
            what: "coordinates per point (2 or 3)",
            expected: 3,
            found: dim,
        });
    }
    check_len("current points", reference.len(), current.len())?;
    check_len(
        "reference points",
        reference.len().next_multiple_of(dim),
        reference.len(),
    )?;
    if !reference.iter().chain(current).all(|c| c.is_finite()) {
        return Err(EncodingError::NotFinite);
    }
    let (p_bar, q_bar) = (centroid(reference, dim), centroid(current, dim));
    // Cross-covariance H = sum (p - p̄)(q - q̄)^T; with H = U S V^T, R = V diag(1, .., det) U^T.
    let mut h = [[0.0; 3]; 3];
    for (p, q) in reference.chunks_exact(dim).zip(current.chunks_exact(dim)) {
        for i in 0..dim {
            for j in 0..dim {
                h[i][j] += (p[i] - p_bar[i]) * (q[j] - q_bar[j]);
            }
        }
    }
    let svd = Mat::<f64>::from_fn(dim, dim, |i, j| h[i][j])
        .svd()
        .map_err(|e| EncodingError::NoConvergence(format!("{e:?}")))?;
    let (u, v) = (svd.U(), svd.V());
    let rotation = |last_sign: f64| {
        let mut r = Matrix3::identity();
        for i in 0..dim {
            for j in 0..dim {
                r[(i, j)] = (0..dim)
                    .map(|k| {
                        let sign = if k == dim - 1 { last_sign } else { 1.0 };
                        sign * v[(i, k)] * u[(j, k)]
                    })
                    .sum();
            }
        }
        r
    };
    let r = rotation(1.0);
    // A reflection fits better: flip the direction of the smallest singular value.
    Ok(if r.determinant() < 0.0 { rotation(-1.0) } else { r })
}

/// Fails when the reference points are too flat to fix a rotation (3D: collinear; 2D: one point).
pub(super) fn check_spread(reference: &[f64], dim: usize) -> Result<(), EncodingError> {
    let c = centroid(reference, dim);
    let mut cov = DMatrix::<f64>::zeros(dim, dim);
    for p in reference.chunks_exact(dim) {
        for i in 0..dim {
            for j in 0..dim {
                cov[(i, j)] += (p[i] - c[i]) * (p[j] - c[j]);
            }
        }
    }
    // Spread along the principal directions; 3D needs two of them, 2D one.
    let spread: Vec<f64> = cov.symmetric_eigenvalues().iter().map(|e| e.max(0.0).sqrt()).collect();
    let largest = spread.iter().copied().fold(0.0, f64::max);
    let span = spread.iter().filter(|&&s| s > DEGENERATE_SPREAD * largest).count();
    if span < dim - 1 {
        return Err(EncodingError::DegenerateHandles {
            count: reference.len() / dim,
            span,
        });
    }
    Ok(())
}

/// A point of `dim` (2 or 3) coordinates as a 3-vector (z = 0 in 2D).
pub(super) fn pad(p: &[f64]) -> Vector3<f64> {
    let mut out = Vector3::zeros();
    out.as_mut_slice()[..p.len()].copy_from_slice(p);
    out
}

/// Centroid of points given `dim` numbers each (the origin for no points).
pub(super) fn centroid(points: &[f64], dim: usize) -> Vector3<f64> {
    let n = points.len() / dim;
    if n == 0 {
        return Vector3::zeros();
    }
    points.chunks_exact(dim).map(pad).sum::<Vector3<f64>>() / n as f64
}
