//! Error and progress of modal candidates and modal blocks (Trusty et al., Eqs. 12-17).

use super::NodeScales;
use faer::MatRef;

/// Error and progress of one candidate block.
#[derive(Clone, Debug, PartialEq)]
pub struct BlockScore {
    /// Index of the block in [`crate::adaptive::candidates::CandidateSet::blocks`].
    pub block: usize,
    /// `G_j` (Eq. 14): the largest per-vertex norm of the block's gradient projection over
    /// that vertex's error scale.
    pub error: f64,
    /// `E_j` (Eq. 15): the block's projected energy change summed over the vertices, each
    /// over its progress scale.
    pub progress: f64,
}

/// The scores of the block of modes `u` (columns over all `dim * n` dofs).
///
/// Error (Eqs. 12, 16, 14): `g^m = Σ_k u_k (u_kᵀ ∇E) / (u_kᵀ u_k)`, the sum of the gradient's
/// projections onto each mode of the block (the paper's formula, which is the orthogonal
/// projection onto the block's span when its modes are Euclidean-orthogonal), then
/// `max_i |g^m_i|₂ / (h² A_i H̄_i)` over the free vertices (plain norm, as for the nodal
/// error). `gradient` must be zero on prescribed dofs.
///
/// Progress (Eqs. 13, 17, 15): with `ū_k` the per-vertex average of mode `k` over its
/// `dim` coordinates, `ΔE^m = Σ_k ū_k (ū_kᵀ ΔE) / (ū_kᵀ ū_k)` and
/// `E_j = Σ_i ΔE^m_i / (h² V_i H̄_i)` over the free vertices. A mode whose averaged vector
/// is zero (its coordinates cancel at every vertex) distributes no energy change and adds
/// nothing, where the formula would divide zero by zero. As the paper writes it, the
/// progress of a mode whose averaged vector changes sign cancels between its positive and
/// negative parts: on a centrally symmetric body, where `h² V_i H̄_i` is symmetric too, a
/// mode odd under the symmetry (the affine stretches about the centre, odd linear modes)
/// scores zero progress whatever the step does, so only its error decides.
pub(super) fn block_score(
    block: usize,
    u: MatRef<'_, f64>,
    gradient: &[f64],
    energy_change: &[f64],
    scales: &NodeScales,
    h: f64,
    free: &[bool],
) -> BlockScore {
    let dim = scales.dim;
    let n = scales.num_vertices();
    let mut projected = vec![0.0; n * dim];
    let mut distributed = vec![0.0; n];
    let mut averaged = vec![0.0; n];
    for k in 0..u.ncols() {
        let col = u.col(k);
        let (mut ug, mut uu) = (0.0, 0.0);
        for r in 0..n * dim {
            ug += col[r] * gradient[r];
            uu += col[r] * col[r];
        }
        if uu > 0.0 {
            let c = ug / uu;
            for (r, p) in projected.iter_mut().enumerate() {
                *p += c * col[r];
            }
        }
        let (mut ue, mut uu) = (0.0, 0.0);
        for (i, a) in averaged.iter_mut().enumerate() {
            *a = (0..dim).map(|c| col[i * dim + c]).sum::<f64>() / dim as f64;
            ue += *a * energy_change[i];
            uu += *a * *a;
        }
        if uu > 0.0 {
            let c = ue / uu;
            distributed.iter_mut().zip(&averaged).for_each(|(e, a)| *e += c * a);
        }
    }
    let mut error = 0.0f64;
    let mut progress = 0.0;
    for i in (0..n).filter(|&i| free[i]) {
        let norm = projected[i * dim..(i + 1) * dim]
            .iter()
            .map(|g| g * g)
            .sum::<f64>()
            .sqrt();
        error = error.max(norm / scales.error_scale(i, h));
        progress += distributed[i] / scales.progress_scale(i, h);
    }
    BlockScore { block, error, progress }
}
