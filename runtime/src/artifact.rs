//! Loading a model artifact (`SCENE.mochi`) from bytes into fixed-capacity storage, as an
//! alternative to generated constants (docs/design.md, decision 4).
//!
//! An artifact is a sequence of sections, each in the envelope of [`crate::envelope`]. The
//! first (magic [`MAGIC`], version [`FORMAT_VERSION`]) holds the deployable payload: the
//! postcard encoding of `payload::Payload` (feature `std`), exactly the fields read here, in
//! the same order. Further sections (the trainer's training-only data) are checked for length
//! and CRC-32 and otherwise skipped. Postcard writes a struct as its fields in order, so the
//! payload is read field by field with serde from one deserializer, the arrays streaming into
//! pools. Nothing is allocated; a pool that is too small is an error, not a panic.

use core::fmt;
use core::marker::PhantomData;

use serde::de::{DeserializeSeed, SeqAccess, Visitor};
use serde::{Deserialize, Deserializer};

use crate::aligned::LINE;
use crate::envelope::{self, EnvelopeError};
use crate::instance::ValidModel;
use crate::model::{
    column_stride, stores_columns, wide_stores_columns, Handle, Layer, Model, ModelError, Problem, Span, WeightFormat,
    HANDLE_SOURCE, MAX_HANDLES, MAX_LAYERS,
};
pub use crate::pool::Pool;
use crate::vertex_lists::{fill_chain_order, UNNAMED};

/// First bytes of every artifact (the magic of its first section).
pub const MAGIC: &[u8; 8] = b"MOCHIMDL";
/// Artifact format version this runtime reads and the trainer writes.
///
/// Version 2 added the bend-encoded rod strands (`encoding.chains`); version 3 moved what only
/// the trainer reads (scene, encoder, PCA, drawing lists, training summary) out of the first
/// section into a section of its own; version 4 moved the triangles to draw from that section
/// into the first (`surface_triangles`, over the drawn vertices); version 5 added decoders that
/// end in a linear basis (`decoder_basis`); version 6 added the trained range of frame times
/// (`dt_range`, for an integrator that takes the frame time as an input) and the run-time
/// collider slots (`collider_shapes`); version 7 added the render mesh embedded in the
/// simulation mesh (`render`); version 8 let a timed integrator read the previous latent's
/// change per frame of `dt` in place of the latent before it (`rate_input`). The runtime also
/// reads versions [`OLDEST_READ_VERSION`] (as a model of one frame time), 6 (as a model
/// without a render mesh) and 7 (a timed integrator reading `z_{t-2}`); other versions are
/// refused with [`EnvelopeError::Version`].
pub const FORMAT_VERSION: u32 = 8;

/// Oldest artifact format version the runtime reads: 5, whose payload is this one without its
/// last two fields (`dt_range`, `collider_shapes`).
pub const OLDEST_READ_VERSION: u32 = 5;

/// Why an artifact was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LoadError {
    /// The envelope of a section was refused: not an artifact, another format version,
    /// truncated, padded or corrupted.
    Envelope(EnvelopeError),
    /// This field could not be read.
    Malformed {
        /// Field being read.
        field: &'static str,
    },
    /// The storage is too small for this field.
    Capacity {
        /// Field being stored.
        field: &'static str,
    },
    /// The payload has bytes after its last field.
    TrailingBytes,
    /// The model read is inconsistent.
    Invalid(ModelError),
}

impl From<EnvelopeError> for LoadError {
    fn from(e: EnvelopeError) -> Self {
        LoadError::Envelope(e)
    }
}

impl fmt::Display for LoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LoadError::Envelope(EnvelopeError::BadMagic) => {
                write!(f, "not a mochi model artifact (bad magic bytes)")
            }
            LoadError::Envelope(e) => write!(f, "artifact is {e}"),
            LoadError::Malformed { field } => write!(f, "artifact field `{field}` is unreadable"),
            LoadError::Capacity { field } => write!(f, "storage too small for artifact field `{field}`"),
            LoadError::TrailingBytes => write!(f, "artifact has bytes after its last field"),
            LoadError::Invalid(e) => write!(f, "artifact is inconsistent: {e}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for LoadError {}

/// Floats of the weights pool [`Storage::load`] fills for the networks of `m` on a CPU with a
/// wide `f32` kernel, which stores the most layers by columns ([`wide_stores_columns`]), every
/// layer on a cache line: the most any loader needs for the artifact `m` came from (storing by
/// columns only pads), computed from the layer shapes alone (the capacity code generation
/// writes, the same whichever machine generates it).
pub fn wide_params_len(m: &Model) -> usize {
    let mut len = 0usize;
    for layer in m.decoder.iter().chain(m.integrator) {
        let (rows, cols) = (layer.rows as usize, layer.cols as usize);
        len = len.next_multiple_of(LINE);
        len += match wide_stores_columns(rows, cols) {
            true => column_stride(rows) * cols,
            false => rows * cols,
        };
        len += rows;
    }
    len
}

/// The deployable payload of an artifact (its first section), after checking every section's
/// envelope.
pub fn payload(bytes: &[u8]) -> Result<&[u8], LoadError> {
    Ok(versioned_payload(bytes)?.1)
}

/// [`payload`] with the artifact's format version.
fn versioned_payload(bytes: &[u8]) -> Result<(u32, &[u8]), LoadError> {
    let (version, payload, rest) = envelope::split_versions(bytes, MAGIC, OLDEST_READ_VERSION..=FORMAT_VERSION)?;
    envelope::check_sections(rest)?;
    Ok((version, payload))
}

/// A model loaded from artifact bytes into pools `P` (weights), `F` (other reals), `I`
/// (indices), `L` (layers) and `G` (handles). Use [`LoadedModel`] on targets and
/// `OwnedModel` (feature `std`) on the desktop.
#[derive(Clone, Debug)]
pub struct Storage<P, F, I, L, G> {
    params: P,
    floats: F,
    indices: I,
    decoder: L,
    integrator: L,
    handles: G,
    /// Sizes, scalars and spans read (its pools stay empty: they are the fields above).
    header: Model<'static>,
    loaded: bool,
}

impl<P: Default, F: Default, I: Default, L: Default, G: Default> Default for Storage<P, F, I, L, G> {
    fn default() -> Self {
        Storage {
            params: P::default(),
            floats: F::default(),
            indices: I::default(),
            decoder: L::default(),
            integrator: L::default(),
            handles: G::default(),
            header: Model::EMPTY,
            loaded: false,
        }
    }
}

/// Fixed-capacity storage: `P` weights and biases, `F` other reals, `I` indices.
pub type LoadedModel<const P: usize, const F: usize, const I: usize> = Storage<
    heapless::Vec<f32, P>,
    heapless::Vec<f32, F>,
    heapless::Vec<u32, I>,
    heapless::Vec<Layer, MAX_LAYERS>,
    heapless::Vec<Handle, MAX_HANDLES>,
>;

/// Heap-backed storage for desktop tools (feature `std`).
#[cfg(feature = "std")]
pub type OwnedModel = Storage<
    crate::aligned::AlignedFloats,
    std::vec::Vec<f32>,
    std::vec::Vec<u32>,
    std::vec::Vec<Layer>,
    std::vec::Vec<Handle>,
>;

impl<const P: usize, const F: usize, const I: usize> LoadedModel<P, F, I> {
    /// Empty storage (usable in a `static`).
    pub const fn new() -> Self {
        Storage {
            params: heapless::Vec::new(),
            floats: heapless::Vec::new(),
            indices: heapless::Vec::new(),
            decoder: heapless::Vec::new(),
            integrator: heapless::Vec::new(),
            handles: heapless::Vec::new(),
            header: Model::EMPTY,
            loaded: false,
        }
    }
}

impl<P, F, I, L, G> Storage<P, F, I, L, G>
where
    P: Pool<f32>,
    F: Pool<f32>,
    I: Pool<u32>,
    L: Pool<Layer>,
    G: Pool<Handle>,
{
    /// The model as a description over the pools (valid only after a successful load).
    fn describe(&self) -> Model<'_> {
        Model {
            params: self.params.as_slice(),
            floats: self.floats.as_slice(),
            indices: self.indices.as_slice(),
            decoder: self.decoder.as_slice(),
            integrator: self.integrator.as_slice(),
            handles: self.handles.as_slice(),
            ..self.header
        }
    }

    /// The loaded model, or `None` before a successful [`Storage::load`].
    /// The pools do not change between a successful load and the next one, so the model is
    /// not validated again here.
    pub fn model(&self) -> Option<ValidModel<'_>> {
        self.loaded.then(|| ValidModel::validated(self.describe()))
    }

    /// Parses, stores and validates the artifact in `bytes`, replacing what was stored.
    pub fn load(&mut self, bytes: &[u8]) -> Result<ValidModel<'_>, LoadError> {
        self.loaded = false;
        for pool in [&mut self.decoder, &mut self.integrator] {
            pool.clear();
        }
        self.params.clear();
        self.floats.clear();
        self.indices.clear();
        self.handles.clear();
        self.header = Model::EMPTY;
        let (version, payload) = versioned_payload(bytes)?;
        self.read(payload, version)?;
        self.describe().validate().map_err(LoadError::Invalid)?;
        self.loaded = true;
        Ok(ValidModel::validated(self.describe()))
    }

    /// Reads every field of the payload in the order of `payload::Payload` (a format-5 payload
    /// ends before `dt_range`, a format-6 payload before `render`).
    fn read(&mut self, payload: &[u8], version: u32) -> Result<(), LoadError> {
        let mut r = Reader {
            de: postcard::Deserializer::from_bytes(payload),
            size: payload.len(),
        };
        let h = &mut self.header;
        h.dt = r.value::<f64>("dt")? as f32;
        h.dim = r.value("dim")?;
        h.num_vertices = r.value("num_vertices")?;
        h.rest = r.seq("rest", &mut self.floats)?;
        h.diagonal = r.value::<f64>("diagonal")? as f32;
        h.rotates = r.value("rotates")?;
        h.handle_vertices = r.seq("handle_vertices", &mut self.indices)?;
        h.free_vertices = r.seq("free_vertices", &mut self.indices)?;
        h.origin_of = r.seq("origin_of", &mut self.indices)?;
        h.root_slots = r.seq("root_slots", &mut self.indices)?;
        (h.chains, h.chain_floats) = r.chains(&mut self.indices, &mut self.floats)?;
        let handles = r.len("handles")?;
        for _ in 0..handles {
            let vertices = r.seq("handles.vertices", &mut self.indices)?;
            let reference = r.seq("handles.reference", &mut self.floats)?;
            let pivot = r.value::<[f32; 3]>("handles.pivot")?;
            let handle = Handle {
                vertices,
                reference,
                pivot,
            };
            if !self.handles.push(handle) {
                return Err(LoadError::Capacity { field: "handles" });
            }
        }
        h.bc_len = r.value("bc_len")?;
        h.surface_vertices = r.seq("surface_vertices", &mut self.indices)?;
        h.latent = r.value("latent")?;
        h.initial_latent = r.seq("initial_latent", &mut self.floats)?;
        h.latent_min = r.seq("latent_min", &mut self.floats)?;
        h.latent_max = r.seq("latent_max", &mut self.floats)?;
        r.network("decoder", &mut self.params, &mut self.decoder, true)?;
        r.network("integrator", &mut self.params, &mut self.integrator, false)?;
        self.header.surface_triangles = r.seq("surface_triangles", &mut self.indices)?;
        self.header.decoder_basis = r.value("decoder_basis")?;
        if version >= 6 {
            let [lo, hi] = r.value::<[f64; 2]>("dt_range")?;
            (self.header.dt_min, self.header.dt_max) = (lo as f32, hi as f32);
            self.header.collider_shapes = r.seq("collider_shapes", &mut self.floats)?;
        }
        if version >= 7 {
            self.header.render_anchors = r.seq("render.anchors", &mut self.indices)?;
            self.header.render_weights = r.seq("render.weights", &mut self.floats)?;
            self.header.render_triangles = r.seq("render.triangles", &mut self.indices)?;
            self.header.render_uvs = r.seq("render.uvs", &mut self.floats)?;
        }
        if version >= 8 {
            self.header.rate_input = r.value("rate_input")?;
        }
        match r.de.finalize() {
            Ok([]) => {}
            _ => return Err(LoadError::TrailingBytes),
        }
        self.header.surface_source = self.surface_source()?;
        self.header.chain_order = self.chain_order()?;
        Ok(())
    }

    /// Per drawn vertex, its free-vertex index or its handle slot (see [`Model`]): a binary
    /// search in the free vertices, then in each handle's (ascending) vertices.
    fn surface_source(&mut self) -> Result<Span, LoadError> {
        if self.handles.as_slice().len() > MAX_HANDLES {
            return Err(invalid("handles", Problem::Unsupported));
        }
        let start = self.indices.as_slice().len();
        for i in 0..self.header.surface_vertices.len as usize {
            let m = self.describe();
            let v = m.surface_vertices().get(i).copied().unwrap_or(u32::MAX);
            let source = match m.free_vertices().binary_search(&v) {
                Ok(j) => j as u32,
                Err(_) => match m.handle_slot(v) {
                    Some(slot) => HANDLE_SOURCE | slot,
                    // A handle out of order hides its vertices from the search.
                    None if !m.handle_lists_ascend() => {
                        return Err(invalid("handle_vertices", Problem::Inconsistent));
                    }
                    None => {
                        return Err(LoadError::Malformed {
                            field: "surface_vertices",
                        })
                    }
                },
            };
            if !self.indices.push(source) {
                return Err(LoadError::Capacity {
                    field: "surface_vertices",
                });
            }
        }
        Ok(span(start, self.indices.as_slice().len()))
    }

    /// Per free vertex of a bend-encoded model, its position among the strands' slots
    /// ([`Model::chain_order`]); empty without strands.
    fn chain_order(&mut self) -> Result<Span, LoadError> {
        let h = self.header;
        let start = self.indices.as_slice().len();
        if h.chains.len == 0 {
            return Ok(span(start, start));
        }
        for _ in 0..h.free_vertices.len {
            if !self.indices.push(UNNAMED) {
                return Err(LoadError::Capacity { field: "chain_order" });
            }
        }
        let (before, order) = self.indices.as_mut_slice().split_at_mut(start);
        fill_chain_order(h.chains.of(before).unwrap_or(&[]), order);
        Ok(span(start, self.indices.as_slice().len()))
    }
}

fn invalid(field: &'static str, problem: Problem) -> LoadError {
    LoadError::Invalid(ModelError { field, problem })
}

fn span(start: usize, end: usize) -> Span {
    Span {
        start: start as u32,
        len: (end - start) as u32,
    }
}

/// Field-by-field reader of the payload.
struct Reader<'de> {
    de: postcard::Deserializer<'de, postcard::de_flavors::Slice<'de>>,
    /// Bytes of the whole payload (no sequence can hold more elements).
    size: usize,
}

impl<'de> Reader<'de> {
    fn value<T: Deserialize<'de>>(&mut self, field: &'static str) -> Result<T, LoadError> {
        T::deserialize(&mut self.de).map_err(|_| LoadError::Malformed { field })
    }

    /// A sequence length prefix.
    fn len(&mut self, field: &'static str) -> Result<usize, LoadError> {
        let n: u64 = postcard_varint(&mut self.de).ok_or(LoadError::Malformed { field })?;
        usize::try_from(n).map_err(|_| LoadError::Malformed { field })
    }

    /// A sequence appended to `pool`; its span.
    fn seq<T, Q>(&mut self, field: &'static str, pool: &mut Q) -> Result<Span, LoadError>
    where
        T: Deserialize<'de>,
        Q: Pool<T>,
    {
        let start = pool.as_slice().len();
        let mut full = false;
        let seed = Append {
            pool,
            full: &mut full,
            _t: PhantomData,
        };
        match seed.deserialize(&mut self.de) {
            Ok(()) => Ok(span(start, pool.as_slice().len())),
            Err(_) if full => Err(LoadError::Capacity { field }),
            Err(_) => Err(LoadError::Malformed { field }),
        }
    }

    /// The bend-encoded strands (`chains`), appended to `indices` and `floats` as
    /// the tables of [`Model::chains`] and [`Model::chain_floats`]; their spans.
    fn chains<I: Pool<u32>, F: Pool<f32>>(
        &mut self,
        indices: &mut I,
        floats: &mut F,
    ) -> Result<(Span, Span), LoadError> {
        const FIELD: &str = "chains";
        let start = (indices.as_slice().len(), floats.as_slice().len());
        let full = LoadError::Capacity { field: FIELD };
        for _ in 0..self.len(FIELD)? {
            let parent = self.value::<[u32; 2]>("chains.parent")?;
            let normal = self.value::<[f32; 3]>("chains.rest_normal")?;
            let n = self.len("chains.slots")?;
            let count = u32::try_from(n).map_err(|_| LoadError::Malformed { field: "chains.slots" })?;
            if !(indices.push(parent[0]) && indices.push(parent[1]) && indices.push(count)) {
                return Err(full);
            }
            for _ in 0..n {
                if !indices.push(self.value("chains.slots")?) {
                    return Err(full);
                }
            }
            if !normal.iter().all(|&v| floats.push(v)) {
                return Err(full);
            }
            let lengths = self.len("chains.lengths")?;
            if lengths != n {
                return Err(LoadError::Invalid(ModelError {
                    field: "chains.lengths",
                    problem: Problem::Length {
                        expected: n,
                        found: lengths,
                    },
                }));
            }
            for _ in 0..n {
                if !floats.push(self.value("chains.lengths")?) {
                    return Err(full);
                }
            }
        }
        Ok((
            span(start.0, indices.as_slice().len()),
            span(start.1, floats.as_slice().len()),
        ))
    }

    /// A network (list of dense layers): weights and biases appended to `params`, layers to
    /// `list`. For a `decoder`, an output layer that [`stores_columns`] is stored column by
    /// column, and where the CPU has a wide kernel every layer that [`wide_stores_columns`].
    fn network<P: Pool<f32>, L: Pool<Layer>>(
        &mut self,
        field: &'static str,
        params: &mut P,
        list: &mut L,
        decoder: bool,
    ) -> Result<(), LoadError> {
        let layers = self.len(field)?;
        if layers > MAX_LAYERS {
            return Err(LoadError::Capacity { field });
        }
        // Where the CPU has a wide kernel, most layers go by columns (`wide_stores_columns`).
        let wide = crate::network::fast::width() != crate::network::Width::Canonical;
        for i in 0..layers {
            let rows: u64 = self.value(field)?;
            let cols: u64 = self.value(field)?;
            let columns = (decoder && i + 1 == layers && stores_columns(cols as usize))
                || (wide && wide_stores_columns(rows as usize, cols as usize));
            // Every layer's weights start on a cache line of the pool (`aligned`).
            while !params.as_slice().len().is_multiple_of(LINE) {
                if !params.push(0.0) {
                    return Err(LoadError::Capacity { field });
                }
            }
            let w = match columns {
                true => self.columns(field, params, rows, cols)?,
                false => self.seq::<f32, _>(field, params)?,
            };
            let b = self.seq::<f32, _>(field, params)?;
            if rows.checked_mul(cols) != Some(w.len as u64) || rows != b.len as u64 {
                return Err(LoadError::Malformed { field });
            }
            let layer = Layer {
                rows: rows as u32,
                cols: cols as u32,
                format: if columns {
                    WeightFormat::F32Columns
                } else {
                    WeightFormat::F32
                },
                weights: w.start,
                bias: b.start,
                ..Layer::default()
            };
            if !list.push(layer) {
                return Err(LoadError::Capacity { field });
            }
        }
        Ok(())
    }
}

impl Reader<'_> {
    /// A `rows x cols` weight matrix written row by row, appended to `params` column by column
    /// ([`WeightFormat::F32Columns`]): each value goes straight to its place, so the layer
    /// needs no more room than row by row.
    fn columns<P: Pool<f32>>(
        &mut self,
        field: &'static str,
        params: &mut P,
        rows: u64,
        cols: u64,
    ) -> Result<Span, LoadError> {
        let n = self.len(field)?;
        // Room is made before the values are read: a count the payload cannot hold is refused
        // first, so that a crafted count never reserves more than the payload's size.
        if rows.checked_mul(cols) != Some(n as u64) || n > self.size / 4 {
            return Err(LoadError::Malformed { field });
        }
        let (rows, cols) = (rows as usize, cols as usize);
        let stride = column_stride(rows);
        let start = params.as_slice().len();
        for _ in 0..stride * cols {
            if !params.push(0.0) {
                return Err(LoadError::Capacity { field });
            }
        }
        for i in 0..n {
            let v: f32 = self.value(field)?;
            if let Some(w) = params.as_mut_slice().get_mut(start + (i % cols) * stride + i / cols) {
                *w = v;
            }
        }
        // The span of the values read (the network check compares its length with the shape).
        Ok(span(start, start + n))
    }
}

/// Reads a postcard varint (a sequence length) through serde: postcard encodes `u64` and
/// sequence lengths the same way.
fn postcard_varint<'de>(de: &mut postcard::Deserializer<'de, postcard::de_flavors::Slice<'de>>) -> Option<u64> {
    u64::deserialize(de).ok()
}

/// Seed that appends a sequence's elements to a pool.
struct Append<'p, T, Q> {
    pool: &'p mut Q,
    full: &'p mut bool,
    _t: PhantomData<T>,
}

impl<'de, T: Deserialize<'de>, Q: Pool<T>> DeserializeSeed<'de> for Append<'_, T, Q> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<(), D::Error> {
        deserializer.deserialize_seq(self)
    }
}

impl<'de, T: Deserialize<'de>, Q: Pool<T>> Visitor<'de> for Append<'_, T, Q> {
    type Value = ();
    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a sequence")
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        while let Some(v) = seq.next_element::<T>()? {
            if !self.pool.push(v) {
                *self.full = true;
                return Err(serde::de::Error::custom("pool full"));
            }
        }
        Ok(())
    }
}
