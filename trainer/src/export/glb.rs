//! A [`MeshAnimation`] as a glTF 2.0 binary (`.glb`) that Blender, three.js, Unity and Unreal
//! open: one node with one mesh whose base shape is the first frame, one morph target per
//! later frame (its position and normal offsets from the base), and one animation that
//! plays the targets' weights at the model's frame rate, each keyframe giving the whole
//! weight to its frame's target. Linear interpolation of those weights between keyframes is
//! linear interpolation of the positions, so an engine showing it between frames sees what
//! the model would give halfway.
//!
//! Written with `gltf-json`'s types (the `gltf` crate's own schema, so the file serialises
//! to the specification's names) and its GLB container; accessors of positions carry their
//! bounds, as the specification asks.

use std::borrow::Cow;
use std::collections::BTreeMap;
use std::path::Path;

use gltf::json;
use json::accessor::{ComponentType, GenericComponentType, Type};
use json::validation::Checked::Valid;
use json::validation::USize64;

use super::MeshAnimation;
use crate::error::{TrainerError, TrainerResult as Result};

/// The base colour of the material: a pale mochi pink, opaque.
const BASE_COLOR: [f32; 4] = [0.96, 0.86, 0.84, 1.0];

/// Writes `animation` to `path` as a `.glb`, whole or not at all; returns the bytes written.
pub fn write(animation: &MeshAnimation, path: &Path) -> Result<usize> {
    let bytes = to_bytes(animation)?;
    mochi_sim::mesh::asset::write_atomically(path, &bytes).map_err(|e| TrainerError::io(path, e))?;
    Ok(bytes.len())
}

/// `animation` as the bytes of a `.glb`.
pub fn to_bytes(animation: &MeshAnimation) -> Result<Vec<u8>> {
    let n = animation.vertices();
    let frames = animation.frames();
    if n == 0 || frames == 0 || animation.triangles.is_empty() {
        return Err(TrainerError::invalid(
            "nothing to export: the mesh has no vertices, triangles or frames",
        ));
    }
    if animation.triangles.iter().any(|&v| v as usize >= n) {
        return Err(TrainerError::invalid("a triangle names a vertex past the mesh"));
    }
    if !animation
        .positions
        .iter()
        .chain(&animation.normals)
        .all(|v| v.is_finite())
    {
        return Err(TrainerError::invalid("a position or normal is not finite"));
    }
    let mut out = Builder::default();
    let indices = out.accessor(
        Some(json::buffer::Target::ElementArrayBuffer),
        bytes_of_u32(&animation.triangles),
        animation.triangles.len(),
        ComponentType::U32,
        Type::Scalar,
        None,
    );
    let (base, base_normals) = (animation.frame_positions(0), animation.frame_normals(0));
    let position = out.vec3(base, true);
    let normal = out.vec3(base_normals, false);
    let mut attributes = BTreeMap::from([
        (Valid(json::mesh::Semantic::Positions), position),
        (Valid(json::mesh::Semantic::Normals), normal),
    ]);
    if animation.uvs.len() == 2 * n {
        let uvs = out.accessor(
            Some(json::buffer::Target::ArrayBuffer),
            bytes_of_f32(&animation.uvs),
            n,
            ComponentType::F32,
            Type::Vec2,
            None,
        );
        attributes.insert(Valid(json::mesh::Semantic::TexCoords(0)), uvs);
    }
    // One morph target per frame after the first: offsets from the base.
    let mut targets = Vec::with_capacity(frames - 1);
    let mut offsets = vec![0.0f32; 3 * n];
    for f in 1..frames {
        let mut target = json::mesh::MorphTarget {
            positions: None,
            normals: None,
            tangents: None,
        };
        for (values, base, slot, bounded) in [
            (animation.frame_positions(f), base, &mut target.positions, true),
            (animation.frame_normals(f), base_normals, &mut target.normals, false),
        ] {
            offsets
                .iter_mut()
                .zip(values.iter().zip(base))
                .for_each(|(o, (v, b))| *o = v - b);
            *slot = Some(out.vec3(&offsets, bounded));
        }
        targets.push(target);
    }
    let material = out.root.push(json::Material {
        name: Some("mochi".into()),
        // Cloth and other open surfaces are seen from both sides.
        double_sided: true,
        pbr_metallic_roughness: json::material::PbrMetallicRoughness {
            base_color_factor: json::material::PbrBaseColorFactor(BASE_COLOR),
            metallic_factor: json::material::StrengthFactor(0.0),
            roughness_factor: json::material::StrengthFactor(0.6),
            ..Default::default()
        },
        ..Default::default()
    });
    let mesh = out.root.push(json::Mesh {
        extensions: None,
        extras: Default::default(),
        name: Some(animation.name.clone()),
        primitives: vec![json::mesh::Primitive {
            attributes,
            extensions: None,
            extras: Default::default(),
            indices: Some(indices),
            material: Some(material),
            mode: Valid(json::mesh::Mode::Triangles),
            targets: (!targets.is_empty()).then_some(targets),
        }],
        weights: (frames > 1).then(|| vec![0.0; frames - 1]),
    });
    let node = out.root.push(json::Node {
        mesh: Some(mesh),
        name: Some(animation.name.clone()),
        ..Default::default()
    });
    let scene = out.root.push(json::Scene {
        extensions: None,
        extras: Default::default(),
        name: Some(animation.name.clone()),
        nodes: vec![node],
    });
    out.root.scene = Some(scene);
    if frames > 1 {
        out.weights_animation(animation, node);
    }
    out.root.asset.generator = Some(format!("mochi {}", env!("CARGO_PKG_VERSION")));
    out.finish()
}

/// The root being filled and the binary chunk behind it.
#[derive(Default)]
struct Builder {
    root: json::Root,
    bin: Vec<u8>,
}

impl Builder {
    /// Appends `bytes` as a buffer view of its own (at a 4-byte boundary) and an accessor of
    /// `count` elements of `kind` over it.
    fn accessor(
        &mut self,
        target: Option<json::buffer::Target>,
        bytes: Vec<u8>,
        count: usize,
        component: ComponentType,
        kind: Type,
        bounds: Option<(Vec<f32>, Vec<f32>)>,
    ) -> json::Index<json::Accessor> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let view = self.root.push(json::buffer::View {
            buffer: json::Index::new(0),
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(self.bin.len())),
            byte_stride: None,
            extensions: None,
            extras: Default::default(),
            name: None,
            target: target.map(Valid),
        });
        self.bin.extend_from_slice(&bytes);
        let (min, max) = match bounds {
            Some((min, max)) => (Some(json::Value::from(min)), Some(json::Value::from(max))),
            None => (None, None),
        };
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(count),
            component_type: Valid(GenericComponentType(component)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(kind),
            min,
            max,
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    /// Three floats per vertex as a vertex attribute; with their bounds when `bounded`.
    fn vec3(&mut self, values: &[f32], bounded: bool) -> json::Index<json::Accessor> {
        let bounds = bounded.then(|| {
            let (mut min, mut max) = (vec![f32::INFINITY; 3], vec![f32::NEG_INFINITY; 3]);
            for p in values.chunks_exact(3) {
                for i in 0..3 {
                    min[i] = min[i].min(p[i]);
                    max[i] = max[i].max(p[i]);
                }
            }
            (min, max)
        });
        self.accessor(
            Some(json::buffer::Target::ArrayBuffer),
            bytes_of_f32(values),
            values.len() / 3,
            ComponentType::F32,
            Type::Vec3,
            bounds,
        )
    }

    /// The animation: keyframe `f` at `f * dt` seconds gives target `f - 1` the whole weight
    /// (keyframe 0, the base, gives none).
    fn weights_animation(&mut self, animation: &MeshAnimation, node: json::Index<json::Node>) {
        let frames = animation.frames();
        let targets = frames - 1;
        let times: Vec<f32> = (0..frames).map(|f| (f as f64 * animation.dt) as f32).collect();
        let bounds = (vec![times[0]], vec![times[frames - 1]]);
        let input = self.accessor(
            None,
            bytes_of_f32(&times),
            frames,
            ComponentType::F32,
            Type::Scalar,
            Some(bounds),
        );
        let mut weights = vec![0.0f32; frames * targets];
        for f in 1..frames {
            weights[f * targets + (f - 1)] = 1.0;
        }
        let output = self.accessor(
            None,
            bytes_of_f32(&weights),
            weights.len(),
            ComponentType::F32,
            Type::Scalar,
            None,
        );
        let sampler = json::Index::new(0);
        self.root.push(json::Animation {
            extensions: None,
            extras: Default::default(),
            channels: vec![json::animation::Channel {
                sampler,
                target: json::animation::Target {
                    extensions: None,
                    extras: Default::default(),
                    node,
                    path: Valid(json::animation::Property::MorphTargetWeights),
                },
                extensions: None,
                extras: Default::default(),
            }],
            name: Some(format!("{} rollout", animation.name)),
            samplers: vec![json::animation::Sampler {
                extensions: None,
                extras: Default::default(),
                input,
                interpolation: Valid(json::animation::Interpolation::Linear),
                output,
            }],
        });
    }

    /// The buffer and the `.glb` bytes.
    fn finish(mut self) -> Result<Vec<u8>> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.root.push(json::Buffer {
            byte_length: USize64::from(self.bin.len()),
            extensions: None,
            extras: Default::default(),
            name: None,
            uri: None,
        });
        let text = json::serialize::to_vec(&self.root).map_err(|e| TrainerError::invalid(format!("glTF JSON: {e}")))?;
        if self.bin.len() > u32::MAX as usize - text.len() - 64 {
            return Err(TrainerError::invalid(format!(
                "the animation takes {} bytes, past a .glb's 4 GiB: export fewer frames",
                self.bin.len()
            )));
        }
        let glb = gltf::binary::Glb {
            header: gltf::binary::Header {
                magic: *b"glTF",
                version: 2,
                length: 0, // `to_vec` writes the real length.
            },
            json: Cow::Owned(text),
            bin: Some(Cow::Owned(self.bin)),
        };
        glb.to_vec()
            .map_err(|e| TrainerError::invalid(format!("GLB container: {e}")))
    }
}

fn bytes_of_f32(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn bytes_of_u32(values: &[u32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}
