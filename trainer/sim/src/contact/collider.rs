//! Analytic run-time colliders: kinematic spheres, capsules and boxes with a rigid pose,
//! and the squared distance from a point to one of them with its exact gradient and Hessian
//! (the IPC convention of [`super::barrier`]: barriers act on squared distances).
//!
//! A collider is a solid; its surface is the contact surface. The distance of a point is its
//! distance to the solid (zero inside), so a point outside sees exactly the distance to the
//! surface. Shapes are written in their own frame and placed by a [`ColliderPose`]: a point
//! `p` is taken to the local `q = R^T (p - c)`, and the derivatives come back as `R g` and
//! `R H R^T`.
//!
//! - **Sphere** of `radius` about the centre: `d = |q| - r`.
//! - **Capsule**: the points within `radius` of the segment from `-half_length` to
//!   `+half_length` along the local y axis: `d = |q - a(q)| - r` with `a(q)` the clamped
//!   projection on the segment (side: no curvature along the axis; end caps: spheres).
//! - **Box** of `half_extents`: `d^2 = sum_i max(|q_i| - h_i, 0)^2`, which is `C1` and
//!   piecewise quadratic (faces, edges and corners each exact).
//!
//! Squared distances are used throughout as in the mesh primitives: `d^2` is smooth where
//! `d` is, and the box's is quadratic in every region. Inside a collider the squared distance
//! is zero with zero derivatives (contact: the barrier is infinite there).

use crate::energy::{Local, Want};
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

type V3 = Vector3<f64>;
type M3 = Matrix3<f64>;

/// A collider's shape, in its own frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "shape", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ColliderShape {
    /// A solid ball.
    Sphere {
        /// Radius (m).
        radius: f64,
    },
    /// The points within `radius` of a segment along the local y axis.
    Capsule {
        /// Radius (m).
        radius: f64,
        /// Half the length of the segment (m); the capsule is `2 (half_length + radius)` long.
        half_length: f64,
    },
    /// A solid box centred on the origin of its frame.
    Box {
        /// Half the side lengths along the local axes (m).
        half_extents: [f64; 3],
    },
}

/// Shape codes of [`ColliderShape::parameters`].
pub const SPHERE_CODE: f64 = 0.0;
/// See [`SPHERE_CODE`].
pub const CAPSULE_CODE: f64 = 1.0;
/// See [`SPHERE_CODE`].
pub const BOX_CODE: f64 = 2.0;

impl ColliderShape {
    /// The largest distance from the frame's origin to a point of the shape.
    pub fn bounding_radius(&self) -> f64 {
        match *self {
            ColliderShape::Sphere { radius } => radius,
            ColliderShape::Capsule { radius, half_length } => half_length + radius,
            ColliderShape::Box { half_extents } => V3::from(half_extents).norm(),
        }
    }

    /// `[code, a, b, c]`: sphere `[0, radius, 0, 0]`, capsule `[1, radius, half_length, 0]`,
    /// box `[2, hx, hy, hz]` (the trajectories' `collider_shapes` rows).
    pub fn parameters(&self) -> [f64; 4] {
        match *self {
            ColliderShape::Sphere { radius } => [SPHERE_CODE, radius, 0.0, 0.0],
            ColliderShape::Capsule { radius, half_length } => [CAPSULE_CODE, radius, half_length, 0.0],
            ColliderShape::Box { half_extents: h } => [BOX_CODE, h[0], h[1], h[2]],
        }
    }

    /// The shape of [`Self::parameters`]' row, if it is one.
    pub fn from_parameters(p: [f64; 4]) -> Option<Self> {
        let shape = match p[0] {
            c if c == SPHERE_CODE => ColliderShape::Sphere { radius: p[1] },
            c if c == CAPSULE_CODE => ColliderShape::Capsule {
                radius: p[1],
                half_length: p[2],
            },
            c if c == BOX_CODE => ColliderShape::Box {
                half_extents: [p[1], p[2], p[3]],
            },
            _ => return None,
        };
        Some(shape)
    }

    /// Squared distance of the local point `q` to the solid, with its gradient and Hessian.
    fn local_squared_distance(&self, q: V3) -> (f64, V3, M3) {
        let zero = (0.0, V3::zeros(), M3::zeros());
        match *self {
            ColliderShape::Sphere { radius } => round_squared_distance(q, radius, None).unwrap_or(zero),
            ColliderShape::Capsule { radius, half_length } => {
                let t = q.y.clamp(-half_length, half_length);
                let side = q.y.abs() < half_length;
                let axis = side.then(V3::y);
                round_squared_distance(q - V3::new(0.0, t, 0.0), radius, axis).unwrap_or(zero)
            }
            ColliderShape::Box { half_extents: h } => {
                let mut e = V3::zeros();
                let mut hess = M3::zeros();
                for i in 0..3 {
                    let excess = q[i].abs() - h[i];
                    if excess > 0.0 {
                        e[i] = excess.copysign(q[i]);
                        hess[(i, i)] = 2.0;
                    }
                }
                (e.norm_squared(), 2.0 * e, hess)
            }
        }
    }

    /// The gradient of [`Self::signed_distance_local`] at `q`: the unit direction from the
    /// closest surface point outward (inside a box, the normal of the nearest face). Where it
    /// is not defined (the centre of a sphere, the axis of a capsule) a fixed unit direction.
    pub fn signed_distance_gradient_local(&self, q: V3) -> V3 {
        let unit = |r: V3, fallback: V3| r.try_normalize(0.0).unwrap_or(fallback);
        match *self {
            ColliderShape::Sphere { .. } => unit(q, V3::y()),
            ColliderShape::Capsule { half_length, .. } => {
                unit(q - V3::new(0.0, q.y.clamp(-half_length, half_length), 0.0), V3::x())
            }
            ColliderShape::Box { half_extents: h } => {
                let excess = V3::from_fn(|i, _| q[i].abs() - h[i]);
                let outside = V3::from_fn(|i, _| excess[i].max(0.0).copysign(q[i]));
                match outside.try_normalize(0.0) {
                    Some(n) => n,
                    None => {
                        let i = excess.imax();
                        let mut n = V3::zeros();
                        n[i] = 1.0f64.copysign(q[i]);
                        n
                    }
                }
            }
        }
    }

    /// Signed distance of the point `q`, in the shape's own frame, to its surface (negative
    /// inside); a convex function of `q`.
    pub fn signed_distance_local(&self, q: V3) -> f64 {
        match *self {
            ColliderShape::Sphere { radius } => q.norm() - radius,
            ColliderShape::Capsule { radius, half_length } => {
                (q - V3::new(0.0, q.y.clamp(-half_length, half_length), 0.0)).norm() - radius
            }
            ColliderShape::Box { half_extents: h } => {
                let excess = V3::from_fn(|i, _| q[i].abs() - h[i]);
                let outside = excess.map(|e| e.max(0.0)).norm();
                outside + excess.max().min(0.0)
            }
        }
    }
}

/// `(|r| - radius)^2` with derivatives in `r`, where `r` is the offset from the closest
/// point of a centre set (a point, or a line of direction `axis`, whose own curvature the
/// Hessian leaves out); `None` inside.
fn round_squared_distance(r: V3, radius: f64, axis: Option<V3>) -> Option<(f64, V3, M3)> {
    let rho = r.norm();
    if rho <= radius {
        return None;
    }
    let d = rho - radius;
    let u = r / rho;
    let mut across = M3::identity() - u * u.transpose();
    if let Some(a) = axis {
        across -= a * a.transpose();
    }
    Some((d * d, 2.0 * d * u, 2.0 * u * u.transpose() + (2.0 * d / rho) * across))
}

/// A rigid placement: the shape's frame origin and its rotation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ColliderPose {
    /// Where the shape's origin is (m).
    pub center: V3,
    /// The shape frame's rotation.
    pub rotation: UnitQuaternion<f64>,
}

impl ColliderPose {
    /// The pose at `center` with rotation vector `rotation` (axis times angle, rad).
    pub fn new(center: [f64; 3], rotation: [f64; 3]) -> Self {
        ColliderPose {
            center: V3::from(center),
            rotation: UnitQuaternion::from_scaled_axis(V3::from(rotation)),
        }
    }

    /// The rotation vector of the pose (angle at most pi).
    pub fn rotation_vector(&self) -> [f64; 3] {
        self.rotation.scaled_axis().into()
    }

    /// The pose the fraction `t` of the way to `to`: the centre on the straight line, the
    /// rotation at the constant angular velocity that turns this rotation into `to`'s
    /// (`R(t) = exp(t log(R_to R^T)) R`, by the smaller angle).
    pub fn towards(&self, to: &ColliderPose, t: f64) -> ColliderPose {
        if t >= 1.0 {
            return *to;
        }
        let turn = (to.rotation * self.rotation.inverse()).scaled_axis();
        ColliderPose {
            center: self.center + t * (to.center - self.center),
            rotation: UnitQuaternion::from_scaled_axis(t * turn) * self.rotation,
        }
    }

    /// The angle (rad) of the rotation from this pose's to `to`'s.
    pub fn angle_to(&self, to: &ColliderPose) -> f64 {
        (to.rotation * self.rotation.inverse()).angle()
    }

    /// Where the point `p`, fixed to the shape at this pose, is at the pose `to`.
    pub fn carry(&self, p: V3, to: &ColliderPose) -> V3 {
        to.center + to.rotation * (self.rotation.inverse() * (p - self.center))
    }
}

/// A shape at a pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Collider {
    /// The shape.
    pub shape: ColliderShape,
    /// Where it is.
    pub pose: ColliderPose,
}

impl Collider {
    /// The squared distance `d^2` of the point `p` (3 coordinates) to the solid; writes its
    /// gradient and exact Hessian (3 and 9 entries) into `out` as `want` asks.
    pub fn squared_distance(&self, p: &[f64], want: Want, out: &mut Local) -> f64 {
        let rot = self.pose.rotation;
        let q = rot.inverse() * (V3::new(p[0], p[1], p[2]) - self.pose.center);
        let (d2, g, h) = self.shape.local_squared_distance(q);
        if want.gradient() {
            out.grad[..3].copy_from_slice((rot * g).as_slice());
        }
        if want.hessian().is_some() {
            let r = rot.to_rotation_matrix();
            let hw = r.matrix() * h * r.matrix().transpose();
            for i in 0..3 {
                for j in 0..3 {
                    out.hess[i * 3 + j] = hw[(i, j)];
                }
            }
        }
        d2
    }

    /// The distance of the point `p` to the solid (zero inside).
    pub fn distance(&self, p: &[f64]) -> f64 {
        self.signed_distance(p).max(0.0)
    }

    /// The signed distance of the point `p` to the surface: positive outside, minus the
    /// depth inside.
    pub fn signed_distance(&self, p: &[f64]) -> f64 {
        let q = self.pose.rotation.inverse() * (V3::new(p[0], p[1], p[2]) - self.pose.center);
        self.shape.signed_distance_local(q)
    }

    /// [`Self::signed_distance`] of the point `p` and its gradient (a unit vector, world
    /// axes; see [`ColliderShape::signed_distance_gradient_local`]).
    pub fn signed_distance_and_gradient(&self, p: &[f64]) -> (f64, V3) {
        let rot = self.pose.rotation;
        let q = rot.inverse() * (V3::new(p[0], p[1], p[2]) - self.pose.center);
        (
            self.shape.signed_distance_local(q),
            rot * self.shape.signed_distance_gradient_local(q),
        )
    }
}
