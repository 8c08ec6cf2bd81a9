//! Wavefront OBJ and STL surfaces.
//!
//! OBJ: `v`, `vt`, `vn` and `f` (any polygon, fan-triangulated), with `o` / `g` naming parts;
//! statements are split as the simulation-mesh reader splits them (`io::obj_statements`). A
//! render vertex is one distinct `v/vt/vn` triple, as an engine draws it. STL (`stl_io`, ASCII
//! or binary): facets whose corners with identical coordinates are one vertex; STL has no
//! normals per vertex and no UVs.

use std::collections::HashMap;
use std::path::Path;

use super::{Part, Surface};
use crate::error::InputError;
use crate::mesh::io::obj_statements;

/// Reads an OBJ file's faces into a surface.
pub(super) fn read_obj(path: &Path, bytes: &[u8]) -> Result<Surface, InputError> {
    let text = std::str::from_utf8(bytes)
        .map_err(|e| InputError::file(path, format!("not UTF-8 text (an OBJ file is text): {e}")))?;
    let mut positions: Vec<[f64; 3]> = Vec::new();
    let mut normals: Vec<[f64; 3]> = Vec::new();
    let mut uvs: Vec<[f64; 2]> = Vec::new();
    let mut surface = Surface::default();
    // Render vertices: one per distinct (v, vt, vn).
    let mut vertex_of: HashMap<[Option<usize>; 3], usize> = HashMap::new();
    let mut corners: Vec<[Option<usize>; 3]> = Vec::new();
    let mut part_name: Option<String> = None;
    let mut part_start = 0;
    for (line, tokens) in obj_statements(text) {
        let (statement, arguments) = (tokens[0], &tokens[1..]);
        let numbers = |count: usize| -> Result<Vec<f64>, InputError> {
            if arguments.len() < count {
                return Err(InputError::line(
                    path,
                    line,
                    format!("`{statement}` needs {count} numbers, this one has {}", arguments.len()),
                ));
            }
            arguments[..count]
                .iter()
                .map(|t| {
                    t.parse::<f64>()
                        .map_err(|_| InputError::line(path, line, format!("`{t}` is not a number")))
                })
                .collect()
        };
        match statement {
            "v" => {
                let p = numbers(3)?;
                positions.push([p[0], p[1], p[2]]);
            }
            "vn" => {
                let n = numbers(3)?;
                normals.push([n[0], n[1], n[2]]);
            }
            "vt" => {
                let t = numbers(if arguments.len() >= 2 { 2 } else { 1 })?;
                uvs.push([t[0], t.get(1).copied().unwrap_or(0.0)]);
            }
            "o" | "g" => {
                if surface.triangles.len() > part_start {
                    surface.parts.push(Part {
                        name: part_name.take(),
                        triangles: part_start..surface.triangles.len(),
                    });
                }
                part_start = surface.triangles.len();
                part_name = (!arguments.is_empty()).then(|| arguments.join(" "));
            }
            "f" => {
                if arguments.len() < 3 {
                    return Err(InputError::line(
                        path,
                        line,
                        format!("a face needs at least 3 vertices, this one has {}", arguments.len()),
                    ));
                }
                let counts = [positions.len(), uvs.len(), normals.len()];
                let mut face = Vec::with_capacity(arguments.len());
                for argument in arguments {
                    let key = reference(path, line, argument, counts)?;
                    let next = vertex_of.len();
                    let v = *vertex_of.entry(key).or_insert_with(|| {
                        corners.push(key);
                        next
                    });
                    face.push(v);
                }
                for k in 1..face.len() - 1 {
                    surface.triangles.push([face[0], face[k], face[k + 1]]);
                }
            }
            _ => {}
        }
    }
    if surface.triangles.len() > part_start {
        surface.parts.push(Part {
            name: part_name,
            triangles: part_start..surface.triangles.len(),
        });
    }
    let position_of = |c: &[Option<usize>; 3]| c[0].map_or([f64::NAN; 3], |v| positions[v]);
    surface.positions = corners.iter().map(position_of).collect();
    if !corners.is_empty() && corners.iter().all(|c| c[2].is_some()) {
        surface.normals = Some(corners.iter().filter_map(|c| c[2].map(|n| normals[n])).collect());
    }
    if !corners.is_empty() && corners.iter().all(|c| c[1].is_some()) {
        surface.uvs = Some(corners.iter().filter_map(|c| c[1].map(|t| uvs[t])).collect());
    }
    Ok(surface)
}

/// The 0-based `[v, vt, vn]` of a face reference `v[/vt][/vn]` (1-based, or negative counting
/// back from the last defined so far).
fn reference(path: &Path, line: usize, argument: &str, counts: [usize; 3]) -> Result<[Option<usize>; 3], InputError> {
    let parts: Vec<&str> = argument.split('/').collect();
    if parts.len() > 3 || parts[0].is_empty() {
        return Err(InputError::line(
            path,
            line,
            format!("`{argument}` is not a vertex reference (expected v, v/vt, v//vn or v/vt/vn)"),
        ));
    }
    let mut out = [None; 3];
    for (slot, part) in parts.iter().enumerate() {
        if part.is_empty() {
            continue;
        }
        let what = ["vertex", "texture coordinate", "normal"][slot];
        let index: i64 = part
            .parse()
            .map_err(|_| InputError::line(path, line, format!("`{part}` is not an integer ({what} reference)")))?;
        let count = counts[slot] as i64;
        let resolved = if index < 0 { count + index } else { index - 1 };
        if index == 0 || resolved < 0 || resolved >= count {
            return Err(InputError::line(
                path,
                line,
                format!("{what} reference {index} is out of range ({count} defined so far)"),
            ));
        }
        out[slot] = Some(resolved as usize);
    }
    Ok(out)
}

/// Reads an STL file's facets into a surface; corners with bit-identical coordinates are one
/// vertex (as the file's writer meant them).
pub(super) fn read_stl(path: &Path, bytes: &[u8]) -> Result<Surface, InputError> {
    // `stl_io` takes a file as ASCII only when it starts with "solid " (a space); writers also
    // put a tab or a line end there, and such a file would be misread as binary.
    let spaced;
    let bytes = if bytes.starts_with(b"solid")
        && bytes.get(5).is_some_and(|&b| b != b' ' && b.is_ascii_whitespace())
        && !binary_length(bytes)
    {
        spaced = [b"solid ".as_slice(), &bytes[5..]].concat();
        spaced.as_slice()
    } else {
        bytes
    };
    let mut cursor = std::io::Cursor::new(bytes);
    let facets = stl_io::create_stl_reader(&mut cursor)
        .map_err(|e| InputError::file(path, format!("not a readable STL file: {e}")))?;
    let mut surface = Surface::default();
    let mut vertex_of: HashMap<[u32; 3], usize> = HashMap::new();
    for (k, facet) in facets.enumerate() {
        let facet =
            facet.map_err(|e| InputError::element(path, k, format!("facet cannot be read (file truncated?): {e}")))?;
        let mut triangle = [0; 3];
        for (slot, corner) in facet.vertices.iter().enumerate() {
            let key = corner.0.map(f32::to_bits);
            let next = surface.positions.len();
            triangle[slot] = *vertex_of.entry(key).or_insert_with(|| {
                surface.positions.push(corner.0.map(f64::from));
                next
            });
        }
        surface.triangles.push(triangle);
    }
    surface.parts.push(Part {
        name: None,
        triangles: 0..surface.triangles.len(),
    });
    Ok(surface)
}

/// Whether the length of `bytes` is that of a binary STL of the triangle count in its header.
fn binary_length(bytes: &[u8]) -> bool {
    bytes.len() >= 84 && {
        let count = u32::from_le_bytes([bytes[80], bytes[81], bytes[82], bytes[83]]) as usize;
        bytes.len() == 84 + 50 * count
    }
}
