//! The free-free Hessian's sparse pattern: a lower-triangular CSC matrix covering every
//! stencil of the fixed energy terms plus any extra couplings (contact pairs between
//! vertices no element joins), its values, the slot map of every term, and the cached
//! symbolic Cholesky factorisation. The Newton solver assembles its objective's Hessian here,
//! and so does anything else that needs the Hessian of the same energy terms (the linear
//! modes of `adaptive::candidates`).

use crate::dofs::NOT_FREE;
use crate::energy::{self, StencilEnergy, MAX_DOF};
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{MatMut, Side};

const NO_SLOT: u32 = u32::MAX;

/// Where each entry of each stencil's local Hessian lands in the sparse matrix.
struct StencilSlots {
    /// `offsets[s]..offsets[s + 1]` indexes `slots` for stencil `s` (row-major `n x n`).
    offsets: Vec<usize>,
    /// Index into the CSC value array, or `NO_SLOT` for fixed DOF / upper triangle.
    slots: Vec<u32>,
}

/// Lower-triangular CSC pattern of the free-free Hessian, its values, the slot maps of
/// every energy term, and the cached symbolic Cholesky factorisation.
pub(crate) struct HessianPattern {
    n: usize,
    col_ptr: Vec<u32>,
    row_idx: Vec<u32>,
    pub(crate) values: Vec<f64>,
    slots: Vec<StencilSlots>,
    symbolic: SymbolicLlt<u32>,
}

impl HessianPattern {
    /// The pattern of `terms` over the `n` free dofs (`free_index` maps global dofs to free
    /// ones), plus the `extra` free-dof entries `[row, column]` (`row >= column`).
    pub(crate) fn new(terms: &[&dyn StencilEnergy], free_index: &[usize], n: usize, extra: &[[u32; 2]]) -> Self {
        let dofs = |e: &dyn StencilEnergy, s: usize| -> Vec<usize> {
            let d = e.dim();
            e.stencil(s)
                .iter()
                .flat_map(|&v| (0..d).map(move |i| free_index[v * d + i]))
                .collect()
        };
        let mut columns: Vec<Vec<u32>> = vec![Vec::new(); n];
        for term in terms {
            for s in 0..term.len() {
                let ds = dofs(*term, s);
                for &r in &ds {
                    for &c in &ds {
                        if r != NOT_FREE && c != NOT_FREE && r >= c {
                            columns[c].push(r as u32);
                        }
                    }
                }
            }
        }
        for &[r, c] in extra {
            columns[c as usize].push(r);
        }
        let mut col_ptr = vec![0u32];
        let mut row_idx = Vec::new();
        for col in &mut columns {
            col.sort_unstable();
            col.dedup();
            row_idx.extend_from_slice(col);
            col_ptr.push(row_idx.len() as u32);
        }
        let slots = terms
            .iter()
            .map(|term| {
                let mut offsets = vec![0];
                let mut slots = Vec::new();
                for s in 0..term.len() {
                    let ds = dofs(*term, s);
                    debug_assert!(ds.len() <= MAX_DOF);
                    for &r in &ds {
                        for &c in &ds {
                            slots.push(if r != NOT_FREE && c != NOT_FREE && r >= c {
                                let col = &row_idx[col_ptr[c] as usize..col_ptr[c + 1] as usize];
                                col_ptr[c]
                                    + col
                                        .binary_search(&(r as u32))
                                        .expect("pattern holds every stencil entry")
                                        as u32
                            } else {
                                NO_SLOT
                            });
                        }
                    }
                    offsets.push(slots.len());
                }
                StencilSlots { offsets, slots }
            })
            .collect();
        let nnz = row_idx.len();
        // The symbolic analysis (ordering, elimination tree, fill) depends only on the
        // pattern: computed once here, reused by every numeric factorisation.
        let symbolic = SymbolicLlt::try_new(
            SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx),
            Side::Lower,
        )
        .expect("symbolic Cholesky of a valid pattern");
        HessianPattern {
            n,
            col_ptr,
            row_idx,
            values: vec![0.0; nnz],
            slots,
            symbolic,
        }
    }

    /// Assembles `sum_t w_t H_t(x)`, the free-free block of the weighted Hessians of `terms`
    /// (the terms the pattern was built from, in that order, each with its weight; a zero
    /// weight skips the term), optionally with every stencil Hessian projected to PSD.
    pub(crate) fn assemble<'a>(
        &mut self,
        terms: impl Iterator<Item = (&'a dyn StencilEnergy, f64)>,
        x: &[f64],
        project: bool,
    ) {
        self.assemble_stencils(terms.map(|(e, w)| (e, w, None)), x, project);
    }

    /// [`Self::assemble`] with each term restricted to the stencils its list names (all
    /// when `None`).
    pub(crate) fn assemble_stencils<'a>(
        &mut self,
        terms: impl Iterator<Item = (&'a dyn StencilEnergy, f64, Option<&'a [usize]>)>,
        x: &[f64],
        project: bool,
    ) {
        self.values.fill(0.0);
        for (term, (energy, weight, stencils)) in terms.enumerate() {
            self.add_stencils(term, energy, weight, stencils, x, project);
        }
    }

    /// Adds `weight` times the Hessians of the stencils `stencils` names (all when `None`)
    /// of term number `term` (as the pattern was built) to the assembled values.
    pub(crate) fn add_stencils(
        &mut self,
        term: usize,
        energy: &dyn StencilEnergy,
        weight: f64,
        stencils: Option<&[usize]>,
        x: &[f64],
        project: bool,
    ) {
        if weight == 0.0 {
            return;
        }
        let slots = &self.slots[term];
        let values = &mut self.values;
        energy::for_each_hessian_of(energy, stencils, x, project, |s, _, local| {
            let range = slots.offsets[s]..slots.offsets[s + 1];
            for (slot, h) in slots.slots[range].iter().zip(&local.hess) {
                if *slot != NO_SLOT {
                    values[*slot as usize] += weight * h;
                }
            }
        });
    }

    /// The assembled matrix's lower triangle (CSC, sorted row indices per column).
    pub(crate) fn lower(&self) -> SparseColMatRef<'_, u32, f64> {
        let pattern = SymbolicSparseColMatRef::new_checked(self.n, self.n, &self.col_ptr, None, &self.row_idx);
        SparseColMatRef::new(pattern, &self.values)
    }

    /// Numeric Cholesky factorisation of the assembled values, reusing the cached symbolic
    /// analysis; `None` if the matrix is not numerically positive definite.
    pub(crate) fn factor(&self) -> Option<Llt<u32, f64>> {
        Llt::try_new_with_symbolic(self.symbolic.clone(), self.lower(), Side::Lower).ok()
    }

    /// Index into the values of entry `(r, c)` (free dofs, `r >= c`), if the pattern has it.
    pub(crate) fn slot(&self, r: usize, c: usize) -> Option<usize> {
        let (start, end) = (self.col_ptr[c] as usize, self.col_ptr[c + 1] as usize);
        self.row_idx[start..end]
            .binary_search(&(r as u32))
            .ok()
            .map(|k| start + k)
    }

    /// Solves `H d = rhs` in place if the assembled `H` is positive definite; returns
    /// false (leaving `rhs` untouched) if its Cholesky factorisation fails.
    pub(crate) fn try_solve(&mut self, rhs: &mut [f64]) -> bool {
        match self.factor() {
            Some(llt) => {
                llt.solve_in_place(MatMut::from_column_major_slice_mut(rhs, self.n, 1));
                true
            }
            None => false,
        }
    }

    /// Whether every assembled value is finite (a NaN or infinite entry, from a material or
    /// load too large for `f64`, would make every factorisation fail).
    pub(crate) fn is_finite(&self) -> bool {
        self.values.iter().all(|v| v.is_finite())
    }

    /// Solves `H d = rhs` in place with a sparse Cholesky factorisation of the assembled
    /// values. If `H` is not numerically positive definite, a growing multiple of the
    /// identity (relative to the largest diagonal entry, times 100 per try) is added until it
    /// is, at most [`MAX_SHIFTS`] times. A non-finite `H`, or one still not factorised after
    /// the last shift, is an error and leaves `rhs` untouched.
    pub(crate) fn solve(&mut self, rhs: &mut [f64]) -> Result<(), Unfactorised> {
        if !self.is_finite() {
            return Err(Unfactorised::NonFinite);
        }
        if self.try_solve(rhs) {
            return Ok(());
        }
        let pattern = SymbolicSparseColMatRef::new_checked(self.n, self.n, &self.col_ptr, None, &self.row_idx);
        let diag_max = (0..self.n)
            .map(|c| self.values[self.col_ptr[c] as usize])
            .fold(0.0f64, |m, v| m.max(v.abs()))
            .max(f64::MIN_POSITIVE);
        let mut shift = 1e-10 * diag_max;
        let mut values = self.values.clone();
        for _ in 0..MAX_SHIFTS {
            values.copy_from_slice(&self.values);
            for c in 0..self.n {
                values[self.col_ptr[c] as usize] += shift;
            }
            let matrix = SparseColMatRef::new(pattern, &values);
            if let Ok(llt) = Llt::try_new_with_symbolic(self.symbolic.clone(), matrix, Side::Lower) {
                llt.solve_in_place(MatMut::from_column_major_slice_mut(rhs, self.n, 1));
                return Ok(());
            }
            shift *= 100.0;
            if !shift.is_finite() {
                break;
            }
        }
        Err(Unfactorised::Indefinite { shift })
    }
}

/// Diagonal shifts [`HessianPattern::solve`] tries before it gives up: 16, from 1e-10 to
/// 1e20 times the largest diagonal entry. Past 1e16 times it the shifted matrix is, to
/// `f64`'s precision, the shift times the identity plus off-diagonal entries too small to
/// spoil its definiteness, so a finite matrix is always factorised by then.
pub(crate) const MAX_SHIFTS: usize = 16;

/// Why [`HessianPattern::solve`] found no direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Unfactorised {
    /// The assembled matrix holds a NaN or infinite entry.
    NonFinite,
    /// Not positive definite even with the largest diagonal shift tried (`shift`).
    Indefinite {
        /// The last shift tried.
        shift: f64,
    },
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::inertia::Inertia;

    /// The pattern of two free 1D vertices' inertia (a diagonal 2 x 2 matrix).
    fn diagonal() -> HessianPattern {
        let inertia = Inertia::new(1, vec![1.0, 1.0]);
        HessianPattern::new(&[&inertia as &dyn StencilEnergy], &[0, 1], 2, &[])
    }

    #[test]
    fn a_non_finite_matrix_is_an_error_not_an_endless_shift() {
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            let mut h = diagonal();
            h.values.copy_from_slice(&[1.0, bad]);
            let mut rhs = [1.0, 2.0];
            assert_eq!(h.solve(&mut rhs), Err(Unfactorised::NonFinite));
            assert_eq!(rhs, [1.0, 2.0], "rhs untouched");
        }
    }

    #[test]
    fn an_indefinite_finite_matrix_is_shifted_until_it_factorises() {
        let mut h = diagonal();
        h.values.copy_from_slice(&[-1.0, -1e300]);
        let mut rhs = [1.0, 2.0];
        h.solve(&mut rhs).unwrap();
        assert!(rhs.iter().all(|d| d.is_finite() && *d > 0.0), "{rhs:?}");
    }
}
