//! Checking that a mesh can be simulated ([`Mesh::validate`]), with errors that name the
//! vertex or element as numbered in its file.

use std::collections::HashMap;
use std::path::Path;

use nalgebra::Vector3;

use super::{tet_signed_volume, triangle_signed_area, Elements, Kind, Mesh, TRIANGLE_EDGES};
use crate::error::InputError;

/// An element counts as degenerate when its volume (area, length) is at most this fraction of
/// its longest edge cubed (squared; of the mesh's bounding-box diagonal for rod segments).
const DEGENERATE_RELATIVE: f64 = 1e-12;

/// Faces of a tet, opposite each vertex, outward for a positively oriented tet.
const TET_FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];

impl Mesh {
    /// Checks that the mesh can be simulated; errors name `source` and the vertex or element.
    ///
    /// Checked: coordinates per vertex match the element kind; at least one vertex and one
    /// element; finite coordinates; vertex indices in range and not repeated within an element;
    /// rods of at least 2 vertices; every vertex used by some element (a vertex of no element
    /// would have no mass, so it is an error rather than silently dropped: the numbering stays
    /// that of the file); no degenerate (zero volume, area or length) elements; tets and 2D
    /// triangles all positively oriented; no face (edge) shared by more than two tets
    /// (triangles); no two elements on the same side of a shared face; cloth triangles wound
    /// consistently across shared edges. Element indices of rods are rod indices.
    pub fn validate(&self, source: &Path) -> Result<(), InputError> {
        let naming = Naming {
            first_vertex: 0,
            element_lines: None,
        };
        self.check(&naming).map_err(|problem| match problem.culprit {
            Culprit::Element(e) => InputError::element(source, e, problem.message),
            Culprit::Whole | Culprit::Vertex(_) => InputError::file(source, problem.message),
        })
    }

    /// [`Mesh::validate`] with vertices and elements named as `naming` says.
    pub(crate) fn check(&self, naming: &Naming) -> Result<(), MeshDefect> {
        let expected_dim = match self.elements {
            Elements::Triangles(_) => 2,
            _ => 3,
        };
        if self.dim != expected_dim {
            return Err(MeshDefect::whole(format!(
                "{} need {expected_dim} coordinates per vertex, the mesh has {}",
                self.element_noun_plural(),
                self.dim
            )));
        }
        if !self.rest.chunks_exact(self.dim).remainder().is_empty() {
            return Err(MeshDefect::whole(format!(
                "{} coordinates is not a whole number of {}D vertices",
                self.rest.len(),
                self.dim
            )));
        }
        let num_vertices = self.num_vertices();
        if num_vertices == 0 {
            return Err(MeshDefect::whole("the mesh has no vertices"));
        }
        let elements = self.element_slices();
        if elements.is_empty() {
            return Err(MeshDefect::whole(format!(
                "the mesh has no {}",
                self.element_noun_plural()
            )));
        }
        if let Some(attributes) = &self.attributes {
            if attributes.len() != elements.len() {
                return Err(MeshDefect::whole(format!(
                    "{} element attributes for {} {}",
                    attributes.len(),
                    elements.len(),
                    self.element_noun_plural()
                )));
            }
        }
        for (v, p) in self.rest.chunks_exact(self.dim).enumerate() {
            if !p.iter().all(|c| c.is_finite()) {
                return Err(MeshDefect::vertex(
                    v,
                    format!("vertex {} has a non-finite coordinate {p:?}", naming.vertex(v)),
                ));
            }
        }
        self.check_indices(&elements, naming)?;
        self.check_measures(&elements)?;
        match &self.elements {
            Elements::Tets(_) => check_shared_facets(&elements, &TET_FACES, self.kind(), naming),
            Elements::Triangles(_) | Elements::Shell(_) => {
                check_shared_facets(&elements, &TRIANGLE_EDGES, self.kind(), naming)
            }
            Elements::Rods(_) => Ok(()),
        }
    }

    /// Index checks: in range, not repeated in an element, rods long enough, every vertex used.
    fn check_indices(&self, elements: &[&[usize]], naming: &Naming) -> Result<(), MeshDefect> {
        let noun = self.element_noun();
        let num_vertices = self.num_vertices();
        let mut used = vec![false; num_vertices];
        for (e, vertices) in elements.iter().enumerate() {
            if vertices.len() < 2 {
                return Err(MeshDefect::element(
                    e,
                    format!("{noun} has {} vertices, at least 2 are needed", vertices.len()),
                ));
            }
            for (k, &v) in vertices.iter().enumerate() {
                if v >= num_vertices {
                    return Err(MeshDefect::element(
                        e,
                        format!(
                            "{noun} refers to vertex {}, but the vertices are {}..={}",
                            naming.vertex(v),
                            naming.vertex(0),
                            naming.vertex(num_vertices - 1)
                        ),
                    ));
                }
                if vertices[..k].contains(&v) {
                    return Err(MeshDefect::element(
                        e,
                        format!("{noun} repeats vertex {}", naming.vertex(v)),
                    ));
                }
                used[v] = true;
            }
        }
        if let Some(v) = used.iter().position(|&u| !u) {
            let unused = used.iter().filter(|&&u| !u).count();
            return Err(MeshDefect::vertex(
                v,
                format!(
                    "vertex {} is used by no element, so it would have no mass \
                     ({unused} unused vertices in all)",
                    naming.vertex(v)
                ),
            ));
        }
        Ok(())
    }

    /// Degenerate elements, and orientation of tets and 2D triangles. Indices must be in range.
    fn check_measures(&self, elements: &[&[usize]]) -> Result<(), MeshDefect> {
        let noun = self.element_noun();
        let kind = self.kind();
        let diagonal = self.rest_diagonal();
        let mut signed = Vec::with_capacity(elements.len());
        for (e, vertices) in elements.iter().enumerate() {
            let points: Vec<Vector3<f64>> = vertices.iter().map(|&v| self.point(v)).collect();
            // Longest edge of a tet or triangle (all its vertex pairs are edges).
            let longest_edge = if kind == Kind::Rods {
                0.0
            } else {
                points
                    .iter()
                    .enumerate()
                    .flat_map(|(i, p)| points[..i].iter().map(move |q| (p - q).norm()))
                    .fold(0.0, f64::max)
            };
            let (measure, what, tolerance) = match kind {
                Kind::Tets => (
                    tet_signed_volume(&points),
                    "signed volume",
                    DEGENERATE_RELATIVE * longest_edge.powi(3),
                ),
                Kind::Triangles => (
                    triangle_signed_area(&points),
                    "signed area",
                    DEGENERATE_RELATIVE * longest_edge.powi(2),
                ),
                Kind::Shell => (
                    0.5 * (points[1] - points[0]).cross(&(points[2] - points[0])).norm(),
                    "area",
                    DEGENERATE_RELATIVE * longest_edge.powi(2),
                ),
                Kind::Rods => {
                    let shortest = points
                        .windows(2)
                        .map(|s| (s[1] - s[0]).norm())
                        .fold(f64::INFINITY, f64::min);
                    (shortest, "shortest segment", DEGENERATE_RELATIVE * diagonal)
                }
            };
            if measure.abs() <= tolerance {
                let scale = if kind == Kind::Rods {
                    format!("mesh diagonal {diagonal:e}")
                } else {
                    format!("longest edge {longest_edge:e}")
                };
                return Err(MeshDefect::element(
                    e,
                    format!("{noun} is degenerate: {what} {measure:e} ({scale})"),
                ));
            }
            signed.push(measure);
        }
        if matches!(kind, Kind::Tets | Kind::Triangles) {
            let negative = signed.iter().filter(|&&m| m < 0.0).count();
            let positive = signed.len() - negative;
            if positive == 0 {
                return Err(MeshDefect::whole(format!(
                    "all {negative} {} are negatively oriented \
                     (Mesh::with_positive_orientation flips them)",
                    self.element_noun_plural()
                )));
            }
            if negative > 0 {
                // Name the first element of the minority orientation (negative on a tie).
                let minority_negative = negative <= positive;
                let e = signed.iter().position(|&m| (m < 0.0) == minority_negative).unwrap_or(0);
                let what = if kind == Kind::Tets {
                    "signed volume"
                } else {
                    "signed area"
                };
                return Err(MeshDefect::element(
                    e,
                    format!(
                        "{noun} is inverted relative to the others: {what} {:e} \
                         ({positive} {} positive, {negative} negative)",
                        signed[e],
                        self.element_noun_plural()
                    ),
                ));
            }
        }
        Ok(())
    }

    fn element_noun(&self) -> &'static str {
        self.kind().noun()
    }

    fn element_noun_plural(&self) -> &'static str {
        self.kind().noun_plural()
    }
}

/// How validation messages name vertices and elements: as numbered in the source file.
pub(crate) struct Naming<'a> {
    /// The number vertex 0 has in the source (0, 1, or a `.node` file's first index).
    pub first_vertex: usize,
    /// The source line of each element, if it came from a file.
    pub element_lines: Option<&'a [usize]>,
}

impl Naming<'_> {
    fn vertex(&self, v: usize) -> usize {
        v.saturating_add(self.first_vertex)
    }

    fn element(&self, e: usize) -> String {
        match self.element_lines.and_then(|lines| lines.get(e)) {
            Some(line) => format!("the element on line {line}"),
            None => format!("element {e}"),
        }
    }
}

/// What a validation problem is about.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Culprit {
    /// The mesh as a whole.
    Whole,
    /// A 0-based vertex.
    Vertex(usize),
    /// A 0-based element (rod, for rods).
    Element(usize),
}

/// A validation problem, before it is placed in a file.
#[derive(Clone, Debug)]
pub(crate) struct MeshDefect {
    pub culprit: Culprit,
    pub message: String,
}

impl MeshDefect {
    fn whole(message: impl Into<String>) -> Self {
        MeshDefect {
            culprit: Culprit::Whole,
            message: message.into(),
        }
    }
    fn vertex(v: usize, message: String) -> Self {
        MeshDefect {
            culprit: Culprit::Vertex(v),
            message,
        }
    }
    fn element(e: usize, message: String) -> Self {
        MeshDefect {
            culprit: Culprit::Element(e),
            message,
        }
    }
}

/// Checks the facets (faces of tets, edges of triangles) that elements share: no facet in more
/// than two elements, and the two elements on opposite sides (tets, 2D triangles) or wound
/// consistently (cloth). `local` lists each element's facets in outward (winding) order.
fn check_shared_facets<const K: usize>(
    elements: &[&[usize]],
    local: &[[usize; K]],
    kind: Kind,
    naming: &Naming,
) -> Result<(), MeshDefect> {
    let facet_noun = if K == 3 { "face" } else { "edge" };
    // Sorted facet -> (elements holding it, orientation parity of the first).
    let mut seen: HashMap<[usize; K], (Vec<usize>, bool)> = HashMap::new();
    for (e, vertices) in elements.iter().enumerate() {
        for corners in local {
            let facet = corners.map(|c| vertices[c]);
            let (key, parity) = sorted_with_parity(facet);
            let entry = seen.entry(key).or_insert_with(|| (Vec::new(), parity));
            let named = || {
                key.iter()
                    .map(|&v| naming.vertex(v).to_string())
                    .collect::<Vec<_>>()
                    .join(" ")
            };
            match entry.0.as_slice() {
                [] => {}
                [other] if entry.1 == parity => {
                    let message = if kind == Kind::Shell {
                        format!(
                            "triangle is wound against {} across their shared edge ({}); \
                             cloth triangles must all be wound the same way",
                            naming.element(*other),
                            named()
                        )
                    } else {
                        format!(
                            "{} overlaps {}: both lie on the same side of their shared \
                             {facet_noun} ({})",
                            kind.noun(),
                            naming.element(*other),
                            named()
                        )
                    };
                    return Err(MeshDefect::element(e, message));
                }
                [_] => {}
                [first, second, ..] => {
                    return Err(MeshDefect::element(
                        e,
                        format!(
                            "{facet_noun} ({}) is shared by more than two {}: also by {} and {}",
                            named(),
                            kind.noun_plural(),
                            naming.element(*first),
                            naming.element(*second)
                        ),
                    ));
                }
            }
            entry.0.push(e);
        }
    }
    Ok(())
}

/// The facet's vertices sorted, and whether sorting took an odd number of swaps.
pub(super) fn sorted_with_parity<const K: usize>(mut facet: [usize; K]) -> ([usize; K], bool) {
    let mut odd = false;
    for i in 1..K {
        let mut j = i;
        while j > 0 && facet[j - 1] > facet[j] {
            facet.swap(j - 1, j);
            odd = !odd;
            j -= 1;
        }
    }
    (facet, odd)
}
