//! Which degrees of freedom a solve moves: Dirichlet conditions eliminate every coordinate
//! of a prescribed vertex, the others are numbered in order (the full-space solver, the
//! adaptive model and the candidate bases share this numbering).

/// `free_index` entry of a prescribed degree of freedom.
pub(crate) const NOT_FREE: usize = usize::MAX;

/// How Dirichlet conditions eliminate degrees of freedom: every coordinate of a fixed vertex
/// is prescribed, the others are numbered in order. Returns the map from each of the
/// `num_dofs` global dofs (`dim` per vertex) to its free index (`NOT_FREE` if prescribed)
/// and the number of free dofs.
pub(crate) fn free_dof_index(dim: usize, num_dofs: usize, fixed_vertices: &[usize]) -> (Vec<usize>, usize) {
    let mut fixed = vec![false; num_dofs];
    for &v in fixed_vertices {
        fixed[v * dim..(v + 1) * dim].fill(true);
    }
    let mut free_index = vec![NOT_FREE; num_dofs];
    let mut num_free = 0;
    for (k, f) in fixed.iter().enumerate() {
        if !f {
            free_index[k] = num_free;
            num_free += 1;
        }
    }
    (free_index, num_free)
}
