//! Meshes: rest positions and elements of solids (tets), 2D bodies (triangles), cloth
//! (triangles in 3D) and rods (polylines).

pub mod asset;
mod bounds;
pub mod embedding;
pub mod io;
mod mass;
pub mod parts;
pub mod procedural;
mod validate;

pub use bounds::BoxSpec;
use nalgebra::Vector3;

pub(crate) use mass::lumped_masses;
#[cfg(test)]
use validate::sorted_with_parity;
use validate::{Culprit, Naming};

/// Edges of a triangle, in its winding order.
const TRIANGLE_EDGES: [[usize; 2]; 3] = [[0, 1], [1, 2], [2, 0]];

/// Edges of a tet.
const TET_EDGES: [[usize; 2]; 6] = [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]];

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
