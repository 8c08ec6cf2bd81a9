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

use super::barrier::{barrier, barrier_first_derivative, barrier_of_squared_distance, barrier_second_derivative};
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

/// The barrier of [`ColliderBarrier::floored_value_and_gradient`] held at `floor` and below:
/// the second-order expansion of `b(d^2, dhat^2)` in the signed distance `d` at `floor`, as
/// `(value, derivative)` at `d`.
fn floored_barrier(d: f64, floor: f64, dhat: f64) -> (f64, f64) {
    let dhat2 = dhat * dhat;
    let s = floor * floor;
    let (b, db, ddb) = (
        barrier(s, dhat2),
        barrier_first_derivative(s, dhat2),
        barrier_second_derivative(s, dhat2),
    );
    // d/dd b(d^2) = 2 d b'(d^2); d^2/dd^2 b(d^2) = 2 b'(d^2) + 4 d^2 b''(d^2).
    let (slope, curvature) = (2.0 * floor * db, 2.0 * db + 4.0 * s * ddb);
    let h = d - floor;
    (b + slope * h + 0.5 * curvature * h * h, slope + curvature * h)
}

impl ColliderBarrier {
    /// The barrier `B(x)` as a loss on states that may penetrate (a network's predictions):
    /// every (vertex, collider) pair at least `floor` (`0 < floor < dhat`) from the surface
    /// counts exactly as in `B`; a pair nearer than `floor`, or inside the collider, counts
    /// the second-order expansion of its barrier in the signed distance at `floor` (convex,
    /// finite everywhere, growing with the depth). Adds `weight` times the gradient into
    /// `grad` (3 numbers per vertex of `x`) and returns the unweighted value. Pairs are
    /// summed in a fixed order.
    pub fn floored_value_and_gradient(&self, x: &[f64], floor: f64, weight: f64, grad: &mut [f64]) -> f64 {
        let dhat = self.dhat;
        let mut total = 0.0;
        for &v in &self.vertices {
            let p = &x[3 * v..3 * v + 3];
            for c in &self.colliders {
                let (d, normal) = c.signed_distance_and_gradient(p);
                if d >= dhat {
                    continue;
                }
                let (value, slope) = if d >= floor {
                    let s = d * d;
                    (
                        barrier(s, dhat * dhat),
                        2.0 * d * barrier_first_derivative(s, dhat * dhat),
                    )
                } else {
                    floored_barrier(d, floor, dhat)
                };
                total += value;
                for i in 0..3 {
                    grad[3 * v + i] += weight * slope * normal[i];
                }
            }
        }
        total
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
