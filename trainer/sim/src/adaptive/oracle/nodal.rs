//! Nodal error and progress (Trusty et al., Eqs. 7, 9-11) from the stencil terms of the
//! incremental potential.

use super::{NodeScales, OracleError, WeightedTerm};
use crate::energy::{gather, Local, StencilEnergy, Want, MAX_DOF};

/// Per-vertex measures of one oracle query.
#[derive(Clone, Debug, PartialEq)]
pub struct NodalMeasures {
    /// `ΔE_i` (Eq. 7): the decrease of the one-ring incremental-potential energy of vertex
    /// `i` under the active-subspace step `d`, `E_i(x) - E_i(x + d)`.
    pub energy_change: Vec<f64>,
    /// `G_i` (Eq. 10): one-ring gradient norm over `h² A_i H̄_i`; 0 on prescribed vertices.
    pub error: Vec<f64>,
    /// `E_i` (Eq. 11): `ΔE_i / (h² V_i H̄_i)`; 0 on prescribed vertices.
    pub progress: Vec<f64>,
}

/// For every vertex, the sorted vertices that share a stencil of `terms` with it (itself
/// included), as offsets into one flat list.
struct OneRings {
    offsets: Vec<usize>,
    vertices: Vec<usize>,
}

impl OneRings {
    fn new(n: usize, terms: &[WeightedTerm<'_>]) -> Self {
        let mut lists: Vec<Vec<usize>> = (0..n).map(|i| vec![i]).collect();
        for t in terms {
            for s in 0..t.energy.len() {
                let verts = t.energy.stencil(s);
                for &a in verts {
                    lists[a].extend_from_slice(verts);
                }
            }
        }
        let mut offsets = Vec::with_capacity(n + 1);
        let mut vertices = Vec::new();
        offsets.push(0);
        for mut l in lists {
            l.sort_unstable();
            l.dedup();
            vertices.extend(l);
            offsets.push(vertices.len());
        }
        OneRings { offsets, vertices }
    }

    /// Position of `j` in the flat list within the ring of `i`.
    fn slot(&self, i: usize, j: usize) -> usize {
        let ring = &self.vertices[self.offsets[i]..self.offsets[i + 1]];
        self.offsets[i] + ring.binary_search(&j).expect("ring holds every stencil neighbour")
    }
}

/// Checks that every term has the body's dimension and names only its vertices.
pub(super) fn check_terms(dim: usize, n: usize, terms: &[WeightedTerm<'_>]) -> Result<(), OracleError> {
    for t in terms {
        let e: &dyn StencilEnergy = t.energy;
        if e.dim() != dim {
            return Err(OracleError::Input(format!(
                "term `{}` has dim {}, the body {dim}",
                e.name(),
                e.dim()
            )));
        }
        if !t.weight.is_finite() {
            return Err(OracleError::Input(format!(
                "term `{}` has weight {}",
                e.name(),
                t.weight
            )));
        }
        for s in 0..e.len() {
            if let Some(&v) = e.stencil(s).iter().find(|&&v| v >= n) {
                return Err(OracleError::Input(format!(
                    "stencil {s} of `{}` names vertex {v}, the body has {n}",
                    e.name()
                )));
            }
        }
    }
    Ok(())
}

/// The nodal measures at positions `x` for the step `d`, with `gradient` the full
/// incremental-potential gradient at `x` and `free[v]` whether vertex `v` is free.
///
/// The one-ring gradient of vertex `i` (Eq. 9) is `g_i = Σ_{s ∋ i} w_s ∇W_s(x)`, the sum of
/// the whole gradients (every vertex's entries) of the stencils that hold `i`, each term's
/// stencils weighted as in the incremental potential (inertia's stencils are single
/// vertices). Its entry at `i` itself is `∇_{x_i} E`; the entries at the neighbours make it
/// the smoother measure the paper prefers. The part of `gradient` that the stencil terms do
/// not produce (terms without a stencil form, such as contact) is added to the entry at
/// `i`, as a single-vertex stencil of `i` would. Entries on prescribed dofs are dropped.
///
/// Units (3D, footnote 2): `E` is `K + h² Ψ` in M L², so `|g_i|₂` is in M L
/// (`h² V_e |B_e| |∂W/∂F|`: T² · L³ · L⁻¹ · M L⁻¹ T⁻²); `h² A_i H̄_i` is
/// T² · L² · M L⁻¹ T⁻² = M L as well. The norm is the plain Euclidean norm, not its
/// square: a squared norm over `h² A_i H̄_i` would keep units of M L and grow with the
/// scene's size and stiffness. Likewise `ΔE_i` is in M L² and `h² V_i H̄_i` in
/// T² · L³ · M L⁻¹ T⁻² = M L² (footnote 3).
pub(super) fn nodal_measures(
    scales: &NodeScales,
    terms: &[WeightedTerm<'_>],
    x: &[f64],
    gradient: &[f64],
    d: &[f64],
    h: f64,
    free: &[bool],
) -> NodalMeasures {
    let dim = scales.dim;
    let n = scales.num_vertices();
    let rings = OneRings::new(n, terms);
    let mut ring_grad = vec![0.0; rings.vertices.len() * dim];
    let mut own = vec![0.0; n * dim];
    let mut energy_change = vec![0.0; n];
    let x_step: Vec<f64> = x.iter().zip(d).map(|(a, b)| a + b).collect();
    let (mut out, mut scratch) = (Local::default(), Local::default());
    let (mut xl, mut xl_step) = ([0.0; MAX_DOF], [0.0; MAX_DOF]);
    for t in terms {
        let e = t.energy;
        for s in 0..e.len() {
            let len = gather(e, s, x, &mut xl);
            gather(e, s, &x_step, &mut xl_step);
            let before = e.eval(s, &xl[..len], Want::Gradient, &mut out);
            let after = e.eval(s, &xl_step[..len], Want::Value, &mut scratch);
            let change = t.weight * (before - after);
            let verts = e.stencil(s);
            for (a, &i) in verts.iter().enumerate() {
                energy_change[i] += change;
                for k in 0..dim {
                    own[i * dim + k] += t.weight * out.grad[a * dim + k];
                }
                for (b, &j) in verts.iter().enumerate() {
                    let at = rings.slot(i, j) * dim;
                    for k in 0..dim {
                        ring_grad[at + k] += t.weight * out.grad[b * dim + k];
                    }
                }
            }
        }
    }
    let mut error = vec![0.0; n];
    let mut progress = vec![0.0; n];
    for i in (0..n).filter(|&i| free[i]) {
        let mut norm2 = 0.0;
        for at in rings.offsets[i]..rings.offsets[i + 1] {
            let j = rings.vertices[at];
            if !free[j] {
                continue;
            }
            for k in 0..dim {
                let mut g = ring_grad[at * dim + k];
                if j == i {
                    g += gradient[i * dim + k] - own[i * dim + k];
                }
                norm2 += g * g;
            }
        }
        error[i] = norm2.sqrt() / scales.error_scale(i, h);
        progress[i] = energy_change[i] / scales.progress_scale(i, h);
    }
    NodalMeasures {
        energy_change,
        error,
        progress,
    }
}
