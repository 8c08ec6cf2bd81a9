//! Data modes: the principal components of a body's displacements in a dataset (the seed's
//! alternative to skinning eigenmodes, Sec. 3.5), mass-weighted so that they are
//! M-orthonormal like the other candidate blocks.
//!
//! With `D` the displacements from rest (one column per frame, zero on prescribed dofs) and
//! `M` the lumped masses, the modes are the leading left singular vectors of `M^½ D` mapped
//! back by `M^-½`: from the frames' mass-weighted Gram matrix `G = Dᵀ M D = V Λ Vᵀ`,
//! `u_k = D v_k / √λ_k`, so `u_kᵀ M u_l = δ_kl`. The Gram matrix is `F x F` for `F`
//! frames, far smaller than the body's dofs.

use faer::Mat;
use nalgebra::{DMatrix, SymmetricEigen};

use super::{Body, CandidateError};

/// Components whose variance is below this fraction of the largest are left out (the
/// frames do not span them).
const RELATIVE_VARIANCE_FLOOR: f64 = 1e-10;

/// Up to `count` data modes of `body` from `frames` (positions, `dim` per vertex, every
/// vertex), as columns; fewer when the frames span fewer directions.
pub fn data_modes(body: &Body, frames: &[&[f64]], count: usize) -> Result<Mat<f64>, CandidateError> {
    body.validate()?;
    let n = body.num_dofs();
    if let Some((i, f)) = frames.iter().enumerate().find(|(_, f)| f.len() != n) {
        return Err(CandidateError::InvalidBody(format!(
            "data frame {i} has {} coordinates, the body {n}",
            f.len()
        )));
    }
    if let Some(i) = frames.iter().position(|f| !f.iter().all(|v| v.is_finite())) {
        return Err(CandidateError::InvalidBody(format!(
            "data frame {i} holds a non-finite value"
        )));
    }
    let (free_index, _) = body.free_dofs();
    let dim = body.dim;
    // Mass-weighted displacements `M^½ d` of every frame, zero on prescribed dofs.
    let weighted: Vec<Vec<f64>> = frames
        .iter()
        .map(|f| {
            (0..n)
                .map(|k| {
                    if free_index[k] == crate::dofs::NOT_FREE {
                        0.0
                    } else {
                        (f[k] - body.rest[k]) * body.masses[k / dim].sqrt()
                    }
                })
                .collect()
        })
        .collect();
    let m = weighted.len();
    let gram: DMatrix<f64> = DMatrix::from_fn(m, m, |i, j| {
        weighted[i].iter().zip(&weighted[j]).map(|(a, b)| a * b).sum()
    });
    let eigen = SymmetricEigen::new(gram);
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
    let largest = order.first().map_or(0.0, |&i| eigen.eigenvalues[i]);
    let kept: Vec<usize> = order
        .into_iter()
        .filter(|&i| largest > 0.0 && eigen.eigenvalues[i] > RELATIVE_VARIANCE_FLOOR * largest)
        .take(count)
        .collect();
    let mut modes = Mat::zeros(n, kept.len());
    for (c, &i) in kept.iter().enumerate() {
        let scale = 1.0 / eigen.eigenvalues[i].sqrt();
        for (w, &v) in weighted.iter().zip(eigen.eigenvectors.column(i).iter()) {
            for (k, &x) in w.iter().enumerate() {
                if x != 0.0 {
                    modes[(k, c)] += x * v * scale / body.masses[k / dim].sqrt();
                }
            }
        }
    }
    Ok(modes)
}
