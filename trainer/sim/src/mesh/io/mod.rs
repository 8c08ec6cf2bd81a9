//! Mesh file readers: MEDIT `.mesh`, TetGen / Triangle `.node` + `.ele`, Wavefront `.obj`.
//!
//! Every reader checks the file as it parses (counts, numbers, indices) and then validates the
//! mesh ([`Mesh::validate`]'s checks), reporting problems at the file line of the vertex or
//! element at fault. Tets and 2D triangles that are all negatively oriented are flipped (a file
//! convention); mixed orientations are an error. Unused vertices are an error, not removed,
//! so vertex numbers stay those of the file.

mod medit;
mod obj;
#[cfg(test)]
mod tests;
mod tetgen;

use std::path::Path;

use medit::parse_medit;
pub(crate) use obj::obj_statements;
use obj::parse_obj;
use tetgen::parse_node_ele;

use super::{Culprit, Mesh, Naming};
use crate::error::InputError;

/// What the caller wants a mesh file read as.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshKind {
    /// Whatever the file holds: tets of a 3D `.mesh` or `.node`, triangles of a 2D one, faces
    /// (cloth) or lines (rods) of an `.obj` that holds only one of them.
    Auto,
    /// A volumetric solid: tetrahedra in 3D ([`Elements::Tets`](super::Elements::Tets)).
    Solid,
    /// A planar solid: triangles in 2D ([`Elements::Triangles`](super::Elements::Triangles)).
    Planar,
    /// Cloth: triangles in 3D ([`Elements::Shell`](super::Elements::Shell)).
    Cloth,
    /// Rods: polylines in 3D ([`Elements::Rods`](super::Elements::Rods)).
    Rods,
}

impl MeshKind {
    fn describe(self) -> &'static str {
        match self {
            MeshKind::Auto => "any mesh",
            MeshKind::Solid => "a solid (tetrahedra)",
            MeshKind::Planar => "a planar solid (2D triangles)",
            MeshKind::Cloth => "cloth (3D triangles)",
            MeshKind::Rods => "rods (polylines)",
        }
    }
}

/// Reads the mesh at `path` as `kind`, choosing the format by extension: `.mesh` (MEDIT),
/// `.node` or `.ele` (TetGen / Triangle; the other file of the pair is read from beside it),
/// `.obj` (Wavefront: faces are cloth, fan-triangulated; `l` polylines are rods).
pub fn load(path: &Path, kind: MeshKind) -> Result<Mesh, InputError> {
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase());
    match extension.as_deref() {
        Some("mesh") => parse_medit(&read_text(path)?, path, kind),
        Some("node") => {
            let ele = path.with_extension("ele");
            parse_node_ele(&read_text(path)?, path, &read_text(&ele)?, &ele, kind)
        }
        Some("ele") => {
            let node = path.with_extension("node");
            parse_node_ele(&read_text(&node)?, &node, &read_text(path)?, path, kind)
        }
        Some("obj") => parse_obj(&read_text(path)?, path, kind),
        _ => Err(InputError::file(
            path,
            "unknown mesh format: expected a .mesh, .node (with .ele) or .obj file",
        )),
    }
}

/// The file's text; bytes that are not UTF-8 become replacement characters (and then fail to
/// parse as numbers if they are anywhere but in a comment).
fn read_text(path: &Path) -> Result<String, InputError> {
    let bytes = std::fs::read(path).map_err(|e| InputError::file(path, format!("cannot read: {e}")))?;
    Ok(String::from_utf8_lossy(&bytes).into_owned())
}

// ---------------------------------------------------------------------------------------------
// Shared parsing helpers

/// The non-empty lines of `text` with `#` comments removed: (1-based line number, tokens).
fn content_lines(text: &str) -> impl Iterator<Item = (usize, Vec<&str>)> {
    text.lines().enumerate().filter_map(|(i, line)| {
        let content = line.split('#').next().unwrap_or("");
        let tokens: Vec<&str> = content.split_whitespace().collect();
        (!tokens.is_empty()).then_some((i + 1, tokens))
    })
}

/// A finite coordinate.
fn parse_coordinate(file: &Path, line: usize, token: &str) -> Result<f64, InputError> {
    let value: f64 = token
        .parse()
        .map_err(|_| InputError::line(file, line, format!("`{token}` is not a number (coordinate)")))?;
    if !value.is_finite() {
        return Err(InputError::line(
            file,
            line,
            format!("coordinate `{token}` is not finite"),
        ));
    }
    Ok(value)
}

/// An integer such as a vertex index (which may be negative in `.obj` files).
fn parse_integer(file: &Path, line: usize, token: &str, what: &str) -> Result<i64, InputError> {
    token
        .parse()
        .map_err(|_| InputError::line(file, line, format!("`{token}` is not an integer ({what})")))
}

/// A non-negative count.
fn parse_count(file: &Path, line: usize, token: &str, what: &str) -> Result<usize, InputError> {
    token
        .parse()
        .map_err(|_| InputError::line(file, line, format!("`{token}` is not a non-negative integer ({what})")))
}

/// The 0-based vertex that `index` names in a file numbering from `first` with `count`
/// vertices.
fn vertex_index(file: &Path, line: usize, index: i64, first: i64, count: usize) -> Result<usize, InputError> {
    let last = first.saturating_add(count as i64).saturating_sub(1);
    let offset = index.checked_sub(first).filter(|&o| o >= 0);
    match offset.and_then(|o| usize::try_from(o).ok()) {
        Some(v) if v < count => Ok(v),
        _ => Err(InputError::line(
            file,
            line,
            format!("vertex index {index} is out of range: the vertices are {first}..={last}"),
        )),
    }
}

/// A parsed mesh with where each vertex and element came from, to place validation errors.
struct Sourced<'a> {
    mesh: Mesh,
    vertex_file: &'a Path,
    vertex_lines: Vec<usize>,
    element_file: &'a Path,
    element_lines: Vec<usize>,
    /// The number the file gives its first vertex.
    first_vertex: usize,
}

impl Sourced<'_> {
    /// Orients the mesh positively if it is all inverted, then validates it.
    fn finish(self) -> Result<Mesh, InputError> {
        let mesh = self.mesh.with_positive_orientation();
        let naming = Naming {
            first_vertex: self.first_vertex,
            element_lines: Some(&self.element_lines),
        };
        match mesh.check(&naming) {
            Ok(()) => Ok(mesh),
            Err(problem) => Err(match problem.culprit {
                Culprit::Vertex(v) => match self.vertex_lines.get(v) {
                    Some(&line) => InputError::line(self.vertex_file, line, problem.message),
                    None => InputError::file(self.vertex_file, problem.message),
                },
                Culprit::Element(e) => match self.element_lines.get(e) {
                    Some(&line) => InputError::line(self.element_file, line, problem.message),
                    None => InputError::element(self.element_file, e, problem.message),
                },
                Culprit::Whole => InputError::file(self.element_file, problem.message),
            }),
        }
    }
}
