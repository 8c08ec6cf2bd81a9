//! One simulated object: the state of a latent rollout (last two latents and the last two
//! boundary-condition signals), stepped and decoded against a shared [`ValidModel`].

use core::fmt;

use nalgebra::Vector3;

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
}

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

    /// Advances one frame with the handles' motion over it (one [`HandleMotion`] per handle,
    /// in the model's handle order). Bad input is refused and leaves the instance unchanged.
    pub fn step(&mut self, model: &ValidModel, bc: &[HandleMotion]) -> Result<Stepped, StepError> {
        let (k, s) = self.check_sizes(model).map_err(StepError::Model)?;
        let m = model.model();
        if bc.len() != m.handles.len() {
            return Err(StepError::HandleCount {
                expected: m.handles.len(),
                found: bc.len(),
            });
        }
        if let Some(handle) = bc.iter().position(|b| !b.is_finite()) {
            return Err(StepError::NotFinite { handle });
        }
        let mut signal = [0.0; S];
        for (chunk, motion) in signal.chunks_exact_mut(SIGNAL_PER_HANDLE).zip(bc) {
            chunk.copy_from_slice(&motion.signal());
        }
        let parts: [&[f32]; 5] = [
            &self.z[..k],
            &self.z_prev[..k],
            &signal[..s],
            &self.signal[..s],
            &self.signal_prev[..s],
        ];
        let h = last_hidden::<H>(&m.weights(), m.integrator, &parts);
        let mut increment = [0.0f32; K];
        OutputRows::new(m.weights(), m.integrator, &h).rows(0, &mut increment[..k]);
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

fn check_len(out: &[f32], expected: usize) -> Result<(), DecodeError> {
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
mod tests {
    use std::vec::Vec;

    use super::*;
    use crate::frame::HandleMotion;
    use crate::model::{Handle, Problem, Span};

    /// Hidden width of the test networks.
    const HIDDEN: usize = 8;
    /// Rest length of every edge of the test strand.
    const L: f32 = 0.1;
    /// The instance type of the test model.
    type Body = Instance<1, 12, HIDDEN>;

    /// A one-strand model: vertices 0 and 1 prescribed (one handle), 2, 3 and 4 free, hanging
    /// along -y at spacing `L`, the chain tables as the trainer writes them and the loader
    /// completes them (`chain_order`); networks of zeros whose decoder outputs the bends `q`
    /// whatever the latent.
    struct Strand {
        params: Vec<f32>,
        floats: Vec<f32>,
        indices: Vec<u32>,
        decoder: [Layer; 2],
        integrator: [Layer; 2],
        handles: [Handle; 1],
        rotates: bool,
        spans: [Span; 13],
    }

    /// Appends `values` to `pool`; their span.
    fn push<T: Copy>(pool: &mut Vec<T>, values: &[T]) -> Span {
        let span = Span {
            start: pool.len() as u32,
            len: values.len() as u32,
        };
        pool.extend_from_slice(values);
        span
    }

    impl Strand {
        fn new(q: [f32; 6], rotates: bool) -> Self {
            let mut params = Vec::new();
            let mut layer = |rows: usize, cols: usize, bias: &[f32]| Layer {
                rows: rows as u32,
                cols: cols as u32,
                weights: push(&mut params, &std::vec![0.0; rows * cols]).start,
                bias: push(&mut params, bias).start,
                ..Layer::default()
            };
            let decoder = [layer(HIDDEN, 1, &[0.0; HIDDEN]), layer(6, HIDDEN, &q)];
            let integrator = [layer(HIDDEN, 2 + 3 * 12, &[0.0; HIDDEN]), layer(1, HIDDEN, &[0.0])];
            let (mut floats, mut indices) = (Vec::new(), Vec::new());
            let rest: Vec<f32> = (0..5).flat_map(|i| [0.0, -L * i as f32, 0.0]).collect();
            let spans = [
                push(&mut floats, &rest),
                push(&mut floats, &[0.0]),
                push(&mut floats, &[-1.0]),
                push(&mut floats, &[1.0]),
                push(&mut indices, &[0, 1]),
                push(&mut indices, &[2, 3, 4]),
                push(&mut indices, &[0, 0, 0]),
                push(&mut indices, &[0]),
                push(&mut indices, &[0, 1, 3, 0, 1, 2]),
                push(&mut floats, &[1.0, 0.0, 0.0, L, L, L]),
                push(&mut indices, &[0, 1, 2, 3, 4]),
                push(&mut indices, &[HANDLE_SOURCE, HANDLE_SOURCE | 1, 0, 1, 2]),
                push(&mut indices, &[0, 1, 2]),
            ];
            let handles = [Handle {
                vertices: spans[4],
                reference: push(&mut floats, &rest[..6]),
                pivot: [0.0, -0.05, 0.0],
            }];
            Strand {
                params,
                floats,
                indices,
                decoder,
                integrator,
                handles,
                rotates,
                spans,
            }
        }

        fn model(&self) -> Model<'_> {
            let [rest, initial_latent, latent_min, latent_max, handle_vertices, free_vertices, origin_of, root_slots, chains, chain_floats, surface_vertices, surface_source, chain_order] =
                self.spans;
            Model {
                dim: 3,
                num_vertices: 5,
                latent: 1,
                bc_len: 12,
                dt: 0.03,
                diagonal: 0.4,
                rotates: self.rotates,
                params: &self.params,
                halves: &[],
                bytes: &[],
                floats: &self.floats,
                indices: &self.indices,
                decoder: &self.decoder,
                decoder_basis: false,
                integrator: &self.integrator,
                handles: &self.handles,
                rest,
                handle_vertices,
                free_vertices,
                origin_of,
                root_slots,
                chains,
                chain_floats,
                chain_order,
                surface_vertices,
                surface_source,
                surface_triangles: Span::default(),
                initial_latent,
                latent_min,
                latent_max,
            }
        }

        /// The full decode after one step to the handle pose `motion`.
        fn decode(&self, motion: HandleMotion) -> [f32; 15] {
            let model = ValidModel::new(self.model()).unwrap();
            let mut body = Body::new(&model).unwrap();
            body.step(&model, &[motion]).unwrap();
            let mut x = [0.0; 15];
            body.decode_into(&model, &mut x).unwrap();
            x
        }
    }

    fn close(a: &[f32], b: &[f32]) -> bool {
        a.len() == b.len() && a.iter().zip(b).all(|(a, b)| (a - b).abs() <= 1e-6)
    }

    #[test]
    fn bends_decode_known_shapes_at_rest_length() {
        let rest = HandleMotion::REST;
        // No bend: the strand continues its parent edge.
        let straight = Strand::new([0.0; 6], false).decode(rest);
        let want: Vec<f32> = (0..5).flat_map(|i| [0.0, -L * i as f32, 0.0]).collect();
        assert!(close(&straight, &want), "{straight:?}");
        // A bend of tan(45 deg) about u = x (the rest normal) turns d = -y by 90 degrees into
        // -w = -z; the next edges continue straight.
        let bent = Strand::new([L, 0.0, 0.0, 0.0, 0.0, 0.0], false).decode(rest);
        let want = [
            0.0,
            0.0,
            0.0,
            0.0,
            -L,
            0.0,
            0.0,
            -L,
            -L,
            0.0,
            -L,
            -2.0 * L,
            0.0,
            -L,
            -3.0 * L,
        ];
        assert!(close(&bent, &want), "{bent:?}");
        // Any bends keep every edge at its rest length.
        let random = Strand::new([0.3, -0.7, 2.0, 0.05, -1.5, 0.9], false).decode(rest);
        for e in 1..4 {
            let edge: f32 = (0..3)
                .map(|c| (random[3 * e + 3 + c] - random[3 * e + c]).powi(2))
                .sum();
            assert!((edge.sqrt() - L).abs() < 1e-6, "edge {e}: {}", edge.sqrt());
        }
    }

    #[test]
    fn bends_turn_with_a_rotating_handle() {
        let q = [0.03, -0.05, 0.08, 0.02, -0.04, 0.06];
        let strand = Strand::new(q, true);
        let at_rest = strand.decode(HandleMotion::REST);
        let (t, r) = ([0.2f32, -0.1, 0.3], [0.3f32, 0.9, -0.4]);
        let moved = strand.decode(HandleMotion {
            translation: t,
            rotation: r,
            ..HandleMotion::REST
        });
        // Rodrigues in f64: the pose applied to the rest decode.
        let angle = r.iter().map(|&v| (v as f64).powi(2)).sum::<f64>().sqrt();
        let k = r.map(|v| v as f64 / angle);
        let pivot = [0.0, -0.05, 0.0];
        for v in 0..5 {
            let p: [f64; 3] = core::array::from_fn(|c| at_rest[3 * v + c] as f64 - pivot[c]);
            let kxp = [
                k[1] * p[2] - k[2] * p[1],
                k[2] * p[0] - k[0] * p[2],
                k[0] * p[1] - k[1] * p[0],
            ];
            let kp = k[0] * p[0] + k[1] * p[1] + k[2] * p[2];
            for c in 0..3 {
                let want = pivot[c]
                    + t[c] as f64
                    + p[c] * angle.cos()
                    + kxp[c] * angle.sin()
                    + k[c] * kp * (1.0 - angle.cos());
                let got = moved[3 * v + c] as f64;
                assert!((got - want).abs() < 1e-5, "vertex {v}: {got} vs {want}");
            }
        }
    }

    #[test]
    fn bends_surface_decode_is_the_full_decode() {
        let strand = Strand::new([0.3, -0.7, 2.0, 0.05, -1.5, 0.9], true);
        let model = ValidModel::new(strand.model()).unwrap();
        let mut body = Body::new(&model).unwrap();
        let motion = HandleMotion {
            translation: [0.1, 0.2, 0.3],
            rotation: [0.5, 0.0, 0.2],
            ..HandleMotion::REST
        };
        body.step(&model, &[motion]).unwrap();
        let (mut full, mut surface) = ([0.0; 15], [0.0; 15]);
        body.decode_into(&model, &mut full).unwrap();
        body.decode_surface_into(&model, &mut surface).unwrap();
        assert_eq!(full, surface);
        // Only some vertices drawn: the same bits for those.
        let mut drawn = strand;
        let sources = push(&mut drawn.indices, &[HANDLE_SOURCE, 2]);
        drawn.spans[10] = push(&mut drawn.indices, &[0, 4]);
        drawn.spans[11] = sources;
        let model = ValidModel::new(drawn.model()).unwrap();
        let mut some = [0.0; 6];
        body.decode_surface_into(&model, &mut some).unwrap();
        assert_eq!(some[..3], full[..3]);
        assert_eq!(some[3..], full[12..]);
    }

    #[test]
    fn malformed_chains_are_refused_naming_the_field() {
        let good = Strand::new([0.0; 6], false);
        assert!(good.model().validate().is_ok());
        let refused = |edit: &dyn Fn(&mut Strand)| {
            let mut s = Strand::new([0.0; 6], false);
            edit(&mut s);
            let e = s.model().validate().unwrap_err();
            (e.field, e.problem)
        };
        let (chains, chain_floats) = (good.spans[8].start as usize, good.spans[9].start as usize);
        type Edit<'e> = &'e dyn Fn(&mut Strand);
        let order = good.spans[12].start as usize;
        let cases: [(Edit, &str, Problem); 12] = [
            (&|s| s.indices[chains] = 2, "chains.parent", Problem::OutOfRange),
            (&|s| s.indices[chains] = 1, "chains.parent", Problem::Inconsistent),
            (&|s| s.indices[chains + 2] = 9, "chains", Problem::Inconsistent),
            (&|s| s.indices[chains + 4] = 3, "chains.slots", Problem::OutOfRange),
            (&|s| s.indices[chains + 4] = 0, "chains.slots", Problem::Inconsistent),
            (
                &|s| s.indices.swap(order, order + 1),
                "chain_order",
                Problem::Inconsistent,
            ),
            (
                &|s| s.spans[12].len -= 1,
                "chain_order",
                Problem::Length { expected: 3, found: 2 },
            ),
            (&|s| s.floats[chain_floats] = 1.1, "chains.rest_normal", Problem::Domain),
            (
                &|s| s.floats[chain_floats + 1] = f32::NAN,
                "chains.rest_normal",
                Problem::NotFinite,
            ),
            (&|s| s.floats[chain_floats + 4] = 0.0, "chains.lengths", Problem::Domain),
            (
                &|s| s.spans[9].len -= 1,
                "chains.lengths",
                Problem::Length { expected: 6, found: 5 },
            ),
            (
                &|s| s.spans[8].start = s.indices.len() as u32,
                "chains",
                Problem::OutOfRange,
            ),
        ];
        for (edit, field, problem) in cases {
            assert_eq!(refused(edit), (field, problem));
        }
        // A strand that covers only two of the three free vertices.
        let short = refused(&|s| {
            s.indices[chains + 2] = 2;
            s.spans[8].len -= 1;
            s.spans[9].len -= 1;
        });
        assert_eq!(short, ("chains.slots", Problem::Length { expected: 3, found: 2 }));
    }
}
