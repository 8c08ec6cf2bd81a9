//! The frozen model the runtime consumes: shapes, weights and the boundary-condition encoding,
//! as slices into a few flat pools so that generated `static` arrays and storage loaded from
//! bytes describe a model the same way.
//!
//! A network is a list of dense layers `[input, inner_0, outer_0, ..., output]` with
//! `h = input(x); h += outer_j(swish(inner_j(h))); y = output(swish(h))`. The integrator maps
//! `[z_{t-1}, z_{t-2}, p_t, p_{t-1}, p_{t-2}]` (then the frame time, for a model trained over a
//! range of frame times: [`Model::timed`]) to the increment `z_t - z_{t-1}`; the decoder
//! maps a latent to the encoded state of the free vertices: `dim` numbers each (positions in
//! the encoding frame), or two numbers each for rod strands encoded by their bends
//! ([`Model::chains`], see [`Chain`]).
//!
//! A decoder may instead end in a linear basis ([`Model::decoder_basis`]): its last layer maps
//! the features `f = [z; 0] + g(z)` to the encoded state, `g` the residual MLP of the layers
//! before it (whose output has as many values as the basis has columns, at least the latent
//! size), or `f = z` when the basis is the only layer (a linear decoder, e.g. a PCA basis).

use core::fmt;

/// Numbers of a collider slot's shape row in a model (`[code, a, b, c]`, [`Model::collider_shapes`]).
pub const SHAPE_ROW: usize = 4;
/// Most collider slots a model may have.
pub const MAX_COLLIDERS: usize = 8;
/// Inputs the integrator reads per collider slot (`collider::features`: centre, the first two
/// columns of the rotation, and velocity in the encoding frame).
pub const FEATURES_PER_COLLIDER: usize = 12;

/// Largest number of handles a model may have.
pub const MAX_HANDLES: usize = 16;
/// Largest number of layers in one network (input, output and 2 per residual block).
pub const MAX_LAYERS: usize = 34;
/// Numbers per handle in the boundary-condition signal (see [`crate::HandleMotion`]).
pub const SIGNAL_PER_HANDLE: usize = 12;
/// Flag in [`Model::surface_source`] marking a prescribed vertex (the rest is its handle slot).
pub const HANDLE_SOURCE: u32 = 1 << 31;

/// A range `start..start + len` of one of a model's pools.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Span {
    /// First element.
    pub start: u32,
    /// Number of elements.
    pub len: u32,
}

impl Span {
    /// The span's elements of `pool`, or `None` when it does not fit.
    pub fn of<T>(self, pool: &[T]) -> Option<&[T]> {
        pool.get(self.start as usize..self.start as usize + self.len as usize)
    }
}

/// How a layer's weight matrix is stored (chosen at code generation; biases and scales are
/// always `f32`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum WeightFormat {
    /// `f32`, in [`Model::params`].
    #[default]
    F32,
    /// IEEE half precision bit patterns, in [`Model::halves`].
    F16,
    /// Signed bytes times a per-row (output channel) scale: `W[r][c] = scale[r] * q[r][c]`,
    /// `q` in [`Model::bytes`], the scales in [`Model::params`].
    Int8,
    /// `f32`, in [`Model::params`], stored **column by column** (`W[r][c]` at
    /// `weights + c * column_stride(rows) + r`, the padding zero), computed like
    /// [`WeightFormat::F32`]: what every loader makes of a decoder's narrow output layer
    /// ([`stores_columns`]), and a loader with a wide kernel of most layers
    /// ([`wide_stores_columns`]). The wide kernel then adds one column into sixteen rows per
    /// instruction instead of reducing each row; the canonical sum reads it in its own
    /// order, so its bits do not depend on the layout.
    F32Columns,
}

/// Floats from one column of a [`WeightFormat::F32Columns`] layer of `rows` rows to the next:
/// `rows` rounded up to a multiple of 16, so that every column has the same alignment and a
/// block of sixteen rows is one aligned load in each.
pub const fn column_stride(rows: usize) -> usize {
    rows.div_ceil(16) * 16
}

impl WeightFormat {
    /// Whether the weights are `f32` (either layout).
    pub fn is_f32(self) -> bool {
        matches!(self, WeightFormat::F32 | WeightFormat::F32Columns)
    }
}

/// Widest decoder output layer every loader stores column by column.
pub const COLUMNS_MAX: usize = 64;

/// Whether every loader stores a decoder's output layer of `cols` columns column by column
/// ([`WeightFormat::F32Columns`]): for at most [`COLUMNS_MAX`] columns (a basis decoder's
/// modes; wider rows cost little to reduce). The same on every target, and code generation
/// keeps exactly these layers by columns, so a generated module holds the same numbers
/// whichever machine generated it.
pub const fn stores_columns(cols: usize) -> bool {
    cols <= COLUMNS_MAX
}

/// The rows of a wider layer that a loader with a wide `f32` kernel stores column by column
/// ([`wide_stores_columns`]): the kernel keeps the sums of 128 rows in registers while it
/// streams the columns (eight 16-lane vectors, twice for 256). With fewer rows its chains
/// over the columns would be too few to hide their latency (a 6-row output layer of 128
/// columns would be one chain of 128 fused multiply-adds), so such layers stay row by row.
pub const COLUMN_ROWS: core::ops::RangeInclusive<usize> = 128..=256;

/// Whether a loader on a CPU with a wide `f32` kernel ([`crate::network::fast`]) stores an
/// `f32` layer of `rows x cols` column by column, whichever network it is in: at most
/// [`COLUMNS_MAX`] columns, or [`COLUMN_ROWS`] rows (the hidden layers of an integrator or a
/// decoder's residual MLP). One pass over the weights in memory order then adds each column
/// into every row's sum and nothing is reduced across lanes. Targets without the wide kernel
/// (and generated code) keep such layers row by row, where the canonical sum takes fewer
/// instructions (the Cortex-M4: rods 667 k against 815 k per frame).
pub const fn wide_stores_columns(rows: usize, cols: usize) -> bool {
    cols <= COLUMNS_MAX || (rows >= *COLUMN_ROWS.start() && rows <= *COLUMN_ROWS.end())
}

/// One dense layer `y = W x + b`: `W` at `weights..weights + rows * cols` of the pool its
/// [`WeightFormat`] names (row-major, except [`WeightFormat::F32Columns`]), `b` at
/// `params[bias..bias + rows]`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Layer {
    /// Outputs.
    pub rows: u32,
    /// Inputs.
    pub cols: u32,
    /// How `W` is stored.
    pub format: WeightFormat,
    /// Offset of `W` in the pool of its format.
    pub weights: u32,
    /// Offset of `b` in [`Model::params`].
    pub bias: u32,
    /// Offset of the per-row scales in [`Model::params`] ([`WeightFormat::Int8`] only).
    pub scales: u32,
}

/// The pools the layers of a model point into.
#[derive(Clone, Copy, Debug)]
pub struct Weights<'a> {
    /// `f32` weights, biases and scales.
    pub params: &'a [f32],
    /// Half-precision weights.
    pub halves: &'a [u16],
    /// Int8 weights.
    pub bytes: &'a [i8],
}

/// A handle: prescribed vertices moved rigidly about a pivot.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Handle {
    /// Its vertices, ascending, in [`Model::indices`].
    pub vertices: Span,
    /// Their identity-pose positions (3 per vertex), in [`Model::floats`].
    pub reference: Span,
    /// Rotation pivot at the identity pose.
    pub pivot: [f32; 3],
}

/// One rod strand of a bend-encoded model (read from [`Model::chains`] and
/// [`Model::chain_floats`] by [`Model::chains`]).
///
/// The strand starts with two prescribed vertices (handle slots `parent`); every free vertex
/// after them is encoded by two numbers `q[2j], q[2j + 1]` (`j` its index among the free
/// vertices), the bend of the edge that ends at it. Decoding starts at the second prescribed
/// vertex with the axes `d` (unit parent edge), `u` (the rest normal turned by the frame
/// rotation, made perpendicular to `d`) and `w = d x u`, and for each edge turns the axes by
/// the Cayley map of the Gibbs vector `g = (u q[2j] + w q[2j + 1]) / length` and steps `length`
/// along the new `d`, so every edge keeps its rest length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Chain<'a> {
    /// Handle slots of the strand's two prescribed vertices (the parent edge goes from the
    /// first to the second).
    pub parent: [u32; 2],
    /// Unit vector perpendicular to the parent edge at rest.
    pub rest_normal: [f32; 3],
    /// Free-vertex indices of the strand's free vertices, root to tip.
    pub slots: &'a [u32],
    /// Rest length of the edge that ends at each of them.
    pub lengths: &'a [f32],
}

/// The strands of a bend-encoded model, in order (see [`Model::chains`]). Stops at the first
/// record that does not fit its table (none in a validated model).
#[derive(Clone, Debug)]
pub struct Chains<'a> {
    indices: &'a [u32],
    floats: &'a [f32],
}

impl<'a> Iterator for Chains<'a> {
    type Item = Chain<'a>;

    fn next(&mut self) -> Option<Chain<'a>> {
        let (&[p0, p1, n], rest) = self.indices.split_first_chunk::<3>()?;
        let (&normal, reals) = self.floats.split_first_chunk::<3>()?;
        let n = n as usize;
        if rest.len() < n || reals.len() < n {
            self.indices = &[];
            self.floats = &[];
            return None;
        }
        let (slots, rest) = rest.split_at(n);
        let (lengths, reals) = reals.split_at(n);
        self.indices = rest;
        self.floats = reals;
        Some(Chain {
            parent: [p0, p1],
            rest_normal: normal,
            slots,
            lengths,
        })
    }
}

/// A frozen model (see the module docs). Every [`Span`] names a range of `floats` or
/// `indices`; [`Model::validate`] checks all of them once, after which the accessors cannot
/// fail.
#[derive(Clone, Copy, Debug)]
pub struct Model<'a> {
    /// Coordinates per vertex (2 or 3).
    pub dim: u32,
    /// Vertices of the full mesh.
    pub num_vertices: u32,
    /// Latent size.
    pub latent: u32,
    /// Boundary-condition signal numbers per frame ([`SIGNAL_PER_HANDLE`] per handle).
    pub bc_len: u32,
    /// Time step in seconds: the frame time [`crate::Instance::step`] advances by.
    pub dt: f32,
    /// Shortest frame time the integrator was trained at; 0 with [`Model::dt_max`] for a model
    /// trained at the one frame time [`Model::dt`].
    pub dt_min: f32,
    /// Longest frame time the integrator was trained at. When positive, the integrator takes
    /// the frame time (seconds) as its last input, a step adds `dt / Model::dt` times the
    /// network's increment (the network predicts a frame of `Model::dt` at every rate), and
    /// [`crate::Instance::step_dt`] steps by any positive frame time (outside
    /// `dt_min..=dt_max` the motion is an extrapolation); when 0 the model steps by [`Model::dt`]
    /// only.
    pub dt_max: f32,
    /// Whether a timed integrator (see [`Model::dt_max`]) reads, in place of the latent before
    /// the last, the last latent's change per frame of [`Model::dt`]:
    /// `(z_{t-1} - z_{t-2}) * Model::dt / dt`, a latent velocity of one scale at every frame
    /// rate. `false` for a model of one frame time and for timed models of format 7.
    pub rate_input: bool,
    /// Rest bounding-box diagonal.
    pub diagonal: f32,
    /// Whether states are encoded relative to the handles' rotation.
    pub rotates: bool,
    /// Weights (those stored as `f32`), biases and scales of both networks.
    pub params: &'a [f32],
    /// Half-precision weights (empty unless a layer is [`WeightFormat::F16`]).
    pub halves: &'a [u16],
    /// Int8 weights (empty unless a layer is [`WeightFormat::Int8`]).
    pub bytes: &'a [i8],
    /// Other real-valued arrays.
    pub floats: &'a [f32],
    /// Index arrays.
    pub indices: &'a [u32],
    /// Decoder layers.
    pub decoder: &'a [Layer],
    /// Whether the decoder's last layer is a linear basis applied to `[z; 0] + g(z)` (see the
    /// module docs) rather than the output layer of a residual MLP.
    pub decoder_basis: bool,
    /// Integrator layers.
    pub integrator: &'a [Layer],
    /// Handles, in boundary-condition signal order.
    pub handles: &'a [Handle],
    /// Rest positions (`dim` per vertex), in `floats`.
    pub rest: Span,
    /// Prescribed vertices in handle order (handles concatenated, each handle's ascending), in
    /// `indices`.
    pub handle_vertices: Span,
    /// Encoded (free) vertices, ascending, in `indices`.
    pub free_vertices: Span,
    /// Per free vertex, its origin (0 for the handle centroid, else a strand), in `indices`.
    pub origin_of: Span,
    /// Per rod strand, the handle slot of its root; empty when the origin is the centroid of
    /// all handle vertices. In `indices`.
    pub root_slots: Span,
    /// Rod strands encoded by their bends instead of positions (see [`Chain`]); empty when the
    /// encoded vertices are positions. In `indices`, one record per strand:
    /// `[parent_0, parent_1, n, slot_0, ..., slot_(n-1)]`. Validation names its parts
    /// `chains` (the table), `chains.parent` and `chains.slots`.
    pub chains: Span,
    /// The real-valued part of [`Model::chains`]: in `floats`, one record per strand,
    /// `[normal_x, normal_y, normal_z, length_0, ..., length_(n-1)]`. Validation names its parts
    /// `chains.rest_normal` and `chains.lengths`.
    pub chain_floats: Span,
    /// Per free vertex of a bend-encoded model, its position among the slots of
    /// [`Model::chains`] taken strand after strand (their inverse, so that validation checks
    /// in one pass that they name every free vertex once); empty without strands. Derived
    /// when an artifact is loaded, not stored in it. In `indices`.
    pub chain_order: Span,
    /// Vertices that are drawn, ascending, in `indices`.
    pub surface_vertices: Span,
    /// Per drawn vertex, its free-vertex index, or [`HANDLE_SOURCE`] | its handle slot.
    pub surface_source: Span,
    /// Triangles to draw, three indices into [`Model::surface_vertices`] each (so into the
    /// buffer of [`crate::Instance::decode_surface_into`]): a tet mesh's boundary faces
    /// (outward), a 2D mesh's or cloth's triangles, none for rods. In `indices`.
    pub surface_triangles: Span,
    /// Latent of the initial (rest) state, in `floats`.
    pub initial_latent: Span,
    /// Smallest value of each latent coordinate in the training data, in `floats`.
    pub latent_min: Span,
    /// Largest value of each latent coordinate in the training data, in `floats`.
    pub latent_max: Span,
    /// The run-time collider slots the integrator reads, four numbers each in `floats`: the
    /// shape row `[code, a, b, c]` of the `collider` module (sphere `[0, radius, 0, 0]`, capsule
    /// `[1, radius, half_length, 0]`, box `[2, hx, hy, hz]`). Empty for a model without
    /// collider inputs. Each slot adds [`FEATURES_PER_COLLIDER`] inputs after
    /// the three signals (before the frame time).
    pub collider_shapes: Span,
    /// The render mesh riding on the simulation mesh ([`crate::render`]): per render vertex,
    /// the four simulation vertices of its tet, in `indices`. Empty without a render mesh.
    pub render_anchors: Span,
    /// Per render vertex, the barycentric weights of its four anchors, in `floats`.
    pub render_weights: Span,
    /// Render triangles, three render-vertex indices each, in `indices`.
    pub render_triangles: Span,
    /// Per render vertex, its texture coordinates `(u, v)`, in `floats`; empty when the asset
    /// has none.
    pub render_uvs: Span,
}

/// What is wrong with a model: the field and the problem.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ModelError {
    /// The offending field.
    pub field: &'static str,
    /// What is wrong with it.
    pub problem: Problem,
}

/// Kinds of [`ModelError`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Problem {
    /// An array has the wrong number of elements.
    Length {
        /// Elements required.
        expected: usize,
        /// Elements found.
        found: usize,
    },
    /// A span or vertex index points outside its pool or mesh.
    OutOfRange,
    /// A value is NaN or infinite.
    NotFinite,
    /// A value is outside what the runtime supports (dimension, layer count, widths).
    Unsupported,
    /// Layer shapes do not chain.
    Shape,
    /// Vertex sets do not partition the mesh, or are not ascending.
    Inconsistent,
    /// A finite value outside its domain (a rest length that is not positive, a normal that is
    /// not of unit length).
    Domain,
}

impl fmt::Display for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "field `{}`: ", self.field)?;
        match self.problem {
            Problem::Length { expected, found } => write!(f, "{found} elements, expected {expected}"),
            Problem::OutOfRange => write!(f, "index out of range"),
            Problem::NotFinite => write!(f, "holds a non-finite value"),
            Problem::Unsupported => write!(f, "value not supported by this runtime"),
            Problem::Shape => write!(f, "layer shapes do not chain"),
            Problem::Inconsistent => write!(f, "vertex sets are inconsistent"),
            Problem::Domain => write!(f, "holds a value outside its domain"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for ModelError {}

impl<'a> Model<'a> {
    /// Coordinates per vertex.
    pub fn dim(&self) -> usize {
        self.dim as usize
    }
    /// Length of a full state (`dim` per vertex).
    pub fn state_len(&self) -> usize {
        self.dim() * self.num_vertices as usize
    }
    /// Length of a surface-only state (`dim` per drawn vertex).
    pub fn surface_len(&self) -> usize {
        self.dim() * self.surface_vertices.len as usize
    }
    /// Whether rod strands are encoded by their bends ([`Model::chains`] is not empty).
    pub fn bends(&self) -> bool {
        self.chains.len > 0
    }
    /// Multiplications of a full decode's strand walk, for cost reports: one
    /// [`crate::ChainWalk::step`] per free vertex of a bend-encoded model (`g` 6, `|g|^2` 3,
    /// each of the three axes 15 for two cross products and the scaled update, the position
    /// 3; its four divisions not counted), 0 for a model without strands.
    pub fn walk_multiply_adds(&self) -> usize {
        match self.bends() {
            true => 57 * self.free_vertices().len(),
            false => 0,
        }
    }
    /// Numbers per encoded (free) vertex: `dim`, or 2 for bends.
    pub fn values_per_vertex(&self) -> usize {
        if self.bends() {
            2
        } else {
            self.dim()
        }
    }
    /// Length of an encoded state (`dim` per free vertex, 2 for bends).
    pub fn encoded_len(&self) -> usize {
        self.values_per_vertex() * self.free_vertices.len as usize
    }
    /// Whether the integrator takes the frame time as an input (trained over a range of frame
    /// times, [`Model::dt_min`] to [`Model::dt_max`]).
    pub fn timed(&self) -> bool {
        self.dt_max > 0.0
    }
    /// Length of the integrator's input: two latents, three signals, the collider slots'
    /// features, and the frame time when [`Model::timed`].
    pub fn integrator_input(&self) -> usize {
        2 * self.latent as usize
            + 3 * self.bc_len as usize
            + FEATURES_PER_COLLIDER * self.colliders()
            + usize::from(self.timed())
    }
    /// Widest hidden layer of either network (for a basis decoder, of its MLP and its
    /// features).
    pub fn hidden(&self) -> usize {
        let net = |layers: &[Layer]| layers.first().map_or(0, |l| l.rows as usize);
        let decoder = match self.decoder.split_last() {
            Some((basis, mlp)) if self.decoder_basis => net(mlp).max(basis.cols as usize),
            _ => net(self.decoder),
        };
        decoder.max(net(self.integrator))
    }
    /// Bytes of network weights, biases and scales.
    pub fn weight_bytes(&self) -> usize {
        core::mem::size_of_val(self.params) + core::mem::size_of_val(self.halves) + self.bytes.len()
    }
    /// The pools the layers point into.
    pub fn weights(&self) -> Weights<'a> {
        Weights {
            params: self.params,
            halves: self.halves,
            bytes: self.bytes,
        }
    }

    fn floats_of(&self, span: Span) -> &'a [f32] {
        span.of(self.floats).unwrap_or(&[])
    }
    fn indices_of(&self, span: Span) -> &'a [u32] {
        span.of(self.indices).unwrap_or(&[])
    }
    /// Rest positions.
    pub fn rest(&self) -> &'a [f32] {
        self.floats_of(self.rest)
    }
    /// Prescribed vertices in handle order.
    pub fn handle_vertices(&self) -> &'a [u32] {
        self.indices_of(self.handle_vertices)
    }
    /// Free vertices, ascending.
    pub fn free_vertices(&self) -> &'a [u32] {
        self.indices_of(self.free_vertices)
    }
    /// Origin of each free vertex.
    pub fn origin_of(&self) -> &'a [u32] {
        self.indices_of(self.origin_of)
    }
    /// Handle slots of the strand roots (empty: centroid origin).
    pub fn root_slots(&self) -> &'a [u32] {
        self.indices_of(self.root_slots)
    }
    /// The strands encoded by their bends, in order (none for positions).
    pub fn chains(&self) -> Chains<'a> {
        Chains {
            indices: self.indices_of(self.chains),
            floats: self.floats_of(self.chain_floats),
        }
    }
    /// Drawn vertices, ascending.
    pub fn surface_vertices(&self) -> &'a [u32] {
        self.indices_of(self.surface_vertices)
    }
    /// Where each drawn vertex comes from (see [`Model::surface_source`]).
    pub fn surface_source(&self) -> &'a [u32] {
        self.indices_of(self.surface_source)
    }
    /// Triangles to draw, three indices into the drawn vertices each.
    pub fn surface_triangles(&self) -> &'a [u32] {
        self.indices_of(self.surface_triangles)
    }
    /// Vertices of handle `h`.
    pub fn handle_vertices_of(&self, h: &Handle) -> &'a [u32] {
        self.indices_of(h.vertices)
    }
    /// Identity-pose positions of handle `h` (3 per vertex).
    pub fn handle_reference_of(&self, h: &Handle) -> &'a [f32] {
        self.floats_of(h.reference)
    }
    /// Initial latent.
    pub fn initial_latent(&self) -> &'a [f32] {
        self.floats_of(self.initial_latent)
    }
    /// Per-coordinate minimum of the training latents.
    pub fn latent_min(&self) -> &'a [f32] {
        self.floats_of(self.latent_min)
    }
    /// Per-coordinate maximum of the training latents.
    pub fn latent_max(&self) -> &'a [f32] {
        self.floats_of(self.latent_max)
    }
    /// The collider slots' shape rows (four numbers each, see [`Model::collider_shapes`]).
    pub fn collider_shape_rows(&self) -> &'a [f32] {
        self.floats_of(self.collider_shapes)
    }
    /// Number of run-time collider slots the integrator reads.
    pub fn colliders(&self) -> usize {
        self.collider_shapes.len as usize / SHAPE_ROW
    }
}

/// Whether `v` ascends strictly.
pub(crate) fn ascending(v: &[u32]) -> bool {
    v.windows(2).all(|w| w[0] < w[1])
}
