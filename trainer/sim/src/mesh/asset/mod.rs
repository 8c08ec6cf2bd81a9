//! Surface assets: an artist's triangle mesh (glTF 2.0, Wavefront OBJ, STL) read into one
//! [`Surface`] type, repaired into what a tet mesher needs, and the render mesh's embedding in
//! the tet mesh made from it.
//!
//! - [`read_surface`] reads a file (format by its contents where the extension lies: a GLB
//!   header, a binary STL); glTF takes every triangle primitive of every node of the default
//!   scene with the node transforms applied.
//! - [`repair::repair`] welds coincident vertices, drops zero-area triangles, orients the
//!   faces outward, and reports holes, non-manifold edges and self-intersections; it refuses
//!   what a mesher cannot take.
//! - [`render::RenderEmbedding`] ties each render vertex to a tet of the simulation mesh.
//!
//! The surface as read keeps the asset's own vertices (split where normals or UVs differ,
//! as an engine draws them); repair works on a welded copy and keeps the map from render
//! vertices to welded ones.

mod gltf_reader;
mod obj_stl;
pub mod render;
mod render_read;
pub mod repair;
#[cfg(test)]
mod tests;

use std::path::Path;

use crate::error::InputError;

/// A named part of a surface: the triangles of one glTF node's mesh, an OBJ object or group.
#[derive(Clone, Debug, PartialEq)]
pub struct Part {
    /// The node's (else the mesh's) name; `None` when the file names neither.
    pub name: Option<String>,
    /// Its triangles: `triangles[range]` of the surface.
    pub triangles: std::ops::Range<usize>,
}

/// A triangle surface as an asset file holds it.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Surface {
    /// Vertex positions (in the asset's units, node transforms applied).
    pub positions: Vec<[f64; 3]>,
    /// Triangles (counter-clockwise seen from outside, as the file gives them).
    pub triangles: Vec<[usize; 3]>,
    /// Per-vertex normals when the file has them for every vertex.
    pub normals: Option<Vec<[f64; 3]>>,
    /// Per-vertex texture coordinates when the file has them for every vertex.
    pub uvs: Option<Vec<[f64; 2]>>,
    /// Named parts in triangle order (one covering everything when the file has no parts).
    pub parts: Vec<Part>,
}

impl Surface {
    /// Axis-aligned bounding box of the positions (infinite bounds when there are none).
    pub fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in &self.positions {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        (lo, hi)
    }

    /// Length of the bounding-box diagonal (0 for no vertices).
    pub fn diagonal(&self) -> f64 {
        if self.positions.is_empty() {
            return 0.0;
        }
        let (lo, hi) = self.bounds();
        (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt()
    }

    /// Bounding box of the vertices of `part`'s triangles.
    pub fn part_bounds(&self, part: &Part) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for t in &self.triangles[part.triangles.clone()] {
            for &v in t {
                for k in 0..3 {
                    lo[k] = lo[k].min(self.positions[v][k]);
                    hi[k] = hi[k].max(self.positions[v][k]);
                }
            }
        }
        (lo, hi)
    }

    /// Checks what every later step relies on: at least one triangle, finite coordinates,
    /// indices in range. Errors name the file, and the vertex or triangle at fault.
    pub fn check(&self, file: &Path) -> Result<(), InputError> {
        if self.triangles.is_empty() {
            return Err(InputError::file(
                file,
                format!("empty surface: no triangles ({} vertices)", self.positions.len()),
            ));
        }
        if let Some(v) = self.positions.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
            return Err(InputError::file(
                file,
                format!(
                    "vertex {v} has a coordinate that is not finite: {:?}",
                    self.positions[v]
                ),
            ));
        }
        let n = self.positions.len();
        if let Some(t) = self.triangles.iter().position(|t| t.iter().any(|&v| v >= n)) {
            return Err(InputError::file(
                file,
                format!(
                    "triangle {t} names vertex {:?}, but there are {n} vertices",
                    self.triangles[t]
                ),
            ));
        }
        Ok(())
    }
}

/// The formats [`read_surface`] reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AssetFormat {
    /// glTF 2.0 JSON (`.gltf`) with its buffers embedded or beside it.
    Gltf,
    /// glTF 2.0 binary (`.glb`).
    Glb,
    /// Wavefront `.obj`.
    Obj,
    /// STL, binary or ASCII.
    Stl,
}

impl AssetFormat {
    /// The format of `bytes` read from `path`: by extension, checked against the contents
    /// (a GLB says `glTF` in its first bytes; a binary STL's length follows from its triangle
    /// count). A file whose contents belong to another format than its extension says is an
    /// error naming both.
    pub fn detect(path: &Path, bytes: &[u8]) -> Result<AssetFormat, InputError> {
        let extension = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        let claimed = match extension.as_deref() {
            Some("gltf") => AssetFormat::Gltf,
            Some("glb") => AssetFormat::Glb,
            Some("obj") => AssetFormat::Obj,
            Some("stl") => AssetFormat::Stl,
            other => {
                return Err(InputError::file(
                    path,
                    format!(
                        "unknown surface format{}: expected .gltf, .glb, .obj or .stl",
                        other.map(|e| format!(" `.{e}`")).unwrap_or_default()
                    ),
                ))
            }
        };
        let glb = bytes.starts_with(b"glTF");
        let binary_stl = bytes.len() >= 84 && {
            let count = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
            bytes.len() == 84 + 50 * count
        };
        let json = bytes.iter().find(|b| !b.is_ascii_whitespace()) == Some(&b'{');
        let found = if glb {
            Some(AssetFormat::Glb)
        } else if binary_stl {
            Some(AssetFormat::Stl)
        } else if json {
            Some(AssetFormat::Gltf)
        } else {
            None
        };
        match (claimed, found) {
            (AssetFormat::Gltf | AssetFormat::Glb, Some(AssetFormat::Gltf | AssetFormat::Glb)) => {
                Ok(found.unwrap_or(claimed))
            }
            (_, Some(f)) if f != claimed => Err(InputError::file(
                path,
                format!("the extension says {claimed:?} but the contents are {f:?}"),
            )),
            _ => Ok(claimed),
        }
    }
}

/// Reads the triangle surface of the asset at `path` (`.gltf`, `.glb`, `.obj`, `.stl`) and
/// checks it ([`Surface::check`]). Errors name the file and what is wrong.
pub fn read_surface(path: &Path) -> Result<Surface, InputError> {
    let bytes = std::fs::read(path).map_err(|e| InputError::file(path, format!("cannot read: {e}")))?;
    let surface = match AssetFormat::detect(path, &bytes)? {
        AssetFormat::Gltf | AssetFormat::Glb => gltf_reader::read_gltf(path, &bytes)?,
        AssetFormat::Obj => obj_stl::read_obj(path, &bytes)?,
        AssetFormat::Stl => obj_stl::read_stl(path, &bytes)?,
    };
    surface.check(path)?;
    Ok(surface)
}

/// Writes `bytes` to `path` whole or not at all: into a temporary file beside it, then renamed
/// over it (a rename within a directory is atomic), so a reader never sees half a file.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let temporary = temporary_beside(path);
    let result = std::fs::write(&temporary, bytes).and_then(|()| std::fs::rename(&temporary, path));
    if result.is_err() {
        let _ = std::fs::remove_file(&temporary);
    }
    result
}

/// A temporary name beside `path` (same directory, so renaming it over `path` is atomic).
pub fn temporary_beside(path: &Path) -> std::path::PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.{}.partial", std::process::id()))
}
