//! Per-subdomain BFGS approximations of the elastic subspace Hessian.
//!
//! Within a time step the elastic part of the unmasked subspace Hessian `Wᵀ ∇²Ψ W` is the
//! sum over the fixed element subdomains `l` of dense `a x a` matrices, each kept as a
//! running BFGS approximation: initialised from an exact evaluation, then updated at every
//! Newton iteration by the secant pair `s = q_k - q_{k-1}`, `y = Wᵀ (∇Ψ_l(x_k) -
//! ∇Ψ_l(x_{k-1}))` ([`super::elastic_subspace`] computes both). The direct (not inverse)
//! update is kept: the subspace Hessian is small and factorised anyway.
//!
//! A subdomain holding an enriched vertex is invalidated: its contribution is then
//! evaluated exactly by the caller, since a BFGS block and exactly integrated coupling
//! entries would not be consistent.
//!
//! An update whose curvature is not clearly positive (`s·y <= floor |s| |y|`) is skipped
//! and counted, which keeps every approximation symmetric positive definite.

use nalgebra::{DMatrix, DVector};

/// Default relative curvature below which an update is skipped.
pub const DEFAULT_CURVATURE_FLOOR: f64 = 1e-8;

/// What one secant update did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SecantUpdate {
    /// The approximation now satisfies `H s = y`.
    Applied,
    /// The pair's curvature was too small (or `s` was zero); nothing changed.
    Skipped,
    /// The subdomain is invalidated (exactly evaluated); nothing changed.
    Invalid,
}

/// A dense BFGS approximation of one symmetric positive definite `a x a` matrix.
#[derive(Clone, Debug)]
pub struct Bfgs {
    h: DMatrix<f64>,
    curvature_floor: f64,
    applied: usize,
    skipped: usize,
}

impl Bfgs {
    /// Starts from the symmetric part of `initial` (square), with the default curvature
    /// floor.
    ///
    /// # Panics
    /// If `initial` is not square.
    pub fn new(initial: DMatrix<f64>) -> Bfgs {
        assert!(initial.is_square(), "a BFGS approximation starts from a square matrix");
        let h = (&initial + initial.transpose()) * 0.5;
        Bfgs {
            h,
            curvature_floor: DEFAULT_CURVATURE_FLOOR,
            applied: 0,
            skipped: 0,
        }
    }

    /// The same with another relative curvature floor (`>= 0`).
    pub fn with_curvature_floor(mut self, floor: f64) -> Bfgs {
        self.curvature_floor = floor.max(0.0);
        self
    }

    /// The current approximation.
    pub fn hessian(&self) -> &DMatrix<f64> {
        &self.h
    }

    /// Size `a` of the approximated matrix.
    pub fn size(&self) -> usize {
        self.h.nrows()
    }

    /// Updates applied since the start.
    pub fn applied(&self) -> usize {
        self.applied
    }

    /// Updates skipped since the start.
    pub fn skipped(&self) -> usize {
        self.skipped
    }

    /// The BFGS update `H + y y^T / (s·y) - H s s^T H / (s·H s)` by the pair `(s, y)`
    /// (both of length `a`), or a counted skip when `s·y <= floor |s| |y|`.
    ///
    /// # Panics
    /// If `s` or `y` does not have length `a`.
    pub fn update(&mut self, s: &DVector<f64>, y: &DVector<f64>) -> SecantUpdate {
        let a = self.size();
        assert!(s.len() == a && y.len() == a, "secant pair of length {a} expected");
        let sy = s.dot(y);
        let hs = &self.h * s;
        let shs = s.dot(&hs);
        let finite = sy.is_finite() && shs.is_finite();
        if !finite || sy <= self.curvature_floor * s.norm() * y.norm() || shs <= 0.0 {
            self.skipped += 1;
            return SecantUpdate::Skipped;
        }
        self.h.ger(1.0 / sy, y, y, 1.0);
        self.h.ger(-1.0 / shs, &hs, &hs, 1.0);
        // Keep it exactly symmetric against round-off.
        for i in 0..a {
            for j in 0..i {
                let m = 0.5 * (self.h[(i, j)] + self.h[(j, i)]);
                self.h[(i, j)] = m;
                self.h[(j, i)] = m;
            }
        }
        self.applied += 1;
        SecantUpdate::Applied
    }
}

/// The elastic subspace Hessians of all subdomains: a BFGS approximation for each valid
/// one; invalidated ones are left to exact evaluation.
#[derive(Clone, Debug)]
pub struct SubdomainHessians {
    a: usize,
    subdomains: Vec<Option<Bfgs>>,
}

impl SubdomainHessians {
    /// One approximation per subdomain, each initialised from its exact `a x a` matrix.
    ///
    /// # Panics
    /// If the matrices are not all square of one size.
    pub fn new(exact: Vec<DMatrix<f64>>) -> SubdomainHessians {
        let a = exact.first().map_or(0, |m| m.nrows());
        assert!(
            exact.iter().all(|m| m.nrows() == a && m.ncols() == a),
            "every subdomain Hessian must be {a} x {a}"
        );
        SubdomainHessians {
            a,
            subdomains: exact.into_iter().map(|m| Some(Bfgs::new(m))).collect(),
        }
    }

    /// Number of subdomains.
    pub fn len(&self) -> usize {
        self.subdomains.len()
    }

    /// Whether there are no subdomains.
    pub fn is_empty(&self) -> bool {
        self.subdomains.is_empty()
    }

    /// Whether subdomain `l` still has a BFGS approximation.
    pub fn is_valid(&self, l: usize) -> bool {
        self.subdomains[l].is_some()
    }

    /// Subdomain `l`'s approximation, if it is valid.
    pub fn get(&self, l: usize) -> Option<&Bfgs> {
        self.subdomains[l].as_ref()
    }

    /// Switches subdomain `l` to exact evaluation (its approximation is dropped).
    pub fn invalidate(&mut self, l: usize) {
        self.subdomains[l] = None;
    }

    /// Restarts subdomain `l` (valid again) from its exact matrix.
    ///
    /// # Panics
    /// If `exact` is not `a x a`.
    pub fn reinitialize(&mut self, l: usize, exact: DMatrix<f64>) {
        assert!(
            exact.nrows() == self.a && exact.ncols() == self.a,
            "subdomain Hessian must be {0} x {0}",
            self.a
        );
        self.subdomains[l] = Some(Bfgs::new(exact));
    }

    /// Updates subdomain `l` by the pair `(s, y)`; an invalidated one is left as it is.
    pub fn update(&mut self, l: usize, s: &DVector<f64>, y: &DVector<f64>) -> SecantUpdate {
        match &mut self.subdomains[l] {
            Some(bfgs) => bfgs.update(s, y),
            None => SecantUpdate::Invalid,
        }
    }

    /// Sum of the valid subdomains' approximations (`a x a`).
    pub fn valid_sum(&self) -> DMatrix<f64> {
        let mut sum = DMatrix::zeros(self.a, self.a);
        for bfgs in self.subdomains.iter().flatten() {
            sum += bfgs.hessian();
        }
        sum
    }

    /// Updates skipped so far over the valid subdomains.
    pub fn skipped(&self) -> usize {
        self.subdomains.iter().flatten().map(Bfgs::skipped).sum()
    }
}
