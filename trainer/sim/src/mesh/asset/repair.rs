//! What a tet mesher needs from a surface, and what is wrong with one: coincident vertices
//! welded, zero-area and repeated triangles dropped, faces oriented consistently and outward;
//! holes (boundary edges), non-manifold edges and self-intersections found and reported.
//!
//! The mesher wants a closed, manifold, non-self-intersecting surface. fTetWild copes with
//! less (it meshes the inside by winding number), so those three defects are errors by
//! default and warnings when the caller accepts them ([`RepairPolicy`]); an empty surface, a
//! non-finite coordinate or a surface of zero-area triangles only is always an error.

use std::collections::HashMap;
use std::path::Path;

use super::Surface;
use crate::contact::intersection::intersecting_pairs;
use crate::contact::ContactSurface;
use crate::error::InputError;
use crate::mesh::{Elements, Mesh};

/// Vertices closer than this fraction of the bounding-box diagonal are welded by default.
pub const DEFAULT_WELD_TOLERANCE: f64 = 1e-6;

/// Which defects [`repair`] accepts (reports as warnings) instead of refusing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RepairPolicy {
    /// Weld tolerance, relative to the bounding-box diagonal.
    pub weld_tolerance: f64,
    /// Accept holes (boundary edges).
    pub open: bool,
    /// Accept edges shared by more than two triangles.
    pub non_manifold: bool,
    /// Accept triangles crossing each other.
    pub self_intersecting: bool,
}

impl Default for RepairPolicy {
    fn default() -> Self {
        RepairPolicy {
            weld_tolerance: DEFAULT_WELD_TOLERANCE,
            open: false,
            non_manifold: false,
            self_intersecting: false,
        }
    }
}

impl RepairPolicy {
    /// A policy that reports every defect but refuses none of the three a robust mesher takes.
    pub fn accepting_defects() -> Self {
        RepairPolicy {
            open: true,
            non_manifold: true,
            self_intersecting: true,
            ..RepairPolicy::default()
        }
    }
}

/// What repair found and did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RepairReport {
    /// Vertices and triangles read.
    pub input_vertices: usize,
    /// Triangles read.
    pub input_triangles: usize,
    /// Vertices after welding.
    pub welded_vertices: usize,
    /// Triangles of zero area (or with a repeated vertex after welding) dropped.
    pub degenerate_triangles: usize,
    /// Triangles repeating another's vertices dropped.
    pub duplicate_triangles: usize,
    /// Triangles flipped to agree with their neighbours or to face outward.
    pub flipped_triangles: usize,
    /// Connected pieces of the surface.
    pub components: usize,
    /// Edges used by one triangle only.
    pub boundary_edges: usize,
    /// Closed loops (or chains) of boundary edges: the holes.
    pub holes: usize,
    /// Edges used by more than two triangles.
    pub non_manifold_edges: usize,
    /// Components whose faces cannot be oriented consistently (Möbius-like, or non-manifold).
    pub non_orientable_components: usize,
    /// Edge-triangle pairs crossing each other (pairs sharing a vertex are not tested).
    pub self_intersections: usize,
    /// Enclosed volume after orientation (positive: outward), in the asset's units cubed.
    pub volume: f64,
}

impl RepairReport {
    /// One-line summary of the findings.
    pub fn summary(&self) -> String {
        format!(
            "{} triangles, {} vertices -> {} welded vertices; {} degenerate and {} duplicate \
             triangles dropped, {} flipped; {} component(s), {} hole(s) ({} boundary edges), {} \
             non-manifold edge(s), {} self-intersection(s); volume {:.4e}",
            self.input_triangles,
            self.input_vertices,
            self.welded_vertices,
            self.degenerate_triangles,
            self.duplicate_triangles,
            self.flipped_triangles,
            self.components,
            self.holes,
            self.boundary_edges,
            self.non_manifold_edges,
            self.self_intersections,
            self.volume
        )
    }
}

/// The surface as the mesher gets it.
#[derive(Clone, Debug, PartialEq)]
pub struct Repaired {
    /// Welded positions.
    pub positions: Vec<[f64; 3]>,
    /// Kept triangles over them, oriented outward.
    pub triangles: Vec<[usize; 3]>,
    /// For each vertex of the surface as read, its welded vertex.
    pub welded_of: Vec<usize>,
    /// What was found and done.
    pub report: RepairReport,
    /// Accepted defects, one sentence each.
    pub warnings: Vec<String>,
}

/// Repairs `surface` (read from `file`) under `policy`. Errors name the file and the defect.
pub fn repair(surface: &Surface, file: &Path, policy: &RepairPolicy) -> Result<Repaired, InputError> {
    surface.check(file)?;
    let diagonal = surface.diagonal();
    let mut report = RepairReport {
        input_vertices: surface.positions.len(),
        input_triangles: surface.triangles.len(),
        ..RepairReport::default()
    };
    let (welded_of, positions) = weld(&surface.positions, policy.weld_tolerance * diagonal);
    report.welded_vertices = positions.len();

    // Zero-area triangles: a repeated vertex, or a cross product negligible against the
    // diagonal (relative 1e-14 of its square, well below any triangle a mesher can resolve).
    let mut triangles = Vec::with_capacity(surface.triangles.len());
    let mut seen: HashMap<[usize; 3], ()> = HashMap::new();
    for t in &surface.triangles {
        let w = t.map(|v| welded_of[v]);
        if w[0] == w[1] || w[1] == w[2] || w[0] == w[2] || area2(&positions, w) <= 1e-14 * diagonal * diagonal {
            report.degenerate_triangles += 1;
            continue;
        }
        let mut key = w;
        key.sort_unstable();
        if seen.insert(key, ()).is_some() {
            report.duplicate_triangles += 1;
            continue;
        }
        triangles.push(w);
    }
    if triangles.is_empty() {
        return Err(InputError::file(
            file,
            format!(
                "degenerate surface: all {} triangles have zero area after welding",
                surface.triangles.len()
            ),
        ));
    }

    let edges = edge_uses(&triangles);
    report.non_manifold_edges = edges.values().filter(|u| u.len() > 2).count();
    let boundary: Vec<[usize; 2]> = edges.iter().filter(|(_, u)| u.len() == 1).map(|(e, _)| *e).collect();
    report.boundary_edges = boundary.len();
    report.holes = count_loops(&boundary);
    let orientation = orient(&positions, &mut triangles, &edges);
    report.flipped_triangles = orientation.flipped;
    report.components = orientation.components;
    report.non_orientable_components = orientation.non_orientable;
    report.volume = triangles.iter().map(|&t| signed_volume(&positions, t)).sum();
    report.self_intersections = self_intersections(&positions, &triangles);

    let mut warnings = Vec::new();
    let mut check = |count: usize, accepted: bool, what: String| -> Result<(), InputError> {
        match (count, accepted) {
            (0, _) => Ok(()),
            (_, true) => {
                warnings.push(what);
                Ok(())
            }
            (_, false) => Err(InputError::file(file, what)),
        }
    };
    check(
        report.boundary_edges,
        policy.open,
        format!(
            "open surface: {} hole(s) bounded by {} edge(s) used by one triangle only (the mesher needs a closed surface)",
            report.holes, report.boundary_edges
        ),
    )?;
    check(
        report.non_manifold_edges,
        policy.non_manifold,
        format!(
            "non-manifold surface: {} edge(s) shared by more than two triangles",
            report.non_manifold_edges
        ),
    )?;
    check(
        report.self_intersections,
        policy.self_intersecting,
        format!(
            "self-intersecting surface: {} edge-triangle crossing(s)",
            report.self_intersections
        ),
    )?;
    Ok(Repaired {
        positions,
        triangles,
        welded_of,
        report,
        warnings,
    })
}

/// Welds vertices closer than `tolerance`: returns each vertex's welded index and the welded
/// positions (each the first vertex of its group). Written here because it is a hash grid of
/// a few lines over this module's types; a pair closer than `tolerance` is always found (its
/// vertices lie in the same or neighbouring cells of side `tolerance`), and groups are closed
/// under chaining (union-find), so the result does not depend on the vertex order beyond
/// which position represents a group. A zero tolerance welds bit-identical positions only.
pub fn weld(points: &[[f64; 3]], tolerance: f64) -> (Vec<usize>, Vec<[f64; 3]>) {
    let mut parent: Vec<usize> = (0..points.len()).collect();
    fn root(parent: &mut [usize], mut v: usize) -> usize {
        while parent[v] != v {
            parent[v] = parent[parent[v]];
            v = parent[v];
        }
        v
    }
    let cell = if tolerance > 0.0 { tolerance } else { 1.0 };
    let key = |p: &[f64; 3]| p.map(|c| (c / cell).floor() as i64);
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (i, p) in points.iter().enumerate() {
        let k = key(p);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(others) = grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) else {
                        continue;
                    };
                    for &j in others {
                        let d2: f64 = (0..3).map(|a| (p[a] - points[j][a]).powi(2)).sum();
                        if d2 <= tolerance * tolerance {
                            let (ri, rj) = (root(&mut parent, i), root(&mut parent, j));
                            parent[ri.max(rj)] = ri.min(rj);
                        }
                    }
                }
            }
        }
        grid.entry(k).or_default().push(i);
    }
    let mut index = vec![usize::MAX; points.len()];
    let mut welded = Vec::new();
    let mut welded_of = Vec::with_capacity(points.len());
    for i in 0..points.len() {
        let r = root(&mut parent, i);
        if index[r] == usize::MAX {
            index[r] = welded.len();
            welded.push(points[r]);
        }
        welded_of.push(index[r]);
    }
    (welded_of, welded)
}

/// Twice the area of triangle `t`.
fn area2(p: &[[f64; 3]], t: [usize; 3]) -> f64 {
    let (a, b, c) = (p[t[0]], p[t[1]], p[t[2]]);
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let n = [
        u[1] * v[2] - u[2] * v[1],
        u[2] * v[0] - u[0] * v[2],
        u[0] * v[1] - u[1] * v[0],
    ];
    (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
}

/// Signed volume of the tet (origin, triangle): summed over a closed surface, its volume.
fn signed_volume(p: &[[f64; 3]], t: [usize; 3]) -> f64 {
    let (a, b, c) = (p[t[0]], p[t[1]], p[t[2]]);
    (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) + a[2] * (b[0] * c[1] - b[1] * c[0])) / 6.0
}

/// For every undirected edge `[low, high]`, the triangles using it.
fn edge_uses(triangles: &[[usize; 3]]) -> HashMap<[usize; 2], Vec<usize>> {
    let mut uses: HashMap<[usize; 2], Vec<usize>> = HashMap::new();
    for (i, t) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            uses.entry([a.min(b), a.max(b)]).or_default().push(i);
        }
    }
    uses
}

/// Connected chains of boundary edges (each hole is one).
fn count_loops(boundary: &[[usize; 2]]) -> usize {
    let mut parent: HashMap<usize, usize> = HashMap::new();
    fn root(parent: &mut HashMap<usize, usize>, v: usize) -> usize {
        let mut r = v;
        while let Some(&p) = parent.get(&r).filter(|&&p| p != r) {
            r = p;
        }
        parent.insert(v, r);
        r
    }
    for &[a, b] in boundary {
        parent.entry(a).or_insert(a);
        parent.entry(b).or_insert(b);
        let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
        parent.insert(ra.max(rb), ra.min(rb));
    }
    let vertices: Vec<usize> = parent.keys().copied().collect();
    let mut roots: Vec<usize> = vertices.into_iter().map(|v| root(&mut parent, v)).collect();
    roots.sort_unstable();
    roots.dedup();
    roots.len()
}

/// How orientation went.
struct Orientation {
    flipped: usize,
    components: usize,
    non_orientable: usize,
}

/// Orients each connected component consistently (neighbours across a manifold edge traverse
/// it in opposite directions), breadth first from its first triangle, then flips a component
/// whose signed volume is negative so that it faces outward.
fn orient(p: &[[f64; 3]], triangles: &mut [[usize; 3]], edges: &HashMap<[usize; 2], Vec<usize>>) -> Orientation {
    let n = triangles.len();
    let mut component = vec![usize::MAX; n];
    let mut flipped = vec![false; n];
    let mut result = Orientation {
        flipped: 0,
        components: 0,
        non_orientable: 0,
    };
    let directed = |t: [usize; 3], a: usize, b: usize| (0..3).any(|k| t[k] == a && t[(k + 1) % 3] == b);
    for start in 0..n {
        if component[start] != usize::MAX {
            continue;
        }
        let id = result.components;
        result.components += 1;
        let mut members = vec![start];
        component[start] = id;
        let mut consistent = true;
        let mut next = 0;
        while next < members.len() {
            let i = members[next];
            next += 1;
            let t = triangles[i];
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let uses = &edges[&[a.min(b), a.max(b)]];
                for &j in uses {
                    if j == i {
                        continue;
                    }
                    // A consistent neighbour traverses the edge from b to a.
                    let agrees = directed(triangles[j], b, a);
                    if component[j] == usize::MAX {
                        component[j] = id;
                        if !agrees && uses.len() == 2 {
                            triangles[j].swap(1, 2);
                            flipped[j] = !flipped[j];
                        }
                        members.push(j);
                    } else if !agrees && uses.len() == 2 {
                        consistent = false;
                    }
                }
            }
        }
        if !consistent {
            result.non_orientable += 1;
        }
        let volume: f64 = members.iter().map(|&i| signed_volume(p, triangles[i])).sum();
        if volume < 0.0 {
            for &i in &members {
                triangles[i].swap(1, 2);
                flipped[i] = !flipped[i];
            }
        }
    }
    result.flipped = flipped.iter().filter(|&&f| f).count();
    result
}

/// Edge-triangle crossings of the surface (exact predicates over a uniform-grid broad phase,
/// the contact module's check; pairs sharing a vertex are skipped there).
fn self_intersections(p: &[[f64; 3]], triangles: &[[usize; 3]]) -> usize {
    let mesh = Mesh {
        dim: 3,
        rest: p.iter().flatten().copied().collect(),
        elements: Elements::Shell(triangles.to_vec()),
        attributes: None,
    };
    let surface = ContactSurface::of_mesh(&mesh);
    intersecting_pairs(&surface, &mesh.rest).len()
}
