//! Projection of symmetric stencil Hessians onto the positive semi-definite cone
//! (eigenvalue clamping, Teran et al. 2005), as Newton needs a descent direction.

use nalgebra::DMatrix;

/// Clamps the eigenvalues of the symmetric row-major `n x n` matrix `h` to be at least
/// zero, in place. The input is symmetrised first to remove round-off asymmetry.
pub fn project_psd(h: &mut [f64], n: usize) {
    let m = DMatrix::from_fn(n, n, |i, j| 0.5 * (h[i * n + j] + h[j * n + i]));
    let eig = m.clone().symmetric_eigen();
    if eig.eigenvalues.iter().all(|&l| l >= 0.0) {
        for i in 0..n {
            for j in 0..n {
                h[i * n + j] = m[(i, j)];
            }
        }
        return;
    }
    let clamped = eig.eigenvalues.map(|l| l.max(0.0));
    let q = &eig.eigenvectors;
    let p = q * DMatrix::from_diagonal(&clamped) * q.transpose();
    for i in 0..n {
        for j in 0..n {
            h[i * n + j] = p[(i, j)];
        }
    }
}

/// Smallest eigenvalue of the symmetric row-major `n x n` matrix `h` (for tests).
#[cfg(test)]
pub fn min_eigenvalue(h: &[f64], n: usize) -> f64 {
    let m = DMatrix::from_fn(n, n, |i, j| 0.5 * (h[i * n + j] + h[j * n + i]));
    m.symmetric_eigen().eigenvalues.min()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_clamps_negative_eigenvalues_and_keeps_positive_part() {
        // diag(2, -1) rotated by 30 degrees.
        let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
        let q = [[c, -s], [s, c]];
        let d = [2.0, -1.0];
        let mut h = [0.0; 4];
        for i in 0..2 {
            for j in 0..2 {
                h[i * 2 + j] = (0..2).map(|k| q[i][k] * d[k] * q[j][k]).sum();
            }
        }
        project_psd(&mut h, 2);
        // Expected: 2 * q0 q0^T.
        for i in 0..2 {
            for j in 0..2 {
                let want = 2.0 * q[i][0] * q[j][0];
                assert!((h[i * 2 + j] - want).abs() < 1e-12, "{h:?}");
            }
        }
        assert!(min_eigenvalue(&h, 2) > -1e-12);
    }
}
