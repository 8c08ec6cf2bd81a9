//! Energies: one definition of each, used by the solver, the training loss and evaluation.
//!
//! Every energy is a sum over *stencils* (an element, a hinge, a rod segment, a single
//! vertex). A kernel sees only the gathered positions of its stencil and returns the
//! stencil's value and, on request, its gradient and Hessian. Summation over stencils,
//! in parallel, lives here so each kernel stays a small, testable function.
//!
//! Layout conventions (all f64):
//! - global positions are flat, `dim` numbers per vertex (`x[v * dim + i]`);
//! - a stencil's local vector is vertex-major: local dof `a * dim + i` is coordinate `i`
//!   of the stencil's `a`-th vertex;
//! - local Hessians are dense, row-major, `n x n` with `n = vertices * dim <= MAX_DOF`.

pub mod external;
pub mod inertia;
pub mod rod;
pub mod shell;
mod simplex;
pub use simplex::SimplexElastic;
pub mod tet;
pub mod tri2d;

#[cfg(test)]
pub(crate) mod fd;
pub(crate) mod psd;

use rayon::prelude::*;

/// Largest number of local degrees of freedom of any stencil (4 vertices in 3D).
pub const MAX_DOF: usize = 12;

/// What an energy evaluation should produce.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Want {
    /// Only the value.
    Value,
    /// Value and gradient.
    Gradient,
    /// Value, gradient and Hessian; `project` clamps the stencil Hessian to be positive
    /// semi-definite (for Newton), otherwise the exact Hessian is returned.
    Hessian {
        /// Project each stencil Hessian onto the PSD cone.
        project: bool,
    },
}

impl Want {
    /// Whether the gradient is requested.
    pub fn gradient(self) -> bool {
        !matches!(self, Want::Value)
    }
    /// Whether the Hessian is requested, and if so whether to project it.
    pub fn hessian(self) -> Option<bool> {
        match self {
            Want::Hessian { project } => Some(project),
            _ => None,
        }
    }
}

/// Output buffers of one stencil evaluation (only the first `n` / `n * n` entries are used).
#[derive(Clone, Debug)]
pub struct Local {
    /// Local gradient, `n` entries.
    pub grad: [f64; MAX_DOF],
    /// Local Hessian, row-major `n x n`.
    pub hess: [f64; MAX_DOF * MAX_DOF],
}

impl Default for Local {
    fn default() -> Self {
        Local {
            grad: [0.0; MAX_DOF],
            hess: [0.0; MAX_DOF * MAX_DOF],
        }
    }
}

impl Local {
    /// Zeroes the first `n` gradient entries and `n * n` Hessian entries.
    pub fn clear(&mut self, n: usize) {
        self.grad[..n].fill(0.0);
        self.clear_hessian(n);
    }
    /// Zeroes the first `n * n` Hessian entries.
    pub fn clear_hessian(&mut self, n: usize) {
        self.hess[..n * n].fill(0.0);
    }
}

/// An energy written as a sum over stencils of a fixed number of vertices.
pub trait StencilEnergy: Send + Sync {
    /// Short name, for logs and per-term energy reports.
    fn name(&self) -> &'static str;
    /// Coordinates per vertex (2 or 3).
    fn dim(&self) -> usize;
    /// Number of stencils.
    fn len(&self) -> usize;
    /// Whether there are no stencils.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Global vertex indices of stencil `s` (at most `MAX_DOF / dim` of them).
    fn stencil(&self, s: usize) -> &[usize];
    /// Evaluates stencil `s` at local positions `x` (vertex-major, `stencil(s).len() * dim`
    /// numbers). Writes the gradient / Hessian into `out` when `want` asks for them
    /// (overwriting, not adding) and returns the value.
    fn eval(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64;
}

/// Gathers the local positions of stencil `s` from the global vector `x` into `local`;
/// returns the local length (`stencil(s).len() * dim`).
pub fn gather(energy: &dyn StencilEnergy, s: usize, x: &[f64], local: &mut [f64; MAX_DOF]) -> usize {
    let dim = energy.dim();
    let verts = energy.stencil(s);
    for (a, &v) in verts.iter().enumerate() {
        local[a * dim..(a + 1) * dim].copy_from_slice(&x[v * dim..(v + 1) * dim]);
    }
    verts.len() * dim
}

/// Stencils evaluated in parallel at a time; each block's results are summed in stencil order
/// before the next, so values and gradients are the same bits on any number of threads (a
/// dataset made on one machine is the bytes made on another).
const BLOCK: usize = 1024;

/// Total value of `energy` at `x`: stencils evaluated in parallel, summed in stencil order.
pub fn value(energy: &dyn StencilEnergy, x: &[f64]) -> f64 {
    let mut total = 0.0;
    in_stencil_order(energy, x, Want::Value, |v, _| v, |_, v| total += v);
    total
}

/// Adds `weight * grad energy(x)` into `grad` and returns `weight * energy(x)`: stencils
/// evaluated in parallel, their values and gradients summed in stencil order.
pub(crate) fn add_gradient(energy: &dyn StencilEnergy, weight: f64, x: &[f64], grad: &mut [f64]) -> f64 {
    let dim = energy.dim();
    let mut val = 0.0;
    let mut g = vec![0.0; grad.len()];
    in_stencil_order(
        energy,
        x,
        Want::Gradient,
        |v, out| (v, out.grad),
        |s, (v, local_grad)| {
            val += v;
            for (a, &vertex) in energy.stencil(s).iter().enumerate() {
                for i in 0..dim {
                    g[vertex * dim + i] += local_grad[a * dim + i];
                }
            }
        },
    );
    grad.iter_mut().zip(&g).for_each(|(a, b)| *a += weight * b);
    weight * val
}

/// Evaluates every stencil for `want` in parallel, a [`BLOCK`] at a time, keeps
/// `pick(value, local)` of each and hands them to `sink(stencil, picked)` in stencil order.
fn in_stencil_order<T: Send>(
    energy: &dyn StencilEnergy,
    x: &[f64],
    want: Want,
    pick: impl Fn(f64, &Local) -> T + Sync,
    mut sink: impl FnMut(usize, T),
) {
    let mut picked: Vec<T> = Vec::new();
    for start in (0..energy.len()).step_by(BLOCK) {
        let end = (start + BLOCK).min(energy.len());
        (start..end)
            .into_par_iter()
            .map_init(
                || (Local::default(), [0.0; MAX_DOF]),
                |(out, xl), s| {
                    let n = gather(energy, s, x, xl);
                    let v = energy.eval(s, &xl[..n], want, out);
                    pick(v, out)
                },
            )
            .collect_into_vec(&mut picked);
        for (k, p) in picked.drain(..).enumerate() {
            sink(start + k, p);
        }
    }
}

/// As [`add_gradient`], on the calling thread only, accumulating straight into `grad`: for
/// callers that already run many evaluations in parallel (the training loss, one sample per
/// thread), where splitting one evaluation would only add allocations. The summation order
/// is fixed, so results are bit-for-bit reproducible.
pub fn add_gradient_sequential(energy: &dyn StencilEnergy, weight: f64, x: &[f64], grad: &mut [f64]) -> f64 {
    let dim = energy.dim();
    let mut out = Local::default();
    let mut xl = [0.0; MAX_DOF];
    let mut val = 0.0;
    for s in 0..energy.len() {
        let n = gather(energy, s, x, &mut xl);
        val += energy.eval(s, &xl[..n], Want::Gradient, &mut out);
        for (a, &v) in energy.stencil(s).iter().enumerate() {
            for i in 0..dim {
                grad[v * dim + i] += weight * out.grad[a * dim + i];
            }
        }
    }
    weight * val
}

/// Evaluates every stencil's value, gradient and (optionally projected) Hessian in
/// parallel and hands them, in stencil order, to `sink(stencil, value, local)`.
///
/// The solver's sparse assembly and Hessian-vector products are built on this.
pub(crate) fn for_each_hessian(
    energy: &dyn StencilEnergy,
    x: &[f64],
    project: bool,
    sink: impl FnMut(usize, f64, &Local),
) {
    for_each_hessian_of(energy, None, x, project, sink);
}

/// [`for_each_hessian`] over the stencils `stencils` lists (all when `None`), in that order.
pub(crate) fn for_each_hessian_of(
    energy: &dyn StencilEnergy,
    stencils: Option<&[usize]>,
    x: &[f64],
    project: bool,
    mut sink: impl FnMut(usize, f64, &Local),
) {
    const CHUNK: usize = 1024;
    let len = stencils.map_or(energy.len(), <[usize]>::len);
    let stencil = |k: usize| stencils.map_or(k, |list| list[k]);
    let mut start = 0;
    let mut buf: Vec<(f64, Local)> = Vec::new();
    while start < len {
        let end = (start + CHUNK).min(len);
        (start..end)
            .into_par_iter()
            .map_init(
                || [0.0; MAX_DOF],
                |xl, k| {
                    let s = stencil(k);
                    let mut out = Local::default();
                    let n = gather(energy, s, x, xl);
                    let v = energy.eval(s, &xl[..n], Want::Hessian { project }, &mut out);
                    (v, out)
                },
            )
            .collect_into_vec(&mut buf);
        for (k, (v, out)) in buf.iter().enumerate() {
            sink(stencil(start + k), *v, out);
        }
        start = end;
    }
}
