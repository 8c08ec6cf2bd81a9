//! One simulated object: the state of a latent rollout (last two latents and the last two
//! boundary-condition signals), stepped and decoded against a shared [`ValidModel`].

use core::fmt;

use nalgebra::Vector3;

use crate::collider::{features, ColliderState, FEATURES_PER_COLLIDER, MAX_COLLIDERS};
use crate::decode::{
    consecutive, consecutive_ascending, decode_run, decoder_features, placed_free, put, walk_chains, ListCursors,
    Origins, OutputRows,
};
use crate::finite::all_finite;
use crate::frame::{HandleMotion, Placement};
use crate::model::{Layer, Model, ModelError, Weights, HANDLE_SOURCE, SIGNAL_PER_HANDLE};
use crate::network::hidden;

/// Latent room of an [`AnyInstance`].
pub const MAX_LATENT: usize = 64;
/// Signal room of an [`AnyInstance`] (every handle a model may have).
pub const MAX_SIGNAL: usize = SIGNAL_PER_HANDLE * crate::model::MAX_HANDLES;
/// Hidden-width room of an [`AnyInstance`].
pub const MAX_HIDDEN: usize = 1024;

/// An instance with room for any model up to [`MAX_LATENT`], [`MAX_SIGNAL`] and
/// [`MAX_HIDDEN`], for hosts that pick models at run time (tools, the C ABI); generated code
/// sizes its `Instance` exactly instead.
pub type AnyInstance = Instance<MAX_LATENT, MAX_SIGNAL, MAX_HIDDEN>;

/// How far a latent may leave the range seen in training before it is clamped, as a fraction
/// of that range's width on each side.
pub const RANGE_MARGIN: f32 = 1.0;

/// A model that passed [`Model::validate`]; only these can be stepped and decoded, so the
/// kernels never meet an inconsistent shape.
#[derive(Clone, Copy, Debug)]
pub struct ValidModel<'a>(Model<'a>);

impl<'a> ValidModel<'a> {
    /// Validates `model`.
    pub fn new(model: Model<'a>) -> Result<Self, ModelError> {
        model.validate()?;
        Ok(ValidModel(model))
    }
    /// `model`, already validated by the caller (storage that validated it when it was loaded).
    pub(crate) fn validated(model: Model<'a>) -> Self {
        ValidModel(model)
    }
    /// The model.
    pub fn model(&self) -> &Model<'a> {
        &self.0
    }
}

/// Why a step was refused (the instance is left as it was).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StepError {
    /// `bc` must hold one motion per handle.
    HandleCount {
        /// Handles of the model.
        expected: usize,
        /// Motions given.
        found: usize,
    },
    /// The motion of this handle holds a NaN or an infinity.
    NotFinite {
        /// Index of the handle.
        handle: usize,
    },
    /// The model's sizes are not the ones this instance was compiled for.
    Model(SizeError),
    /// The frame time given to [`Instance::step_dt`] is not a positive finite number.
    FrameTime,
    /// The model was trained at the one frame time [`Model::dt`] (it does not take the frame
    /// time as an input) and another was given.
    FixedFrameTime,
    /// More colliders were given than the model has slots.
    ColliderCount {
        /// Collider slots of the model.
        slots: usize,
        /// Colliders given.
        found: usize,
    },
    /// The state of this collider holds a NaN or an infinity.
    ColliderNotFinite {
        /// Index of the collider.
        collider: usize,
    },
}

/// Relative difference from [`Model::dt`] within which a model of one frame time accepts a
/// frame time given to [`Instance::step_dt`] (a host's rounding of `1/30`).
pub const FRAME_TIME_TOLERANCE: f32 = 1e-4;

/// Why a decode was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DecodeError {
    /// The output buffer must hold `expected` numbers.
    BufferLength {
        /// Numbers required.
        expected: usize,
        /// Length of the buffer given.
        found: usize,
    },
    /// The decoded state was not finite; the buffer holds the rest positions instead.
    NotFinite,
    /// The model's sizes are not the ones this instance was compiled for.
    Model(SizeError),
}

/// Why an instance cannot run a model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SizeError {
    /// Which compile-time size does not fit: `latent`, `signal` or `hidden`.
    pub size: &'static str,
    /// What the model needs.
    pub model: usize,
    /// What the instance type was compiled with.
    pub compiled: usize,
}

impl fmt::Display for StepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StepError::HandleCount { expected, found } => {
                write!(f, "{found} handle motions given, the model has {expected} handles")
            }
            StepError::NotFinite { handle } => write!(f, "motion of handle {handle} is not finite"),
            StepError::Model(e) => write!(f, "{e}"),
            StepError::FrameTime => write!(f, "frame time is not a positive finite number"),
            StepError::FixedFrameTime => write!(
                f,
                "the model was trained at one frame time (its `dt`) and does not take another"
            ),
            StepError::ColliderCount { slots, found } => {
                write!(f, "{found} colliders given, the model has {slots} collider slots")
            }
            StepError::ColliderNotFinite { collider } => write!(f, "state of collider {collider} is not finite"),
        }
    }
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DecodeError::BufferLength { expected, found } => {
                write!(f, "output buffer holds {found} numbers, expected {expected}")
            }
            DecodeError::NotFinite => write!(f, "decoded state is not finite; rest positions written"),
            DecodeError::Model(e) => write!(f, "{e}"),
        }
    }
}

impl fmt::Display for SizeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "model needs {} {}, instance compiled for {}",
            self.size, self.model, self.compiled
        )
    }
}

#[cfg(feature = "std")]
impl std::error::Error for StepError {}
#[cfg(feature = "std")]
impl std::error::Error for DecodeError {}
#[cfg(feature = "std")]
impl std::error::Error for SizeError {}

/// What a step did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stepped {
    /// Advanced normally.
    Ok,
    /// The new latent left the trained range by more than [`RANGE_MARGIN`] and was clamped.
    Clamped,
    /// The network produced a non-finite latent; the previous latent was kept.
    Held,
}

/// The state of one object, with room for `K` latent coordinates and `S` boundary-condition
/// numbers; `H` is the widest hidden layer the instance can run (scratch lives on the stack
/// during calls, not in the instance). Generated code sizes these exactly for its model; a
/// C engine uses one type with room for any model (`capi`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Instance<const K: usize, const S: usize, const H: usize> {
    z: [f32; K],
    z_prev: [f32; K],
    signal: [f32; S],
    signal_prev: [f32; S],
    /// Latent size and signal length of the model the instance was created for.
    latent: u16,
    signal_len: u16,
    frames: u32,
}

impl<const K: usize, const S: usize, const H: usize> Instance<K, S, H> {
    /// An instance at the model's rest state, handles at their reference placement.
    pub fn new(model: &ValidModel) -> Result<Self, SizeError> {
        let m = model.model();
        for (size, need, room) in [
            ("latent", m.latent as usize, K),
            ("signal", m.bc_len as usize, S),
            ("hidden", m.hidden(), H),
        ] {
            if need > room {
                return Err(SizeError {
                    size,
                    model: need,
                    compiled: room,
                });
            }
        }
        let mut z = [0.0; K];
        let latent = m.initial_latent();
        z[..latent.len()].copy_from_slice(latent);
        Ok(Instance {
            z,
            z_prev: z,
            signal: [0.0; S],
            signal_prev: [0.0; S],
            latent: m.latent as u16,
            signal_len: m.bc_len as u16,
            frames: 0,
        })
    }

    /// Checks that `model` has the sizes this instance was created for (every call checks: an
    /// instance may be handed a different model than the one it was created with) and that
    /// they fit the instance's room (instance memory that a C caller overwrote may claim more
    /// than it has). Returns the latent size and signal length.
    fn check_sizes(&self, model: &ValidModel) -> Result<(usize, usize), SizeError> {
        let m = model.model();
        let (k, s) = (self.latent as usize, self.signal_len as usize);
        // An instance stores no hidden width: the model's need only fit the room.
        for (size, need, stored, room) in [
            ("latent", m.latent as usize, k, K),
            ("signal", m.bc_len as usize, s, S),
            ("hidden", m.hidden(), m.hidden(), H),
        ] {
            if need > room || need != stored {
                return Err(SizeError {
                    size,
                    model: need,
                    compiled: if need > room { room } else { stored },
                });
            }
        }
        Ok((k, s))
    }

    /// The current latent (the model's latent size), for engines that decode on the GPU.
    pub fn latent(&self) -> &[f32] {
        &self.z[..(self.latent as usize).min(K)]
    }

    /// Frames stepped since creation.
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// Advances one frame of the model's own frame time ([`Model::dt`]) with the handles'
    /// motion over it (one [`HandleMotion`] per handle, in the model's handle order). Bad input
    /// is refused and leaves the instance unchanged.
    pub fn step(&mut self, model: &ValidModel, bc: &[HandleMotion]) -> Result<Stepped, StepError> {
        self.step_dt(model, bc, model.model().dt)
    }

    /// Advances one frame of `dt` seconds (the host's frame time: 1/72, 1/90, 1/120 s on a
    /// headset) with the handles' motion over it. A model that takes the frame time as an input
    /// ([`Model::timed`]) steps by any positive `dt` (outside its trained range
    /// [`Model::dt_min`]..=[`Model::dt_max`] the motion is an extrapolation); a model of one
    /// frame time accepts only its own ([`FRAME_TIME_TOLERANCE`]). Bad input is refused and
    /// leaves the instance unchanged.
    pub fn step_dt(&mut self, model: &ValidModel, bc: &[HandleMotion], dt: f32) -> Result<Stepped, StepError> {
        self.step_with(model, bc, &[], dt)
    }

    /// [`Instance::step_dt`] with the run-time colliders of this frame, one per collider slot
    /// of the model ([`Model::colliders`]) in slot order; slots past the end of `colliders`
    /// are empty (read as absent, [`crate::collider::features`]). A model without slots takes
    /// none.
    pub fn step_with(
        &mut self,
        model: &ValidModel,
        bc: &[HandleMotion],
        colliders: &[ColliderState],
        dt: f32,
    ) -> Result<Stepped, StepError> {
        let (k, s) = self.check_sizes(model).map_err(StepError::Model)?;
        let m = model.model();
        if !(dt.is_finite() && dt > 0.0) {
            return Err(StepError::FrameTime);
        }
        if !m.timed() && (dt - m.dt).abs() > FRAME_TIME_TOLERANCE * m.dt {
            return Err(StepError::FixedFrameTime);
        }
        if bc.len() != m.handles.len() {
            return Err(StepError::HandleCount {
                expected: m.handles.len(),
                found: bc.len(),
            });
        }
        if let Some(handle) = bc.iter().position(|b| !b.is_finite()) {
            return Err(StepError::NotFinite { handle });
        }
        let slots = m.colliders();
        if colliders.len() > slots {
            return Err(StepError::ColliderCount {
                slots,
                found: colliders.len(),
            });
        }
        if let Some(collider) = colliders.iter().position(|c| !c.is_finite()) {
            return Err(StepError::ColliderNotFinite { collider });
        }
        let mut signal = [0.0; S];
        for (chunk, motion) in signal.chunks_exact_mut(SIGNAL_PER_HANDLE).zip(bc) {
            chunk.copy_from_slice(&motion.signal());
        }
        let time = [dt];
        // A rate-input model reads the last latent's change per frame of its `dt`.
        let mut rate = [0.0f32; K];
        if m.rate_input {
            let scale = m.dt / dt;
            for ((r, z), p) in rate.iter_mut().zip(&self.z[..k]).zip(&self.z_prev[..k]) {
                *r = (z - p) * scale;
            }
        }
        let mut touch = [0.0f32; MAX_COLLIDERS * FEATURES_PER_COLLIDER];
        if slots > 0 {
            let place = Placement::new(m, &signal[..s]);
            let origin = place.centroid();
            for (slot, out) in touch.chunks_exact_mut(FEATURES_PER_COLLIDER).take(slots).enumerate() {
                out.copy_from_slice(&features(&place.frame, &origin, m.diagonal, colliders.get(slot)));
            }
        }
        let parts: [&[f32]; 7] = [
            &self.z[..k],
            if m.rate_input { &rate[..k] } else { &self.z_prev[..k] },
            &signal[..s],
            &self.signal[..s],
            &self.signal_prev[..s],
            &touch[..slots * FEATURES_PER_COLLIDER],
            if m.timed() { &time } else { &[] },
        ];
        let h = last_hidden::<H>(&m.weights(), m.integrator, &parts);
        let mut increment = [0.0f32; K];
        OutputRows::new(m.weights(), m.integrator, &h).rows(0, &mut increment[..k]);
        if m.timed() {
            // A timed network predicts the increment of a frame of the model's `dt`.
            let scale = dt / m.dt;
            increment[..k].iter_mut().for_each(|v| *v *= scale);
        }
        let mut z = self.z;
        z.iter_mut().zip(&increment[..k]).for_each(|(z, dz)| *z += dz);
        let mut status = Stepped::Ok;
        if !z[..k].iter().all(|v| v.is_finite()) {
            z = self.z;
            status = Stepped::Held;
        }
        for ((zr, &lo), &hi) in z.iter_mut().zip(m.latent_min()).zip(m.latent_max()) {
            let margin = RANGE_MARGIN * (hi - lo);
            let clamped = zr.clamp(lo - margin, hi + margin);
            if clamped != *zr {
                *zr = clamped;
                if status == Stepped::Ok {
                    status = Stepped::Clamped;
                }
            }
        }
        self.z_prev = self.z;
        self.z = z;
        self.signal_prev = self.signal;
        self.signal = signal;
        self.frames = self.frames.wrapping_add(1);
        Ok(status)
    }

    /// Writes the world positions of every vertex (`dim` per vertex) into `out`.
    pub fn decode_into(&self, model: &ValidModel, out: &mut [f32]) -> Result<(), DecodeError> {
        let (k, s) = self.check_sizes(model).map_err(DecodeError::Model)?;
        let m = model.model();
        let d = m.dim();
        check_len(out, m.state_len())?;
        let h = decoder_features::<H>(m, &self.z[..k]);
        let place = Placement::new(m, &self.signal[..s]);
        if m.bends() {
            let free = m.free_vertices();
            walk_chains(m, &h, &place, |_, j, p| {
                if let Some(&v) = free.get(j) {
                    put(out, v as usize, d, &Vector3::from(*p));
                }
            });
        } else {
            // Runs of consecutive free vertices: their output rows are contiguous, decoded
            // straight into place and turned into world positions there.
            let (free, origin_of) = (m.free_vertices(), m.origin_of());
            let mut origins = Origins::new(&place, f32_decoder(m));
            let output = OutputRows::new(m.weights(), m.decoder, &h);
            let mut j = placed_free(&output, d, free, origin_of, out, &mut origins);
            while j < free.len() {
                let v = free[j];
                let run = consecutive_ascending(&free[j..]);
                let of = origin_of.get(j..j + run).unwrap_or(&[]);
                if let Some(block) = out.get_mut(v as usize * d..(v as usize + run) * d) {
                    decode_run(&output, d, j * d, block, of, &mut origins);
                }
                j += run;
            }
        }
        let handle_vertices = m.handle_vertices();
        place.each_target(|slot, p| {
            if let Some(&v) = handle_vertices.get(slot) {
                put(out, v as usize, d, &p);
            }
        });
        finite_or_rest(out, m.rest())
    }

    /// Writes the world positions of the drawn vertices only ([`Model::surface_vertices`],
    /// `dim` each) into `out`; the decoder's output layer runs only for their rows (for a
    /// bend-encoded model every strand is walked from its root, as in a full decode).
    pub fn decode_surface_into(&self, model: &ValidModel, out: &mut [f32]) -> Result<(), DecodeError> {
        let (k, s) = self.check_sizes(model).map_err(DecodeError::Model)?;
        let m = model.model();
        if m.surface_len() == m.state_len() {
            // Every vertex is drawn (the drawn list ascends and is unique): the full decode.
            return self.decode_into(model, out);
        }
        let d = m.dim();
        check_len(out, m.surface_len())?;
        let h = decoder_features::<H>(m, &self.z[..k]);
        let place = Placement::new(m, &self.signal[..s]);
        let (origins, sources) = (m.origin_of(), m.surface_source());
        if m.bends() {
            for (i, &source) in sources.iter().enumerate() {
                if source & HANDLE_SOURCE != 0 {
                    put(out, i, d, &place.target((source & !HANDLE_SOURCE) as usize));
                }
            }
            let (free, surface) = (m.free_vertices(), m.surface_vertices());
            let mut cursors = ListCursors::START;
            walk_chains(m, &h, &place, |lane, j, p| {
                if let Some(i) = free.get(j).and_then(|&v| cursors.find(surface, lane, v)) {
                    put(out, i, d, &Vector3::from(*p));
                }
            });
        } else {
            let mut origin_at = Origins::new(&place, f32_decoder(m));
            let output = OutputRows::new(m.weights(), m.decoder, &h);
            let mut i = 0;
            while i < sources.len() {
                let source = sources[i];
                if source & HANDLE_SOURCE != 0 {
                    put(out, i, d, &place.target((source & !HANDLE_SOURCE) as usize));
                    i += 1;
                    continue;
                }
                // A run of drawn vertices that are consecutive free vertices: their rows of the
                // output layer are contiguous and go through the kernel together.
                let j = source as usize;
                let run = consecutive(&sources[i..]);
                if let Some(block) = out.get_mut(i * d..(i + run) * d) {
                    let of = origins.get(j..j + run).unwrap_or(&[]);
                    decode_run(&output, d, j * d, block, of, &mut origin_at);
                }
                i += run;
            }
        }
        match finite_or_rest(out, &[]) {
            Ok(()) => Ok(()),
            Err(e) => {
                // Rest positions of the drawn vertices.
                for (o, &v) in out.chunks_exact_mut(d).zip(m.surface_vertices()) {
                    let rest = m.rest().get(v as usize * d..v as usize * d + d).unwrap_or(&[]);
                    o.iter_mut().zip(rest).for_each(|(o, r)| *o = *r);
                }
                Err(e)
            }
        }
    }
}

/// Whether the decoder's output layer is stored in `f32` (see [`Origins`]).
fn f32_decoder(m: &Model) -> bool {
    m.decoder.last().is_some_and(|l| l.format.is_f32())
}

/// The last hidden activation of the network `layers` for the input `parts`, with scratch on
/// the stack (`H` is at least the hidden width: checked by `check_sizes`).
fn last_hidden<const H: usize>(weights: &Weights, layers: &[Layer], parts: &[&[f32]]) -> [f32; H] {
    let (mut h, mut a, mut b) = ([0.0f32; H], [0.0f32; H], [0.0f32; H]);
    hidden(weights, layers, parts, &mut h, [&mut a, &mut b]);
    h
}

pub(crate) fn check_len(out: &[f32], expected: usize) -> Result<(), DecodeError> {
    if out.len() == expected {
        Ok(())
    } else {
        Err(DecodeError::BufferLength {
            expected,
            found: out.len(),
        })
    }
}

/// `Ok` when `out` is finite; otherwise overwrites it with `rest` (zeros past its end) and
/// reports it, so no NaN reaches the caller.
fn finite_or_rest(out: &mut [f32], rest: &[f32]) -> Result<(), DecodeError> {
    if all_finite(out) {
        return Ok(());
    }
    for (i, o) in out.iter_mut().enumerate() {
        *o = rest.get(i).copied().unwrap_or(0.0);
    }
    Err(DecodeError::NotFinite)
}

#[cfg(all(test, feature = "std"))]
#[path = "instance_tests.rs"]
mod tests;
