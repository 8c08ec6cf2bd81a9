//! Broad phase: the primitive pairs of a contact surface that may be within a distance of
//! each other, at one configuration (the barrier's candidates within `dhat`) or at any time
//! of a linear step (the CCD candidates).
//!
//! A 3D surface gives point-triangle pairs (a surface vertex against a face) and edge-edge
//! pairs; a 2D surface gives point-edge pairs. Pairs that share a vertex are left out (their
//! distance is zero by construction; contact between neighbours is carried by the pairs
//! around them). A 3D surface without faces (rods) gives edge-edge pairs only.
//!
//! Two primitives within distance `r` of each other have boxes that overlap once each is
//! inflated by `r / 2` (the gap along every axis is at most the distance), so the pairs
//! found are a superset of the pairs within `r`. [`Candidates::within_brute_force`] and
//! [`Candidates::swept_brute_force`] find the same pairs by testing every pair.

pub mod aabb;
pub mod spatial_hash;

use aabb::Aabb;
use spatial_hash::{
    overlapping_pairs, overlapping_pairs_brute_force, overlapping_self_pairs, overlapping_self_pairs_brute_force,
};

use super::ContactSurface;

/// Candidate primitive pairs of a surface, each list sorted.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Candidates {
    /// `[vertex, face]`: a vertex (index into the positions) and a face (index into
    /// `surface.faces`), 3D.
    pub point_triangle: Vec<[usize; 2]>,
    /// `[edge a, edge b]`, `a < b`, indices into `surface.edges`, 3D.
    pub edge_edge: Vec<[usize; 2]>,
    /// `[vertex, edge]`: a vertex and an edge (index into `surface.edges`), 2D.
    pub point_edge: Vec<[usize; 2]>,
}

impl Candidates {
    /// Pairs whose primitives may be within `dhat` of each other at positions `x`.
    pub fn within(surface: &ContactSurface, x: &[f64], dhat: f64) -> Candidates {
        let boxes = Boxes::new(surface, |verts| Aabb::of_vertices(x, surface.dim, verts), dhat);
        boxes.pairs(surface, false)
    }

    /// Pairs whose primitives may come within `inflation` of each other at some time of the
    /// linear step from `x0` to `x1` (swept boxes; `inflation` 0 for plain CCD).
    pub fn swept(surface: &ContactSurface, x0: &[f64], x1: &[f64], inflation: f64) -> Candidates {
        let boxes = Boxes::new(surface, |verts| Aabb::swept(x0, x1, surface.dim, verts), inflation);
        boxes.pairs(surface, false)
    }

    /// [`Self::within`] by testing every pair.
    pub fn within_brute_force(surface: &ContactSurface, x: &[f64], dhat: f64) -> Candidates {
        let boxes = Boxes::new(surface, |verts| Aabb::of_vertices(x, surface.dim, verts), dhat);
        boxes.pairs(surface, true)
    }

    /// [`Self::swept`] by testing every pair.
    pub fn swept_brute_force(surface: &ContactSurface, x0: &[f64], x1: &[f64], inflation: f64) -> Candidates {
        let boxes = Boxes::new(surface, |verts| Aabb::swept(x0, x1, surface.dim, verts), inflation);
        boxes.pairs(surface, true)
    }

    /// Number of pairs.
    pub fn len(&self) -> usize {
        self.point_triangle.len() + self.edge_edge.len() + self.point_edge.len()
    }

    /// Whether there is no pair.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Boxes of a surface's vertices, edges and faces, each inflated by half the distance.
struct Boxes {
    vertices: Vec<Aabb>,
    edges: Vec<Aabb>,
    faces: Vec<Aabb>,
}

impl Boxes {
    fn new(surface: &ContactSurface, of: impl Fn(&[usize]) -> Aabb, distance: f64) -> Boxes {
        let r = 0.5 * distance;
        Boxes {
            vertices: surface.vertices.iter().map(|&v| of(&[v]).inflated(r)).collect(),
            edges: surface.edges.iter().map(|e| of(e).inflated(r)).collect(),
            faces: surface.faces.iter().map(|f| of(f).inflated(r)).collect(),
        }
    }

    fn pairs(&self, surface: &ContactSurface, brute_force: bool) -> Candidates {
        let (v, e, f) = (&surface.vertices, &surface.edges, &surface.faces);
        let cross = |a: &[Aabb], b: &[Aabb], keep: &dyn Fn(usize, usize) -> bool| {
            if brute_force {
                overlapping_pairs_brute_force(a, b, keep)
            } else {
                overlapping_pairs(a, b, keep)
            }
        };
        let mut out = Candidates::default();
        if surface.dim == 2 {
            out.point_edge = cross(&self.vertices, &self.edges, &|i, j| !e[j].contains(&v[i]));
            for p in &mut out.point_edge {
                p[0] = v[p[0]];
            }
            out.point_edge.sort_unstable();
            return out;
        }
        out.point_triangle = cross(&self.vertices, &self.faces, &|i, j| !f[j].contains(&v[i]));
        for p in &mut out.point_triangle {
            p[0] = v[p[0]];
        }
        out.point_triangle.sort_unstable();
        let apart = |i: usize, j: usize| !e[i].iter().any(|a| e[j].contains(a));
        out.edge_edge = if brute_force {
            overlapping_self_pairs_brute_force(&self.edges, apart)
        } else {
            overlapping_self_pairs(&self.edges, apart)
        };
        out
    }
}
