//! The scene's `[[colliders]]` tables: analytic kinematic colliders that touch the body at
//! run time (a poking finger, a ball, a floor), through the IPC barrier of `[contact]`
//! (`docs/design.md`, decision 8), and how datasets move them.
//!
//! ```toml
//! [[colliders]]
//! name = "finger"            # default "collider-K" (K its index)
//! shape = "capsule"          # "sphere", "capsule" or "box" (required)
//! radius = 0.015             # sphere and capsule (m), required for them
//! length = 0.06              # capsule: length of its axis segment (m), required for it;
//!                            # the capsule is `length + 2 radius` long, along its local y
//! half_extents = [0.1, 0.02, 0.1]  # box: half side lengths (m), required for it
//! rotation = [0.0, 0.0, 0.0] # orientation, a rotation vector (rad; default none); a capsule
//!                            # whose motion aligns it ignores it
//!
//! [colliders.motion]         # how datasets move it (absent: it rests at its parked pose)
//! speed = [0.05, 0.2]        # training range of speeds (m/s), levels as handles' (required)
//! region = { min = [-0.1, 0.0, -0.05], max = [0.1, 0.06, 0.05] }
//!                            # box of the aim points (default: the body's rest bounding box)
//! directions = [[0.0, -1.0, 0.0]]  # first approach directions (default: any direction)
//! hold_frames = [0, 10]      # frames resting at each aim point (default [0, 0])
//! clearance = 0.01           # distance (m) kept from the handles (default 0)
//! share = 1.0                # share of the sequences it takes part in (default 1)
//! align = true               # capsule axis along the first approach (default true)
//!
//! [colliders.placement]      # instead of `motion`: datasets put it somewhere for a whole
//!                            # sequence and it rests there (a floor, a wall, a table)
//! center = { min = [0.0, -0.3, 0.0], max = [0.0, -0.1, 0.0] }
//!                            # box its centre is drawn in (m; required)
//! tilt = [0.0, 0.2]          # training range of tilts (rad) about a horizontal axis drawn
//!                            # uniformly, after `rotation`; levels as handles' speeds, so a
//!                            # test beyond the range tilts `beyond` times the top (default [0, 0])
//! ```
//!
//! **K**, the number of `[[colliders]]` tables (at most [`MAX_COLLIDERS`]), is the scene's
//! number of collider slots: every sequence of its dataset has K collider tracks, the
//! simulator takes K poses per step, and a model learned on the scene takes K colliders as
//! inputs. A collider with a `placement` rests where each sequence puts it; one that does
//! not take part in a sequence (neither, or not drawn by `share`) rests at its **parked pose**, [`PARKED_DIAGONALS`] rest diagonals above the
//! centre of the body's rest bounding box: far from anything it could touch.
//!
//! Colliders need a `[contact]` table (its `dhat`, barrier stiffness and `friction` serve
//! them) and a 3D body; they act on the body's surface vertices.

use crate::bc::colliders::ColliderPlacementSpec;
use crate::bc::ColliderMotionSpec;
use crate::contact::{ColliderPose, ColliderShape};
use serde::{Deserialize, Serialize};

/// Most colliders a scene may declare.
pub const MAX_COLLIDERS: usize = 8;

/// How far above the body's rest bounding-box centre a parked collider rests, in rest
/// bounding-box diagonals.
pub const PARKED_DIAGONALS: f64 = 10.0;

/// The kind of a collider's shape.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ShapeKind {
    /// A ball.
    Sphere,
    /// A segment grown by a radius.
    Capsule,
    /// A box.
    Box,
}

/// One `[[colliders]]` table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColliderSpec {
    /// Name (default `collider-K`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// The kind of shape.
    pub shape: ShapeKind,
    /// Sphere and capsule radius (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius: Option<f64>,
    /// Capsule segment length (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub length: Option<f64>,
    /// Box half side lengths (m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub half_extents: Option<[f64; 3]>,
    /// Orientation as a rotation vector (rad).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation: Option<[f64; 3]>,
    /// Dataset motion (absent: placed, or parked).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion: Option<ColliderMotionSpec>,
    /// Where datasets put it for a whole sequence, instead of a motion (absent: parked).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub placement: Option<ColliderPlacementSpec>,
}

impl ColliderSpec {
    /// The collider's name, `collider-K` by default (`k` its index).
    pub fn name_or_default(&self, k: usize) -> String {
        self.name.clone().unwrap_or_else(|| format!("collider-{k}"))
    }

    /// The shape, or the field (under `colliders[k]`) that is missing or does not belong to
    /// the shape, and why.
    pub fn shape(&self) -> Result<ColliderShape, (&'static str, String)> {
        let kind = match self.shape {
            ShapeKind::Sphere => "a sphere",
            ShapeKind::Capsule => "a capsule",
            ShapeKind::Box => "a box",
        };
        let needs = |field: &'static str| (field, format!("{kind} needs `{field}`"));
        let refuses = |field: &'static str| (field, format!("{kind} has no `{field}`"));
        match self.shape {
            ShapeKind::Sphere | ShapeKind::Capsule if self.half_extents.is_some() => Err(refuses("half_extents")),
            ShapeKind::Sphere if self.length.is_some() => Err(refuses("length")),
            ShapeKind::Box if self.radius.is_some() => Err(refuses("radius")),
            ShapeKind::Box if self.length.is_some() => Err(refuses("length")),
            ShapeKind::Sphere => Ok(ColliderShape::Sphere {
                radius: self.radius.ok_or_else(|| needs("radius"))?,
            }),
            ShapeKind::Capsule => Ok(ColliderShape::Capsule {
                radius: self.radius.ok_or_else(|| needs("radius"))?,
                half_length: 0.5 * self.length.ok_or_else(|| needs("length"))?,
            }),
            ShapeKind::Box => Ok(ColliderShape::Box {
                half_extents: self.half_extents.ok_or_else(|| needs("half_extents"))?,
            }),
        }
    }

    /// The orientation the scene gives (identity when none).
    pub fn orientation(&self) -> ColliderPose {
        ColliderPose::new([0.0; 3], self.rotation.unwrap_or([0.0; 3]))
    }

    /// Where the collider is when no sequence places or moves it, for a body whose rest
    /// bounding box is `[lo, hi]`: the middle of its placement's centre box, untilted, when
    /// it has a placement; its parked pose otherwise; in the scene's orientation.
    pub fn idle_pose(&self, lo: [f64; 3], hi: [f64; 3]) -> ColliderPose {
        let rotation = self.orientation().rotation;
        match &self.placement {
            Some(p) => ColliderPose {
                center: [0, 1, 2].map(|i| 0.5 * (p.center.min[i] + p.center.max[i])).into(),
                rotation,
            },
            None => ColliderPose {
                rotation,
                ..parked_pose(lo, hi)
            },
        }
    }
}

/// The parked pose for a body whose rest bounding box is `[lo, hi]`.
pub fn parked_pose(lo: [f64; 3], hi: [f64; 3]) -> ColliderPose {
    let diagonal = (0..3).map(|i| (hi[i] - lo[i]).powi(2)).sum::<f64>().sqrt();
    let center = [0, 1, 2].map(|i| 0.5 * (lo[i] + hi[i]) + if i == 1 { PARKED_DIAGONALS * diagonal } else { 0.0 });
    ColliderPose::new(center, [0.0; 3])
}
