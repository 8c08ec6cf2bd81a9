//! The MEDIT `.mesh` reader.

use std::path::Path;

use super::{content_lines, parse_coordinate, parse_count, parse_integer, vertex_index, MeshKind, Sourced};
use crate::error::InputError;
use crate::mesh::{Elements, Mesh};

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
pub(super) fn parse_medit(text: &str, file: &Path, kind: MeshKind) -> Result<Mesh, InputError> {
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
