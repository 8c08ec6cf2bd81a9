//! Rigid and affine modes of a body: the motions that keep it undeformed (translations and
//! linearised rotations) and those that deform it uniformly (the affine maps), each set
//! mass-orthonormal (`U^T M U = I` with the lumped mass) and zero on the prescribed
//! vertices.
//!
//! The vectors are built about the centre of mass `c` of the free vertices:
//! - rigid, 3D: the 3 translations `e_i` and the 3 linearised rotations `e_k x (x - c)`;
//!   2D: 2 translations and the rotation `(-(y - c_y), x - c_x)`;
//! - affine: the rigid ones, then `e_i (x_j - c_j)` for every pair `i, j` (3D: 12 in all,
//!   2D: 6), of which the rotations are already spanned.
//!
//! They are made M-orthonormal in that order by modified Gram-Schmidt (two passes), so the
//! first columns of the affine modes are the rigid modes. A vector that is (numerically) a
//! combination of the ones before it is left out: the rotation about its own axis of a
//! straight rod, the affine maps that move a flat sheet out of its plane only in
//! proportion to an out-of-plane coordinate, every mode of a body whose vertices are all
//! prescribed. So there are at most 6 (3 in 2D) rigid and 12 (6) affine modes.

use super::{Body, CandidateError};
use faer::Mat;

/// A vector whose M-norm falls below this fraction of its norm before orthogonalisation
/// is taken to be a combination of the ones before it. Round-off leaves about 1e-15 of a
/// dependent vector; an independent one keeps a share of the order of the body's extent
/// over its size, far above this.
const DEPENDENT: f64 = 1e-8;

/// The rigid modes of `body`, as columns (`dim * n` rows), M-orthonormal, zero on the
/// prescribed vertices: translations, then linearised rotations about the free vertices'
/// centre of mass (see the module documentation for the modes left out).
pub fn rigid_modes(body: &Body) -> Result<Mat<f64>, CandidateError> {
    body.validate()?;
    let generators = Generators::new(body);
    Ok(generators.orthonormal(&generators.rigid()))
}

/// The affine modes of `body`, as columns, M-orthonormal, zero on the prescribed vertices.
/// The first `rigid_modes(body).ncols()` columns are the rigid modes; the others span the
/// rest of the affine motions (stretches and shears).
pub fn affine_modes(body: &Body) -> Result<Mat<f64>, CandidateError> {
    body.validate()?;
    let generators = Generators::new(body);
    let mut raw = generators.rigid();
    raw.extend(generators.linear_maps());
    Ok(generators.orthonormal(&raw))
}

/// The generating vectors of a body's rigid and affine modes.
struct Generators<'a> {
    body: &'a Body<'a>,
    /// Whether each vertex is free.
    free: Vec<bool>,
    /// Centre of mass of the free vertices.
    centre: [f64; 3],
}

impl<'a> Generators<'a> {
    fn new(body: &'a Body<'a>) -> Self {
        let d = body.dim;
        let mut free = vec![true; body.num_vertices()];
        body.fixed_vertices.iter().for_each(|&v| free[v] = false);
        let mut centre = [0.0; 3];
        let mut mass = 0.0;
        for (v, &m) in body.masses.iter().enumerate().filter(|(v, _)| free[*v]) {
            mass += m;
            (0..d).for_each(|i| centre[i] += m * body.rest[v * d + i]);
        }
        if mass > 0.0 {
            centre.iter_mut().for_each(|c| *c /= mass);
        }
        Generators { body, free, centre }
    }

    /// A vector over all dofs: the first `dim` numbers of `f(position relative to the
    /// centre)` on each free vertex, zero on the prescribed ones.
    fn field(&self, f: impl Fn(&[f64; 3]) -> [f64; 3]) -> Vec<f64> {
        let d = self.body.dim;
        let mut out = vec![0.0; self.body.num_dofs()];
        for v in (0..self.body.num_vertices()).filter(|&v| self.free[v]) {
            let mut r = [0.0; 3];
            (0..d).for_each(|i| r[i] = self.body.rest[v * d + i] - self.centre[i]);
            out[v * d..(v + 1) * d].copy_from_slice(&f(&r)[..d]);
        }
        out
    }

    /// Translations, then linearised rotations.
    fn rigid(&self) -> Vec<Vec<f64>> {
        let d = self.body.dim;
        let mut raw: Vec<Vec<f64>> = (0..d)
            .map(|i| {
                self.field(|_| {
                    let mut e = [0.0; 3];
                    e[i] = 1.0;
                    e
                })
            })
            .collect();
        if d == 2 {
            raw.push(self.field(|r| [-r[1], r[0], 0.0]));
        } else {
            raw.push(self.field(|r| [0.0, -r[2], r[1]]));
            raw.push(self.field(|r| [r[2], 0.0, -r[0]]));
            raw.push(self.field(|r| [-r[1], r[0], 0.0]));
        }
        raw
    }

    /// `e_i (x_j - c_j)` for every pair `i, j`.
    fn linear_maps(&self) -> Vec<Vec<f64>> {
        let d = self.body.dim;
        let mut raw = Vec::with_capacity(d * d);
        for i in 0..d {
            for j in 0..d {
                raw.push(self.field(|r| {
                    let mut e = [0.0; 3];
                    e[i] = r[j];
                    e
                }));
            }
        }
        raw
    }

    /// M-orthonormalises `raw` in order by modified Gram-Schmidt (two passes), leaving out
    /// the vectors that depend on the ones before them.
    fn orthonormal(&self, raw: &[Vec<f64>]) -> Mat<f64> {
        let d = self.body.dim;
        let mass = |k: usize| self.body.masses[k / d];
        let dot =
            |a: &[f64], b: &[f64]| -> f64 { a.iter().zip(b).enumerate().map(|(k, (x, y))| mass(k) * x * y).sum() };
        let mut kept: Vec<Vec<f64>> = Vec::new();
        for w in raw {
            let mut w = w.clone();
            let norm0 = dot(&w, &w).sqrt();
            if norm0 == 0.0 {
                continue;
            }
            for _ in 0..2 {
                for u in &kept {
                    let c = dot(u, &w);
                    w.iter_mut().zip(u).for_each(|(x, y)| *x -= c * y);
                }
            }
            let norm = dot(&w, &w).sqrt();
            if norm > DEPENDENT * norm0 {
                w.iter_mut().for_each(|x| *x /= norm);
                kept.push(w);
            }
        }
        Mat::from_fn(self.body.num_dofs(), kept.len(), |k, j| kept[j][k])
    }
}
