//! Additive continuous collision detection (ACCD; Li et al. 2021, *Codimensional
//! Incremental Potential Contact*).
//!
//! For a stencil moving linearly from `x0` (time 0) to `x1` (time 1), conservative
//! advancement on the distance: if every vertex of one primitive moves at most `|p_a|` and
//! every vertex of the other at most `|p_b|` per unit time, the distance between the two
//! primitives shrinks at most at rate `l_p = max |p_a| + max |p_b|`. So from a configuration
//! at distance `d` (minimum separation `xi`), the stencil can advance by
//! `eta (d - xi) / l_p` without the distance dropping below `(1 - eta) (d - xi) + xi`.
//! Repeating the advance from the new configuration adds up a lower bound on the time of
//! impact; the search stops once `d - xi` has fallen below `(1 - eta)` times its initial
//! value, the returned time being the last one at which it had not. The common mean of the
//! displacements is removed first (distances are translation invariant), which makes `l_p`
//! smaller. `d - xi` is evaluated as `(d^2 - xi^2) / (d + xi)` from the squared distances
//! of [`crate::contact::distance`].
//!
//! The result is a time at which the pair is still at least `(1 - eta) (d0 - xi)` apart,
//! not the exact time of contact: that margin is what lets a line search step right up to
//! the reported time.
//!
//! Every distance is computed with a rounding error of a few `eps` times the coordinates'
//! magnitude `L`, which matters once the distance itself is tiny (a start near contact):
//! each advance is then off by up to that error over `l_p`. The reported time is lowered by
//! [`ROUNDING_ULPS`]` eps L / l_p` per advance made to cover that rounding
//! (`scripts/check-ipctk.sh` compares the times with IPC's toolkit, which rounds
//! differently).
//!
//! **Floor.** With distances accurate to a few `eps L` (the nearly parallel edges included,
//! see [`crate::contact::distance::edge_edge`]), a crossing is never missed while the start
//! distance exceeds [`FLOOR_ULPS`]` eps L`, `L` the largest coordinate magnitude of the
//! motion: below about that, the gap is not represented by the rounded positions
//! themselves (docs/results/contact.md has the measurement).

use crate::contact::distance::{
    edge_edge_distance, point_edge_distance, point_point_distance, point_triangle_distance,
};
use crate::energy::{Local, Want};

/// Most coordinates of any stencil (edge-edge or point-triangle in 3D).
const MAX_STENCIL: usize = 12;

/// Allowance for the rounding error of one distance evaluation, in units of `eps` times the
/// largest coordinate magnitude: a bound with slack for the few products and sums of the
/// distance formulas (measured: under one unit for a point 1e-12 .. 1e-9 off an edge). At a
/// distance of 1e-4 and coordinates near 1 it lowers a time of impact by a relative 2e-11.
pub const ROUNDING_ULPS: f64 = 8.0;

/// The start distance, in units of `eps` times the largest coordinate magnitude, above
/// which no crossing with a time of impact in `(0, tmax]` is reported as "no impact"
/// (3.6e-15 for coordinates near one; the largest start gap missed in the measurement was
/// 1.8e-15).
pub const FLOOR_ULPS: f64 = 16.0;

/// Parameters of additive CCD. The defaults are those of IPC's toolkit (`ipctk`'s
/// `AdditiveCCD`), which `scripts/check-ipctk.sh` compares against.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdditiveCcd {
    /// `eta` in `(0, 1]`: each advance may close this fraction of the remaining distance,
    /// and a collision is reported once `d - xi` is below `1 - eta` of its initial value.
    pub conservative_rescaling: f64,
    /// Advances after which the search gives up and reports the time reached as the time
    /// of impact (conservative: only pairs sliding along each other at a tiny distance
    /// need this many).
    pub max_iterations: usize,
}

impl Default for AdditiveCcd {
    fn default() -> Self {
        AdditiveCcd {
            conservative_rescaling: 0.9,
            max_iterations: 10_000_000,
        }
    }
}

/// Which primitive pair a stencil holds: how its squared distance is computed and where the
/// first primitive's vertices end (for `l_p`).
#[derive(Clone, Copy, Debug)]
enum Pair {
    PointPoint,
    PointEdge,
    PointTriangle,
    EdgeEdge,
}

impl Pair {
    fn vertices(self) -> (usize, usize) {
        match self {
            Pair::PointPoint => (1, 2),
            Pair::PointEdge => (1, 3),
            Pair::PointTriangle => (1, 4),
            Pair::EdgeEdge => (2, 4),
        }
    }

    fn squared_distance(self, x: &[f64], dim: usize, scratch: &mut Local) -> f64 {
        match self {
            Pair::PointPoint => point_point_distance(x, dim, Want::Value, scratch),
            Pair::PointEdge => point_edge_distance(x, dim, Want::Value, scratch),
            Pair::PointTriangle => point_triangle_distance(x, Want::Value, scratch),
            Pair::EdgeEdge => edge_edge_distance(x, Want::Value, scratch),
        }
    }
}

impl AdditiveCcd {
    /// Time of impact in `[0, tmax]` of two points `x = [p0, p1]` (`dim` 2 or 3) moving from
    /// `x0` to `x1`, kept `min_distance` apart; `None` if they do not come closer than that
    /// before `tmax`.
    pub fn point_point(&self, x0: &[f64], x1: &[f64], dim: usize, min_distance: f64, tmax: f64) -> Option<f64> {
        self.time_of_impact(Pair::PointPoint, x0, x1, dim, min_distance, tmax)
    }

    /// As [`Self::point_point`] for a point and an edge, `x = [p, e0, e1]` (`dim` 2 or 3).
    pub fn point_edge(&self, x0: &[f64], x1: &[f64], dim: usize, min_distance: f64, tmax: f64) -> Option<f64> {
        self.time_of_impact(Pair::PointEdge, x0, x1, dim, min_distance, tmax)
    }

    /// As [`Self::point_point`] for a point and a triangle, `x = [p, t0, t1, t2]` (3D).
    pub fn point_triangle(&self, x0: &[f64], x1: &[f64], min_distance: f64, tmax: f64) -> Option<f64> {
        self.time_of_impact(Pair::PointTriangle, x0, x1, 3, min_distance, tmax)
    }

    /// As [`Self::point_point`] for two edges, `x = [ea0, ea1, eb0, eb1]` (3D).
    pub fn edge_edge(&self, x0: &[f64], x1: &[f64], min_distance: f64, tmax: f64) -> Option<f64> {
        self.time_of_impact(Pair::EdgeEdge, x0, x1, 3, min_distance, tmax)
    }

    fn time_of_impact(
        &self,
        pair: Pair,
        x0: &[f64],
        x1: &[f64],
        dim: usize,
        min_distance: f64,
        tmax: f64,
    ) -> Option<f64> {
        let (split, verts) = pair.vertices();
        let n = verts * dim;
        assert!(
            x0.len() == n && x1.len() == n && n <= MAX_STENCIL,
            "stencil of {n} coordinates"
        );
        let mut scratch = Local::default();
        let xi2 = min_distance * min_distance;
        let d2 = pair.squared_distance(x0, dim, &mut scratch);
        if d2.is_nan() || d2 <= xi2 {
            // Already within the minimum separation (or not a number): no step is safe.
            return Some(0.0);
        }
        // Displacements less their mean; l_p bounds how fast the distance can shrink.
        let mut dx = [0.0; MAX_STENCIL];
        for ((d, a), b) in dx.iter_mut().zip(x0).zip(x1) {
            *d = b - a;
        }
        for k in 0..dim {
            let mean = (0..verts).map(|a| dx[a * dim + k]).sum::<f64>() / verts as f64;
            for a in 0..verts {
                dx[a * dim + k] -= mean;
            }
        }
        if dx[..n].iter().any(|v| !v.is_finite()) {
            return Some(0.0);
        }
        let norm = |a: usize| dx[a * dim..(a + 1) * dim].iter().map(|v| v * v).sum::<f64>().sqrt();
        let largest = |r: std::ops::Range<usize>| r.map(norm).fold(0.0, f64::max);
        let lp = largest(0..split) + largest(split..verts);
        if lp == 0.0 {
            return None;
        }
        let mut x = [0.0; MAX_STENCIL];
        let eta = self.conservative_rescaling;
        let mut d = d2.sqrt();
        let mut excess = d2 - xi2; // d^2 - xi^2
        let gap = (1.0 - eta) * excess / (d + min_distance);
        let scale = x0.iter().chain(x1).fold(0.0f64, |m, v| m.max(v.abs()));
        let per_advance = ROUNDING_ULPS * f64::EPSILON * scale / lp;
        let lowered = |t: f64, advances: usize| Some((t - per_advance * advances as f64).max(0.0));
        let mut t = 0.0;
        for k in 0..self.max_iterations {
            let advance = eta * excess / ((d + min_distance) * lp);
            // The positions at the new time from the start, not by adding the advances up:
            // over millions of advances (edges sliding along each other at a tiny distance)
            // the sum's rounding drifts by more than the gap.
            let next = t + advance;
            for ((xk, start), dk) in x.iter_mut().zip(x0).zip(&dx).take(n) {
                *xk = start + next * dk;
            }
            let d2 = pair.squared_distance(&x[..n], dim, &mut scratch);
            d = d2.sqrt();
            excess = d2 - xi2;
            // The advance is sized so the distance cannot fall below the gap; the second
            // test catches rounding (or a non-number) on the very first advance.
            if (t > 0.0 && excess / (d + min_distance) < gap) || excess.is_nan() || excess <= 0.0 {
                return lowered(t, k + 1);
            }
            t = next;
            if t > tmax {
                return None;
            }
        }
        lowered(t, self.max_iterations)
    }
}
