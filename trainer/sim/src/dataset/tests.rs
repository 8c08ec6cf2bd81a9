//! Tests of [`crate::dataset`].

use super::*;

#[test]
fn frame_rates_spread_over_training_and_validation_and_leave_tests_at_the_scene_step() {
    let spec = DatasetSpec {
        train: 6,
        varied: 1,
        frame_rates: Some([30.0, 120.0]),
        ..DatasetSpec::default()
    };
    let plans = plan(&spec);
    for split in [Split::Train, Split::Validation] {
        let mut rates: Vec<f64> = plans
            .iter()
            .filter(|p| p.split == split)
            .map(|p| 1.0 / p.dt.expect("a frame time"))
            .collect();
        let in_order = rates.clone();
        rates.sort_by(f64::total_cmp);
        assert!((rates[0] - 30.0).abs() < 1e-9 && (rates[rates.len() - 1] - 120.0).abs() < 1e-9);
        // Geometric: equal ratios between neighbours.
        let ratios: Vec<f64> = rates.windows(2).map(|w| w[1] / w[0]).collect();
        assert!(ratios.iter().all(|r| (r - ratios[0]).abs() < 1e-9), "{ratios:?}");
        if split == Split::Train {
            assert_ne!(in_order, rates, "rates follow the speed levels");
        }
    }
    assert!(plans.iter().filter(|p| p.split == Split::Test).all(|p| p.dt.is_none()));
    // The same plan without rates is the plan with them, frame times aside.
    let plain = plan(&DatasetSpec {
        frame_rates: None,
        ..spec
    });
    for (a, b) in plain.iter().zip(&plans) {
        assert_eq!((&a.name, &a.speeds, a.seed), (&b.name, &b.speeds, b.seed));
    }
}

#[test]
fn plan_holds_out_test_speeds_and_goes_beyond_the_range() {
    let spec = DatasetSpec {
        train: 5,
        test: 5,
        frames: 100,
        seed: 3,
        beyond: 1.5,
        test_frames: None,
        steady: 0,
        varied: 0,
        validation: 2,
        frame_rates: None,
    };
    let plans = plan(&spec);
    let train: Vec<f64> = plans
        .iter()
        .filter(|p| p.split == Split::Train)
        .map(|p| p.speeds.at(0).0)
        .collect();
    assert_eq!(train, vec![0.0, 0.25, 0.5, 0.75, 1.0]);
    let tests: Vec<&SequencePlan> = plans.iter().filter(|p| p.split == Split::Test).collect();
    assert_eq!(tests.len(), 5);
    // Sudden drop at half time.
    assert_eq!(tests[0].speeds.at(0), (1.0, 1.5));
    assert_eq!(tests[0].speeds.at(50), (1.0, 0.15));
    // Beyond the top of the range.
    assert_eq!(tests[1].speeds.at(10), (1.0, 1.5));
    // Held-out levels differ from every training level.
    for t in &tests[2..] {
        let (level, factor) = t.speeds.at(0);
        assert_eq!(factor, 1.0);
        assert!(
            train.iter().all(|l| (l - level).abs() > 0.1),
            "level {level} too close to training"
        );
    }
    // Validation levels lie between training levels and apart from the test levels.
    let validation: Vec<f64> = plans
        .iter()
        .filter(|p| p.split == Split::Validation)
        .map(|p| p.speeds.at(0).0)
        .collect();
    assert_eq!(validation.len(), 2);
    for level in &validation {
        assert!(
            train.iter().all(|l| (l - level).abs() > 0.05),
            "validation level {level}"
        );
        let apart = tests
            .iter()
            .all(|t| (t.speeds.at(0).0 - level).abs() > 0.01 || t.speeds.at(0).1 != 1.0);
        assert!(apart, "validation level {level} equals a test level");
    }
    let mut seeds: Vec<u64> = plans.iter().map(|p| p.seed).collect();
    seeds.sort();
    seeds.dedup();
    assert_eq!(seeds.len(), plans.len());
}

#[test]
fn steady_sequences_are_added_at_the_top_speed_and_leave_the_tests_alone() {
    let random = DatasetSpec {
        train: 3,
        test: 4,
        ..DatasetSpec::default()
    };
    let with_steady = DatasetSpec { steady: 3, ..random };
    let (a, b) = (plan(&random), plan(&with_steady));
    let of =
        |plans: &[SequencePlan], split: Split| plans.iter().filter(|p| p.split == split).cloned().collect::<Vec<_>>();
    assert_eq!(of(&a, Split::Test), of(&b, Split::Test));
    let (ta, tb) = (of(&a, Split::Train), of(&b, Split::Train));
    assert_eq!(tb.len(), 6);
    assert_eq!(ta[..], tb[..3]);
    let shares: Vec<Option<f64>> = tb[3..].iter().map(|p| p.speeds.steady).collect();
    assert_eq!(shares, vec![Some(0.0), Some(0.5), Some(1.0)]);
    assert!(tb[3..].iter().all(|p| p.speeds.at(0) == (1.0, 1.0)));
    assert_eq!(tb[5].name, "train-05");
}

#[test]
fn varied_sequences_redraw_the_level_and_leave_the_rest_alone() {
    let base = DatasetSpec {
        train: 3,
        steady: 2,
        test: 4,
        frames: 200,
        ..DatasetSpec::default()
    };
    let with_varied = DatasetSpec { varied: 2, ..base };
    let (a, b) = (plan(&base), plan(&with_varied));
    // The same sequences as before, then the varied ones (named after them), then the tests.
    assert_eq!(a[..5], b[..5]);
    assert_eq!(a[5..], b[7..]);
    let varied = &b[5..7];
    assert_eq!(
        (varied[0].name.as_str(), varied[1].name.as_str()),
        ("train-05", "train-06")
    );
    for p in varied {
        assert_eq!(p.split, Split::Train);
        let starts: Vec<usize> = p.speeds.pieces.iter().map(|q| q.0).collect();
        assert_eq!(starts, (0..200).step_by(VARIED_PIECE_FRAMES).collect::<Vec<_>>());
        assert!(p.speeds.pieces.iter().all(|q| (0.0..=1.0).contains(&q.1) && q.2 == 1.0));
        // The level changes from piece to piece.
        assert!(p.speeds.at(0) != p.speeds.at(VARIED_PIECE_FRAMES));
    }
    assert_ne!(varied[0].speeds, varied[1].speeds);
    // Planning is deterministic.
    assert_eq!(plan(&with_varied), b);
}
