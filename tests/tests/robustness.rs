//! The runtime never panics and never writes a NaN: random and hostile boundary conditions,
//! wrong buffer lengths, latents driven out of the trained range, and artifacts made of random,
//! truncated or corrupted bytes all get a documented answer.

use mochi_runtime::artifact::{FORMAT_VERSION, MAGIC};
use mochi_runtime::{
    envelope, DecodeError, EnvelopeError, HandleMotion, LoadError, LoadedModel, OwnedModel, StepError, Stepped,
    ValidModel, RANGE_MARGIN,
};
use mochi_tests::tiny;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn model() -> ValidModel<'static> {
    ValidModel::new(tiny::MODEL).unwrap()
}

fn artifact_bytes() -> Vec<u8> {
    std::fs::read("artifacts/tiny.mochi").unwrap()
}

/// A random handle motion: ordinary, huge but finite, or with a NaN or infinity somewhere.
fn hostile(rng: &mut ChaCha8Rng) -> HandleMotion {
    let mut s = [0.0f32; 12];
    let huge = rng.random_bool(0.2);
    for v in &mut s {
        *v = if huge {
            [f32::MAX, -f32::MAX, 1e30, f32::MIN_POSITIVE][rng.random_range(0..4)]
        } else {
            rng.random_range(-3.0..3.0)
        };
    }
    if rng.random_bool(0.2) {
        s[rng.random_range(0..12)] = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][rng.random_range(0..3)];
    }
    HandleMotion::from_signal(&s)
}

fn assert_in_widened_range(z: &[f32]) {
    let m = tiny::MODEL;
    for ((&v, &lo), &hi) in z.iter().zip(m.latent_min()).zip(m.latent_max()) {
        let margin = RANGE_MARGIN * (hi - lo);
        assert!(
            v.is_finite() && v >= lo - margin && v <= hi + margin,
            "latent {v} outside [{lo}, {hi}] + margin"
        );
    }
}

#[test]
fn random_and_hostile_boundary_conditions_never_panic_or_leak_nans() {
    let model = model();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut body = tiny::Instance::new(&model).unwrap();
    let (mut full, mut surface) = ([0.0f32; tiny::STATE_LEN], [0.0f32; tiny::SURFACE_LEN]);
    let mut outcomes = [0usize; 4];
    for _ in 0..3000 {
        let bc = hostile(&mut rng);
        let before = body;
        match body.step(&model, &[bc]) {
            Err(StepError::NotFinite { handle: 0 }) => {
                assert!(!bc.is_finite());
                assert_eq!(body, before, "a refused step must leave the instance unchanged");
                outcomes[0] += 1;
            }
            Ok(status) => {
                assert!(bc.is_finite());
                outcomes[1 + status as usize] += 1;
            }
            Err(e) => panic!("unexpected {e}"),
        }
        assert_in_widened_range(body.latent());
        // Decoding may refuse a state it cannot represent, but never writes a NaN.
        let _ = body.decode_into(&model, &mut full);
        let _ = body.decode_surface_into(&model, &mut surface);
        assert!(full.iter().chain(&surface).all(|v| v.is_finite()));
    }
    assert!(
        outcomes[0] > 0 && outcomes[1] > 0 && outcomes[2] > 0,
        "refused / ok / clamped: {outcomes:?}"
    );
}

#[test]
fn a_latent_driven_out_of_range_is_clamped_and_recovers() {
    let model = model();
    let mut body = tiny::Instance::new(&model).unwrap();
    let violent = HandleMotion {
        linear_velocity: [0.0, 50.0, 0.0],
        ..HandleMotion::REST
    };
    let mut clamped = false;
    for _ in 0..20 {
        clamped |= body.step(&model, &[violent]).unwrap() == Stepped::Clamped;
        assert_in_widened_range(body.latent());
    }
    assert!(
        clamped,
        "a 50 m/s handle should push the latent out of the trained range"
    );
    // Back at rest, the instance keeps stepping with finite output.
    let mut x = [0.0f32; tiny::STATE_LEN];
    for _ in 0..200 {
        body.step(&model, &[HandleMotion::REST]).unwrap();
    }
    body.decode_into(&model, &mut x).unwrap();
    assert!(x.iter().all(|v| v.is_finite()));
}

#[test]
fn wrong_handle_counts_and_buffer_lengths_are_refused() {
    let model = model();
    let mut body = tiny::Instance::new(&model).unwrap();
    for n in [0, 2, 5] {
        let bc = vec![HandleMotion::REST; n];
        assert_eq!(
            body.step(&model, &bc),
            Err(StepError::HandleCount { expected: 1, found: n })
        );
    }
    for len in [0, tiny::STATE_LEN - 1, tiny::STATE_LEN + 3] {
        let mut out = vec![7.0f32; len];
        assert_eq!(
            body.decode_into(&model, &mut out),
            Err(DecodeError::BufferLength {
                expected: tiny::STATE_LEN,
                found: len
            })
        );
        assert!(out.iter().all(|&v| v == 7.0), "a refused decode writes nothing");
        let mut out = vec![0.0f32; len];
        assert!(body.decode_surface_into(&model, &mut out).is_err());
    }
    // An instance compiled for other sizes is refused up front.
    assert!(mochi_runtime::Instance::<3, { tiny::SIGNAL }, { tiny::HIDDEN }>::new(&model).is_err());
    assert!(mochi_runtime::Instance::<{ tiny::LATENT }, { tiny::SIGNAL }, 8>::new(&model).is_err());
}

/// Loads into fixed-capacity storage; must return, not panic.
fn load(bytes: &[u8]) -> Result<(), LoadError> {
    let mut storage = Box::new(LoadedModel::<20_000, 2_000, 2_000>::new());
    storage.load(bytes).map(|_| ())
}

#[test]
fn random_truncated_and_bit_flipped_artifacts_are_refused_without_panic() {
    let bytes = artifact_bytes();
    assert_eq!(load(&bytes), Ok(()));
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    for _ in 0..200 {
        let len = rng.random_range(0..2000);
        let noise: Vec<u8> = (0..len).map(|_| rng.random()).collect();
        assert!(load(&noise).is_err());
    }
    for cut in (0..bytes.len()).step_by(97).chain(0..64) {
        assert!(load(&bytes[..cut]).is_err(), "truncated at {cut}");
    }
    for _ in 0..200 {
        let mut damaged = bytes.clone();
        let i = rng.random_range(0..damaged.len());
        damaged[i] ^= 1 << rng.random_range(0..8);
        assert!(load(&damaged).is_err(), "bit flip at byte {i} was accepted");
    }
}

#[test]
fn corrupted_payloads_with_a_valid_checksum_are_refused_without_panic() {
    // Damage behind a correct envelope reaches the parser and the validation.
    let bytes = artifact_bytes();
    let (payload, _) = envelope::split(&bytes, MAGIC, FORMAT_VERSION).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(13);
    for round in 0..400 {
        let mut p = payload.to_vec();
        if round % 2 == 0 {
            for _ in 0..rng.random_range(1..8) {
                let i = rng.random_range(0..p.len());
                p[i] = rng.random();
            }
        } else {
            p.truncate(rng.random_range(0..p.len()));
        }
        let wrapped = envelope::wrap(MAGIC, FORMAT_VERSION, &p);
        let loaded = load(&wrapped);
        if p.len() < payload.len() {
            assert!(loaded.is_err(), "payload truncated to {} bytes was accepted", p.len());
        }
        // A changed weight is still a finite number and cannot be detected without the CRC;
        // whatever was accepted is a valid model that steps without panicking.
        let mut storage = OwnedModel::default();
        if let Ok(model) = storage.load(&wrapped) {
            let m = model.model();
            if m.latent as usize == tiny::LATENT && m.bc_len as usize == tiny::SIGNAL && m.hidden() <= tiny::HIDDEN {
                let mut body = tiny::Instance::new(&model).unwrap();
                let mut x = vec![0.0f32; m.state_len()];
                let _ = body.step(&model, &[HandleMotion::REST]);
                let _ = body.decode_into(&model, &mut x);
                assert!(x.iter().all(|v| v.is_finite()));
            }
        }
    }
}

#[test]
fn too_small_storage_names_the_field_that_did_not_fit() {
    let bytes = artifact_bytes();
    let mut small = Box::new(LoadedModel::<1_000, 2_000, 2_000>::new());
    assert_eq!(small.load(&bytes).err(), Some(LoadError::Capacity { field: "decoder" }));
    assert!(small.model().is_none(), "a failed load leaves no model behind");
    let mut few_indices = Box::new(LoadedModel::<20_000, 2_000, 10>::new());
    assert_eq!(
        few_indices.load(&bytes).err(),
        Some(LoadError::Capacity { field: "free_vertices" })
    );
}

#[test]
fn wrong_magic_and_version_are_named() {
    let mut bytes = artifact_bytes();
    assert_eq!(mochi_runtime::ARTIFACT_VERSION, 8);
    // Format 1 (before `encoding.chains`), 2 (one section), 3 (no triangles in the model
    // section), 4 (no `decoder_basis`) and a future format 9; the runtime reads 8, 7, 6 and 5.
    for version in [1, 2, 3, 4, 9] {
        bytes[8] = version;
        let expected = EnvelopeError::Version {
            found: version as u32,
            expected: 8,
        };
        assert_eq!(load(&bytes), Err(LoadError::Envelope(expected)));
        if (2..=7).contains(&version) {
            continue; // the trainer reads formats 2 to 7, and these bytes are none of them
        }
        let trainer = mochi_trainer::artifact::Artifact::from_bytes(&bytes, std::path::Path::new("old.mochi"))
            .unwrap_err()
            .to_string();
        assert!(trainer.contains(&format!("version {version}")), "{trainer}");
    }
    // Format-8 bytes labelled 7, 6 or 5 are read as those formats, which end one, two or four
    // fields earlier.
    for version in [7, 6, 5] {
        bytes[8] = version;
        assert_eq!(load(&bytes), Err(LoadError::TrailingBytes));
    }
    bytes[0] = b'X';
    assert_eq!(load(&bytes), Err(LoadError::Envelope(EnvelopeError::BadMagic)));
}

#[test]
fn inconsistent_model_descriptions_are_refused_naming_the_field() {
    let good = tiny::MODEL;
    assert!(ValidModel::new(good).is_ok());
    // A prescribed vertex listed twice (and so another vertex never written).
    let mut indices = good.indices.to_vec();
    let hv = good.handle_vertices;
    indices[hv.start as usize + 1] = indices[hv.start as usize];
    let bad = mochi_runtime::Model {
        indices: &indices,
        ..good
    };
    assert_eq!(ValidModel::new(bad).unwrap_err().field, "handle_vertices");
    // A span past the end of its pool.
    let bad = mochi_runtime::Model {
        rest: mochi_runtime::Span {
            start: good.floats.len() as u32,
            len: 3,
        },
        ..good
    };
    assert_eq!(
        ValidModel::new(bad).unwrap_err().problem,
        mochi_runtime::Problem::OutOfRange
    );
    // A weight that is not finite.
    let mut params = good.params.to_vec();
    params[17] = f32::NAN;
    let bad = mochi_runtime::Model {
        params: &params,
        ..good
    };
    assert_eq!(ValidModel::new(bad).unwrap_err().field, "params");
    // A layer pointing past the weights.
    let mut decoder = good.decoder.to_vec();
    decoder[0].weights = good.params.len() as u32;
    let bad = mochi_runtime::Model {
        decoder: &decoder,
        ..good
    };
    assert_eq!(ValidModel::new(bad).unwrap_err().field, "decoder");
}
