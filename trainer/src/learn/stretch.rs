//! Edge stretch of decoded states: a term of the autoencoder's loss that asks decoded states
//! to keep the edge lengths of the states they encode.
//!
//! Reconstruction errors of a few tenths of a percent of the diagonal are small as positions
//! but not as strains: on a stiff sheet they can multiply the membrane energy of a decoded
//! state several times over (docs/notes/2026-11-24-edge-stretch-autoencoder.md, the `one_step` diagnostic), and the
//! physics loss of the integrator then favours states that relieve a stretch the real sheet
//! never had. This term measures, per edge `(i, j)` with rest length `L`,
//! `s = (|x̂_i - x̂_j|^2 - |x_i - x_j|^2) / (2 L)`, the first-order change of the edge's
//! length in length units, and the penalty is the mean of `s^2` over the batch and the edges.
//! Edge lengths of a triangle fix its metric, so on cloth a decoding with no edge stretch has
//! the truth's in-plane strain. It is geometry, not an energy: the energies themselves are
//! defined once, in [`mochi_sim::energy`].
//!
//! Encoded positions are `R^T (x - o)` per vertex ([`Encoding::encode`]), a rigid map, so
//! edge lengths are the same in encoded and world coordinates; edges to prescribed vertices
//! (not encoded) are left out.

use candle_core::{DType, Device, Tensor};

use crate::learn::encoding::Encoding;
use mochi_sim::mesh::Mesh;

/// Why the edge stretch of a mesh cannot be measured.
#[derive(Debug, thiserror::Error)]
pub enum StretchError {
    /// The encoding or the mesh has nothing to measure (the message says why).
    #[error("{0}")]
    Unusable(String),
    /// candle failed.
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
}

/// The edges between encoded vertices and their rest lengths, ready for candle.
#[derive(Debug, Clone)]
pub struct EdgeStretch {
    /// Values per vertex in the encoded vector.
    dim: usize,
    /// Encoded vertices.
    vertices: usize,
    /// Slot of each edge's first and second vertex in the encoded vector, `(edges,)` `u32`.
    first: Tensor,
    second: Tensor,
    /// `1 / (2 L)` per edge, `(1, edges)`.
    inv_two_rest: Tensor,
}

impl EdgeStretch {
    /// The edges of `mesh` whose vertices are both encoded by `encoding`. Fails when the
    /// encoding stores something other than positions (strand bends), or no edge joins two
    /// encoded vertices.
    pub fn new(mesh: &Mesh, encoding: &Encoding) -> Result<EdgeStretch, StretchError> {
        if encoding.strand_bends() {
            return Err(StretchError::Unusable(
                "edge stretch needs encoded positions; strand bends cannot stretch".into(),
            ));
        }
        let dim = encoding.dim();
        let mut slot = vec![None; mesh.num_vertices()];
        for (s, &v) in encoding.free_vertices().iter().enumerate() {
            slot[v] = Some(s as u32);
        }
        let (mut first, mut second, mut inv) = (Vec::new(), Vec::new(), Vec::new());
        for [a, b] in mesh.edges() {
            let (Some(sa), Some(sb)) = (slot[a], slot[b]) else {
                continue;
            };
            let rest: f64 = (0..dim)
                .map(|c| (mesh.rest[a * dim + c] - mesh.rest[b * dim + c]).powi(2))
                .sum::<f64>()
                .sqrt();
            if rest <= 0.0 {
                return Err(StretchError::Unusable(format!("edge ({a}, {b}) has zero rest length")));
            }
            first.push(sa);
            second.push(sb);
            inv.push((0.5 / rest) as f32);
        }
        if first.is_empty() {
            return Err(StretchError::Unusable("no edge joins two encoded vertices".into()));
        }
        let edges = first.len();
        Ok(EdgeStretch {
            dim,
            vertices: encoding.free_vertices().len(),
            first: Tensor::from_vec(first, edges, &Device::Cpu)?,
            second: Tensor::from_vec(second, edges, &Device::Cpu)?,
            inv_two_rest: Tensor::from_vec(inv, (1, edges), &Device::Cpu)?,
        })
    }

    /// Number of edges measured.
    #[cfg(test)]
    pub fn num_edges(&self) -> usize {
        self.first.dims1().unwrap_or(0)
    }

    /// Per sample and edge, `s = (|x̂_i - x̂_j|^2 - |x_i - x_j|^2) / (2 L)` of encoded states
    /// `decoded` against `truth` (both `(batch, encoded_len)`): `(batch, edges)`. Gradients
    /// flow through `decoded` only.
    pub fn stretch(&self, decoded: &Tensor, truth: &Tensor) -> candle_core::Result<Tensor> {
        let squared = self.squared_lengths(decoded)? - self.squared_lengths(&truth.detach())?;
        squared?.broadcast_mul(&self.inv_two_rest)
    }

    /// The loss term: the mean of `s^2` over the batch and the edges.
    pub fn penalty(&self, decoded: &Tensor, truth: &Tensor) -> candle_core::Result<Tensor> {
        self.stretch(decoded, truth)?.sqr()?.mean_all()
    }

    fn squared_lengths(&self, states: &Tensor) -> candle_core::Result<Tensor> {
        let batch = states.dim(0)?;
        let vertices = states.to_dtype(DType::F32)?.reshape((batch, self.vertices, self.dim))?;
        let a = vertices.index_select(&self.first, 1)?;
        let b = vertices.index_select(&self.second, 1)?;
        (a - b)?.sqr()?.sum(2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mochi_sim::bc::Handle;
    use mochi_sim::mesh::procedural::cloth_grid;
    use nalgebra::{Rotation3, Vector3};

    /// A handle holding `vertices` of `mesh` (3D) where they rest.
    fn pin(mesh: &Mesh, vertices: &[usize]) -> Handle {
        let at = |v: usize| [mesh.rest[v * 3], mesh.rest[v * 3 + 1], mesh.rest[v * 3 + 2]];
        Handle {
            name: "pin".into(),
            vertices: vertices.to_vec(),
            reference: vertices.iter().map(|&v| at(v)).collect(),
            pivot: at(vertices[0]),
        }
    }

    /// A 4 x 4 cloth with its first vertex pinned, and its encoding.
    fn sheet() -> (Mesh, Encoding) {
        let mesh = cloth_grid([1.0, 1.0], [4, 4], [0.0; 3], ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0])).unwrap();
        let encoding = Encoding::from_parts(&mesh, &[pin(&mesh, &[0])], false).unwrap();
        (mesh, encoding)
    }

    fn encoded(encoding: &Encoding, x: &[f64]) -> Tensor {
        let q: Vec<f32> = encoding.encode_state(x).unwrap().iter().map(|&v| v as f32).collect();
        let n = q.len();
        Tensor::from_vec(q, (1, n), &Device::Cpu).unwrap()
    }

    #[test]
    fn edges_to_prescribed_vertices_are_left_out() {
        let (mesh, encoding) = sheet();
        // Vertex 0 of the grid has three edges (along both sides and a diagonal).
        assert_eq!(EdgeStretch::new(&mesh, &encoding).unwrap().num_edges(), 33 - 3);
    }

    #[test]
    fn rigid_motions_do_not_stretch_and_uniform_scaling_does() {
        let (mesh, encoding) = sheet();
        let stretch = EdgeStretch::new(&mesh, &encoding).unwrap();
        let truth = encoded(&encoding, &mesh.rest);
        let rotation = Rotation3::from_axis_angle(&Vector3::x_axis(), 0.7);
        let moved: Vec<f64> = mesh
            .rest
            .chunks(3)
            .flat_map(|p| {
                let v = rotation * Vector3::new(p[0], p[1], p[2]) + Vector3::new(0.3, -1.0, 2.0);
                [v.x, v.y, v.z]
            })
            .collect();
        let rigid = stretch.penalty(&encoded(&encoding, &moved), &truth).unwrap();
        assert!(rigid.to_scalar::<f32>().unwrap() < 1e-12);
        // Scaling every length by (1 + e) changes an edge of rest length L by
        // ((1 + e)^2 - 1) L / 2 in this measure.
        let e = 0.01;
        let scaled: Vec<f64> = mesh.rest.iter().map(|v| v * (1.0 + e)).collect();
        let s = stretch.stretch(&encoded(&encoding, &scaled), &truth).unwrap();
        let s: Vec<f32> = s.flatten_all().unwrap().to_vec1().unwrap();
        let mut lengths: Vec<f64> = Vec::new();
        for [a, b] in mesh.edges().into_iter().filter(|&[a, _]| a != 0) {
            let d: f64 = (0..3)
                .map(|c| (mesh.rest[a * 3 + c] - mesh.rest[b * 3 + c]).powi(2))
                .sum();
            lengths.push(d.sqrt());
        }
        assert_eq!(s.len(), lengths.len());
        for (got, l) in s.iter().zip(&lengths) {
            let want = ((1.0 + e).powi(2) - 1.0) * l / 2.0;
            assert!((*got as f64 - want).abs() < 1e-6 * l.max(1.0), "{got} vs {want}");
        }
    }

    #[test]
    fn the_gradient_moves_only_the_decoded_state() {
        let (mesh, encoding) = sheet();
        let stretch = EdgeStretch::new(&mesh, &encoding).unwrap();
        let truth = encoded(&encoding, &mesh.rest);
        let pulled: Vec<f64> = mesh
            .rest
            .iter()
            .enumerate()
            .map(|(i, v)| if i == 15 { v + 0.1 } else { *v })
            .collect();
        let decoded = candle_core::Var::from_tensor(&encoded(&encoding, &pulled)).unwrap();
        let penalty = stretch.penalty(decoded.as_tensor(), &truth).unwrap();
        let grads = penalty.backward().unwrap();
        let g: Vec<f32> = grads
            .get(decoded.as_tensor())
            .unwrap()
            .flatten_all()
            .unwrap()
            .to_vec1()
            .unwrap();
        // Vertex 5 (x of vertex 5 is value 15 of the state; slot 4 once vertex 0 is dropped)
        // was pulled along +x: the penalty pulls it back.
        assert!(g[4 * 3] > 0.0);
        // A central finite difference of the penalty in that coordinate agrees.
        let h = 1e-3;
        let at = |delta: f64| {
            let mut x = pulled.clone();
            x[15] += delta;
            stretch
                .penalty(&encoded(&encoding, &x), &truth)
                .unwrap()
                .to_scalar::<f32>()
                .unwrap() as f64
        };
        let fd = (at(h) - at(-h)) / (2.0 * h);
        assert!((fd - g[4 * 3] as f64).abs() < 1e-2 * fd.abs(), "{fd} vs {}", g[4 * 3]);
    }

    #[test]
    fn strand_bends_are_refused() {
        let mesh = Mesh {
            dim: 3,
            rest: vec![0.0, 0.0, 0.0, 0.0, -0.1, 0.0, 0.0, -0.2, 0.0],
            elements: mochi_sim::mesh::Elements::Rods(vec![vec![0, 1, 2]]),
            attributes: None,
        };
        // Strands encoded by bends are held by their first two vertices.
        let encoding = Encoding::from_parts(&mesh, &[pin(&mesh, &[0, 1])], false)
            .unwrap()
            .with_strand_bends(&mesh)
            .unwrap();
        let err = EdgeStretch::new(&mesh, &encoding).unwrap_err().to_string();
        assert!(err.contains("strand bends"), "{err}");
    }
}
