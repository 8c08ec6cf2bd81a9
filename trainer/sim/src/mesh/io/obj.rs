//! The Wavefront `.obj` reader.

use std::path::Path;

use super::{parse_coordinate, vertex_index, MeshKind, Sourced};
use crate::error::InputError;
use crate::mesh::{Elements, Mesh};

/// Reads a Wavefront `.obj` file: `v x y z [w]` (or `v x y z r g b`) vertices, `f` faces with
/// `v`, `v/vt`, `v//vn` or `v/vt/vn` references (fan-triangulated into cloth triangles), `l`
/// polylines (one rod each, listed from the root). Indices are 1-based; negative ones count
/// back from the last vertex defined so far. Lines ending in `\` continue on the next line.
/// Other statements (`vt`, `vn`, `g`, `o`, `s`, `usemtl`, ...) are ignored. A file must hold
/// faces or lines, not both.
pub(super) fn parse_obj(text: &str, file: &Path, kind: MeshKind) -> Result<Mesh, InputError> {
    let mut rest = Vec::new();
    let mut vertex_lines = Vec::new();
    // (line, 1-based or negative references) of each face and polyline.
    let mut faces: Vec<(usize, Vec<i64>)> = Vec::new();
    let mut polylines: Vec<(usize, Vec<i64>)> = Vec::new();
    for (line, tokens) in obj_statements(text) {
        let Some((&statement, arguments)) = tokens.split_first() else {
            continue;
        };
        match statement {
            "v" => {
                if ![3, 4, 6].contains(&arguments.len()) {
                    return Err(InputError::line(
                        file,
                        line,
                        format!(
                            "a vertex needs x y z (and optionally w, or r g b colours); \
                             this one has {} numbers",
                            arguments.len()
                        ),
                    ));
                }
                for token in &arguments[..3] {
                    rest.push(parse_coordinate(file, line, token)?);
                }
                for token in &arguments[3..] {
                    token
                        .parse::<f64>()
                        .map_err(|_| InputError::line(file, line, format!("`{token}` is not a number")))?;
                }
                vertex_lines.push(line);
            }
            "f" | "l" => {
                let (needed, what) = if statement == "f" { (3, "a face") } else { (2, "a line") };
                if arguments.len() < needed {
                    return Err(InputError::line(
                        file,
                        line,
                        format!(
                            "{what} needs at least {needed} vertices, this one has {}",
                            arguments.len()
                        ),
                    ));
                }
                let mut references = Vec::with_capacity(arguments.len());
                for argument in arguments {
                    let index = obj_reference(file, line, argument, statement)?;
                    // Resolve negative references against the vertices defined so far.
                    let absolute = if index < 0 {
                        (vertex_lines.len() as i64).saturating_add(index + 1)
                    } else {
                        index
                    };
                    if absolute < 1 {
                        return Err(InputError::line(
                            file,
                            line,
                            format!(
                                "vertex reference {index} is before the first vertex \
                                 ({} defined so far)",
                                vertex_lines.len()
                            ),
                        ));
                    }
                    references.push(absolute);
                }
                if statement == "f" {
                    faces.push((line, references));
                } else {
                    polylines.push((line, references));
                }
            }
            _ => {}
        }
    }

    if vertex_lines.is_empty() {
        return Err(InputError::file(file, "no vertices (`v`)"));
    }
    let first_line = |items: &[(usize, Vec<i64>)]| items.first().map_or(0, |(l, _)| *l);
    let cloth = match kind {
        MeshKind::Solid | MeshKind::Planar => {
            return Err(InputError::file(
                file,
                format!(".obj files hold cloth (faces) or rods (lines), not {}", kind.describe()),
            ))
        }
        _ if !faces.is_empty() && !polylines.is_empty() => {
            let (face_line, polyline_line) = (first_line(&faces), first_line(&polylines));
            let (later, message) = if face_line > polyline_line {
                (
                    face_line,
                    format!("a face (`f`) after lines (`l`, from line {polyline_line})"),
                )
            } else {
                (
                    polyline_line,
                    format!("a line (`l`) after faces (`f`, from line {face_line})"),
                )
            };
            return Err(InputError::line(
                file,
                later,
                format!("{message}: a body is either cloth or rods, not both"),
            ));
        }
        MeshKind::Cloth if faces.is_empty() => {
            return Err(InputError::file(
                file,
                format!(
                    "no faces (`f`) to read as cloth{}",
                    if polylines.is_empty() {
                        ""
                    } else {
                        "; the file holds lines: load it as MeshKind::Rods"
                    }
                ),
            ))
        }
        MeshKind::Rods if polylines.is_empty() => {
            return Err(InputError::file(
                file,
                format!(
                    "no lines (`l`) to read as rods{}",
                    if faces.is_empty() {
                        ""
                    } else {
                        "; the file holds faces: load it as MeshKind::Cloth"
                    }
                ),
            ))
        }
        MeshKind::Cloth => true,
        MeshKind::Rods => false,
        _ if !faces.is_empty() => true,
        _ if !polylines.is_empty() => false,
        _ => {
            return Err(InputError::file(
                file,
                "no faces (`f`) or lines (`l`): nothing to simulate",
            ))
        }
    };

    let num_vertices = vertex_lines.len();
    let mut element_lines = Vec::new();
    let elements = if cloth {
        let mut triangles = Vec::new();
        for (line, references) in &faces {
            let vertices = obj_vertices(file, *line, references, num_vertices)?;
            for k in 1..vertices.len() - 1 {
                triangles.push([vertices[0], vertices[k], vertices[k + 1]]);
                element_lines.push(*line);
            }
        }
        Elements::Shell(triangles)
    } else {
        let mut rods = Vec::new();
        for (line, references) in &polylines {
            rods.push(obj_vertices(file, *line, references, num_vertices)?);
            element_lines.push(*line);
        }
        Elements::Rods(rods)
    };
    Sourced {
        mesh: Mesh {
            dim: 3,
            rest,
            elements,
            attributes: None,
        },
        vertex_file: file,
        vertex_lines,
        element_file: file,
        element_lines,
        first_vertex: 1,
    }
    .finish()
}

/// The statements of an `.obj` file: (first line, tokens), with `#` comments removed and
/// lines ending in `\` joined to the next.
pub(crate) fn obj_statements(text: &str) -> Vec<(usize, Vec<&str>)> {
    let mut statements: Vec<(usize, Vec<&str>)> = Vec::new();
    let mut continuing = false;
    for (i, line) in text.lines().enumerate() {
        let content = line.split('#').next().unwrap_or("").trim_end();
        let (content, continues) = match content.strip_suffix('\\') {
            Some(c) => (c, true),
            None => (content, false),
        };
        let tokens = content.split_whitespace();
        match statements.last_mut() {
            Some((_, previous)) if continuing => previous.extend(tokens),
            _ => statements.push((i + 1, tokens.collect())),
        }
        continuing = continues;
    }
    statements.retain(|(_, tokens)| !tokens.is_empty());
    statements
}

/// The vertex index (1-based, or negative) of a face or line reference `v[/vt[/vn]]`.
fn obj_reference(file: &Path, line: usize, argument: &str, statement: &str) -> Result<i64, InputError> {
    let parts: Vec<&str> = argument.split('/').collect();
    let max_parts = if statement == "f" { 3 } else { 2 };
    let malformed = || {
        InputError::line(
            file,
            line,
            format!(
                "`{argument}` is not a vertex reference (expected {})",
                if statement == "f" {
                    "v, v/vt, v//vn or v/vt/vn"
                } else {
                    "v or v/vt"
                }
            ),
        )
    };
    if parts.len() > max_parts || parts[1..].iter().any(|p| !p.is_empty() && p.parse::<i64>().is_err()) {
        return Err(malformed());
    }
    let index: i64 = parts[0].parse().map_err(|_| malformed())?;
    if index == 0 {
        return Err(InputError::line(
            file,
            line,
            format!("vertex reference `{argument}`: .obj indices start at 1, not 0"),
        ));
    }
    Ok(index)
}

/// 0-based vertices of resolved 1-based references.
fn obj_vertices(file: &Path, line: usize, references: &[i64], num_vertices: usize) -> Result<Vec<usize>, InputError> {
    references
        .iter()
        .map(|&r| vertex_index(file, line, r, 1, num_vertices))
        .collect()
}
