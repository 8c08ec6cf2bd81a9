//! Linear modes of a body's rest shape: the lowest eigenpairs of `K u = lambda M u`, `K`
//! the Hessian of the body's elastic energy at the rest shape and `M` its lumped mass,
//! over the free dofs (prescribed ones eliminated as the solver does). `lambda` is the
//! squared angular frequency `omega^2` of the mode's small vibrations.
//!
//! `K` is assembled by the solver's own sparse Hessian assembly (`solver::hessian`) from
//! the same energy terms the solver minimises, so it is the Hessian of the one definition
//! of each energy. The pairs come from shift-invert block Lanczos ([`super::lanczos`]) with
//! a small negative shift `sigma`: `K - sigma M` is positive definite even where `K` is
//! singular (a floating body), and faer's sparse Cholesky factorises it with the solver's
//! symbolic analysis. For a floating body (no prescribed vertex) the rigid modes span
//! `K`'s null space; they are deflated, so the linear modes are the lowest pairs above
//! them and M-orthogonal to them. A body of several disconnected parts has more zero
//! modes than its rigid ones; those come out as linear modes with `lambda` near zero.

use super::lanczos::{lowest_eigenpairs, LanczosSettings, Pencil};
use super::{rigid_modes, Body, CandidateError};
use crate::dofs::NOT_FREE;
use crate::energy::inertia::Inertia;
use crate::energy::StencilEnergy;
use crate::hessian::HessianPattern;
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::Mat;
use std::time::Instant;

/// How linear modes are computed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinearModeSettings {
    /// The shift is `sigma = -relative_shift * mean(K_ii / M_ii)`, a fraction of the
    /// stiffness-to-mass scale of the mesh's finest elements (far above the lowest
    /// eigenvalues, which is what makes the shift small).
    pub relative_shift: f64,
    /// The eigensolver's settings.
    pub lanczos: LanczosSettings,
}

impl Default for LinearModeSettings {
    fn default() -> Self {
        LinearModeSettings {
            relative_shift: 1e-8,
            lanczos: LanczosSettings::default(),
        }
    }
}

/// Seconds spent in each stage of [`linear_modes`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LinearModeTimings {
    /// Sparse pattern, symbolic analysis and the assembly of `K` and `K - sigma M`.
    pub assembly: f64,
    /// Numeric Cholesky factorisation of `K - sigma M`.
    pub factorisation: f64,
    /// Block Lanczos (solves, orthogonalisation, Rayleigh-Ritz).
    pub eigensolve: f64,
}

/// The lowest linear modes of a body.
#[derive(Clone, Debug)]
pub struct LinearModes {
    /// Eigenvalues `lambda = omega^2` (s^-2), ascending.
    pub eigenvalues: Vec<f64>,
    /// The modes as columns over all dofs (`dim * n` rows, zero on prescribed dofs),
    /// M-orthonormal (`U^T M U = I`).
    pub modes: Mat<f64>,
    /// Relative residual `||K u - lambda M u|| / ||K u||` of each pair (free dofs;
    /// `||(K - sigma M) u||` in the denominator where that is larger).
    pub residuals: Vec<f64>,
    /// The shift sigma used.
    pub shift: f64,
    /// Lanczos restarts taken.
    pub restarts: usize,
    /// Where the time went.
    pub timings: LinearModeTimings,
}

impl LinearModes {
    /// Frequencies `sqrt(lambda) / (2 pi)` in Hz (0 for eigenvalues round-off made negative).
    pub fn frequencies_hz(&self) -> Vec<f64> {
        self.eigenvalues
            .iter()
            .map(|l| l.max(0.0).sqrt() / (2.0 * std::f64::consts::PI))
            .collect()
    }
}

/// The `count` lowest linear modes of `body` under the elastic terms `elastic` (above the
/// rigid modes for a floating body). Asking for more than the free dofs allow (less the
/// rigid modes of a floating body) is an error, as are terms of another dimension or with
/// vertices the body lacks.
pub fn linear_modes(
    body: &Body,
    elastic: &[&dyn StencilEnergy],
    count: usize,
    settings: &LinearModeSettings,
) -> Result<LinearModes, CandidateError> {
    let start = Instant::now();
    body.validate()?;
    // A floating body has every dof free, so its rigid modes are free-dof vectors as they are.
    let deflate: Vec<Vec<f64>> = if body.is_floating() {
        let rigid = rigid_modes(body)?;
        (0..rigid.ncols()).map(|j| rigid.col_as_slice(j).to_vec()).collect()
    } else {
        Vec::new()
    };
    let (_, num_free) = body.free_dofs();
    let available = num_free.saturating_sub(deflate.len());
    if count > available {
        return Err(CandidateError::TooManyModes {
            requested: count,
            available,
            free_dofs: num_free,
            deflated: deflate.len(),
        });
    }
    if !(settings.relative_shift > 0.0 && settings.relative_shift.is_finite()) {
        return Err(CandidateError::InvalidSetting(format!(
            "relative_shift is {}, must be positive",
            settings.relative_shift
        )));
    }
    if count == 0 {
        return Ok(LinearModes {
            eigenvalues: Vec::new(),
            modes: Mat::zeros(body.num_dofs(), 0),
            residuals: Vec::new(),
            shift: 0.0,
            restarts: 0,
            timings: LinearModeTimings::default(),
        });
    }
    let mut assembly = RestAssembly::new(body, elastic)?;
    let shift = -settings.relative_shift * assembly.stiffness_scale();
    assembly.assemble(elastic, body.rest, -shift);
    let mut timings = LinearModeTimings {
        assembly: start.elapsed().as_secs_f64(),
        ..Default::default()
    };
    let factor_start = Instant::now();
    let shifted = assembly
        .pattern
        .factor()
        .ok_or(CandidateError::NotPositiveDefinite { shift })?;
    timings.factorisation = factor_start.elapsed().as_secs_f64();
    let solve_start = Instant::now();
    let pencil = Pencil {
        stiffness: assembly.stiffness.as_ref(),
        mass: &assembly.mass,
        shifted: &shifted,
        shift,
    };
    let pairs = lowest_eigenpairs(&pencil, &deflate, count, &settings.lanczos)?;
    timings.eigensolve = solve_start.elapsed().as_secs_f64();
    let modes = assembly.scatter(pairs.vectors.as_ref());
    Ok(LinearModes {
        eigenvalues: pairs.values,
        modes,
        residuals: pairs.residuals,
        shift,
        restarts: pairs.restarts,
        timings,
    })
}

/// The rest-shape stiffness `K` over the free dofs, the free lumped masses, and the sparse
/// pattern (inertia term first, then the elastic terms) that assembles `K + w M`.
pub(crate) struct RestAssembly {
    pub(crate) free_index: Vec<usize>,
    pub(crate) num_free: usize,
    /// Diagonal of `M` over the free dofs.
    pub(crate) mass: Vec<f64>,
    /// Lower triangle of `K` (CSC).
    pub(crate) stiffness: SparseColMat<u32, f64>,
    inertia: Inertia,
    pattern: HessianPattern,
}

impl RestAssembly {
    /// Validates `body` and `elastic` and assembles `K` at the rest shape.
    pub(crate) fn new(body: &Body, elastic: &[&dyn StencilEnergy]) -> Result<Self, CandidateError> {
        body.validate()?;
        let n = body.num_vertices();
        for (t, term) in elastic.iter().enumerate() {
            if term.dim() != body.dim {
                return Err(CandidateError::InvalidBody(format!(
                    "elastic term {t} ({}) is {}D, the body {}D",
                    term.name(),
                    term.dim(),
                    body.dim
                )));
            }
            if let Some(s) = (0..term.len()).find(|&s| term.stencil(s).iter().any(|&v| v >= n)) {
                return Err(CandidateError::InvalidBody(format!(
                    "stencil {s} of elastic term {t} ({}) has a vertex beyond the body's {n}",
                    term.name()
                )));
            }
        }
        let (free_index, num_free) = body.free_dofs();
        let mass = body.free_masses(&free_index, num_free);
        let inertia = Inertia::new(body.dim, body.masses.to_vec());
        let terms: Vec<&dyn StencilEnergy> = std::iter::once(&inertia as &dyn StencilEnergy)
            .chain(elastic.iter().copied())
            .collect();
        let mut pattern = HessianPattern::new(&terms, &free_index, num_free, &[]);
        pattern.assemble(weighted(&inertia, elastic, 0.0), body.rest, false);
        let lower = pattern.lower();
        let stiffness = SparseColMat::new(
            SymbolicSparseColMat::new_checked(
                num_free,
                num_free,
                lower.symbolic().col_ptr().to_vec(),
                None,
                lower.symbolic().row_idx().to_vec(),
            ),
            lower.val().to_vec(),
        );
        Ok(RestAssembly {
            free_index,
            num_free,
            mass,
            stiffness,
            inertia,
            pattern,
        })
    }

    /// Assembles `K + mass_weight M` (exact Hessians, no projection) into the pattern.
    fn assemble(&mut self, elastic: &[&dyn StencilEnergy], rest: &[f64], mass_weight: f64) {
        self.pattern
            .assemble(weighted(&self.inertia, elastic, mass_weight), rest, false);
    }

    /// `mean(K_ii / M_ii)` over the free dofs (1 if that is not positive: no stiffness).
    fn stiffness_scale(&self) -> f64 {
        let k = self.stiffness.as_ref();
        let (col_ptr, row_idx, values) = (k.symbolic().col_ptr(), k.symbolic().row_idx(), k.val());
        let mut sum = 0.0;
        for c in 0..self.num_free {
            let p = col_ptr[c] as usize;
            if p < col_ptr[c + 1] as usize && row_idx[p] as usize == c {
                sum += values[p] / self.mass[c];
            }
        }
        let mean = sum / self.num_free.max(1) as f64;
        if mean > 0.0 && mean.is_finite() {
            mean
        } else {
            1.0
        }
    }

    /// Free-dof columns spread over all dofs (zero on the prescribed ones).
    pub(crate) fn scatter(&self, free: faer::MatRef<'_, f64>) -> Mat<f64> {
        Mat::from_fn(self.free_index.len(), free.ncols(), |k, j| match self.free_index[k] {
            NOT_FREE => 0.0,
            f => free[(f, j)],
        })
    }
}

/// The pattern's terms with their weights: the inertia term (whose Hessian is `M`) with
/// `mass_weight`, each elastic term with 1.
fn weighted<'a>(
    inertia: &'a Inertia,
    elastic: &'a [&'a dyn StencilEnergy],
    mass_weight: f64,
) -> impl Iterator<Item = (&'a dyn StencilEnergy, f64)> + 'a {
    std::iter::once((inertia as &dyn StencilEnergy, mass_weight)).chain(elastic.iter().map(|e| (*e, 1.0)))
}
