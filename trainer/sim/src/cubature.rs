//! Optimised cubature for reduced-order models (An et al. 2008, "Optimizing cubature for
//! efficient integration of subspace deformations"; von Tycowicz et al. 2013).
//!
//! In a subspace `x = f(z)` with few reduced coordinates `z`, the elastic energy
//! `P = sum_e P_e` over all `E` elements is approximated by `P~ = sum_{e in S} w_e P_e`
//! over a small set `S` of elements with weights `w_e >= 0`, chosen so that on training
//! samples `z_i` the energy and the reduced forces `J_i^T grad P_e` are reproduced.
//!
//! The caller builds the `m x E` matrix `A` ([`ColumnMatrix`]), one column per element and,
//! per sample, the rows `[P_e(f(z_i)), (J_i^T grad P_e(f(z_i)))_1..r]`, usually with each
//! sample's rows divided by the norm of that sample's target so that every sample counts
//! alike. [`fit_cubature`] then solves `min ||A w - b||` over `w >= 0`, with `b = A 1` (the
//! row sums: all elements, unit weight), by greedy selection: it repeatedly adds the
//! candidate element whose column best correlates with the residual and re-solves the
//! non-negative least-squares problem on the selected columns, dropping elements whose
//! weight falls to zero, until the relative residual `||A w - b|| / ||b||` is below the
//! tolerance or the size limit is reached. [`CubatureEnergy`] evaluates the result with the
//! same energy kernels as the full model.

mod nnls;
#[cfg(test)]
mod tests;

use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::energy::{Local, StencilEnergy, Want};

/// A dense matrix stored column by column: the cubature training matrix, one column per
/// element.
#[derive(Clone, Debug, PartialEq)]
pub struct ColumnMatrix {
    rows: usize,
    cols: usize,
    /// Column-major entries, `rows * cols` of them.
    data: Vec<f64>,
}

impl ColumnMatrix {
    /// A `rows x cols` matrix of zeros.
    pub fn zeros(rows: usize, cols: usize) -> Self {
        ColumnMatrix {
            rows,
            cols,
            data: vec![0.0; rows * cols],
        }
    }

    /// A `rows x cols` matrix from its column-major entries (entry `(i, e)` at
    /// `data[e * rows + i]`); fails unless there are exactly `rows * cols` of them.
    pub fn from_column_major(rows: usize, cols: usize, data: Vec<f64>) -> Result<Self, CubatureError> {
        if rows.checked_mul(cols) != Some(data.len()) {
            return Err(CubatureError::Shape {
                rows,
                cols,
                len: data.len(),
            });
        }
        Ok(ColumnMatrix { rows, cols, data })
    }

    /// A `rows x cols` matrix whose column `e` is written by `column(e, slice)` (the slice
    /// starts zeroed).
    pub fn from_columns(rows: usize, cols: usize, mut column: impl FnMut(usize, &mut [f64])) -> Self {
        let mut m = Self::zeros(rows, cols);
        for e in 0..cols {
            column(e, m.column_mut(e));
        }
        m
    }

    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Number of columns.
    pub fn cols(&self) -> usize {
        self.cols
    }

    /// Column `e`.
    pub fn column(&self, e: usize) -> &[f64] {
        &self.data[e * self.rows..(e + 1) * self.rows]
    }

    /// Column `e`, writable.
    pub fn column_mut(&mut self, e: usize) -> &mut [f64] {
        &mut self.data[e * self.rows..(e + 1) * self.rows]
    }

    /// The sum of all columns: the target `A 1` of the fit.
    pub fn row_sums(&self) -> Vec<f64> {
        let mut sums = vec![0.0; self.rows];
        for e in 0..self.cols {
            sums.iter_mut().zip(self.column(e)).for_each(|(s, v)| *s += v);
        }
        sums
    }
}

/// Settings of [`fit_cubature`].
#[derive(Clone, Debug, PartialEq)]
pub struct CubatureSettings {
    /// Largest number of elements in the cubature. Default 300.
    pub max_elements: usize,
    /// Relative residual `||A w - b|| / ||b||` at which the greedy selection stops.
    /// Default `1e-3`.
    pub tolerance: f64,
    /// Elements scored per greedy step, drawn at random from those not selected (all of
    /// them when there are fewer). Default 1000.
    pub candidates: usize,
    /// Seed of the candidate draws; the fit is deterministic given it. Default 0.
    pub seed: u64,
}

impl Default for CubatureSettings {
    fn default() -> Self {
        CubatureSettings {
            max_elements: 300,
            tolerance: 1e-3,
            candidates: 1000,
            seed: 0,
        }
    }
}

/// A cubature rule: the selected elements (stencil indices of the full energy, ascending)
/// and their weights (positive), in the same order.
#[derive(Clone, Debug, PartialEq)]
pub struct Cubature {
    /// Selected element (stencil) indices.
    pub elements: Vec<usize>,
    /// Weight of each selected element.
    pub weights: Vec<f64>,
}

/// How well a cubature fits its training matrix.
#[derive(Clone, Debug, PartialEq)]
pub struct CubatureFit {
    /// `||A w - b|| / ||b||` of the returned weights.
    pub relative_residual: f64,
    /// Greedy steps taken (elements added, including any dropped again later).
    pub iterations: usize,
}

/// Why a cubature could not be fitted or used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CubatureError {
    /// The training matrix has no rows or no columns.
    #[error("the cubature matrix is empty ({rows} rows, {cols} columns)")]
    Empty {
        /// Rows.
        rows: usize,
        /// Columns.
        cols: usize,
    },
    /// The number of entries does not match the shape.
    #[error("{len} entries do not fill a {rows} x {cols} matrix")]
    Shape {
        /// Rows.
        rows: usize,
        /// Columns.
        cols: usize,
        /// Entries given.
        len: usize,
    },
    /// An entry of the training matrix is NaN or infinite.
    #[error("entry ({row}, {column}) of the cubature matrix is not finite ({value})")]
    NonFinite {
        /// Row of the entry.
        row: usize,
        /// Column (element) of the entry.
        column: usize,
        /// The entry.
        value: f64,
    },
    /// The row sums of the training matrix are all zero: there is nothing to fit.
    #[error("the cubature target (the row sums of the matrix) is zero")]
    ZeroTarget,
    /// A setting is out of range.
    #[error("cubature setting `{field}`: {message}")]
    Settings {
        /// The setting.
        field: &'static str,
        /// What is wrong with it.
        message: String,
    },
    /// A cubature's element and weight lists differ in length.
    #[error("the cubature has {elements} elements but {weights} weights")]
    Length {
        /// Elements listed.
        elements: usize,
        /// Weights listed.
        weights: usize,
    },
    /// A cubature element is not a stencil of the energy.
    #[error("cubature element {element} is out of range (the energy has {stencils} stencils)")]
    ElementRange {
        /// The element.
        element: usize,
        /// Stencils of the energy.
        stencils: usize,
    },
    /// A cubature weight is negative or not finite.
    #[error("cubature weight {index} is negative or not finite ({value})")]
    Weight {
        /// Position in the weight list.
        index: usize,
        /// The weight.
        value: f64,
    },
}

/// Fits a cubature to the training matrix `a` (one column per element; see the module
/// documentation): greedy selection of elements with non-negative least-squares weights
/// against the target `b = A 1`.
///
/// Stops when the relative residual is at most `settings.tolerance`, when
/// `settings.max_elements` are selected, or when no element can lower the residual; the
/// cubature is returned in every case, with its residual in [`CubatureFit`], for the caller
/// to judge. Fails on an empty or non-finite matrix, a zero target or invalid settings.
pub fn fit_cubature(a: &ColumnMatrix, settings: &CubatureSettings) -> Result<(Cubature, CubatureFit), CubatureError> {
    check_input(a, settings)?;
    let (m, num) = (a.rows(), a.cols());
    let b = DVector::from_vec(a.row_sums());
    let b_norm = b.norm();
    if b_norm == 0.0 || !b_norm.is_finite() {
        return Err(CubatureError::ZeroTarget);
    }
    let norms: Vec<f64> = (0..num).map(|e| dot(a.column(e), a.column(e)).sqrt()).collect();
    let mut rng = ChaCha8Rng::seed_from_u64(settings.seed);
    let mut selected: Vec<usize> = Vec::new();
    let mut weights = DVector::<f64>::zeros(0);
    let mut in_set = vec![false; num];
    let mut residual = b.clone();
    let mut relative = 1.0;
    let mut iterations = 0;
    // Dropped elements may be selected again; this cap only guards against cycling.
    let max_iterations = 4 * settings.max_elements + 10;
    while relative > settings.tolerance && selected.len() < settings.max_elements && iterations < max_iterations {
        let Some(best) = best_candidate(a, &norms, &in_set, residual.as_slice(), settings.candidates, &mut rng) else {
            break;
        };
        iterations += 1;
        selected.push(best);
        in_set[best] = true;
        let columns = DMatrix::from_fn(m, selected.len(), |i, j| a.column(selected[j])[i]);
        let start = DVector::from_fn(selected.len(), |j, _| weights.get(j).copied().unwrap_or(0.0));
        let solution = nnls::nnls(&columns, &b, Some(&start));
        let new_residual = &b - &columns * &solution;
        let new_relative = new_residual.norm() / b_norm;
        let kept: Vec<usize> = (0..selected.len()).filter(|&j| solution[j] > 0.0).collect();
        for (j, &e) in selected.iter().enumerate() {
            in_set[e] = solution[j] > 0.0;
        }
        selected = kept.iter().map(|&j| selected[j]).collect();
        weights = DVector::from_iterator(kept.len(), kept.iter().map(|&j| solution[j]));
        let progressed = new_relative < relative;
        residual = new_residual;
        relative = new_relative;
        if !progressed {
            break;
        }
    }
    let mut order: Vec<usize> = (0..selected.len()).collect();
    order.sort_by_key(|&j| selected[j]);
    let cubature = Cubature {
        elements: order.iter().map(|&j| selected[j]).collect(),
        weights: order.iter().map(|&j| weights[j]).collect(),
    };
    let fit = CubatureFit {
        relative_residual: relative,
        iterations,
    };
    Ok((cubature, fit))
}

/// Rejects an empty or non-finite matrix and out-of-range settings.
fn check_input(a: &ColumnMatrix, settings: &CubatureSettings) -> Result<(), CubatureError> {
    if a.rows() == 0 || a.cols() == 0 {
        return Err(CubatureError::Empty {
            rows: a.rows(),
            cols: a.cols(),
        });
    }
    for e in 0..a.cols() {
        if let Some((row, &value)) = a.column(e).iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(CubatureError::NonFinite { row, column: e, value });
        }
    }
    let bad = |field, message: &str| {
        Err(CubatureError::Settings {
            field,
            message: message.to_string(),
        })
    };
    if settings.max_elements == 0 {
        return bad("max_elements", "must be at least 1");
    }
    if settings.candidates == 0 {
        return bad("candidates", "must be at least 1");
    }
    if !(settings.tolerance.is_finite() && settings.tolerance >= 0.0) {
        return bad(
            "tolerance",
            &format!("must be finite and >= 0, not {}", settings.tolerance),
        );
    }
    Ok(())
}

/// The element, among up to `candidates` drawn at random from those not selected and with a
/// non-zero column, whose column has the largest positive correlation `a_e . r / ||a_e||`
/// with the residual `r`. When no drawn candidate correlates positively, every remaining
/// element is scored; `None` when none does (no element can lower the residual).
fn best_candidate(
    a: &ColumnMatrix,
    norms: &[f64],
    in_set: &[bool],
    residual: &[f64],
    candidates: usize,
    rng: &mut ChaCha8Rng,
) -> Option<usize> {
    let pool: Vec<usize> = (0..a.cols()).filter(|&e| !in_set[e] && norms[e] > 0.0).collect();
    let r_norm = dot(residual, residual).sqrt();
    // Correlations this small are rounding noise, not descent directions.
    let threshold = 1e-12 * r_norm;
    let best_of = |ids: &mut dyn Iterator<Item = usize>| {
        ids.map(|e| (e, dot(a.column(e), residual) / norms[e]))
            .filter(|&(_, score)| score > threshold)
            .max_by(|x, y| x.1.total_cmp(&y.1))
            .map(|(e, _)| e)
    };
    if pool.len() > candidates {
        let drawn = rand::seq::index::sample(rng, pool.len(), candidates);
        if let Some(e) = best_of(&mut drawn.iter().map(|k| pool[k])) {
            return Some(e);
        }
    }
    best_of(&mut pool.iter().copied())
}

/// Dot product of two equally long slices.
fn dot(x: &[f64], y: &[f64]) -> f64 {
    x.iter().zip(y).map(|(a, b)| a * b).sum()
}

/// The cubature approximation `sum_{e in S} w_e P_e` of an energy, itself a
/// [`StencilEnergy`] over the selected stencils only: stencil `s` is element
/// `cubature.elements[s]` of the wrapped energy, and its value, gradient and Hessian are
/// that element's, times `cubature.weights[s]`. The wrapped energy's kernels do all the
/// work, so there is one definition of each energy. Weights are non-negative, so projected
/// Hessians stay positive semi-definite.
pub struct CubatureEnergy<'a> {
    energy: &'a dyn StencilEnergy,
    cubature: Cubature,
}

impl<'a> CubatureEnergy<'a> {
    /// Wraps `energy` with `cubature`; fails when the element and weight lists differ in
    /// length, an element is not a stencil of `energy`, or a weight is negative or not
    /// finite.
    pub fn new(energy: &'a dyn StencilEnergy, cubature: Cubature) -> Result<Self, CubatureError> {
        if cubature.elements.len() != cubature.weights.len() {
            return Err(CubatureError::Length {
                elements: cubature.elements.len(),
                weights: cubature.weights.len(),
            });
        }
        if let Some(&element) = cubature.elements.iter().find(|&&e| e >= energy.len()) {
            return Err(CubatureError::ElementRange {
                element,
                stencils: energy.len(),
            });
        }
        if let Some((index, &value)) = cubature
            .weights
            .iter()
            .enumerate()
            .find(|(_, w)| !(w.is_finite() && **w >= 0.0))
        {
            return Err(CubatureError::Weight { index, value });
        }
        Ok(CubatureEnergy { energy, cubature })
    }

    /// The cubature rule.
    pub fn cubature(&self) -> &Cubature {
        &self.cubature
    }

    /// The wrapped full energy.
    pub fn full(&self) -> &'a dyn StencilEnergy {
        self.energy
    }
}

impl StencilEnergy for CubatureEnergy<'_> {
    fn name(&self) -> &'static str {
        self.energy.name()
    }

    fn dim(&self) -> usize {
        self.energy.dim()
    }

    fn len(&self) -> usize {
        self.cubature.elements.len()
    }

    fn stencil(&self, s: usize) -> &[usize] {
        self.energy.stencil(self.cubature.elements[s])
    }

    fn eval(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        let w = self.cubature.weights[s];
        let value = self.energy.eval(self.cubature.elements[s], x, want, out);
        let n = x.len();
        if want.gradient() {
            out.grad[..n].iter_mut().for_each(|g| *g *= w);
        }
        if want.hessian().is_some() {
            out.hess[..n * n].iter_mut().for_each(|h| *h *= w);
        }
        w * value
    }
}
