//! Mesh file readers: MEDIT `.mesh`, TetGen / Triangle `.node` + `.ele`, Wavefront `.obj`.
//!
//! Every reader checks the file as it parses (counts, numbers, indices) and then validates the
//! mesh ([`Mesh::validate`]'s checks), reporting problems at the file line of the vertex or
//! element at fault. Tets and 2D triangles that are all negatively oriented are flipped (a file
//! convention); mixed orientations are an error. Unused vertices are an error, not removed,
//! so vertex numbers stay those of the file.

use std::path::Path;

use super::{Culprit, Elements, Mesh, Naming};
use crate::error::InputError;

/// What the caller wants a mesh file read as.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshKind {
    /// Whatever the file holds: tets of a 3D `.mesh` or `.node`, triangles of a 2D one, faces
    /// (cloth) or lines (rods) of an `.obj` that holds only one of them.
    Auto,
    /// A volumetric solid: tetrahedra in 3D ([`Elements::Tets`]).
    Solid,
    /// A planar solid: triangles in 2D ([`Elements::Triangles`]).
    Planar,
    /// Cloth: triangles in 3D ([`Elements::Shell`]).
    Cloth,
    /// Rods: polylines in 3D ([`Elements::Rods`]).
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

// ---------------------------------------------------------------------------------------------
// MEDIT .mesh

/// Whether a MEDIT token is a number (`nan` and `inf` included: coordinates reject them later
/// with a clearer message) or else a keyword (starting with a letter); anything else is an error.
fn medit_is_number(file: &Path, line: usize, token: &str) -> Result<bool, InputError> {
    if token.parse::<f64>().is_ok() {
        Ok(true)
    } else if token.starts_with(|c: char| c.is_ascii_alphabetic()) {
        Ok(false)
    } else {
        Err(InputError::line(
            file,
            line,
            format!("`{token}` is neither a number nor a keyword"),
        ))
    }
}

/// One record of a MEDIT section: the line it starts on and its numbers.
struct Record<'a> {
    line: usize,
    numbers: &'a [(usize, &'a str)],
}

/// A MEDIT section read as `count` records of `width` numbers.
struct Section<'a> {
    keyword_line: usize,
    records: Vec<Record<'a>>,
}

/// The sections of a MEDIT file that mochi reads.
#[derive(Default)]
struct MeditSections<'a> {
    dimension: Option<usize>,
    vertices: Option<Section<'a>>,
    tetrahedra: Option<Section<'a>>,
    triangles: Option<Section<'a>>,
}

/// Reads a MEDIT `.mesh` file: `Dimension`, `Vertices` (coordinates and a reference),
/// `Tetrahedra` (4 indices and a reference), `Triangles` (3 and a reference), optional `Edges`
/// and any other sections (skipped), `End`. Keywords are case-insensitive, records may span
/// lines, `#` starts a comment, indices are 1-based. `Auto` reads tets in 3D and triangles in
/// 2D; 3D triangles are read only as `Cloth`. The references of the elements read (an
/// integer each) become the mesh's attributes.
fn parse_medit(text: &str, file: &Path, kind: MeshKind) -> Result<Mesh, InputError> {
    let tokens: Vec<(usize, &str)> = content_lines(text)
        .flat_map(|(line, words)| words.into_iter().map(move |w| (line, w)))
        .collect();
    let MeditSections {
        dimension,
        vertices,
        tetrahedra,
        triangles,
    } = medit_sections(&tokens, file)?;

    let Some(dim) = dimension else {
        return Err(InputError::file(file, "no `Dimension`"));
    };
    let Some(vertices) = vertices else {
        return Err(InputError::file(file, "no `Vertices` section"));
    };
    if vertices.records.is_empty() {
        return Err(InputError::line(file, vertices.keyword_line, "`Vertices` is empty"));
    }
    let tetrahedra = tetrahedra.filter(|s| !s.records.is_empty());
    let triangles = triangles.filter(|s| !s.records.is_empty());
    let count = |s: &Option<Section>| s.as_ref().map_or(0, |s| s.records.len());
    let wants_tets = match (kind, dim) {
        (MeshKind::Auto | MeshKind::Solid, 3) => true,
        (MeshKind::Auto | MeshKind::Planar, 2) | (MeshKind::Cloth, 3) => false,
        _ => {
            return Err(InputError::file(
                file,
                format!(
                    "a {dim}D MEDIT file cannot be read as {}{}",
                    kind.describe(),
                    if dim == 2 {
                        "; load it as MeshKind::Planar"
                    } else {
                        "; load it as MeshKind::Solid or MeshKind::Cloth"
                    }
                ),
            ))
        }
    };
    let (section, per_element) = if wants_tets {
        match tetrahedra {
            Some(s) => (s, 4),
            None => {
                return Err(InputError::file(
                    file,
                    match count(&triangles) {
                        0 => "no tetrahedra".to_string(),
                        n => format!(
                            "no tetrahedra (the file has {n} triangles: load it as \
                             MeshKind::Cloth to simulate them as cloth)"
                        ),
                    },
                ))
            }
        }
    } else {
        match triangles {
            Some(s) => (s, 3),
            None => {
                return Err(InputError::file(
                    file,
                    format!("no triangles (the file has {} tetrahedra)", count(&tetrahedra)),
                ))
            }
        }
    };

    let num_vertices = vertices.records.len();
    let mut rest = Vec::with_capacity(num_vertices * dim);
    let mut vertex_lines = Vec::with_capacity(num_vertices);
    for record in &vertices.records {
        for (_, token) in &record.numbers[..dim] {
            rest.push(parse_coordinate(file, record.line, token)?);
        }
        vertex_lines.push(record.line);
    }
    let mut indices = Vec::with_capacity(section.records.len());
    let mut element_lines = Vec::with_capacity(section.records.len());
    let mut references = Vec::with_capacity(section.records.len());
    for record in &section.records {
        let mut element = [0usize; 4];
        for (slot, (_, token)) in element.iter_mut().zip(&record.numbers[..per_element]) {
            let index = parse_integer(file, record.line, token, "vertex index")?;
            *slot = vertex_index(file, record.line, index, 1, num_vertices)?;
        }
        let (line, reference) = record.numbers[per_element];
        references.push(parse_integer(file, line, reference, "element reference")?);
        indices.push(element);
        element_lines.push(record.line);
    }
    let elements = match (per_element, dim) {
        (4, _) => Elements::Tets(indices),
        (_, 2) => Elements::Triangles(indices.iter().map(|e| [e[0], e[1], e[2]]).collect()),
        _ => Elements::Shell(indices.iter().map(|e| [e[0], e[1], e[2]]).collect()),
    };
    Sourced {
        mesh: Mesh {
            dim,
            rest,
            elements,
            attributes: Some(references),
        },
        vertex_file: file,
        vertex_lines,
        element_file: file,
        element_lines,
        first_vertex: 1,
    }
    .finish()
}

/// Splits MEDIT tokens (line, text) into sections, checking each one's counts.
fn medit_sections<'a>(tokens: &'a [(usize, &'a str)], file: &Path) -> Result<MeditSections<'a>, InputError> {
    let mut sections = MeditSections::default();
    let mut i = 0;
    while i < tokens.len() {
        let (keyword_line, keyword) = tokens[i];
        if medit_is_number(file, keyword_line, keyword)? {
            return Err(InputError::line(
                file,
                keyword_line,
                format!("expected a keyword, found the number `{keyword}`"),
            ));
        }
        // The section's numbers run to the next keyword.
        let mut end = i + 1;
        while let Some(&(line, token)) = tokens.get(end) {
            if !medit_is_number(file, line, token)? {
                break;
            }
            end += 1;
        }
        let numbers = &tokens[i + 1..end];
        let next = tokens.get(end).copied();
        let lower = keyword.to_ascii_lowercase();
        match lower.as_str() {
            "end" => break,
            "meshversionformatted" if numbers.len() != 1 => {
                return Err(InputError::line(
                    file,
                    keyword_line,
                    "`MeshVersionFormatted` takes one number",
                ));
            }
            "dimension" => {
                if sections.dimension.is_some() {
                    return Err(InputError::line(file, keyword_line, "second `Dimension`"));
                }
                let d = match numbers {
                    [(line, token)] => parse_count(file, *line, token, "dimension")?,
                    _ => {
                        return Err(InputError::line(
                            file,
                            keyword_line,
                            "`Dimension` takes one number (2 or 3)",
                        ))
                    }
                };
                if d != 2 && d != 3 {
                    return Err(InputError::line(
                        file,
                        keyword_line,
                        format!("dimension {d} is not supported (2 or 3)"),
                    ));
                }
                sections.dimension = Some(d);
            }
            "vertices" | "tetrahedra" | "triangles" => {
                let (slot, width, record) = match lower.as_str() {
                    "vertices" => {
                        let Some(d) = sections.dimension else {
                            return Err(InputError::line(
                                file,
                                keyword_line,
                                "`Vertices` before `Dimension`: the number of coordinates \
                                 is unknown",
                            ));
                        };
                        (&mut sections.vertices, d + 1, "vertex (coordinates and a reference)")
                    }
                    "tetrahedra" => (
                        &mut sections.tetrahedra,
                        5,
                        "tetrahedron (4 vertex indices and a reference)",
                    ),
                    _ => (
                        &mut sections.triangles,
                        4,
                        "triangle (3 vertex indices and a reference)",
                    ),
                };
                if slot.is_some() {
                    return Err(InputError::line(
                        file,
                        keyword_line,
                        format!("second `{keyword}` section"),
                    ));
                }
                *slot = Some(medit_section(
                    file,
                    keyword,
                    keyword_line,
                    numbers,
                    next,
                    width,
                    record,
                )?);
            }
            // Edges, Corners, Ridges, Normals, ...: not needed for simulation.
            _ => {}
        }
        i = end;
    }

    Ok(sections)
}

/// Splits a MEDIT section's numbers (count first) into records of `width` numbers, reporting
/// a wrong count or a record line of the wrong length. `next` is the token that ended the
/// section, if any.
fn medit_section<'a>(
    file: &Path,
    keyword: &str,
    keyword_line: usize,
    numbers: &'a [(usize, &'a str)],
    next: Option<(usize, &str)>,
    width: usize,
    record: &str,
) -> Result<Section<'a>, InputError> {
    let Some(((count_line, count_token), data)) = numbers.split_first() else {
        return Err(InputError::line(
            file,
            keyword_line,
            format!("`{keyword}` needs a count"),
        ));
    };
    let count = parse_count(file, *count_line, count_token, "record count")?;
    let expected = count.checked_mul(width);
    if expected != Some(data.len()) {
        // Find a line whose number of values is not `width` (records one per line, as usual).
        let mut start = 0;
        while start < data.len() {
            let line = data[start].0;
            let len = data[start..].iter().take_while(|(l, _)| *l == line).count();
            if len != width {
                let cause = match next {
                    Some((next_line, token)) if next_line == line => {
                        format!("; `{token}` is not a number")
                    }
                    _ => String::new(),
                };
                return Err(InputError::line(
                    file,
                    line,
                    format!(
                        "a {record} needs {width} numbers, this line has {len} \
                         (in `{keyword}` of line {keyword_line}){cause}"
                    ),
                ));
            }
            start += len;
        }
        let ended = match next {
            Some((line, token)) => format!("the section ends at `{token}` on line {line}"),
            None => "the file ends".to_string(),
        };
        return Err(match expected {
            Some(n) if n < data.len() => InputError::line(
                file,
                data[n].0,
                format!("`{keyword}` of line {keyword_line} declares {count} records; this is one more"),
            ),
            _ => InputError::line(
                file,
                keyword_line,
                format!(
                    "`{keyword}` declares {count} records but only {} follow ({ended})",
                    data.len() / width
                ),
            ),
        });
    }
    let records = data
        .chunks_exact(width)
        .map(|chunk| Record {
            line: chunk[0].0,
            numbers: chunk,
        })
        .collect();
    Ok(Section { keyword_line, records })
}

// ---------------------------------------------------------------------------------------------
// TetGen / Triangle .node + .ele

/// Reads a `.node` file (`<vertices> <dimension> [<attributes> [<boundary markers>]]`, then
/// `<index> <coordinates> [attributes] [marker]` per vertex) and its `.ele` file
/// (`<elements> <vertices per element> [<attributes>]`, then `<index> <vertex indices>
/// [attributes]`): tets in 3D (TetGen), triangles in 2D (Triangle). Vertices are numbered
/// consecutively from the first index in the `.node` file. The first element attribute (a
/// region attribute, which must be an integer) becomes the mesh's attributes; further element
/// attributes and the vertex attributes and markers are checked to be numbers and ignored.
fn parse_node_ele(
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

// ---------------------------------------------------------------------------------------------
// Wavefront .obj

/// Reads a Wavefront `.obj` file: `v x y z [w]` (or `v x y z r g b`) vertices, `f` faces with
/// `v`, `v/vt`, `v//vn` or `v/vt/vn` references (fan-triangulated into cloth triangles), `l`
/// polylines (one rod each, listed from the root). Indices are 1-based; negative ones count
/// back from the last vertex defined so far. Lines ending in `\` continue on the next line.
/// Other statements (`vt`, `vn`, `g`, `o`, `s`, `usemtl`, ...) are ignored. A file must hold
/// faces or lines, not both.
fn parse_obj(text: &str, file: &Path, kind: MeshKind) -> Result<Mesh, InputError> {
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
fn obj_statements(text: &str) -> Vec<(usize, Vec<&str>)> {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::error::Location;
    use crate::mesh::{tet_signed_volume, triangle_signed_area};
    use nalgebra::Vector3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use std::path::PathBuf;

    fn data(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../data").join(name)
    }

    /// Writes `files` (name, text) into a fresh temporary directory and loads the first.
    fn load_files(files: &[(&str, &str)], kind: MeshKind) -> Result<Mesh, InputError> {
        let dir = tempfile::tempdir().unwrap();
        for (name, text) in files {
            std::fs::write(dir.path().join(name), text).unwrap();
        }
        load(&dir.path().join(files[0].0), kind)
    }

    fn load_text(name: &str, text: &str, kind: MeshKind) -> Result<Mesh, InputError> {
        load_files(&[(name, text)], kind)
    }

    /// Asserts the error is at `line` of a file called `name` and its message holds `needle`.
    fn assert_line_error(result: Result<Mesh, InputError>, name: &str, line: usize, needle: &str) {
        let err = result.expect_err("expected an error");
        let shown = err.to_string();
        assert_eq!(err.location, Location::Line(line), "{shown}");
        assert!(err.file.ends_with(name), "{shown}");
        assert!(shown.contains(&format!("{name}:{line}: ")), "{shown}");
        assert!(shown.contains(needle), "`{needle}` not in: {shown}");
    }

    /// Asserts the error is about the file `name` as a whole and its message holds `needle`.
    fn assert_file_error(result: Result<Mesh, InputError>, name: &str, needle: &str) {
        let err = result.expect_err("expected an error");
        let shown = err.to_string();
        assert_eq!(err.location, Location::File, "{shown}");
        assert!(err.file.ends_with(name), "{shown}");
        assert!(shown.contains(needle), "`{needle}` not in: {shown}");
    }

    fn tet_volumes(mesh: &Mesh) -> Vec<f64> {
        let Elements::Tets(tets) = &mesh.elements else {
            panic!("not tets")
        };
        tets.iter()
            .map(|t| {
                let p: Vec<Vector3<f64>> = t.iter().map(|&v| mesh.point(v)).collect();
                tet_signed_volume(&p)
            })
            .collect()
    }

    fn triangle_areas(mesh: &Mesh) -> Vec<f64> {
        let Elements::Triangles(tris) = &mesh.elements else {
            panic!("not 2D triangles")
        };
        tris.iter()
            .map(|t| {
                let p: Vec<Vector3<f64>> = t.iter().map(|&v| mesh.point(v)).collect();
                triangle_signed_area(&p)
            })
            .collect()
    }

    // --- real files -------------------------------------------------------------------------

    #[test]
    fn beam365_mesh_loads_with_positive_tets() {
        let mesh = load(&data("beam365.mesh"), MeshKind::Auto).unwrap();
        assert_eq!(mesh.dim, 3);
        assert_eq!(mesh.num_vertices(), 365);
        assert_eq!(mesh.num_elements(), 1343);
        let volumes = tet_volumes(&mesh);
        assert!(volumes.iter().all(|&v| v > 0.0));
        // The beam spans 1.2 x 1.2 x 4.11 (a box of 5.92); volume summed independently.
        let total: f64 = volumes.iter().sum();
        approx::assert_relative_eq!(total, 5.920910101003435, max_relative = 1e-12);
        assert_eq!(mesh, load(&data("beam365.mesh"), MeshKind::Solid).unwrap());
        // First vertex and first tet as written (1-based `91 70 135 169`).
        assert_eq!(&mesh.rest[..3], &[-0.610143, -0.6336986703486888, 0.03592465556080646]);
        let Elements::Tets(tets) = &mesh.elements else {
            unreachable!()
        };
        assert_eq!(tets[0], [90, 69, 134, 168]);
    }

    #[test]
    fn beam365_mesh_kind_mismatches_are_errors() {
        assert_file_error(
            load(&data("beam365.mesh"), MeshKind::Cloth),
            "beam365.mesh",
            "no triangles (the file has 1343 tetrahedra)",
        );
        assert_file_error(
            load(&data("beam365.mesh"), MeshKind::Planar),
            "beam365.mesh",
            "a 3D MEDIT file cannot be read as a planar solid",
        );
        assert_file_error(
            load(&data("beam365.mesh"), MeshKind::Rods),
            "beam365.mesh",
            "cannot be read as rods",
        );
    }

    #[test]
    fn cantilever_node_ele_loads_with_positive_triangles() {
        let mesh = load(&data("longerCantileverP2.node"), MeshKind::Auto).unwrap();
        assert_eq!(mesh.dim, 2);
        assert_eq!(mesh.num_vertices(), 431);
        assert_eq!(mesh.num_elements(), 738);
        let areas = triangle_areas(&mesh);
        assert!(areas.iter().all(|&a| a > 0.0));
        // The bar is 8 x 1 (its curved-free boundary is sampled exactly up to ~1e-9).
        approx::assert_relative_eq!(areas.iter().sum::<f64>(), 8.0, max_relative = 1e-8);
        assert_eq!(&mesh.rest[..2], &[-4.0, -0.5]);
        // Reading the pair through the .ele path gives the same mesh.
        let via_ele = load(&data("longerCantileverP2.ele"), MeshKind::Planar).unwrap();
        assert_eq!(mesh, via_ele);
    }

    #[test]
    fn cantilever_as_solid_is_an_error() {
        assert_line_error(
            load(&data("longerCantileverP2.node"), MeshKind::Solid),
            "longerCantileverP2.node",
            1,
            "a 2D .node file (Triangle) cannot be read as a solid (tetrahedra); load it as \
             MeshKind::Planar",
        );
    }

    #[test]
    fn all_inverted_beam_is_flipped_back() {
        let original = load(&data("beam365.mesh"), MeshKind::Solid).unwrap();
        let text = std::fs::read_to_string(data("beam365.mesh")).unwrap();
        // Swap the last two indices of every tet: all volumes negative.
        let start = text.find("Tetrahedra").unwrap();
        let mut flipped = text[..start].to_string();
        for line in text[start..].lines() {
            let words: Vec<&str> = line.split_whitespace().collect();
            if words.len() == 5 {
                flipped += &format!("{} {} {} {} {}\n", words[0], words[1], words[3], words[2], words[4]);
            } else {
                flipped += line;
                flipped.push('\n');
            }
        }
        let mesh = load_text("flipped.mesh", &flipped, MeshKind::Solid).unwrap();
        // Flipping swaps the last two indices again, giving back the original tets.
        assert_eq!(mesh, original);
    }

    // --- MEDIT errors -----------------------------------------------------------------------

    /// Two positive unit tets sharing the face (1 2 3), with one line per item:
    /// line 1 `MeshVersionFormatted`, 2 `Dimension`, 3 `Vertices`, 4 count, 5..=9 vertices,
    /// 10 `Tetrahedra`, 11 count, 12..=13 tets, 14 `End`.
    fn two_tets(vertices: &[&str], tets: &[&str]) -> String {
        let mut text = String::from("MeshVersionFormatted 1\nDimension 3\nVertices\n");
        text += &format!("{}\n", vertices.len());
        for v in vertices {
            text += v;
            text.push('\n');
        }
        text += &format!("Tetrahedra\n{}\n", tets.len());
        for t in tets {
            text += t;
            text.push('\n');
        }
        text + "End\n"
    }

    const VERTICES: [&str; 5] = ["0 0 0 0", "1 0 0 0", "0 1 0 0", "0 0 1 0", "1 1 1 0"];
    const TETS: [&str; 2] = ["1 2 3 4 0", "2 3 4 5 0"];

    #[test]
    fn medit_small_file_loads() {
        let mesh = load_text("ok.mesh", &two_tets(&VERTICES, &TETS), MeshKind::Auto).unwrap();
        assert_eq!(mesh.elements, Elements::Tets(vec![[0, 1, 2, 3], [1, 2, 3, 4]]));
        assert!(tet_volumes(&mesh).iter().all(|&v| v > 0.0));
        // Keywords in any case, records spread over lines, comments, Edges and Triangles
        // sections, and a missing `End` are all fine.
        let free = "# a comment\nmeshversionformatted 2\nDIMENSION\n3\nvertices 5\n0 0 0 0 1 0 0 0\n\
                    0 1 0 0 0 0 1 0 1 1 1 0 # five vertices\nEdges 1\n1 2 0\nTriangles 1 1 2 3 0\n\
                    tetrahedra 2\n1 2 3 4 0\n2 3 4\n5 0\n";
        assert_eq!(load_text("free.mesh", free, MeshKind::Solid).unwrap(), mesh);
    }

    #[test]
    fn medit_count_errors() {
        // Header says 5 vertices, 4 follow.
        let text = two_tets(&VERTICES, &TETS).replacen("5\n0 0 0 0", "6\n0 0 0 0", 1);
        assert_line_error(
            load_text("fewer.mesh", &text, MeshKind::Solid),
            "fewer.mesh",
            3,
            "`Vertices` declares 6 records but only 5 follow (the section ends at `Tetrahedra` on \
             line 10)",
        );
        // Header says 1 tet, 2 follow: the extra one is named.
        let text = two_tets(&VERTICES, &TETS).replacen("Tetrahedra\n2", "Tetrahedra\n1", 1);
        assert_line_error(
            load_text("more.mesh", &text, MeshKind::Solid),
            "more.mesh",
            13,
            "declares 1 records; this is one more",
        );
        // The file ends inside the tets.
        let text = two_tets(&VERTICES, &TETS).replace("2 3 4 5 0\nEnd\n", "");
        assert_line_error(
            load_text("truncated.mesh", &text, MeshKind::Solid),
            "truncated.mesh",
            10,
            "declares 2 records but only 1 follow (the file ends)",
        );
    }

    #[test]
    fn medit_missing_sections() {
        let no_tets = "Dimension 3\nVertices\n1\n0 0 0 0\nEnd\n";
        assert_file_error(
            load_text("no_tets.mesh", no_tets, MeshKind::Solid),
            "no_tets.mesh",
            "no tetrahedra",
        );
        let no_vertices = "Dimension 3\nTetrahedra\n1\n1 2 3 4 0\n";
        assert_file_error(
            load_text("no_vertices.mesh", no_vertices, MeshKind::Solid),
            "no_vertices.mesh",
            "no `Vertices` section",
        );
        let no_dimension = "Vertices\n1\n0 0 0 0\n";
        assert_line_error(
            load_text("no_dimension.mesh", no_dimension, MeshKind::Solid),
            "no_dimension.mesh",
            1,
            "`Vertices` before `Dimension`",
        );
        let empty = "Dimension 3\nVertices\n0\nTetrahedra\n0\nEnd\n";
        assert_line_error(
            load_text("empty.mesh", empty, MeshKind::Solid),
            "empty.mesh",
            2,
            "`Vertices` is empty",
        );
        assert_file_error(
            load_text("blank.mesh", "", MeshKind::Auto),
            "blank.mesh",
            "no `Dimension`",
        );
    }

    #[test]
    fn medit_token_errors() {
        let mut vertices = VERTICES;
        vertices[2] = "0 1x 0 0";
        assert_line_error(
            load_text("token.mesh", &two_tets(&vertices, &TETS), MeshKind::Solid),
            "token.mesh",
            7,
            "`1x` is neither a number nor a keyword",
        );
        // A word inside a section ends it early; the count error says where.
        vertices[2] = "0 one 0 0";
        assert_line_error(
            load_text("word.mesh", &two_tets(&vertices, &TETS), MeshKind::Solid),
            "word.mesh",
            7,
            "a vertex (coordinates and a reference) needs 4 numbers, this line has 1 \
             (in `Vertices` of line 3); `one` is not a number",
        );
        vertices[2] = "0 nan 0 0";
        assert_line_error(
            load_text("nan.mesh", &two_tets(&vertices, &TETS), MeshKind::Solid),
            "nan.mesh",
            7,
            "coordinate `nan` is not finite",
        );
        vertices[2] = "0 -inf 0 0";
        assert_line_error(
            load_text("inf.mesh", &two_tets(&vertices, &TETS), MeshKind::Solid),
            "inf.mesh",
            7,
            "coordinate `-inf` is not finite",
        );
        assert_line_error(
            load_text(
                "fraction.mesh",
                &two_tets(&VERTICES, &["1 2 3 4.5 0", TETS[1]]),
                MeshKind::Solid,
            ),
            "fraction.mesh",
            12,
            "`4.5` is not an integer (vertex index)",
        );
    }

    #[test]
    fn medit_element_errors() {
        let cases: [(&str, [&str; 2], usize, &str); 6] = [
            (
                "indices.mesh",
                ["1 2 3 0", TETS[1]],
                12,
                "needs 5 numbers, this line has 4",
            ),
            (
                "range.mesh",
                ["1 2 3 6 0", TETS[1]],
                12,
                "index 6 is out of range: the vertices are 1..=5",
            ),
            (
                "zero.mesh",
                ["0 2 3 4 0", TETS[1]],
                12,
                "vertex index 0 is out of range",
            ),
            (
                "repeat.mesh",
                [TETS[0], "2 3 3 5 0"],
                13,
                "tetrahedron repeats vertex 3",
            ),
            (
                "mixed.mesh",
                [TETS[0], "2 4 3 5 0"],
                13,
                "tetrahedron is inverted relative to the others: signed volume -3.3",
            ),
            (
                "overlap.mesh",
                [TETS[0], "1 2 3 5 0"],
                13,
                "element on line 12: both lie on the same side of their shared face (1 2 3)",
            ),
        ];
        for (name, tets, line, needle) in cases {
            assert_line_error(
                load_text(name, &two_tets(&VERTICES, &tets), MeshKind::Solid),
                name,
                line,
                needle,
            );
        }
    }

    #[test]
    fn medit_geometry_errors() {
        // Vertex 5 flattened into the plane of 2 3 4: the second tet is degenerate.
        let mut vertices = VERTICES;
        vertices[4] = "0.5 0.5 0 0";
        let flat = ["1 2 3 4 0", "2 3 5 1 0"];
        assert_line_error(
            load_text("flat.mesh", &two_tets(&vertices, &flat), MeshKind::Solid),
            "flat.mesh",
            13,
            "tetrahedron is degenerate: signed volume 0e0 (longest edge 1.4",
        );
        // A vertex no tet uses is named at its own line.
        assert_line_error(
            load_text("unused.mesh", &two_tets(&VERTICES, &TETS[..1]), MeshKind::Solid),
            "unused.mesh",
            9,
            "vertex 5 is used by no element, so it would have no mass (1 unused vertices in all)",
        );
        // A third tet on the face (2 3 4) between the first two.
        let vertices = [
            VERTICES[0],
            VERTICES[1],
            VERTICES[2],
            VERTICES[3],
            VERTICES[4],
            "0.1 0.1 0.1 0",
        ];
        let tets = ["1 2 3 4 0", "2 3 4 5 0", "6 2 3 4 0"];
        let text = two_tets(&vertices, &tets);
        assert_line_error(
            load_text("fan.mesh", &text, MeshKind::Solid),
            "fan.mesh",
            15,
            "face (2 3 4) is shared by more than two tetrahedra: also by the element on line 13 \
             and the element on line 14",
        );
    }

    #[test]
    fn medit_two_dimensional_and_surface_files() {
        let planar = "Dimension 2\nVertices\n3\n0 0 0\n1 0 0\n0 1 0\nTriangles\n1\n1 2 3 0\nEnd\n";
        let mesh = load_text("planar.mesh", planar, MeshKind::Auto).unwrap();
        assert_eq!(mesh.dim, 2);
        assert_eq!(mesh.elements, Elements::Triangles(vec![[0, 1, 2]]));
        assert_file_error(
            load_text("planar.mesh", planar, MeshKind::Solid),
            "planar.mesh",
            "a 2D MEDIT file cannot be read as a solid (tetrahedra); load it as MeshKind::Planar",
        );
        let surface = "Dimension 3\nVertices\n3\n0 0 0 0\n1 0 0 0\n0 1 0 0\nTriangles\n1\n1 2 3 0\nEnd\n";
        let mesh = load_text("surface.mesh", surface, MeshKind::Cloth).unwrap();
        assert_eq!(mesh.elements, Elements::Shell(vec![[0, 1, 2]]));
        assert_file_error(
            load_text("surface.mesh", surface, MeshKind::Auto),
            "surface.mesh",
            "no tetrahedra (the file has 1 triangles: load it as MeshKind::Cloth",
        );
        assert_line_error(
            load_text("dim4.mesh", "Dimension 4\n", MeshKind::Auto),
            "dim4.mesh",
            1,
            "dimension 4 is not supported",
        );
    }

    // --- .node / .ele -----------------------------------------------------------------------

    /// A unit square of two triangles, numbered from 0, with an attribute and a marker.
    const SQUARE_NODE: &str = "# square\n4 2 1 1\n0 0 0 7 1\n1 1 0 7 1\n2 1 1 7 1\n3 0 1 7 1\n";
    const SQUARE_ELE: &str = "2 3 1\n0 0 1 2 5\n1 0 2 3 5\n";

    fn load_node_ele(node: &str, ele: &str, kind: MeshKind) -> Result<Mesh, InputError> {
        load_files(&[("sq.node", node), ("sq.ele", ele)], kind)
    }

    #[test]
    fn node_ele_zero_based_with_attributes_loads() {
        let mesh = load_node_ele(SQUARE_NODE, SQUARE_ELE, MeshKind::Auto).unwrap();
        assert_eq!(mesh.rest, vec![0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0]);
        assert_eq!(mesh.elements, Elements::Triangles(vec![[0, 1, 2], [0, 2, 3]]));
        // Clockwise triangles are all flipped.
        let clockwise = "2 3 1\n0 0 2 1 5\n1 0 3 2 5\n";
        let flipped = load_node_ele(SQUARE_NODE, clockwise, MeshKind::Planar).unwrap();
        assert!(triangle_areas(&flipped).iter().all(|&a| a > 0.0));
    }

    #[test]
    fn ele_region_attributes_are_kept() {
        let mesh = load_node_ele(SQUARE_NODE, SQUARE_ELE, MeshKind::Auto).unwrap();
        assert_eq!(mesh.attributes, Some(vec![5, 5]));
        // The first of several attributes, integers written as floats, none without any.
        let two = "2 3 2\n0 0 1 2 -3.0 0.25\n1 0 2 3 4e0 7\n";
        let mesh = load_node_ele(SQUARE_NODE, two, MeshKind::Auto).unwrap();
        assert_eq!(mesh.attributes, Some(vec![-3, 4]));
        let none = "2 3\n0 0 1 2\n1 0 2 3\n";
        assert_eq!(
            load_node_ele(SQUARE_NODE, none, MeshKind::Auto).unwrap().attributes,
            None
        );
        let fraction = "2 3 1\n0 0 1 2 5\n1 0 2 3 0.5\n";
        assert_line_error(
            load_node_ele(SQUARE_NODE, fraction, MeshKind::Auto),
            "sq.ele",
            3,
            "region attribute `0.5` is not an integer",
        );
    }

    #[test]
    fn medit_element_references_are_kept() {
        let tets = ["1 2 3 4 7", "2 3 4 5 -2"];
        let mesh = load_text("ok.mesh", &two_tets(&VERTICES, &tets), MeshKind::Auto).unwrap();
        assert_eq!(mesh.attributes, Some(vec![7, -2]));
        let fraction = ["1 2 3 4 7", "2 3 4 5 1.5"];
        let result = load_text("bad.mesh", &two_tets(&VERTICES, &fraction), MeshKind::Auto);
        assert!(result
            .unwrap_err()
            .to_string()
            .contains("`1.5` is not an integer (element reference)"));
    }

    #[test]
    fn node_kind_mismatch_names_the_header_line() {
        assert_line_error(
            load_node_ele(SQUARE_NODE, SQUARE_ELE, MeshKind::Cloth),
            "sq.node",
            2,
            "a 2D .node file (Triangle) cannot be read as cloth (3D triangles)",
        );
    }

    #[test]
    fn node_ele_tetgen_loads() {
        let node = "5 3 0 0\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n";
        let ele = "2 4 0\n1 1 2 3 4\n2 2 3 4 5\n";
        let mesh = load_files(&[("t.ele", ele), ("t.node", node)], MeshKind::Solid).unwrap();
        assert_eq!(mesh.elements, Elements::Tets(vec![[0, 1, 2, 3], [1, 2, 3, 4]]));
        assert_line_error(
            load_files(&[("t.node", node), ("t.ele", ele)], MeshKind::Planar),
            "t.node",
            1,
            "a 3D .node file (TetGen) cannot be read as a planar solid (2D triangles); load it as \
             MeshKind::Solid",
        );
        assert_line_error(
            load_files(
                &[("t.node", node), ("t.ele", "1 10 0\n1 1 2 3 4 5 6 7 8 9 10\n")],
                MeshKind::Solid,
            ),
            "t.ele",
            1,
            "elements have 10 vertices; the 3D .node file needs 4 (quadratic elements are not \
             supported)",
        );
    }

    #[test]
    fn node_errors() {
        let cases: [(&str, usize, &str); 7] = [
            (
                "5 2 1 1\n0 0 0 7 1\n1 1 0 7 1\n2 1 1 7 1\n3 0 1 7 1\n",
                1,
                "the header declares 5 vertices but the file has only 4",
            ),
            (
                "3 2 1 1\n0 0 0 7 1\n1 1 0 7 1\n2 1 1 7 1\n3 0 1 7 1\n",
                5,
                "the header (line 1) declares 3 vertices; this is one more",
            ),
            (
                "4 2 1 1\n0 0 0 7 1\n1 1 0 7\n2 1 1 7 1\n3 0 1 7 1\n",
                3,
                "needs 5 numbers (index, 2 coordinates, 1 attributes, 1 markers), this one has 4",
            ),
            (
                "4 2 1 1\n0 0 0 7 1\n1 1 0 7 1\n2 1 one 7 1\n3 0 1 7 1\n",
                4,
                "`one` is not a number (coordinate)",
            ),
            (
                "4 2 1 1\n0 0 0 7 1\n1 1 0 7 1\n2 1 NaN 7 1\n3 0 1 7 1\n",
                4,
                "coordinate `NaN` is not finite",
            ),
            (
                "4 2 1 1\n0 0 0 7 1\n1 1 0 7 1\n3 1 1 7 1\n3 0 1 7 1\n",
                4,
                "vertices must be numbered consecutively: expected 2, found 3",
            ),
            ("0 2 0 0\n", 1, "the header declares no vertices"),
        ];
        for (node, line, needle) in cases {
            assert_line_error(load_node_ele(node, SQUARE_ELE, MeshKind::Auto), "sq.node", line, needle);
        }
        assert_file_error(
            load_files(&[("lonely.node", SQUARE_NODE)], MeshKind::Auto),
            "lonely.ele",
            "cannot read",
        );
    }

    #[test]
    fn ele_errors() {
        let cases: [(&str, usize, &str); 7] = [
            (
                "3 3 1\n0 0 1 2 5\n1 0 2 3 5\n",
                1,
                "the header declares 3 elements but the file has only 2",
            ),
            (
                "1 3 1\n0 0 1 2 5\n1 0 2 3 5\n",
                3,
                "the header (line 1) declares 1 elements; this is one more",
            ),
            (
                "2 3 1\n0 0 1 2 5\n1 0 2 3\n",
                3,
                "needs 5 numbers (index, 3 vertex indices, 1 attributes), this one has 4",
            ),
            (
                "2 3 1\n0 0 1 2 5\n1 0 2 4 5\n",
                3,
                "vertex index 4 is out of range: the vertices are 0..=3",
            ),
            ("2 3 1\n0 0 1 2 5\n1 0 2 2 5\n", 3, "triangle repeats vertex 2"),
            (
                "2 3 1\n0 0 1 2 5\n1 0 3 2 5\n",
                3,
                "triangle is inverted relative to the others: signed area -5e-1",
            ),
            (
                "2 3 1\n0 0 1 2 5\n1 0 1 3 5\n",
                3,
                "triangle overlaps the element on line 2",
            ),
        ];
        for (ele, line, needle) in cases {
            assert_line_error(load_node_ele(SQUARE_NODE, ele, MeshKind::Auto), "sq.ele", line, needle);
        }
        // A vertex no triangle uses is reported in the .node file.
        assert_line_error(
            load_node_ele(SQUARE_NODE, "1 3 0\n0 0 1 2\n", MeshKind::Auto),
            "sq.node",
            6,
            "vertex 3 is used by no element",
        );
        // Collinear vertices.
        let node = "3 2\n1 0 0\n2 1 1\n3 2 2\n";
        assert_line_error(
            load_files(&[("line.node", node), ("line.ele", "1 3\n1 1 2 3\n")], MeshKind::Auto),
            "line.ele",
            2,
            "triangle is degenerate: signed area 0e0",
        );
    }

    // --- .obj -------------------------------------------------------------------------------

    #[test]
    fn obj_cloth_with_all_reference_forms() {
        let text = "# two quads\nmtllib x.mtl\no sheet\nv 0 0 0\nv 1 0 0 1.0\nv 2 0 0\nv 0 1 0\n\
                    v 1 1 0 0.5 0.5 0.5\nv 2 1 0\nvt 0 0\nvn 0 0 1\ns off\n\
                    f 1/1/1 2/1/1 5/1/1 4/1/1\nf -5//1 -4 \\\n -1/1 -2\n";
        let mesh = load_text("quads.obj", text, MeshKind::Auto).unwrap();
        assert_eq!(mesh.num_vertices(), 6);
        assert_eq!(mesh.rest[3..6], [1.0, 0.0, 0.0]);
        assert_eq!(
            mesh.elements,
            Elements::Shell(vec![[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
        );
        assert_eq!(mesh, load_text("quads.obj", text, MeshKind::Cloth).unwrap());
        // A pentagon is fanned from its first vertex.
        let pentagon = "v 0 0 0\nv 2 0 0\nv 3 1 0\nv 1 2 0\nv -1 1 0\nf 1 2 3 4 5\n";
        let mesh = load_text("pentagon.obj", pentagon, MeshKind::Cloth).unwrap();
        assert_eq!(mesh.elements, Elements::Shell(vec![[0, 1, 2], [0, 2, 3], [0, 3, 4]]));
    }

    #[test]
    fn obj_rods() {
        let text = "v 0 0 0\nv 0 -1 0\nv 0 -2 0\nv 1 0 0\nv 1 -1 0\nl 1 2 3\nl 4/1 5/2\n";
        let mesh = load_text("rods.obj", text, MeshKind::Auto).unwrap();
        assert_eq!(mesh.elements, Elements::Rods(vec![vec![0, 1, 2], vec![3, 4]]));
        assert_eq!(mesh.num_elements(), 3);
        assert_eq!(mesh, load_text("rods.obj", text, MeshKind::Rods).unwrap());
        assert_file_error(
            load_text("rods.obj", text, MeshKind::Cloth),
            "rods.obj",
            "no faces (`f`) to read as cloth; the file holds lines: load it as MeshKind::Rods",
        );
        assert_file_error(
            load_text("rods.obj", text, MeshKind::Solid),
            "rods.obj",
            ".obj files hold cloth (faces) or rods (lines), not a solid (tetrahedra)",
        );
    }

    #[test]
    fn obj_errors() {
        let square = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";
        let cases: [(&str, usize, &str); 11] = [
            (
                "f 1 2 3\nf 1 3 4\nl 1 2\n",
                7,
                "a line (`l`) after faces (`f`, from line 5): a body is either cloth or rods",
            ),
            ("f 1 2\n", 5, "a face needs at least 3 vertices, this one has 2"),
            ("l 1\n", 5, "a line needs at least 2 vertices, this one has 1"),
            ("f 1 2 0\n", 5, "vertex reference `0`: .obj indices start at 1, not 0"),
            ("f 1 2 5\n", 5, "vertex index 5 is out of range: the vertices are 1..=4"),
            (
                "f 1 2 -5\n",
                5,
                "vertex reference -5 is before the first vertex (4 defined so far)",
            ),
            (
                "f 1 2 3/x\n",
                5,
                "`3/x` is not a vertex reference (expected v, v/vt, v//vn or v/vt/vn)",
            ),
            ("f 1 2 3/1/1/1\n", 5, "is not a vertex reference"),
            ("f 1 2 2\nf 1 3 4\n", 5, "triangle repeats vertex 2"),
            (
                "f 1 2 3\nf 1 4 3\n",
                6,
                "triangle is wound against the element on line 5 across their shared edge (1 3)",
            ),
            ("f 1 2 3\n", 4, "vertex 4 is used by no element"),
        ];
        for (faces, line, needle) in cases {
            let text = format!("{square}{faces}");
            assert_line_error(load_text("bad.obj", &text, MeshKind::Auto), "bad.obj", line, needle);
        }
        assert_line_error(
            load_text("v.obj", "v 0 0\n", MeshKind::Auto),
            "v.obj",
            1,
            "a vertex needs x y z (and optionally w, or r g b colours); this one has 2 numbers",
        );
        assert_line_error(
            load_text("v.obj", "v 0 inf 0\n", MeshKind::Auto),
            "v.obj",
            1,
            "coordinate `inf` is not finite",
        );
        assert_line_error(
            load_text("flat.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", MeshKind::Auto),
            "flat.obj",
            4,
            "triangle is degenerate: area 0e0",
        );
        assert_line_error(
            load_text("short.obj", "v 0 0 0\nv 0 0 0\nl 1 2\n", MeshKind::Auto),
            "short.obj",
            3,
            "rod is degenerate: shortest segment 0e0",
        );
        assert_file_error(
            load_text("none.obj", "v 0 0 0\n", MeshKind::Auto),
            "none.obj",
            "no faces (`f`) or lines (`l`)",
        );
        assert_file_error(
            load_text("empty.obj", "# nothing\n", MeshKind::Auto),
            "empty.obj",
            "no vertices",
        );
        assert_file_error(
            load_text("mesh.stl", "solid", MeshKind::Auto),
            "mesh.stl",
            "unknown mesh format",
        );
    }

    // --- robustness -------------------------------------------------------------------------

    /// Parses `text` as each format (no files needed); must not panic.
    fn parse_all(text: &str) -> [bool; 3] {
        let file = Path::new("fuzz");
        [
            parse_medit(text, file, MeshKind::Auto).is_ok(),
            parse_node_ele(text, file, text, file, MeshKind::Auto).is_ok(),
            parse_obj(text, file, MeshKind::Auto).is_ok(),
        ]
    }

    #[test]
    fn random_bytes_and_token_soup_never_panic() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for _ in 0..300 {
            let len = rng.random_range(0..600);
            let bytes: Vec<u8> = (0..len).map(|_| rng.random()).collect();
            assert_eq!(parse_all(&String::from_utf8_lossy(&bytes)), [false; 3]);
        }
        // Plausible tokens in random order reach deeper into the parsers.
        const WORDS: [&str; 24] = [
            "Dimension",
            "3",
            "2",
            "Vertices",
            "Tetrahedra",
            "Triangles",
            "End",
            "1",
            "0",
            "-1",
            "4",
            "0.5",
            "nan",
            "1e308",
            "99999999999999999999",
            "\n",
            "\n",
            "#",
            "v",
            "f",
            "l",
            "1/2/3",
            "-2//1",
            "\\\n",
        ];
        let mut parsed = 0;
        for _ in 0..3000 {
            let len = rng.random_range(0..80);
            let text: Vec<&str> = (0..len).map(|_| WORDS[rng.random_range(0..WORDS.len())]).collect();
            parsed += parse_all(&text.join(" ")).iter().filter(|&&ok| ok).count();
        }
        // Soup is almost never a valid mesh; what matters is that nothing panicked.
        assert!(parsed < 30, "{parsed}");
    }

    #[test]
    fn truncated_and_mutated_real_files_are_errors_not_panics() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mesh_text = std::fs::read_to_string(data("beam365.mesh")).unwrap();
        let node_text = std::fs::read_to_string(data("longerCantileverP2.node")).unwrap();
        let ele_text = std::fs::read_to_string(data("longerCantileverP2.ele")).unwrap();
        let file = Path::new("cut");
        let full_mesh = parse_medit(&mesh_text, file, MeshKind::Auto).unwrap();
        assert!(parse_node_ele(&node_text, file, &ele_text, file, MeshKind::Auto).is_ok());
        for _ in 0..60 {
            // A cut file either fails or (cut after the last record) reads the same.
            let cut = rng.random_range(0..mesh_text.len());
            match parse_medit(&mesh_text[..cut], file, MeshKind::Auto) {
                Ok(mesh) => assert_eq!(mesh, full_mesh, "cut at {cut}"),
                Err(e) => assert!(matches!(e.location, Location::Line(_) | Location::File), "{e}"),
            }
            // Node and ele files cut after a whole line lack records; cut inside the last
            // line they may still be a valid (different) mesh, so anywhere else: no panic.
            let line_end = |text: &str, at: usize| text[..at].rfind('\n').map_or(0, |i| i + 1);
            let cut = line_end(&node_text, rng.random_range(0..node_text.len()));
            assert!(parse_node_ele(&node_text[..cut], file, &ele_text, file, MeshKind::Auto).is_err());
            let cut = line_end(&ele_text, rng.random_range(0..ele_text.len()));
            assert!(parse_node_ele(&node_text, file, &ele_text[..cut], file, MeshKind::Auto).is_err());
            let cut = rng.random_range(0..ele_text.len());
            let _ = parse_node_ele(&node_text[..cut], file, &ele_text[..cut], file, MeshKind::Auto);
            // A few random bytes overwritten: any result, but no panic.
            let mut bytes = mesh_text.clone().into_bytes();
            for _ in 0..rng.random_range(1..4) {
                let at = rng.random_range(0..bytes.len());
                bytes[at] = rng.random();
            }
            let _ = parse_medit(&String::from_utf8_lossy(&bytes), file, MeshKind::Auto);
            let mut bytes = ele_text.clone().into_bytes();
            let at = rng.random_range(0..bytes.len());
            bytes[at] = b"0123456789 -\n"[rng.random_range(0..13)];
            let _ = parse_node_ele(&node_text, file, &String::from_utf8_lossy(&bytes), file, MeshKind::Auto);
        }
    }
}
