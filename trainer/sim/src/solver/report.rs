//! What a solve reports: iterations, convergence, and where its time went.

/// What one solve did.
#[derive(Clone, Debug, Default)]
pub struct StepReport {
    /// Newton iterations taken.
    pub iterations: usize,
    /// Scaled Newton step norm of each iteration (the convergence measure).
    pub step_norms: Vec<f64>,
    /// Whether the tolerance was met.
    pub converged: bool,
    /// Iterations whose exact Hessian was indefinite, so the projected one was used.
    pub projected_iterations: usize,
    /// Objective value at the solution.
    pub objective: f64,
    /// Wall-clock seconds of the solve.
    pub seconds: f64,
    /// Contact pairs loaded at the end of the solve (0 without contact).
    pub contact_pairs: usize,
    /// Where the solve's time went.
    pub phases: SolvePhases,
    /// What the adaptive model did (with an adaptive model attached).
    pub adaptive: Option<crate::adaptive::solver::AdaptiveStepStats>,
}

/// Seconds a solve spent in each of its phases (the rest of [`StepReport::seconds`] is
/// energy and gradient evaluation and the line search's objective values).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SolvePhases {
    /// Contact broad phase: the pairs within `dhat`, and those a step's swept boxes bring together.
    pub broad_phase: f64,
    /// Continuous collision detection bounding each line-search step.
    pub ccd: f64,
    /// Hessian assembly (with contact stencils, and PSD projection where used).
    pub assembly: f64,
    /// Sparse Cholesky factorisation and solve.
    pub linear_solve: f64,
}
