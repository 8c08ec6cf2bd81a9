//! The [`Encoding`] of a body: built from its mesh and handles, it encodes full-space states
//! relative to their boundary conditions and decodes them back.

use nalgebra::{Matrix3, Vector3};

use crate::learn::recipe::RodEncoding;
use mochi_sim::bc::Handle;
use mochi_sim::error::InputError;
use mochi_sim::mesh::{Elements, Mesh};
use mochi_sim::scene::BuiltScene;
use mochi_sim::trajectory::Trajectory;

use super::error::{check_len, EncodingError};
use super::frame::{best_fit_rotation, centroid, check_spread, handles_rotate, pad, Frame, Origins};
use super::strands::{cayley, cayley_vjp, normal_to, strand_roots, walk_chain, Chain, ChainStart};

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

    /// This encoding with rod strands encoded by their positions (root-relative, as
    /// [`Encoding::from_parts`] makes it).
    pub fn without_strand_bends(&self) -> Encoding {
        Encoding {
            chains: Vec::new(),
            ..self.clone()
        }
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
    pub fn encode(&self, x: &[f64], frame: &Frame) -> Result<Vec<f64>, EncodingError> {
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

/// `[z_{t-1}, z_{t-2}, p_t, p_{t-1}, p_{t-2}]` from the three signals, then the collider
/// slots' inputs `colliders` (`collider_inputs`; empty for a model without them), then the
/// frame time `dt` (seconds) for an integrator that takes it as an input
/// (`mochi_runtime::Model::timed`): the one owner of the integrator's input layout on the
/// trainer's side (the runtime's `Instance::step_with` packs the same).
pub(crate) fn pack_signals(
    z_prev: &[f32],
    z_prev2: &[f32],
    signals: [&[f64]; 3],
    colliders: &[f32],
    dt: Option<f64>,
) -> Vec<f32> {
    let mut row: Vec<f32> = z_prev.iter().chain(z_prev2).copied().collect();
    for p in signals {
        row.extend(p.iter().map(|&v| v as f32));
    }
    row.extend_from_slice(colliders);
    row.extend(dt.map(|dt| dt as f32));
    row
}

/// The world-space state of an encoded vector `q` (f32, as decoded) in `frame`.
pub fn decode_world(encoding: &Encoding, q: &[f32], frame: &Frame, targets: &[f64]) -> Result<Vec<f64>, EncodingError> {
    let q64: Vec<f64> = q.iter().map(|&v| v as f64).collect();
    let mut out = vec![0.0; encoding.state_len()];
    encoding.decode_into(&q64, frame, targets, &mut out)?;
    Ok(out)
}
