//! Encoding of full-space states relative to their boundary conditions (Li et al. 2025,
//! Sec. 3.2; docs/design.md, decision 3), so that networks never have to learn the rigid motion
//! of the handles.
//!
//! Handle (prescribed) vertices are left out of the encoded vector `q`; decoding puts them
//! at their boundary-condition targets. Every other vertex `v` is stored, in ascending
//! vertex order, `dim` numbers each, as
//!
//! ```text
//! q_v = R^T (x_v - o_v)          decoded as          x_v = R q_v + o_v
//! ```
//!
//! where the [`Frame`] of a state holds the rotation `R` and the origins `o`:
//!
//! - `o_v` is the root vertex of `v`'s strand for rods whose every root is prescribed
//!   ([`Origins::StrandRoots`]), and otherwise (cloth, solids, 2D, anything else) the
//!   centroid `c` of the current handle-vertex positions ([`Origins::HandleCentroid`]);
//! - `R` is the best-fit proper rotation (Kabsch) carrying the handles' reference
//!   positions (their frame-0 targets) to their current targets, when the scene's handles
//!   can rotate, and the identity otherwise (e.g. the cloth's two pinned corners are
//!   collinear, so their rotation is ill-determined; translation alone is removed there).
//!
//! Both `R` and the origins depend only on the handle targets, so decoding is one affine map
//! per vertex that a runtime without allocation can repeat. For a single rigid handle,
//! `R` equals the handle's pose rotation and `c` is the pose applied to the reference
//! centroid, so such a runtime need not run an SVD. In 2D, `R` is the upper-left 2x2 block
//! and the third components of the origins are zero.

use faer::Mat;
use nalgebra::{DMatrix, Matrix3, Vector3};

use crate::learn::recipe::RodEncoding;
use mochi_sim::bc::Handle;
use mochi_sim::error::InputError;
use mochi_sim::mesh::{Elements, Mesh};
use mochi_sim::scene::{BuiltScene, HandleSpec};
use mochi_sim::trajectory::Trajectory;

/// Spread of the handle points along a principal direction, relative to the largest, below
/// which that direction counts as absent.
const DEGENERATE_SPREAD: f64 = 1e-10;

/// Something wrong with the inputs of an [`Encoding`].
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum EncodingError {
    /// A vector has the wrong length.
    #[error("{what}: expected {expected} values, found {found}")]
    Length {
        /// Which input.
        what: &'static str,
        /// Length the encoding needs.
        expected: usize,
        /// Length given.
        found: usize,
    },
    /// The handles do not describe prescribed vertices of the mesh.
    #[error("handle `{handle}`: {message}")]
    BadHandle {
        /// Handle name.
        handle: String,
        /// What is wrong.
        message: String,
    },
    /// A point of the rotation fit holds a NaN or infinity.
    #[error("the points of the rotation fit hold a non-finite value")]
    NotFinite,
    /// The SVD of the rotation fit did not converge.
    #[error("the SVD of the rotation fit did not converge: {0}")]
    NoConvergence(String),
    /// Rotation was asked for, but the handle vertices cannot determine one (3D needs
    /// them to span a plane, 2D a line).
    #[error("the {count} handle vertices span {span} dimension(s), too few to fix a rotation")]
    DegenerateHandles {
        /// Number of handle vertices.
        count: usize,
        /// Dimension of the affine space they span (0: a point, 1: a line).
        span: usize,
    },
}

fn check_len(what: &'static str, expected: usize, found: usize) -> Result<(), EncodingError> {
    if expected == found {
        Ok(())
    } else {
        Err(EncodingError::Length { what, expected, found })
    }
}

/// Where the origins `o_v` of the encoded vertices come from.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Origins {
    /// One origin for every vertex: the centroid of the current handle targets (the
    /// origin is 0 when there are no handles).
    HandleCentroid,
    /// One origin per rod strand: the target of its root vertex. `root_slots[s]` is the
    /// position of strand `s`'s root in the handle-target list.
    StrandRoots {
        /// Per strand, the index of its root among the handle vertices.
        root_slots: Vec<usize>,
    },
}

/// The frame of one state: rotation and origins (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// `R`; the identity when the handles do not rotate (upper-left 2x2 used in 2D).
    pub rotation: Matrix3<f64>,
    /// The origins, indexed by [`Encoding::origin_of`] (z = 0 in 2D).
    pub origins: Vec<Vector3<f64>>,
    /// Per strand, where its chain starts (empty unless strands are encoded by bends).
    pub chains: Vec<ChainStart>,
}

/// How the states of one body are encoded relative to its boundary conditions.
#[derive(Clone, Debug, PartialEq)]
pub struct Encoding {
    dim: usize,
    num_vertices: usize,
    /// Prescribed vertices in handle-target order (handles concatenated).
    handle_vertices: Vec<usize>,
    /// Their frame-0 targets (`dim` per vertex), the reference of the rotation fit.
    reference: Vec<f64>,
    rotates: bool,
    /// Encoded vertices, ascending.
    free_vertices: Vec<usize>,
    /// Per encoded vertex, the index of its origin in [`Frame::origins`].
    origin_of: Vec<usize>,
    origins: Origins,
    /// Rod strands encoded by their bends instead of their positions
    /// ([`Encoding::with_strand_bends`]); empty for the affine encoding.
    chains: Vec<Chain>,
}

/// One rod strand in the stretch-free encoding ([`Encoding::with_strand_bends`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Chain {
    /// Handle slots of the strand's two prescribed vertices; the edge from the first to the
    /// second is the parent of the first free edge.
    pub parent: [usize; 2],
    /// A unit vector perpendicular to the parent edge at rest: with the handles' rotation
    /// applied, it fixes the first bend's axes.
    pub rest_normal: Vector3<f64>,
    /// Indices into the encoded vertices of the strand's free vertices, root to tip.
    pub slots: Vec<usize>,
    /// Rest length of the edge that ends at each of them.
    pub lengths: Vec<f64>,
}

/// Where a strand's chain starts in one state: its last prescribed vertex and the axes
/// (parent-edge direction, then two normals) of the first bend.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChainStart {
    /// Position of the strand's last prescribed vertex.
    pub anchor: Vector3<f64>,
    /// Unit parent-edge direction `d`, and the normals `u`, `w` (`d x u = w`).
    pub axes: [Vector3<f64>; 3],
}

impl Encoding {
    /// The encoding of a built scene, rod strands encoded as `rods` says: rotation is removed when some handle can rotate
    /// (see [`handles_rotate`]).
    pub fn new(problem: &BuiltScene, rods: RodEncoding) -> Result<Encoding, InputError> {
        let rotates = handles_rotate(&problem.scene.handles);
        let encoding = Encoding::from_parts(&problem.mesh, &problem.handles, rotates)
            .map_err(|e| InputError::field(&problem.scene.source, "handles", e.to_string()))?;
        match rods {
            RodEncoding::Positions => Ok(encoding),
            RodEncoding::Bends => encoding
                .with_strand_bends(&problem.mesh)
                .map_err(|e| InputError::field(&problem.scene.source, "latent.rods", e.to_string())),
        }
    }

    /// The encoding of `mesh` with prescribed `handles`; `rotates` says whether to remove
    /// the handles' rotation (it needs handle vertices that are not collinear in 3D, or
    /// not all one point in 2D).
    pub(crate) fn from_parts(mesh: &Mesh, handles: &[Handle], rotates: bool) -> Result<Encoding, EncodingError> {
        let dim = mesh.dim;
        let num_vertices = mesh.num_vertices();
        let mut slot_of = vec![None; num_vertices];
        let mut handle_vertices = Vec::new();
        let mut reference = Vec::new();
        for h in handles {
            let bad = |message: String| EncodingError::BadHandle {
                handle: h.name.clone(),
                message,
            };
            if h.reference.len() != h.vertices.len() {
                return Err(bad(format!(
                    "{} reference positions for {} vertices",
                    h.reference.len(),
                    h.vertices.len()
                )));
            }
            for (&v, r) in h.vertices.iter().zip(&h.reference) {
                match slot_of.get(v) {
                    None => return Err(bad(format!("vertex {v} out of range (mesh has {num_vertices})"))),
                    Some(Some(_)) => return Err(bad(format!("vertex {v} is prescribed twice"))),
                    Some(None) => slot_of[v] = Some(handle_vertices.len()),
                }
                handle_vertices.push(v);
                reference.extend_from_slice(&r[..dim]);
            }
        }
        if rotates {
            check_spread(&reference, dim)?;
        }
        let free_vertices: Vec<usize> = (0..num_vertices).filter(|&v| slot_of[v].is_none()).collect();
        let (origins, origin_of) = match strand_roots(mesh, &slot_of, &free_vertices) {
            Some((root_slots, strand_of)) => (Origins::StrandRoots { root_slots }, strand_of),
            None => (Origins::HandleCentroid, vec![0; free_vertices.len()]),
        };
        Ok(Encoding {
            dim,
            num_vertices,
            handle_vertices,
            reference,
            rotates,
            free_vertices,
            origin_of,
            origins,
            chains: Vec::new(),
        })
    }

    /// Encodes the rod strands of `mesh` by their bends instead of their positions, so that
    /// no encoded vector can stretch a rod. Every strand must start with exactly two
    /// prescribed vertices (a clamped root) and every free vertex must lie on a strand.
    ///
    /// Each free edge `e` of a strand is stored as two numbers `l_e (g . u, g . w)`, where
    /// `l_e` is its rest length and `g = d x d_e / (1 + d . d_e)` the Gibbs vector
    /// (`tan(angle / 2)` times the axis) of the smallest rotation carrying the previous
    /// edge's direction `d` to the edge's own `d_e`, in the axes `(d, u, w)` that the root's
    /// axes reach by the same rotations (parallel transport along the strand). Decoding
    /// rotates the axes by the Cayley map of `g` and steps `l_e` along the new direction:
    /// rational arithmetic only, every edge at its rest length, exact for any rod that is
    /// not stretched. The root's axes are the parent edge's direction and the rest normal
    /// turned by the handles' rotation.
    pub(crate) fn with_strand_bends(mut self, mesh: &Mesh) -> Result<Encoding, EncodingError> {
        let bad = |message: String| EncodingError::BadHandle {
            handle: "rod roots".into(),
            message,
        };
        let Elements::Rods(strands) = &mesh.elements else {
            return Err(bad("bend encoding needs a rods mesh".into()));
        };
        if self.dim != 3 {
            return Err(bad(format!(
                "bend encoding needs 3D rods, the mesh has {} coordinates per vertex",
                self.dim
            )));
        }
        let slot_of = |v: usize| self.handle_vertices.iter().position(|&h| h == v);
        let index_of = |v: usize| self.free_vertices.binary_search(&v).ok();
        let point = |v: usize| pad(&mesh.rest[v * 3..v * 3 + 3]);
        let mut covered = 0;
        let mut chains = Vec::with_capacity(strands.len());
        for (k, strand) in strands.iter().enumerate() {
            let (Some(a), Some(b)) = (
                strand.first().and_then(|&v| slot_of(v)),
                strand.get(1).and_then(|&v| slot_of(v)),
            ) else {
                return Err(bad(format!(
                    "strand {k} does not start with two prescribed vertices (select rod-roots = 2)"
                )));
            };
            let parent = point(strand[1]) - point(strand[0]);
            if parent.norm() == 0.0 {
                return Err(bad(format!("strand {k}: its first edge has zero rest length")));
            }
            let mut slots = Vec::with_capacity(strand.len().saturating_sub(2));
            let mut lengths = Vec::with_capacity(slots.capacity());
            for pair in strand[1..].windows(2) {
                let j = index_of(pair[1])
                    .ok_or_else(|| bad(format!("strand {k}: vertex {} after the root is prescribed", pair[1])))?;
                let length = (point(pair[1]) - point(pair[0])).norm();
                if length == 0.0 {
                    return Err(bad(format!(
                        "strand {k}: the edge to vertex {} has zero rest length",
                        pair[1]
                    )));
                }
                slots.push(j);
                lengths.push(length);
            }
            covered += slots.len();
            chains.push(Chain {
                parent: [a, b],
                rest_normal: normal_to(&parent.normalize()),
                slots,
                lengths,
            });
        }
        if covered != self.free_vertices.len() {
            return Err(bad(format!(
                "{} free vertices, {covered} of them on strands: every free vertex must lie on exactly one strand",
                self.free_vertices.len()
            )));
        }
        self.chains = chains;
        Ok(self)
    }

    /// The strands encoded by their bends (empty for the affine encoding).
    pub fn chains(&self) -> &[Chain] {
        &self.chains
    }

    /// Whether rod strands are encoded by their bends ([`Encoding::with_strand_bends`]).
    pub fn strand_bends(&self) -> bool {
        !self.chains.is_empty()
    }

    /// Numbers per encoded vertex: `dim` for positions, 2 for bends.
    pub(crate) fn values_per_vertex(&self) -> usize {
        if self.strand_bends() {
            2
        } else {
            self.dim
        }
    }

    /// Coordinates per vertex.
    pub fn dim(&self) -> usize {
        self.dim
    }
    /// Length of a full state (`dim` per mesh vertex).
    pub fn state_len(&self) -> usize {
        self.num_vertices * self.dim
    }
    /// Length of an encoded vector (`dim` per encoded vertex, 2 with strand bends).
    pub fn encoded_len(&self) -> usize {
        self.free_vertices.len() * self.values_per_vertex()
    }
    /// Length of the handle targets (`dim` per prescribed vertex).
    pub(crate) fn targets_len(&self) -> usize {
        self.handle_vertices.len() * self.dim
    }
    /// The identity-pose handle targets (`dim` per prescribed vertex), the reference of the
    /// rotation fit.
    pub fn reference(&self) -> &[f64] {
        &self.reference
    }
    /// Whether the handles' rotation is removed.
    pub fn rotates(&self) -> bool {
        self.rotates
    }
    /// The encoded vertices, in encoded order (ascending).
    pub fn free_vertices(&self) -> &[usize] {
        &self.free_vertices
    }
    /// The prescribed vertices, in handle-target order.
    pub fn handle_vertices(&self) -> &[usize] {
        &self.handle_vertices
    }
    /// Per encoded vertex, the index of its origin in [`Frame::origins`].
    pub fn origin_of(&self) -> &[usize] {
        &self.origin_of
    }
    /// Where the origins come from.
    pub(crate) fn origins(&self) -> &Origins {
        &self.origins
    }

    /// The handle targets of a full state: the positions of its prescribed vertices.
    pub fn handle_targets(&self, x: &[f64]) -> Result<Vec<f64>, EncodingError> {
        check_len("state", self.state_len(), x.len())?;
        let d = self.dim;
        Ok(self
            .handle_vertices
            .iter()
            .flat_map(|&v| &x[v * d..(v + 1) * d])
            .copied()
            .collect())
    }

    /// The frame fixed by the handle targets (`dim` per prescribed vertex, handle order).
    pub fn frame(&self, handle_targets: &[f64]) -> Result<Frame, EncodingError> {
        check_len("handle targets", self.targets_len(), handle_targets.len())?;
        let point = |slot: usize| pad(&handle_targets[slot * self.dim..(slot + 1) * self.dim]);
        let rotation = if self.rotates {
            best_fit_rotation(&self.reference, handle_targets, self.dim)?
        } else {
            Matrix3::identity()
        };
        let origins = match &self.origins {
            Origins::HandleCentroid => vec![centroid(handle_targets, self.dim)],
            Origins::StrandRoots { root_slots } => root_slots.iter().map(|&s| point(s)).collect(),
        };
        let chains = self
            .chains
            .iter()
            .map(|c| {
                let anchor = point(c.parent[1]);
                let d = (anchor - point(c.parent[0])).normalize();
                let turned = rotation * c.rest_normal;
                let projected = turned - d * d.dot(&turned);
                let u = if projected.norm() > 1e-6 {
                    projected.normalize()
                } else {
                    normal_to(&d)
                };
                if !(d.iter().chain(u.iter()).all(|x| x.is_finite())) {
                    return Err(EncodingError::NotFinite);
                }
                Ok(ChainStart {
                    anchor,
                    axes: [d, u, d.cross(&u)],
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Frame {
            rotation,
            origins,
            chains,
        })
    }

    fn check_frame(&self, frame: &Frame) -> Result<(), EncodingError> {
        let expected = match &self.origins {
            Origins::HandleCentroid => 1,
            Origins::StrandRoots { root_slots } => root_slots.len(),
        };
        check_len("frame origins", expected, frame.origins.len())?;
        check_len("frame chains", self.chains.len(), frame.chains.len())
    }

    /// Encodes the full state `x` in `frame`: `q_v = R^T (x_v - o_v)` for every encoded vertex.
    pub(crate) fn encode(&self, x: &[f64], frame: &Frame) -> Result<Vec<f64>, EncodingError> {
        check_len("state", self.state_len(), x.len())?;
        self.check_frame(frame)?;
        if self.strand_bends() {
            return Ok(self.encode_bends(x, frame));
        }
        let d = self.dim;
        let rt = frame.rotation.transpose();
        let mut q = Vec::with_capacity(self.encoded_len());
        for (&v, &o) in self.free_vertices.iter().zip(&self.origin_of) {
            let local = rt * (pad(&x[v * d..(v + 1) * d]) - frame.origins[o]);
            q.extend_from_slice(&local.as_slice()[..d]);
        }
        Ok(q)
    }

    /// Pulls a full-space gradient `dE/dx`, taken at the decoding of `q` in `frame`, back to
    /// the encoded coordinates (the chain rule through [`Encoding::decode_into`]), scaled by
    /// `1 / scale`, into `out` (`encoded_len` values). For positions this is
    /// `dE/dq_v = R^T dE/dx_v` and does not depend on `q`; for strand bends it is the
    /// reverse pass through each chain.
    pub fn encode_gradient(
        &self,
        q: &[f64],
        grad: &[f64],
        frame: &Frame,
        scale: f64,
        out: &mut [f64],
    ) -> Result<(), EncodingError> {
        check_len("encoded vector", self.encoded_len(), q.len())?;
        check_len("gradient", self.state_len(), grad.len())?;
        check_len("encoded gradient", self.encoded_len(), out.len())?;
        self.check_frame(frame)?;
        if self.strand_bends() {
            self.bends_gradient(q, grad, frame, scale, out);
            return Ok(());
        }
        let d = self.dim;
        let rt = frame.rotation.transpose();
        for (j, &v) in self.free_vertices.iter().enumerate() {
            let local = rt * pad(&grad[v * d..(v + 1) * d]);
            for c in 0..d {
                out[j * d + c] = local[c] / scale;
            }
        }
        Ok(())
    }

    /// The bends of every free edge of `x` (see [`Encoding::with_strand_bends`]).
    fn encode_bends(&self, x: &[f64], frame: &Frame) -> Vec<f64> {
        let mut q = vec![0.0; self.encoded_len()];
        for (chain, start) in self.chains.iter().zip(&frame.chains) {
            let (mut previous, mut axes) = (start.anchor, start.axes);
            for (&j, &length) in chain.slots.iter().zip(&chain.lengths) {
                let v = self.free_vertices[j];
                let p = pad(&x[v * 3..v * 3 + 3]);
                let direction = (p - previous).normalize();
                let g = axes[0].cross(&direction) / (1.0 + axes[0].dot(&direction));
                q[2 * j] = length * g.dot(&axes[1]);
                q[2 * j + 1] = length * g.dot(&axes[2]);
                axes = axes.map(|y| cayley(&g, &y));
                previous = p;
            }
        }
        q
    }

    /// Walks every chain of `q` from its anchor, calling `place(j, position)` for each
    /// encoded vertex `j`.
    fn decode_bends(&self, q: &[f64], frame: &Frame, mut place: impl FnMut(usize, &Vector3<f64>)) {
        for (chain, start) in self.chains.iter().zip(&frame.chains) {
            walk_chain(chain, start, q, |j, _, _, position| place(j, position));
        }
    }

    /// Reverse pass of [`Encoding::decode_bends`]: `dE/dq` from `dE/dx`.
    fn bends_gradient(&self, q: &[f64], grad: &[f64], frame: &Frame, scale: f64, out: &mut [f64]) {
        for (chain, start) in self.chains.iter().zip(&frame.chains) {
            // Forward: the axes before each edge and its Gibbs vector.
            let mut before = Vec::with_capacity(chain.slots.len());
            walk_chain(chain, start, q, |_, axes, g, _| before.push((*axes, *g)));
            // Backward: `tail` sums dE/dx over the vertices from edge e to the tip; `carry`
            // is the adjoint of the axes after edge e from the edges beyond it.
            let mut tail = Vector3::zeros();
            let mut carry = [Vector3::zeros(); 3];
            for e in (0..chain.slots.len()).rev() {
                let (j, length) = (chain.slots[e], chain.lengths[e]);
                let v = self.free_vertices[j];
                tail += pad(&grad[v * 3..v * 3 + 3]);
                let mut adjoint = carry;
                adjoint[0] += tail * length;
                let (axes, g) = &before[e];
                let g_bar: Vector3<f64> = (0..3).map(|c| cayley_vjp(g, &axes[c], &adjoint[c])).sum();
                out[2 * j] = g_bar.dot(&axes[1]) / length / scale;
                out[2 * j + 1] = g_bar.dot(&axes[2]) / length / scale;
                carry = adjoint.map(|a| cayley(&-g, &a));
                carry[1] += g_bar * (q[2 * j] / length);
                carry[2] += g_bar * (q[2 * j + 1] / length);
            }
        }
    }

    /// Encodes a full state in the frame of its own prescribed vertices.
    pub fn encode_state(&self, x: &[f64]) -> Result<Vec<f64>, EncodingError> {
        let frame = self.frame(&self.handle_targets(x)?)?;
        self.encode(x, &frame)
    }

    /// Encodes every frame of a trajectory of this body (each in the frame of its own
    /// prescribed vertices).
    pub fn encode_trajectory(&self, trajectory: &Trajectory) -> Result<Vec<Vec<f64>>, EncodingError> {
        check_len("trajectory coordinates per vertex", self.dim, trajectory.dim)?;
        trajectory.positions.iter().map(|x| self.encode_state(x)).collect()
    }

    /// Decodes `q` into the full state `out`: `x_v = R q_v + o_v` for encoded vertices,
    /// the targets for prescribed ones. `frame` must be `self.frame(handle_targets)`.
    pub fn decode_into(
        &self,
        q: &[f64],
        frame: &Frame,
        handle_targets: &[f64],
        out: &mut [f64],
    ) -> Result<(), EncodingError> {
        check_len("encoded vector", self.encoded_len(), q.len())?;
        check_len("handle targets", self.targets_len(), handle_targets.len())?;
        check_len("output state", self.state_len(), out.len())?;
        self.check_frame(frame)?;
        let d = self.dim;
        if self.strand_bends() {
            self.decode_bends(q, frame, |j, p| {
                let v = self.free_vertices[j];
                out[v * 3..v * 3 + 3].copy_from_slice(p.as_slice());
            });
        } else {
            for (k, (&v, &o)) in self.free_vertices.iter().zip(&self.origin_of).enumerate() {
                let world = frame.rotation * pad(&q[k * d..(k + 1) * d]) + frame.origins[o];
                out[v * d..(v + 1) * d].copy_from_slice(&world.as_slice()[..d]);
            }
        }
        for (slot, &v) in self.handle_vertices.iter().enumerate() {
            out[v * d..(v + 1) * d].copy_from_slice(&handle_targets[slot * d..(slot + 1) * d]);
        }
        Ok(())
    }

    /// Decodes `q` with the handles at `handle_targets` into a new full state.
    pub fn decode(&self, q: &[f64], handle_targets: &[f64]) -> Result<Vec<f64>, EncodingError> {
        let frame = self.frame(handle_targets)?;
        let mut out = vec![0.0; self.state_len()];
        self.decode_into(q, &frame, handle_targets, &mut out)?;
        Ok(out)
    }
}

/// Whether any handle can rotate: it has a script with a non-zero angular velocity, or a
/// sampled motion that can pick a rotating segment (rotation axes, and either no
/// translation directions or a positive `rotation_share`).
pub(crate) fn handles_rotate(handles: &[HandleSpec]) -> bool {
    handles.iter().any(|h| {
        let scripted = h.script.iter().any(|s| s.angular_velocity.iter().any(|w| *w != 0.0));
        let sampled = h
            .motion
            .as_ref()
            .is_some_and(|m| !m.rotation_axes.is_empty() && (m.directions.is_empty() || m.rotation_share > 0.0));
        scripted || sampled
    })
}

/// The proper rotation `R` (det +1) minimising `sum |R (p_i - p̄) - (q_i - q̄)|^2` (Kabsch)
/// between point sets `reference` (p) and `current` (q), `dim` (2 or 3) numbers per point.
/// A 2D rotation is returned in the upper-left block of a 3x3 matrix.
///
/// The SVD is faer's: nalgebra 0.35's SVD returned singular vectors off by 4e-3 for the
/// nearly repeated singular values of a symmetric handle (the 4 x 4 grid of rod roots),
/// where faer's is accurate to round-off.
pub(crate) fn best_fit_rotation(reference: &[f64], current: &[f64], dim: usize) -> Result<Matrix3<f64>, EncodingError> {
    if !(dim == 2 || dim == 3) {
        return Err(EncodingError::Length {
            what: "coordinates per point (2 or 3)",
            expected: 3,
            found: dim,
        });
    }
    check_len("current points", reference.len(), current.len())?;
    check_len(
        "reference points",
        reference.len().next_multiple_of(dim),
        reference.len(),
    )?;
    if !reference.iter().chain(current).all(|c| c.is_finite()) {
        return Err(EncodingError::NotFinite);
    }
    let (p_bar, q_bar) = (centroid(reference, dim), centroid(current, dim));
    // Cross-covariance H = sum (p - p̄)(q - q̄)^T; with H = U S V^T, R = V diag(1, .., det) U^T.
    let mut h = [[0.0; 3]; 3];
    for (p, q) in reference.chunks_exact(dim).zip(current.chunks_exact(dim)) {
        for i in 0..dim {
            for j in 0..dim {
                h[i][j] += (p[i] - p_bar[i]) * (q[j] - q_bar[j]);
            }
        }
    }
    let svd = Mat::<f64>::from_fn(dim, dim, |i, j| h[i][j])
        .svd()
        .map_err(|e| EncodingError::NoConvergence(format!("{e:?}")))?;
    let (u, v) = (svd.U(), svd.V());
    let rotation = |last_sign: f64| {
        let mut r = Matrix3::identity();
        for i in 0..dim {
            for j in 0..dim {
                r[(i, j)] = (0..dim)
                    .map(|k| {
                        let sign = if k == dim - 1 { last_sign } else { 1.0 };
                        sign * v[(i, k)] * u[(j, k)]
                    })
                    .sum();
            }
        }
        r
    };
    let r = rotation(1.0);
    // A reflection fits better: flip the direction of the smallest singular value.
    Ok(if r.determinant() < 0.0 { rotation(-1.0) } else { r })
}

/// Fails when the reference points are too flat to fix a rotation (3D: collinear; 2D: one point).
fn check_spread(reference: &[f64], dim: usize) -> Result<(), EncodingError> {
    let c = centroid(reference, dim);
    let mut cov = DMatrix::<f64>::zeros(dim, dim);
    for p in reference.chunks_exact(dim) {
        for i in 0..dim {
            for j in 0..dim {
                cov[(i, j)] += (p[i] - c[i]) * (p[j] - c[j]);
            }
        }
    }
    // Spread along the principal directions; 3D needs two of them, 2D one.
    let spread: Vec<f64> = cov.symmetric_eigenvalues().iter().map(|e| e.max(0.0).sqrt()).collect();
    let largest = spread.iter().copied().fold(0.0, f64::max);
    let span = spread.iter().filter(|&&s| s > DEGENERATE_SPREAD * largest).count();
    if span < dim - 1 {
        return Err(EncodingError::DegenerateHandles {
            count: reference.len() / dim,
            span,
        });
    }
    Ok(())
}

/// For rods whose every root is prescribed and whose every free vertex lies on a strand:
/// the handle slot of each strand's root, and the strand of each free vertex.
fn strand_roots(mesh: &Mesh, slot_of: &[Option<usize>], free: &[usize]) -> Option<(Vec<usize>, Vec<usize>)> {
    let Elements::Rods(strands) = &mesh.elements else {
        return None;
    };
    let root_slots = strands
        .iter()
        .map(|s| s.first().and_then(|&root| slot_of.get(root).copied().flatten()))
        .collect::<Option<Vec<usize>>>()?;
    let mut strand_of_vertex = vec![None; mesh.num_vertices()];
    for (k, s) in strands.iter().enumerate() {
        for &v in s {
            if let Some(strand) = strand_of_vertex.get_mut(v) {
                strand.get_or_insert(k);
            }
        }
    }
    let strand_of = free
        .iter()
        .map(|&v| strand_of_vertex[v])
        .collect::<Option<Vec<usize>>>()?;
    Some((root_slots, strand_of))
}

/// Walks one chain of `q` from `start`, edge by edge, calling
/// `visit(j, axes before the edge, its Gibbs vector, position of encoded vertex j)`.
fn walk_chain(
    chain: &Chain,
    start: &ChainStart,
    q: &[f64],
    mut visit: impl FnMut(usize, &[Vector3<f64>; 3], &Vector3<f64>, &Vector3<f64>),
) {
    let (mut position, mut axes) = (start.anchor, start.axes);
    for (&j, &length) in chain.slots.iter().zip(&chain.lengths) {
        let g = (axes[1] * q[2 * j] + axes[2] * q[2 * j + 1]) / length;
        let before = axes;
        axes = axes.map(|y| cayley(&g, &y));
        position += axes[0] * length;
        visit(j, &before, &g, &position);
    }
}

/// `y` turned by the rotation whose Gibbs vector is `g` (the Cayley map:
/// `y + 2 / (1 + |g|^2) (g x y + g x (g x y))`).
fn cayley(g: &Vector3<f64>, y: &Vector3<f64>) -> Vector3<f64> {
    let h = g.cross(y);
    y + (h + g.cross(&h)) * (2.0 / (1.0 + g.norm_squared()))
}

/// `(d cayley(g, y) / d g)^T y_bar`: how the turned vector's adjoint reaches `g`.
fn cayley_vjp(g: &Vector3<f64>, y: &Vector3<f64>, y_bar: &Vector3<f64>) -> Vector3<f64> {
    let c = 2.0 / (1.0 + g.norm_squared());
    let h = g.cross(y);
    let k = g.cross(&h);
    g * (-c * c * (h + k).dot(y_bar)) + (y.cross(y_bar) + h.cross(y_bar) + y.cross(&y_bar.cross(g))) * c
}

/// A unit vector perpendicular to the unit vector `d`: the coordinate axis least aligned
/// with `d`, with its `d` component removed.
fn normal_to(d: &Vector3<f64>) -> Vector3<f64> {
    let axis = (0..3).min_by(|&a, &b| d[a].abs().total_cmp(&d[b].abs())).unwrap_or(0);
    let e = Vector3::ith(axis, 1.0);
    (e - d * d.dot(&e)).normalize()
}

/// A point of `dim` (2 or 3) coordinates as a 3-vector (z = 0 in 2D).
fn pad(p: &[f64]) -> Vector3<f64> {
    let mut out = Vector3::zeros();
    out.as_mut_slice()[..p.len()].copy_from_slice(p);
    out
}

/// Centroid of points given `dim` numbers each (the origin for no points).
fn centroid(points: &[f64], dim: usize) -> Vector3<f64> {
    let n = points.len() / dim;
    if n == 0 {
        return Vector3::zeros();
    }
    points.chunks_exact(dim).map(pad).sum::<Vector3<f64>>() / n as f64
}

/// `[z_{t-1}, z_{t-2}, p_t, p_{t-1}, p_{t-2}]` from the three signals.
pub(crate) fn pack_signals(z_prev: &[f32], z_prev2: &[f32], signals: [&[f64]; 3]) -> Vec<f32> {
    let mut row: Vec<f32> = z_prev.iter().chain(z_prev2).copied().collect();
    for p in signals {
        row.extend(p.iter().map(|&v| v as f32));
    }
    row
}

/// The world-space state of an encoded vector `q` (f32, as decoded) in `frame`.
pub fn decode_world(encoding: &Encoding, q: &[f32], frame: &Frame, targets: &[f64]) -> Result<Vec<f64>, EncodingError> {
    let q64: Vec<f64> = q.iter().map(|&v| v as f64).collect();
    let mut out = vec![0.0; encoding.state_len()];
    encoding.decode_into(&q64, frame, targets, &mut out)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::recipe::Recipe;
    use mochi_sim::dataset::SpeedPlan;
    use nalgebra::{Rotation3, UnitQuaternion};

    /// A built scene and a short simulated trajectory of it.
    fn simulate(name: &str, frames: usize) -> (BuiltScene, Trajectory) {
        let mut problem = Recipe::load(name).unwrap().build().unwrap();
        let seq = problem.sequence(&SpeedPlan::constant(0.5), frames, 1);
        let traj = problem.run(&seq, &mochi_sim::Silent).unwrap();
        (problem, traj)
    }

    fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
        assert_eq!(a.len(), b.len());
        a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
    }

    /// Applies `x -> rotation x + shift` to every vertex of a flat state.
    fn moved(x: &[f64], dim: usize, rotation: &Matrix3<f64>, shift: Vector3<f64>) -> Vec<f64> {
        x.chunks_exact(dim)
            .flat_map(|p| {
                let y = rotation * pad(p) + shift;
                y.as_slice()[..dim].to_vec()
            })
            .collect()
    }

    /// Decoding inverts encoding: exactly for positions; for strand bends, which decode at
    /// rest length, exactly from the encoded side (`encode(decode(q)) = q`).
    fn round_trip_is_exact(enc: &Encoding, states: &[Vec<f64>]) {
        for x in states {
            let q = enc.encode_state(x).unwrap();
            assert_eq!(q.len(), enc.encoded_len());
            let back = enc.decode(&q, &enc.handle_targets(x).unwrap()).unwrap();
            if enc.strand_bends() {
                let again = enc.encode_state(&back).unwrap();
                assert!(
                    max_abs_diff(&again, &q) < 1e-12,
                    "bends round trip {}",
                    max_abs_diff(&again, &q)
                );
                continue;
            }
            assert!(
                max_abs_diff(&back, x) < 1e-12,
                "round trip error {}",
                max_abs_diff(&back, x)
            );
        }
    }

    #[test]
    fn encoding_round_trip_is_exact_on_simulated_beam_and_rods() {
        let (beam, traj) = simulate("beam", 10);
        let enc = Encoding::new(&beam, RodEncoding::Positions).unwrap();
        assert!(enc.rotates());
        assert_eq!(enc.origins(), &Origins::HandleCentroid);
        let clamp = beam.handles[0].vertices.len();
        assert_eq!(enc.encoded_len(), (beam.mesh.num_vertices() - clamp) * 3);
        round_trip_is_exact(&enc, &traj.positions);
        // At frame 0 the clamp is at its reference: R = I and q_v = x_v - (clamp centroid).
        let encoded = enc.encode_trajectory(&traj).unwrap();
        assert_eq!(encoded.len(), traj.num_frames());
        let c = centroid(&enc.handle_targets(&traj.positions[0]).unwrap(), 3);
        for (k, &v) in enc.free_vertices().iter().enumerate() {
            for i in 0..3 {
                assert!((encoded[0][k * 3 + i] - (traj.positions[0][v * 3 + i] - c[i])).abs() < 1e-15);
            }
        }

        let (rods, traj) = simulate("rods", 10);
        let enc = Encoding::from_parts(&rods.mesh, &rods.handles, false).unwrap();
        assert!(!enc.rotates());
        let Origins::StrandRoots { root_slots } = enc.origins() else {
            panic!("rods encode relative to their roots");
        };
        assert_eq!(root_slots.len(), 16);
        // Two prescribed vertices per strand, 28 encoded.
        assert_eq!(enc.encoded_len(), 16 * 28 * 3);
        round_trip_is_exact(&enc, &traj.positions);
        // The encoding is the offset from the strand root, exactly as the paper has it.
        let Elements::Rods(strands) = &rods.mesh.elements else {
            unreachable!()
        };
        let x = traj.positions.last().unwrap();
        let q = enc.encode_state(x).unwrap();
        let (root, tip) = (strands[3][0], *strands[3].last().unwrap());
        let k = enc.free_vertices().iter().position(|&v| v == tip).unwrap();
        for i in 0..3 {
            assert_eq!(q[k * 3 + i], x[tip * 3 + i] - x[root * 3 + i]);
        }
        // The root moved, so a root-relative code differs from the raw position.
        assert!((x[root * 3] - rods.mesh.rest[root * 3]).abs() > 1e-3);
    }

    #[test]
    fn encoding_ignores_rigid_motion_of_state_and_handles_together() {
        let (beam, traj) = simulate("beam", 8);
        encoding_ignores_rigid_motion(&Encoding::new(&beam, RodEncoding::Positions).unwrap(), &traj.positions);
        // Rods with their roots' rotation removed as well.
        let (rods, traj) = simulate("rods", 4);
        let enc = Encoding::from_parts(&rods.mesh, &rods.handles, true).unwrap();
        encoding_ignores_rigid_motion(&enc, &traj.positions[traj.positions.len() - 1..]);
        round_trip_is_exact(&enc, &traj.positions);
    }

    /// Asserts that moving each 3D state rigidly (handles included) leaves its encoding unchanged.
    fn encoding_ignores_rigid_motion(enc: &Encoding, states: &[Vec<f64>]) {
        let rotation = *Rotation3::from_scaled_axis(Vector3::new(0.3, -1.1, 0.7)).matrix();
        let shift = Vector3::new(0.4, -2.0, 1.5);
        for x in states {
            let q = enc.encode_state(x).unwrap();
            let q_moved = enc.encode_state(&moved(x, 3, &rotation, shift)).unwrap();
            assert!(max_abs_diff(&q, &q_moved) < 1e-12, "{}", max_abs_diff(&q, &q_moved));
        }
    }

    /// The rods scene's encoding by strand bends, with or without the roots' rotation removed.
    fn rod_bends(rods: &BuiltScene, rotates: bool) -> Encoding {
        Encoding::from_parts(&rods.mesh, &rods.handles, rotates)
            .unwrap()
            .with_strand_bends(&rods.mesh)
            .unwrap()
    }

    /// Rest length of every rod edge, and the same edges' lengths in `x`.
    fn edge_lengths(mesh: &Mesh, x: &[f64]) -> Vec<(f64, f64)> {
        let Elements::Rods(strands) = &mesh.elements else {
            unreachable!()
        };
        let length = |p: &[f64], a: usize, b: usize| (pad(&p[b * 3..b * 3 + 3]) - pad(&p[a * 3..a * 3 + 3])).norm();
        strands
            .iter()
            .flat_map(|s| s.windows(2))
            .map(|e| (length(&mesh.rest, e[0], e[1]), length(x, e[0], e[1])))
            .collect()
    }

    #[test]
    fn strand_bends_decode_at_rest_length_and_track_simulated_rods() {
        let (rods, traj) = simulate("rods", 20);
        let bends = Recipe::load("rods").unwrap().latent.rods;
        assert_eq!(bends, RodEncoding::Bends);
        let enc = Encoding::new(&rods, bends).unwrap();
        assert!(enc.strand_bends());
        assert_eq!(enc.values_per_vertex(), 2);
        assert_eq!(enc.encoded_len(), 16 * 28 * 2);
        let length = 0.3;
        for x in &traj.positions {
            let targets = enc.handle_targets(x).unwrap();
            let back = enc.decode(&enc.encode_state(x).unwrap(), &targets).unwrap();
            for (rest, decoded) in edge_lengths(&rods.mesh, &back) {
                assert!((rest - decoded).abs() < 1e-12 * length, "{rest} {decoded}");
            }
            // The simulated rods stretch by a strain of about 1e-4, all the difference there is.
            let strain = edge_lengths(&rods.mesh, x)
                .iter()
                .map(|(r, l)| (l / r - 1.0).abs())
                .fold(0.0, f64::max);
            assert!(strain < 1e-2, "strain {strain}");
            assert!(
                max_abs_diff(&back, x) <= 2.0 * strain * length + 1e-12,
                "{} {strain}",
                max_abs_diff(&back, x)
            );
        }
        round_trip_is_exact(&enc, &traj.positions);
        // Any encoded vector is a valid state; its encoding is itself.
        let targets = enc.handle_targets(&traj.positions[7]).unwrap();
        let q: Vec<f64> = (0..enc.encoded_len())
            .map(|i| 0.004 * (i as f64 * 0.61).sin())
            .collect();
        let x = enc.decode(&q, &targets).unwrap();
        assert!(max_abs_diff(&enc.encode_state(&x).unwrap(), &q) < 1e-12);
        // A bend that folds an edge far back still round-trips.
        let mut folded = q.clone();
        folded[2 * 5] = 0.09;
        let x = enc.decode(&folded, &targets).unwrap();
        assert!(max_abs_diff(&enc.encode_state(&x).unwrap(), &folded) < 1e-10);
    }

    #[test]
    fn strand_bends_ignore_rigid_motion_of_state_and_handles_together() {
        let (rods, traj) = simulate("rods", 6);
        encoding_ignores_rigid_motion(&rod_bends(&rods, true), &traj.positions);
    }

    #[test]
    fn strand_bends_gradient_matches_finite_differences() {
        let (rods, traj) = simulate("rods", 6);
        for rotates in [false, true] {
            let enc = rod_bends(&rods, rotates);
            let x0 = traj.positions.last().unwrap();
            let targets = enc.handle_targets(x0).unwrap();
            let frame = enc.frame(&targets).unwrap();
            let q = enc.encode(x0, &frame).unwrap();
            // E(x) = sum c_i x_i + 0.5 |x - x0|^2 * 40: linear and curved parts.
            let c: Vec<f64> = (0..x0.len()).map(|i| (i as f64 * 1.7).cos()).collect();
            let energy = |q: &[f64]| -> f64 {
                let x = enc.decode(q, &targets).unwrap();
                x.iter()
                    .zip(&c)
                    .zip(x0)
                    .map(|((x, c), r)| c * x + 20.0 * (x - r).powi(2))
                    .sum()
            };
            let mut q = q;
            for (i, v) in q.iter_mut().enumerate() {
                *v += 0.01 * (i as f64 * 0.3).sin();
            }
            let x = enc.decode(&q, &targets).unwrap();
            let grad: Vec<f64> = x.iter().zip(&c).zip(x0).map(|((x, c), r)| c + 40.0 * (x - r)).collect();
            let mut analytic = vec![0.0; enc.encoded_len()];
            enc.encode_gradient(&q, &grad, &frame, 2.0, &mut analytic).unwrap();
            let h = 1e-6;
            for i in (0..q.len()).step_by(7) {
                let mut shifted = q.clone();
                shifted[i] += h;
                let plus = energy(&shifted);
                shifted[i] -= 2.0 * h;
                let minus = energy(&shifted);
                let numeric = (plus - minus) / (2.0 * h) / 2.0;
                assert!(
                    (numeric - analytic[i]).abs() <= 1e-6 * (1.0 + numeric.abs()),
                    "rotates {rotates}, coordinate {i}: {numeric} vs {}",
                    analytic[i]
                );
            }
        }
    }

    #[test]
    fn strand_bends_refuse_what_they_cannot_encode() {
        let beam = Recipe::load("beam").unwrap().build().unwrap();
        let enc = Encoding::from_parts(&beam.mesh, &beam.handles, false).unwrap();
        let err = enc.with_strand_bends(&beam.mesh).unwrap_err().to_string();
        assert!(err.contains("rods mesh"), "{err}");
        // Only the roots prescribed: the first free edge would have no parent edge.
        let rods = Recipe::load("rods").unwrap().build().unwrap();
        let Elements::Rods(strands) = &rods.mesh.elements else {
            unreachable!()
        };
        let mut handles = rods.handles.clone();
        let roots: Vec<usize> = strands.iter().map(|s| s[0]).collect();
        handles[0].reference = roots
            .iter()
            .map(|&v| [0, 1, 2].map(|c| rods.mesh.rest[v * 3 + c]))
            .collect();
        handles[0].vertices = roots;
        let enc = Encoding::from_parts(&rods.mesh, &handles, false).unwrap();
        let err = enc.with_strand_bends(&rods.mesh).unwrap_err().to_string();
        assert!(
            err.contains("strand 0 does not start with two prescribed vertices"),
            "{err}"
        );
    }

    /// States of a scene with its handles at the targets of a sampled sequence and the
    /// other vertices displaced from rest by a smooth pattern (no simulation).
    fn displaced_states(problem: &BuiltScene, frames: usize) -> Vec<Vec<f64>> {
        let dim = problem.mesh.dim;
        let seq = problem.sequence(&SpeedPlan::constant(1.0), frames, 2);
        (0..=frames)
            .map(|f| {
                let mut x: Vec<f64> = (problem.mesh.rest.iter().enumerate())
                    .map(|(i, r)| r + 0.01 * (i as f64 * 0.37 + f as f64).sin())
                    .collect();
                let targets = seq.targets(&problem.handles, f, dim);
                let fixed = problem.handles.iter().flat_map(|h| &h.vertices);
                for (slot, &v) in fixed.enumerate() {
                    x[v * dim..(v + 1) * dim].copy_from_slice(&targets[slot * dim..(slot + 1) * dim]);
                }
                x
            })
            .collect()
    }

    #[test]
    fn encoding_ignores_translation_in_every_scene() {
        for name in crate::learn::recipe::shipped_scene_names() {
            let problem = Recipe::load(&name).unwrap().build().unwrap();
            // 3D scenes use simulated states. 2D ones use displaced states: in debug builds
            // `energy::value` trips a debug assertion on 2D elements (it passes all
            // MAX_DOF gathered values to `eval`), and `BuiltScene::run` calls it.
            let states = if problem.mesh.dim == 3 {
                simulate(&name, 2).1.positions
            } else {
                displaced_states(&problem, 5)
            };
            let enc = Encoding::new(&problem, RodEncoding::Positions).unwrap();
            let dim = enc.dim();
            let shift = Vector3::new(0.7, -0.3, if dim == 3 { 1.9 } else { 0.0 });
            for x in &states {
                let q = enc.encode_state(x).unwrap();
                let q_moved = enc.encode_state(&moved(x, dim, &Matrix3::identity(), shift)).unwrap();
                assert!(
                    max_abs_diff(&q, &q_moved) < 1e-12,
                    "{name}: {}",
                    max_abs_diff(&q, &q_moved)
                );
            }
            round_trip_is_exact(&enc, &states);
        }
    }

    #[test]
    fn encoding_kabsch_recovers_a_known_rotation() {
        let points: Vec<f64> = (0..7)
            .flat_map(|i| {
                let t = i as f64;
                [t.sin(), (1.3 * t).cos() * 2.0, 0.5 * t - 1.0]
            })
            .collect();
        let rotation = *UnitQuaternion::from_scaled_axis(Vector3::new(-0.4, 2.2, 0.9))
            .to_rotation_matrix()
            .matrix();
        let current = moved(&points, 3, &rotation, Vector3::new(3.0, 1.0, -2.0));
        let fit = best_fit_rotation(&points, &current, 3).unwrap();
        assert!((fit - rotation).abs().max() < 1e-12, "{fit} vs {rotation}");
        assert!((fit.determinant() - 1.0).abs() < 1e-12);

        // Coplanar points (a clamped face) still fix a proper rotation.
        let planar: Vec<f64> = (0..9).flat_map(|i| [0.0, (i % 3) as f64, (i / 3) as f64]).collect();
        let current = moved(&planar, 3, &rotation, Vector3::zeros());
        let fit = best_fit_rotation(&planar, &current, 3).unwrap();
        assert!((fit - rotation).abs().max() < 1e-12);

        // 2D: a rotation by 2 rad about z.
        let flat: Vec<f64> = vec![0.0, 0.0, 1.0, 0.0, 0.3, 0.8];
        let r2 = *Rotation3::from_axis_angle(&Vector3::z_axis(), 2.0).matrix();
        let current = moved(&flat, 2, &r2, Vector3::new(1.0, -1.0, 0.0));
        let fit = best_fit_rotation(&flat, &current, 2).unwrap();
        assert!((fit - r2).abs().max() < 1e-12, "{fit}");
    }

    fn is_length<T>(result: Result<T, EncodingError>) -> bool {
        matches!(result, Err(EncodingError::Length { .. }))
    }

    #[test]
    fn encoding_bad_input_is_an_error() {
        let problem = Recipe::load("beam").unwrap().build().unwrap();
        let enc = Encoding::new(&problem, RodEncoding::Positions).unwrap();
        let x = problem.mesh.rest.clone();
        let targets = enc.handle_targets(&x).unwrap();
        let frame = enc.frame(&targets).unwrap();
        assert!(is_length(enc.encode(&x[1..], &frame)));
        assert!(is_length(enc.encode_state(&x[..6])));
        assert!(is_length(enc.frame(&targets[1..])));
        let q = enc.encode(&x, &frame).unwrap();
        let mut out = vec![0.0; x.len()];
        assert!(is_length(enc.decode_into(&q[1..], &frame, &targets, &mut out)));
        assert!(is_length(enc.decode_into(&q, &frame, &targets[3..], &mut out)));
        assert!(is_length(enc.decode_into(&q, &frame, &targets, &mut out[1..])));
        let mut no_origin = frame.clone();
        no_origin.origins.clear();
        assert!(is_length(enc.decode_into(&q, &no_origin, &targets, &mut out)));
        assert!(is_length(best_fit_rotation(&[0.0; 6], &[0.0; 3], 3)));
        assert!(is_length(best_fit_rotation(&[0.0; 4], &[0.0; 4], 3)));
        let mut traj = Trajectory {
            scene: "beam".into(),
            dt: 0.1,
            dim: 2,
            positions: vec![x.clone()],
            bc_signal: vec![vec![]],
            energy_names: vec![],
            energies: vec![vec![]],
            newton_iterations: vec![0],
            step_seconds: vec![0.0],
            meta: vec![],
        };
        assert!(is_length(enc.encode_trajectory(&traj)));
        traj.dim = 3;
        traj.positions.push(x[3..].to_vec());
        assert!(is_length(enc.encode_trajectory(&traj)));

        // The cloth's two corners cannot fix a rotation.
        let cloth = Recipe::load("cloth").unwrap().build().unwrap();
        assert!(!Encoding::new(&cloth, RodEncoding::Positions).unwrap().rotates());
        assert_eq!(
            Encoding::from_parts(&cloth.mesh, &cloth.handles, true),
            Err(EncodingError::DegenerateHandles { count: 2, span: 1 })
        );
        // Handles that do not fit the mesh.
        let mut handles = problem.handles.clone();
        handles[0].vertices[0] = problem.mesh.num_vertices();
        assert!(matches!(
            Encoding::from_parts(&problem.mesh, &handles, true),
            Err(EncodingError::BadHandle { .. })
        ));
        let mut handles = problem.handles.clone();
        handles.push(handles[0].clone());
        assert!(matches!(
            Encoding::from_parts(&problem.mesh, &handles, false),
            Err(EncodingError::BadHandle { .. })
        ));
        let mut handles = problem.handles.clone();
        handles[0].reference.pop();
        assert!(matches!(
            Encoding::from_parts(&problem.mesh, &handles, false),
            Err(EncodingError::BadHandle { .. })
        ));
    }

    #[test]
    fn encoding_without_handles_is_the_identity() {
        let problem = Recipe::load("beam").unwrap().build().unwrap();
        let enc = Encoding::from_parts(&problem.mesh, &[], false).unwrap();
        assert_eq!(enc.encoded_len(), problem.mesh.rest.len());
        let q = enc.encode_state(&problem.mesh.rest).unwrap();
        assert_eq!(q, problem.mesh.rest);
        assert_eq!(enc.decode(&q, &[]).unwrap(), problem.mesh.rest);
    }
}
