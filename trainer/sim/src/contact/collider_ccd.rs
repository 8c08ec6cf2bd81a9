//! The largest collision-free fraction of a step between vertices and moving colliders:
//! conservative advancement on the analytic distance (as the additive CCD of
//! [`super::ccd`] does on primitive distances).
//!
//! Over a step a vertex moves on the line from `p0` to `p1` while a collider moves from
//! pose `P0` to pose `P1` as [`ColliderPose::towards`] moves it: its centre on the line from
//! `c0` to `c1`, its rotation at the constant angular velocity `w` (the rotation vector
//! from `R0` to `R1`). In the collider's own frame the vertex is at `q = R^T (p - c)`, whose
//! speed is that of the vertex relative to the collider's rigid motion at it,
//! `|dp - dc - w x (p - c)|` with `p - c = (p0 - c0) + t (dp - dc)`, so at most
//! `L = |dp - dc - w x (p0 - c0)| + |w| |dp - dc|` over the step (`w` is left out for a
//! sphere, which a rotation about its centre leaves in place). The distance to the shape is
//! 1-Lipschitz in `q`, so it shrinks at most at the rate `L`. A vertex that the Newton step
//! carries along with the collider thus has `L` near zero and is not held back. From a time
//! where the distance is `d`, the step may advance by `eta d / L` and the distance stays
//! above `(1 - eta) d`. Advances add up until the distance has fallen below `(1 - eta)`
//! times its start value; the time returned is the end of that last advance, so at every
//! time up to it the vertex is outside the collider by at least `(1 - eta)^2` of its start
//! distance. The bound is conservative (the distance rarely shrinks at the rate `L`), never
//! optimistic.
//!
//! Without a turn (translations only, or any motion of a sphere) the vertex moves on a
//! straight line in the collider's frame, and the distance to a convex shape is a convex
//! function of the time: the bound is then found exactly (to `1e-13` of the step) as the
//! first time the distance falls to `(1 - eta)` of its start value, by a golden-section
//! search for its minimum and a bisection. A vertex sliding along a collider at a tiny
//! distance, which conservative advancement would hold back to tiny advances, then takes
//! its whole step.

use super::collider::{Collider, ColliderPose, ColliderShape};
use nalgebra::Vector3;

/// `eta`: each advance closes at most this share of the remaining distance (IPC toolkit's
/// additive CCD uses the same 0.9).
pub const CONSERVATIVE_RESCALING: f64 = 0.9;

/// Advances after which the search stops and reports the time reached (a vertex sliding
/// along a collider at a tiny distance makes tiny advances).
pub const MAX_ADVANCES: usize = 100_000;

/// The largest `t` in `[0, 1]` up to which the vertex moving from `p0` to `p1` stays outside
/// `collider` moving from its pose to `to` (`1` when the step cannot bring them within
/// `(1 - eta)` of their start distance; `0` when the vertex starts inside or touching, or a
/// number is not finite).
pub fn collider_max_step(collider: &Collider, to: &ColliderPose, p0: &[f64], p1: &[f64]) -> f64 {
    let from = collider.pose;
    let d0 = collider.signed_distance(p0);
    let finite = p0.iter().chain(p1).all(|v| v.is_finite());
    if !(finite && d0 > 0.0) {
        return 0.0;
    }
    let (a, b) = (Vector3::new(p0[0], p0[1], p0[2]), Vector3::new(p1[0], p1[1], p1[2]));
    let relative = (b - a) - (to.center - from.center);
    let w = match collider.shape {
        ColliderShape::Sphere { .. } => Vector3::zeros(),
        _ => (to.rotation * from.rotation.inverse()).scaled_axis(),
    };
    let rate = (relative - w.cross(&(a - from.center))).norm() + w.norm() * relative.norm();
    if !rate.is_finite() {
        return 0.0;
    }
    let eta = CONSERVATIVE_RESCALING;
    if rate <= eta * d0 {
        return 1.0;
    }
    let floor = (1.0 - eta) * d0;
    if w == Vector3::zeros() {
        // No turn that matters: the vertex moves on a line in the collider's frame.
        let q0 = from.rotation.inverse() * (a - from.center);
        let q1 = q0 + from.rotation.inverse() * relative;
        return straight_max_step(&collider.shape, q0, q1, floor);
    }
    let (mut t, mut d) = (0.0, d0);
    let mut at = *collider;
    for _ in 0..MAX_ADVANCES {
        let next = t + eta * d / rate;
        if next >= 1.0 {
            // The last advance covers the rest of the step.
            return 1.0;
        }
        at.pose = from.towards(to, next);
        let p = [0, 1, 2].map(|i| p0[i] + next * (p1[i] - p0[i]));
        let dn = at.signed_distance(&p);
        if dn.is_nan() || dn <= 0.0 {
            return t;
        }
        if dn < floor {
            // The advance kept the distance above `(1 - eta)` of its value at `t`, itself
            // above the floor: the whole advance is safe, and the search ends.
            return next;
        }
        (t, d) = (next, dn);
    }
    t
}

/// The largest `t` in `[0, 1]` that keeps every vertex `vertices` (3 coordinates each in
/// `x0`, `x1`) outside every collider of `colliders` moving to `goals` (one pose each).
pub fn colliders_max_step(
    colliders: &[Collider],
    goals: &[ColliderPose],
    vertices: &[usize],
    x0: &[f64],
    x1: &[f64],
) -> f64 {
    let mut t: f64 = 1.0;
    for (c, goal) in colliders.iter().zip(goals) {
        for &v in vertices {
            let r = 3 * v..3 * v + 3;
            t = t.min(collider_max_step(c, goal, &x0[r.clone()], &x1[r]));
            if t == 0.0 {
                return 0.0;
            }
        }
    }
    t
}

/// Iterations of the golden-section and bisection searches: the step is found to within
/// `0.618^60` (1e-13) of its length.
const SEARCH_ITERATIONS: usize = 60;

/// The largest `t` in `[0, 1]` up to which the point on the line from `q0` to `q1` (in the
/// shape's frame) stays at least `floor` outside `shape`. The signed distance to a convex
/// shape is convex along a line, so it is at least `floor` on one interval from `t = 0`:
/// where its minimum over `[0, 1]` (golden-section search) is above `floor` the whole step
/// is allowed; otherwise the distance falls through `floor` once before the minimum, which
/// a bisection brackets from the side where it holds.
fn straight_max_step(shape: &ColliderShape, q0: Vector3<f64>, q1: Vector3<f64>, floor: f64) -> f64 {
    let d = |t: f64| shape.signed_distance_local(q0 + t * (q1 - q0));
    if d(1.0) < floor || d(0.5) < floor {
        return bisect(&d, 0.0, if d(0.5) < floor { 0.5 } else { 1.0 }, floor);
    }
    let ratio = 0.5 * (5f64.sqrt() - 1.0);
    let (mut lo, mut hi) = (0.0, 1.0);
    let (mut x1, mut x2) = (hi - ratio * (hi - lo), lo + ratio * (hi - lo));
    let (mut f1, mut f2) = (d(x1), d(x2));
    for _ in 0..SEARCH_ITERATIONS {
        if f1.min(f2) < floor {
            let below = if f1 < floor { x1 } else { x2 };
            return bisect(&d, 0.0, below, floor);
        }
        if f1 < f2 {
            hi = x2;
            (x2, f2) = (x1, f1);
            x1 = hi - ratio * (hi - lo);
            f1 = d(x1);
        } else {
            lo = x1;
            (x1, f1) = (x2, f2);
            x2 = lo + ratio * (hi - lo);
            f2 = d(x2);
        }
    }
    1.0
}

/// The largest `t` found in `[lo, hi]` with `d(t) >= floor`, where `d(lo) >= floor > d(hi)`.
fn bisect(d: &dyn Fn(f64) -> f64, mut lo: f64, mut hi: f64, floor: f64) -> f64 {
    for _ in 0..SEARCH_ITERATIONS {
        let mid = 0.5 * (lo + hi);
        if d(mid) >= floor {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}
