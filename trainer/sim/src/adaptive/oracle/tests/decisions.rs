//! Decisions: a point load at two time steps, and a translation the subspace holds.

use super::*;

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
