//! Meshes: rest positions and elements of solids (tets), 2D bodies (triangles), cloth
//! (triangles in 3D) and rods (polylines).

pub mod io;
pub mod parts;
pub mod procedural;

use std::collections::HashMap;
use std::path::Path;

use nalgebra::Vector3;

use crate::error::InputError;

/// The elements of a body, which also say what kind of body it is.
#[derive(Clone, Debug, PartialEq)]
pub enum Elements {
    /// Volumetric solid: tetrahedra in 3D.
    Tets(Vec<[usize; 4]>),
    /// Planar solid: triangles in 2D (plane strain).
    Triangles(Vec<[usize; 3]>),
    /// Cloth: triangles in 3D (discrete shell).
    Shell(Vec<[usize; 3]>),
    /// Rods: polylines in 3D, each listed from its root.
    Rods(Vec<Vec<usize>>),
}

/// A body's rest shape and elements.
#[derive(Clone, Debug, PartialEq)]
pub struct Mesh {
    /// Coordinates per vertex: 2 for `Triangles`, 3 otherwise.
    pub dim: usize,
    /// Rest positions, flat, `dim` per vertex.
    pub rest: Vec<f64>,
    /// Elements.
    pub elements: Elements,
    /// Region attribute of each element as the mesh file gives it (the first attribute of a
    /// TetGen / Triangle `.ele` element, the reference of a MEDIT element); `None` for meshes
    /// without them (procedural meshes, `.obj` files, `.ele` files without attributes). Scenes
    /// select materials by it (`[[material.regions]] attribute = ...`).
    pub attributes: Option<Vec<i64>>,
}

impl Mesh {
    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.rest.len() / self.dim
    }

    /// Number of elements (tets, triangles, or rod segments).
    pub fn num_elements(&self) -> usize {
        match &self.elements {
            Elements::Tets(t) => t.len(),
            Elements::Triangles(t) | Elements::Shell(t) => t.len(),
            Elements::Rods(r) => r.iter().map(|s| s.len().saturating_sub(1)).sum(),
        }
    }

    /// Axis-aligned bounding box (min, max) of `x` (flat, `dim` per vertex), padded to 3D.
    pub fn bounding_box(&self, x: &[f64]) -> ([f64; 3], [f64; 3]) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in x.chunks_exact(self.dim) {
            for i in 0..3 {
                let c = p.get(i).copied().unwrap_or(0.0);
                lo[i] = lo[i].min(c);
                hi[i] = hi[i].max(c);
            }
        }
        (lo, hi)
    }

    /// Length of the diagonal of the rest bounding box (the unit of reported errors).
    pub fn rest_diagonal(&self) -> f64 {
        let (lo, hi) = self.bounding_box(&self.rest);
        (0..3).map(|i| (hi[i] - lo[i]).powi(2)).sum::<f64>().sqrt()
    }

    /// Triangles to draw: boundary faces of a tet mesh (outward), all triangles otherwise;
    /// empty for rods.
    pub fn surface_triangles(&self) -> Vec<[usize; 3]> {
        match &self.elements {
            Elements::Tets(tets) => boundary_faces(tets),
            Elements::Triangles(t) | Elements::Shell(t) => t.clone(),
            Elements::Rods(_) => Vec::new(),
        }
    }

    /// Every edge of the elements once, as `[low, high]` vertex pairs in ascending order:
    /// the six edges of each tet, the three of each triangle, the segments of each rod.
    pub fn edges(&self) -> Vec<[usize; 2]> {
        let mut edges: Vec<[usize; 2]> = match &self.elements {
            Elements::Tets(tets) => tets
                .iter()
                .flat_map(|t| TET_EDGES.iter().map(move |&[a, b]| [t[a], t[b]]))
                .collect(),
            Elements::Triangles(tris) | Elements::Shell(tris) => tris
                .iter()
                .flat_map(|t| TRIANGLE_EDGES.iter().map(move |&[a, b]| [t[a], t[b]]))
                .collect(),
            Elements::Rods(strands) => strands
                .iter()
                .flat_map(|s| s.windows(2).map(|w| [w[0], w[1]]))
                .collect(),
        };
        for e in &mut edges {
            e.sort_unstable();
        }
        edges.sort_unstable();
        edges.dedup();
        edges
    }

    /// Sorted vertices that are drawn: those on the surface of a tet mesh, all otherwise.
    pub fn surface_vertices(&self) -> Vec<usize> {
        match &self.elements {
            Elements::Tets(_) => {
                let mut v: Vec<usize> = self.surface_triangles().into_iter().flatten().collect();
                v.sort_unstable();
                v.dedup();
                v
            }
            _ => (0..self.num_vertices()).collect(),
        }
    }
}

/// An element counts as degenerate when its volume (area, length) is at most this fraction of
/// its longest edge cubed (squared; of the mesh's bounding-box diagonal for rod segments).
const DEGENERATE_RELATIVE: f64 = 1e-12;

/// Faces of a tet, opposite each vertex, outward for a positively oriented tet.
const TET_FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];

/// Edges of a triangle, in its winding order.
const TRIANGLE_EDGES: [[usize; 2]; 3] = [[0, 1], [1, 2], [2, 0]];

/// Edges of a tet.
const TET_EDGES: [[usize; 2]; 6] = [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]];

impl Mesh {
    /// The mesh centred on its bounding-box centre and divided by its largest bounding-box
    /// extent (as the peer project prepares every mesh), so it fits a unit box around the origin.
    /// A mesh whose extent is zero or not finite is only centred (if it can be).
    pub fn normalized(&self) -> Mesh {
        if self.num_vertices() == 0 {
            return self.clone();
        }
        let (lo, hi) = self.bounding_box(&self.rest);
        let extent = (0..self.dim).map(|i| hi[i] - lo[i]).fold(0.0, f64::max);
        let scale = if extent > 0.0 && extent.is_finite() {
            1.0 / extent
        } else {
            1.0
        };
        let centre: Vec<f64> = (0..self.dim).map(|i| 0.5 * (lo[i] + hi[i])).collect();
        let rest = self
            .rest
            .chunks_exact(self.dim)
            .flat_map(|p| p.iter().zip(&centre).map(|(c, m)| (c - m) * scale))
            .collect();
        Mesh { rest, ..self.clone() }
    }

    /// The mesh with axis `i` of every rest position multiplied by `factors[i]`. Missing factors
    /// count as 1 and extra ones are ignored (so `[1.0, 0.5, 1.0]` halves y of a 2D mesh too).
    /// When the factors mirror the mesh (their product is negative) every element's winding is
    /// flipped so that orientations stay positive. Zero factors give a degenerate mesh, which
    /// [`Mesh::validate`] reports.
    pub fn scaled(&self, factors: &[f64]) -> Mesh {
        let factor = |i: usize| factors.get(i).copied().unwrap_or(1.0);
        let rest = self
            .rest
            .chunks_exact(self.dim)
            .flat_map(|p| p.iter().enumerate().map(move |(i, c)| c * factor(i)))
            .collect();
        let mut elements = self.elements.clone();
        if (0..self.dim).map(factor).product::<f64>() < 0.0 {
            flip_orientation(&mut elements);
        }
        Mesh {
            dim: self.dim,
            rest,
            elements,
            attributes: self.attributes.clone(),
        }
    }

    /// The mesh with every tet (2D triangle) flipped when none is positively oriented and some
    /// are negatively oriented: a file convention, not an error. Mixed orientations are left as
    /// they are for [`Mesh::validate`] to report. Cloth and rods are returned unchanged.
    pub fn with_positive_orientation(mut self) -> Mesh {
        if let Some(measures) = self.signed_measures() {
            let any_positive = measures.iter().any(|&m| m > 0.0);
            let any_negative = measures.iter().any(|&m| m < 0.0);
            if any_negative && !any_positive {
                flip_orientation(&mut self.elements);
            }
        }
        self
    }

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

    /// Signed volumes (areas) of the tets (2D triangles); `None` for cloth and rods or when
    /// an index is out of range.
    fn signed_measures(&self) -> Option<Vec<f64>> {
        let elements = self.element_slices();
        let kind = self.kind();
        if !matches!(kind, Kind::Tets | Kind::Triangles) || self.dim != kind.dim() {
            return None;
        }
        let n = self.num_vertices();
        if elements.iter().flat_map(|e| e.iter()).any(|&v| v >= n) {
            return None;
        }
        Some(
            elements
                .iter()
                .map(|vertices| {
                    let points: Vec<Vector3<f64>> = vertices.iter().map(|&v| self.point(v)).collect();
                    match kind {
                        Kind::Tets => tet_signed_volume(&points),
                        _ => triangle_signed_area(&points),
                    }
                })
                .collect(),
        )
    }

    /// Rest position of vertex `v` (in range) padded to 3D.
    fn point(&self, v: usize) -> Vector3<f64> {
        let p = &self.rest[v * self.dim..(v + 1) * self.dim];
        Vector3::new(p[0], p[1], p.get(2).copied().unwrap_or(0.0))
    }

    /// The vertex lists of all elements (rods: whole polylines).
    fn element_slices(&self) -> Vec<&[usize]> {
        match &self.elements {
            Elements::Tets(t) => t.iter().map(|e| e.as_slice()).collect(),
            Elements::Triangles(t) | Elements::Shell(t) => t.iter().map(|e| e.as_slice()).collect(),
            Elements::Rods(r) => r.iter().map(|e| e.as_slice()).collect(),
        }
    }

    fn kind(&self) -> Kind {
        match self.elements {
            Elements::Tets(_) => Kind::Tets,
            Elements::Triangles(_) => Kind::Triangles,
            Elements::Shell(_) => Kind::Shell,
            Elements::Rods(_) => Kind::Rods,
        }
    }

    fn element_noun(&self) -> &'static str {
        self.kind().noun()
    }

    fn element_noun_plural(&self) -> &'static str {
        self.kind().noun_plural()
    }
}

/// What an [`Elements`] holds, without the data.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Kind {
    Tets,
    Triangles,
    Shell,
    Rods,
}

impl Kind {
    fn dim(self) -> usize {
        if self == Kind::Triangles {
            2
        } else {
            3
        }
    }

    fn noun(self) -> &'static str {
        match self {
            Kind::Tets => "tetrahedron",
            Kind::Triangles | Kind::Shell => "triangle",
            Kind::Rods => "rod",
        }
    }

    fn noun_plural(self) -> &'static str {
        match self {
            Kind::Tets => "tetrahedra",
            Kind::Triangles | Kind::Shell => "triangles",
            Kind::Rods => "rods",
        }
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
fn sorted_with_parity<const K: usize>(mut facet: [usize; K]) -> ([usize; K], bool) {
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

/// Reverses the orientation of every tet and triangle; rods are unchanged.
fn flip_orientation(elements: &mut Elements) {
    match elements {
        Elements::Tets(tets) => tets.iter_mut().for_each(|t| t.swap(2, 3)),
        Elements::Triangles(tris) | Elements::Shell(tris) => tris.iter_mut().for_each(|t| t.swap(1, 2)),
        Elements::Rods(_) => {}
    }
}

/// Signed volume of the tet `p[0..4]` (the energy module's definition).
fn tet_signed_volume(p: &[Vector3<f64>]) -> f64 {
    crate::energy::tet::signed_volume([0, 1, 2, 3].map(|i| p[i].into()))
}

/// Signed area of the 2D triangle `p[0..3]`, z ignored (the energy module's definition).
fn triangle_signed_area(p: &[Vector3<f64>]) -> f64 {
    crate::energy::tri2d::signed_area([0, 1, 2].map(|i| [p[i].x, p[i].y]))
}

/// Boundary faces of a tet mesh, oriented with outward normals for positively oriented tets.
pub(crate) fn boundary_faces(tets: &[[usize; 4]]) -> Vec<[usize; 3]> {
    use std::collections::HashMap;
    // Faces opposite each vertex, oriented outward for a tet with positive volume.
    const FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]];
    let mut count: HashMap<[usize; 3], (usize, [usize; 3])> = HashMap::new();
    for t in tets {
        for f in FACES {
            let face = [t[f[0]], t[f[1]], t[f[2]]];
            let mut key = face;
            key.sort_unstable();
            count.entry(key).or_insert((0, face)).0 += 1;
        }
    }
    let mut faces: Vec<[usize; 3]> = count.into_values().filter(|(c, _)| *c == 1).map(|(_, f)| f).collect();
    faces.sort_unstable();
    faces
}

#[cfg(test)]
mod tests;
