//! The contact surface of a body: the primitives contact acts on.
//!
//! 3D solids contribute their boundary triangles (outward, from the tet mesh), the edges of
//! those triangles and their vertices; cloth its triangles and their edges; rods their
//! segments; 2D solids the boundary edges of their triangle mesh (oriented so the outward
//! normal is on the right of each edge for counter-clockwise triangles) and their vertices.

use std::collections::HashMap;

use crate::mesh::{boundary_faces, Elements, Mesh};

/// A body's contact primitives, as indices into its vertices.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ContactSurface {
    /// Coordinates per vertex (2 or 3).
    pub dim: usize,
    /// Sorted vertices that lie on the surface.
    pub vertices: Vec<usize>,
    /// Surface edges: sorted `[low, high]` pairs in 3D; oriented boundary edges in 2D.
    pub edges: Vec<[usize; 2]>,
    /// Surface triangles (3D only), oriented outward for solids.
    pub faces: Vec<[usize; 3]>,
}

impl ContactSurface {
    /// The contact surface of `mesh`.
    pub fn of_mesh(mesh: &Mesh) -> Self {
        let (edges, faces) = match &mesh.elements {
            Elements::Tets(tets) => {
                let faces = boundary_faces(tets);
                (triangle_edges(&faces), faces)
            }
            Elements::Shell(tris) => (triangle_edges(tris), tris.clone()),
            Elements::Triangles(tris) => (boundary_edges_2d(tris), Vec::new()),
            Elements::Rods(strands) => {
                let mut edges: Vec<[usize; 2]> = strands
                    .iter()
                    .flat_map(|s| s.windows(2).map(|w| [w[0].min(w[1]), w[0].max(w[1])]))
                    .collect();
                edges.sort_unstable();
                edges.dedup();
                (edges, Vec::new())
            }
        };
        let mut vertices: Vec<usize> = edges.iter().flatten().chain(faces.iter().flatten()).copied().collect();
        vertices.sort_unstable();
        vertices.dedup();
        ContactSurface {
            dim: mesh.dim,
            vertices,
            edges,
            faces,
        }
    }

    /// Adds the primitives of `other` with its vertex indices shifted by `offset`: the
    /// surfaces of several bodies whose positions are stacked in one vector, the second
    /// body's vertices starting at `offset`.
    pub fn append(&mut self, other: &ContactSurface, offset: usize) {
        assert_eq!(self.dim, other.dim, "surfaces of different dimensions");
        self.vertices.extend(other.vertices.iter().map(|v| v + offset));
        self.vertices.sort_unstable();
        self.vertices.dedup();
        self.edges.extend(other.edges.iter().map(|e| e.map(|v| v + offset)));
        self.faces.extend(other.faces.iter().map(|f| f.map(|v| v + offset)));
    }
}

/// Every edge of the triangles once, as sorted `[low, high]` pairs in ascending order.
pub fn triangle_edges(tris: &[[usize; 3]]) -> Vec<[usize; 2]> {
    let mut edges: Vec<[usize; 2]> = tris
        .iter()
        .flat_map(|t| [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]])
        .map(|[a, b]| [a.min(b), a.max(b)])
        .collect();
    edges.sort_unstable();
    edges.dedup();
    edges
}

/// Edges used by exactly one triangle, in that triangle's winding order, sorted.
pub fn boundary_edges_2d(tris: &[[usize; 3]]) -> Vec<[usize; 2]> {
    let mut count: HashMap<[usize; 2], (usize, [usize; 2])> = HashMap::new();
    for t in tris {
        for e in [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]] {
            count.entry([e[0].min(e[1]), e[0].max(e[1])]).or_insert((0, e)).0 += 1;
        }
    }
    let mut edges: Vec<[usize; 2]> = count.into_values().filter(|(c, _)| *c == 1).map(|(_, e)| e).collect();
    edges.sort_unstable();
    edges
}
