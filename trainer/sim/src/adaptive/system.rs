//! The adaptive model's Newton system and its solution (Trusty et al., Sec. 3.8, 3.10):
//! `[Bᵀ H B, Bᵀ H S; Sᵀ H B, Sᵀ H S] [d_q; d_x] = [Bᵀ r; Sᵀ r]` with `B` the masked
//! modal basis, `S` the enriched coordinates and `r = -g`, by the Schur complement; and the
//! timing of the three linear solvers of one such system (the paper's Table 3).

use std::time::Instant;

use faer::sparse::{SparseColMat, SparseColMatRef, Triplet};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use super::full_space::{cholesky_direction, pcg_direction};
use super::lower_csc::{symmetric_block_product, symmetric_product};
use super::model::{EnrichedDofs, ModalBasis};
use super::pcg::PcgSettings;
use super::schur::{AdaptiveSystem, Coupling};
use super::SolveError;

/// A model's direction.
pub(super) struct ModelDirection {
    /// `B d_q + S d_x` over the free dofs.
    pub direction: Vec<f64>,
    /// `W d_q`: the step of each candidate column of `B`.
    pub candidate_step: DVector<f64>,
    /// Conjugate-gradient iterations of the Schur complement solve.
    pub pcg_iterations: usize,
}

/// The direction of the model `(b, enriched)` for the Hessian `h` (lower triangle, free
/// dofs) plus, when given, a matrix added to `Bᵀ H B` (the approximated elastic subspace
/// Hessian), and right-hand side `rhs = -g`; `hb` is `H B` when already computed.
pub(super) fn model_direction(
    b: &ModalBasis,
    enriched: &EnrichedDofs,
    num_free: usize,
    (h, approximated): (SparseColMatRef<'_, u32, f64>, Option<&DMatrix<f64>>),
    hb: Option<DMatrix<f64>>,
    rhs: &[f64],
    pcg: &PcgSettings,
) -> Result<ModelDirection, SolveError> {
    let (a, nx) = (b.len(), enriched.dofs.len());
    let hb = hb.unwrap_or_else(|| hessian_times(h, &b.basis));
    let mut h_q = b.basis.transpose() * &hb;
    if let Some(extra) = approximated {
        h_q += extra;
    }
    // C = B^T H S: the enriched rows of H B, transposed.
    let coupling = DMatrix::from_fn(a, nx, |r, c| hb[(enriched.dofs[c], r)]);
    let mut triplets = Vec::new();
    for (c, &fc) in enriched.dofs.iter().enumerate() {
        for (fr, &v) in h.symbolic().row_idx_of_col(fc).zip(h.val_of_col(fc)) {
            if let Some(r) = enriched.position[fr] {
                triplets.push(Triplet::new(r as u32, c as u32, v));
            }
        }
    }
    let h_x =
        SparseColMat::<u32, f64>::try_new_from_triplets(nx, nx, &triplets).map_err(|_| SolveError::NonFinite("H_x"))?;
    let r = DVector::from_column_slice(rhs);
    let g_q: Vec<f64> = (b.basis.transpose() * &r).iter().map(|v| -v).collect();
    let g_x: Vec<f64> = enriched.dofs.iter().map(|&f| -rhs[f]).collect();
    let system = AdaptiveSystem {
        h_q: &h_q,
        coupling: Coupling::Dense(&coupling),
        h_x: h_x.as_ref(),
        g_q: &g_q,
        g_x: &g_x,
    };
    let solution = system.solve(pcg)?;
    let d_q = DVector::from_column_slice(&solution.d_q);
    let mut direction = vec![0.0; num_free];
    if a > 0 {
        direction.copy_from_slice((&b.basis * &d_q).as_slice());
    }
    for (&f, dx) in enriched.dofs.iter().zip(&solution.d_x) {
        direction[f] += dx;
    }
    let candidate_step = if a > 0 {
        &b.coefficients * &d_q
    } else {
        DVector::zeros(0)
    };
    Ok(ModelDirection {
        direction,
        candidate_step,
        pcg_iterations: solution.report.iterations,
    })
}

/// `H U` for the symmetric `H` stored as its lower triangle: the columns split into one
/// group per thread, each group by one pass over `H`.
pub(super) fn hessian_times(h: SparseColMatRef<'_, u32, f64>, u: &DMatrix<f64>) -> DMatrix<f64> {
    let (n, k) = u.shape();
    let mut hu = DMatrix::zeros(n, k);
    if k == 0 {
        return hu;
    }
    let group = k.div_ceil(rayon::current_num_threads().max(1));
    let groups: Vec<(usize, Vec<f64>)> = (0..k)
        .step_by(group)
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|start| {
            let width = group.min(k - start);
            let mut x = vec![0.0; n * width];
            for j in 0..width {
                for (r, v) in u.column(start + j).iter().enumerate() {
                    x[r * width + j] = *v;
                }
            }
            let mut y = vec![0.0; n * width];
            symmetric_block_product(h, &x, width, &mut y);
            (start, y)
        })
        .collect();
    for (start, y) in groups {
        let width = group.min(k - start);
        for j in 0..width {
            for (r, out) in hu.column_mut(start + j).iter_mut().enumerate() {
                *out = y[r * width + j];
            }
        }
    }
    hu
}

/// One Newton-iterate system kept for timing.
#[derive(Clone)]
pub(super) struct KeptSystem {
    pub hessian: SparseColMat<u32, f64>,
    pub rhs: Vec<f64>,
    pub masked: ModalBasis,
    pub enriched: EnrichedDofs,
}

/// The three solvers on one system (seconds, and how far each is from solving it).
#[derive(Clone, Debug, PartialEq)]
pub struct LinearSolverTimings {
    /// Free coordinates of the full system.
    pub free_dofs: usize,
    /// Enriched coordinates and modal columns of the model.
    pub enriched_dofs: usize,
    /// See `enriched_dofs`.
    pub modes: usize,
    /// The model's system by the Schur complement (its Hessian products included), and the
    /// conjugate-gradient iterations.
    pub schur_seconds: f64,
    /// See `schur_seconds`.
    pub schur_iterations: usize,
    /// The full system by faer's sparse Cholesky (symbolic and numeric factorisation,
    /// solve).
    pub cholesky_seconds: f64,
    /// The full system by block-Jacobi PCG (relative tolerance as the Schur one's), and its
    /// iterations.
    pub pcg_seconds: f64,
    /// See `pcg_seconds`.
    pub pcg_iterations: usize,
    /// `|H d - r| / |r|` of the Cholesky and PCG directions on the full system.
    pub full_residuals: [f64; 2],
}

/// Times the three solvers on `kept`.
pub(super) fn time_solvers(
    kept: &KeptSystem,
    num_free: usize,
    pcg: &PcgSettings,
) -> Result<LinearSolverTimings, SolveError> {
    let h = kept.hessian.as_ref();
    let g: Vec<f64> = kept.rhs.iter().map(|v| -v).collect();
    let clock = Instant::now();
    let model = model_direction(&kept.masked, &kept.enriched, num_free, (h, None), None, &kept.rhs, pcg)?;
    let schur_seconds = clock.elapsed().as_secs_f64();
    let clock = Instant::now();
    let cholesky = cholesky_direction(h, &g)?;
    let cholesky_seconds = clock.elapsed().as_secs_f64();
    let clock = Instant::now();
    let (iterative, report) = pcg_direction(h, &g, pcg)?;
    let pcg_seconds = clock.elapsed().as_secs_f64();
    let residual = |d: &[f64]| {
        let mut hd = vec![0.0; d.len()];
        symmetric_product(h, d, &mut hd);
        let num: f64 = hd.iter().zip(&kept.rhs).map(|(a, b)| (a - b) * (a - b)).sum();
        let den: f64 = kept.rhs.iter().map(|b| b * b).sum();
        (num / den.max(f64::MIN_POSITIVE)).sqrt()
    };
    Ok(LinearSolverTimings {
        free_dofs: num_free,
        enriched_dofs: kept.enriched.dofs.len(),
        modes: kept.masked.len(),
        schur_seconds,
        schur_iterations: model.pcg_iterations,
        cholesky_seconds,
        pcg_seconds,
        pcg_iterations: report.iterations,
        full_residuals: [residual(&cholesky), residual(&iterative)],
    })
}
