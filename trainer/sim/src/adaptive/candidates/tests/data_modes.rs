//! Data modes: the mass-weighted span of data frames, joining a candidate set.

use super::*;

#[test]
fn data_modes_are_the_mass_weighted_span_of_the_frames() {
    let s = solid([0.4, 0.1, 0.1], [4, 1, 1], RUBBER);
    let fixed = s.clamped_end();
    let body = s.body(&fixed);
    let n = body.num_dofs();
    let (free_index, _) = body.free_dofs();
    // Two displacement patterns, zero on the clamped end: a sag and a twist-like field.
    let pattern = |k: usize, which: usize| {
        if free_index[k] == crate::dofs::NOT_FREE {
            return 0.0;
        }
        let (v, c) = (k / 3, k % 3);
        let x = s.mesh.rest[3 * v];
        match (which, c) {
            (0, 1) => -x * x,
            (1, 2) => x * s.mesh.rest[3 * v + 1],
            (1, 1) => -x * s.mesh.rest[3 * v + 2],
            _ => 0.0,
        }
    };
    let frames: Vec<Vec<f64>> = [(1.0, 0.0), (0.5, 2.0), (-1.0, 1.0), (2.0, -0.5)]
        .iter()
        .map(|&(a, b)| {
            (0..n)
                .map(|k| s.mesh.rest[k] + a * pattern(k, 0) + b * pattern(k, 1))
                .collect()
        })
        .collect();
    let refs: Vec<&[f64]> = frames.iter().map(Vec::as_slice).collect();
    // Five asked for, two spanned.
    let modes = data_modes(&body, &refs, 5).unwrap();
    assert_eq!(modes.ncols(), 2);
    assert_mass_orthonormal(&body, modes.as_ref(), 1e-10);
    for &v in &fixed {
        for c in 0..3 {
            assert_eq!(modes[(3 * v + c, 0)], 0.0);
            assert_eq!(modes[(3 * v + c, 1)], 0.0);
        }
    }
    // Each pattern lies in the modes' span: its M-projection leaves nothing.
    for which in 0..2 {
        let p: Vec<f64> = (0..n).map(|k| pattern(k, which)).collect();
        let mut residual = p.clone();
        for c in 0..2 {
            let coefficient: f64 = (0..n).map(|k| modes[(k, c)] * s.masses[k / 3] * p[k]).sum();
            residual
                .iter_mut()
                .enumerate()
                .for_each(|(k, r)| *r -= coefficient * modes[(k, c)]);
        }
        let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
        assert!(norm(&residual) < 1e-10 * norm(&p), "{which}: {}", norm(&residual));
    }
    // The larger variance comes first.
    let one = data_modes(&body, &refs, 1).unwrap();
    assert_eq!(one.ncols(), 1);
    let dot: f64 = (0..n).map(|k| one[(k, 0)] * s.masses[k / 3] * modes[(k, 0)]).sum();
    assert!((dot.abs() - 1.0).abs() < 1e-10);
}

#[test]
fn data_modes_join_the_candidates_one_block_each_and_refuse_bad_frames() {
    let s = solid([0.4, 0.1, 0.1], [4, 1, 1], RUBBER);
    let fixed = s.clamped_end();
    let body = s.body(&fixed);
    let n = body.num_dofs();
    let spec = CandidateSpec {
        linear_modes: 2,
        ..CandidateSpec::default()
    };
    let set = CandidateSet::new(&body, &[&s.elastic], &spec).unwrap();
    let before = set.modes.ncols();
    let frames: Vec<Vec<f64>> = (1..4)
        .map(|i| (0..n).map(|k| s.mesh.rest[k] + 1e-3 * ((i * k) % 7) as f64).collect())
        .collect();
    let refs: Vec<&[f64]> = frames.iter().map(Vec::as_slice).collect();
    let modes = data_modes(&body, &refs, 3).unwrap();
    let set = set.with_data_modes(modes).unwrap();
    let data: Vec<_> = set
        .blocks
        .iter()
        .filter(|b| matches!(b.kind, BlockKind::DataMode(_)))
        .collect();
    assert_eq!(data.len(), 3);
    assert_eq!(data[0].columns, before..before + 1);
    assert_eq!(set.modes.ncols(), before + 3);

    let short = vec![0.0; n - 1];
    let err = data_modes(&body, &[&short], 1).unwrap_err().to_string();
    assert!(err.contains("data frame 0 has"), "{err}");
    let mut bad = frames[0].clone();
    bad[5] = f64::NAN;
    let err = data_modes(&body, &[&bad], 1).unwrap_err().to_string();
    assert!(err.contains("non-finite"), "{err}");
    let err = set.with_data_modes(Mat::zeros(n + 1, 1)).unwrap_err().to_string();
    assert!(err.contains("rows"), "{err}");
}
