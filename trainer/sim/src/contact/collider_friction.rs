//! Lagged friction between surface vertices and kinematic colliders (IPC, Li et al. 2020,
//! Sec. 5, as [`super::friction_potential`] does for mesh pairs), as a [`StencilEnergy`].
//!
//! At the start of a solve every (vertex, collider) pair closer than `dhat` gives one
//! stencil of the vertex alone, lagged there: the normal `n` of the distance, the tangent
//! plane's basis `T` around it, the normal force `N = -kappa 2 d b'(d^2, dhat^2)`, and the
//! displacement `u_c` that the collider's motion over the step gives its surface point
//! closest to the vertex. The potential `D = mu N f0(|T^T (x - x^t - u_c)|, eps_v h)` then
//! resists the vertex's slip relative to the collider's surface: a collider that drags
//! across the body carries the vertices it presses.

use super::barrier::barrier_force_magnitude;
use super::collider::ColliderPose;
use super::collider_barrier::ColliderBarrier;
use super::friction::{point_point_tangent_basis, FrictionStencil, RelativeVelocity};
use crate::energy::{Local, StencilEnergy, Want};
use nalgebra::Vector3;

/// Lagged friction stencils of vertices against colliders.
#[derive(Clone, Debug)]
pub struct ColliderFriction {
    eps_u: f64,
    vertices: Vec<usize>,
    /// Per stencil, the lagged position plus the collider's displacement at the contact.
    anchors: Vec<[f64; 3]>,
    stencils: Vec<FrictionStencil>,
}

impl ColliderFriction {
    /// Friction with coefficient `mu` for the pairs of `barrier` within `dhat` at the lagged
    /// positions `x` (stiffness `kappa`), the colliders moving from their poses to `goals`
    /// over the step, smoothed below the displacement `eps_u` (`eps_v` times the step).
    pub fn lagged(
        barrier: &ColliderBarrier,
        x: &[f64],
        goals: &[ColliderPose],
        kappa: f64,
        mu: f64,
        eps_u: f64,
    ) -> Self {
        Self::lagged_above(barrier, x, goals, (kappa, mu, eps_u), None)
    }

    /// [`Self::lagged`] for states that may penetrate (a training loss on a network's
    /// predictions; [`ColliderBarrier::floored_value_and_gradient`]): pairs nearer than
    /// `floor`, or inside a collider, take part with the normal force at `floor` and the
    /// normal of the signed distance.
    pub fn lagged_floored(
        barrier: &ColliderBarrier,
        x: &[f64],
        goals: &[ColliderPose],
        (kappa, mu, eps_u): (f64, f64, f64),
        floor: f64,
    ) -> Self {
        Self::lagged_above(barrier, x, goals, (kappa, mu, eps_u), Some(floor))
    }

    fn lagged_above(
        barrier: &ColliderBarrier,
        x: &[f64],
        goals: &[ColliderPose],
        (kappa, mu, eps_u): (f64, f64, f64),
        floor: Option<f64>,
    ) -> Self {
        let mut out = ColliderFriction {
            eps_u,
            vertices: Vec::new(),
            anchors: Vec::new(),
            stencils: Vec::new(),
        };
        if mu <= 0.0 {
            return out;
        }
        let dhat = barrier.dhat();
        let lowest = floor.unwrap_or(0.0);
        for s in 0..barrier.len() {
            let (v, c) = barrier.pair(s);
            let collider = &barrier.colliders()[c];
            let p = &x[3 * v..3 * v + 3];
            let (d, n) = collider.signed_distance_and_gradient(p);
            if d >= dhat || (floor.is_none() && d <= 0.0) {
                continue;
            }
            let normal_force = barrier_force_magnitude(d.max(lowest).powi(2), dhat, kappa);
            if normal_force <= 0.0 {
                continue;
            }
            let here = Vector3::new(p[0], p[1], p[2]);
            let contact = here - d * n;
            let carried = collider.pose.carry(contact, &goals[c]) - contact;
            let pair = [0.0, 0.0, 0.0, n.x, n.y, n.z];
            out.vertices.push(v);
            out.anchors.push((here + carried).into());
            out.stencils.push(FrictionStencil {
                basis: point_point_tangent_basis(&pair, 3),
                relative: RelativeVelocity {
                    verts: 1,
                    weights: [1.0, 0.0, 0.0, 0.0],
                },
                normal_force,
                mu,
            });
        }
        out
    }
}

impl StencilEnergy for ColliderFriction {
    fn name(&self) -> &'static str {
        "collider friction"
    }
    fn dim(&self) -> usize {
        3
    }
    fn len(&self) -> usize {
        self.stencils.len()
    }
    fn stencil(&self, s: usize) -> &[usize] {
        &self.vertices[s..s + 1]
    }
    fn eval(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        let a = self.anchors[s];
        let u = [x[0] - a[0], x[1] - a[1], x[2] - a[2]];
        self.stencils[s].eval(&u, self.eps_u, want, out)
    }
}
