//! A body as the candidate bases see it: rest shape, lumped masses and Dirichlet vertices.

use super::CandidateError;
use crate::dofs::free_dof_index;

/// A body as the candidate bases see it. Every candidate mode is a vector over all of its
/// degrees of freedom (`dim` per vertex, vertex-major as positions are) and is zero on the
/// prescribed ones, which the solver eliminates.
#[derive(Clone, Copy, Debug)]
pub struct Body<'a> {
    /// Coordinates per vertex: 2 (planar solids) or 3 (solids, cloth, rods).
    pub dim: usize,
    /// Rest positions, flat, `dim` per vertex.
    pub rest: &'a [f64],
    /// Lumped vertex masses, as the solver's inertia uses them.
    pub masses: &'a [f64],
    /// Vertices whose positions are prescribed (every coordinate of each).
    pub fixed_vertices: &'a [usize],
}

impl Body<'_> {
    /// Number of vertices.
    pub fn num_vertices(&self) -> usize {
        self.masses.len()
    }

    /// Number of degrees of freedom, prescribed ones included (`dim` per vertex).
    pub fn num_dofs(&self) -> usize {
        self.rest.len()
    }

    /// Whether no vertex is prescribed: a free-floating body, whose rest-shape stiffness
    /// has the rigid modes in its null space.
    pub fn is_floating(&self) -> bool {
        self.fixed_vertices.is_empty()
    }

    /// The solver's elimination of prescribed dofs: each dof's free index (`NOT_FREE` for
    /// prescribed ones) and the number of free dofs.
    pub(crate) fn free_dofs(&self) -> (Vec<usize>, usize) {
        free_dof_index(self.dim, self.num_dofs(), self.fixed_vertices)
    }

    /// Lumped mass of every free dof, in free-dof order.
    pub(crate) fn free_masses(&self, free_index: &[usize], num_free: usize) -> Vec<f64> {
        let mut m = vec![0.0; num_free];
        for (k, &f) in free_index.iter().enumerate() {
            if f != crate::dofs::NOT_FREE {
                m[f] = self.masses[k / self.dim];
            }
        }
        m
    }

    /// Checks lengths, the dimension, vertex indices and masses (finite, non-negative,
    /// positive on free vertices: a massless free vertex has no finite frequency).
    pub fn validate(&self) -> Result<(), CandidateError> {
        let bad = |m: String| Err(CandidateError::InvalidBody(m));
        if self.dim != 2 && self.dim != 3 {
            return bad(format!("dim is {}, must be 2 or 3", self.dim));
        }
        let n = self.masses.len();
        if self.rest.len() != n * self.dim {
            return bad(format!(
                "rest has {} coordinates, expected {} ({n} masses times dim {})",
                self.rest.len(),
                n * self.dim,
                self.dim
            ));
        }
        if let Some(k) = self.rest.iter().position(|c| !c.is_finite()) {
            return bad(format!("rest coordinate {k} is not finite ({})", self.rest[k]));
        }
        let mut fixed = vec![false; n];
        for &v in self.fixed_vertices {
            if v >= n {
                return bad(format!("fixed vertex {v} out of range (the body has {n} vertices)"));
            }
            fixed[v] = true;
        }
        for (v, &m) in self.masses.iter().enumerate() {
            if !(m.is_finite() && m >= 0.0) || (m == 0.0 && !fixed[v]) {
                return bad(format!(
                    "mass of vertex {v} is {m}, must be positive (or zero on a fixed vertex)"
                ));
            }
        }
        Ok(())
    }
}
