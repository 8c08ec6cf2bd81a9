//! The deployable payload of an artifact as owned data (feature `std`): the schema the loader
//! in [`crate::artifact`] reads, field for field and in the same order, and the writer of the
//! artifact's first section (docs/design.md, decision 4).
//!
//! An artifact is the envelope ([`crate::envelope`]) with [`MAGIC`] and [`FORMAT_VERSION`]
//! around the postcard encoding of a [`Payload`], optionally followed by further sections (the
//! trainer's training-only data), which the runtime checks but does not read.

use std::vec::Vec;

use serde::{Deserialize, Serialize};

use crate::artifact::{FORMAT_VERSION, MAGIC};
use crate::envelope;

/// Everything the runtime reads from an artifact, in the order it reads it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Payload {
    /// Time step in seconds.
    pub dt: f64,
    /// Coordinates per vertex (2 or 3).
    pub dim: u32,
    /// Vertices of the full mesh.
    pub num_vertices: u32,
    /// Rest positions, `dim` per vertex.
    pub rest: Vec<f32>,
    /// Rest bounding-box diagonal.
    pub diagonal: f64,
    /// Whether states are encoded relative to the handles' best-fit rotation.
    pub rotates: bool,
    /// Prescribed vertices, in handle-target order (the handles' lists concatenated).
    pub handle_vertices: Vec<u32>,
    /// Encoded (free) vertices, ascending.
    pub free_vertices: Vec<u32>,
    /// Per encoded vertex, the index of its origin.
    pub origin_of: Vec<u32>,
    /// Empty: one origin, the centroid of the handle targets. Otherwise, per rod strand, the
    /// slot of its root among the handle vertices.
    pub root_slots: Vec<u32>,
    /// Empty: encoded vertices are positions. Otherwise the rod strands, encoded by their
    /// bends (see [`crate::Chain`]).
    pub chains: Vec<ChainData>,
    /// Handles, in boundary-condition signal order.
    pub handles: Vec<HandleData>,
    /// Boundary-condition signal numbers per frame (12 per handle).
    pub bc_len: u32,
    /// Vertices that are drawn, ascending.
    pub surface_vertices: Vec<u32>,
    /// Latent size.
    pub latent: u32,
    /// Latent of the initial state.
    pub initial_latent: Vec<f32>,
    /// Per latent coordinate, the smallest value in the training data.
    pub latent_min: Vec<f32>,
    /// Per latent coordinate, the largest value in the training data.
    pub latent_max: Vec<f32>,
    /// Decoder: latent -> encoded state.
    pub decoder: Vec<LayerData>,
    /// Integrator: `[z_{t-1}, z_{t-2}, p_t, p_{t-1}, p_{t-2}]`, then the collider slots'
    /// features, then the frame time when `dt_range` is not zero -> latent increment.
    pub integrator: Vec<LayerData>,
    /// Triangles to draw, three indices into `surface_vertices` each: the boundary faces of a
    /// tet mesh (outward), the triangles of a 2D mesh or cloth, none for rods. Last, so that a
    /// format-3 payload followed by one `0x00` byte (an empty list) reads as this one.
    pub surface_triangles: Vec<u32>,
    /// Whether the decoder's last layer is a linear basis (see [`crate::Model::decoder_basis`]).
    /// Last, so that a format-4 payload followed by one `0x00` byte (`false`) reads as this one.
    pub decoder_basis: bool,
    /// Shortest and longest frame time (seconds) the integrator was trained at, when it takes
    /// the frame time as its last input; `[0, 0]` for a model of the one frame time `dt` (see
    /// [`crate::Model::dt_max`]). A format-5 payload is this one without it and what follows.
    pub dt_range: [f64; 2],
    /// The run-time collider slots' shape rows, four numbers each (see
    /// [`crate::Model::collider_shapes`]); empty for a model without collider inputs.
    pub collider_shapes: Vec<f32>,
    /// The render mesh riding on the simulation mesh (all lists empty when there is none). A
    /// format-6 payload is this one without it.
    pub render: RenderData,
    /// Whether a timed integrator reads the previous latent's change per frame of `dt` in
    /// place of `z_{t-2}` (see [`crate::Model::rate_input`]). A format-7 payload is this one
    /// without it (`false`).
    pub rate_input: bool,
}

/// A render mesh embedded in the simulation mesh's tets (see [`crate::render`]): four
/// simulation vertices and four barycentric weights per render vertex, the triangles over the
/// render vertices and, where the asset has them, their texture coordinates.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RenderData {
    /// Per render vertex, the four simulation vertices of its tet.
    pub anchors: Vec<u32>,
    /// Per render vertex, the four barycentric weights of those vertices.
    pub weights: Vec<f32>,
    /// Render triangles, three render-vertex indices each, counter-clockwise seen from outside.
    pub triangles: Vec<u32>,
    /// Per render vertex, its texture coordinates `(u, v)`; empty when the asset has none.
    pub uvs: Vec<f32>,
}

/// One rod strand of the bend encoding (see [`crate::Chain`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ChainData {
    /// Handle slots of the strand's two prescribed vertices (parent edge: first to second).
    pub parent: [u32; 2],
    /// Unit vector perpendicular to the parent edge at rest.
    pub rest_normal: [f32; 3],
    /// Encoded-vertex indices of the strand's free vertices, root to tip.
    pub slots: Vec<u32>,
    /// Rest length of the edge ending at each of them.
    pub lengths: Vec<f32>,
}

/// A handle: prescribed vertices moved rigidly about a pivot.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HandleData {
    /// Prescribed vertices, ascending (the runtime searches them).
    pub vertices: Vec<u32>,
    /// Their identity-pose positions, 3 per vertex.
    pub reference: Vec<f32>,
    /// Rotation pivot at the identity pose.
    pub pivot: [f32; 3],
}

/// One dense layer `y = W x + b` (see [`crate::Layer`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LayerData {
    /// Outputs.
    pub rows: u64,
    /// Inputs.
    pub cols: u64,
    /// `W`, row-major.
    pub weights: Vec<f32>,
    /// `b`.
    pub bias: Vec<f32>,
}

impl Payload {
    /// The payload's postcard encoding (what goes in the first section).
    pub fn encode(&self) -> Result<Vec<u8>, postcard::Error> {
        postcard::to_extend(self, Vec::new())
    }

    /// Decodes a payload's postcard encoding (the first section's contents).
    pub fn decode(bytes: &[u8]) -> Result<Payload, postcard::Error> {
        postcard::from_bytes(bytes)
    }

    /// The artifact's first section: the payload in the envelope with [`MAGIC`] and
    /// [`FORMAT_VERSION`]. Further sections may be appended with [`envelope::wrap`].
    pub fn to_section(&self) -> Result<Vec<u8>, postcard::Error> {
        Ok(envelope::wrap(MAGIC, FORMAT_VERSION, &self.encode()?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::artifact::LoadError;
    use crate::envelope::EnvelopeError;
    use crate::{OwnedModel, Problem};
    use std::vec;

    /// A tiny valid model: a 2D triangle, one handle on vertices 0 and 1, vertex 2 free.
    fn payload() -> Payload {
        let layer = |rows: u64, cols: u64| LayerData {
            rows,
            cols,
            weights: (0..rows * cols).map(|i| 0.01 * i as f32).collect(),
            bias: (0..rows).map(|i| -0.1 * i as f32).collect(),
        };
        Payload {
            dt: 0.01,
            dim: 2,
            num_vertices: 3,
            rest: vec![0.0, 0.0, 1.0, 0.0, 0.0, 1.0],
            diagonal: 2f64.sqrt(),
            rotates: false,
            handle_vertices: vec![0, 1],
            free_vertices: vec![2],
            origin_of: vec![0],
            root_slots: vec![],
            chains: vec![],
            handles: vec![HandleData {
                vertices: vec![0, 1],
                reference: vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
                pivot: [0.5, 0.0, 0.0],
            }],
            bc_len: 12,
            surface_vertices: vec![0, 1, 2],
            latent: 1,
            initial_latent: vec![0.0],
            latent_min: vec![-1.0],
            latent_max: vec![1.0],
            decoder: vec![layer(4, 1), layer(2, 4)],
            integrator: vec![layer(4, 38), layer(1, 4)],
            surface_triangles: vec![0, 1, 2],
            decoder_basis: false,
            dt_range: [0.0; 2],
            collider_shapes: vec![],
            render: RenderData::default(),
            rate_input: false,
        }
    }

    #[test]
    fn what_is_written_is_what_the_loader_reads() {
        let p = payload();
        let bytes = p.to_section().unwrap();
        let mut storage = OwnedModel::default();
        let valid = storage.load(&bytes).unwrap();
        let m = valid.model();
        assert_eq!((m.dim, m.num_vertices, m.latent, m.bc_len), (2, 3, 1, 12));
        assert_eq!((m.dt, m.diagonal), (p.dt as f32, p.diagonal as f32));
        assert_eq!(m.rest(), &p.rest[..]);
        assert_eq!(m.handle_vertices(), &p.handle_vertices[..]);
        assert_eq!(m.free_vertices(), &p.free_vertices[..]);
        assert_eq!(m.surface_vertices(), &p.surface_vertices[..]);
        assert_eq!(m.surface_triangles(), &p.surface_triangles[..]);
        assert_eq!(m.decoder.len(), 2);
        assert_eq!(m.integrator.len(), 2);
        let first = m.decoder[0];
        assert_eq!((first.rows, first.cols), (4, 1));
        assert_eq!(&m.params[first.weights as usize..][..4], &p.decoder[0].weights[..]);
        assert_eq!(Payload::decode(crate::artifact::payload(&bytes).unwrap()).unwrap(), p);
    }

    #[test]
    fn triangles_must_be_whole_and_over_the_drawn_vertices() {
        let refused = |triangles: Vec<u32>| {
            let p = Payload {
                surface_triangles: triangles,
                ..payload()
            };
            match OwnedModel::default().load(&p.to_section().unwrap()) {
                Err(LoadError::Invalid(e)) => Some((e.field, e.problem)),
                _ => None,
            }
        };
        assert_eq!(refused(vec![]), None);
        assert_eq!(refused(vec![2, 1, 0, 0, 1, 2]), None);
        let field = "surface_triangles";
        assert_eq!(refused(vec![0, 1, 3]), Some((field, Problem::OutOfRange)));
        let length = Problem::Length { expected: 3, found: 5 };
        assert_eq!(refused(vec![0, 1, 2, 0, 1]), Some((field, length)));
        // Indices count drawn vertices, not mesh vertices: with vertex 2 not drawn, 2 is out.
        let p = Payload {
            surface_vertices: vec![0, 1],
            surface_triangles: vec![0, 1, 2],
            ..payload()
        };
        let err = OwnedModel::default().load(&p.to_section().unwrap()).unwrap_err();
        assert_eq!(
            err,
            LoadError::Invalid(crate::ModelError {
                field,
                problem: Problem::OutOfRange
            })
        );
    }

    #[test]
    fn sections_after_the_payload_are_checked_not_read() {
        let mut bytes = payload().to_section().unwrap();
        let first = bytes.len();
        bytes.extend(envelope::wrap(b"OTHERSEC", 7, b"training-only data"));
        assert!(OwnedModel::default().load(&bytes).is_ok());
        assert!(OwnedModel::default().load(&bytes[..first]).is_ok());
        let mut flipped = bytes.clone();
        *flipped.last_mut().unwrap() ^= 1;
        assert_eq!(
            OwnedModel::default().load(&flipped).err(),
            Some(LoadError::Envelope(EnvelopeError::Corrupt))
        );
        bytes.push(0);
        assert!(matches!(
            OwnedModel::default().load(&bytes),
            Err(LoadError::Envelope(EnvelopeError::Truncated { len: 1 }))
        ));
    }

    /// The decoder of [`payload`] replaced by a basis decoder: `layers` before a `2 x m` basis.
    fn with_basis(mlp: Vec<LayerData>, m: u64) -> Payload {
        let mut decoder = mlp;
        decoder.push(LayerData {
            rows: 2,
            cols: m,
            weights: (0..2 * m).map(|i| 0.3 - 0.2 * i as f32).collect(),
            bias: vec![0.25, -0.5],
        });
        Payload {
            decoder,
            decoder_basis: true,
            dt_range: [0.0; 2],
            collider_shapes: vec![],
            ..payload()
        }
    }

    fn layer(rows: u64, cols: u64, seed: f32) -> LayerData {
        LayerData {
            rows,
            cols,
            weights: (0..rows * cols).map(|i| (seed * (i as f32 + 1.0)).sin()).collect(),
            bias: (0..rows).map(|i| 0.1 * seed * i as f32).collect(),
        }
    }

    /// `x * sigmoid(x)` in `f64`.
    fn swish(x: f64) -> f64 {
        x / (1.0 + (-x).exp())
    }

    /// `W x + b` in `f64`.
    fn apply(l: &LayerData, x: &[f64]) -> Vec<f64> {
        (0..l.rows as usize)
            .map(|r| {
                let row = &l.weights[r * l.cols as usize..][..l.cols as usize];
                l.bias[r] as f64 + row.iter().zip(x).map(|(&w, &v)| w as f64 * v).sum::<f64>()
            })
            .collect()
    }

    /// The encoded state a basis decoder gives for `z`, written out: `B ([z; 0] + g(z)) + b`.
    fn basis_decode(decoder: &[LayerData], z: &[f64]) -> Vec<f64> {
        let (basis, mlp) = decoder.split_last().unwrap();
        let mut f = vec![0.0; basis.cols as usize];
        if let [input, blocks @ .., output] = mlp {
            let mut h = apply(input, z);
            for pair in blocks.chunks_exact(2) {
                let a: Vec<f64> = apply(&pair[0], &h).into_iter().map(swish).collect();
                h.iter_mut().zip(apply(&pair[1], &a)).for_each(|(h, r)| *h += r);
            }
            let h: Vec<f64> = h.into_iter().map(swish).collect();
            f = apply(output, &h);
        }
        f.iter_mut().zip(z).for_each(|(f, z)| *f += z);
        apply(basis, &f)
    }

    #[test]
    fn basis_decoders_decode_as_written_out() {
        use crate::{HandleMotion, Instance};
        let cases = [
            ("linear", with_basis(vec![], 1)),
            ("mlp + basis", with_basis(vec![layer(4, 1, 0.7), layer(3, 4, 1.3)], 3)),
            (
                "mlp with a block + basis",
                with_basis(
                    vec![layer(5, 1, 0.4), layer(5, 5, 0.9), layer(5, 5, 1.1), layer(2, 5, 0.6)],
                    2,
                ),
            ),
        ];
        for (what, p) in cases {
            let mut storage = OwnedModel::default();
            let model = storage.load(&p.to_section().unwrap()).unwrap();
            assert!(model.model().decoder_basis);
            let mut body = Instance::<1, 12, 8>::new(&model).unwrap();
            body.step(&model, &[HandleMotion::default()]).unwrap();
            let z = body.latent()[0];
            let mut full = [0.0f32; 6];
            body.decode_into(&model, &mut full).unwrap();
            // Handles at rest: vertex 2 is its encoded offset from the handle centroid (0.5, 0).
            let q = basis_decode(&p.decoder, &[z as f64]);
            let want = [0.5 + q[0], q[1]];
            for c in 0..2 {
                assert!(
                    (full[4 + c] as f64 - want[c]).abs() < 1e-5,
                    "{what}: {:?} vs {want:?}",
                    &full[4..]
                );
            }
            let mut surface = [0.0f32; 6];
            body.decode_surface_into(&model, &mut surface).unwrap();
            assert_eq!(surface, full, "{what}: the surface decode is the full decode");
        }
    }

    #[test]
    fn basis_decoders_of_the_wrong_shape_are_refused() {
        let refused = |p: Payload| match OwnedModel::default().load(&p.to_section().unwrap()) {
            Err(LoadError::Invalid(e)) => Some((e.field, e.problem)),
            Ok(_) => None,
            Err(e) => panic!("{e:?}"),
        };
        let shape = Some(("decoder", Problem::Shape));
        // A linear basis has as many columns as the latent.
        assert_eq!(refused(with_basis(vec![], 2)), shape);
        // The MLP before the basis writes as many features as the basis reads.
        assert_eq!(refused(with_basis(vec![layer(4, 1, 0.7), layer(3, 4, 1.3)], 2)), shape);
        // ... and maps the latent.
        assert_eq!(refused(with_basis(vec![layer(4, 2, 0.7), layer(3, 4, 1.3)], 3)), shape);
        // The basis writes the encoded state.
        let mut p = with_basis(vec![], 1);
        p.decoder[0] = layer(3, 1, 0.5);
        assert_eq!(refused(p), shape);
        // The same layers without the flag are an MLP decoder of the wrong shape.
        let p = Payload {
            decoder_basis: false,
            dt_range: [0.0; 2],
            collider_shapes: vec![],
            ..with_basis(vec![layer(4, 1, 0.7), layer(3, 4, 1.3)], 3)
        };
        assert_eq!(refused(p), Some(("decoder", Problem::Unsupported)));
        assert_eq!(refused(with_basis(vec![layer(4, 1, 0.7), layer(3, 4, 1.3)], 3)), None);
    }
}
