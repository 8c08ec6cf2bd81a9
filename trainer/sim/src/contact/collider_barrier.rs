//! The barrier between a body's surface vertices and analytic colliders:
//! `B(x) = sum_v sum_c b(d_c^2(x_v), dhat^2)` with `d_c` the distance of vertex `v` to
//! collider `c` ([`super::collider`]) and `b` IPC's barrier ([`super::barrier`]), as a
//! [`StencilEnergy`] (unscaled: the solver multiplies it by the stiffness `kappa`).
//!
//! This is the one definition of the collider contact energy: the full-space solver adds
//! it to the incremental potential, and a training loss evaluates the same type on decoded
//! positions (value, gradient and Hessian through [`crate::energy`]'s sums). Each stencil
//! is one (vertex, collider) pair, all of them always: an analytic distance costs a few
//! dozen operations, so no broad phase is needed for the handful of colliders a scene
//! holds, and pairs farther than `dhat` contribute exact zeros.
//!
//! The colliders act on vertices only: an edge or a face of the body can still cut into a
//! collider between its vertices by about the sagitta of the shape over an edge. Shapes much
//! larger than the body's surface edges keep that small.

use super::barrier::barrier_of_squared_distance;
use super::collider::{Collider, ColliderPose, ColliderShape};
use crate::energy::{Local, StencilEnergy, Want};

/// IPC's barrier between surface vertices and kinematic colliders.
#[derive(Clone, Debug, PartialEq)]
pub struct ColliderBarrier {
    dhat: f64,
    vertices: Vec<usize>,
    colliders: Vec<Collider>,
}

impl ColliderBarrier {
    /// A barrier with activation distance `dhat` between the vertices `vertices` (indices
    /// into the position vectors it is evaluated at, 3 coordinates per vertex) and
    /// `colliders`.
    pub fn new(vertices: Vec<usize>, colliders: Vec<Collider>, dhat: f64) -> Self {
        ColliderBarrier {
            dhat,
            vertices,
            colliders,
        }
    }

    /// The activation distance.
    pub fn dhat(&self) -> f64 {
        self.dhat
    }

    /// The vertices the colliders act on.
    pub fn vertices(&self) -> &[usize] {
        &self.vertices
    }

    /// The colliders at their current poses.
    pub fn colliders(&self) -> &[Collider] {
        &self.colliders
    }

    /// The colliders' shapes.
    pub fn shapes(&self) -> Vec<ColliderShape> {
        self.colliders.iter().map(|c| c.shape).collect()
    }

    /// The colliders' current poses.
    pub fn poses(&self) -> Vec<ColliderPose> {
        self.colliders.iter().map(|c| c.pose).collect()
    }

    /// Moves the colliders to `poses` (one per collider, in order).
    pub fn set_poses(&mut self, poses: &[ColliderPose]) {
        assert_eq!(poses.len(), self.colliders.len(), "one pose per collider");
        for (c, p) in self.colliders.iter_mut().zip(poses) {
            c.pose = *p;
        }
    }

    /// The vertex and the collider of stencil `s`.
    pub fn pair(&self, s: usize) -> (usize, usize) {
        let k = self.colliders.len();
        (self.vertices[s / k], s % k)
    }

    /// The smallest distance of any vertex to any collider at positions `x` (infinite
    /// without colliders or vertices).
    pub fn min_distance(&self, x: &[f64]) -> f64 {
        self.min_signed_distance(x).max(0.0)
    }

    /// The smallest signed distance of any vertex to any collider's surface at positions
    /// `x` (negative: the depth of the deepest vertex inside one).
    pub fn min_signed_distance(&self, x: &[f64]) -> f64 {
        self.vertices
            .iter()
            .flat_map(|&v| {
                self.colliders
                    .iter()
                    .map(move |c| c.signed_distance(&x[3 * v..3 * v + 3]))
            })
            .fold(f64::INFINITY, f64::min)
    }
}

impl StencilEnergy for ColliderBarrier {
    fn name(&self) -> &'static str {
        "collider barrier"
    }
    fn dim(&self) -> usize {
        3
    }
    fn len(&self) -> usize {
        self.vertices.len() * self.colliders.len()
    }
    fn stencil(&self, s: usize) -> &[usize] {
        let a = s / self.colliders.len();
        &self.vertices[a..a + 1]
    }
    fn eval(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        let collider = &self.colliders[s % self.colliders.len()];
        let exact = match want {
            Want::Hessian { .. } => Want::Hessian { project: false },
            w => w,
        };
        let d2 = collider.squared_distance(x, exact, out);
        if d2 >= self.dhat * self.dhat {
            out.clear(3);
            return 0.0;
        }
        barrier_of_squared_distance(d2, 3, self.dhat, want, out)
    }
}
