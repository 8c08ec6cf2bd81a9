//! The barrier potential of a contact surface: `B(x) = sum_k b(d_k^2(x), dhat^2)` over the
//! candidate pairs (point-triangle and mollified edge-edge in 3D, point-edge in 2D), as a
//! [`StencilEnergy`] (unscaled: the solver multiplies it by the stiffness `kappa`).
//!
//! Contact stencils are not fixed like elements: they are the pairs the broad phase finds
//! near the current positions. The potential therefore keeps a stencil list that
//! [`BarrierPotential::set_candidates`] rebuilds before evaluations at new positions; between
//! rebuilds it is an ordinary [`StencilEnergy`], so the energy module's parallel value,
//! gradient and Hessian sums and its finite-difference checks serve it unchanged. The list
//! must hold every pair closer than `dhat` at the positions evaluated (pairs farther away
//! contribute zero): the pairs within `dhat` of one configuration, or those whose boxes
//! swept over a step come within `dhat`, for every point of that step.
//!
//! Each candidate is a stencil of its own with its closest features classified at every
//! evaluation. A point near an edge shared by two triangles is thus counted by both
//! (IPC's toolkit merges such duplicates into one point-edge pair): the barrier is then
//! up to twice as stiff there, which changes no guarantee.

use super::barrier::{barrier_of_squared_distance, edge_edge_barrier};
use super::broad_phase::Candidates;
use super::distance::{
    edge_edge_distance, edge_edge_mollifier_threshold, point_edge_distance, point_triangle_distance,
};
use super::ContactSurface;
use crate::energy::{Local, StencilEnergy, Want};

/// Which primitive pair a stencil holds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PairKind {
    /// `[p, t0, t1, t2]`, 3D.
    PointTriangle,
    /// `[ea0, ea1, eb0, eb1]`, 3D, with the mollifier threshold `eps_x` of the rest edges.
    EdgeEdge {
        /// The rest-based mollifier threshold.
        eps_x: f64,
    },
    /// `[p, e0, e1]`, 2D.
    PointEdge,
}

/// IPC's barrier over a contact surface's candidate pairs.
pub struct BarrierPotential {
    dim: usize,
    dhat: f64,
    surface: ContactSurface,
    rest: Vec<f64>,
    stencils: Vec<[usize; 4]>,
    kinds: Vec<PairKind>,
}

impl BarrierPotential {
    /// A barrier with activation distance `dhat` over `surface`, whose rest positions
    /// `rest` set the edge-edge mollifier thresholds. It starts with no stencils.
    pub fn new(surface: ContactSurface, rest: Vec<f64>, dhat: f64) -> Self {
        BarrierPotential {
            dim: surface.dim,
            dhat,
            surface,
            rest,
            stencils: Vec::new(),
            kinds: Vec::new(),
        }
    }

    /// The activation distance.
    pub fn dhat(&self) -> f64 {
        self.dhat
    }

    /// The contact surface.
    pub fn surface(&self) -> &ContactSurface {
        &self.surface
    }

    /// Replaces the stencils by the candidate pairs.
    pub fn set_candidates(&mut self, candidates: &Candidates) {
        self.stencils.clear();
        self.kinds.clear();
        let s = &self.surface;
        for &[v, f] in &candidates.point_triangle {
            let t = s.faces[f];
            self.stencils.push([v, t[0], t[1], t[2]]);
            self.kinds.push(PairKind::PointTriangle);
        }
        for &[i, j] in &candidates.edge_edge {
            let (a, b) = (s.edges[i], s.edges[j]);
            let verts = [a[0], a[1], b[0], b[1]];
            let mut rest = [0.0; 12];
            for (k, &v) in verts.iter().enumerate() {
                rest[3 * k..3 * k + 3].copy_from_slice(&self.rest[3 * v..3 * v + 3]);
            }
            self.stencils.push(verts);
            self.kinds.push(PairKind::EdgeEdge {
                eps_x: edge_edge_mollifier_threshold(&rest),
            });
        }
        for &[v, e] in &candidates.point_edge {
            let edge = s.edges[e];
            self.stencils.push([v, edge[0], edge[1], usize::MAX]);
            self.kinds.push(PairKind::PointEdge);
        }
    }

    /// The kind of stencil `s`.
    pub fn kind(&self, s: usize) -> PairKind {
        self.kinds[s]
    }

    /// Squared distance of stencil `s` at its local positions `x` (unmollified).
    pub fn squared_distance(&self, s: usize, x: &[f64]) -> f64 {
        let mut scratch = Local::default();
        match self.kinds[s] {
            PairKind::PointTriangle => point_triangle_distance(x, Want::Value, &mut scratch),
            PairKind::EdgeEdge { .. } => edge_edge_distance(x, Want::Value, &mut scratch),
            PairKind::PointEdge => point_edge_distance(x, self.dim, Want::Value, &mut scratch),
        }
    }

    /// The smallest squared distance over the stencils at positions `x` (infinite if there
    /// are none).
    pub fn min_squared_distance(&self, x: &[f64]) -> f64 {
        let mut xl = [0.0; crate::energy::MAX_DOF];
        (0..self.len())
            .map(|s| {
                let n = crate::energy::gather(self, s, x, &mut xl);
                self.squared_distance(s, &xl[..n])
            })
            .fold(f64::INFINITY, f64::min)
    }
}

impl StencilEnergy for BarrierPotential {
    fn name(&self) -> &'static str {
        "contact barrier"
    }
    fn dim(&self) -> usize {
        self.dim
    }
    fn len(&self) -> usize {
        self.stencils.len()
    }
    fn stencil(&self, s: usize) -> &[usize] {
        match self.kinds[s] {
            PairKind::PointEdge => &self.stencils[s][..3],
            _ => &self.stencils[s],
        }
    }
    fn eval(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        let n = x.len();
        let d2 = match self.kinds[s] {
            PairKind::EdgeEdge { eps_x } => return edge_edge_barrier(x, eps_x, self.dhat, want, out),
            PairKind::PointTriangle => point_triangle_distance(x, want, out),
            PairKind::PointEdge => point_edge_distance(x, self.dim, want, out),
        };
        if d2 >= self.dhat * self.dhat {
            out.clear(n);
            return 0.0;
        }
        barrier_of_squared_distance(d2, n, self.dhat, want, out)
    }
}
