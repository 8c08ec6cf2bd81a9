//! The Newton-iterate system of the adaptive model solved by its Schur complement.
//!
//! The system couples `a` subspace coordinates and the `n = 3m` coordinates of `m` enriched
//! vertices:
//!
//! ```text
//! [ H_q  C   ] [d_q]     [g_q]
//! [ C^T  H_x ] [d_x] = - [g_x]
//! ```
//!
//! with `H_q` small, dense and symmetric positive definite, `H_x` sparse symmetric positive
//! definite (its lower triangle in faer's CSC format), and `C` (`a x n`) sparse or dense.
//! `H_q` is factorised once (Cholesky); then conjugate gradients solve the Schur complement
//! system `(H_x - C^T H_q^{-1} C) d_x = C^T H_q^{-1} g_q - g_x` with matrix-free products
//! (`C v`, two triangular solves, `C^T w`, and the sparse `H_x v`) and a block-Jacobi
//! preconditioner whose blocks are the exact diagonal blocks of the Schur complement,
//! `H_x,ii - W_i^T W_i` with `W_i = L^{-1} C_i` (`H_q = L L^T`, `C_i` the columns of
//! vertex `i`). Finally `d_q = -H_q^{-1} (C d_x + g_q)`.

use faer::sparse::SparseColMatRef;
use nalgebra::{Cholesky, DMatrix, DVector, Dyn};

use super::lower_csc::{check_lower, diagonal_blocks, symmetric_product};
use super::pcg::{self, check_blocks, BlockJacobi, PcgReport, PcgSettings};
use super::solve_error::{dimension, SolveError};

/// The Schur complement's name in errors.
const SCHUR: &str = "the Schur complement H_x - C^T H_q^-1 C";

/// The coupling block `C` (`a x n`) between subspace and enriched coordinates.
#[derive(Clone, Copy, Debug)]
pub enum Coupling<'a, I: faer::Index> {
    /// A dense `a x n` matrix.
    Dense(&'a DMatrix<f64>),
    /// A sparse `a x n` matrix (all its entries, in faer's CSC format).
    Sparse(SparseColMatRef<'a, I, f64>),
}

impl<I: faer::Index> Coupling<'_, I> {
    fn shape(&self) -> (usize, usize) {
        match self {
            Coupling::Dense(c) => c.shape(),
            Coupling::Sparse(c) => (c.nrows(), c.ncols()),
        }
    }

    fn is_finite(&self) -> bool {
        match self {
            Coupling::Dense(c) => c.iter().all(|v| v.is_finite()),
            Coupling::Sparse(c) => c.val().iter().all(|v| v.is_finite()),
        }
    }

    /// `out = C v`.
    fn times(&self, v: &[f64], out: &mut DVector<f64>) {
        match self {
            Coupling::Dense(c) => c.mul_to(&DVector::from_column_slice(v), out),
            Coupling::Sparse(c) => {
                out.fill(0.0);
                for (j, &vj) in v.iter().enumerate() {
                    if vj != 0.0 {
                        for (r, &x) in c.symbolic().row_idx_of_col(j).zip(c.val_of_col(j)) {
                            out[r] += x * vj;
                        }
                    }
                }
            }
        }
    }

    /// `out = C^T w`.
    fn transpose_times(&self, w: &DVector<f64>, out: &mut [f64]) {
        match self {
            Coupling::Dense(c) => {
                for (j, o) in out.iter_mut().enumerate() {
                    *o = c.column(j).dot(w);
                }
            }
            Coupling::Sparse(c) => {
                for (j, o) in out.iter_mut().enumerate() {
                    *o = c
                        .symbolic()
                        .row_idx_of_col(j)
                        .zip(c.val_of_col(j))
                        .map(|(r, &x)| x * w[r])
                        .sum();
                }
            }
        }
    }

    /// The dense columns `first..first + count`, or `None` when they are all zero.
    fn columns(&self, first: usize, count: usize) -> Option<DMatrix<f64>> {
        match self {
            Coupling::Dense(c) => {
                let cols = c.columns(first, count).into_owned();
                cols.iter().any(|&v| v != 0.0).then_some(cols)
            }
            Coupling::Sparse(c) => {
                let mut cols = DMatrix::zeros(c.nrows(), count);
                let mut any = false;
                for k in 0..count {
                    for (r, &x) in c.symbolic().row_idx_of_col(first + k).zip(c.val_of_col(first + k)) {
                        cols[(r, k)] += x;
                        any |= x != 0.0;
                    }
                }
                any.then_some(cols)
            }
        }
    }
}

/// One Newton-iterate system of the adaptive model.
#[derive(Clone, Copy, Debug)]
pub struct AdaptiveSystem<'a, I: faer::Index> {
    /// Subspace Hessian `H_q`, `a x a`, symmetric positive definite (its lower triangle is
    /// used).
    pub h_q: &'a DMatrix<f64>,
    /// Coupling `C`, `a x n`.
    pub coupling: Coupling<'a, I>,
    /// Enriched-vertex Hessian `H_x`, `n x n`, symmetric positive definite, lower triangle.
    pub h_x: SparseColMatRef<'a, I, f64>,
    /// Subspace gradient `g_q`, `a` entries.
    pub g_q: &'a [f64],
    /// Enriched-vertex gradient `g_x`, `n` entries.
    pub g_x: &'a [f64],
}

/// The solution of an [`AdaptiveSystem`] and how the iterative phase went.
#[derive(Clone, Debug)]
pub struct SchurSolution {
    /// Subspace direction `d_q`.
    pub d_q: Vec<f64>,
    /// Enriched-vertex direction `d_x`.
    pub d_x: Vec<f64>,
    /// The conjugate-gradient solve of the Schur complement system (its residual is that
    /// system's, relative to its right-hand side).
    pub report: PcgReport,
}

impl<I: faer::Index> AdaptiveSystem<'_, I> {
    fn check(&self, settings: &PcgSettings) -> Result<(), SolveError> {
        let a = self.h_q.nrows();
        let n = self.h_x.nrows();
        if self.h_q.ncols() != a {
            return Err(dimension(
                "H_q",
                "a square matrix",
                format!("{a} x {}", self.h_q.ncols()),
            ));
        }
        check_lower("H_x", self.h_x, n)?;
        check_blocks("H_x", n, settings)?;
        let (ca, cn) = self.coupling.shape();
        if (ca, cn) != (a, n) {
            return Err(dimension("C", format!("{a} x {n}"), format!("{ca} x {cn}")));
        }
        if self.g_q.len() != a {
            return Err(dimension("g_q", a, self.g_q.len()));
        }
        if self.g_x.len() != n {
            return Err(dimension("g_x", n, self.g_x.len()));
        }
        if self.h_q.iter().any(|v| !v.is_finite()) {
            return Err(SolveError::NonFinite("H_q"));
        }
        if !self.coupling.is_finite() {
            return Err(SolveError::NonFinite("C"));
        }
        if self.g_q.iter().chain(self.g_x).any(|v| !v.is_finite()) {
            return Err(SolveError::NonFinite("gradient"));
        }
        Ok(())
    }

    /// Solves the system by the Schur complement of `H_q` (module docs).
    pub fn solve(&self, settings: &PcgSettings) -> Result<SchurSolution, SolveError> {
        self.check(settings)?;
        let a = self.h_q.nrows();
        let n = self.h_x.nrows();
        let chol: Cholesky<f64, Dyn> = Cholesky::new(self.h_q.clone()).ok_or(SolveError::NotPositiveDefinite("H_q"))?;
        let g_q = DVector::from_column_slice(self.g_q);
        let hq_inv_gq = chol.solve(&g_q);
        let mut rhs = vec![0.0; n];
        self.coupling.transpose_times(&hq_inv_gq, &mut rhs);
        for (r, g) in rhs.iter_mut().zip(self.g_x) {
            *r -= g;
        }
        let blocks = self.schur_diagonal_blocks(&chol, settings.block);
        let precond = BlockJacobi::new(SCHUR, &blocks, settings.block)?;
        let mut t = DVector::zeros(a);
        let mut ct = vec![0.0; n];
        let apply = |v: &[f64], out: &mut [f64]| {
            symmetric_product(self.h_x, v, out);
            if a > 0 {
                self.coupling.times(v, &mut t);
                chol.solve_mut(&mut t);
                self.coupling.transpose_times(&t, &mut ct);
                for (o, c) in out.iter_mut().zip(&ct) {
                    *o -= c;
                }
            }
        };
        let (d_x, report) = pcg::solve(SCHUR, apply, &precond, &rhs, settings)?;
        let mut cd = DVector::zeros(a);
        self.coupling.times(&d_x, &mut cd);
        let d_q = -chol.solve(&(cd + g_q));
        Ok(SchurSolution {
            d_q: d_q.as_slice().to_vec(),
            d_x,
            report,
        })
    }

    /// The exact `block x block` diagonal blocks of the Schur complement (row-major, one
    /// after the other): `H_x,ii - W_i^T W_i` with `W_i = L^{-1} C_i`.
    pub(crate) fn schur_diagonal_blocks(&self, chol: &Cholesky<f64, Dyn>, block: usize) -> Vec<f64> {
        let mut blocks = diagonal_blocks(self.h_x, block);
        let l = chol.l();
        for (k, b) in blocks.chunks_exact_mut(block * block).enumerate() {
            let Some(mut w) = self.coupling.columns(k * block, block) else {
                continue;
            };
            // L has a positive diagonal (a Cholesky factor), so the solve cannot fail.
            let _ = l.solve_lower_triangular_mut(&mut w);
            let wtw = w.transpose() * &w;
            for i in 0..block {
                for j in 0..block {
                    b[i * block + j] -= wtw[(i, j)];
                }
            }
        }
        blocks
    }
}
