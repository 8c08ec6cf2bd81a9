//! The active model of an adaptive solve and the bases it spans over the free dofs.
//!
//! A model is a set of active candidate blocks and a set of enriched vertices. Newton's
//! direction lives in `U_a d_q + S d_x` (Trusty et al., Sec. 3.6): `U_a` holds the active
//! blocks' columns restricted to the free dofs and zeroed on the enriched vertices (the
//! non-overlapping decomposition: a vertex moves either through the modes or through its
//! own coordinates, never both), re-orthonormalised, which drops the directions the
//! masking annihilated; `S` selects the enriched vertices' coordinates. The oracle's step
//! (Eq. 18) uses the same columns unmasked.

use nalgebra::{DMatrix, SymmetricEigen};

use super::candidates::CandidateSet;
use crate::dofs::NOT_FREE;

/// Relative eigenvalue of a basis' Gram matrix below which a direction counts as
/// annihilated by the masking (and is dropped).
const RANK_TOLERANCE: f64 = 1e-10;

/// The active model: which candidate blocks span the subspace and which vertices are
/// enriched.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ActiveModel {
    /// `blocks[b]`: whether block `b` of the candidate set is active.
    pub blocks: Vec<bool>,
    /// `enriched[i]`: whether vertex `i` is enriched (prescribed vertices are ignored).
    pub enriched: Vec<bool>,
}

impl ActiveModel {
    /// Checks the model's lengths against `candidates` and a body of `vertices` vertices.
    pub fn check(&self, candidates: &CandidateSet, vertices: usize) -> Result<(), String> {
        if self.blocks.len() != candidates.blocks.len() {
            return Err(format!(
                "blocks has {} entries, the candidates {} blocks",
                self.blocks.len(),
                candidates.blocks.len()
            ));
        }
        if self.enriched.len() != vertices {
            return Err(format!(
                "enriched has {} entries, the body {vertices} vertices",
                self.enriched.len()
            ));
        }
        Ok(())
    }

    /// The candidate columns of the active blocks, ascending.
    pub fn columns(&self, candidates: &CandidateSet) -> Vec<usize> {
        active_columns(candidates, &self.blocks)
    }
}

/// The candidate columns of the blocks where `blocks` holds, ascending.
pub(super) fn active_columns(candidates: &CandidateSet, blocks: &[bool]) -> Vec<usize> {
    candidates
        .blocks
        .iter()
        .zip(blocks)
        .filter(|(_, &on)| on)
        .flat_map(|(b, _)| b.columns.clone())
        .collect()
}

/// Orthonormal columns over the free dofs spanning some candidate columns, with the map
/// back to those columns' coefficients.
#[derive(Clone, Debug)]
pub struct ModalBasis {
    /// The candidate columns it spans.
    pub columns: Vec<usize>,
    /// `B`, `num_free x a`, orthonormal.
    pub basis: DMatrix<f64>,
    /// `W`, `columns.len() x a`: `B = U_sel W`, so a step `B d` moves candidate column
    /// `columns[j]` by `(W d)_j`.
    pub coefficients: DMatrix<f64>,
}

impl ModalBasis {
    /// The span of `columns` of `candidates` over the free dofs (`free_index` maps each dof
    /// to its free index or `NOT_FREE`), zeroed on the vertices where `masked` is true.
    pub fn new(
        candidates: &CandidateSet,
        columns: Vec<usize>,
        free_index: &[usize],
        num_free: usize,
        masked: Option<&[bool]>,
    ) -> Self {
        let d = candidates.dim;
        let mut u = DMatrix::zeros(num_free, columns.len());
        for (k, &f) in free_index.iter().enumerate() {
            if f == NOT_FREE || masked.is_some_and(|m| m[k / d]) {
                continue;
            }
            for (j, &c) in columns.iter().enumerate() {
                u[(f, j)] = candidates.modes[(k, c)];
            }
        }
        let (basis, coefficients) = orthonormal_range(&u);
        ModalBasis {
            columns,
            basis,
            coefficients,
        }
    }

    /// Number of orthonormal columns (`a`).
    pub fn len(&self) -> usize {
        self.basis.ncols()
    }

    /// Whether it spans nothing.
    pub fn is_empty(&self) -> bool {
        self.basis.ncols() == 0
    }
}

/// The enriched free dofs of a model, ascending, and each free dof's index among them.
#[derive(Clone, Debug)]
pub struct EnrichedDofs {
    /// The enriched free dofs.
    pub dofs: Vec<usize>,
    /// `position[f]`: index of free dof `f` in `dofs`, if enriched.
    pub position: Vec<Option<usize>>,
}

impl EnrichedDofs {
    /// The free dofs of the vertices where `enriched` is true.
    pub fn new(enriched: &[bool], dim: usize, free_index: &[usize], num_free: usize) -> Self {
        let mut dofs = Vec::new();
        let mut position = vec![None; num_free];
        for (k, &f) in free_index.iter().enumerate() {
            if f != NOT_FREE && enriched[k / dim] {
                position[f] = Some(dofs.len());
                dofs.push(f);
            }
        }
        EnrichedDofs { dofs, position }
    }
}

/// An orthonormal basis `B = U W` of the column space of `u` (from the eigen-decomposition
/// of its Gram matrix, dropping directions whose eigenvalue is below `RANK_TOLERANCE` times
/// the largest, or all of them when `u` is zero), and `W`.
pub fn orthonormal_range(u: &DMatrix<f64>) -> (DMatrix<f64>, DMatrix<f64>) {
    if u.ncols() == 0 {
        return (u.clone(), DMatrix::zeros(0, 0));
    }
    let eigen = SymmetricEigen::new(u.transpose() * u);
    let largest = eigen.eigenvalues.iter().fold(0.0f64, |m, &l| m.max(l));
    let keep: Vec<usize> = (0..u.ncols())
        .filter(|&j| largest > 0.0 && eigen.eigenvalues[j] > RANK_TOLERANCE * largest)
        .collect();
    let mut w = DMatrix::zeros(u.ncols(), keep.len());
    for (c, &j) in keep.iter().enumerate() {
        let col = eigen.eigenvectors.column(j) / eigen.eigenvalues[j].sqrt();
        w.column_mut(c).copy_from(&col);
    }
    (u * &w, w)
}
