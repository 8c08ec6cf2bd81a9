//! Meshes: rest positions and elements of solids (tets), 2D bodies (triangles), cloth
//! (triangles in 3D) and rods (polylines).

pub mod io;
pub mod procedural;

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

/// Boundary faces of a tet mesh, oriented with outward normals for positively oriented tets.
pub fn boundary_faces(tets: &[[usize; 4]]) -> Vec<[usize; 3]> {
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
    let mut faces: Vec<[usize; 3]> = count
        .into_values()
        .filter(|(c, _)| *c == 1)
        .map(|(_, f)| f)
        .collect();
    faces.sort_unstable();
    faces
}
