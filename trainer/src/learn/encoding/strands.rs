//! Rod strands encoded by their bends ([`Encoding::with_strand_bends`](super::Encoding::with_strand_bends)):
//! the chains, where they start, and the rotations (Cayley map) that walk them.

use nalgebra::Vector3;

use mochi_sim::mesh::{Elements, Mesh};

/// One rod strand in the stretch-free encoding ([`Encoding::with_strand_bends`](super::Encoding::with_strand_bends)).
#[derive(Clone, Debug, PartialEq)]
pub struct Chain {
    /// Handle slots of the strand's two prescribed vertices; the edge from the first to the
    /// second is the parent of the first free edge.
    pub parent: [usize; 2],
    /// A unit vector perpendicular to the parent edge at rest: with the handles' rotation
    /// applied, it fixes the first bend's axes.
    pub rest_normal: Vector3<f64>,
    /// Indices into the encoded vertices of the strand's free vertices, root to tip.
    pub slots: Vec<usize>,
    /// Rest length of the edge that ends at each of them.
    pub lengths: Vec<f64>,
}

/// Where a strand's chain starts in one state: its last prescribed vertex and the axes
/// (parent-edge direction, then two normals) of the first bend.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChainStart {
    /// Position of the strand's last prescribed vertex.
    pub anchor: Vector3<f64>,
    /// Unit parent-edge direction `d`, and the normals `u`, `w` (`d x u = w`).
    pub axes: [Vector3<f64>; 3],
}

/// For rods whose every root is prescribed and whose every free vertex lies on a strand:
/// the handle slot of each strand's root, and the strand of each free vertex.
pub(super) fn strand_roots(mesh: &Mesh, slot_of: &[Option<usize>], free: &[usize]) -> Option<(Vec<usize>, Vec<usize>)> {
    let Elements::Rods(strands) = &mesh.elements else {
        return None;
    };
    let root_slots = strands
        .iter()
        .map(|s| s.first().and_then(|&root| slot_of.get(root).copied().flatten()))
        .collect::<Option<Vec<usize>>>()?;
    let mut strand_of_vertex = vec![None; mesh.num_vertices()];
    for (k, s) in strands.iter().enumerate() {
        for &v in s {
            if let Some(strand) = strand_of_vertex.get_mut(v) {
                strand.get_or_insert(k);
            }
        }
    }
    let strand_of = free
        .iter()
        .map(|&v| strand_of_vertex[v])
        .collect::<Option<Vec<usize>>>()?;
    Some((root_slots, strand_of))
}

/// Walks one chain of `q` from `start`, edge by edge, calling
/// `visit(j, axes before the edge, its Gibbs vector, position of encoded vertex j)`.
pub(super) fn walk_chain(
    chain: &Chain,
    start: &ChainStart,
    q: &[f64],
    mut visit: impl FnMut(usize, &[Vector3<f64>; 3], &Vector3<f64>, &Vector3<f64>),
) {
    let (mut position, mut axes) = (start.anchor, start.axes);
    for (&j, &length) in chain.slots.iter().zip(&chain.lengths) {
        let g = (axes[1] * q[2 * j] + axes[2] * q[2 * j + 1]) / length;
        let before = axes;
        axes = axes.map(|y| cayley(&g, &y));
        position += axes[0] * length;
        visit(j, &before, &g, &position);
    }
}

/// `y` turned by the rotation whose Gibbs vector is `g` (the Cayley map:
/// `y + 2 / (1 + |g|^2) (g x y + g x (g x y))`).
pub(super) fn cayley(g: &Vector3<f64>, y: &Vector3<f64>) -> Vector3<f64> {
    let h = g.cross(y);
    y + (h + g.cross(&h)) * (2.0 / (1.0 + g.norm_squared()))
}

/// `(d cayley(g, y) / d g)^T y_bar`: how the turned vector's adjoint reaches `g`.
pub(super) fn cayley_vjp(g: &Vector3<f64>, y: &Vector3<f64>, y_bar: &Vector3<f64>) -> Vector3<f64> {
    let c = 2.0 / (1.0 + g.norm_squared());
    let h = g.cross(y);
    let k = g.cross(&h);
    g * (-c * c * (h + k).dot(y_bar)) + (y.cross(y_bar) + h.cross(y_bar) + y.cross(&y_bar.cross(g))) * c
}

/// A unit vector perpendicular to the unit vector `d`: the coordinate axis least aligned
/// with `d`, with its `d` component removed.
pub(super) fn normal_to(d: &Vector3<f64>) -> Vector3<f64> {
    let axis = (0..3).min_by(|&a, &b| d[a].abs().total_cmp(&d[b].abs())).unwrap_or(0);
    let e = Vector3::ith(axis, 1.0);
    (e - d * d.dot(&e)).normalize()
}
