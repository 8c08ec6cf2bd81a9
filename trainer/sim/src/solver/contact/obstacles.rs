//! Obstacle meshes of the contact surface and their scripted motion (`keyframes`): where a
//! moving obstacle is at a time, and where its vertices sit among the stacked obstacle
//! coordinates.

use crate::contact::ContactSurface;

/// An obstacle mesh: its surface (indices into its own vertices), positions and scripted
/// motion.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactObstacle {
    /// The obstacle's contact surface.
    pub surface: ContactSurface,
    /// Its vertex positions (`dim` per vertex) before any motion.
    pub positions: Vec<f64>,
    /// Scripted translation: `[time (s), dx, dy, dz]`, increasing in time, linear in
    /// between, held before the first and after the last; empty for a static obstacle.
    pub keyframes: Vec<[f64; 4]>,
}

impl ContactObstacle {
    /// The translation at `time` (seconds).
    pub fn offset_at(&self, time: f64) -> [f64; 3] {
        let k = &self.keyframes;
        let (Some(first), Some(last)) = (k.first(), k.last()) else {
            return [0.0; 3];
        };
        let lerp = |a: &[f64; 4], b: &[f64; 4], s: f64| [1, 2, 3].map(|i| a[i] + s * (b[i] - a[i]));
        if time <= first[0] {
            return lerp(first, first, 0.0);
        }
        if time >= last[0] {
            return lerp(last, last, 0.0);
        }
        let j = k.partition_point(|f| f[0] <= time);
        let (a, b) = (&k[j - 1], &k[j]);
        lerp(a, b, (time - a[0]) / (b[0] - a[0]))
    }
}

/// A moving obstacle's place among the stacked obstacle coordinates, and its script.
pub(super) struct ObstacleScript {
    pub(super) range: std::ops::Range<usize>,
    pub(super) obstacle: ContactObstacle,
}

impl ObstacleScript {
    /// Writes the obstacle at `time` (its rest positions in `rest`, translated) into `out`.
    pub(super) fn place(&self, rest: &[f64], time: f64, out: &mut [f64]) {
        let offset = self.obstacle.offset_at(time);
        let dim = self.obstacle.surface.dim;
        for (p, r) in out[self.range.clone()]
            .chunks_mut(dim)
            .zip(rest[self.range.clone()].chunks(dim))
        {
            for i in 0..dim {
                p[i] = r[i] + offset[i];
            }
        }
    }
}
