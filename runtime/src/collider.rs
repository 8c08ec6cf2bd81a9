//! Run-time colliders: analytic shapes a host moves every frame (a hand's capsules, a ball, a
//! floor box) and the cheap correction that pushes decoded vertices out of them, in fixed
//! memory, `O(vertices x colliders)`.
//!
//! The shapes are the simulator's (`mochi_sim::contact::ColliderShape`, whose parameter rows
//! `[code, a, b, c]` these mirror): a sphere of `radius`; a capsule, the points within
//! `radius` of a segment of half length `half_length` along the shape's local y axis; a box of
//! half extents along its local axes. A shape sits at a pose: the world position of its frame's
//! origin and the frame's rotation as a rotation vector (axis times angle, radians).
//!
//! [`push_out`] moves every vertex nearer to a collider's surface than `margin` (or inside it)
//! by the shortest way to `margin` outside it: radially from a sphere's centre or a capsule's
//! axis, across the nearest face of a box (along the distance's direction when the vertex is
//! outside within the margin). Colliders are taken in order, so where two overlap the later one
//! wins. The correction does not know the body's physics: it is what a renderer needs so that
//! no drawn vertex shows inside a collider, not a response of the body to the contact.

use core::fmt;

use nalgebra::{Matrix3, Vector3};

use crate::frame::rotation;

/// [`Collider::shape`] of a sphere (`size = [radius, 0, 0]`).
pub const SPHERE: u32 = 0;
/// [`Collider::shape`] of a capsule (`size = [radius, half_length, 0]`, axis along local y).
pub const CAPSULE: u32 = 1;
/// [`Collider::shape`] of a box (`size` = half extents along its local axes).
pub const BOX: u32 = 2;

type V3 = Vector3<f32>;

use crate::model::Model;
pub use crate::model::{FEATURES_PER_COLLIDER, MAX_COLLIDERS, SHAPE_ROW};
/// Beyond this many rest diagonals from the body's encoding origin a collider reads as absent
/// ([`features`]).
pub const FAR_DIAGONALS: f32 = 2.0;

/// A collider slot's shape from its row `[code, a, b, c]` of a model: `(shape, size)`, or
/// `None` when the row is not a shape with positive sizes (a capsule's half length may be 0).
pub fn shape_from_row(row: &[f32]) -> Option<(u32, [f32; 3])> {
    let &[code, a, b, c] = row else {
        return None;
    };
    let shape = [SPHERE, CAPSULE, BOX].into_iter().find(|&s| s as f32 == code)?;
    let size = match shape {
        SPHERE => [a, 0.0, 0.0],
        CAPSULE => [a, b, 0.0],
        _ => [a, b, c],
    };
    let probe = Collider {
        shape,
        size,
        center: [0.0; 3],
        rotation: [0.0; 3],
    };
    probe.is_valid().then_some((shape, size))
}

/// Collider slot `slot` of `model`: its shape at the pose of `state` (what [`push_out`]
/// takes); `None` for a slot the model does not have.
pub fn slot_collider(model: &Model, slot: usize, state: &ColliderState) -> Option<Collider> {
    let row = model
        .collider_shape_rows()
        .get(slot * SHAPE_ROW..(slot + 1) * SHAPE_ROW)?;
    let (shape, size) = shape_from_row(row)?;
    Some(Collider {
        shape,
        size,
        center: state.center,
        rotation: state.rotation,
    })
}

/// A collider slot's state in a frame, as the host gives it: the pose of the shape's frame and
/// its motion over the step that ends at the frame (the layout of a dataset's
/// `collider_states` row).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ColliderState {
    /// World position of the shape frame's origin.
    pub center: [f32; 3],
    /// Rotation of the shape frame, a rotation vector (radians).
    pub rotation: [f32; 3],
    /// Linear velocity of the centre (units / s).
    pub linear_velocity: [f32; 3],
    /// Angular velocity (rad / s, world axes).
    pub angular_velocity: [f32; 3],
}

impl ColliderState {
    /// Whether every number is finite.
    pub fn is_finite(&self) -> bool {
        self.center
            .iter()
            .chain(&self.rotation)
            .chain(&self.linear_velocity)
            .chain(&self.angular_velocity)
            .all(|v| v.is_finite())
    }
}

/// The integrator's inputs for one collider slot, in the body's encoding frame (rotation
/// `frame`, origin `origin`; a model's [`crate::frame::Placement`]): the centre `R^T (c - o)`,
/// the first two columns of `R^T R_c` (the shape's x and y axes: a continuous function of
/// the orientation, where a rotation vector jumps from `pi a` to `-pi a` at a half turn, the
/// orientation of a capsule pointing straight down), and the velocity `R^T v`. A collider
/// farther than [`FAR_DIAGONALS`] rest diagonals from the origin, or an absent one (`None`),
/// reads as absent: its centre `FAR_DIAGONALS * diagonal * R^T y` (above the body), axes
/// those of the encoding frame, velocity zero. The one definition: the trainer packs its
/// training inputs with it too.
pub fn features(
    frame: &Matrix3<f32>,
    origin: &V3,
    diagonal: f32,
    state: Option<&ColliderState>,
) -> [f32; FEATURES_PER_COLLIDER] {
    let far = FAR_DIAGONALS * diagonal;
    let inverse = frame.transpose();
    let mut out = [0.0; FEATURES_PER_COLLIDER];
    let near = state.filter(|s| (V3::from(s.center) - origin).norm() <= far);
    match near {
        Some(s) => {
            let centre = inverse * (V3::from(s.center) - origin);
            let turned = inverse * *rotation(&s.rotation).matrix();
            let velocity = inverse * V3::from(s.linear_velocity);
            let axes = turned.column(0).into_iter().chain(turned.column(1));
            for (o, v) in out.iter_mut().zip(centre.iter().chain(axes).chain(velocity.iter())) {
                *o = *v;
            }
        }
        None => {
            let centre = inverse * (V3::y() * far);
            out[..3].copy_from_slice(centre.as_slice());
            (out[3], out[7]) = (1.0, 1.0);
        }
    }
    out
}

/// One analytic collider at its pose this frame.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Collider {
    /// [`SPHERE`], [`CAPSULE`] or [`BOX`].
    pub shape: u32,
    /// Sphere `[radius, 0, 0]`, capsule `[radius, half_length, 0]`, box half extents (all in
    /// the model's length unit).
    pub size: [f32; 3],
    /// World position of the shape frame's origin (its centre).
    pub center: [f32; 3],
    /// Rotation of the shape frame, a rotation vector (axis times angle, radians).
    pub rotation: [f32; 3],
}

/// Why [`push_out`] was refused (the positions are left as they were).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColliderError {
    /// Collider `index` has an unknown shape, a size that is not positive (a capsule's half
    /// length may be zero), or a non-finite number.
    Invalid {
        /// Its index in the list given.
        index: usize,
    },
    /// `dim` is not 2 or 3, the positions are not a whole number of vertices, or the margin
    /// is negative or not finite.
    Arguments,
}

impl fmt::Display for ColliderError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ColliderError::Invalid { index } => write!(
                f,
                "collider {index} has an unknown shape, a size that is not positive, or a non-finite number"
            ),
            ColliderError::Arguments => {
                write!(
                    f,
                    "positions must be whole 2D or 3D vertices and the margin finite and >= 0"
                )
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for ColliderError {}

impl Collider {
    /// Whether the shape is known, its sizes positive (a capsule's half length may be 0) and
    /// every number finite.
    pub fn is_valid(&self) -> bool {
        let finite = self
            .size
            .iter()
            .chain(&self.center)
            .chain(&self.rotation)
            .all(|v| v.is_finite());
        let [a, b, c] = self.size;
        finite
            && match self.shape {
                SPHERE => a > 0.0,
                CAPSULE => a > 0.0 && b >= 0.0,
                BOX => a > 0.0 && b > 0.0 && c > 0.0,
                _ => false,
            }
    }

    /// The largest distance from the centre to a point of the shape.
    pub fn bounding_radius(&self) -> f32 {
        let [a, b, c] = self.size;
        match self.shape {
            SPHERE => a,
            CAPSULE => a + b,
            _ => libm::sqrtf(a * a + b * b + c * c),
        }
    }

    /// `p` in the shape's own frame.
    fn local(&self, p: V3) -> V3 {
        rotation(&self.rotation).inverse() * (p - V3::from(self.center))
    }

    /// Signed distance of `p` (world) to the shape's surface, negative inside.
    pub fn signed_distance(&self, p: [f32; 3]) -> f32 {
        local_signed_distance(self, self.local(V3::from(p)))
    }

    /// Where `p` (world) goes to lie at least `margin` outside the shape, by the shortest way;
    /// `None` when it already does.
    pub fn pushed(&self, p: [f32; 3], margin: f32) -> Option<[f32; 3]> {
        let q = self.local(V3::from(p));
        if local_signed_distance(self, q) >= margin {
            return None;
        }
        let moved = local_pushed(self, q, margin);
        Some((V3::from(self.center) + rotation(&self.rotation) * moved).into())
    }
}

/// Signed distance of the local point `q` to `c`'s surface.
fn local_signed_distance(c: &Collider, q: V3) -> f32 {
    let [a, b, _] = c.size;
    match c.shape {
        SPHERE => q.norm() - a,
        CAPSULE => (q - V3::new(0.0, q.y.clamp(-b, b), 0.0)).norm() - a,
        _ => {
            let excess = V3::from_fn(|i, _| q[i].abs() - c.size[i]);
            excess.map(|e| e.max(0.0)).norm() + excess.max().min(0.0)
        }
    }
}

/// The local point `q` (nearer than `margin` to `c`'s surface) moved the shortest way to
/// `margin` outside it.
fn local_pushed(c: &Collider, q: V3, margin: f32) -> V3 {
    let [a, b, _] = c.size;
    // A round shape: out from the closest point of its centre set (a point or a segment).
    let round = |core: V3, fallback: V3| {
        let r = q - core;
        let n = r.try_normalize(f32::EPSILON).unwrap_or(fallback);
        core + n * (a + margin)
    };
    match c.shape {
        SPHERE => round(V3::zeros(), V3::y()),
        CAPSULE => {
            let core = V3::new(0.0, q.y.clamp(-b, b), 0.0);
            // On the axis itself: out through the nearer cap, or sideways along x.
            let fallback = if q.y.abs() >= b && b > 0.0 {
                V3::y() * q.y.signum()
            } else {
                V3::x()
            };
            round(core, fallback)
        }
        _ => {
            let h = V3::from(c.size);
            let closest = q.zip_map(&h, |v, e| v.clamp(-e, e));
            let outside = q - closest;
            match outside.try_normalize(f32::EPSILON) {
                // Outside within the margin: along the distance's direction.
                Some(n) => closest + n * margin,
                // Inside: across the face of least penetration.
                None => {
                    let excess = V3::from_fn(|i, _| q[i].abs() - h[i]);
                    let i = excess.imax();
                    let mut moved = q;
                    let side = if q[i] < 0.0 { -1.0 } else { 1.0 };
                    moved[i] = side * (h[i] + margin);
                    moved
                }
            }
        }
    }
}

/// Pushes every vertex of `positions` (`dim` numbers each; a 2D vertex is at z = 0 and keeps
/// only its x and y) nearer than `margin` to a collider's surface, or inside it, out to
/// `margin` from it, collider after collider; returns how many vertex moves were made. Bad
/// input is refused before anything moves.
pub fn push_out(
    positions: &mut [f32],
    dim: usize,
    colliders: &[Collider],
    margin: f32,
) -> Result<usize, ColliderError> {
    if !(dim == 2 || dim == 3) || !positions.len().is_multiple_of(dim) || !(margin.is_finite() && margin >= 0.0) {
        return Err(ColliderError::Arguments);
    }
    if let Some(index) = colliders.iter().position(|c| !c.is_valid()) {
        return Err(ColliderError::Invalid { index });
    }
    let mut moved = 0;
    for c in colliders {
        // The collider's frame once, and a bounding sphere that rules most vertices out
        // before any rotation.
        let turn = *rotation(&c.rotation).matrix();
        let centre = V3::from(c.center);
        let reach = c.bounding_radius() + margin;
        for v in positions.chunks_exact_mut(dim) {
            let offset = V3::new(v[0], v[1], if dim == 3 { v[2] } else { 0.0 }) - centre;
            if offset.norm_squared() > reach * reach {
                continue;
            }
            let q = turn.transpose() * offset;
            if local_signed_distance(c, q) >= margin {
                continue;
            }
            let to = centre + turn * local_pushed(c, q, margin);
            v.copy_from_slice(&to.as_slice()[..dim]);
            moved += 1;
        }
    }
    Ok(moved)
}

#[cfg(all(test, feature = "std"))]
#[path = "collider_tests.rs"]
mod tests;
