//! What the integrator reads besides latents and signals. The frame time: a timed model
//! (`dt_range` in the artifact) reads it after everything else and steps by any positive one, a
//! model of one frame time refuses others, bad frame times change nothing, and an artifact of
//! the previous format (5, without `dt_range` and collider slots) loads and steps exactly as the
//! same model written in this one, one of format 6 (without the render mesh) as the same
//! model without one, and one of format 7 (without `rate_input`) as a timed model reading
//! `z_{t-2}`. A rate-input model reads the last latent's change per frame of its `dt` in place
//! of `z_{t-2}`. Run-time colliders: a model with collider slots reads each
//! slot's features in the body's encoding frame (absent and far colliders alike), and refuses
//! too many or non-finite colliders and malformed slots.

use mochi_runtime::artifact::{FORMAT_VERSION, MAGIC, OLDEST_READ_VERSION};
use mochi_runtime::collider::{ColliderState, FAR_DIAGONALS, FEATURES_PER_COLLIDER};
use mochi_runtime::envelope::{self, EnvelopeError};
use mochi_runtime::network::activation::swish;
use mochi_runtime::payload::{HandleData, LayerData, Payload, RenderData};
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
/// `HIDDEN * swish(dt) * dt / DT` to the latent; untimed, the same weights sit on the last
/// signal.
fn payload(timed: bool) -> Payload {
    payload_with(timed, &[], None)
}

/// [`payload`] with collider slots (shape rows of four numbers each); with `read`, the input
/// layer reads that input instead of the last one.
fn payload_with(timed: bool, slots: &[f32], read: Option<u64>) -> Payload {
    let layer = |rows: u64, cols: u64, weights: Vec<f32>| LayerData {
        rows,
        cols,
        weights,
        bias: vec![0.0; rows as usize],
    };
    let input = 2 + 3 * 12 + (FEATURES_PER_COLLIDER * slots.len() / 4) as u64 + u64::from(timed);
    let column = read.unwrap_or(input - 1);
    let first: Vec<f32> = (0..HIDDEN * input)
        .map(|i| if i % input == column { 1.0 } else { 0.0 })
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
        collider_shapes: slots.to_vec(),
        render: RenderData::default(),
        rate_input: false,
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
        // Two steps of the network's increment, each scaled by dt over the model's frame time.
        let want = 2.0 * HIDDEN as f32 * swish(dt) * (dt / m.dt);
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

/// Steps and decodes two loaded models side by side: the same latents and positions.
fn same_rollouts(a: &OwnedModel, b: &OwnedModel) {
    let (a, b) = (a.model().unwrap(), b.model().unwrap());
    let (mut x, mut y) = (AnyInstance::new(&a).unwrap(), AnyInstance::new(&b).unwrap());
    let (mut xs, mut ys) = ([0.0f32; 6], [0.0f32; 6]);
    for f in 0..20 {
        let bc = motion(0.05 * f as f32);
        assert_eq!(x.step(&a, &bc), y.step(&b, &bc));
        x.decode_into(&a, &mut xs).unwrap();
        y.decode_into(&b, &mut ys).unwrap();
        assert_eq!(xs, ys, "frame {f}");
    }
}

#[test]
fn a_format_5_artifact_loads_and_steps_as_the_same_model_in_this_format() {
    let p = payload(false);
    let current = p.to_section().unwrap();
    // Format 5's payload is this one without its last fields (`dt_range`, two f64, the empty
    // `collider_shapes`, one byte, the empty render mesh, four bytes, and `rate_input`, one).
    let encoded = p.encode().unwrap();
    let old = envelope::wrap(MAGIC, OLDEST_READ_VERSION, &encoded[..encoded.len() - 22]);
    assert_eq!(OLDEST_READ_VERSION, 5);
    assert_eq!(FORMAT_VERSION, 8);
    let (a, b) = (load(&current), load(&old));
    assert!(!b.model().unwrap().model().timed());
    same_rollouts(&a, &b);
    // A format-8 payload cut short is refused, not read as format 5.
    let cut = envelope::wrap(MAGIC, FORMAT_VERSION, &encoded[..encoded.len() - 22]);
    assert!(OwnedModel::default().load(&cut).is_err());
    // Older and newer formats are refused naming the version.
    for version in [4, 9] {
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
fn a_format_6_artifact_loads_and_steps_as_the_same_model_without_a_render_mesh() {
    let p = payload(true);
    let current = p.to_section().unwrap();
    // Format 6's payload is this one without the render mesh (four empty lists, four bytes)
    // and `rate_input` (one byte).
    let encoded = p.encode().unwrap();
    let old = envelope::wrap(MAGIC, 6, &encoded[..encoded.len() - 5]);
    let (a, b) = (load(&current), load(&old));
    let m = b.model().unwrap();
    assert!(m.model().timed());
    assert!(!m.model().has_render());
    same_rollouts(&a, &b);
    // A format-7 payload labelled 6 is refused for its trailing render mesh.
    let labelled = envelope::wrap(MAGIC, 6, &encoded[..encoded.len() - 1]);
    assert_eq!(
        OwnedModel::default().load(&labelled).err(),
        Some(LoadError::TrailingBytes)
    );
}

/// The timed test model whose input layer also reads the latent slot after the last latent
/// (`z_{t-2}`, or the rate with `rate_input`) with weight `w`: one step adds
/// `HIDDEN * swish(dt + w * slot) * dt / DT`.
fn reading_the_second_slot(w: f32, rate_input: bool) -> Payload {
    let mut p = payload(true);
    let cols = p.integrator[0].cols as usize;
    for row in p.integrator[0].weights.chunks_mut(cols) {
        row[1] = w;
    }
    p.rate_input = rate_input;
    p
}

#[test]
fn a_format_7_timed_artifact_reads_the_latent_before_the_last() {
    let p = reading_the_second_slot(0.5, false);
    let encoded = p.encode().unwrap();
    // Format 7's payload is this one without `rate_input` (one byte, `false`).
    let old = envelope::wrap(MAGIC, 7, &encoded[..encoded.len() - 1]);
    let (a, b) = (load(&p.to_section().unwrap()), load(&old));
    assert!(!b.model().unwrap().model().rate_input);
    same_rollouts(&a, &b);
    // A format-8 payload labelled 7 is refused for its trailing flag.
    let labelled = envelope::wrap(MAGIC, 7, &encoded);
    assert_eq!(
        OwnedModel::default().load(&labelled).err(),
        Some(LoadError::TrailingBytes)
    );
}

#[test]
fn a_rate_input_model_reads_the_last_latents_change_per_frame_of_its_dt() {
    let w = 0.5f32;
    let step = |z: f32, slot: f32, dt: f32| z + HIDDEN as f32 * swish(dt + w * slot) * dt / DT as f32;
    for rate_input in [true, false] {
        let storage = load(&reading_the_second_slot(w, rate_input).to_section().unwrap());
        let model = storage.model().unwrap();
        assert_eq!(model.model().rate_input, rate_input);
        for dt in [1.0 / 120.0f32, 1.0 / 60.0, 1.0 / 30.0, 1.0 / 24.0] {
            let mut body = AnyInstance::new(&model).unwrap();
            let (mut z, mut z_prev) = (0.0f32, 0.0f32);
            for frame in 0..4 {
                assert_eq!(body.step_dt(&model, &motion(0.0), dt), Ok(Stepped::Ok));
                let slot = match rate_input {
                    true => (z - z_prev) * (DT as f32 / dt),
                    false => z_prev,
                };
                (z, z_prev) = (step(z, slot, dt), z);
                let got = body.latent()[0];
                assert!(
                    (got - z).abs() <= 1e-5 * z.abs().max(1e-3),
                    "rate input {rate_input}, dt {dt}, frame {frame}: {got} against {z}"
                );
            }
        }
    }
    // Only a timed model has a rate to read.
    let mut p = payload(false);
    p.rate_input = true;
    assert_eq!(
        OwnedModel::default().load(&p.to_section().unwrap()).err(),
        Some(LoadError::Invalid(ModelError {
            field: "rate_input",
            problem: Problem::Domain
        }))
    );
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

/// The first collider feature (its centre's x in the encoding frame) read by the test model
/// of one slot (a capsule), after one step with the collider at `state` (none: absent) and the
/// handle turned by `turn` about z.
fn latent_with_collider(state: Option<ColliderState>, turn: f32) -> f32 {
    let storage = load(
        &payload_with(false, &[1.0, 0.05, 0.1, 0.0], Some(2 + 36))
            .to_section()
            .unwrap(),
    );
    let model = storage.model().unwrap();
    assert_eq!(
        (model.model().colliders(), model.model().integrator_input()),
        (1, 2 + 36 + mochi_runtime::collider::FEATURES_PER_COLLIDER)
    );
    let mut body = AnyInstance::new(&model).unwrap();
    let motion = [HandleMotion {
        rotation: [0.0, 0.0, turn],
        ..HandleMotion::default()
    }];
    let given: Vec<ColliderState> = state.into_iter().collect();
    body.step_with(&model, &motion, &given, DT as f32).unwrap();
    body.latent()[0]
}

#[test]
fn collider_slots_are_read_in_the_encoding_frame_and_far_ones_as_absent() {
    // The handle's targets are vertices 0 and 1, at rest: their centroid (0.5, 0) is the origin.
    let at = |x: f32, y: f32| ColliderState {
        center: [x, y, 0.0],
        ..ColliderState::default()
    };
    let step = |feature: f32| HIDDEN as f32 * swish(feature);
    let z = latent_with_collider(Some(at(0.8, 0.1)), 0.0);
    assert!((z - step(0.3)).abs() < 1e-6, "{z} vs {}", step(0.3));
    // Absent, or farther than FAR_DIAGONALS rest diagonals: the centre reads as straight up
    // (x = 0) in the frame, the same numbers.
    let diagonal = 2f32.sqrt();
    let far = latent_with_collider(Some(at(0.5 + 1.01 * FAR_DIAGONALS * diagonal, 0.0)), 0.0);
    assert_eq!(far, latent_with_collider(None, 0.0));
    assert_eq!(far, step(0.0));
    // A model that does not rotate with its handle reads world axes whatever the turn.
    assert_eq!(latent_with_collider(Some(at(0.8, 0.1)), 1.0), z);
}

#[test]
fn bad_colliders_are_refused_and_change_nothing() {
    let storage = load(
        &payload_with(false, &[0.0, 0.1, 0.0, 0.0], Some(2 + 36))
            .to_section()
            .unwrap(),
    );
    let model = storage.model().unwrap();
    let mut body = AnyInstance::new(&model).unwrap();
    let start = body;
    let fine = ColliderState::default();
    let nan = ColliderState {
        linear_velocity: [0.0, f32::NAN, 0.0],
        ..fine
    };
    assert_eq!(
        body.step_with(&model, &motion(0.0), &[fine, fine], DT as f32),
        Err(StepError::ColliderCount { slots: 1, found: 2 })
    );
    assert_eq!(
        body.step_with(&model, &motion(0.0), &[nan], DT as f32),
        Err(StepError::ColliderNotFinite { collider: 0 })
    );
    assert_eq!(body, start);
    // A model without slots takes none.
    let plain = load(&payload(false).to_section().unwrap());
    let plain = plain.model().unwrap();
    let mut other = AnyInstance::new(&plain).unwrap();
    assert_eq!(
        other.step_with(&plain, &motion(0.0), &[fine], DT as f32),
        Err(StepError::ColliderCount { slots: 0, found: 1 })
    );
}

#[test]
fn malformed_collider_slots_are_refused_naming_the_field() {
    let too_many: Vec<f32> = (0..9).flat_map(|_| [0.0, 0.1, 0.0, 0.0]).collect();
    for (rows, problem) in [
        (vec![0.0, 0.1, 0.0], Problem::Unsupported),
        (too_many, Problem::Unsupported),
        (vec![5.0, 0.1, 0.0, 0.0], Problem::Domain),
        (vec![0.0, -0.1, 0.0, 0.0], Problem::Domain),
        (vec![2.0, 0.1, 0.1, 0.0], Problem::Domain),
        (vec![1.0, 0.1, f32::NAN, 0.0], Problem::NotFinite),
    ] {
        let p = payload_with(false, &rows, None);
        let err = OwnedModel::default().load(&p.to_section().unwrap()).err();
        assert_eq!(
            err,
            Some(LoadError::Invalid(ModelError {
                field: "collider_shapes",
                problem
            })),
            "{rows:?}"
        );
    }
}
