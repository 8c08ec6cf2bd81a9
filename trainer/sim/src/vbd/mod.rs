//! Vertex Block Descent (Chen et al. 2024): the implicit-Euler incremental potential
//! minimised by block coordinate descent over vertices.
//!
//! Each iteration sweeps the vertices colour by colour (Gauss-Seidel across colours);
//! a vertex's update is one Newton step on its own `dim x dim` block,
//! `dx_i = -H_i^{-1} g_i`, where `g_i` and `H_i` are the gradient and diagonal Hessian
//! block of the incremental potential with respect to that vertex alone. They sum, over the
//! stencils that touch the vertex, each term's own stencil gradient and Hessian
//! ([`crate::energy`]: inertia `m_i (x_i - xhat_i)` and `m_i I` from the inertia term, the
//! elastic and external terms weighted by `dt^2`), so there is no second copy of any
//! energy. Vertices of one colour share no stencil, so their updates are independent:
//! they are computed in parallel (rayon) from the positions at the start of the colour and
//! then applied. After each sweep the paper's Chebyshev semi-iterative acceleration mixes
//! the sweep's result with the iterate two sweeps back.
//!
//! A fixed point has `g_i = 0` at every free vertex, the full-space implicit Euler step, so
//! with enough iterations the result is the Newton solver's. Prescribed vertices sit at
//! their targets and take no colour. IPC contact is not handled (a scene with `[contact]`
//! refuses this solver); the analytic-obstacle collision energy is an ordinary
//! single-vertex term and is.

mod block;
mod colouring;
#[cfg(test)]
mod tests;

pub use block::{block_step, vertex_block, vertex_step, WeightedTerm};
pub use colouring::{colour_vertices, Adjacency, Incidence};

use crate::energy::StencilEnergy;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Settings of Vertex Block Descent (`[solver] kind = "vbd"`); every field has the default
/// named in its documentation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VbdSettings {
    /// Sweeps over all colours per time step (default 20). VBD runs a fixed number of
    /// iterations, as in the paper; more iterations come closer to the exact implicit Euler
    /// step.
    pub iterations: usize,
    /// `rho`, the estimated spectral radius of the Chebyshev acceleration, in `[0, 1)`
    /// (default 0.95, the paper's example value; 0 turns the acceleration off). Too large a
    /// value for a scene can make the iterations oscillate.
    pub rho: f64,
    /// Where each step's iterations start (default `adaptive`, the paper's choice).
    pub initial_guess: InitialGuess,
}

impl Default for VbdSettings {
    fn default() -> Self {
        VbdSettings {
            iterations: 20,
            rho: 0.95,
            initial_guess: InitialGuess::Adaptive,
        }
    }
}

impl VbdSettings {
    /// The first setting out of range, as `(field, message)`.
    pub fn invalid(&self) -> Option<(String, String)> {
        if self.iterations == 0 {
            return Some(("iterations".into(), "must be at least 1".into()));
        }
        if !(0.0..1.0).contains(&self.rho) {
            return Some(("rho".into(), format!("must be in [0, 1), got {}", self.rho)));
        }
        None
    }
}

/// The initial guess of a time step's iterations (Chen et al., Sec. 3.7), with `x`, `v` the
/// current positions and velocities, `h` the time step and `a_ext` each vertex's external
/// acceleration (gravity and loads over its mass).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum InitialGuess {
    /// `x`: the current positions.
    Previous,
    /// `x + h v`: the inertial prediction.
    Inertia,
    /// `x + h v + h^2 a_ext`: the inertial prediction with the full external acceleration.
    External,
    /// `x + h v + h^2 a~`, `a~ = alpha a_ext` per vertex with `alpha` the last step's
    /// acceleration `(v - v_prev) / h` along `a_ext`, over `|a_ext|`, clamped to `[0, 1]`:
    /// a falling vertex starts where free fall takes it, a resting one where it is.
    #[default]
    Adaptive,
}

/// The initial guess `mode` for a step of length `h` from positions `x`, velocities `v`,
/// the previous step's velocities `v_prev` and the external accelerations `a_ext` (all flat,
/// `dim` per vertex).
pub fn initial_guess(
    mode: InitialGuess,
    dim: usize,
    h: f64,
    x: &[f64],
    v: &[f64],
    v_prev: &[f64],
    a_ext: &[f64],
) -> Vec<f64> {
    let mut out: Vec<f64> = match mode {
        InitialGuess::Previous => return x.to_vec(),
        _ => x.iter().zip(v).map(|(x, v)| x + h * v).collect(),
    };
    for (i, o) in out.chunks_exact_mut(dim).enumerate() {
        let range = i * dim..(i + 1) * dim;
        let a = &a_ext[range.clone()];
        let alpha = match mode {
            InitialGuess::Previous | InitialGuess::Inertia => 0.0,
            InitialGuess::External => 1.0,
            InitialGuess::Adaptive => {
                let norm = a.iter().map(|c| c * c).sum::<f64>().sqrt();
                if norm == 0.0 {
                    0.0
                } else {
                    let along: f64 = (0..dim)
                        .map(|k| (v[range.start + k] - v_prev[range.start + k]) / h * a[k])
                        .sum();
                    (along / (norm * norm)).clamp(0.0, 1.0)
                }
            }
        };
        for k in 0..dim {
            o[k] += h * h * alpha * a[k];
        }
    }
    out
}

/// The Chebyshev weight `omega_n` of iteration `n` (1-based) after `previous`
/// (`omega_{n-1}`): `omega_1 = 1`, `omega_2 = 2 / (2 - rho^2)`,
/// `omega_n = 4 / (4 - rho^2 omega_{n-1})`.
pub fn chebyshev_omega(n: usize, rho: f64, previous: f64) -> f64 {
    match n {
        0 | 1 => 1.0,
        2 => 2.0 / (2.0 - rho * rho),
        _ => 4.0 / (4.0 - rho * rho * previous),
    }
}

/// What one VBD solve did.
#[derive(Clone, Debug, Default)]
pub struct VbdSolve {
    /// Largest coordinate change of each iteration (after acceleration) over `norm_scale`.
    pub step_norms: Vec<f64>,
    /// Block updates that fell back to projected stencil Hessians or were skipped, summed
    /// over the iterations.
    pub fallback_blocks: usize,
}

/// Vertex Block Descent over a fixed list of terms: their vertex-to-stencil adjacency and the
/// colouring of the free vertices.
#[derive(Clone, Debug)]
pub struct VertexBlockDescent {
    settings: VbdSettings,
    dim: usize,
    adjacency: Adjacency,
    colours: Vec<Vec<usize>>,
}

impl VertexBlockDescent {
    /// VBD over `terms` (the same terms, in the same order, that [`Self::solve`] is given
    /// with their weights) on `free.len()` vertices, those with `free[v]` unset prescribed.
    pub fn new(settings: VbdSettings, dim: usize, terms: &[&dyn StencilEnergy], free: &[bool]) -> Self {
        let adjacency = Adjacency::new(free.len(), terms);
        let colours = colour_vertices(&adjacency, terms, free);
        VertexBlockDescent {
            settings,
            dim,
            adjacency,
            colours,
        }
    }

    /// The settings.
    pub fn settings(&self) -> &VbdSettings {
        &self.settings
    }

    /// The free vertices of each colour.
    pub fn colours(&self) -> &[Vec<usize>] {
        &self.colours
    }

    /// The vertex-to-stencil adjacency.
    pub fn adjacency(&self) -> &Adjacency {
        &self.adjacency
    }

    /// Runs `iterations` sweeps (the settings' count when `None`) on `x`, which holds the
    /// initial guess with the prescribed vertices at their targets, minimising
    /// `sum_t w_t E_t` over `terms` (as given to [`Self::new`]). Each iteration's largest
    /// coordinate change is divided by `norm_scale`. A non-finite update stops it with the
    /// iteration's index as the error.
    pub fn solve(
        &self,
        terms: &[WeightedTerm],
        x: &mut [f64],
        norm_scale: f64,
        iterations: Option<usize>,
    ) -> Result<VbdSolve, usize> {
        let dim = self.dim;
        let iterations = iterations.unwrap_or(self.settings.iterations);
        let rho = self.settings.rho;
        let mut report = VbdSolve::default();
        let mut prev = x.to_vec();
        let mut prev2 = x.to_vec();
        let mut omega = 1.0;
        let mut updates: Vec<([f64; block::MAX_DIM], bool)> = Vec::new();
        for n in 1..=iterations {
            for colour in &self.colours {
                let at: &[f64] = x;
                colour
                    .par_iter()
                    .map(|&v| vertex_step(terms, &self.adjacency, dim, v, at))
                    .collect_into_vec(&mut updates);
                for (&v, (dx, fell_back)) in colour.iter().zip(&updates) {
                    report.fallback_blocks += usize::from(*fell_back);
                    for k in 0..dim {
                        x[v * dim + k] += dx[k];
                    }
                }
            }
            omega = chebyshev_omega(n, rho, omega);
            let mut change = 0.0f64;
            for colour in &self.colours {
                for &v in colour {
                    for k in v * dim..(v + 1) * dim {
                        if omega != 1.0 {
                            x[k] = omega * (x[k] - prev2[k]) + prev2[k];
                        }
                        change = change.max((x[k] - prev[k]).abs());
                    }
                }
            }
            if !change.is_finite() {
                return Err(n - 1);
            }
            report.step_norms.push(change / norm_scale);
            std::mem::swap(&mut prev, &mut prev2);
            prev.copy_from_slice(x);
        }
        Ok(report)
    }
}
