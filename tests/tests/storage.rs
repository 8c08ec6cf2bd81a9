//! Weight storage and instance room: the generated `f16` and int8 models are exactly the
//! runtime's re-storage of the artifact, stay close to the `f32` model over the reference
//! script, and malformed stored weights are refused; an instance with room to spare gives the
//! same bits as one sized exactly.

use mochi_codegen::{Options, Quantized};
use mochi_runtime::{AnyInstance, Instance, Model, OwnedModel, StepError, ValidModel, WeightFormat};
use mochi_target_common::{diagonal, run, Script, FRAMES};
use mochi_tests::{beam, tiny, tiny_f16, tiny_int8};

/// Positions of every frame of the reference script.
fn rollout(model: Model<'static>) -> Vec<Vec<f32>> {
    let model = ValidModel::new(model).unwrap();
    let mut x = vec![0.0f32; model.model().state_len()];
    let mut frames = Vec::new();
    run::<{ tiny::LATENT }, { tiny::SIGNAL }, { tiny::HIDDEN }>(&model, FRAMES, &mut x, |_, _, p| {
        frames.push(p.to_vec())
    })
    .unwrap();
    frames
}

#[test]
fn generated_storages_are_the_runtimes_restorage_of_the_artifact() {
    let bytes = std::fs::read("artifacts/tiny.mochi").unwrap();
    let mut storage = OwnedModel::default();
    let base = *storage.load(&bytes).unwrap().model();
    for (format, generated) in [
        (WeightFormat::F16, tiny_f16::MODEL),
        (WeightFormat::Int8, tiny_int8::MODEL),
    ] {
        let options = Options::weights(format);
        let q = Quantized::split(&base, options.decoder, options.integrator);
        let m = q.model(&base);
        assert_eq!(m.params, generated.params, "{format:?}");
        assert_eq!(m.halves, generated.halves, "{format:?}");
        assert_eq!(m.bytes, generated.bytes, "{format:?}");
        assert_eq!(m.decoder, generated.decoder, "{format:?}");
        assert_eq!(m.integrator, generated.integrator, "{format:?}");
        assert!(generated.decoder.iter().all(|l| l.format == format));
    }
    // int8 keeps the integrator in f16 (see `Options::weights`).
    assert!(tiny_int8::MODEL
        .integrator
        .iter()
        .all(|l| l.format == WeightFormat::F16));
    assert_eq!(tiny_int8::DECODER_WEIGHTS, WeightFormat::Int8);
}

#[test]
fn stored_weights_stay_close_to_f32_and_shrink_the_model() {
    let reference = rollout(tiny::MODEL);
    let m = tiny::MODEL;
    let diag = diagonal(m.rest(), m.dim());
    let worst = |frames: &[Vec<f32>]| {
        frames
            .iter()
            .zip(&reference)
            .flat_map(|(a, b)| {
                a.chunks(3)
                    .zip(b.chunks(3))
                    .map(|(p, q)| p.iter().zip(q).map(|(x, y)| (x - y) * (x - y)).sum::<f32>().sqrt() / diag)
            })
            .fold(0.0f32, f32::max)
    };
    let f16 = worst(&rollout(tiny_f16::MODEL));
    let int8 = worst(&rollout(tiny_int8::MODEL));
    println!("largest distance from f32 over {FRAMES} frames: f16 {f16:.2e}, int8 {int8:.2e} of the diagonal");
    assert!(f16 > 0.0 && f16 < 2e-3, "f16: {f16:.2e}");
    assert!(int8 > f16 && int8 < 2e-2, "int8: {int8:.2e}");
    let sizes = [tiny_int8::MODEL, tiny_f16::MODEL, tiny::MODEL].map(|m| m.weight_bytes());
    assert!(sizes[0] < sizes[1] && sizes[1] < sizes[2], "{sizes:?}");
}

#[test]
fn an_instance_with_room_to_spare_gives_the_same_bits() {
    let model = ValidModel::new(tiny::MODEL).unwrap();
    let script = Script::for_model(&model);
    let mut exact = tiny::Instance::new(&model).unwrap();
    let mut roomy = AnyInstance::new(&model).unwrap();
    let (mut a, mut b) = (vec![0.0f32; tiny::STATE_LEN], vec![0.0f32; tiny::STATE_LEN]);
    for frame in 1..=300 {
        let bc = [script.motion(frame)];
        assert_eq!(exact.step(&model, &bc), roomy.step(&model, &bc));
        exact.decode_into(&model, &mut a).unwrap();
        roomy.decode_into(&model, &mut b).unwrap();
        assert_eq!(a, b, "frame {frame}");
        assert_eq!(exact.latent(), roomy.latent());
    }
    assert_eq!(roomy.latent().len(), tiny::LATENT);
    // An instance created for one model refuses another of other sizes.
    let other = ValidModel::new(beam::MODEL).unwrap();
    assert!(matches!(
        roomy.step(&other, &[script.motion(1)]),
        Err(StepError::Model(e)) if e.size == "latent"
    ));
    // A beam instance does not fit in tiny's exact instance type.
    assert!(Instance::<{ tiny::LATENT }, { tiny::SIGNAL }, { tiny::HIDDEN }>::new(&other).is_err());
}

#[test]
fn malformed_stored_weights_are_refused_naming_the_field() {
    let good = tiny_f16::MODEL;
    let mut halves = good.halves.to_vec();
    halves[5] = 0x7c00; // +infinity
    let bad = Model {
        halves: &halves,
        ..good
    };
    assert_eq!(ValidModel::new(bad).unwrap_err().field, "halves");
    let short = Model {
        halves: &good.halves[..good.halves.len() - 1],
        ..good
    };
    assert_eq!(ValidModel::new(short).unwrap_err().field, "integrator");

    let good = tiny_int8::MODEL;
    let mut decoder = good.decoder.to_vec();
    decoder[0].scales = good.params.len() as u32;
    let bad = Model {
        decoder: &decoder,
        ..good
    };
    assert_eq!(ValidModel::new(bad).unwrap_err().field, "decoder");
    let short = Model {
        bytes: &good.bytes[..good.bytes.len() - 1],
        ..good
    };
    assert_eq!(ValidModel::new(short).unwrap_err().field, "decoder");
}
