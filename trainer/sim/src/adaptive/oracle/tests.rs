//! The oracle's scales against hand-computed values, the invariances the measures are
//! built for, and its decisions on a poked body and on a translating one.

use super::*;
use crate::adaptive::candidates::{rigid_modes, Body, CandidateSpec};
use crate::adaptive::partition::Partition;
use crate::energy::external::ConstantForce;
use crate::energy::inertia::{lumped_masses, Inertia};
use crate::energy::tet::TetElastic;
use crate::energy::tri2d::Tri2dElastic;
use crate::energy::{self, StencilEnergy};
use crate::material::{ElementMaterial, MaterialLaw};
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

#[test]
fn single_tet_scales_are_opposite_face_areas_and_quarter_volumes() {
    let rest = [0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 3.0, 0.0, 0.0, 0.0, 1.0];
    let e = tets(&rest, &[[0, 1, 2, 3]], MaterialLaw::Stvk, RUBBER);
    let s = NodeScales::new(3, &rest, &[&e]).unwrap();
    // Faces opposite each vertex: (2,0,0)-(0,3,0)-(0,0,1) has area |(3, 2, 6)| / 2 = 3.5;
    // the others are right triangles with legs 3 x 1, 2 x 1 and 2 x 3. Volume 2 * 3 / 6 = 1.
    for (got, want) in s.area.iter().zip([3.5, 1.5, 1.0, 3.0]) {
        assert!(close(*got, want, 1e-14), "area {got} vs {want}");
    }
    assert!(s.volume.iter().all(|v| close(*v, 0.25, 1e-14)), "{:?}", s.volume);
    let h = stvk_rest_norm(RUBBER, 3);
    assert!(
        s.hessian_norm.iter().all(|v| close(*v, h, 1e-12)),
        "{:?} vs {h}",
        s.hessian_norm
    );
    assert!(close(s.error_scale(0, 0.1), 0.01 * 3.5 * h, 1e-12));
    assert!(close(s.progress_scale(2, 0.1), 0.01 * 0.25 * h, 1e-12));
}

#[test]
fn single_triangle_scales_are_opposite_edges_and_third_areas() {
    let rest = [0.0, 0.0, 3.0, 0.0, 0.0, 4.0];
    let e = Tri2dElastic::new(MaterialLaw::Stvk, &rest, &[[0, 1, 2]], &[RUBBER], Path::new("test")).unwrap();
    let s = NodeScales::new(2, &rest, &[&e]).unwrap();
    for (got, want) in s.area.iter().zip([5.0, 4.0, 3.0]) {
        assert!(close(*got, want, 1e-14), "length {got} vs {want}");
    }
    assert!(s.volume.iter().all(|v| close(*v, 2.0, 1e-14)), "{:?}", s.volume);
    let h = stvk_rest_norm(RUBBER, 2);
    assert!(
        s.hessian_norm.iter().all(|v| close(*v, h, 1e-12)),
        "{:?} vs {h}",
        s.hessian_norm
    );
}

#[test]
fn box_scales_match_the_kuhn_split_by_hand() {
    // Two unit cubes along x, 6 tets each around the diagonal (0,0,0)-(1,1,1) of each cube.
    let mesh = box_tets([0.0; 3], [2.0, 1.0, 1.0], [2, 1, 1]).unwrap();
    let Elements::Tets(t) = &mesh.elements else {
        unreachable!()
    };
    let neo = tets(&mesh.rest, t, MaterialLaw::StableNeoHookean, RUBBER);
    let s = NodeScales::new(3, &mesh.rest, &[&neo]).unwrap();
    let id = |i: usize, j: usize, k: usize| i + 3 * (j + 2 * k);
    // A cube's diagonal corners lie in all 6 of its tets, the others in 2, each tet a sixth.
    let v = |tets: f64| tets / 6.0 / 4.0;
    let want_volume = [
        (id(0, 0, 0), v(6.0)),
        (id(1, 0, 0), v(2.0 + 6.0)),
        (id(2, 0, 0), v(2.0)),
        (id(1, 1, 1), v(6.0 + 2.0)),
        (id(2, 1, 1), v(6.0)),
        (id(0, 1, 0), v(2.0)),
    ];
    for (vertex, want) in want_volume {
        assert!(
            close(s.volume[vertex], want, 1e-14),
            "V of {vertex}: {} vs {want}",
            s.volume[vertex]
        );
    }
    assert!(close(s.volume.iter().sum(), 2.0, 1e-14));
    // The faces opposite a diagonal corner tile the cube's three far faces (area 3); the
    // faces opposite (1,0,0) in the first cube are the two half-diagonal planes through
    // (0,0,0), (1,1,0) or (1,0,1), and (1,1,1): right triangles of legs 1 and sqrt 2.
    let half_diagonal = 2.0f64.sqrt() / 2.0;
    for (vertex, want) in [
        (id(0, 0, 0), 3.0),
        (id(2, 1, 1), 3.0),
        (id(1, 0, 0), 2.0 * half_diagonal + 3.0),
    ] {
        assert!(
            close(s.area[vertex], want, 1e-14),
            "A of {vertex}: {} vs {want}",
            s.area[vertex]
        );
    }
    // The density Hessian at rest depends on the material only, not on the tet's shape.
    let first = s.hessian_norm[0];
    assert!(
        s.hessian_norm.iter().all(|h| close(*h, first, 1e-10)),
        "{:?}",
        s.hessian_norm
    );
    let stiffer = tets(
        &mesh.rest,
        t,
        MaterialLaw::StableNeoHookean,
        ElementMaterial {
            youngs: 3.0 * RUBBER.youngs,
            ..RUBBER
        },
    );
    let s3 = NodeScales::new(3, &mesh.rest, &[&stiffer]).unwrap();
    assert!(close(s3.hessian_norm[5], 3.0 * first, 1e-12));
}

#[test]
fn scales_reject_non_simplex_stencils_and_uncovered_vertices() {
    let rest = [
        0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 5.0, 5.0, 5.0,
    ];
    let e = tets(&rest, &[[0, 1, 2, 3]], MaterialLaw::Stvk, RUBBER);
    let err = NodeScales::new(3, &rest, &[&e]).unwrap_err();
    assert!(err.to_string().contains("vertex 4"), "{err}");
    let load = ConstantForce::load(3, vec![0], [1.0, 0.0, 0.0]);
    let err = NodeScales::new(3, &rest[..12], &[&load]).unwrap_err();
    assert!(err.to_string().contains("4 vertices"), "{err}");
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

/// The nodal measures and the block scores of every candidate block of `solid` in a
/// deformed state, with the predicted positions elsewhere, for the invariance tests.
fn measures(solid: &mut Solid, size: f64, zero_inertia: bool, linear_modes: usize) -> (NodalMeasures, Vec<BlockScore>) {
    let x = deformed(&solid.mesh.rest, size, 0.2);
    let xhat = if zero_inertia {
        x.clone()
    } else {
        deformed(&solid.mesh.rest, size, 0.1)
    };
    solid.inertia.set_target(&xhat);
    let step = deformed(&solid.mesh.rest, size, 0.05)
        .iter()
        .zip(&solid.mesh.rest)
        .map(|(a, b)| a - b)
        .collect::<Vec<_>>();
    let spec = CandidateSpec {
        linear_modes,
        ..CandidateSpec::default()
    };
    let candidates = CandidateSet::new(&solid.body(), &[&solid.elastic], &spec).unwrap();
    let oracle = Oracle::new(solid.scales(), &[], &vec![0; solid.masses.len()], Thresholds::default()).unwrap();
    let terms = solid.terms(&[]);
    let g = gradient(&terms, &x);
    let query = Query {
        terms: &terms,
        x: &x,
        gradient: &g,
        step: &step,
        dt: solid.dt,
    };
    let decision = oracle
        .decide(&query, &candidates, &vec![false; candidates.blocks.len()], &[false])
        .unwrap();
    (decision.nodal, decision.blocks)
}

fn assert_same(a: &(NodalMeasures, Vec<BlockScore>), b: &(NodalMeasures, Vec<BlockScore>), progress: bool) {
    // Relative to the largest value of each kind: some block progresses cancel to
    // round-off (see `a_one_mode_block_scores_as_the_per_mode_formulas`).
    let same = |what: &str, x: &[f64], y: &[f64]| {
        let scale = x.iter().chain(y).fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(scale > 0.0, "{what} all zero");
        for (p, q) in x.iter().zip(y) {
            assert!((p - q).abs() <= 1e-9 * scale, "{what}: {p} vs {q} (largest {scale})");
        }
    };
    let errors = |m: &(NodalMeasures, Vec<BlockScore>)| m.1.iter().map(|s| s.error).collect::<Vec<_>>();
    let progresses = |m: &(NodalMeasures, Vec<BlockScore>)| m.1.iter().map(|s| s.progress).collect::<Vec<_>>();
    same("nodal error", &a.0.error, &b.0.error);
    same("block error", &errors(a), &errors(b));
    if progress {
        same("nodal progress", &a.0.progress, &b.0.progress);
        same("block progress", &progresses(a), &progresses(b));
    }
}

#[test]
fn measures_are_invariant_under_scaling_the_mesh_with_the_time_step() {
    // Footnote 2: lengths times s and h times s leave both measures unchanged (the
    // inertia and elastic gradients both scale as s⁴, their scale h² A H̄ too).
    let (cells, dt) = ([3, 2, 2], 0.01);
    let base = measures(&mut Solid::new([1.5, 1.0, 1.0], cells, RUBBER, dt), 1.0, false, 0);
    assert!(base.0.error.iter().any(|e| *e > 1e-3) && base.0.progress.iter().any(|p| p.abs() > 1e-6));
    let s = 7.0;
    let scaled = measures(&mut Solid::new([1.5 * s, s, s], cells, RUBBER, dt * s), s, false, 0);
    assert_same(&base, &scaled, true);
    // Without the time step the inertia part no longer keeps pace: the measure changes.
    let unscaled_dt = measures(&mut Solid::new([1.5 * s, s, s], cells, RUBBER, dt), s, false, 0);
    let moved = base
        .0
        .error
        .iter()
        .zip(&unscaled_dt.0.error)
        .filter(|(a, b)| !close(**a, **b, 1e-3));
    assert!(moved.count() > 0);
}

#[test]
fn measures_are_invariant_under_scaling_stiffness_with_density_or_alone_without_inertia() {
    let (hi, cells, dt) = ([1.5, 1.0, 1.0], [3, 2, 2], 0.01);
    let c = 40.0;
    let heavy_stiff = ElementMaterial {
        youngs: c * RUBBER.youngs,
        density: c * RUBBER.density,
        ..RUBBER
    };
    let base = measures(&mut Solid::new(hi, cells, RUBBER, dt), 1.0, false, 0);
    let scaled = measures(&mut Solid::new(hi, cells, heavy_stiff, dt), 1.0, false, 0);
    assert_same(&base, &scaled, true);
    // Young's modulus alone: the elastic gradient and H̄ scale alike, so the error is
    // unchanged where the inertia gradient vanishes (x at the prediction); the progress
    // is not (the step's inertia energy does not scale).
    let stiff = ElementMaterial {
        youngs: c * RUBBER.youngs,
        ..RUBBER
    };
    let base = measures(&mut Solid::new(hi, cells, RUBBER, dt), 1.0, true, 0);
    let scaled = measures(&mut Solid::new(hi, cells, stiff, dt), 1.0, true, 0);
    assert_same(&base, &scaled, false);
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

/// The oracle's decision on a free bar of 8 x 2 x 2 cells, undeformed and at rest but for
/// one end-face vertex `v`, pulled out by most of a cell and loaded by a point force of
/// twice its error scale over `h²`, with a subspace of the rigid modes: the line-searched
/// rigid Newton step, the decision, and `v`.
fn point_load(dt: f64) -> (Solid, Partition, Decision, usize) {
    let cells = [8, 2, 2];
    let mut solid = Solid::new([4.0, 1.0, 1.0], cells, RUBBER, dt);
    let v = grid(cells, 0, 1, 1);
    let mut x = solid.mesh.rest.clone();
    x[3 * v] -= 0.4;
    x[3 * v + 1] += 0.1;
    solid.inertia.set_target(&x);
    let f = 2.0 * solid.scales().error_scale(v, 1.0);
    let load = ConstantForce::load(3, vec![v], [-0.8 * f, 0.6 * f, 0.0]);
    let extra: [&dyn StencilEnergy; 1] = [&load];
    let terms = solid.terms(&extra);
    let g = gradient(&terms, &x);
    let step = subspace_step(&terms, &x, &rigid_basis(&solid));
    let partition = Partition::new(&solid.mesh, 4).unwrap();
    let oracle = Oracle::new(
        solid.scales(),
        &[],
        partition.vertex_subdomains(),
        Thresholds::default(),
    )
    .unwrap();
    let spec = CandidateSpec {
        linear_modes: 0,
        ..CandidateSpec::default()
    };
    let candidates = CandidateSet::new(&solid.body(), &[&solid.elastic], &spec).unwrap();
    let query = Query {
        terms: &terms,
        x: &x,
        gradient: &g,
        step: &step,
        dt,
    };
    let decision = oracle.decide(&query, &candidates, &[true, false], &[false; 4]).unwrap();
    drop(terms);
    (solid, partition, decision, v)
}

#[test]
fn a_point_load_enriches_the_subdomain_around_it_and_not_the_far_ones() {
    // At a step much shorter than a wave's time to cross the bar, the rigid step barely
    // moves it, so the load's vertex keeps its error and makes no progress.
    let (solid, partition, d, v) = point_load(2e-5);
    let th = Thresholds::default();
    let ring = one_ring(&solid.mesh, v);
    let err = &d.nodal.error;
    let top = (0..err.len()).max_by(|&a, &b| err[a].total_cmp(&err[b])).unwrap();
    assert_eq!(
        top, v,
        "largest error at {top}, {} there, {} at the loaded vertex",
        err[top], err[v]
    );
    for w in 0..err.len() {
        if ring[w] {
            assert!(err[w] > 1e-2 * err[v], "neighbour {w}: error {} vs {}", err[w], err[v]);
        } else {
            assert!(err[w] < 1e-6 * err[v], "far vertex {w}: error {}", err[w]);
        }
    }
    assert!(
        err[v] > th.nodal_error && d.nodal.progress[v] < th.progress,
        "{} {}",
        err[v],
        d.nodal.progress[v]
    );
    let subdomain = partition.vertex_subdomains();
    let near: Vec<usize> = (0..err.len()).filter(|&w| ring[w]).map(|w| subdomain[w]).collect();
    let enriched: Vec<usize> = d.enrich_subdomains.iter().map(|s| s.subdomain).collect();
    assert!(enriched.contains(&subdomain[v]), "{enriched:?}");
    assert!(
        enriched.iter().all(|l| near.contains(l)),
        "{enriched:?} vs near {near:?}"
    );
    assert!((0..4).filter(|l| !near.contains(l)).count() >= 2, "near {near:?}");
    let by_v = d
        .enrich_subdomains
        .iter()
        .find(|s| s.subdomain == subdomain[v])
        .unwrap();
    assert_eq!((by_v.vertex, by_v.error), (v, err[v]));
}

#[test]
fn a_point_load_that_one_rigid_step_absorbs_shows_as_progress() {
    // At a 500 times longer step the rigid step moves the bar far enough that the load's
    // work on it (Eq. 7 counts the load's own stencil at its vertex) is progress there:
    // the same error no longer enriches.
    let (_, _, d, v) = point_load(1e-2);
    let th = Thresholds::default();
    assert!(d.nodal.error[v] > th.nodal_error, "{}", d.nodal.error[v]);
    assert!(d.nodal.progress[v] > th.progress, "{}", d.nodal.progress[v]);
    assert!(d.enrich_subdomains.is_empty(), "{:?}", d.enrich_subdomains);
}

#[test]
fn a_translation_the_subspace_holds_makes_progress_and_enriches_nothing() {
    // Fig. 5: the body is predicted to slide by t along x; the translation mode moves it
    // there exactly, so every vertex's large error comes with large progress.
    let cells = [4, 2, 2];
    let mut solid = Solid::new([2.0, 1.0, 1.0], cells, RUBBER, 0.003);
    let t = 0.1;
    let x = solid.mesh.rest.clone();
    let xhat: Vec<f64> = x
        .iter()
        .enumerate()
        .map(|(k, p)| p + if k % 3 == 0 { t } else { 0.0 })
        .collect();
    solid.inertia.set_target(&xhat);
    let terms = solid.terms(&[]);
    let g = gradient(&terms, &x);
    let step = subspace_step(&terms, &x, &rigid_basis(&solid));
    for (k, s) in step.iter().enumerate() {
        let want = if k % 3 == 0 { t } else { 0.0 };
        assert!((s - want).abs() < 1e-9 * t, "step[{k}] = {s}");
    }
    let partition = Partition::new(&solid.mesh, 3).unwrap();
    let oracle = Oracle::new(
        solid.scales(),
        &[],
        partition.vertex_subdomains(),
        Thresholds::default(),
    )
    .unwrap();
    let spec = CandidateSpec {
        linear_modes: 2,
        ..CandidateSpec::default()
    };
    let candidates = CandidateSet::new(&solid.body(), &[&solid.elastic], &spec).unwrap();
    let mut active = vec![false; candidates.blocks.len()];
    active[0] = true;
    let query = Query {
        terms: &terms,
        x: &x,
        gradient: &g,
        step: &step,
        dt: solid.dt,
    };
    let th = oracle.thresholds();
    let d = oracle.decide(&query, &candidates, &active, &[false; 3]).unwrap();
    assert!(d.nodal.error.iter().all(|e| *e > th.nodal_error), "{:?}", d.nodal.error);
    assert!(
        d.nodal.progress.iter().all(|p| *p > th.progress),
        "{:?}",
        d.nodal.progress
    );
    assert!(d.enrich_subdomains.is_empty(), "{:?}", d.enrich_subdomains);
    assert!(d.activate_blocks.is_empty(), "{:?}", d.blocks);
    // Without the active step the same error enriches every subdomain.
    let still = vec![0.0; x.len()];
    let d = oracle
        .decide(&Query { step: &still, ..query }, &candidates, &active, &[false; 3])
        .unwrap();
    assert_eq!(d.enrich_subdomains.len(), 3, "{:?}", d.enrich_subdomains);
}

#[test]
fn a_one_mode_block_scores_as_the_per_mode_formulas() {
    let cells = [3, 2, 2];
    let mut solid = Solid::new([1.5, 1.0, 1.0], cells, RUBBER, 0.01);
    let spec = CandidateSpec {
        linear_modes: 3,
        ..CandidateSpec::default()
    };
    let candidates = CandidateSet::new(&solid.body(), &[&solid.elastic], &spec).unwrap();
    let (nodal, blocks) = measures(&mut solid, 1.0, false, 3);
    let scales = solid.scales();
    let x = deformed(&solid.mesh.rest, 1.0, 0.2);
    let g = gradient(&solid.terms(&[]), &x);
    let n = solid.masses.len();
    let mut checked = 0;
    for (b, block) in candidates.blocks.iter().enumerate() {
        if block.columns.len() != 1 {
            continue;
        }
        let u: Vec<f64> = (0..3 * n).map(|r| candidates.modes[(r, block.columns.start)]).collect();
        // Eq. 12 and 14.
        let c = u.iter().zip(&g).map(|(a, b)| a * b).sum::<f64>() / u.iter().map(|a| a * a).sum::<f64>();
        let error = (0..n)
            .map(|i| (0..3).map(|k| (c * u[3 * i + k]).powi(2)).sum::<f64>().sqrt() / scales.error_scale(i, 0.01))
            .fold(0.0, f64::max);
        // Eq. 13 and 15.
        let ubar: Vec<f64> = (0..n).map(|i| (u[3 * i] + u[3 * i + 1] + u[3 * i + 2]) / 3.0).collect();
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let cbar = dot(&ubar, &nodal.energy_change) / dot(&ubar, &ubar);
        let progress: f64 = (0..n).map(|i| cbar * ubar[i] / scales.progress_scale(i, 0.01)).sum();
        let got = &blocks[b];
        assert_eq!(got.block, b);
        assert!(close(got.error, error, 1e-12), "block {b}: {} vs {error}", got.error);
        assert!(
            close(got.progress, progress, 1e-10),
            "block {b}: {} vs {progress}",
            got.progress
        );
        assert!(error > 0.0 && progress.abs() > 0.0);
        checked += 1;
    }
    assert_eq!(checked, 3);
}

#[test]
fn gradient_without_a_stencil_form_counts_at_its_vertex() {
    // A force given only through the gradient (as contact would be) gives the same nodal
    // error as the same force given as a single-vertex stencil term.
    let cells = [3, 2, 2];
    let mut solid = Solid::new([1.5, 1.0, 1.0], cells, RUBBER, 0.01);
    let x = deformed(&solid.mesh.rest, 1.0, 0.1);
    solid.inertia.set_target(&solid.mesh.rest.clone());
    let v = grid(cells, 3, 2, 1);
    // A force of the size of the vertex's error scale over h² (error about 1).
    let f = solid.scales().error_scale(v, 1.0);
    let load = ConstantForce::load(3, vec![v], [0.8 * f, -0.6 * f, 0.0]);
    let extra: [&dyn StencilEnergy; 1] = [&load];
    let with_load = solid.terms(&extra);
    let g = gradient(&with_load, &x);
    let step = vec![0.0; x.len()];
    let oracle = Oracle::new(solid.scales(), &[], &vec![0; solid.masses.len()], Thresholds::default()).unwrap();
    let q = Query {
        terms: &with_load,
        x: &x,
        gradient: &g,
        step: &step,
        dt: solid.dt,
    };
    let stencil = oracle.nodal(&q).unwrap();
    let without = solid.terms(&[]);
    let remainder = oracle.nodal(&Query { terms: &without, ..q }).unwrap();
    for (w, (a, b)) in stencil.error.iter().zip(&remainder.error).enumerate() {
        assert!(close(*a, *b, 1e-12), "vertex {w} (load at {v}): {a} vs {b}");
    }
    let bare = gradient(&without, &x);
    let unloaded = oracle.nodal(&Query { gradient: &bare, ..q }).unwrap();
    assert!(
        stencil.error[v] > 2.0 * unloaded.error[v],
        "{} vs {}",
        stencil.error[v],
        unloaded.error[v]
    );
}

#[test]
fn prescribed_vertices_are_not_candidates_and_bad_input_is_named() {
    let cells = [2, 1, 1];
    let solid = Solid::new([1.0, 0.5, 0.5], cells, RUBBER, 0.01);
    let fixed = [grid(cells, 0, 0, 0)];
    let oracle = Oracle::new(
        solid.scales(),
        &fixed,
        &vec![0; solid.masses.len()],
        Thresholds::default(),
    )
    .unwrap();
    let terms = solid.terms(&[]);
    let x = deformed(&solid.mesh.rest, 1.0, 0.3);
    let g = gradient(&terms, &x);
    let step = vec![0.0; x.len()];
    let q = Query {
        terms: &terms,
        x: &x,
        gradient: &g,
        step: &step,
        dt: solid.dt,
    };
    let m = oracle.nodal(&q).unwrap();
    assert_eq!((m.error[fixed[0]], m.progress[fixed[0]]), (0.0, 0.0));
    assert!(m.error.iter().any(|e| *e > 0.0));
    let err = oracle.nodal(&Query { dt: 0.0, ..q }).unwrap_err();
    assert!(err.to_string().contains("dt"), "{err}");
    let err = oracle.nodal(&Query { step: &step[1..], ..q }).unwrap_err();
    assert!(err.to_string().contains("step has"), "{err}");
    let err = Oracle::new(
        solid.scales(),
        &[99],
        &vec![0; solid.masses.len()],
        Thresholds::default(),
    )
    .unwrap_err();
    assert!(err.to_string().contains("fixed vertex 99"), "{err}");
}
