//! Which stencils touch each vertex, and a greedy graph colouring of the free vertices so
//! that no two vertices of one colour share a stencil (their block updates are then
//! independent and may run in parallel).

use crate::energy::StencilEnergy;

/// One stencil that touches a vertex: the term it belongs to, its index in that term and
/// the vertex's position in it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Incidence {
    /// Index of the term in the list the adjacency was built from.
    pub term: u32,
    /// Stencil index within the term.
    pub stencil: u32,
    /// The vertex's local index in the stencil (its block is local dofs
    /// `local * dim .. (local + 1) * dim`).
    pub local: u32,
}

/// Vertex-to-stencil incidence over a list of terms (compressed rows, one per vertex).
#[derive(Clone, Debug)]
pub struct Adjacency {
    start: Vec<usize>,
    entries: Vec<Incidence>,
}

impl Adjacency {
    /// The incidence of `num_vertices` vertices in the stencils of `terms`, each vertex's
    /// stencils in term order, then stencil order.
    pub fn new(num_vertices: usize, terms: &[&dyn StencilEnergy]) -> Adjacency {
        let mut count = vec![0usize; num_vertices + 1];
        for term in terms {
            for s in 0..term.len() {
                for &v in term.stencil(s) {
                    count[v + 1] += 1;
                }
            }
        }
        for v in 0..num_vertices {
            count[v + 1] += count[v];
        }
        let start = count.clone();
        let mut next = count;
        let empty = Incidence {
            term: 0,
            stencil: 0,
            local: 0,
        };
        let mut entries = vec![empty; start[num_vertices]];
        for (t, term) in terms.iter().enumerate() {
            for s in 0..term.len() {
                for (a, &v) in term.stencil(s).iter().enumerate() {
                    entries[next[v]] = Incidence {
                        term: t as u32,
                        stencil: s as u32,
                        local: a as u32,
                    };
                    next[v] += 1;
                }
            }
        }
        Adjacency { start, entries }
    }

    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.start.len() - 1
    }

    /// The stencils touching vertex `v`.
    pub fn of(&self, v: usize) -> &[Incidence] {
        &self.entries[self.start[v]..self.start[v + 1]]
    }
}

/// Greedy colouring of the vertices with `free[v]` set: each, in index order, takes the
/// smallest colour none of its already coloured free neighbours (vertices sharing a stencil
/// of `terms`, as `adjacency` lists them) has. Returns the vertices of each colour, in
/// index order. Prescribed vertices do not move, so they get no colour and constrain none.
pub fn colour_vertices(adjacency: &Adjacency, terms: &[&dyn StencilEnergy], free: &[bool]) -> Vec<Vec<usize>> {
    let n = adjacency.num_vertices();
    const NONE: usize = usize::MAX;
    let mut colour = vec![NONE; n];
    // `taken[c] == v` marks colour `c` as used by a neighbour of `v`.
    let mut taken: Vec<usize> = Vec::new();
    let mut colours: Vec<Vec<usize>> = Vec::new();
    for v in (0..n).filter(|&v| free[v]) {
        for inc in adjacency.of(v) {
            for &u in terms[inc.term as usize].stencil(inc.stencil as usize) {
                let c = colour[u];
                if u != v && c != NONE {
                    taken[c] = v;
                }
            }
        }
        let c = (0..taken.len()).find(|&c| taken[c] != v).unwrap_or(taken.len());
        if c == taken.len() {
            taken.push(NONE);
            colours.push(Vec::new());
        }
        colour[v] = c;
        colours[c].push(v);
    }
    colours
}
