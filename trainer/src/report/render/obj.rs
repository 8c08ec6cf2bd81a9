//! Wavefront OBJ files of frames: the surface of a tet mesh (only its surface vertices,
//! renumbered), all triangles of cloth and 2D meshes (2D padded with z = 0), and rods as `l`
//! polylines.

use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::error::{bail, Context, TrainerError, TrainerResult};
use mochi_sim::mesh::{Elements, Mesh};

/// What an OBJ file of a mesh holds, with vertex indices renumbered to the written subset.
struct ObjTopology {
    /// Original indices of the vertices written, in order.
    vertices: Vec<usize>,
    /// Triangles in written (0-based) indices.
    faces: Vec<[usize; 3]>,
    /// Polylines in written (0-based) indices.
    lines: Vec<Vec<usize>>,
}

impl ObjTopology {
    fn new(mesh: &Mesh) -> TrainerResult<Self> {
        check_mesh(mesh)?;
        if let Elements::Rods(rods) = &mesh.elements {
            return Ok(ObjTopology {
                vertices: (0..mesh.num_vertices()).collect(),
                faces: Vec::new(),
                lines: rods.iter().filter(|r| r.len() >= 2).cloned().collect(),
            });
        }
        let vertices = mesh.surface_vertices();
        let mut new_index = vec![usize::MAX; mesh.num_vertices()];
        for (i, &v) in vertices.iter().enumerate() {
            new_index[v] = i;
        }
        let faces = mesh
            .surface_triangles()
            .iter()
            .map(|t| t.map(|v| new_index[v]))
            .collect();
        Ok(ObjTopology {
            vertices,
            faces,
            lines: Vec::new(),
        })
    }

    fn write(&self, path: &Path, dim: usize, x: &[f64]) -> TrainerResult<()> {
        let mut text = String::with_capacity(40 * (self.vertices.len() + self.faces.len()));
        text.push_str("# mochi frame\n");
        for &v in &self.vertices {
            let p = &x[v * dim..(v + 1) * dim];
            let z = if dim == 3 { p[2] } else { 0.0 };
            // `{}` prints the shortest text that reads back as the same f64.
            writeln!(text, "v {} {} {}", p[0], p[1], z)?;
        }
        for f in &self.faces {
            writeln!(text, "f {} {} {}", f[0] + 1, f[1] + 1, f[2] + 1)?;
        }
        for line in &self.lines {
            text.push('l');
            for v in line {
                write!(text, " {}", v + 1)?;
            }
            text.push('\n');
        }
        let write = || -> std::io::Result<()> {
            let mut file = BufWriter::new(File::create(path)?);
            file.write_all(text.as_bytes())?;
            file.flush()
        };
        write().map_err(|e| TrainerError::io(path, e))
    }
}

/// Writes positions `x` (flat, `mesh.dim` per vertex) of `mesh` as a Wavefront OBJ file.
pub fn write_obj(path: &Path, mesh: &Mesh, x: &[f64]) -> TrainerResult<()> {
    let topology = ObjTopology::new(mesh)?;
    check_frame(mesh, x).with_context(|| format!("writing {}", path.display()))?;
    topology
        .write(path, mesh.dim, x)
        .with_context(|| format!("writing {}", path.display()))
}

/// Writes every `every`-th frame (0, every, 2 every, ...) as `dir/{stem}_{frame:05}.obj`,
/// creating `dir` if needed; returns the paths written.
pub fn write_obj_sequence(
    dir: &Path,
    stem: &str,
    mesh: &Mesh,
    frames: &[Vec<f64>],
    every: usize,
) -> TrainerResult<Vec<PathBuf>> {
    if every == 0 {
        bail!("write_obj_sequence: `every` must be at least 1");
    }
    let topology = ObjTopology::new(mesh)?;
    crate::error::fs::create_dir_all(dir)?;
    let mut written = Vec::new();
    for (f, x) in frames.iter().enumerate().step_by(every) {
        let path = dir.join(format!("{stem}_{f:05}.obj"));
        check_frame(mesh, x).with_context(|| format!("frame {f}"))?;
        topology
            .write(&path, mesh.dim, x)
            .with_context(|| format!("writing {}", path.display()))?;
        written.push(path);
    }
    Ok(written)
}

/// Checks the mesh's dimension against its kind and that every element index refers to a
/// vertex of the mesh.
pub(super) fn check_mesh(mesh: &Mesh) -> TrainerResult<()> {
    let dim = match mesh.elements {
        Elements::Triangles(_) => 2,
        _ => 3,
    };
    if mesh.dim != dim || !mesh.rest.len().is_multiple_of(dim) {
        bail!(
            "mesh of dimension {} with {} rest coordinates; its elements need {dim}D",
            mesh.dim,
            mesh.rest.len()
        );
    }
    let n = mesh.num_vertices();
    let bad = |e: usize| TrainerError::Invalid(format!("element {e} refers to a vertex beyond the {n} of the mesh"));
    match &mesh.elements {
        Elements::Tets(t) => t.iter().position(|e| e.iter().any(|&v| v >= n)),
        Elements::Triangles(t) | Elements::Shell(t) => t.iter().position(|e| e.iter().any(|&v| v >= n)),
        Elements::Rods(r) => r.iter().position(|e| e.iter().any(|&v| v >= n)),
    }
    .map_or(Ok(()), |e| Err(bad(e)))
}

/// Checks that `x` has one finite point per vertex of a mesh that passed [`check_mesh`].
pub(super) fn check_frame(mesh: &Mesh, x: &[f64]) -> TrainerResult<()> {
    if x.len() != mesh.rest.len() {
        bail!(
            "{} coordinates for a mesh of {} vertices in {}D",
            x.len(),
            mesh.num_vertices(),
            mesh.dim
        );
    }
    if let Some(i) = x.iter().position(|v| !v.is_finite()) {
        bail!("vertex {} has a non-finite coordinate {}", i / mesh.dim, x[i]);
    }
    Ok(())
}
