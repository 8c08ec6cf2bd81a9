//! Invariances of the measures, the modal formulas, and how the gradient and the
//! prescribed vertices enter.

use super::*;

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
