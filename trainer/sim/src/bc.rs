//! Boundary conditions: handles (sets of prescribed vertices) moved rigidly by
//! piecewise-constant linear and angular velocities, analytic colliders' paths
//! ([`colliders`]), and the random motions that datasets sample from speed ranges with a
//! seed.

use nalgebra::{UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

type V3 = Vector3<f64>;

pub mod colliders;
pub use colliders::{ColliderMotionSpec, ColliderTrack};

/// Numbers per handle in the boundary-condition signal: linear velocity (3), angular
/// velocity (3), translation (3) and rotation vector (3) of the handle's pose.
pub const SIGNAL_PER_HANDLE: usize = 12;

/// A piece of motion: constant linear and angular velocity (about the moving pivot).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Segment {
    /// Duration in frames.
    pub frames: usize,
    /// Linear velocity of the pivot (units / s).
    #[serde(default)]
    pub velocity: [f64; 3],
    /// Angular velocity about the pivot (rad / s, world axes).
    #[serde(default)]
    pub angular_velocity: [f64; 3],
}

/// A rigid pose relative to a handle's reference placement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Translation of the pivot.
    pub translation: V3,
    /// Rotation about the pivot.
    pub rotation: UnitQuaternion<f64>,
}

impl Pose {
    /// No motion.
    pub fn identity() -> Self {
        Pose {
            translation: V3::zeros(),
            rotation: UnitQuaternion::identity(),
        }
    }
    /// Moves the reference point `p` of a handle pivoting about `pivot`.
    pub fn apply(&self, p: V3, pivot: V3) -> V3 {
        pivot + self.translation + self.rotation * (p - pivot)
    }
    /// The pose after moving for `dt` seconds with the velocities of `segment`.
    pub fn advanced(&self, segment: &Segment, dt: f64) -> Pose {
        Pose {
            translation: self.translation + V3::from(segment.velocity) * dt,
            rotation: UnitQuaternion::from_scaled_axis(V3::from(segment.angular_velocity) * dt) * self.rotation,
        }
    }
}

/// A set of prescribed vertices that moves rigidly.
#[derive(Clone, Debug, PartialEq)]
pub struct Handle {
    /// Name from the scene.
    pub name: String,
    /// Prescribed vertices.
    pub vertices: Vec<usize>,
    /// Their positions at the identity pose (3D; z = 0 for 2D meshes).
    pub reference: Vec<[f64; 3]>,
    /// Point the handle rotates about (at the identity pose).
    pub pivot: [f64; 3],
}

impl Handle {
    /// Writes the handle's vertex positions at `pose` into `out` (`dim` per vertex).
    pub fn place(&self, pose: &Pose, dim: usize, out: &mut Vec<f64>) {
        let pivot = V3::from(self.pivot);
        for r in &self.reference {
            let p = pose.apply(V3::from(*r), pivot);
            out.extend_from_slice(&p.as_slice()[..dim]);
        }
    }
}

/// One handle's motion over a sequence: its pose and velocities at every frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Track {
    /// Pose at frames `0..=frames` (frame 0 is the identity).
    pub poses: Vec<Pose>,
    /// Linear and angular velocity over the step that ends at each frame (zero at frame 0).
    pub velocities: Vec<[f64; 6]>,
}

impl Track {
    /// Integrates `segments` over `frames` steps of `dt`; after the last segment the
    /// handle holds still.
    pub fn from_segments(segments: &[Segment], frames: usize, dt: f64) -> Track {
        let mut poses = vec![Pose::identity()];
        let mut velocities = vec![[0.0; 6]];
        let rest = Segment {
            frames: usize::MAX,
            velocity: [0.0; 3],
            angular_velocity: [0.0; 3],
        };
        let mut active = segments
            .iter()
            .flat_map(|s| std::iter::repeat_n(s, s.frames))
            .chain(std::iter::repeat(&rest));
        for _ in 0..frames {
            let seg = active.next().unwrap_or(&rest);
            poses.push(poses.last().expect("starts non-empty").advanced(seg, dt));
            let mut v = [0.0; 6];
            v[..3].copy_from_slice(&seg.velocity);
            v[3..].copy_from_slice(&seg.angular_velocity);
            velocities.push(v);
        }
        Track { poses, velocities }
    }
}

/// The boundary conditions of one sequence: one track per handle and one per collider.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BcSequence {
    /// Tracks, in the scene's handle order.
    pub tracks: Vec<Track>,
    /// Number of frames after the initial one (also for scenes without handles).
    pub frames: usize,
    /// The analytic colliders' paths, in the scene's collider order (empty without
    /// colliders).
    pub colliders: Vec<ColliderTrack>,
}

impl BcSequence {
    /// Number of frames after the initial one.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Target positions of all handle vertices at `frame` (handles concatenated).
    pub fn targets(&self, handles: &[Handle], frame: usize, dim: usize) -> Vec<f64> {
        let mut out = Vec::new();
        for (h, t) in handles.iter().zip(&self.tracks) {
            h.place(&t.poses[frame], dim, &mut out);
        }
        out
    }

    /// Every `stride`-th frame of this sequence (`stride` >= 1; frame 0 kept): the same motion
    /// in `stride` times larger steps, `frames / stride` of them. The velocity over a new step
    /// is the mean of the velocities over the old steps it spans.
    pub fn every(&self, stride: usize) -> BcSequence {
        let stride = stride.max(1);
        let frames = self.frames / stride;
        let tracks = self
            .tracks
            .iter()
            .map(|t| Track {
                poses: (0..=frames).map(|f| t.poses[f * stride]).collect(),
                velocities: std::iter::once([0.0; 6])
                    .chain((1..=frames).map(|f| {
                        let mut v = [0.0; 6];
                        for old in &t.velocities[(f - 1) * stride + 1..=f * stride] {
                            v.iter_mut().zip(old).for_each(|(a, b)| *a += b / stride as f64);
                        }
                        v
                    }))
                    .collect(),
            })
            .collect();
        let colliders = self.colliders.iter().map(|c| c.every(stride, frames)).collect();
        BcSequence {
            tracks,
            frames,
            colliders,
        }
    }

    /// This sequence in `factor` times smaller steps (the inverse of [`Self::every`]): each
    /// step of `dt` seconds becomes `factor` steps of `dt / factor` with the same velocities,
    /// so the poses at every `factor`-th new frame are this sequence's (rotations about one
    /// axis compose exactly) and `frames * factor` frames follow frame 0.
    pub fn refined(&self, factor: usize, dt: f64) -> BcSequence {
        let factor = factor.max(1);
        let small = dt / factor as f64;
        let tracks = self
            .tracks
            .iter()
            .map(|t| {
                let mut poses = vec![t.poses[0]];
                let mut velocities = vec![[0.0; 6]];
                for f in 1..=self.frames {
                    let v = t.velocities[f];
                    let segment = Segment {
                        frames: 1,
                        velocity: [v[0], v[1], v[2]],
                        angular_velocity: [v[3], v[4], v[5]],
                    };
                    for _ in 0..factor {
                        poses.push(poses.last().expect("starts non-empty").advanced(&segment, small));
                        velocities.push(v);
                    }
                    // Back onto the coarse pose, so that rounding does not accumulate.
                    *poses.last_mut().expect("just pushed") = t.poses[f];
                }
                Track { poses, velocities }
            })
            .collect();
        BcSequence {
            tracks,
            frames: self.frames * factor,
            colliders: self.colliders.iter().map(|c| c.refined(factor)).collect(),
        }
    }

    /// Frames `0..=frames` of this sequence (all of it when it is shorter).
    pub fn first(&self, frames: usize) -> BcSequence {
        let frames = frames.min(self.frames);
        let tracks = self
            .tracks
            .iter()
            .map(|t| Track {
                poses: t.poses[..=frames].to_vec(),
                velocities: t.velocities[..=frames].to_vec(),
            })
            .collect();
        let colliders = self
            .colliders
            .iter()
            .map(|c| ColliderTrack {
                poses: c.poses[..=frames].to_vec(),
                velocities: c.velocities[..=frames].to_vec(),
            })
            .collect();
        BcSequence {
            tracks,
            frames,
            colliders,
        }
    }

    /// The same motion (this sequence's steps last `dt` seconds) seen at another frame time
    /// `new_dt`: `frames` frames after frame 0, the pose at each new frame's time integrated
    /// from the piecewise-constant velocities, and the velocity over each new step the mean of
    /// the old ones it spans (time-weighted). Past this sequence's end the handles hold still.
    /// [`Self::refined`] and [`Self::every`] are the whole-number cases.
    pub fn resampled(&self, dt: f64, new_dt: f64, frames: usize) -> BcSequence {
        let velocity_at = |t: &Track, step: usize| {
            t.velocities
                .get(step)
                .filter(|_| step >= 1 && step <= self.frames)
                .copied()
                .unwrap_or([0.0; 6])
        };
        let segment = |v: [f64; 6]| Segment {
            frames: 1,
            velocity: [v[0], v[1], v[2]],
            angular_velocity: [v[3], v[4], v[5]],
        };
        // The old step (1-based) a time falls in, and how far into it, in seconds.
        let locate = |time: f64| {
            let steps = time / dt;
            let whole = (steps.floor() as usize).min(self.frames);
            (whole, time - whole as f64 * dt)
        };
        let tracks = self
            .tracks
            .iter()
            .map(|t| {
                let pose_at = |time: f64| {
                    let (whole, rest) = locate(time);
                    let base = t.poses[whole];
                    if rest <= 0.0 {
                        base
                    } else {
                        base.advanced(&segment(velocity_at(t, whole + 1)), rest)
                    }
                };
                let mut poses = vec![t.poses[0]];
                let mut velocities = vec![[0.0; 6]];
                for f in 1..=frames {
                    let (t0, t1) = ((f - 1) as f64 * new_dt, f as f64 * new_dt);
                    poses.push(pose_at(t1));
                    // Time-weighted mean of the old velocities over [t0, t1].
                    let mut v = [0.0; 6];
                    let mut time = t0;
                    while time < t1 {
                        let step = (time / dt).floor() as usize + 1;
                        let end = (step as f64 * dt).min(t1);
                        let weight = (end - time) / new_dt;
                        let old = velocity_at(t, step);
                        v.iter_mut().zip(old).for_each(|(a, b)| *a += weight * b);
                        // Guard against a step boundary that rounding puts at `time` itself.
                        time = if end > time { end } else { time + 1e-12 * dt };
                    }
                    velocities.push(v);
                }
                Track { poses, velocities }
            })
            .collect();
        // The colliders' poses at the new frames' times, each between the two old frames
        // around it (held after the last), velocities by differences.
        let colliders = self
            .colliders
            .iter()
            .map(|c| {
                let poses = (0..=frames)
                    .map(|f| {
                        let (whole, rest) = locate(f as f64 * new_dt);
                        match c.poses.get(whole + 1) {
                            Some(next) if rest > 0.0 => c.poses[whole].towards(next, rest / dt),
                            _ => c.poses[whole.min(c.poses.len() - 1)],
                        }
                    })
                    .collect();
                ColliderTrack::from_poses(poses, new_dt)
            })
            .collect();
        BcSequence {
            tracks,
            frames,
            colliders,
        }
    }

    /// The colliders' poses at `frame`.
    pub fn collider_poses(&self, frame: usize) -> Vec<crate::contact::ColliderPose> {
        self.colliders.iter().map(|c| c.poses[frame]).collect()
    }

    /// The colliders' states at `frame`, one row of a trajectory's `collider_states`: per
    /// collider centre, rotation vector, velocity and angular velocity
    /// ([`colliders::STATE_PER_COLLIDER`] numbers).
    pub fn collider_states(&self, frame: usize) -> Vec<f64> {
        self.colliders.iter().flat_map(|c| c.state(frame)).collect()
    }

    /// The boundary-condition signal at `frame`: per handle, linear and angular velocity,
    /// translation and rotation vector ([`SIGNAL_PER_HANDLE`] numbers).
    pub fn signal(&self, frame: usize) -> Vec<f64> {
        let mut out = Vec::with_capacity(self.tracks.len() * SIGNAL_PER_HANDLE);
        for t in &self.tracks {
            out.extend_from_slice(&t.velocities[frame]);
            let pose = &t.poses[frame];
            out.extend_from_slice(pose.translation.as_slice());
            out.extend_from_slice(pose.rotation.scaled_axis().as_slice());
        }
        out
    }
}

/// How a handle moves in sampled sequences (scene field `handles.motion`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionSpec {
    /// Range of segment lengths in frames.
    #[serde(default = "default_segment_frames")]
    pub segment_frames: [usize; 2],
    /// Translation directions to choose from (a random sign is applied).
    #[serde(default)]
    pub directions: Vec<[f64; 3]>,
    /// Rotation axes to choose from (a random sign is applied).
    #[serde(default)]
    pub rotation_axes: Vec<[f64; 3]>,
    /// Probability that a segment rotates rather than translates.
    #[serde(default)]
    pub rotation_share: f64,
    /// Training range of linear speeds (units / s).
    #[serde(default)]
    pub speed: [f64; 2],
    /// Training range of angular speeds (rad / s).
    #[serde(default)]
    pub angular_speed: [f64; 2],
    /// Follow every segment by its reverse, so the handle returns where it started.
    #[serde(default = "default_true")]
    pub back_and_forth: bool,
}

fn default_segment_frames() -> [usize; 2] {
    [15, 30]
}
fn default_true() -> bool {
    true
}

impl MotionSpec {
    /// Checks ranges and directions; returns the offending field name and a message.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        let [lo, hi] = self.segment_frames;
        if lo == 0 || hi < lo {
            return Err(("segment_frames", format!("needs 1 <= min <= max, got [{lo}, {hi}]")));
        }
        for (field, range) in [("speed", self.speed), ("angular_speed", self.angular_speed)] {
            if !range.iter().all(|v| v.is_finite() && *v >= 0.0) || range[1] < range[0] {
                return Err((field, format!("needs finite 0 <= min <= max, got {range:?}")));
            }
        }
        for (field, dirs) in [("directions", &self.directions), ("rotation_axes", &self.rotation_axes)] {
            if dirs
                .iter()
                .any(|d| !d.iter().all(|c| c.is_finite()) || V3::from(*d).norm() < 1e-12)
            {
                return Err((field, "every entry must be a finite non-zero vector".into()));
            }
        }
        if !(0.0..=1.0).contains(&self.rotation_share) {
            return Err((
                "rotation_share",
                format!("must be in [0, 1], got {}", self.rotation_share),
            ));
        }
        if self.rotation_share > 0.0 && self.rotation_axes.is_empty() {
            return Err(("rotation_axes", "rotation_share > 0 needs at least one axis".into()));
        }
        if self.rotation_share < 1.0 && self.directions.is_empty() && !self.rotation_axes.is_empty() {
            return Err(("directions", "translating segments need at least one direction".into()));
        }
        Ok(())
    }

    /// Linear and angular speed at `level`: 0 is the bottom of the training ranges, 1 the
    /// top; levels above 1 extrapolate beyond the training range.
    pub fn speeds_at(&self, level: f64) -> (f64, f64) {
        let lerp = |r: [f64; 2]| r[0] + level * (r[1] - r[0]);
        (lerp(self.speed), lerp(self.angular_speed))
    }

    /// The same motion with every segment of one length, the fraction `share` (0 shortest,
    /// 1 longest, clamped) of the way through `segment_frames`: a steady rhythm.
    pub fn steady(&self, share: f64) -> MotionSpec {
        let [lo, hi] = self.segment_frames;
        let len = lo + (share.clamp(0.0, 1.0) * (hi - lo) as f64).round() as usize;
        MotionSpec {
            segment_frames: [len, len],
            ..self.clone()
        }
    }

    /// Samples segments covering `frames`, using `speeds(frame) = (linear, angular)` for a
    /// segment starting at `frame`, with directions and lengths drawn from `rng`.
    pub fn sample(&self, frames: usize, speeds: &dyn Fn(usize) -> (f64, f64), rng: &mut ChaCha8Rng) -> Vec<Segment> {
        let mut segments = Vec::new();
        let mut frame = 0;
        if self.directions.is_empty() && self.rotation_axes.is_empty() {
            return segments;
        }
        while frame < frames {
            let len = rng.random_range(self.segment_frames[0]..=self.segment_frames[1]);
            let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
            let (lin, ang) = speeds(frame);
            let rotate =
                !self.rotation_axes.is_empty() && (self.directions.is_empty() || rng.random_bool(self.rotation_share));
            let mut seg = Segment {
                frames: len,
                velocity: [0.0; 3],
                angular_velocity: [0.0; 3],
            };
            if rotate {
                let axis = V3::from(self.rotation_axes[rng.random_range(0..self.rotation_axes.len())]).normalize();
                seg.angular_velocity = (axis * sign * ang).into();
            } else {
                let dir = V3::from(self.directions[rng.random_range(0..self.directions.len())]).normalize();
                seg.velocity = (dir * sign * lin).into();
            }
            segments.push(seg);
            frame += len;
            if self.back_and_forth && frame < frames {
                let (lin2, ang2) = speeds(frame);
                let scale = |v: [f64; 3], s: f64, s0: f64| {
                    let f = if s0 > 0.0 { s / s0 } else { 0.0 };
                    [-v[0] * f, -v[1] * f, -v[2] * f]
                };
                segments.push(Segment {
                    frames: len,
                    velocity: scale(seg.velocity, lin2, lin),
                    angular_velocity: scale(seg.angular_velocity, ang2, ang),
                });
                frame += len;
            }
        }
        segments
    }
}

/// A seeded random generator for motion sampling (ChaCha8: same stream on every platform).
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

#[cfg(test)]
mod tests;
