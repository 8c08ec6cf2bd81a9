//! Candidate bases against dense eigen-decompositions, the null space of a floating body,
//! Euler-Bernoulli theory, and their error paths.

use super::linear_modes::RestAssembly;
use super::*;
use crate::energy::tet::TetElastic;
use crate::energy::tri2d::Tri2dElastic;
use crate::material::{ElementMaterial, MaterialLaw};
use crate::mesh::lumped_masses;
use crate::mesh::procedural::box_tets;
use crate::mesh::{Elements, Mesh};
use crate::scene::Scene;
use faer::{Mat, Side};
use std::path::Path;

mod data_modes;

const RUBBER: ElementMaterial = ElementMaterial {
    youngs: 1e6,
    poisson: 0.3,
    density: 1000.0,
};

/// A tet box body and its stable neo-Hookean elasticity.
struct Solid {
    mesh: Mesh,
    masses: Vec<f64>,
    elastic: TetElastic,
}

fn solid(hi: [f64; 3], cells: [usize; 3], material: ElementMaterial) -> Solid {
    let mesh = box_tets([0.0; 3], hi, cells).unwrap();
    let Elements::Tets(tets) = &mesh.elements else {
        unreachable!()
    };
    let elastic = TetElastic::new(
        MaterialLaw::StableNeoHookean,
        &mesh.rest,
        tets,
        &[material],
        Path::new("test"),
    )
    .unwrap();
    let masses = lumped_masses(&mesh, &[material.density], 1.0, 1.0);
    Solid { mesh, masses, elastic }
}

impl Solid {
    fn body<'a>(&'a self, fixed: &'a [usize]) -> Body<'a> {
        Body {
            dim: 3,
            rest: &self.mesh.rest,
            masses: &self.masses,
            fixed_vertices: fixed,
        }
    }
    /// The vertices on the plane `x = 0`.
    fn clamped_end(&self) -> Vec<usize> {
        (0..self.mesh.num_vertices())
            .filter(|&v| self.mesh.rest[3 * v] == 0.0)
            .collect()
    }
}

/// A 2D rectangle of `nx x ny` squares, each split into two counter-clockwise triangles.
fn rectangle(nx: usize, ny: usize) -> (Vec<f64>, Vec<[usize; 3]>) {
    let id = |i: usize, j: usize| i + (nx + 1) * j;
    let rest = (0..=ny)
        .flat_map(|j| (0..=nx).flat_map(move |i| [i as f64 * 0.1, j as f64 * 0.1]))
        .collect();
    let tris = (0..ny)
        .flat_map(|j| {
            (0..nx).flat_map(move |i| {
                [
                    [id(i, j), id(i + 1, j), id(i + 1, j + 1)],
                    [id(i, j), id(i + 1, j + 1), id(i, j + 1)],
                ]
            })
        })
        .collect();
    (rest, tris)
}

/// The dense free-dof `K` and the diagonal of `M` of a body.
fn dense_pencil(body: &Body, elastic: &[&dyn StencilEnergy]) -> (Mat<f64>, Vec<f64>) {
    let assembly = RestAssembly::new(body, elastic).unwrap();
    let n = assembly.num_free;
    let lower = assembly.stiffness.as_ref();
    let mut k = Mat::zeros(n, n);
    for c in 0..n {
        for (r, v) in lower.row_idx_of_col(c).zip(lower.val_of_col(c)) {
            k[(r, c)] = *v;
            k[(c, r)] = *v;
        }
    }
    (k, assembly.mass)
}

/// Eigenvalues of `K u = lambda M u`, ascending, from the dense `M^-1/2 K M^-1/2`.
fn dense_eigenvalues(k: &Mat<f64>, m: &[f64]) -> Vec<f64> {
    let n = m.len();
    let a = Mat::from_fn(n, n, |i, j| k[(i, j)] / (m[i] * m[j]).sqrt());
    a.self_adjoint_eigenvalues(Side::Lower).unwrap()
}

/// `U^T M V` for full-dof columns.
fn mass_products(body: &Body, u: faer::MatRef<'_, f64>, v: faer::MatRef<'_, f64>) -> Mat<f64> {
    Mat::from_fn(u.ncols(), v.ncols(), |i, j| {
        (0..u.nrows())
            .map(|k| body.masses[k / body.dim] * u[(k, i)] * v[(k, j)])
            .sum()
    })
}

fn assert_mass_orthonormal(body: &Body, u: faer::MatRef<'_, f64>, tol: f64) {
    let g = mass_products(body, u, u);
    for i in 0..g.nrows() {
        for j in 0..g.ncols() {
            let expected = if i == j { 1.0 } else { 0.0 };
            assert!((g[(i, j)] - expected).abs() < tol, "U^T M U [{i},{j}] = {}", g[(i, j)]);
        }
    }
}

/// `||K u|| / (||K||_max ||u||)` for a full-dof column `u` of a floating body (every dof free).
fn relative_stiffness_norm(k: &Mat<f64>, u: &[f64]) -> f64 {
    let n = u.len();
    let kmax = (0..n).map(|i| k[(i, i)].abs()).fold(0.0, f64::max);
    let ku: f64 = (0..n)
        .map(|i| (0..n).map(|j| k[(i, j)] * u[j]).sum::<f64>().powi(2))
        .sum();
    let un: f64 = u.iter().map(|x| x * x).sum();
    ku.sqrt() / (kmax * un.sqrt())
}

#[test]
fn clamped_modes_match_a_dense_generalised_eigensolve() {
    let s = solid([1.0, 0.3, 0.3], [6, 2, 2], RUBBER);
    let fixed = s.clamped_end();
    let body = s.body(&fixed);
    let elastic: [&dyn StencilEnergy; 1] = [&s.elastic];
    let count = 6;
    let modes = linear_modes(&body, &elastic, count, &LinearModeSettings::default()).unwrap();
    let (k, m) = dense_pencil(&body, &elastic);
    let dense = dense_eigenvalues(&k, &m);
    // 162 free dofs, and the Krylov space of a cycle is 42: the solve restarted at least once.
    assert_eq!(m.len(), 162);
    assert!(modes.restarts >= 1, "{} restarts", modes.restarts);
    for j in 0..count {
        let rel = (modes.eigenvalues[j] - dense[j]).abs() / dense[j];
        assert!(
            rel < 1e-9,
            "lambda_{j}: {} vs dense {} (relative {rel:e})",
            modes.eigenvalues[j],
            dense[j]
        );
    }
    // Residuals from the dense K, on the free dofs.
    let (free_index, _) = body.free_dofs();
    for j in 0..count {
        let u: Vec<f64> = (0..body.num_dofs())
            .filter(|&d| free_index[d] != crate::dofs::NOT_FREE)
            .map(|d| modes.modes[(d, j)])
            .collect();
        let ku: Vec<f64> = (0..u.len())
            .map(|i| (0..u.len()).map(|c| k[(i, c)] * u[c]).sum())
            .collect();
        let r: f64 = (0..u.len())
            .map(|i| (ku[i] - modes.eigenvalues[j] * m[i] * u[i]).powi(2))
            .sum();
        let kn: f64 = ku.iter().map(|x| x * x).sum();
        let rel = (r / kn).sqrt();
        assert!(rel < 1e-8, "residual of mode {j}: {rel:e}");
        assert!(
            (rel - modes.residuals[j]).abs() < 1e-8,
            "reported {:e}, measured {rel:e}",
            modes.residuals[j]
        );
    }
    assert_mass_orthonormal(&body, modes.modes.as_ref(), 1e-10);
    for &v in &fixed {
        for j in 0..count {
            assert_eq!(modes.modes.as_ref().subrows(3 * v, 3).col(j).norm_l2(), 0.0);
        }
    }
}

#[test]
fn a_floating_body_has_its_rigid_modes_as_null_space() {
    let s = solid([1.0, 0.4, 0.3], [4, 2, 2], RUBBER);
    let body = s.body(&[]);
    let elastic: [&dyn StencilEnergy; 1] = [&s.elastic];
    let (k, m) = dense_pencil(&body, &elastic);
    let dense = dense_eigenvalues(&k, &m);
    let top = dense[dense.len() - 1];
    for (j, l) in dense.iter().take(6).enumerate() {
        assert!(l.abs() < 1e-10 * top, "lambda_{j} = {l:e} of {top:e}");
    }
    assert!(dense[6] > 1e-4 * top, "lambda_6 = {:e} of {top:e}", dense[6]);

    let rigid = rigid_modes(&body).unwrap();
    assert_eq!(rigid.ncols(), 6);
    assert_mass_orthonormal(&body, rigid.as_ref(), 1e-12);
    for j in 0..6 {
        let r = relative_stiffness_norm(&k, rigid.col_as_slice(j));
        assert!(r < 1e-12, "|K u_rigid {j}| relative {r:e}");
    }

    let count = 8;
    let modes = linear_modes(&body, &elastic, count, &LinearModeSettings::default()).unwrap();
    for j in 0..count {
        let rel = (modes.eigenvalues[j] - dense[6 + j]).abs() / dense[6 + j];
        assert!(
            rel < 1e-9,
            "lambda_{j}: {} vs dense {}",
            modes.eigenvalues[j],
            dense[6 + j]
        );
    }
    let cross = mass_products(&body, rigid.as_ref(), modes.modes.as_ref());
    let worst = (0..6)
        .flat_map(|i| (0..count).map(move |j| (i, j)))
        .fold(0.0f64, |w, (i, j)| w.max(cross[(i, j)].abs()));
    assert!(worst < 1e-10, "rigid^T M linear up to {worst:e}");
    assert_mass_orthonormal(&body, modes.modes.as_ref(), 1e-10);
}

#[test]
fn planar_bodies_have_three_rigid_and_six_affine_modes() {
    let (rest, tris) = rectangle(4, 2);
    let elastic = Tri2dElastic::new(
        MaterialLaw::StableNeoHookean,
        &rest,
        &tris,
        &[RUBBER],
        Path::new("test"),
    )
    .unwrap();
    let mesh = Mesh {
        dim: 2,
        rest,
        elements: Elements::Triangles(tris),
        attributes: None,
    };
    let masses = lumped_masses(&mesh, &[RUBBER.density], 1.0, 1.0);
    let body = Body {
        dim: 2,
        rest: &mesh.rest,
        masses: &masses,
        fixed_vertices: &[],
    };
    let terms: [&dyn StencilEnergy; 1] = [&elastic];
    let (k, m) = dense_pencil(&body, &terms);
    let dense = dense_eigenvalues(&k, &m);
    let rigid = rigid_modes(&body).unwrap();
    let affine = affine_modes(&body).unwrap();
    assert_eq!((rigid.ncols(), affine.ncols()), (3, 6));
    assert_mass_orthonormal(&body, affine.as_ref(), 1e-12);
    for j in 0..3 {
        assert!(relative_stiffness_norm(&k, rigid.col_as_slice(j)) < 1e-12);
        // The affine modes start with the rigid ones.
        let diff = (0..body.num_dofs()).fold(0.0f64, |w, d| w.max((rigid[(d, j)] - affine[(d, j)]).abs()));
        assert!(diff < 1e-12, "affine column {j} differs from the rigid one by {diff:e}");
    }
    // The stretches and shears do deform the body.
    for j in 3..6 {
        assert!(relative_stiffness_norm(&k, affine.col_as_slice(j)) > 1e-3);
    }
    let modes = linear_modes(&body, &terms, 4, &LinearModeSettings::default()).unwrap();
    for j in 0..4 {
        let rel = (modes.eigenvalues[j] - dense[3 + j]).abs() / dense[3 + j];
        assert!(
            rel < 1e-9,
            "lambda_{j}: {} vs dense {}",
            modes.eigenvalues[j],
            dense[3 + j]
        );
    }
}

#[test]
fn degenerate_vertex_sets_lose_the_modes_they_cannot_have() {
    // A straight rod along a diagonal: no rotation about its own axis.
    let rest: Vec<f64> = (0..5).flat_map(|i| [i as f64, i as f64, i as f64]).collect();
    let masses = vec![1.0; 5];
    let rod = Body {
        dim: 3,
        rest: &rest,
        masses: &masses,
        fixed_vertices: &[],
    };
    assert_eq!(rigid_modes(&rod).unwrap().ncols(), 5);
    // A flat sheet (z = 0): no map that scales with z.
    let sheet: Vec<f64> = (0..9).flat_map(|v| [(v % 3) as f64, (v / 3) as f64, 0.0]).collect();
    let masses = vec![0.5; 9];
    let body = Body {
        dim: 3,
        rest: &sheet,
        masses: &masses,
        fixed_vertices: &[4],
    };
    let affine = affine_modes(&body).unwrap();
    assert_eq!(affine.ncols(), 9);
    assert_mass_orthonormal(&body, affine.as_ref(), 1e-12);
    assert_eq!(affine.as_ref().subrows(12, 3).norm_l2(), 0.0);
    // Every vertex prescribed: nothing moves.
    let all: Vec<usize> = (0..9).collect();
    let pinned = Body {
        fixed_vertices: &all,
        ..body
    };
    assert_eq!(affine_modes(&pinned).unwrap().ncols(), 0);
}

#[test]
fn cantilever_bending_matches_euler_bernoulli() {
    // A 1 x 0.1 x 0.1 beam clamped at x = 0, against omega = 1.875^2 sqrt(E I / (rho A L^4)).
    // The linear modes are the linear-elastic limit of stable neo-Hookean (its Hessian at
    // rest is linear elasticity with the same Lame parameters); nu = 0 leaves no Poisson
    // contraction for the clamp to stiffen. Linear tets are too stiff in bending, by an
    // error of order h^2: measured, the two bending frequencies (y and z; the Kuhn split
    // makes one stiffer) are 6.7% and 12.3% above the theory with 4 cells across the
    // section, 1.3% and 2.8% with 8. Extrapolating those two meshes to h = 0 (Richardson,
    // order 2) leaves -0.55% and -0.40%: Euler-Bernoulli neglects shear and rotary inertia,
    // which lower the frequency of a beam of L/h = 10 by about that much (Timoshenko).
    let (length, side) = (1.0f64, 0.1f64);
    let material = ElementMaterial {
        youngs: 1e7,
        poisson: 0.0,
        density: 1000.0,
    };
    let (area, inertia) = (side * side, side.powi(4) / 12.0);
    let theory = 1.875f64.powi(2) * (material.youngs * inertia / (material.density * area * length.powi(4))).sqrt();
    let bending = |across: usize| -> Vec<f64> {
        let s = solid([length, side, side], [10 * across, across, across], material);
        let fixed = s.clamped_end();
        let elastic: [&dyn StencilEnergy; 1] = [&s.elastic];
        let modes = linear_modes(&s.body(&fixed), &elastic, 2, &LinearModeSettings::default()).unwrap();
        modes.eigenvalues.iter().map(|l| l.sqrt()).collect()
    };
    let (coarse, fine) = (bending(4), bending(8));
    for j in 0..2 {
        let (e_coarse, e_fine) = (coarse[j] / theory - 1.0, fine[j] / theory - 1.0);
        assert!(
            e_fine > 0.0 && e_fine < 0.03,
            "mode {j}: {:.4} rad/s vs {theory:.4} (8 across)",
            fine[j]
        );
        assert!(
            e_coarse > 3.0 * e_fine,
            "mode {j}: error {e_coarse:.4} with 4 across, {e_fine:.4} with 8"
        );
        let extrapolated = (4.0 * fine[j] - coarse[j]) / 3.0;
        let e = extrapolated / theory - 1.0;
        assert!(
            e.abs() < 0.01,
            "mode {j}: extrapolated {extrapolated:.4} rad/s vs {theory:.4}"
        );
    }
}

#[test]
fn impossible_requests_are_errors() {
    let s = solid([1.0, 0.5, 0.5], [2, 1, 1], RUBBER);
    let elastic: [&dyn StencilEnergy; 1] = [&s.elastic];
    let settings = LinearModeSettings::default();
    // Floating: 12 vertices, 36 dofs, 6 of them rigid.
    let body = s.body(&[]);
    let err = linear_modes(&body, &elastic, 31, &settings).unwrap_err();
    assert!(
        matches!(
            err,
            CandidateError::TooManyModes {
                requested: 31,
                available: 30,
                free_dofs: 36,
                deflated: 6
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("asked for 31 linear modes"), "{err}");
    // Exactly as many as there are: the Krylov space is the whole complement.
    let all = linear_modes(&body, &elastic, 30, &settings).unwrap();
    assert_eq!(all.eigenvalues.len(), 30);
    assert!(all.eigenvalues.windows(2).all(|w| w[0] <= w[1]));
    // Every vertex prescribed.
    let fixed: Vec<usize> = (0..s.mesh.num_vertices()).collect();
    let pinned = s.body(&fixed);
    assert!(matches!(
        linear_modes(&pinned, &elastic, 1, &settings),
        Err(CandidateError::TooManyModes { available: 0, .. })
    ));
    // Malformed bodies and settings.
    let short = Body {
        masses: &s.masses[1..],
        ..body
    };
    assert!(matches!(
        linear_modes(&short, &elastic, 1, &settings),
        Err(CandidateError::InvalidBody(_))
    ));
    let out_of_range = s.body(&[99]);
    let err = rigid_modes(&out_of_range).unwrap_err();
    assert!(err.to_string().contains("fixed vertex 99 out of range"), "{err}");
    let bad = LinearModeSettings {
        relative_shift: -1.0,
        ..settings
    };
    assert!(matches!(
        linear_modes(&body, &elastic, 1, &bad),
        Err(CandidateError::InvalidSetting(_))
    ));
    // A tolerance no cycle can meet, with no restart allowed.
    let strict = LinearModeSettings {
        lanczos: LanczosSettings {
            tolerance: 1e-300,
            max_restarts: 0,
            ..LanczosSettings::default()
        },
        ..settings
    };
    let big_enough = solid([1.0, 0.3, 0.3], [6, 2, 2], RUBBER);
    let clamped_big = big_enough.clamped_end();
    let terms: [&dyn StencilEnergy; 1] = [&big_enough.elastic];
    let err = linear_modes(&big_enough.body(&clamped_big), &terms, 2, &strict).unwrap_err();
    assert!(matches!(err, CandidateError::NotConverged { restarts: 0, .. }), "{err}");
    // An energy over another mesh's vertices.
    let big = solid([1.0, 0.5, 0.5], [3, 1, 1], RUBBER);
    let foreign: [&dyn StencilEnergy; 1] = [&big.elastic];
    assert!(matches!(
        linear_modes(&body, &foreign, 1, &settings),
        Err(CandidateError::InvalidBody(_))
    ));
}

#[test]
fn candidate_sets_group_modes_into_blocks() {
    let s = solid([1.0, 0.3, 0.3], [4, 1, 1], RUBBER);
    let fixed = s.clamped_end();
    let body = s.body(&fixed);
    let elastic: [&dyn StencilEnergy; 1] = [&s.elastic];
    let spec = CandidateSpec {
        linear_modes: 3,
        ..CandidateSpec::default()
    };
    let set = CandidateSet::new(&body, &elastic, &spec).unwrap();
    let kinds: Vec<BlockKind> = set.blocks.iter().map(|b| b.kind).collect();
    assert_eq!(
        kinds,
        [
            BlockKind::Rigid,
            BlockKind::Affine,
            BlockKind::LinearMode(0),
            BlockKind::LinearMode(1),
            BlockKind::LinearMode(2)
        ]
    );
    assert_eq!(set.blocks[0].columns, 0..6);
    assert_eq!(set.blocks[1].columns, 6..12);
    assert_eq!(set.modes.ncols(), 15);
    assert_eq!(set.modes.nrows(), 3 * s.mesh.num_vertices());
    for b in 0..set.blocks.len() {
        assert_mass_orthonormal(&body, set.block(b), 1e-10);
    }
    let linear = set.linear.as_ref().unwrap();
    let diff = (0..set.modes.nrows()).fold(0.0f64, |w, d| {
        w.max((set.block(3)[(d, 0)] - linear.modes[(d, 1)]).abs())
    });
    assert_eq!(diff, 0.0);
}

#[test]
fn a_scene_clamps_its_handles_vertices() {
    let text = r#"
name = "bar"
[mesh]
type = "box"
min = [0.0, 0.0, 0.0]
max = [1.0, 0.2, 0.2]
cells = [5, 1, 1]
[material]
youngs = 1e6
poisson = 0.3
density = 1000.0
[[handles]]
name = "clamp"
select = { side = { axis = 0, end = "min" } }
"#;
    let scene = Scene::parse(text, Path::new("bar.toml")).unwrap();
    let spec = CandidateSpec {
        linear_modes: 4,
        ..CandidateSpec::default()
    };
    let set = scene.candidate_set(&spec).unwrap();
    let s = solid([1.0, 0.2, 0.2], [5, 1, 1], RUBBER);
    let fixed = s.clamped_end();
    assert_eq!(fixed.len(), 4);
    let elastic: [&dyn StencilEnergy; 1] = [&s.elastic];
    let direct = linear_modes(&s.body(&fixed), &elastic, 4, &LinearModeSettings::default()).unwrap();
    let from_scene = set.linear.as_ref().unwrap();
    for j in 0..4 {
        let rel = (from_scene.eigenvalues[j] - direct.eigenvalues[j]).abs() / direct.eigenvalues[j];
        assert!(
            rel < 1e-9,
            "lambda_{j}: {} from the scene, {} direct",
            from_scene.eigenvalues[j],
            direct.eigenvalues[j]
        );
    }
    for &v in &fixed {
        assert_eq!(set.modes.as_ref().subrows(3 * v, 3).norm_l2(), 0.0, "vertex {v} moves");
    }
    // A handle over vertices the mesh lacks: the error names the field.
    let bad_text = text.replace("{ side = { axis = 0, end = \"min\" } }", "{ indices = [999] }");
    let bad = Scene::parse(&bad_text, Path::new("bar.toml")).unwrap();
    let err = bad.candidate_set(&spec).unwrap_err();
    assert!(matches!(err, CandidateError::Input(_)), "{err}");
    assert!(err.to_string().contains("handles[0].select"), "{err}");
}
