//! What every target runs (host, Cortex-M4, wasm, the C program): a fixed boundary-condition
//! script, a checksum of the decoded positions, and the positions every [`SAMPLE_EVERY`]
//! frames, so that their outputs can be compared with the host's.
//!
//! The script uses only IEEE-754 single-precision arithmetic and `libm` (a software library,
//! the same bits on every machine). What targets agree on depends on the weight storage (see
//! `mochi_runtime::network`): with `f16` and int8 weights the kernels fix every bit, so every
//! target's checksums equal the host's ([`bit_identical`]); with `f32` weights each target may
//! use fused multiply-add and its own vector width, and its positions stay within `1e-5` of
//! the rest diagonal of the host's at every sampled frame of the 1,000.
#![no_std]

use mochi_runtime::collider::{ColliderState, MAX_COLLIDERS};
use mochi_runtime::model::MAX_HANDLES;
use mochi_runtime::{DecodeError, HandleMotion, Instance, SizeError, StepError, ValidModel};

/// How far a target's unit render normals may lie from the host's (the length of their
/// difference) with `f32` weights: a normal is a difference of positions over an edge, so it
/// moves by [`TOLERANCE`] times the diagonal over the edge length; 1e-3 is 0.06 degrees.
pub const NORMAL_TOLERANCE: f32 = 1e-3;

/// Frames of the reference run every target makes.
pub const FRAMES: u32 = 1000;

/// Frames after which targets report the running checksum (the last is [`FRAMES`]).
pub const CHECKPOINTS: [u32; 4] = [1, 10, 100, FRAMES];

/// A target with `f32` weights reports its positions every this many frames.
pub const SAMPLE_EVERY: u32 = 10;

/// Frames whose positions a target with `f32` weights reports.
pub const SAMPLES: usize = (FRAMES / SAMPLE_EVERY) as usize;

/// Largest distance between a target's positions and the host's at any sampled frame, in
/// rest diagonals, where the storage is not [`bit_identical`].
pub const TOLERANCE: f32 = 1e-5;

/// Whether models with the weight storage `weights` (`f32`, `f16`, `int8`) give the same bits
/// on every target (their checksums are compared), or agree within [`TOLERANCE`] (their
/// sampled positions are).
pub fn bit_identical(weights: &str) -> bool {
    weights != "f32"
}

/// Whether a target running `weights` reports the positions of `frame` (`frame <n> ...`).
pub fn sampled(weights: &str, frame: u32) -> bool {
    !bit_identical(weights) && frame.is_multiple_of(SAMPLE_EVERY) && frame <= FRAMES
}

/// The fixed boundary-condition script: every handle sways along y and z and twists about x,
/// with an amplitude of a tenth of the model's rest bounding-box diagonal (speeds inside the
/// ranges the shipped scenes train on); every run-time collider slot of a model that has them
/// circles the top of the body's rest bounding box, turning as it goes
/// ([`Script::collider`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Script {
    amplitude: f32,
    dt: f32,
    /// Centre of the rest bounding box's top face.
    top: [f32; 3],
    /// Radius of the colliders' circle: a quarter of the rest diagonal.
    circle: f32,
}

/// Seconds per turn of a collider round the body.
const COLLIDER_PERIOD: f32 = 5.0;

/// Seconds per sway period along y, along z, and of the twist.
const PERIODS: [f32; 3] = [3.0, 4.5, 4.0];
/// Twist amplitude in radians.
const TWIST: f32 = 0.2;

impl Script {
    /// The script for a model with rest positions `rest` (`dim` per vertex) and time step `dt`.
    pub fn new(rest: &[f32], dim: usize, dt: f32) -> Self {
        let (lo, hi) = bounds(rest, dim);
        let diagonal = diagonal(rest, dim);
        Script {
            amplitude: 0.1 * diagonal,
            dt,
            top: [0.5 * (lo[0] + hi[0]), hi[1], 0.5 * (lo[2] + hi[2])],
            circle: 0.25 * diagonal,
        }
    }

    /// The script for `model`.
    pub fn for_model(model: &ValidModel) -> Self {
        let m = model.model();
        Script::new(m.rest(), m.dim(), m.dt)
    }

    /// Translation and rotation vector of every handle at the end of `frame`.
    pub fn pose(&self, frame: u32) -> ([f32; 3], [f32; 3]) {
        let t = frame as f32 * self.dt;
        let phase = |period: f32| libm::sinf(2.0 * core::f32::consts::PI * t / period);
        let translation = [
            0.0,
            self.amplitude * phase(PERIODS[0]),
            0.5 * self.amplitude * phase(PERIODS[1]),
        ];
        (translation, [TWIST * phase(PERIODS[2]), 0.0, 0.0])
    }

    /// Centre and rotation vector of collider slot `slot` of `slots` at the end of `frame`:
    /// on a circle of a quarter diagonal round the centre of the rest bounding box's top face
    /// (the slots evenly apart on it), turning about y once per turn round the body.
    pub fn collider_pose(&self, frame: u32, slot: usize, slots: usize) -> ([f32; 3], [f32; 3]) {
        let turns = frame as f32 * self.dt / COLLIDER_PERIOD + slot as f32 / slots.max(1) as f32;
        let angle = 2.0 * core::f32::consts::PI * (turns - libm::floorf(turns));
        let centre = [
            self.top[0] + self.circle * libm::cosf(angle),
            self.top[1],
            self.top[2] + self.circle * libm::sinf(angle),
        ];
        // The rotation vector's angle in (-pi, pi].
        let spin = if angle > core::f32::consts::PI {
            angle - 2.0 * core::f32::consts::PI
        } else {
            angle
        };
        (centre, [0.0, spin, 0.0])
    }

    /// The state of collider slot `slot` of `slots` over the step that ends at `frame`
    /// (velocities by finite difference of the poses, as [`Script::motion`]'s).
    pub fn collider(&self, frame: u32, slot: usize, slots: usize) -> ColliderState {
        let (c1, r1) = self.collider_pose(frame, slot, slots);
        let (c0, _) = self.collider_pose(frame.saturating_sub(1), slot, slots);
        let spin = 2.0 * core::f32::consts::PI / COLLIDER_PERIOD;
        ColliderState {
            center: c1,
            rotation: r1,
            linear_velocity: [0, 1, 2].map(|i| (c1[i] - c0[i]) / self.dt),
            angular_velocity: [0.0, if frame == 0 { 0.0 } else { spin }, 0.0],
        }
    }

    /// The motion of every handle over the step that ends at `frame` (velocities by finite
    /// difference of the poses, the way an engine that tracks poses gets them).
    pub fn motion(&self, frame: u32) -> HandleMotion {
        let (t1, r1) = self.pose(frame);
        let (t0, r0) = self.pose(frame.saturating_sub(1));
        let rate = |a: [f32; 3], b: [f32; 3]| [0, 1, 2].map(|i| (a[i] - b[i]) / self.dt);
        HandleMotion {
            linear_velocity: rate(t1, t0),
            // The twist keeps its axis, so the angular velocity is the rotation vector's rate.
            angular_velocity: rate(r1, r0),
            translation: t1,
            rotation: r1,
        }
    }
}

/// Rest bounding-box diagonal of `rest` (`dim` coordinates per vertex).
pub fn diagonal(rest: &[f32], dim: usize) -> f32 {
    let (lo, hi) = bounds(rest, dim);
    let squared: f32 = (0..3).map(|c| (hi[c] - lo[c]) * (hi[c] - lo[c])).sum();
    libm::sqrtf(squared)
}

/// Rest bounding box of `rest` (`dim` coordinates per vertex; zero extent along the axes it
/// lacks, and for no vertices).
fn bounds(rest: &[f32], dim: usize) -> ([f32; 3], [f32; 3]) {
    let dim = dim.clamp(1, 3);
    let (mut lo, mut hi) = ([0.0f32; 3], [0.0f32; 3]);
    for c in 0..dim {
        let values = rest.iter().skip(c).step_by(dim);
        let min = values.clone().fold(f32::INFINITY, |a, &b| a.min(b));
        let max = values.fold(f32::NEG_INFINITY, |a, &b| a.max(b));
        if max >= min {
            (lo[c], hi[c]) = (min, max);
        }
    }
    (lo, hi)
}

/// FNV-1a (64-bit) over the bit patterns of every decoded coordinate of every frame, in
/// order: equal checksums mean bit-identical positions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Checksum(pub u64);

impl Default for Checksum {
    fn default() -> Self {
        Checksum(0xcbf2_9ce4_8422_2325)
    }
}

impl Checksum {
    /// Folds the coordinates of one frame in.
    pub fn update(&mut self, positions: &[f32]) {
        for v in positions {
            for byte in v.to_bits().to_le_bytes() {
                self.0 ^= u64::from(byte);
                self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
            }
        }
    }
}

/// Why a reference run stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunError {
    /// The instance type does not fit the model.
    Size(SizeError),
    /// A step was refused.
    Step(StepError),
    /// A decode was refused or gave a non-finite state.
    Decode(DecodeError),
}

impl core::fmt::Display for RunError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            RunError::Size(e) => write!(f, "instance: {e}"),
            RunError::Step(e) => write!(f, "step: {e}"),
            RunError::Decode(e) => write!(f, "decode: {e}"),
        }
    }
}

/// Runs `model` from rest for `frames` frames of the [`Script`], decoding every frame into
/// `positions` (`state_len` numbers) and folding it into the checksum; `visit(frame,
/// checksum, positions)` sees every frame (1-based). Returns the final checksum.
pub fn run<const K: usize, const S: usize, const H: usize>(
    model: &ValidModel,
    frames: u32,
    positions: &mut [f32],
    mut visit: impl FnMut(u32, Checksum, &[f32]),
) -> Result<Checksum, RunError> {
    let mut checksum = Checksum::default();
    step_script::<K, S, H>(model, frames, |frame, body| {
        body.decode_into(model, positions).map_err(RunError::Decode)?;
        checksum.update(positions);
        visit(frame, checksum, positions);
        Ok(())
    })?;
    Ok(checksum)
}

/// As [`run`], decoding the model's render mesh instead
/// ([`mochi_runtime::Instance::decode_render_into`]: the full decode into `sim`, then the
/// render positions and normals, `render_len` numbers each), the checksum folding in the
/// positions and then the normals of every frame; `visit(frame, checksum, positions,
/// normals)`. A model without a render mesh folds in nothing.
pub fn run_render<const K: usize, const S: usize, const H: usize>(
    model: &ValidModel,
    frames: u32,
    sim: &mut [f32],
    positions: &mut [f32],
    normals: &mut [f32],
    mut visit: impl FnMut(u32, Checksum, &[f32], &[f32]),
) -> Result<Checksum, RunError> {
    let mut checksum = Checksum::default();
    step_script::<K, S, H>(model, frames, |frame, body| {
        body.decode_render_into(model, sim, positions, normals)
            .map_err(RunError::Decode)?;
        checksum.update(positions);
        checksum.update(normals);
        visit(frame, checksum, positions, normals);
        Ok(())
    })?;
    Ok(checksum)
}

/// Steps `model` from rest through `frames` frames of the [`Script`] (every handle the same
/// motion, each collider slot on its circle), handing the instance to `after_step(frame,
/// body)` after each step.
fn step_script<const K: usize, const S: usize, const H: usize>(
    model: &ValidModel,
    frames: u32,
    mut after_step: impl FnMut(u32, &Instance<K, S, H>) -> Result<(), RunError>,
) -> Result<(), RunError> {
    let script = Script::for_model(model);
    let m = model.model();
    let handles = m.handles.len().min(MAX_HANDLES);
    let slots = m.colliders().min(MAX_COLLIDERS);
    let mut body = Instance::<K, S, H>::new(model).map_err(RunError::Size)?;
    let mut bc = [HandleMotion::REST; MAX_HANDLES];
    let mut colliders = [ColliderState::default(); MAX_COLLIDERS];
    for frame in 1..=frames {
        bc[..handles].fill(script.motion(frame));
        for (slot, c) in colliders[..slots].iter_mut().enumerate() {
            *c = script.collider(frame, slot, slots);
        }
        body.step_with(model, &bc[..handles], &colliders[..slots], m.dt)
            .map_err(RunError::Step)?;
        after_step(frame, &body)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checksum_tells_bit_patterns_apart() {
        let mut a = Checksum::default();
        let mut b = Checksum::default();
        a.update(&[0.0, 1.0]);
        b.update(&[-0.0, 1.0]);
        assert_ne!(a, b);
        let mut c = Checksum::default();
        c.update(&[0.0, 1.0]);
        assert_eq!(a, c);
    }

    #[test]
    fn script_starts_at_rest_and_moves() {
        let script = Script::new(&[0.0, 0.0, 0.0, 3.0, 4.0, 0.0], 3, 0.02);
        assert_eq!(script.amplitude, 0.5);
        let rest = script.motion(0);
        assert_eq!(rest, HandleMotion::REST);
        let m = script.motion(10);
        assert!(m.translation[1] > 0.0 && m.linear_velocity[1] > 0.0 && m.rotation[0] > 0.0);
        // Velocity is the finite difference of the poses.
        let (t9, _) = script.pose(9);
        assert!((m.linear_velocity[1] - (m.translation[1] - t9[1]) / 0.02).abs() < 1e-6);
    }

    #[test]
    fn colliders_circle_the_top_of_the_body_apart_and_turn() {
        // A 3 x 4 box from the origin: its top face centre (1.5, 4, 0), diagonal 5.
        let script = Script::new(&[0.0, 0.0, 0.0, 3.0, 4.0, 0.0], 3, 0.02);
        let (c, r) = script.collider_pose(0, 0, 2);
        assert_eq!((c, r), ([1.5 + 1.25, 4.0, 0.0], [0.0; 3]));
        let (c, _) = script.collider_pose(0, 1, 2);
        assert!((c[0] - (1.5 - 1.25)).abs() < 1e-6 && c[2].abs() < 1e-6, "{c:?}");
        let s = script.collider(50, 0, 1);
        let (c49, _) = script.collider_pose(49, 0, 1);
        let radius = libm::sqrtf((s.center[0] - 1.5).powi(2) + s.center[2].powi(2));
        assert!((radius - 1.25).abs() < 1e-5 && s.center[1] == 4.0);
        assert!((s.linear_velocity[2] - (s.center[2] - c49[2]) / 0.02).abs() < 1e-4);
        assert!(s.rotation[1] > 0.0 && s.angular_velocity[1] > 0.0);
        // Past half a turn the rotation vector's angle stays in (-pi, pi].
        assert!(script.collider(150, 0, 1).rotation[1] < 0.0);
    }
}

/// What a target printed (the protocol every target follows) and its check against the host.
#[cfg(feature = "std")]
pub mod host {
    extern crate std;

    use std::string::{String, ToString};
    use std::vec::Vec;
    use std::{format, vec};

    use super::*;

    /// A target's report: checksums at the [`CHECKPOINTS`] and the final positions.
    #[derive(Clone, Debug, Default, PartialEq)]
    pub struct Report {
        /// Model name.
        pub model: String,
        /// Weight storage.
        pub weights: String,
        /// Frames run.
        pub frames: u32,
        /// `(frame, checksum)` per checkpoint.
        pub checksums: Vec<(u32, u64)>,
        /// Decoded positions of the final frame.
        pub positions: Vec<f32>,
        /// `(frame, positions)` every [`SAMPLE_EVERY`] frames (`f32` weights).
        pub samples: Vec<(u32, Vec<f32>)>,
        /// Instructions per frame (step + full decode), where the target counts them.
        pub instructions_per_frame: Option<u64>,
        /// `(frame, checksum)` of the render pass ([`super::run_render`]) per checkpoint;
        /// empty for a model without a render mesh.
        pub render_checksums: Vec<(u32, u64)>,
        /// Render positions of the render pass's final frame.
        pub render_positions: Vec<f32>,
        /// Render normals of the render pass's final frame.
        pub render_normals: Vec<f32>,
        /// Instructions per frame of the render decode alone (full decode, render positions
        /// and normals), where the target counts them.
        pub render_instructions_per_frame: Option<u64>,
    }

    /// Parses a target's output:
    ///
    /// ```text
    /// model <name> weights <f32|f16|int8> frames <N>
    /// checksum <frame> <16 hex digits>       (one per checkpoint)
    /// frame <n> <8 hex digits per float>    (every SAMPLE_EVERY frames, f32 weights only)
    /// positions <8 hex digits per float>    (final frame)
    /// instructions_per_frame <count>        (optional)
    /// render_checksum <frame> <16 hex digits> (one per checkpoint; a model with a render mesh)
    /// render_positions <8 hex digits per float> (final frame of the render pass)
    /// render_normals <8 hex digits per float>
    /// render_instructions_per_frame <count> (optional)
    /// status ok
    /// ```
    pub fn parse(output: &str) -> Result<Report, String> {
        let mut report = Report::default();
        let mut ok = false;
        for line in output.lines() {
            let words: Vec<&str> = line.split_whitespace().collect();
            match words.as_slice() {
                ["model", name, "weights", weights, "frames", frames] => {
                    report.model = name.to_string();
                    report.weights = weights.to_string();
                    report.frames = frames.parse().map_err(|e| format!("frames `{frames}`: {e}"))?;
                }
                ["checksum", frame, hash] => report.checksums.push((
                    frame.parse().map_err(|e| format!("checksum frame `{frame}`: {e}"))?,
                    u64::from_str_radix(hash, 16).map_err(|e| format!("checksum `{hash}`: {e}"))?,
                )),
                ["positions", values @ ..] => {
                    report.positions = floats(values).map_err(|e| format!("positions: {e}"))?;
                }
                ["frame", frame, values @ ..] => {
                    let n = frame.parse().map_err(|e| format!("frame `{frame}`: {e}"))?;
                    report
                        .samples
                        .push((n, floats(values).map_err(|e| format!("frame {n}: {e}"))?));
                }
                ["render_checksum", frame, hash] => report.render_checksums.push((
                    frame
                        .parse()
                        .map_err(|e| format!("render_checksum frame `{frame}`: {e}"))?,
                    u64::from_str_radix(hash, 16).map_err(|e| format!("render_checksum `{hash}`: {e}"))?,
                )),
                ["render_positions", values @ ..] => {
                    report.render_positions = floats(values).map_err(|e| format!("render_positions: {e}"))?;
                }
                ["render_normals", values @ ..] => {
                    report.render_normals = floats(values).map_err(|e| format!("render_normals: {e}"))?;
                }
                ["render_instructions_per_frame", n] => {
                    report.render_instructions_per_frame = Some(
                        n.parse()
                            .map_err(|e| format!("render_instructions_per_frame `{n}`: {e}"))?,
                    );
                }
                ["instructions_per_frame", n] => {
                    report.instructions_per_frame =
                        Some(n.parse().map_err(|e| format!("instructions_per_frame `{n}`: {e}"))?);
                }
                ["status", "ok"] => ok = true,
                ["status", ..] => return Err(format!("target reported: {line}")),
                _ => {}
            }
        }
        if !ok {
            return Err(format!("no `status ok` line in the target's output:\n{output}"));
        }
        Ok(report)
    }

    /// The hexadecimal bit patterns of `values` as floats.
    fn floats(values: &[&str]) -> Result<Vec<f32>, std::num::ParseIntError> {
        values
            .iter()
            .map(|v| u32::from_str_radix(v, 16).map(f32::from_bits))
            .collect()
    }

    /// Runs the reference on the host with `Instance<K, S, H>` and checks `report` against it:
    /// the final positions, and every sampled frame's where the storage is `f32`, within
    /// [`TOLERANCE`] of the rest diagonal; for [`bit_identical`] storages, the checksums at
    /// every checkpoint too. Returns the largest distance / diagonal.
    pub fn check<const K: usize, const S: usize, const H: usize>(
        model: &ValidModel,
        report: &Report,
    ) -> Result<f32, String> {
        let m = model.model();
        let mut positions = vec![0.0f32; m.state_len()];
        let mut expected = Vec::new();
        let mut samples = Vec::new();
        run::<K, S, H>(model, report.frames, &mut positions, |frame, checksum, now| {
            if CHECKPOINTS.contains(&frame) {
                expected.push((frame, checksum.0));
            }
            if sampled(&report.weights, frame) {
                samples.push((frame, now.to_vec()));
            }
        })
        .map_err(|e| format!("host run: {e}"))?;
        let diagonal = diagonal(m.rest(), m.dim());
        let distance = |what: &str, target: &[f32], host: &[f32]| -> Result<f32, String> {
            if target.len() != host.len() {
                return Err(format!(
                    "target printed {} coordinates for {what}, the model has {}",
                    target.len(),
                    host.len()
                ));
            }
            let worst = target
                .chunks(m.dim())
                .zip(host.chunks(m.dim()))
                .map(|(a, b)| libm::sqrtf(a.iter().zip(b).map(|(a, b)| (a - b) * (a - b)).sum::<f32>()) / diagonal)
                .fold(0.0f32, |w, d| if d > w || d.is_nan() { d } else { w });
            if worst.is_nan() || worst > TOLERANCE {
                return Err(format!(
                    "{what}: positions differ from the host's by {worst:.3e} of the diagonal (limit {TOLERANCE:.0e})"
                ));
            }
            Ok(worst)
        };
        let mut worst = distance("the final frame", &report.positions, &positions)?;
        if report.samples.len() != samples.len() {
            return Err(format!(
                "target printed {} sampled frames, {} expected for {} weights",
                report.samples.len(),
                samples.len(),
                report.weights
            ));
        }
        for ((frame, target), (expected_frame, host)) in report.samples.iter().zip(&samples) {
            if frame != expected_frame {
                return Err(format!("target sampled frame {frame}, expected {expected_frame}"));
            }
            worst = worst.max(distance(&format!("frame {frame}"), target, host)?);
        }
        if bit_identical(&report.weights) && report.checksums != expected {
            return Err(format!(
                "checksums differ from the host's (positions within {worst:.1e} of the diagonal):\n  target {:x?}\n  host   {:x?}",
                report.checksums, expected
            ));
        }
        if m.has_render() {
            worst = worst.max(check_render::<K, S, H>(model, report)?);
        }
        Ok(worst)
    }

    /// The render pass of `report` against the host's [`run_render`]: the final frame's render
    /// positions within [`TOLERANCE`] of the rest diagonal, its normals within
    /// [`NORMAL_TOLERANCE`], and for [`bit_identical`] storages the checksums at every
    /// checkpoint. Returns the largest position distance / diagonal.
    fn check_render<const K: usize, const S: usize, const H: usize>(
        model: &ValidModel,
        report: &Report,
    ) -> Result<f32, String> {
        let m = model.model();
        let mut sim = vec![0.0f32; m.state_len()];
        let (mut positions, mut normals) = (vec![0.0f32; m.render_len()], vec![0.0f32; m.render_len()]);
        let mut expected = Vec::new();
        run_render::<K, S, H>(
            model,
            report.frames,
            &mut sim,
            &mut positions,
            &mut normals,
            |frame, sum, _, _| {
                if CHECKPOINTS.contains(&frame) {
                    expected.push((frame, sum.0));
                }
            },
        )
        .map_err(|e| format!("host render run: {e}"))?;
        let gap = |what: &str, target: &[f32], host: &[f32], scale: f32| -> Result<f32, String> {
            if target.len() != host.len() {
                return Err(format!(
                    "target printed {} {what}, the render mesh has {}",
                    target.len(),
                    host.len()
                ));
            }
            Ok(target
                .chunks(3)
                .zip(host.chunks(3))
                .map(|(a, b)| libm::sqrtf(a.iter().zip(b).map(|(a, b)| (a - b) * (a - b)).sum::<f32>()) / scale)
                .fold(0.0f32, |w, d| if d > w || d.is_nan() { d } else { w }))
        };
        let worst = gap(
            "render positions",
            &report.render_positions,
            &positions,
            diagonal(m.rest(), m.dim()),
        )?;
        if worst.is_nan() || worst > TOLERANCE {
            return Err(format!(
                "render positions differ from the host's by {worst:.3e} of the diagonal (limit {TOLERANCE:.0e})"
            ));
        }
        let turn = gap("render normals", &report.render_normals, &normals, 1.0)?;
        if turn.is_nan() || turn > NORMAL_TOLERANCE {
            return Err(format!(
                "render normals differ from the host's by {turn:.3e} (limit {NORMAL_TOLERANCE:.0e})"
            ));
        }
        if bit_identical(&report.weights) && report.render_checksums != expected {
            return Err(format!(
                "render checksums differ from the host's:\n  target {:x?}\n  host   {:x?}",
                report.render_checksums, expected
            ));
        }
        Ok(worst)
    }
}
