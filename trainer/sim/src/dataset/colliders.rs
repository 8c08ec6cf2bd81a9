//! The analytic colliders of a dataset's sequences: their paths, drawn from the sequence's
//! seed at the sequence's speeds ([`crate::bc::colliders`]), placing and moving them in the
//! simulator frame by frame, and what trajectories record of them.

use super::SpeedPlan;
use crate::bc::colliders::PathSetting;
use crate::bc::{self, BcSequence, ColliderTrack};
use crate::contact::ColliderBarrier;
use crate::scene::BuiltScene;
use crate::solver::StepError;
use crate::trajectory::{ColliderFrames, Trajectory, COLLIDER_LAYOUT};
use rand::Rng;

#[cfg(test)]
mod tests;

/// Added to a sequence's seed, with [`COLLIDER_SEED_STRIDE`] per collider, for its path:
/// apart from the seeds of the handles' motions.
const COLLIDER_SEED_OFFSET: u64 = 0xc011_1de5;
/// See [`COLLIDER_SEED_OFFSET`].
const COLLIDER_SEED_STRIDE: u64 = 104_729;

impl BuiltScene {
    /// The colliders' tracks of a sequence of `frames` frames with speeds `speeds` and seed
    /// `seed`: a collider with a `motion` that the seed's draw lets take part follows a path
    /// drawn from the seed, one with a `placement` rests where the seed puts it (tilted by
    /// the speed level and factor of frame 0); the others rest at their parked pose. `handles` holds the
    /// handles' vertices at frame 0, which paths keep clear of.
    pub fn collider_tracks(
        &self,
        speeds: &SpeedPlan,
        frames: usize,
        seed: u64,
        handles: &[[f64; 3]],
    ) -> Vec<ColliderTrack> {
        let (lo, hi) = self.mesh.bounding_box(&self.mesh.rest);
        let setting = PathSetting {
            body: (lo, hi),
            fixed: handles,
            dt: self.scene.dt,
            frames,
        };
        self.scene
            .colliders
            .iter()
            .enumerate()
            .map(|(k, spec)| {
                let rotation = spec.orientation().rotation;
                let parked = spec.idle_pose(lo, hi);
                let rng = &mut bc::rng(
                    seed.wrapping_add(COLLIDER_SEED_OFFSET)
                        .wrapping_add(COLLIDER_SEED_STRIDE.wrapping_mul(k as u64)),
                );
                if let Some(placement) = &spec.placement {
                    return ColliderTrack::resting(placement.sample(rotation, speeds.at(0), rng), frames);
                }
                let (Some(motion), Ok(shape)) = (&spec.motion, spec.shape()) else {
                    return ColliderTrack::resting(parked, frames);
                };
                if !rng.random_bool(motion.share) {
                    return ColliderTrack::resting(parked, frames);
                }
                let speed = |frame: usize| {
                    let (level, factor) = speeds.at(frame);
                    let [low, high] = motion.speed;
                    (low + level * (high - low)) * factor
                };
                let poses = motion.sample(&shape, rotation, &setting, &speed, rng);
                ColliderTrack::from_poses(poses, self.scene.dt)
            })
            .collect()
    }

    /// Places the colliders at frame 0 of `seq` (at their idle poses when `seq` has no
    /// collider tracks).
    pub(super) fn place_colliders(&mut self, seq: &BcSequence) -> Result<(), StepError> {
        if self.scene.colliders.is_empty() {
            return Ok(());
        }
        let poses = if seq.colliders.is_empty() {
            let (lo, hi) = self.mesh.bounding_box(&self.mesh.rest);
            self.scene.colliders.iter().map(|spec| spec.idle_pose(lo, hi)).collect()
        } else {
            seq.collider_poses(0)
        };
        self.simulator.place_colliders(&poses)
    }

    /// Sends the colliders to their poses at `frame` of `seq` for the next step (they stay
    /// where they are when `seq` has no collider tracks).
    pub(super) fn move_colliders(&mut self, seq: &BcSequence, frame: usize) -> Result<(), StepError> {
        if seq.colliders.is_empty() {
            return Ok(());
        }
        self.simulator.set_collider_poses(&seq.collider_poses(frame))
    }

    /// The colliders' rows of a trajectory's first frame (`None` without colliders).
    pub(super) fn collider_frames(&self, seq: &BcSequence) -> Option<ColliderFrames> {
        let barrier = self
            .simulator
            .collider_barrier()
            .filter(|b| !b.colliders().is_empty())?;
        Some(ColliderFrames {
            names: (0..self.scene.colliders.len())
                .map(|k| self.scene.colliders[k].name_or_default(k))
                .collect(),
            shapes: barrier.shapes().iter().map(|s| s.parameters()).collect(),
            states: vec![collider_states(barrier, seq, 0)],
        })
    }

    /// Appends the colliders' states after the step to `frame` to `traj`.
    pub(super) fn record_colliders(&self, seq: &BcSequence, frame: usize, traj: &mut Trajectory) {
        if let (Some(c), Some(barrier)) = (&mut traj.colliders, self.simulator.collider_barrier()) {
            c.states.push(collider_states(barrier, seq, frame));
        }
    }

    /// The layout entry of a trajectory's metadata, when the scene has colliders.
    pub(super) fn collider_meta(&self) -> Option<(String, String)> {
        (!self.scene.colliders.is_empty()).then(|| ("collider_layout".into(), COLLIDER_LAYOUT.into()))
    }
}

/// The colliders' poses where the simulator has them and their velocities from `seq`'s
/// tracks (zero when it has none) at `frame`, one row.
fn collider_states(barrier: &ColliderBarrier, seq: &BcSequence, frame: usize) -> Vec<f64> {
    let mut row = Vec::new();
    for (k, pose) in barrier.poses().iter().enumerate() {
        let track = ColliderTrack {
            poses: vec![*pose],
            velocities: vec![seq.colliders.get(k).map_or([0.0; 6], |t| t.velocities[frame])],
        };
        row.extend_from_slice(&track.state(0));
    }
    row
}

/// The smallest signed distance of a vertex `vertices` to a collider over every frame of
/// `traj` (negative: the deepest penetration), or `None` without colliders.
pub fn closest_collider_approach(traj: &Trajectory, vertices: &[usize]) -> Option<f64> {
    let c = traj.colliders.as_ref()?;
    let closest = traj
        .positions
        .iter()
        .enumerate()
        .map(|(frame, x)| ColliderBarrier::new(vertices.to_vec(), c.colliders_at(frame), 1.0).min_signed_distance(x))
        .fold(f64::INFINITY, f64::min);
    Some(closest)
}
