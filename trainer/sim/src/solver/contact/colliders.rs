//! Kinematic colliders in the solve: the body's surface vertices against analytic shapes
//! through [`ColliderBarrier`] (the same barrier, stiffness `kappa` and line-search bound as
//! the obstacle meshes).
//!
//! A caller gives each collider's pose at the end of the next step
//! ([`super::super::Simulator::set_collider_poses`]). As keyframed obstacles do, the
//! colliders reach it during the solve: their remaining motion is part of every Newton
//! step, the body's direction answers the push through the barrier's Hessian
//! (`H_ff d_f = -g_f - H_fo d_o`, where moving a collider rigidly by `(dc, dtheta)` acts on a
//! vertex `p` as moving the vertex by `-(dc + dtheta x (p - c))`), the CCD bound of
//! [`crate::contact::collider_ccd`] covers the colliders' motion along the path of
//! [`ColliderPose::towards`], and the line search moves them the same fraction as the body.
//! With `[contact] friction`, lagged friction ([`ColliderFriction`]) resists slip against
//! them as against meshes.

use super::Contact;
use crate::contact::collider_ccd::colliders_max_step;
use crate::contact::collider_friction::ColliderFriction;
use crate::contact::{Collider, ColliderBarrier, ColliderPose};
use crate::energy::{self, StencilEnergy};
use crate::solver::StepError;
use nalgebra::Vector3;

/// The colliders' barrier (holding their current poses), where they must be at the end
/// of the current solve when they are not there yet, and their lagged friction.
#[derive(Clone, Debug)]
pub(super) struct MovingColliders {
    pub(super) barrier: ColliderBarrier,
    pub(super) goal: Option<Vec<ColliderPose>>,
    pub(super) friction: Option<ColliderFriction>,
}

impl MovingColliders {
    /// `colliders` at their initial poses against the body's surface vertices `vertices`.
    pub(super) fn new(vertices: Vec<usize>, colliders: Vec<Collider>, dhat: f64) -> Self {
        MovingColliders {
            barrier: ColliderBarrier::new(vertices, colliders, dhat),
            goal: None,
            friction: None,
        }
    }
}

impl Contact {
    /// How many colliders the body meets.
    pub(crate) fn num_colliders(&self) -> usize {
        self.colliders.barrier.colliders().len()
    }

    /// The colliders' barrier (shapes and current poses).
    pub(crate) fn collider_barrier(&self) -> &ColliderBarrier {
        &self.colliders.barrier
    }

    /// Asks the colliders to be at `poses` by the end of the next solve.
    pub(crate) fn set_collider_goal(&mut self, poses: &[ColliderPose]) {
        let moves = poses != self.colliders.barrier.poses().as_slice();
        self.colliders.goal = moves.then(|| poses.to_vec());
    }

    /// Places the colliders at `poses` at once (no solve).
    pub(crate) fn place_colliders(&mut self, poses: &[ColliderPose]) {
        self.colliders.barrier.set_poses(poses);
        self.colliders.goal = None;
    }

    /// Where the colliders are headed in this solve (their current poses once there).
    pub(super) fn collider_goal(&self) -> Vec<ColliderPose> {
        self.colliders
            .goal
            .clone()
            .unwrap_or_else(|| self.colliders.barrier.poses())
    }

    /// Moves the colliders `alpha` of the way from `from` to their goal.
    pub(super) fn move_colliders(&mut self, from: &[ColliderPose], alpha: f64) {
        let Some(goal) = &self.colliders.goal else { return };
        let poses: Vec<ColliderPose> = from.iter().zip(goal).map(|(f, g)| f.towards(g, alpha)).collect();
        self.colliders.barrier.set_poses(&poses);
        if alpha >= 1.0 {
            self.colliders.goal = None;
        }
    }

    /// The largest fraction of the step from `x0` to `x1` (body positions) that keeps every
    /// surface vertex outside every collider moving to its goal.
    pub(super) fn collider_bound(&self, x0: &[f64], x1: &[f64]) -> f64 {
        let b = &self.colliders.barrier;
        if b.is_empty() {
            return 1.0;
        }
        colliders_max_step(b.colliders(), &self.collider_goal(), b.vertices(), x0, x1)
    }

    /// Adds into `out` (body-length) the body's part of `H_bo d_o` for the colliders'
    /// remaining motion: per vertex `-kappa H_v (dc + dtheta x (p - c))`.
    pub(super) fn add_collider_coupling(&self, x: &[f64], out: &mut [f64]) {
        let Some(goal) = &self.colliders.goal else { return };
        let b = &self.colliders.barrier;
        let k = b.colliders().len();
        let moves: Vec<(Vector3<f64>, Vector3<f64>, Vector3<f64>)> = b
            .colliders()
            .iter()
            .zip(goal)
            .map(|(c, g)| {
                let turn = (g.rotation * c.pose.rotation.inverse()).scaled_axis();
                (g.center - c.pose.center, turn, c.pose.center)
            })
            .collect();
        let kappa = self.kappa;
        energy::for_each_hessian(b, x, true, |s, _, local| {
            let v = b.stencil(s)[0];
            let (dc, turn, center) = moves[s % k];
            let p = Vector3::new(x[3 * v], x[3 * v + 1], x[3 * v + 2]);
            let carried = dc + turn.cross(&(p - center));
            for i in 0..3 {
                let row = &local.hess[3 * i..3 * i + 3];
                out[3 * v + i] -= kappa * (0..3).map(|j| row[j] * carried[j]).sum::<f64>();
            }
        });
    }

    /// Lags the colliders' friction at the body positions `x` (start of a solve) with the
    /// coefficient `mu` and smoothing displacement `eps_u`, or drops it (`None`).
    pub(super) fn lag_collider_friction(&mut self, x: &[f64], friction: Option<(f64, f64)>) {
        let goals = self.collider_goal();
        let kappa = self.kappa;
        let b = &self.colliders.barrier;
        self.colliders.friction = friction
            .filter(|_| !b.is_empty())
            .map(|(mu, eps_u)| ColliderFriction::lagged(b, x, &goals, kappa, mu, eps_u));
    }

    /// IPC's range of the barrier stiffness for this body, `(kappa_min, kappa_max)`: where a
    /// solve starts without contact, and the most it raises it to.
    pub(crate) fn stiffness_range(&self) -> (f64, f64) {
        let bounds = crate::contact::stiffness::initial_barrier_stiffness(
            self.bbox_diagonal,
            self.settings.dhat,
            self.average_mass,
            &[],
            &[],
            super::MIN_STIFFNESS_SCALE,
        );
        (bounds.min, bounds.max)
    }

    /// The smallest squared distance of a surface vertex to a collider at `x`.
    pub(super) fn collider_min_squared_distance(&self, x: &[f64]) -> f64 {
        self.colliders.barrier.min_distance(x).powi(2)
    }
}

/// The simulator's side of the colliders: what a caller asks of them.
impl crate::solver::Simulator {
    /// The analytic colliders' barrier (their shapes and current poses), if the simulator
    /// has contact.
    pub fn collider_barrier(&self) -> Option<&ColliderBarrier> {
        self.contact.as_ref().map(Contact::collider_barrier)
    }

    /// IPC's range of the barrier stiffness for this body, `(kappa_min, kappa_max)` (the
    /// solver starts a solve at or above the first and raises it up to the second as
    /// contacts close), if the simulator has contact.
    pub fn barrier_stiffness_range(&self) -> Option<(f64, f64)> {
        self.contact.as_ref().map(Contact::stiffness_range)
    }

    /// Asks the analytic colliders to be at `poses` (one per collider, in the scene's order)
    /// at the end of the next step; they move there during its solve, CCD-bounded like the
    /// body. Until called again they stay there. A list of the wrong length is refused.
    pub fn set_collider_poses(&mut self, poses: &[ColliderPose]) -> Result<(), StepError> {
        let Some(c) = &mut self.contact else {
            return Self::collider_count(0, poses.len());
        };
        Self::collider_count(c.num_colliders(), poses.len())?;
        c.set_collider_goal(poses);
        Ok(())
    }

    /// Places the analytic colliders at `poses` at once, without a solve (a sequence's first
    /// frame). A list of the wrong length is refused.
    pub fn place_colliders(&mut self, poses: &[ColliderPose]) -> Result<(), StepError> {
        let Some(c) = &mut self.contact else {
            return Self::collider_count(0, poses.len());
        };
        Self::collider_count(c.num_colliders(), poses.len())?;
        c.place_colliders(poses);
        Ok(())
    }

    fn collider_count(expected: usize, got: usize) -> Result<(), StepError> {
        if expected == got {
            Ok(())
        } else {
            Err(StepError::ColliderCount { expected, got })
        }
    }
}
