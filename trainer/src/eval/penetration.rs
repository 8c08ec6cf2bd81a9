//! Penetration of a rollout's surface into the scene's run-time colliders, with and without
//! the runtime's push-out correction (`mochi_runtime::collider::push_out`, docs/design.md
//! decision 11): how deep the deepest surface vertex goes, in how many frames any vertex is
//! inside a collider or deeper than the barrier's `dhat`, and what the correction does to the
//! error against the reference.

use mochi_runtime::collider::{push_out, shape_from_row, Collider as RuntimeCollider};
use mochi_sim::contact::{Collider, ColliderPose, ColliderShape};
use mochi_sim::measure::mean_and_max_error;
use mochi_sim::BuiltScene;

/// What a rollout measured of its colliders.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Penetration {
    /// The barrier's activation distance (m): the depth the acceptance allows.
    pub dhat: f64,
    /// Largest depth of a surface vertex inside a collider over the frames measured (m; 0
    /// when none went in).
    pub max_depth: f64,
    /// Share of the frames measured with a surface vertex inside a collider.
    pub inside_share: f64,
    /// Share of the frames measured with a surface vertex deeper than `dhat`.
    pub deep_share: f64,
    /// [`Penetration::max_depth`] after the runtime's push-out of the decoded surface.
    pub pushed_max_depth: f64,
    /// Mean vertex error / diagonal with the push-out applied, over the frames compared with
    /// the reference (`NaN` when none were).
    pub pushed_mean_error: f64,
    /// Frames measured.
    pub frames: usize,
}

/// Accumulates [`Penetration`] frame by frame.
pub(crate) struct PenetrationMeter {
    vertices: Vec<usize>,
    shapes: Vec<ColliderShape>,
    totals: Penetration,
    inside_frames: usize,
    deep_frames: usize,
    pushed_errors: Vec<f64>,
    scratch: Vec<f32>,
}

impl PenetrationMeter {
    /// A meter for `problem`'s colliders and surface vertices; `None` without colliders.
    pub(crate) fn new(problem: &BuiltScene) -> Option<Self> {
        let barrier = problem.simulator.collider_barrier()?;
        if barrier.colliders().is_empty() {
            return None;
        }
        Some(PenetrationMeter {
            vertices: barrier.vertices().to_vec(),
            shapes: barrier.shapes(),
            totals: Penetration {
                dhat: barrier.dhat(),
                ..Default::default()
            },
            inside_frames: 0,
            deep_frames: 0,
            pushed_errors: Vec::new(),
            scratch: vec![0.0; 3 * barrier.vertices().len()],
        })
    }

    /// Measures the world state `x` with the colliders at `poses`; with `reference` (the
    /// frame's reference state and the diagonal) also the error after the push-out.
    pub(crate) fn frame(&mut self, x: &[f64], poses: &[ColliderPose], reference: Option<(&[f64], f64)>) {
        let colliders: Vec<Collider> = self
            .shapes
            .iter()
            .zip(poses)
            .map(|(&shape, &pose)| Collider { shape, pose })
            .collect();
        let depth = deepest(
            &colliders,
            self.vertices.iter().map(|&v| [x[3 * v], x[3 * v + 1], x[3 * v + 2]]),
        );
        let t = &mut self.totals;
        t.frames += 1;
        t.max_depth = t.max_depth.max(depth);
        self.inside_frames += usize::from(depth > 0.0);
        self.deep_frames += usize::from(depth > t.dhat);
        // The runtime's correction on the surface vertices, in f32 as a host runs it.
        for (k, &v) in self.vertices.iter().enumerate() {
            for i in 0..3 {
                self.scratch[3 * k + i] = x[3 * v + i] as f32;
            }
        }
        let runtime: Vec<RuntimeCollider> = colliders.iter().filter_map(runtime_collider).collect();
        if push_out(&mut self.scratch, 3, &runtime, 0.0).is_err() {
            return;
        }
        let pushed = deepest(
            &colliders,
            self.scratch
                .chunks_exact(3)
                .map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]),
        );
        t.pushed_max_depth = t.pushed_max_depth.max(pushed);
        if let Some((xr, diagonal)) = reference {
            let mut corrected = x.to_vec();
            for (k, &v) in self.vertices.iter().enumerate() {
                for i in 0..3 {
                    corrected[3 * v + i] = self.scratch[3 * k + i] as f64;
                }
            }
            self.pushed_errors
                .push(mean_and_max_error(&corrected, xr, 3, diagonal).0);
        }
    }

    /// What the frames measured.
    pub(crate) fn finish(mut self) -> Penetration {
        let frames = self.totals.frames.max(1) as f64;
        self.totals.inside_share = self.inside_frames as f64 / frames;
        self.totals.deep_share = self.deep_frames as f64 / frames;
        self.totals.pushed_mean_error = match self.pushed_errors.len() {
            0 => f64::NAN,
            n => self.pushed_errors.iter().sum::<f64>() / n as f64,
        };
        self.totals
    }
}

/// Largest depth (m, 0 when outside) of `points` inside any of `colliders`.
fn deepest(colliders: &[Collider], points: impl Iterator<Item = [f64; 3]>) -> f64 {
    points
        .flat_map(|p| colliders.iter().map(move |c| -c.signed_distance(&p)))
        .fold(0.0, f64::max)
}

/// The runtime's collider of a simulator collider (its shape row and pose, in f32).
fn runtime_collider(c: &Collider) -> Option<RuntimeCollider> {
    let (shape, size) = shape_from_row(&c.shape.parameters().map(|v| v as f32))?;
    Some(RuntimeCollider {
        shape,
        size,
        center: [c.pose.center.x as f32, c.pose.center.y as f32, c.pose.center.z as f32],
        rotation: c.pose.rotation_vector().map(|v| v as f32),
    })
}
