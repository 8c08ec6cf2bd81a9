//! The TetGen / Triangle `.node` + `.ele` reader.

use std::path::Path;

use super::{content_lines, parse_coordinate, parse_count, parse_integer, vertex_index, MeshKind, Sourced};
use crate::error::InputError;
use crate::mesh::{Elements, Mesh};

/// Reads a `.node` file (`<vertices> <dimension> [<attributes> [<boundary markers>]]`, then
/// `<index> <coordinates> [attributes] [marker]` per vertex) and its `.ele` file
/// (`<elements> <vertices per element> [<attributes>]`, then `<index> <vertex indices>
/// [attributes]`): tets in 3D (TetGen), triangles in 2D (Triangle). Vertices are numbered
/// consecutively from the first index in the `.node` file. The first element attribute (a
/// region attribute, which must be an integer) becomes the mesh's attributes; further element
/// attributes and the vertex attributes and markers are checked to be numbers and ignored.
pub(super) fn parse_node_ele(
    node_text: &str,
    node_file: &Path,
    ele_text: &str,
    ele_file: &Path,
    kind: MeshKind,
) -> Result<Mesh, InputError> {
    let NodeFile {
        header_line,
        dim,
        first,
        rest,
        vertex_lines,
    } = parse_node(node_text, node_file)?;
    let kind_fits = matches!(
        (kind, dim),
        (MeshKind::Auto | MeshKind::Solid, 3) | (MeshKind::Auto | MeshKind::Planar, 2)
    );
    if !kind_fits {
        return Err(InputError::line(
            node_file,
            header_line,
            format!(
                "a {dim}D .node file ({}) cannot be read as {}; load it as {}",
                if dim == 3 { "TetGen" } else { "Triangle" },
                kind.describe(),
                if dim == 3 {
                    "MeshKind::Solid"
                } else {
                    "MeshKind::Planar"
                }
            ),
        ));
    }
    let num_vertices = vertex_lines.len();
    let EleFile {
        elements: indices,
        lines: element_lines,
        attributes,
    } = parse_ele(ele_text, ele_file, dim + 1, first, num_vertices)?;
    let elements = if dim == 3 {
        Elements::Tets(indices)
    } else {
        Elements::Triangles(indices.iter().map(|e| [e[0], e[1], e[2]]).collect())
    };
    Sourced {
        mesh: Mesh {
            dim,
            rest,
            elements,
            attributes,
        },
        vertex_file: node_file,
        vertex_lines,
        element_file: ele_file,
        element_lines,
        first_vertex: usize::try_from(first).unwrap_or(0),
    }
    .finish()
}

/// The contents of a `.node` file.
struct NodeFile {
    header_line: usize,
    /// 2 or 3.
    dim: usize,
    /// The number of the first vertex (0 or 1 as a rule).
    first: i64,
    /// Coordinates, `dim` per vertex.
    rest: Vec<f64>,
    /// The line of each vertex.
    vertex_lines: Vec<usize>,
}

/// Parses a `.node` file.
fn parse_node(text: &str, file: &Path) -> Result<NodeFile, InputError> {
    let mut lines = content_lines(text);
    let Some((header_line, header)) = lines.next() else {
        return Err(InputError::file(file, "empty .node file: no header"));
    };
    if !(2..=4).contains(&header.len()) {
        return Err(InputError::line(
            file,
            header_line,
            format!(
                "the header has {} numbers; expected `<vertices> <dimension> [<attributes> \
                 [<boundary markers>]]`",
                header.len()
            ),
        ));
    }
    let count = parse_count(file, header_line, header[0], "vertex count")?;
    let dim = parse_count(file, header_line, header[1], "dimension")?;
    let attributes = match header.get(2) {
        Some(t) => parse_count(file, header_line, t, "attribute count")?,
        None => 0,
    };
    let markers = match header.get(3) {
        Some(t) => parse_count(file, header_line, t, "boundary marker count")?,
        None => 0,
    };
    if dim != 2 && dim != 3 {
        return Err(InputError::line(
            file,
            header_line,
            format!("dimension {dim} is not supported (2 or 3)"),
        ));
    }
    if markers > 1 {
        return Err(InputError::line(
            file,
            header_line,
            format!("{markers} boundary markers per vertex; the format allows 0 or 1"),
        ));
    }
    if count == 0 {
        return Err(InputError::line(file, header_line, "the header declares no vertices"));
    }
    let width = 1usize
        .saturating_add(dim)
        .saturating_add(attributes)
        .saturating_add(markers);
    let mut first = 0i64;
    let mut rest = Vec::new();
    let mut vertex_lines = Vec::new();
    for (line, tokens) in lines {
        if vertex_lines.len() == count {
            return Err(InputError::line(
                file,
                line,
                format!("the header (line {header_line}) declares {count} vertices; this is one more"),
            ));
        }
        if tokens.len() != width {
            return Err(InputError::line(
                file,
                line,
                format!(
                    "a vertex line needs {width} numbers (index, {dim} coordinates, \
                     {attributes} attributes, {markers} markers), this one has {}",
                    tokens.len()
                ),
            ));
        }
        let index = parse_integer(file, line, tokens[0], "vertex number")?;
        if vertex_lines.is_empty() {
            if index < 0 {
                return Err(InputError::line(
                    file,
                    line,
                    format!("vertex number {index} is negative"),
                ));
            }
            first = index;
        } else {
            let expected = first.saturating_add(vertex_lines.len() as i64);
            if index != expected {
                return Err(InputError::line(
                    file,
                    line,
                    format!(
                        "vertices must be numbered consecutively: expected {expected}, \
                         found {index}"
                    ),
                ));
            }
        }
        for token in &tokens[1..=dim] {
            rest.push(parse_coordinate(file, line, token)?);
        }
        for token in &tokens[1 + dim..] {
            token.parse::<f64>().map_err(|_| {
                InputError::line(file, line, format!("`{token}` is not a number (attribute or marker)"))
            })?;
        }
        vertex_lines.push(line);
    }
    if vertex_lines.len() < count {
        return Err(InputError::line(
            file,
            header_line,
            format!(
                "the header declares {count} vertices but the file has only {}",
                vertex_lines.len()
            ),
        ));
    }
    Ok(NodeFile {
        header_line,
        dim,
        first,
        rest,
        vertex_lines,
    })
}

/// The contents of an `.ele` file.
struct EleFile {
    /// 0-based vertex indices; triangles fill the first 3 slots.
    elements: Vec<[usize; 4]>,
    /// The line of each element.
    lines: Vec<usize>,
    /// The first attribute of each element, when the header declares attributes.
    attributes: Option<Vec<i64>>,
}

/// Parses an `.ele` file of `per_element`-vertex elements (3 or 4).
fn parse_ele(
    text: &str,
    file: &Path,
    per_element: usize,
    first: i64,
    num_vertices: usize,
) -> Result<EleFile, InputError> {
    let mut lines = content_lines(text);
    let Some((header_line, header)) = lines.next() else {
        return Err(InputError::file(file, "empty .ele file: no header"));
    };
    if !(2..=3).contains(&header.len()) {
        return Err(InputError::line(
            file,
            header_line,
            format!(
                "the header has {} numbers; expected `<elements> <vertices per element> \
                 [<attributes>]`",
                header.len()
            ),
        ));
    }
    let count = parse_count(file, header_line, header[0], "element count")?;
    let nodes = parse_count(file, header_line, header[1], "vertices per element")?;
    let attributes = match header.get(2) {
        Some(t) => parse_count(file, header_line, t, "attribute count")?,
        None => 0,
    };
    if nodes != per_element {
        let quadratic = if nodes == per_element * (per_element + 1) / 2 {
            " (quadratic elements are not supported)"
        } else {
            ""
        };
        return Err(InputError::line(
            file,
            header_line,
            format!(
                "elements have {nodes} vertices; the {}D .node file needs {per_element}{quadratic}",
                per_element - 1
            ),
        ));
    }
    if count == 0 {
        return Err(InputError::line(file, header_line, "the header declares no elements"));
    }
    let width = (1 + nodes).saturating_add(attributes);
    let mut elements = Vec::new();
    let mut element_lines = Vec::new();
    let mut region_attributes = Vec::new();
    for (line, tokens) in lines {
        if elements.len() == count {
            return Err(InputError::line(
                file,
                line,
                format!("the header (line {header_line}) declares {count} elements; this is one more"),
            ));
        }
        if tokens.len() != width {
            return Err(InputError::line(
                file,
                line,
                format!(
                    "an element line needs {width} numbers (index, {nodes} vertex indices, \
                     {attributes} attributes), this one has {}",
                    tokens.len()
                ),
            ));
        }
        parse_integer(file, line, tokens[0], "element number")?;
        let mut element = [0usize; 4];
        for (slot, token) in element.iter_mut().zip(&tokens[1..=nodes]) {
            let index = parse_integer(file, line, token, "vertex index")?;
            *slot = vertex_index(file, line, index, first, num_vertices)?;
        }
        for token in &tokens[1 + nodes..] {
            token
                .parse::<f64>()
                .map_err(|_| InputError::line(file, line, format!("`{token}` is not a number (attribute)")))?;
        }
        if let Some(token) = tokens.get(1 + nodes) {
            region_attributes.push(region_attribute(file, line, token)?);
        }
        elements.push(element);
        element_lines.push(line);
    }
    if elements.len() < count {
        return Err(InputError::line(
            file,
            header_line,
            format!(
                "the header declares {count} elements but the file has only {}",
                elements.len()
            ),
        ));
    }
    Ok(EleFile {
        elements,
        lines: element_lines,
        attributes: (attributes > 0).then_some(region_attributes),
    })
}

/// An element's region attribute: an integer, possibly written as a float (`2`, `2.0`, `2e0`).
fn region_attribute(file: &Path, line: usize, token: &str) -> Result<i64, InputError> {
    if let Ok(value) = token.parse::<i64>() {
        return Ok(value);
    }
    let value: f64 = token.parse().unwrap_or(f64::NAN);
    // Integers of magnitude below 2^53 are exact in f64, so the cast below is exact.
    if value.fract() == 0.0 && value.abs() < 9.007_199_254_740_992e15 {
        Ok(value as i64)
    } else {
        Err(InputError::line(
            file,
            line,
            format!("region attribute `{token}` is not an integer (scenes select regions by integer attributes)"),
        ))
    }
}
