//! The lowest eigenpairs of a sparse symmetric pencil `K u = lambda M u` (`M` diagonal and
//! positive) by shift-invert block Lanczos with full M-reorthogonalisation, Rayleigh-Ritz
//! on `K` and restarts from the Ritz vectors.
//!
//! Each cycle builds an M-orthonormal basis `V` of the block Krylov space of
//! `(K - sigma M)^-1 M` from a start block of `p` vectors: `steps` blocks, each the
//! shift-inverted image of the one before, M-orthogonalised (classical Gram-Schmidt, twice)
//! against the deflated vectors and every vector already in `V`. Vectors that fall to
//! round-off are dependent and left out, so once `V` spans the whole space the solve is
//! exact. Rayleigh-Ritz on the pencil itself (`V^T K V`, dense) gives the Ritz pairs,
//! ascending; the lowest `p` start the next cycle, until the wanted ones meet the
//! tolerance. Shift-invert makes the eigenvalues nearest `sigma` (the lowest, with `sigma`
//! below them) the dominant ones of the operator.
//!
//! Why not faer's `matrix_free::eigen::partial_self_adjoint_eigen` (faer 0.24): it is a
//! single-vector Lanczos, which finds one vector per eigenvalue of a multiple (or nearly
//! multiple) eigenvalue in exact arithmetic and only slowly the others in floating point,
//! and bodies are full of such pairs (the two bending modes of a beam of square section);
//! its convergence test is an absolute residual of the shift-inverted operator; and it
//! panics when the Krylov space it asks for is as large as the problem. A block of `p`
//! vectors (the wanted count plus some) holds every multiplicity up to `p`.

use super::CandidateError;
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::Llt;
use faer::sparse::SparseColMatRef;
use faer::{Mat, Side};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// How the eigensolver runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LanczosSettings {
    /// Each wanted pair is converged when `||K u - lambda M u|| <= tolerance * ||K u||`
    /// (`||(K - sigma M) u||` in place of `||K u||` where that is larger: eigenvalues near
    /// zero), or when the residuals stall at round-off within 100 times it
    /// (`stalled_at_round_off`).
    pub tolerance: f64,
    /// Cycles after the first before giving up.
    pub max_restarts: usize,
    /// Start-block vectors beyond the wanted count (also the largest multiplicity beyond
    /// it that the block is sure to resolve).
    pub oversampling: usize,
    /// Blocks per cycle (the Krylov degree plus one).
    pub steps: usize,
    /// Seed of the random start block.
    pub seed: u64,
}

impl Default for LanczosSettings {
    fn default() -> Self {
        LanczosSettings {
            tolerance: 1e-8,
            max_restarts: 50,
            oversampling: 8,
            steps: 3,
            seed: 0,
        }
    }
}

/// The pencil over the free dofs.
pub(crate) struct Pencil<'a> {
    /// Lower triangle of the symmetric `K` (CSC).
    pub stiffness: SparseColMatRef<'a, u32, f64>,
    /// Diagonal of `M`, positive.
    pub mass: &'a [f64],
    /// Cholesky factorisation of `K - sigma M`.
    pub shifted: &'a Llt<u32, f64>,
    /// The shift sigma.
    pub shift: f64,
}

/// Converged eigenpairs, ascending.
pub(crate) struct Eigenpairs {
    pub values: Vec<f64>,
    /// M-orthonormal eigenvectors as columns (free dofs).
    pub vectors: Mat<f64>,
    /// Relative residuals (see [`LanczosSettings::tolerance`]).
    pub residuals: Vec<f64>,
    /// Restarts taken.
    pub restarts: usize,
}

impl Pencil<'_> {
    fn dim(&self) -> usize {
        self.mass.len()
    }

    /// `y = K x` from the lower triangle.
    fn apply_stiffness(&self, x: &[f64], y: &mut [f64]) {
        y.fill(0.0);
        let k = self.stiffness;
        let (col_ptr, row_idx, values) = (k.symbolic().col_ptr(), k.symbolic().row_idx(), k.val());
        for c in 0..k.ncols() {
            for p in col_ptr[c] as usize..col_ptr[c + 1] as usize {
                let (r, v) = (row_idx[p] as usize, values[p]);
                y[r] += v * x[c];
                if r != c {
                    y[c] += v * x[r];
                }
            }
        }
    }

    fn dot_m(&self, a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).zip(self.mass).map(|((x, y), m)| m * x * y).sum()
    }

    /// Relative residual of the pair `(lambda, u)`, with `ku = K u`.
    fn residual(&self, lambda: f64, u: &[f64], ku: &[f64]) -> f64 {
        let mut r2 = 0.0;
        let mut k2 = 0.0;
        let mut s2 = 0.0;
        for i in 0..u.len() {
            let mu = self.mass[i] * u[i];
            r2 += (ku[i] - lambda * mu).powi(2);
            k2 += ku[i] * ku[i];
            s2 += (ku[i] - self.shift * mu).powi(2);
        }
        r2.sqrt() / k2.max(s2).sqrt().max(f64::MIN_POSITIVE)
    }
}

/// The `count` lowest eigenpairs of the pencil on the M-orthogonal complement of `deflate`
/// (M-orthonormal columns, an invariant subspace such as K's null space). The caller
/// checks that `count` does not exceed the complement's dimension.
pub(crate) fn lowest_eigenpairs(
    pencil: &Pencil,
    deflate: &[Vec<f64>],
    count: usize,
    settings: &LanczosSettings,
) -> Result<Eigenpairs, CandidateError> {
    let n = pencil.dim();
    let available = n - deflate.len();
    debug_assert!(count <= available);
    if settings.tolerance.is_nan() || settings.tolerance <= 0.0 || settings.steps == 0 {
        return Err(CandidateError::InvalidSetting(format!(
            "tolerance {} must be positive and steps {} at least 1",
            settings.tolerance, settings.steps
        )));
    }
    if count == 0 {
        return Ok(Eigenpairs {
            values: Vec::new(),
            vectors: Mat::zeros(n, 0),
            residuals: Vec::new(),
            restarts: 0,
        });
    }
    let width = (count + settings.oversampling).min(available);
    let mut rng = ChaCha8Rng::seed_from_u64(settings.seed);
    let mut start: Vec<Vec<f64>> = Vec::with_capacity(width);
    let mut worst = f64::INFINITY;
    let mut history: Vec<f64> = Vec::new();
    for restart in 0..=settings.max_restarts {
        // Random vectors fill the start block (all of the first, and whatever the Ritz
        // vectors leave short of its width after a cycle that lost vectors).
        while start.len() < width {
            start.push((0..n).map(|_| rng.random_range(-1.0..1.0)).collect());
        }
        let basis = krylov_basis(pencil, deflate, start, settings.steps, available);
        let ritz = rayleigh_ritz(pencil, &basis)?;
        let wanted = count.min(ritz.values.len());
        let whole_space = basis.len() == available;
        worst = ritz.residuals[..wanted].iter().fold(0.0, |w: f64, r| w.max(*r));
        history.push(worst);
        if wanted == count && (worst <= settings.tolerance || whole_space || stalled_at_round_off(&history, settings)) {
            let vectors = Mat::from_fn(n, count, |i, j| ritz.vectors[j][i]);
            return Ok(Eigenpairs {
                values: ritz.values[..count].to_vec(),
                vectors,
                residuals: ritz.residuals[..count].to_vec(),
                restarts: restart,
            });
        }
        start = ritz.vectors.into_iter().take(width).collect();
    }
    Err(CandidateError::NotConverged {
        restarts: settings.max_restarts,
        worst_residual: worst,
        tolerance: settings.tolerance,
    })
}

/// Whether the worst residual has stopped falling a little above the tolerance: at most
/// [`STALL_FACTOR`] times it and not halved over the last [`STALL_CYCLES`] cycles. The
/// residual a computed pair can reach is about machine epsilon times `K`'s condition on the
/// pair, which on fine meshes of stiff bodies is near the default tolerance itself (a
/// 21,825-vertex cantilever at 5 MPa stalled at 1.29e-8 for 1e-8); further cycles there only
/// redo round-off.
fn stalled_at_round_off(history: &[f64], settings: &LanczosSettings) -> bool {
    let Some((&worst, earlier)) = history.split_last() else {
        return false;
    };
    earlier.len() >= STALL_CYCLES
        && worst <= STALL_FACTOR * settings.tolerance
        && worst > 0.5 * earlier[earlier.len() - STALL_CYCLES]
}

/// Cycles over which a residual that has not halved counts as stalled.
const STALL_CYCLES: usize = 3;
/// How far above the tolerance a stalled residual is still accepted.
const STALL_FACTOR: f64 = 100.0;

/// The M-orthonormal block Krylov basis of `(K - sigma M)^-1 M` from `start`, with
/// `steps` blocks at most and `available` vectors at most, M-orthogonal to `deflate`.
fn krylov_basis(
    pencil: &Pencil,
    deflate: &[Vec<f64>],
    start: Vec<Vec<f64>>,
    steps: usize,
    available: usize,
) -> Vec<Vec<f64>> {
    let n = pencil.dim();
    let mut basis: Vec<Vec<f64>> = Vec::new();
    let mut block = start;
    for step in 0..steps {
        let first = basis.len();
        for mut w in block {
            if basis.len() == available {
                break;
            }
            if orthogonalise(pencil, deflate, &basis, &mut w) {
                basis.push(w);
            }
        }
        let added = basis.len() - first;
        if added == 0 || basis.len() == available || step + 1 == steps {
            break;
        }
        // The next block: (K - sigma M)^-1 M times the block just added.
        let mut rhs = Mat::from_fn(n, added, |i, j| pencil.mass[i] * basis[first + j][i]);
        pencil.shifted.solve_in_place(rhs.as_mut());
        block = (0..added).map(|j| rhs.col_as_slice(j).to_vec()).collect();
    }
    basis
}

/// M-orthogonalises `w` against `deflate` and `basis` (classical Gram-Schmidt, twice) and
/// M-normalises it; false if it falls to round-off (dependent on them).
fn orthogonalise(pencil: &Pencil, deflate: &[Vec<f64>], basis: &[Vec<f64>], w: &mut [f64]) -> bool {
    const DEPENDENT: f64 = 1e-10;
    let norm0 = pencil.dot_m(w, w).sqrt();
    if !(norm0 > 0.0 && norm0.is_finite()) {
        return false;
    }
    for _ in 0..2 {
        let coefficients: Vec<f64> = deflate.iter().chain(basis).map(|u| pencil.dot_m(u, w)).collect();
        for (u, c) in deflate.iter().chain(basis).zip(coefficients) {
            w.iter_mut().zip(u).for_each(|(x, y)| *x -= c * y);
        }
    }
    let norm = pencil.dot_m(w, w).sqrt();
    if norm <= DEPENDENT * norm0 {
        return false;
    }
    w.iter_mut().for_each(|x| *x /= norm);
    true
}

/// Ritz pairs of the pencil on the span of the M-orthonormal `basis`, ascending.
struct Ritz {
    values: Vec<f64>,
    vectors: Vec<Vec<f64>>,
    residuals: Vec<f64>,
}

fn rayleigh_ritz(pencil: &Pencil, basis: &[Vec<f64>]) -> Result<Ritz, CandidateError> {
    let (n, m) = (pencil.dim(), basis.len());
    let kv: Vec<Vec<f64>> = basis
        .iter()
        .map(|v| {
            let mut y = vec![0.0; n];
            pencil.apply_stiffness(v, &mut y);
            y
        })
        .collect();
    let dot = |a: &[f64], b: &[f64]| -> f64 { a.iter().zip(b).map(|(x, y)| x * y).sum() };
    let projected = Mat::from_fn(m, m, |i, j| 0.5 * (dot(&basis[i], &kv[j]) + dot(&basis[j], &kv[i])));
    let eigen = projected
        .self_adjoint_eigen(Side::Lower)
        .map_err(|_| CandidateError::DenseEigen)?;
    let (y, s) = (eigen.U(), eigen.S());
    let combine = |columns: &[Vec<f64>], j: usize| -> Vec<f64> {
        let mut out = vec![0.0; n];
        for (i, c) in columns.iter().enumerate() {
            let a = y[(i, j)];
            out.iter_mut().zip(c).for_each(|(o, x)| *o += a * x);
        }
        out
    };
    let mut ritz = Ritz {
        values: Vec::with_capacity(m),
        vectors: Vec::with_capacity(m),
        residuals: Vec::with_capacity(m),
    };
    for j in 0..m {
        let lambda = s[j];
        let u = combine(basis, j);
        let ku = combine(&kv, j);
        ritz.residuals.push(pencil.residual(lambda, &u, &ku));
        ritz.values.push(lambda);
        ritz.vectors.push(u);
    }
    Ok(ritz)
}
