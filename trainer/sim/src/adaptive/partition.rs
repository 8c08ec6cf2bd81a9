//! The fixed decomposition of a body's mesh into `P` subdomains, computed once per mesh.
//!
//! It serves two purposes of the adaptive solver: nodal enrichment adds whole vertex groups
//! (a vertex's subdomain), and the elastic subspace Hessian is integrated per element
//! subdomain, each with its own BFGS approximation ([`super::elastic_subspace`]).
//!
//! The vertices are split by METIS's multilevel k-way partitioner on the mesh's nodal graph
//! (two vertices adjacent when an element joins them), asking for contiguous parts when
//! that graph is connected (METIS refuses the request otherwise); each element then goes to
//! the subdomain holding most of its vertices.
//!
//! Why METIS, through the `metis` crate: it is the partitioner the method was designed
//! with (edge-cut minimising, contiguous, balanced parts, deterministic for a fixed seed),
//! and `metis-sys` builds the METIS 5 sources it vendors with the C compiler, needing no
//! system library and no bindgen (`metis-sys` and `metis` with their build dependencies
//! compiled in about 17 s at `-j1` on a busy two-core machine).
//! The pure-Rust `coupe` 0.1 was set aside: its only release pulls a second nalgebra
//! (0.29), ndarray, sprs and rand 0.8 into the build and offers geometric and topological
//! pieces to compose rather than a ready multilevel k-way partitioner. A geometric method
//! (recursive coordinate bisection) balances well but cuts without regard to connectivity,
//! so on a non-convex body a subdomain can fall apart into pieces.

use crate::mesh::{Elements, Mesh};

/// METIS's random seed: a fixed one keeps the decomposition reproducible.
const METIS_SEED: i32 = 1;

/// METIS keeps its random generator's state in a process-wide global (GKlib's Mersenne
/// twister), so concurrent calls would race on it and give different partitions: calls
/// are made one at a time.
static METIS_LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Why a mesh could not be decomposed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PartitionError {
    /// The number of subdomains is zero or exceeds the number of vertices.
    #[error("cannot split a mesh of {vertices} vertices into {parts} subdomains (need 1 <= parts <= vertices)")]
    Parts {
        /// Subdomains asked for.
        parts: usize,
        /// Vertices of the mesh.
        vertices: usize,
    },
    /// An element names a vertex the mesh does not have.
    #[error("element {element} names vertex {vertex}, but the mesh has {vertices} vertices")]
    VertexOutOfRange {
        /// The element.
        element: usize,
        /// The vertex it names.
        vertex: usize,
        /// Vertices of the mesh.
        vertices: usize,
    },
    /// The nodal graph is too large for METIS's 32-bit indices.
    #[error("the mesh's nodal graph ({entries} adjacency entries) exceeds METIS's 32-bit indices")]
    TooLarge {
        /// Adjacency entries (twice the edges).
        entries: usize,
    },
    /// METIS reported an error.
    #[error("METIS failed: {0}")]
    Metis(String),
    /// METIS returned a partition in which a subdomain has no vertex.
    #[error("METIS left subdomain {0} without vertices; ask for fewer subdomains")]
    EmptySubdomain(usize),
}

/// A fixed decomposition of a mesh into subdomains.
#[derive(Clone, Debug)]
pub struct Partition {
    vertex_subdomain: Vec<usize>,
    element_subdomain: Vec<usize>,
    vertices: Vec<Vec<usize>>,
    elements: Vec<Vec<usize>>,
}

impl Partition {
    /// Splits `mesh` into `parts` subdomains with METIS.
    pub fn new(mesh: &Mesh, parts: usize) -> Result<Partition, PartitionError> {
        let n = mesh.num_vertices();
        let elements = element_vertices(&mesh.elements);
        for (e, verts) in elements.iter().enumerate() {
            if let Some(&v) = verts.iter().find(|&&v| v >= n) {
                return Err(PartitionError::VertexOutOfRange {
                    element: e,
                    vertex: v,
                    vertices: n,
                });
            }
        }
        let vertex_subdomain = metis_vertex_parts(n, &elements, parts)?;
        Ok(Partition::from_vertex_parts(&elements, parts, vertex_subdomain))
    }

    /// The decomposition given by each vertex's subdomain (`< parts`), with elements
    /// assigned by majority; every subdomain must hold a vertex.
    fn from_vertex_parts(elements: &[Vec<usize>], parts: usize, vertex_subdomain: Vec<usize>) -> Partition {
        let mut vertices = vec![Vec::new(); parts];
        for (v, &p) in vertex_subdomain.iter().enumerate() {
            vertices[p].push(v);
        }
        let element_subdomain = majority_subdomains(elements, &vertex_subdomain, parts);
        let mut element_members = vec![Vec::new(); parts];
        for (e, &p) in element_subdomain.iter().enumerate() {
            element_members[p].push(e);
        }
        Partition {
            vertex_subdomain,
            element_subdomain,
            vertices,
            elements: element_members,
        }
    }

    /// Number of subdomains.
    pub fn num_subdomains(&self) -> usize {
        self.vertices.len()
    }

    /// Subdomain of each vertex (the nodal enrichment groups).
    pub fn vertex_subdomains(&self) -> &[usize] {
        &self.vertex_subdomain
    }

    /// Subdomain of each element (the subspace integration domains).
    pub fn element_subdomains(&self) -> &[usize] {
        &self.element_subdomain
    }

    /// Vertices whose subdomain is `l`, ascending.
    pub fn vertices(&self, l: usize) -> &[usize] {
        &self.vertices[l]
    }

    /// Elements whose subdomain is `l`, ascending.
    pub fn elements(&self, l: usize) -> &[usize] {
        &self.elements[l]
    }
}

/// The vertex lists of a mesh's elements (tets, triangles, rod segments).
/// Each element's (or stencil's) subdomain, given each vertex's (`< parts`): the one holding
/// most of its vertices; a tie goes to the subdomain with fewer elements so far, then to the
/// lower index (an element without vertices goes to subdomain 0).
pub(crate) fn majority_subdomains(elements: &[Vec<usize>], vertex_subdomain: &[usize], parts: usize) -> Vec<usize> {
    let mut members = vec![0usize; parts];
    let mut count = vec![0usize; parts];
    let mut out = Vec::with_capacity(elements.len());
    for verts in elements {
        for &v in verts {
            count[vertex_subdomain[v]] += 1;
        }
        let p = verts
            .iter()
            .map(|&v| vertex_subdomain[v])
            .min_by_key(|&p| (std::cmp::Reverse(count[p]), members[p], p))
            .unwrap_or(0);
        for &v in verts {
            count[vertex_subdomain[v]] = 0;
        }
        out.push(p);
        members[p] += 1;
    }
    out
}

pub(crate) fn element_vertices(elements: &Elements) -> Vec<Vec<usize>> {
    match elements {
        Elements::Tets(t) => t.iter().map(|e| e.to_vec()).collect(),
        Elements::Triangles(t) | Elements::Shell(t) => t.iter().map(|e| e.to_vec()).collect(),
        Elements::Rods(strands) => strands.iter().flat_map(|s| s.windows(2).map(|w| w.to_vec())).collect(),
    }
}

/// Each vertex's part from METIS k-way on the nodal graph of `elements` (indices checked).
fn metis_vertex_parts(n: usize, elements: &[Vec<usize>], parts: usize) -> Result<Vec<usize>, PartitionError> {
    if parts == 0 || parts > n {
        return Err(PartitionError::Parts { parts, vertices: n });
    }
    let mut neighbours: Vec<Vec<usize>> = vec![Vec::new(); n];
    for verts in elements {
        for &a in verts {
            for &b in verts {
                if a != b {
                    neighbours[a].push(b);
                }
            }
        }
    }
    let mut xadj = Vec::with_capacity(n + 1);
    let mut adjncy = Vec::new();
    xadj.push(0i32);
    for list in &mut neighbours {
        list.sort_unstable();
        list.dedup();
        adjncy.extend(list.iter().map(|&v| v as i32));
        let end = i32::try_from(adjncy.len()).map_err(|_| PartitionError::TooLarge { entries: adjncy.len() })?;
        xadj.push(end);
    }
    let nparts = i32::try_from(parts).map_err(|_| PartitionError::Parts { parts, vertices: n })?;
    let mut part = vec![0i32; n];
    // A panic elsewhere while holding the lock leaves METIS's state as valid as any call.
    let _one_at_a_time = METIS_LOCK.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    metis::Graph::new(1, nparts, &xadj, &adjncy)
        .map_err(|e| PartitionError::Metis(format!("{e:?}")))?
        .set_option(metis::option::Contig(is_connected(&neighbours)))
        .set_option(metis::option::Seed(METIS_SEED))
        .part_kway(&mut part)
        .map_err(|e| PartitionError::Metis(format!("{e:?}")))?;
    let mut seen = vec![false; parts];
    let mut out = Vec::with_capacity(n);
    for &p in &part {
        let p = usize::try_from(p)
            .ok()
            .filter(|&p| p < parts)
            .ok_or_else(|| PartitionError::Metis(format!("returned part {p} outside 0..{parts}")))?;
        seen[p] = true;
        out.push(p);
    }
    if let Some(l) = seen.iter().position(|&s| !s) {
        return Err(PartitionError::EmptySubdomain(l));
    }
    Ok(out)
}

/// Whether the graph of the adjacency lists `neighbours` is connected.
fn is_connected(neighbours: &[Vec<usize>]) -> bool {
    let mut reached = vec![false; neighbours.len()];
    let mut stack = vec![0];
    let mut count = 0;
    while let Some(v) = stack.pop() {
        if v < reached.len() && !reached[v] {
            reached[v] = true;
            count += 1;
            stack.extend(&neighbours[v]);
        }
    }
    count == neighbours.len()
}
