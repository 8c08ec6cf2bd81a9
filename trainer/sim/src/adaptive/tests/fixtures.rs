//! Test systems: seeded random symmetric positive definite matrices, dense/sparse
//! conversions, and the Hessian of a small deformed tet mesh.

use std::path::Path;

use faer::sparse::{SparseColMat, Triplet};
use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::energy::{self, tet::TetElastic};
use crate::material::{ElementMaterial, MaterialLaw};
use crate::mesh::lumped_masses;
use crate::mesh::{procedural::box_tets, Elements, Mesh};

/// A seeded generator.
pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Uniform entries in `[-1, 1)`.
pub fn random_matrix(rows: usize, cols: usize, rng: &mut ChaCha8Rng) -> DMatrix<f64> {
    DMatrix::from_fn(rows, cols, |_, _| rng.random_range(-1.0..1.0))
}

/// Uniform entries in `[-1, 1)`.
pub fn random_vector(n: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    (0..n).map(|_| rng.random_range(-1.0..1.0)).collect()
}

/// A dense SPD matrix `M M^T + shift I`.
pub fn random_spd(n: usize, shift: f64, rng: &mut ChaCha8Rng) -> DMatrix<f64> {
    let m = random_matrix(n, n, rng);
    &m * m.transpose() + DMatrix::identity(n, n) * shift
}

/// A sparse SPD matrix over `nodes` nodes of 3 coordinates: a 3 x 3 block on every edge of
/// a ring plus a few random chords, made diagonally dominant by `1 + margin` times the sum
/// of the absolute off-diagonal entries of each row.
pub fn random_sparse_spd(nodes: usize, margin: f64, rng: &mut ChaCha8Rng) -> DMatrix<f64> {
    let n = 3 * nodes;
    let mut h = DMatrix::zeros(n, n);
    let mut couple = |a: usize, b: usize, rng: &mut ChaCha8Rng| {
        for i in 0..3 {
            for j in 0..3 {
                let v = rng.random_range(-1.0..1.0);
                h[(3 * a + i, 3 * b + j)] = v;
                h[(3 * b + j, 3 * a + i)] = v;
            }
        }
    };
    for a in 0..nodes {
        couple(a, (a + 1) % nodes, rng);
    }
    for _ in 0..nodes / 2 {
        let (a, b) = (rng.random_range(0..nodes), rng.random_range(0..nodes));
        if a != b {
            couple(a, b, rng);
        }
    }
    for a in 0..nodes {
        // An SPD (not diagonal) 3 x 3 node block plus the dominance margin.
        let m = random_matrix(3, 3, rng);
        let b = &m * m.transpose();
        for i in 0..3 {
            for j in 0..3 {
                h[(3 * a + i, 3 * a + j)] = b[(i, j)];
            }
        }
    }
    for r in 0..n {
        let off: f64 = (0..n).filter(|&c| c != r).map(|c| h[(r, c)].abs()).sum();
        h[(r, r)] += (1.0 + margin) * off + 1e-3;
    }
    h
}

/// The lower triangle of `h` (its nonzero entries) as a faer CSC matrix.
pub fn lower_csc(h: &DMatrix<f64>) -> SparseColMat<u32, f64> {
    let mut triplets = Vec::new();
    for c in 0..h.ncols() {
        for r in c..h.nrows() {
            if h[(r, c)] != 0.0 {
                triplets.push(Triplet::new(r as u32, c as u32, h[(r, c)]));
            }
        }
    }
    SparseColMat::try_new_from_triplets(h.nrows(), h.ncols(), &triplets).expect("valid triplets")
}

/// All nonzero entries of `m` as a faer CSC matrix.
pub fn full_csc(m: &DMatrix<f64>) -> SparseColMat<u32, f64> {
    let mut triplets = Vec::new();
    for c in 0..m.ncols() {
        for r in 0..m.nrows() {
            if m[(r, c)] != 0.0 {
                triplets.push(Triplet::new(r as u32, c as u32, m[(r, c)]));
            }
        }
    }
    SparseColMat::try_new_from_triplets(m.nrows(), m.ncols(), &triplets).expect("valid triplets")
}

/// `-A^{-1} g` by a dense LU solve.
pub fn dense_direction(a: &DMatrix<f64>, g: &[f64]) -> Vec<f64> {
    let rhs = nalgebra::DVector::from_iterator(g.len(), g.iter().map(|v| -v));
    a.clone().lu().solve(&rhs).expect("nonsingular").as_slice().to_vec()
}

/// `|a - b| / |b|`.
pub fn relative_error(a: &[f64], b: &[f64]) -> f64 {
    let diff: f64 = a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt();
    diff / b.iter().map(|y| y * y).sum::<f64>().sqrt()
}

/// A beam of tets, `[0, 4] x [0, 1] x [0, 1]`, with `cells` cubes per axis.
pub fn beam(cells: [usize; 3]) -> Mesh {
    box_tets([0.0; 3], [4.0, 1.0, 1.0], cells).expect("valid box")
}

/// The rubber of the test beams: 1 MPa, Poisson's ratio 0.45, 1000 kg/m³.
const RUBBER: ElementMaterial = ElementMaterial {
    youngs: 1e6,
    poisson: 0.45,
    density: 1000.0,
};

/// A rubber [`beam`] and its stable neo-Hookean elasticity.
pub fn rubber_beam(cells: [usize; 3]) -> (Mesh, TetElastic) {
    let mesh = beam(cells);
    let Elements::Tets(tets) = &mesh.elements else {
        unreachable!("box_tets gives tets")
    };
    let elastic = TetElastic::new(
        MaterialLaw::StableNeoHookean,
        &mesh.rest,
        tets,
        &[RUBBER],
        Path::new("<test beam>"),
    )
    .expect("valid beam");
    (mesh, elastic)
}

/// The implicit-Euler Hessian `M / h^2 + ∇²Ψ` (stencil Hessians projected to PSD) of a
/// rubber beam at a bent, randomly perturbed state, assembled densely from the energy
/// kernels the solver assembles; with the mesh.
pub fn tet_hessian(cells: [usize; 3], seed: u64) -> (Mesh, DMatrix<f64>) {
    let (mesh, elastic) = rubber_beam(cells);
    let mut rng = rng(seed);
    let x: Vec<f64> = mesh
        .rest
        .chunks_exact(3)
        .flat_map(|p| {
            let bend = 0.05 * p[0] * p[0];
            [p[0], p[1], p[2] + bend]
        })
        .zip(random_vector(mesh.rest.len(), &mut rng))
        .map(|(x, r)| x + 0.02 * r)
        .collect();
    let n = x.len();
    let mut h = DMatrix::zeros(n, n);
    energy::for_each_hessian(&elastic, &x, true, |s, _, local| {
        let verts = energy::StencilEnergy::stencil(&elastic, s);
        let k = verts.len() * 3;
        for (a, &va) in verts.iter().enumerate() {
            for (b, &vb) in verts.iter().enumerate() {
                for i in 0..3 {
                    for j in 0..3 {
                        h[(3 * va + i, 3 * vb + j)] += local.hess[(3 * a + i) * k + 3 * b + j];
                    }
                }
            }
        }
    });
    let dt = 1.0 / 60.0;
    for (v, m) in lumped_masses(&mesh, &[RUBBER.density], 1.0, 1.0).iter().enumerate() {
        for i in 0..3 {
            h[(3 * v + i, 3 * v + i)] += m / (dt * dt);
        }
    }
    (mesh, h)
}
