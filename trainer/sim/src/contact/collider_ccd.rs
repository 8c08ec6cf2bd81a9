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
