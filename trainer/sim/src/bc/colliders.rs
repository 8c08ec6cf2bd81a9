//! Collider paths: each analytic collider's pose and velocity at every frame of a sequence,
//! the random paths datasets draw through and around the body (scene field
//! `colliders.motion`), and the places datasets put a collider that rests through a
//! sequence (scene field `colliders.placement`: a floor, a wall, a table).
//!
//! A path starts outside the body's rest bounding box (grown by the collider's bounding
//! radius and its `clearance`, then by `approach`), heads for an aim point drawn uniformly
//! in the motion's `region`, rests there for `hold_frames`, and goes on to the next aim
//! point, and so on, at the sequence's speed: the collider pokes into the body, presses,
//! and drags through it. Each leg keeps the collider's bounding sphere `clearance` away from
//! the handles' vertices (at their frame-0 places) where a draw allows (64 tries a leg, then
//! it rests). Everything comes from the sequence's seed, so a sequence is the same on every
//! run.

use crate::contact::{ColliderPose, ColliderShape};
use nalgebra::{UnitQuaternion, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

type V3 = Vector3<f64>;

/// Numbers per collider in a trajectory's `collider_states` rows: centre (3), rotation
/// vector (3), linear velocity (3), angular velocity (3).
pub const STATE_PER_COLLIDER: usize = 12;

/// Draws of an aim point per leg before the collider rests instead.
const AIM_TRIES: usize = 64;

/// One collider's motion over a sequence.
#[derive(Clone, Debug, PartialEq)]
pub struct ColliderTrack {
    /// Pose at frames `0..=frames`.
    pub poses: Vec<ColliderPose>,
    /// Linear and angular velocity over the step that ends at each frame (zero at frame 0).
    pub velocities: Vec<[f64; 6]>,
}

impl ColliderTrack {
    /// A collider that rests at `pose` for `frames` steps.
    pub fn resting(pose: ColliderPose, frames: usize) -> Self {
        ColliderTrack {
            poses: vec![pose; frames + 1],
            velocities: vec![[0.0; 6]; frames + 1],
        }
    }

    /// The track of `poses` (frames `0..`), velocities by finite differences over `dt`.
    pub fn from_poses(poses: Vec<ColliderPose>, dt: f64) -> Self {
        let velocities = std::iter::once([0.0; 6])
            .chain(poses.windows(2).map(|w| {
                let v = (w[1].center - w[0].center) / dt;
                let turn = (w[1].rotation * w[0].rotation.inverse()).scaled_axis() / dt;
                [v.x, v.y, v.z, turn.x, turn.y, turn.z]
            }))
            .collect();
        ColliderTrack { poses, velocities }
    }

    /// Every `stride`-th frame of the first `frames * stride` (as [`super::BcSequence::every`]):
    /// the poses there, and the mean velocity over the steps each new step spans.
    pub fn every(&self, stride: usize, frames: usize) -> Self {
        let velocities = std::iter::once([0.0; 6])
            .chain((1..=frames).map(|f| {
                let mut v = [0.0; 6];
                for old in &self.velocities[(f - 1) * stride + 1..=f * stride] {
                    v.iter_mut().zip(old).for_each(|(a, b)| *a += b / stride as f64);
                }
                v
            }))
            .collect();
        ColliderTrack {
            poses: (0..=frames).map(|f| self.poses[f * stride]).collect(),
            velocities,
        }
    }

    /// The same path in `factor` times smaller steps (as [`super::BcSequence::refined`]):
    /// poses on [`ColliderPose::towards`]'s path between the old frames, velocities kept.
    pub fn refined(&self, factor: usize) -> Self {
        let mut poses = vec![self.poses[0]];
        let mut velocities = vec![[0.0; 6]];
        for (w, v) in self.poses.windows(2).zip(&self.velocities[1..]) {
            for k in 1..=factor {
                poses.push(w[0].towards(&w[1], k as f64 / factor as f64));
                velocities.push(*v);
            }
        }
        ColliderTrack { poses, velocities }
    }

    /// `[centre, rotation vector, velocity, angular velocity]` at `frame`
    /// ([`STATE_PER_COLLIDER`] numbers).
    pub fn state(&self, frame: usize) -> [f64; STATE_PER_COLLIDER] {
        let p = &self.poses[frame];
        let r = p.rotation_vector();
        let v = self.velocities[frame];
        [
            p.center.x, p.center.y, p.center.z, r[0], r[1], r[2], v[0], v[1], v[2], v[3], v[4], v[5],
        ]
    }
}

/// How a collider moves in sampled sequences (scene field `colliders.motion`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColliderMotionSpec {
    /// Training range of speeds (m/s), scaled by the sequence's speed level as handles'.
    pub speed: [f64; 2],
    /// Box the aim points are drawn in (default: the body's rest bounding box).
    #[serde(default)]
    pub region: Option<crate::mesh::BoxSpec>,
    /// Directions of the first approach to choose from (default: uniform over all).
    #[serde(default)]
    pub directions: Vec<[f64; 3]>,
    /// Range of frames to rest at each aim point (default `[0, 0]`).
    #[serde(default)]
    pub hold_frames: [usize; 2],
    /// Distance (m) the collider's bounding sphere keeps from the handles' vertices, and by
    /// which the start lies outside the body's bounding box (default 0).
    #[serde(default)]
    pub clearance: f64,
    /// How far (m) beyond the point where the collider's bounding sphere, grown by
    /// `clearance`, leaves the body's bounding box the path starts, along its first approach
    /// (default: the bounding radius plus `clearance` again). A flat box's bounding sphere
    /// reaches far past its faces, so a small `approach` starts it nearer the body.
    #[serde(default)]
    pub approach: Option<f64>,
    /// Share of the sequences the collider takes part in (default 1); in the others it rests
    /// at its parked pose.
    #[serde(default = "one")]
    pub share: f64,
    /// Turn a capsule's axis along the first approach direction (default true); otherwise
    /// the collider keeps the scene's `rotation`.
    #[serde(default = "yes")]
    pub align: bool,
}

fn one() -> f64 {
    1.0
}
fn yes() -> bool {
    true
}

/// What a collider path is drawn against: the body's rest bounding box and the handles'
/// vertices at frame 0.
pub struct PathSetting<'a> {
    /// Lower and upper corners of the body's rest bounding box.
    pub body: ([f64; 3], [f64; 3]),
    /// The handles' vertices at frame 0.
    pub fixed: &'a [[f64; 3]],
    /// Time step (s).
    pub dt: f64,
    /// Frames after the initial one.
    pub frames: usize,
}

impl ColliderMotionSpec {
    /// Checks ranges and directions; returns the offending field and a message.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        let [lo, hi] = self.speed;
        if !(lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo <= hi) {
            return Err(("speed", format!("needs finite 0 <= min <= max, got [{lo}, {hi}]")));
        }
        if let Some(r) = &self.region {
            if let Some(i) = (0..3).find(|&i| r.min[i].partial_cmp(&r.max[i]).is_none_or(|o| o.is_gt())) {
                return Err(("region.max", format!("must be at least `min` along axis {i}")));
            }
        }
        if self
            .directions
            .iter()
            .any(|d| !d.iter().all(|c| c.is_finite()) || V3::from(*d).norm() < 1e-12)
        {
            return Err(("directions", "every entry must be a finite non-zero vector".into()));
        }
        let [h0, h1] = self.hold_frames;
        if h1 < h0 {
            return Err(("hold_frames", format!("needs min <= max, got [{h0}, {h1}]")));
        }
        if !(self.clearance.is_finite() && self.clearance >= 0.0) {
            return Err((
                "clearance",
                format!("must be finite and non-negative, got {}", self.clearance),
            ));
        }
        if let Some(a) = self.approach.filter(|a| !(a.is_finite() && *a >= 0.0)) {
            return Err(("approach", format!("must be finite and non-negative, got {a}")));
        }
        if !(0.0..=1.0).contains(&self.share) {
            return Err(("share", format!("must be in [0, 1], got {}", self.share)));
        }
        Ok(())
    }

    /// A path for `shape` (whose orientation is `rotation` when not aligned), speeds
    /// `speed(frame)` in m/s, drawn from `rng`.
    pub fn sample(
        &self,
        shape: &ColliderShape,
        rotation: UnitQuaternion<f64>,
        setting: &PathSetting,
        speed: &dyn Fn(usize) -> f64,
        rng: &mut ChaCha8Rng,
    ) -> Vec<ColliderPose> {
        let (lo, hi) = setting.body;
        let reach = shape.bounding_radius() + self.clearance;
        let (rlo, rhi) = self.region.map_or((lo, hi), |r| (r.min, r.max));
        let draw_aim = |rng: &mut ChaCha8Rng| {
            V3::from_fn(|i, _| {
                if rhi[i] > rlo[i] {
                    rng.random_range(rlo[i]..=rhi[i])
                } else {
                    rlo[i]
                }
            })
        };
        let clear = |a: &V3, b: &V3| {
            setting
                .fixed
                .iter()
                .all(|p| segment_distance(&V3::from(*p), a, b) >= reach)
        };
        // The first approach: a direction, an aim point, and the start outside the box.
        let mut start = None;
        for _ in 0..AIM_TRIES {
            let dir = self.draw_direction(rng);
            let aim = draw_aim(rng);
            let back = exit_distance(&aim, &(-dir), lo, hi, reach) + self.approach.unwrap_or(reach);
            let from = aim - back * dir;
            if clear(&from, &aim) {
                start = Some((dir, from, aim));
                break;
            }
        }
        let (dir, from, aim) = start.unwrap_or_else(|| {
            // No clear approach: start far above the body and rest there.
            let c = V3::from_fn(|i, _| 0.5 * (lo[i] + hi[i]));
            let far = c + V3::y() * (V3::from(hi) - V3::from(lo)).norm() * 2.0 + V3::y() * reach;
            (V3::y(), far, far)
        });
        let rotation = match shape {
            ColliderShape::Capsule { .. } if self.align => {
                UnitQuaternion::rotation_between(&V3::y(), &dir).unwrap_or_else(UnitQuaternion::identity)
            }
            _ => rotation,
        };
        let mut poses = vec![ColliderPose { center: from, rotation }];
        let (mut at, mut target, mut hold) = (from, aim, 0usize);
        while poses.len() <= setting.frames {
            let frame = poses.len() - 1;
            if hold > 0 {
                hold -= 1;
            } else {
                let step = speed(frame).max(0.0) * setting.dt;
                let left = target - at;
                if left.norm() <= step {
                    at = target;
                    let [h0, h1] = self.hold_frames;
                    hold = rng.random_range(h0..=h1.max(h0));
                    target = (0..AIM_TRIES)
                        .map(|_| draw_aim(rng))
                        .find(|next| clear(&at, next))
                        .unwrap_or(at);
                } else {
                    at += left * (step / left.norm());
                }
            }
            poses.push(ColliderPose { center: at, rotation });
        }
        poses
    }

    /// A unit direction from the list (or uniform over the sphere when it is empty).
    fn draw_direction(&self, rng: &mut ChaCha8Rng) -> V3 {
        if !self.directions.is_empty() {
            let d = V3::from(self.directions[rng.random_range(0..self.directions.len())]);
            return d.normalize();
        }
        loop {
            let d = V3::from_fn(|_, _| rng.random_range(-1.0..=1.0));
            let n = d.norm();
            if n > 1e-3 && n <= 1.0 {
                return d / n;
            }
        }
    }
}

/// Where datasets put a collider that rests through a whole sequence (scene field
/// `colliders.placement`): a floor at a height and slope the sequence draws.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ColliderPlacementSpec {
    /// Box the collider's centre is drawn in, uniformly (m).
    pub center: crate::mesh::BoxSpec,
    /// Training range of tilts (rad), scaled by the sequence's speed level and factor as
    /// handles' speeds are (a test sequence beyond the range tilts `beyond` times the top):
    /// the scene's `rotation` turned by the tilt about a horizontal axis (in the x-z plane)
    /// drawn uniformly (default `[0, 0]`: the scene's `rotation`).
    #[serde(default)]
    pub tilt: [f64; 2],
}

impl ColliderPlacementSpec {
    /// Checks the centre box and the tilt range; returns the offending field and a message.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        let (lo, hi) = (self.center.min, self.center.max);
        if let Some(i) = (0..3).find(|&i| lo[i].partial_cmp(&hi[i]).is_none_or(|o| o.is_gt())) {
            return Err(("center.max", format!("must be at least `min` along axis {i}")));
        }
        let [t0, t1] = self.tilt;
        if !(t0.is_finite() && t1.is_finite() && 0.0 <= t0 && t0 <= t1 && t1 < std::f64::consts::FRAC_PI_2) {
            return Err((
                "tilt",
                format!("needs 0 <= min <= max < pi / 2 (radians), got [{t0}, {t1}]"),
            ));
        }
        Ok(())
    }

    /// The pose of a collider oriented `rotation` placed for a sequence whose speed level
    /// and factor are `(level, factor)`, drawn from `rng`.
    pub fn sample(
        &self,
        rotation: UnitQuaternion<f64>,
        (level, factor): (f64, f64),
        rng: &mut ChaCha8Rng,
    ) -> ColliderPose {
        let (lo, hi) = (self.center.min, self.center.max);
        let center = V3::from_fn(|i, _| {
            if hi[i] > lo[i] {
                rng.random_range(lo[i]..=hi[i])
            } else {
                lo[i]
            }
        });
        let [t0, t1] = self.tilt;
        let tilt = (t0 + level * (t1 - t0)) * factor;
        let heading = rng.random_range(0.0..std::f64::consts::TAU);
        let axis = V3::new(heading.cos(), 0.0, heading.sin());
        ColliderPose {
            center,
            rotation: UnitQuaternion::from_scaled_axis(axis * tilt) * rotation,
        }
    }
}

/// Distance from `p` to the segment `[a, b]`.
fn segment_distance(p: &V3, a: &V3, b: &V3) -> f64 {
    let ab = b - a;
    let len2 = ab.norm_squared();
    let t = if len2 > 0.0 {
        ((p - a).dot(&ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + t * ab)).norm()
}

/// How far from `p` along the unit `dir` the box `[lo, hi]` grown by `margin` ends (zero
/// when `p` is outside it).
fn exit_distance(p: &V3, dir: &V3, lo: [f64; 3], hi: [f64; 3], margin: f64) -> f64 {
    let mut exit = f64::INFINITY;
    for i in 0..3 {
        let (l, h) = (lo[i] - margin, hi[i] + margin);
        if p[i] < l || p[i] > h {
            return 0.0;
        }
        if dir[i] > 0.0 {
            exit = exit.min((h - p[i]) / dir[i]);
        } else if dir[i] < 0.0 {
            exit = exit.min((l - p[i]) / dir[i]);
        }
    }
    if exit.is_finite() {
        exit
    } else {
        0.0
    }
}
