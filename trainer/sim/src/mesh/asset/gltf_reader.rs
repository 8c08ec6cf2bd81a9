//! glTF 2.0 (`.gltf` JSON and `.glb` binary) through the `gltf` crate: the triangle primitives
//! of every mesh node of the default scene (else the first scene, else every root node), each
//! with its node's world transform applied, named by the node (else the mesh).
//!
//! The crate parses and validates the document; buffers are resolved here (the GLB binary
//! chunk, base64 `data:` URIs, files beside the asset) so that a missing or short buffer is an
//! error naming it instead of a panic deep in an accessor.

use std::path::Path;

use base64::Engine;
use gltf::mesh::Mode;
use nalgebra::{Matrix3, Matrix4};

use super::{Part, Surface};
use crate::error::InputError;

/// Reads the glTF document `bytes` (from `path`) into a surface.
pub(super) fn read_gltf(path: &Path, bytes: &[u8]) -> Result<Surface, InputError> {
    let gltf = gltf::Gltf::from_slice(bytes)
        .map_err(|e| InputError::file(path, format!("not a readable glTF 2.0 file: {e}")))?;
    let buffers = load_buffers(path, &gltf)?;
    let document = &gltf.document;
    let roots: Vec<gltf::Node> = match document.default_scene().or_else(|| document.scenes().next()) {
        Some(scene) => scene.nodes().collect(),
        None => {
            let children: std::collections::HashSet<usize> =
                document.nodes().flat_map(|n| n.children().map(|c| c.index())).collect();
            document.nodes().filter(|n| !children.contains(&n.index())).collect()
        }
    };
    let mut builder = Builder::default();
    let mut stack: Vec<(gltf::Node, Matrix4<f64>)> = roots.into_iter().map(|n| (n, Matrix4::identity())).collect();
    stack.reverse();
    let mut visited = 0usize;
    while let Some((node, parent)) = stack.pop() {
        visited += 1;
        if visited > 1_000_000 {
            return Err(InputError::file(path, "the node hierarchy has a cycle"));
        }
        let local = Matrix4::from_fn(|r, c| node.transform().matrix()[c][r] as f64);
        let world = parent * local;
        if let Some(mesh) = node.mesh() {
            let name = node.name().or(mesh.name()).map(str::to_owned);
            let first = builder.surface.triangles.len();
            for primitive in mesh.primitives() {
                builder.primitive(path, &buffers, &mesh, &primitive, &world)?;
            }
            let range = first..builder.surface.triangles.len();
            if !range.is_empty() {
                builder.surface.parts.push(Part { name, triangles: range });
            }
        }
        let children: Vec<gltf::Node> = node.children().collect();
        stack.extend(children.into_iter().rev().map(|c| (c, world)));
    }
    let mut surface = builder.surface;
    if !builder.all_normals {
        surface.normals = None;
    }
    if !builder.all_uvs {
        surface.uvs = None;
    }
    Ok(surface)
}

/// Every buffer's bytes, each checked to be at least as long as the document says.
fn load_buffers(path: &Path, gltf: &gltf::Gltf) -> Result<Vec<Vec<u8>>, InputError> {
    let mut buffers = Vec::new();
    for buffer in gltf.document.buffers() {
        let what = format!("buffer {}", buffer.index());
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => gltf
                .blob
                .clone()
                .ok_or_else(|| InputError::field(path, &what, "refers to the GLB binary chunk, which is missing"))?,
            gltf::buffer::Source::Uri(uri) => {
                if let Some(rest) = uri.strip_prefix("data:") {
                    let encoded = rest.split_once(";base64,").map(|(_, d)| d).ok_or_else(|| {
                        InputError::field(path, &what, "a data URI that is not base64 is not supported")
                    })?;
                    base64::engine::general_purpose::STANDARD
                        .decode(encoded)
                        .map_err(|e| InputError::field(path, &what, format!("bad base64 data URI: {e}")))?
                } else {
                    let file = path.parent().unwrap_or(Path::new(".")).join(percent_decoded(uri));
                    std::fs::read(&file)
                        .map_err(|e| InputError::field(path, &what, format!("cannot read `{}`: {e}", file.display())))?
                }
            }
        };
        if data.len() < buffer.length() {
            return Err(InputError::field(
                path,
                &what,
                format!(
                    "truncated: {} bytes where the document declares {}",
                    data.len(),
                    buffer.length()
                ),
            ));
        }
        buffers.push(data);
    }
    Ok(buffers)
}

/// A relative URI's `%XX` escapes decoded (file names with spaces are written `%20`).
fn percent_decoded(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = |b: u8| (b as char).to_digit(16);
        if bytes[i] == b'%' && i + 2 < bytes.len() {
            if let (Some(h), Some(l)) = (hex(bytes[i + 1]), hex(bytes[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(bytes[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The surface being assembled, and whether every primitive so far had normals and UVs.
struct Builder {
    surface: Surface,
    all_normals: bool,
    all_uvs: bool,
}

impl Default for Builder {
    fn default() -> Self {
        Builder {
            surface: Surface {
                normals: Some(Vec::new()),
                uvs: Some(Vec::new()),
                ..Surface::default()
            },
            all_normals: true,
            all_uvs: true,
        }
    }
}

impl Builder {
    /// Appends one primitive's vertices (transformed by `world`) and triangles. Points and
    /// lines are skipped: they have no surface.
    fn primitive(
        &mut self,
        path: &Path,
        buffers: &[Vec<u8>],
        mesh: &gltf::Mesh,
        primitive: &gltf::Primitive,
        world: &Matrix4<f64>,
    ) -> Result<(), InputError> {
        let what = format!("meshes[{}].primitives[{}]", mesh.index(), primitive.index());
        let mode = primitive.mode();
        if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
            return Ok(());
        }
        let reader = primitive.reader(|b| buffers.get(b.index()).map(Vec::as_slice));
        let positions: Vec<[f32; 3]> = reader
            .read_positions()
            .ok_or_else(|| InputError::field(path, &what, "no POSITION attribute"))?
            .collect();
        let n = positions.len();
        let normals: Option<Vec<[f32; 3]>> = reader.read_normals().map(|r| r.collect());
        let uvs: Option<Vec<[f32; 2]>> = reader.read_tex_coords(0).map(|r| r.into_f32().collect());
        let indices: Vec<usize> = match reader.read_indices() {
            Some(r) => r.into_u32().map(|i| i as usize).collect(),
            None => (0..n).collect(),
        };
        if let Some(&bad) = indices.iter().find(|&&i| i >= n) {
            return Err(InputError::field(
                path,
                &what,
                format!("index {bad} is out of range: the primitive has {n} vertices"),
            ));
        }
        let base = self.surface.positions.len();
        let linear = world.fixed_view::<3, 3>(0, 0).into_owned();
        let flip = linear.determinant() < 0.0;
        let normal_map: Matrix3<f64> = linear.try_inverse().map_or(linear, |m| m.transpose());
        for p in &positions {
            let q = world * nalgebra::Vector4::new(p[0] as f64, p[1] as f64, p[2] as f64, 1.0);
            self.surface.positions.push([q.x, q.y, q.z]);
        }
        match (normals, self.surface.normals.as_mut()) {
            (Some(normals), Some(out)) if normals.len() == n => out.extend(normals.iter().map(|m| {
                let v = normal_map * nalgebra::Vector3::new(m[0] as f64, m[1] as f64, m[2] as f64);
                let v = v.try_normalize(0.0).unwrap_or(v);
                [v.x, v.y, v.z]
            })),
            _ => self.all_normals = false,
        }
        match (uvs, self.surface.uvs.as_mut()) {
            (Some(uvs), Some(out)) if uvs.len() == n => out.extend(uvs.iter().map(|t| [t[0] as f64, t[1] as f64])),
            _ => self.all_uvs = false,
        }
        let mut triangles: Vec<[usize; 3]> = match mode {
            Mode::Triangles => indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect(),
            Mode::TriangleStrip => (2..indices.len())
                .map(|k| {
                    let (a, b, c) = (indices[k - 2], indices[k - 1], indices[k]);
                    if k % 2 == 0 {
                        [a, b, c]
                    } else {
                        [b, a, c]
                    }
                })
                .collect(),
            _ => (2..indices.len())
                .map(|k| [indices[0], indices[k - 1], indices[k]])
                .collect(),
        };
        for t in &mut triangles {
            if flip {
                t.swap(1, 2);
            }
            *t = t.map(|v| v + base);
        }
        self.surface.triangles.extend(triangles);
        Ok(())
    }
}
