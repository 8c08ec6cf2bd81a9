//! The frame time as an input of the integrator: a timed model (`dt_range` in the artifact)
//! reads the frame time after the signals and steps by any positive one, a model of one frame
//! time refuses others, bad frame times change nothing, and an artifact of the previous format
//! (5, without `dt_range`) loads and steps exactly as the same model written in this one.

use mochi_runtime::artifact::{FORMAT_VERSION, MAGIC, OLDEST_READ_VERSION};
use mochi_runtime::envelope::{self, EnvelopeError};
use mochi_runtime::network::activation::swish;
use mochi_runtime::payload::{HandleData, LayerData, Payload};
use mochi_runtime::{
    AnyInstance, HandleMotion, LoadError, ModelError, OwnedModel, Problem, StepError, Stepped, ValidModel,
};

/// Hidden width of the test integrator.
const HIDDEN: u64 = 4;
/// The test model's own frame time (s).
const DT: f64 = 1.0 / 30.0;

/// A 2D triangle (vertices 0 and 1 held by one handle, vertex 2 free) with a one-number latent.
/// The integrator's input layer reads only the frame time (when `timed`, its last input) with
/// weight 1 into every hidden unit and its output layer sums them, so one step adds
/// `HIDDEN * swish(dt)` to the latent; untimed, the same weights sit on the last signal.
fn payload(timed: bool) -> Payload {
    let layer = |rows: u64, cols: u64, weights: Vec<f32>| LayerData {
        rows,
        cols,
        weights,
        bias: vec![0.0; rows as usize],
    };
    let input = 2 + 3 * 12 + u64::from(timed);
    let first: Vec<f32> = (0..HIDDEN * input)
        .map(|i| if i % input == input - 1 { 1.0 } else { 0.0 })
        .collect();
    Payload {
        dt: DT,
        dim: 2,
        num_vertices: 3,
        rest: vec![0.0, 0.0, 1.0, 0.0, 0.0, 1.0],
        diagonal: 2f64.sqrt(),
        rotates: false,
        handle_vertices: vec![0, 1],
        free_vertices: vec![2],
        origin_of: vec![0],
        root_slots: vec![],
        chains: vec![],
        handles: vec![HandleData {
            vertices: vec![0, 1],
            reference: vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
            pivot: [0.5, 0.0, 0.0],
        }],
        bc_len: 12,
        surface_vertices: vec![0, 1, 2],
        latent: 1,
        initial_latent: vec![0.0],
        latent_min: vec![-10.0],
        latent_max: vec![10.0],
        decoder: vec![layer(4, 1, vec![0.5; 4]), layer(2, 4, vec![0.25; 8])],
        integrator: vec![
            layer(HIDDEN, input, first),
            layer(1, HIDDEN, vec![1.0; HIDDEN as usize]),
        ],
        surface_triangles: vec![0, 1, 2],
        decoder_basis: false,
        dt_range: if timed { [1.0 / 120.0, 1.0 / 30.0] } else { [0.0; 2] },
    }
}

/// A motion of the one handle: still, except for `velocity` along x (the last signal number
/// the untimed test integrator reads is the rotation's z, zero here).
fn motion(velocity: f32) -> [HandleMotion; 1] {
    [HandleMotion {
        linear_velocity: [velocity, 0.0, 0.0],
        ..HandleMotion::default()
    }]
}

fn load(bytes: &[u8]) -> OwnedModel {
    let mut storage = OwnedModel::default();
    storage.load(bytes).unwrap();
    storage
}

fn latent_after(model: &ValidModel, steps: &[f32]) -> f32 {
    let mut body = AnyInstance::new(model).unwrap();
    for &dt in steps {
        assert_eq!(body.step_dt(model, &motion(0.0), dt), Ok(Stepped::Ok));
    }
    body.latent()[0]
}

#[test]
fn a_timed_model_reads_the_frame_time_after_the_signals() {
    let storage = load(&payload(true).to_section().unwrap());
    let model = storage.model().unwrap();
    let m = model.model();
    assert!(m.timed());
    assert_eq!((m.dt_min, m.dt_max), ((1.0f64 / 120.0) as f32, (1.0f64 / 30.0) as f32));
    assert_eq!(m.integrator_input(), 2 + 36 + 1);
    for dt in [1.0 / 120.0, 1.0 / 72.0, 1.0 / 30.0, 1.0 / 20.0] {
        let z = latent_after(&model, &[dt, dt]);
        let want = 2.0 * HIDDEN as f32 * swish(dt);
        assert!((z - want).abs() <= 1e-6 * want, "dt {dt}: latent {z}, expected {want}");
    }
    // `step` is a step of the model's own `dt`, bit for bit.
    let mut body = AnyInstance::new(&model).unwrap();
    body.step(&model, &motion(0.0)).unwrap();
    assert_eq!(body.latent()[0], latent_after(&model, &[m.dt]));
}

#[test]
fn a_model_of_one_frame_time_refuses_another_and_bad_frame_times_change_nothing() {
    let storage = load(&payload(false).to_section().unwrap());
    let model = storage.model().unwrap();
    let m = model.model();
    assert!(!m.timed());
    let mut body = AnyInstance::new(&model).unwrap();
    body.step(&model, &motion(0.1)).unwrap();
    let before = body;
    assert_eq!(
        body.step_dt(&model, &motion(0.1), 1.0 / 90.0),
        Err(StepError::FixedFrameTime)
    );
    // Its own frame time as a host rounds it is accepted.
    let mut other = body;
    assert!(other.step_dt(&model, &motion(0.1), m.dt * (1.0 + 1e-6)).is_ok());
    let timed = load(&payload(true).to_section().unwrap());
    let timed = timed.model().unwrap();
    let mut timed_body = AnyInstance::new(&timed).unwrap();
    for bad in [0.0, -DT as f32, f32::NAN, f32::INFINITY] {
        assert_eq!(body.step_dt(&model, &motion(0.1), bad), Err(StepError::FrameTime));
        assert_eq!(timed_body.step_dt(&timed, &motion(0.1), bad), Err(StepError::FrameTime));
    }
    assert_eq!(body, before);
    assert_eq!(timed_body, AnyInstance::new(&timed).unwrap());
}

#[test]
fn a_format_5_artifact_loads_and_steps_as_the_same_model_in_this_format() {
    let p = payload(false);
    let current = p.to_section().unwrap();
    // Format 5's payload is this one without its last field (`dt_range`, two f64).
    let encoded = p.encode().unwrap();
    let old = envelope::wrap(MAGIC, OLDEST_READ_VERSION, &encoded[..encoded.len() - 16]);
    assert_eq!(OLDEST_READ_VERSION, 5);
    assert_eq!(FORMAT_VERSION, 6);
    let (a, b) = (load(&current), load(&old));
    let (a, b) = (a.model().unwrap(), b.model().unwrap());
    assert!(!b.model().timed());
    let (mut x, mut y) = (AnyInstance::new(&a).unwrap(), AnyInstance::new(&b).unwrap());
    let (mut xs, mut ys) = ([0.0f32; 6], [0.0f32; 6]);
    for f in 0..20 {
        let bc = motion(0.05 * f as f32);
        assert_eq!(x.step(&a, &bc), y.step(&b, &bc));
        x.decode_into(&a, &mut xs).unwrap();
        y.decode_into(&b, &mut ys).unwrap();
        assert_eq!(xs, ys, "frame {f}");
    }
    // A format-6 payload cut short is refused, not read as format 5.
    let cut = envelope::wrap(MAGIC, FORMAT_VERSION, &encoded[..encoded.len() - 16]);
    assert!(OwnedModel::default().load(&cut).is_err());
    // Older and newer formats are refused naming the version.
    for version in [4, 7] {
        let bytes = envelope::wrap(MAGIC, version, &encoded);
        assert_eq!(
            OwnedModel::default().load(&bytes).err(),
            Some(LoadError::Envelope(EnvelopeError::Version {
                found: version,
                expected: FORMAT_VERSION
            }))
        );
    }
}

#[test]
fn frame_time_ranges_are_validated_naming_the_field() {
    let cases = [
        ([1.0 / 30.0, 1.0 / 120.0], "dt_max", Problem::Domain),
        ([-0.01, 1.0 / 30.0], "dt_min", Problem::Domain),
        ([0.0, 1.0 / 30.0], "dt_min", Problem::Domain),
        ([f64::NAN, 1.0 / 30.0], "dt_min", Problem::NotFinite),
        ([0.01, f64::INFINITY], "dt_max", Problem::NotFinite),
    ];
    for (range, field, problem) in cases {
        let mut p = payload(true);
        p.dt_range = range;
        let err = OwnedModel::default().load(&p.to_section().unwrap()).err();
        assert_eq!(
            err,
            Some(LoadError::Invalid(ModelError { field, problem })),
            "{range:?}"
        );
    }
    // A timed range on an integrator without the time input does not chain.
    let mut p = payload(false);
    p.dt_range = [0.01, 0.02];
    let err = OwnedModel::default().load(&p.to_section().unwrap()).err();
    assert!(
        matches!(
            err,
            Some(LoadError::Invalid(ModelError {
                field: "integrator",
                ..
            }))
        ),
        "{err:?}"
    );
}
