//! Nodal error and progress (Trusty et al., Eqs. 7, 9-11) from the stencil terms of the
//! incremental potential.

use super::{NodeScales, OracleError, WeightedTerm};
use crate::energy::{gather, Local, StencilEnergy, Want, MAX_DOF};
use rayon::prelude::*;

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
#[derive(Clone, Debug)]
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

/// The one-rings of a body's terms and, per term and stencil, the ring slot of every
/// vertex pair `(a, b)` of the stencil (row-major), built once per oracle: the terms of a
/// simulator do not change between queries.
#[derive(Clone, Debug)]
pub(super) struct RingCache {
    /// Each term's stencil count, to tell whether a query's terms are those it was built for.
    signature: Vec<usize>,
    rings: OneRings,
    /// Per term, `offsets[s]..offsets[s + 1]` into `pairs` for stencil `s`.
    offsets: Vec<Vec<usize>>,
    pairs: Vec<Vec<usize>>,
}

impl RingCache {
    /// The cache of `terms` on a body of `n` vertices (the terms must be checked).
    pub(super) fn new(n: usize, terms: &[WeightedTerm<'_>]) -> Self {
        let rings = OneRings::new(n, terms);
        let mut offsets = Vec::with_capacity(terms.len());
        let mut pairs = Vec::with_capacity(terms.len());
        for t in terms {
            let e = t.energy;
            let mut off = Vec::with_capacity(e.len() + 1);
            let mut list = Vec::new();
            off.push(0);
            for s in 0..e.len() {
                let verts = e.stencil(s);
                for &i in verts {
                    for &j in verts {
                        list.push(rings.slot(i, j));
                    }
                }
                off.push(list.len());
            }
            offsets.push(off);
            pairs.push(list);
        }
        RingCache {
            signature: signature(terms),
            rings,
            offsets,
            pairs,
        }
    }

    /// Whether it was built for `terms`.
    pub(super) fn fits(&self, terms: &[WeightedTerm<'_>]) -> bool {
        self.signature == signature(terms)
    }
}

fn signature(terms: &[WeightedTerm<'_>]) -> Vec<usize> {
    terms.iter().map(|t| t.energy.len()).collect()
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
#[allow(clippy::too_many_arguments)]
pub(super) fn nodal_measures(
    scales: &NodeScales,
    cache: &RingCache,
    terms: &[WeightedTerm<'_>],
    x: &[f64],
    gradient: &[f64],
    d: &[f64],
    h: f64,
    free: &[bool],
) -> NodalMeasures {
    let dim = scales.dim;
    let n = scales.num_vertices();
    let rings = &cache.rings;
    let mut ring_grad = vec![0.0; rings.vertices.len() * dim];
    let mut own = vec![0.0; n * dim];
    let mut energy_change = vec![0.0; n];
    let x_step: Vec<f64> = x.iter().zip(d).map(|(a, b)| a + b).collect();
    for (t, (offsets, pairs)) in terms.iter().zip(cache.offsets.iter().zip(&cache.pairs)) {
        let e = t.energy;
        // The stencils' gradients and energy changes, in parallel; their sums below in
        // stencil order, so the measures do not depend on the thread count.
        let local: Vec<(f64, [f64; MAX_DOF])> = (0..e.len())
            .into_par_iter()
            .map_init(
                || (Local::default(), Local::default(), [0.0; MAX_DOF], [0.0; MAX_DOF]),
                |(out, scratch, xl, xl_step), s| {
                    let len = gather(e, s, x, xl);
                    gather(e, s, &x_step, xl_step);
                    let before = e.eval(s, &xl[..len], Want::Gradient, out);
                    let after = e.eval(s, &xl_step[..len], Want::Value, scratch);
                    (t.weight * (before - after), out.grad)
                },
            )
            .collect();
        for (s, (change, grad)) in local.iter().enumerate() {
            let verts = e.stencil(s);
            let slots = &pairs[offsets[s]..offsets[s + 1]];
            let len = verts.len();
            for (a, &i) in verts.iter().enumerate() {
                energy_change[i] += change;
                for k in 0..dim {
                    own[i * dim + k] += t.weight * grad[a * dim + k];
                }
                for b in 0..len {
                    let at = slots[a * len + b] * dim;
                    for k in 0..dim {
                        ring_grad[at + k] += t.weight * grad[b * dim + k];
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
