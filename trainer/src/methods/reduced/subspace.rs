//! The subspace map of the reduced solver: a decoder `D: z -> q` followed by the scene's
//! boundary-condition frame, `x_v = R q_v + o_v` for the encoded (free) vertices and the
//! handle targets for the prescribed ones (the same map as
//! [`Encoding::decode_into`](crate::learn::encoding::Encoding::decode_into)).
//!
//! The decoder is a trained network or a PCA's linear map ([`SubspaceDecoder`]). The map's
//! Jacobian `dx/dz` is exact: forward mode through the decoder, then the rotation `R`. Prescribed vertices do not depend on `z`; their rows are zero. A gradient
//! `(dx/dz)^T g` needs no Jacobian: `R^T g`, then reverse mode through the decoder. The map's
//! second derivatives enter only contracted with a world-space vector `g` (the exact reduced
//! Hessian's term `sum_i g_i d^2 x_i / dz^2`): since the frame is affine in `q`, that is the
//! decoder's own contracted Hessian with the pulled-back weights `R^T g`.

use nalgebra::{Matrix3, Vector3};

use super::decoder_map::DecoderMap;
pub use super::decoder_map::SubspaceDecoder;
use crate::error::{TrainerError, TrainerResult};
use crate::learn::encoding::{Encoding, Frame};
use crate::learn::network::ModelResult;

/// A decoder in a scene's boundary-condition frame, with the buffers its derivatives need.
#[derive(Clone)]
pub struct DecoderSubspace {
    map: DecoderMap,
    dim: usize,
    state_len: usize,
    /// Per encoded vertex `k`: its global vertex and the index of its origin.
    free: Vec<(usize, usize)>,
    handle_vertices: Vec<usize>,
    rotation: Matrix3<f64>,
    origins: Vec<Vector3<f64>>,
    targets: Vec<f64>,
    q: Vec<f64>,
    jq: Vec<f64>,
    w: Vec<f64>,
    /// The latent of the last [`DecoderSubspace::positions`], and whether the decoder's
    /// workspace still holds its hidden pass (a gradient there reuses it).
    decoded_at: Vec<f64>,
    decoded_fresh: bool,
}

impl DecoderSubspace {
    /// The map of `decoder` (latent -> encoded state of `encoding`), with the handles at
    /// `targets` (`dim` per prescribed vertex) until [`DecoderSubspace::set_frame`] moves them.
    pub fn new<'d>(
        decoder: impl Into<SubspaceDecoder<'d>>,
        encoding: &Encoding,
        targets: &[f64],
    ) -> TrainerResult<Self> {
        if encoding.strand_bends() {
            return Err(TrainerError::invalid(
                "the reduced solver needs positions encoded as points; this scene encodes rod strands by their bends \
                 (`latent.rods = \"bends\"`)",
            ));
        }
        let map = DecoderMap::new(decoder.into());
        if map.output_len() != encoding.encoded_len() {
            return Err(TrainerError::invalid(format!(
                "the decoder gives {} values per state, the scene's encoding has {}",
                map.output_len(),
                encoding.encoded_len()
            )));
        }
        let r = map.input_len();
        let n = encoding.encoded_len();
        let mut subspace = DecoderSubspace {
            dim: encoding.dim(),
            state_len: encoding.state_len(),
            free: encoding
                .free_vertices()
                .iter()
                .copied()
                .zip(encoding.origin_of().iter().copied())
                .collect(),
            handle_vertices: encoding.handle_vertices().to_vec(),
            rotation: Matrix3::identity(),
            origins: Vec::new(),
            targets: Vec::new(),
            q: vec![0.0; n],
            jq: vec![0.0; n * r],
            w: vec![0.0; n],
            decoded_at: vec![0.0; r],
            decoded_fresh: false,
            map,
        };
        subspace.set_frame(&encoding.frame(targets)?, targets);
        Ok(subspace)
    }

    /// Latent size `r`.
    pub fn latent_len(&self) -> usize {
        self.map.input_len()
    }

    /// Length of a world state (`dim` per vertex).
    pub fn state_len(&self) -> usize {
        self.state_len
    }

    /// Coordinates per vertex.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Places the handles at `targets` (`dim` per prescribed vertex) in `frame`, which must
    /// be `encoding.frame(targets)` for the encoding this map was built with.
    pub fn set_frame(&mut self, frame: &Frame, targets: &[f64]) {
        self.rotation = frame.rotation;
        self.origins.clone_from(&frame.origins);
        self.targets.clear();
        self.targets.extend_from_slice(targets);
    }

    /// `x = f(z)`, the world state (`state_len` values).
    pub fn positions(&mut self, z: &[f64], x: &mut [f64]) -> TrainerResult<()> {
        self.check_len("state", self.state_len, x.len())?;
        self.forget_decoded();
        self.map.value(z, &mut self.q)?;
        self.decoded_at.clear();
        self.decoded_at.extend_from_slice(z);
        self.decoded_fresh = true;
        self.place(x);
        Ok(())
    }

    /// `x = f(z)` and the Jacobian `dx/dz` (`state_len x r`, row-major; zero rows for
    /// prescribed vertices).
    pub fn positions_and_jacobian(&mut self, z: &[f64], x: &mut [f64], jac: &mut [f64]) -> TrainerResult<()> {
        let r = self.latent_len();
        self.check_len("state", self.state_len, x.len())?;
        self.check_len("Jacobian", self.state_len * r, jac.len())?;
        self.forget_decoded();
        self.map.jacobian(z, &mut self.q, &mut self.jq)?;
        self.place(x);
        let d = self.dim;
        for &v in &self.handle_vertices {
            jac[v * d * r..(v + 1) * d * r].fill(0.0);
        }
        for (k, &(v, _)) in self.free.iter().enumerate() {
            let src = &self.jq[k * d * r..(k + 1) * d * r];
            for i in 0..d {
                let row = &mut jac[(v * d + i) * r..(v * d + i + 1) * r];
                row.fill(0.0);
                for c in 0..d {
                    let rot = self.rotation[(i, c)];
                    if rot != 0.0 {
                        row.iter_mut()
                            .zip(&src[c * r..(c + 1) * r])
                            .for_each(|(o, s)| *o += rot * s);
                    }
                }
            }
        }
        Ok(())
    }

    /// `(dx/dz)^T g` (`r` values) at `z` for a world-space vector `g` (`state_len` values):
    /// the reduced gradient when `g = dE/dx`, by reverse mode through the decoder (prescribed
    /// vertices do not depend on `z`). Right after [`DecoderSubspace::positions`] at the same
    /// `z` (as an objective's gradient call comes), the decoder's hidden pass is not repeated.
    pub fn gradient(&mut self, z: &[f64], g: &[f64], out: &mut [f64]) -> TrainerResult<()> {
        let after_value = self.decoded_fresh && self.decoded_at == z;
        if !after_value {
            self.forget_decoded();
        }
        self.with_pulled_back(g, |map, w| map.pulled_back(z, w, out, after_value))
    }

    /// `sum_i g_i d^2 x_i / dz^2` (`r x r`, row-major) at `z` for a world-space vector `g`
    /// (`state_len` values): the second-order term of the exact reduced Hessian.
    pub fn contracted_hessian(&mut self, z: &[f64], g: &[f64], out: &mut [f64]) -> TrainerResult<()> {
        self.forget_decoded();
        self.with_pulled_back(g, |map, w| map.contracted_hessian(z, w, out))
    }

    /// Calls `decoder_call` with the decoder, `g` pulled back to the encoded layout (the
    /// decoder's output weights).
    fn with_pulled_back(
        &mut self,
        g: &[f64],
        decoder_call: impl FnOnce(&mut DecoderMap, &[f64]) -> ModelResult<()>,
    ) -> TrainerResult<()> {
        let mut w = std::mem::take(&mut self.w);
        let pulled = self.pull_back(g, &mut w);
        let result = pulled.and_then(|()| Ok(decoder_call(&mut self.map, &w)?));
        self.w = w;
        result
    }

    /// `d^2/dt^2 f(z + t v)` at `t = 0` (`state_len` values; zero for prescribed vertices).
    pub fn second_directional(&mut self, z: &[f64], v: &[f64], out: &mut [f64]) -> TrainerResult<()> {
        self.check_len("state", self.state_len, out.len())?;
        self.forget_decoded();
        self.map.second_directional(z, v, &mut self.w)?;
        let d = self.dim;
        for &h in &self.handle_vertices {
            out[h * d..(h + 1) * d].fill(0.0);
        }
        for (k, &(vertex, _)) in self.free.iter().enumerate() {
            let mut local = Vector3::zeros();
            local.as_mut_slice()[..d].copy_from_slice(&self.w[k * d..(k + 1) * d]);
            let world = self.rotation * local;
            out[vertex * d..(vertex + 1) * d].copy_from_slice(&world.as_slice()[..d]);
        }
        Ok(())
    }

    /// Pulls a world-space vector `g` back to the encoded layout: `R^T g_v` for each encoded
    /// vertex `v`, in encoding order (`out` has the decoder's output length).
    pub fn pull_back(&self, g: &[f64], out: &mut [f64]) -> TrainerResult<()> {
        self.check_len("world vector", self.state_len, g.len())?;
        self.check_len("encoded vector", self.free.len() * self.dim, out.len())?;
        let d = self.dim;
        let rt = self.rotation.transpose();
        for (k, &(v, _)) in self.free.iter().enumerate() {
            let mut gv = Vector3::zeros();
            gv.as_mut_slice()[..d].copy_from_slice(&g[v * d..(v + 1) * d]);
            let pulled = rt * gv;
            out[k * d..(k + 1) * d].copy_from_slice(&pulled.as_slice()[..d]);
        }
        Ok(())
    }

    /// Marks the decoder's workspace as no longer holding the hidden pass of the last
    /// [`DecoderSubspace::positions`] (every other decoder call overwrites it).
    fn forget_decoded(&mut self) {
        self.decoded_fresh = false;
    }

    /// Writes the world state of the encoded state in `self.q`.
    fn place(&self, x: &mut [f64]) {
        let d = self.dim;
        for (k, &(v, o)) in self.free.iter().enumerate() {
            let mut local = Vector3::zeros();
            local.as_mut_slice()[..d].copy_from_slice(&self.q[k * d..(k + 1) * d]);
            let world = self.rotation * local + self.origins[o];
            x[v * d..(v + 1) * d].copy_from_slice(&world.as_slice()[..d]);
        }
        for (slot, &v) in self.handle_vertices.iter().enumerate() {
            x[v * d..(v + 1) * d].copy_from_slice(&self.targets[slot * d..(slot + 1) * d]);
        }
    }

    fn check_len(&self, what: &str, expected: usize, got: usize) -> TrainerResult<()> {
        if expected != got {
            return Err(TrainerError::invalid(format!(
                "reduced solver: the {what} has {got} values, the subspace needs {expected}"
            )));
        }
        Ok(())
    }
}
