//! The oracle's scales against hand-computed values ([`scales`]), the invariances its
//! measures are built for and their formulas ([`measures`]), and its decisions on a
//! point-loaded bar and a sliding one ([`decisions`]).

mod decisions;
mod measures;
mod scales;

use super::*;
use crate::adaptive::candidates::{rigid_modes, Body, CandidateSpec};
use crate::adaptive::partition::Partition;
use crate::energy::external::ConstantForce;
use crate::energy::inertia::Inertia;
use crate::energy::tet::TetElastic;
use crate::energy::tri2d::Tri2dElastic;
use crate::energy::{self, StencilEnergy};
use crate::material::{ElementMaterial, MaterialLaw};
use crate::mesh::lumped_masses;
use crate::mesh::procedural::box_tets;
use crate::mesh::{Elements, Mesh};
use nalgebra::{DMatrix, DVector};
use std::path::Path;

const RUBBER: ElementMaterial = ElementMaterial {
    youngs: 1e5,
    poisson: 0.3,
    density: 1000.0,
};

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()).max(1e-300)
}

/// `|d²Ψ/dF²(I)|_F` of StVK: the Hessian at rest is `2 mu P_sym + lambda vec(I) vec(I)ᵀ`,
/// so its squared norm is `4 mu² rank(P_sym) + 4 mu lambda D + lambda² D²`.
fn stvk_rest_norm(m: ElementMaterial, dim: usize) -> f64 {
    let (mu, la, d) = (m.mu(), m.lambda(), dim as f64);
    let sym_rank = d * (d + 1.0) / 2.0;
    (4.0 * mu * mu * sym_rank + 4.0 * mu * la * d + la * la * d * d).sqrt()
}

fn tets(rest: &[f64], elements: &[[usize; 4]], law: MaterialLaw, m: ElementMaterial) -> TetElastic {
    TetElastic::new(law, rest, elements, &[m], Path::new("test")).unwrap()
}

/// A free tet box body with its terms, and the incremental potential's gradient.
struct Solid {
    mesh: Mesh,
    masses: Vec<f64>,
    elastic: TetElastic,
    inertia: Inertia,
    dt: f64,
}

impl Solid {
    fn new(hi: [f64; 3], cells: [usize; 3], m: ElementMaterial, dt: f64) -> Solid {
        let mesh = box_tets([0.0; 3], hi, cells).unwrap();
        let Elements::Tets(t) = &mesh.elements else {
            unreachable!()
        };
        let elastic = tets(&mesh.rest, t, MaterialLaw::StableNeoHookean, m);
        let masses = lumped_masses(&mesh, &[m.density], 1.0, 1.0);
        let inertia = Inertia::new(3, masses.clone());
        Solid {
            mesh,
            masses,
            elastic,
            inertia,
            dt,
        }
    }
    fn scales(&self) -> NodeScales {
        NodeScales::new(3, &self.mesh.rest, &[&self.elastic]).unwrap()
    }
    fn body(&self) -> Body<'_> {
        Body {
            dim: 3,
            rest: &self.mesh.rest,
            masses: &self.masses,
            fixed_vertices: &[],
        }
    }
    /// Inertia with weight 1 and the potentials with weight `h²` (implicit Euler).
    fn terms<'a>(&'a self, extra: &'a [&'a dyn StencilEnergy]) -> Vec<WeightedTerm<'a>> {
        let h2 = self.dt * self.dt;
        let mut terms = vec![
            WeightedTerm {
                energy: &self.inertia,
                weight: 1.0,
            },
            WeightedTerm {
                energy: &self.elastic,
                weight: h2,
            },
        ];
        terms.extend(extra.iter().map(|e| WeightedTerm { energy: *e, weight: h2 }));
        terms
    }
}

fn total(terms: &[WeightedTerm<'_>], x: &[f64]) -> f64 {
    terms.iter().map(|t| t.weight * energy::value(t.energy, x)).sum()
}

fn gradient(terms: &[WeightedTerm<'_>], x: &[f64]) -> Vec<f64> {
    let mut g = vec![0.0; x.len()];
    for t in terms {
        energy::add_gradient(t.energy, t.weight, x, &mut g);
    }
    g
}

/// The line-searched Newton step of the incremental potential within the span of `u`
/// (dense; small meshes only).
fn subspace_step(terms: &[WeightedTerm<'_>], x: &[f64], u: &DMatrix<f64>) -> Vec<f64> {
    let n = x.len();
    let mut h = DMatrix::zeros(n, n);
    for t in terms {
        let dim = t.energy.dim();
        energy::for_each_hessian(t.energy, x, false, |s, _, local| {
            let verts = t.energy.stencil(s);
            let m = verts.len() * dim;
            for (a, &va) in verts.iter().enumerate() {
                for (b, &vb) in verts.iter().enumerate() {
                    for i in 0..dim {
                        for k in 0..dim {
                            h[(va * dim + i, vb * dim + k)] += t.weight * local.hess[(a * dim + i) * m + b * dim + k];
                        }
                    }
                }
            }
        });
    }
    let g = DVector::from_vec(gradient(terms, x));
    let q = (u.transpose() * &h * u).lu().solve(&(-(u.transpose() * g))).unwrap();
    let d = u * q;
    let e0 = total(terms, x);
    let mut alpha = 1.0;
    loop {
        let trial: Vec<f64> = x.iter().zip(d.iter()).map(|(a, b)| a + alpha * b).collect();
        if total(terms, &trial) <= e0 || alpha < 1e-12 {
            return d.iter().map(|v| alpha * v).collect();
        }
        alpha *= 0.5;
    }
}

fn rigid_basis(solid: &Solid) -> DMatrix<f64> {
    let r = rigid_modes(&solid.body()).unwrap();
    DMatrix::from_fn(r.nrows(), r.ncols(), |i, j| r[(i, j)])
}

/// A smooth deformation of `rest` (bend and twist of amplitude `a`, relative to `size`).
fn deformed(rest: &[f64], size: f64, a: f64) -> Vec<f64> {
    rest.chunks_exact(3)
        .flat_map(|p| {
            let (x, y, z) = (p[0] / size, p[1] / size, p[2] / size);
            [
                p[0] + size * a * (y * z),
                p[1] + size * a * (x * x - 0.3 * z),
                p[2] + size * a * (0.5 * x * y + 0.2 * z * z),
            ]
        })
        .collect()
}

/// Vertex `(i, j, k)` of a `box_tets` grid with `cells`.
fn grid(cells: [usize; 3], i: usize, j: usize, k: usize) -> usize {
    i + (cells[0] + 1) * (j + (cells[1] + 1) * k)
}

/// The vertices that share an element with `v` (itself included).
fn one_ring(mesh: &Mesh, v: usize) -> Vec<bool> {
    let Elements::Tets(t) = &mesh.elements else {
        unreachable!()
    };
    let mut ring = vec![false; mesh.num_vertices()];
    for tet in t.iter().filter(|t| t.contains(&v)) {
        tet.iter().for_each(|&w| ring[w] = true);
    }
    ring
}
