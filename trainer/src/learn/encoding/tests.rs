//! Tests of the encoding: round trips, rigid motion, strand bends and bad input.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

use super::frame::{best_fit_rotation, centroid, pad};
use super::*;
use crate::learn::recipe::{Recipe, RodEncoding};
use mochi_sim::dataset::SpeedPlan;
use mochi_sim::mesh::{Elements, Mesh};
use mochi_sim::scene::BuiltScene;
use mochi_sim::trajectory::Trajectory;

/// A built scene and a short simulated trajectory of it.
fn simulate(name: &str, frames: usize) -> (BuiltScene, Trajectory) {
    let mut problem = Recipe::load(name).unwrap().build().unwrap();
    let seq = problem.sequence(&SpeedPlan::constant(0.5), frames, 1);
    let traj = problem.run(&seq, &mochi_sim::Silent).unwrap();
    (problem, traj)
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

/// Applies `x -> rotation x + shift` to every vertex of a flat state.
fn moved(x: &[f64], dim: usize, rotation: &Matrix3<f64>, shift: Vector3<f64>) -> Vec<f64> {
    x.chunks_exact(dim)
        .flat_map(|p| {
            let y = rotation * pad(p) + shift;
            y.as_slice()[..dim].to_vec()
        })
        .collect()
}

/// Decoding inverts encoding: exactly for positions; for strand bends, which decode at
/// rest length, exactly from the encoded side (`encode(decode(q)) = q`).
fn round_trip_is_exact(enc: &Encoding, states: &[Vec<f64>]) {
    for x in states {
        let q = enc.encode_state(x).unwrap();
        assert_eq!(q.len(), enc.encoded_len());
        let back = enc.decode(&q, &enc.handle_targets(x).unwrap()).unwrap();
        if enc.strand_bends() {
            let again = enc.encode_state(&back).unwrap();
            assert!(
                max_abs_diff(&again, &q) < 1e-12,
                "bends round trip {}",
                max_abs_diff(&again, &q)
            );
            continue;
        }
        assert!(
            max_abs_diff(&back, x) < 1e-12,
            "round trip error {}",
            max_abs_diff(&back, x)
        );
    }
}

#[test]
fn encoding_round_trip_is_exact_on_simulated_beam_and_rods() {
    let (beam, traj) = simulate("beam", 10);
    let enc = Encoding::new(&beam, RodEncoding::Positions).unwrap();
    assert!(enc.rotates());
    assert_eq!(enc.origins(), &Origins::HandleCentroid);
    let clamp = beam.handles[0].vertices.len();
    assert_eq!(enc.encoded_len(), (beam.mesh.num_vertices() - clamp) * 3);
    round_trip_is_exact(&enc, &traj.positions);
    // At frame 0 the clamp is at its reference: R = I and q_v = x_v - (clamp centroid).
    let encoded = enc.encode_trajectory(&traj).unwrap();
    assert_eq!(encoded.len(), traj.num_frames());
    let c = centroid(&enc.handle_targets(&traj.positions[0]).unwrap(), 3);
    for (k, &v) in enc.free_vertices().iter().enumerate() {
        for i in 0..3 {
            assert!((encoded[0][k * 3 + i] - (traj.positions[0][v * 3 + i] - c[i])).abs() < 1e-15);
        }
    }

    let (rods, traj) = simulate("rods", 10);
    let enc = Encoding::from_parts(&rods.mesh, &rods.handles, false).unwrap();
    assert!(!enc.rotates());
    let Origins::StrandRoots { root_slots } = enc.origins() else {
        panic!("rods encode relative to their roots");
    };
    assert_eq!(root_slots.len(), 16);
    // Two prescribed vertices per strand, 28 encoded.
    assert_eq!(enc.encoded_len(), 16 * 28 * 3);
    round_trip_is_exact(&enc, &traj.positions);
    // The encoding is the offset from the strand root, exactly as the paper has it.
    let Elements::Rods(strands) = &rods.mesh.elements else {
        unreachable!()
    };
    let x = traj.positions.last().unwrap();
    let q = enc.encode_state(x).unwrap();
    let (root, tip) = (strands[3][0], *strands[3].last().unwrap());
    let k = enc.free_vertices().iter().position(|&v| v == tip).unwrap();
    for i in 0..3 {
        assert_eq!(q[k * 3 + i], x[tip * 3 + i] - x[root * 3 + i]);
    }
    // The root moved, so a root-relative code differs from the raw position.
    assert!((x[root * 3] - rods.mesh.rest[root * 3]).abs() > 1e-3);
}

#[test]
fn encoding_ignores_rigid_motion_of_state_and_handles_together() {
    let (beam, traj) = simulate("beam", 8);
    encoding_ignores_rigid_motion(&Encoding::new(&beam, RodEncoding::Positions).unwrap(), &traj.positions);
    // Rods with their roots' rotation removed as well.
    let (rods, traj) = simulate("rods", 4);
    let enc = Encoding::from_parts(&rods.mesh, &rods.handles, true).unwrap();
    encoding_ignores_rigid_motion(&enc, &traj.positions[traj.positions.len() - 1..]);
    round_trip_is_exact(&enc, &traj.positions);
}

/// Asserts that moving each 3D state rigidly (handles included) leaves its encoding unchanged.
fn encoding_ignores_rigid_motion(enc: &Encoding, states: &[Vec<f64>]) {
    let rotation = *Rotation3::from_scaled_axis(Vector3::new(0.3, -1.1, 0.7)).matrix();
    let shift = Vector3::new(0.4, -2.0, 1.5);
    for x in states {
        let q = enc.encode_state(x).unwrap();
        let q_moved = enc.encode_state(&moved(x, 3, &rotation, shift)).unwrap();
        assert!(max_abs_diff(&q, &q_moved) < 1e-12, "{}", max_abs_diff(&q, &q_moved));
    }
}

/// The rods scene's encoding by strand bends, with or without the roots' rotation removed.
fn rod_bends(rods: &BuiltScene, rotates: bool) -> Encoding {
    Encoding::from_parts(&rods.mesh, &rods.handles, rotates)
        .unwrap()
        .with_strand_bends(&rods.mesh)
        .unwrap()
}

/// Rest length of every rod edge, and the same edges' lengths in `x`.
fn edge_lengths(mesh: &Mesh, x: &[f64]) -> Vec<(f64, f64)> {
    let Elements::Rods(strands) = &mesh.elements else {
        unreachable!()
    };
    let length = |p: &[f64], a: usize, b: usize| (pad(&p[b * 3..b * 3 + 3]) - pad(&p[a * 3..a * 3 + 3])).norm();
    strands
        .iter()
        .flat_map(|s| s.windows(2))
        .map(|e| (length(&mesh.rest, e[0], e[1]), length(x, e[0], e[1])))
        .collect()
}

#[test]
fn strand_bends_decode_at_rest_length_and_track_simulated_rods() {
    let (rods, traj) = simulate("rods", 20);
    let bends = Recipe::load("rods").unwrap().latent.rods;
    assert_eq!(bends, RodEncoding::Bends);
    let enc = Encoding::new(&rods, bends).unwrap();
    assert!(enc.strand_bends());
    assert_eq!(enc.values_per_vertex(), 2);
    assert_eq!(enc.encoded_len(), 16 * 28 * 2);
    let length = 0.3;
    for x in &traj.positions {
        let targets = enc.handle_targets(x).unwrap();
        let back = enc.decode(&enc.encode_state(x).unwrap(), &targets).unwrap();
        for (rest, decoded) in edge_lengths(&rods.mesh, &back) {
            assert!((rest - decoded).abs() < 1e-12 * length, "{rest} {decoded}");
        }
        // The simulated rods stretch by a strain of about 1e-4, all the difference there is.
        let strain = edge_lengths(&rods.mesh, x)
            .iter()
            .map(|(r, l)| (l / r - 1.0).abs())
            .fold(0.0, f64::max);
        assert!(strain < 1e-2, "strain {strain}");
        assert!(
            max_abs_diff(&back, x) <= 2.0 * strain * length + 1e-12,
            "{} {strain}",
            max_abs_diff(&back, x)
        );
    }
    round_trip_is_exact(&enc, &traj.positions);
    // Any encoded vector is a valid state; its encoding is itself.
    let targets = enc.handle_targets(&traj.positions[7]).unwrap();
    let q: Vec<f64> = (0..enc.encoded_len())
        .map(|i| 0.004 * (i as f64 * 0.61).sin())
        .collect();
    let x = enc.decode(&q, &targets).unwrap();
    assert!(max_abs_diff(&enc.encode_state(&x).unwrap(), &q) < 1e-12);
    // A bend that folds an edge far back still round-trips.
    let mut folded = q.clone();
    folded[2 * 5] = 0.09;
    let x = enc.decode(&folded, &targets).unwrap();
    assert!(max_abs_diff(&enc.encode_state(&x).unwrap(), &folded) < 1e-10);
}

#[test]
fn strand_bends_ignore_rigid_motion_of_state_and_handles_together() {
    let (rods, traj) = simulate("rods", 6);
    encoding_ignores_rigid_motion(&rod_bends(&rods, true), &traj.positions);
}

#[test]
fn strand_bends_gradient_matches_finite_differences() {
    let (rods, traj) = simulate("rods", 6);
    for rotates in [false, true] {
        let enc = rod_bends(&rods, rotates);
        let x0 = traj.positions.last().unwrap();
        let targets = enc.handle_targets(x0).unwrap();
        let frame = enc.frame(&targets).unwrap();
        let q = enc.encode(x0, &frame).unwrap();
        // E(x) = sum c_i x_i + 0.5 |x - x0|^2 * 40: linear and curved parts.
        let c: Vec<f64> = (0..x0.len()).map(|i| (i as f64 * 1.7).cos()).collect();
        let energy = |q: &[f64]| -> f64 {
            let x = enc.decode(q, &targets).unwrap();
            x.iter()
                .zip(&c)
                .zip(x0)
                .map(|((x, c), r)| c * x + 20.0 * (x - r).powi(2))
                .sum()
        };
        let mut q = q;
        for (i, v) in q.iter_mut().enumerate() {
            *v += 0.01 * (i as f64 * 0.3).sin();
        }
        let x = enc.decode(&q, &targets).unwrap();
        let grad: Vec<f64> = x.iter().zip(&c).zip(x0).map(|((x, c), r)| c + 40.0 * (x - r)).collect();
        let mut analytic = vec![0.0; enc.encoded_len()];
        enc.encode_gradient(&q, &grad, &frame, 2.0, &mut analytic).unwrap();
        let h = 1e-6;
        for i in (0..q.len()).step_by(7) {
            let mut shifted = q.clone();
            shifted[i] += h;
            let plus = energy(&shifted);
            shifted[i] -= 2.0 * h;
            let minus = energy(&shifted);
            let numeric = (plus - minus) / (2.0 * h) / 2.0;
            assert!(
                (numeric - analytic[i]).abs() <= 1e-6 * (1.0 + numeric.abs()),
                "rotates {rotates}, coordinate {i}: {numeric} vs {}",
                analytic[i]
            );
        }
    }
}

#[test]
fn strand_bends_refuse_what_they_cannot_encode() {
    let beam = Recipe::load("beam").unwrap().build().unwrap();
    let enc = Encoding::from_parts(&beam.mesh, &beam.handles, false).unwrap();
    let err = enc.with_strand_bends(&beam.mesh).unwrap_err().to_string();
    assert!(err.contains("rods mesh"), "{err}");
    // Only the roots prescribed: the first free edge would have no parent edge.
    let rods = Recipe::load("rods").unwrap().build().unwrap();
    let Elements::Rods(strands) = &rods.mesh.elements else {
        unreachable!()
    };
    let mut handles = rods.handles.clone();
    let roots: Vec<usize> = strands.iter().map(|s| s[0]).collect();
    handles[0].reference = roots
        .iter()
        .map(|&v| [0, 1, 2].map(|c| rods.mesh.rest[v * 3 + c]))
        .collect();
    handles[0].vertices = roots;
    let enc = Encoding::from_parts(&rods.mesh, &handles, false).unwrap();
    let err = enc.with_strand_bends(&rods.mesh).unwrap_err().to_string();
    assert!(
        err.contains("strand 0 does not start with two prescribed vertices"),
        "{err}"
    );
}

/// States of a scene with its handles at the targets of a sampled sequence and the
/// other vertices displaced from rest by a smooth pattern (no simulation).
fn displaced_states(problem: &BuiltScene, frames: usize) -> Vec<Vec<f64>> {
    let dim = problem.mesh.dim;
    let seq = problem.sequence(&SpeedPlan::constant(1.0), frames, 2);
    (0..=frames)
        .map(|f| {
            let mut x: Vec<f64> = (problem.mesh.rest.iter().enumerate())
                .map(|(i, r)| r + 0.01 * (i as f64 * 0.37 + f as f64).sin())
                .collect();
            let targets = seq.targets(&problem.handles, f, dim);
            let fixed = problem.handles.iter().flat_map(|h| &h.vertices);
            for (slot, &v) in fixed.enumerate() {
                x[v * dim..(v + 1) * dim].copy_from_slice(&targets[slot * dim..(slot + 1) * dim]);
            }
            x
        })
        .collect()
}

#[test]
fn encoding_ignores_translation_in_every_scene() {
    for name in crate::learn::recipe::shipped_scene_names() {
        let problem = Recipe::load(&name).unwrap().build().unwrap();
        // Scenes without handles (the contact scenes) are encoded in world coordinates, the
        // frame their static ground is fixed in: there is no handle to be relative to.
        if problem.handles.is_empty() {
            let enc = Encoding::new(&problem, RodEncoding::Positions).unwrap();
            round_trip_is_exact(&enc, &simulate(&name, 2).1.positions);
            continue;
        }
        // 3D scenes use simulated states. 2D ones use displaced states: in debug builds
        // `energy::value` trips a debug assertion on 2D elements (it passes all
        // MAX_DOF gathered values to `eval`), and `BuiltScene::run` calls it.
        let states = if problem.mesh.dim == 3 {
            simulate(&name, 2).1.positions
        } else {
            displaced_states(&problem, 5)
        };
        let enc = Encoding::new(&problem, RodEncoding::Positions).unwrap();
        let dim = enc.dim();
        let shift = Vector3::new(0.7, -0.3, if dim == 3 { 1.9 } else { 0.0 });
        for x in &states {
            let q = enc.encode_state(x).unwrap();
            let q_moved = enc.encode_state(&moved(x, dim, &Matrix3::identity(), shift)).unwrap();
            assert!(
                max_abs_diff(&q, &q_moved) < 1e-12,
                "{name}: {}",
                max_abs_diff(&q, &q_moved)
            );
        }
        round_trip_is_exact(&enc, &states);
    }
}

#[test]
fn encoding_kabsch_recovers_a_known_rotation() {
    let points: Vec<f64> = (0..7)
        .flat_map(|i| {
            let t = i as f64;
            [t.sin(), (1.3 * t).cos() * 2.0, 0.5 * t - 1.0]
        })
        .collect();
    let rotation = *UnitQuaternion::from_scaled_axis(Vector3::new(-0.4, 2.2, 0.9))
        .to_rotation_matrix()
        .matrix();
    let current = moved(&points, 3, &rotation, Vector3::new(3.0, 1.0, -2.0));
    let fit = best_fit_rotation(&points, &current, 3).unwrap();
    assert!((fit - rotation).abs().max() < 1e-12, "{fit} vs {rotation}");
    assert!((fit.determinant() - 1.0).abs() < 1e-12);

    // Coplanar points (a clamped face) still fix a proper rotation.
    let planar: Vec<f64> = (0..9).flat_map(|i| [0.0, (i % 3) as f64, (i / 3) as f64]).collect();
    let current = moved(&planar, 3, &rotation, Vector3::zeros());
    let fit = best_fit_rotation(&planar, &current, 3).unwrap();
    assert!((fit - rotation).abs().max() < 1e-12);

    // 2D: a rotation by 2 rad about z.
    let flat: Vec<f64> = vec![0.0, 0.0, 1.0, 0.0, 0.3, 0.8];
    let r2 = *Rotation3::from_axis_angle(&Vector3::z_axis(), 2.0).matrix();
    let current = moved(&flat, 2, &r2, Vector3::new(1.0, -1.0, 0.0));
    let fit = best_fit_rotation(&flat, &current, 2).unwrap();
    assert!((fit - r2).abs().max() < 1e-12, "{fit}");
}

fn is_length<T>(result: Result<T, EncodingError>) -> bool {
    matches!(result, Err(EncodingError::Length { .. }))
}

#[test]
fn encoding_bad_input_is_an_error() {
    let problem = Recipe::load("beam").unwrap().build().unwrap();
    let enc = Encoding::new(&problem, RodEncoding::Positions).unwrap();
    let x = problem.mesh.rest.clone();
    let targets = enc.handle_targets(&x).unwrap();
    let frame = enc.frame(&targets).unwrap();
    assert!(is_length(enc.encode(&x[1..], &frame)));
    assert!(is_length(enc.encode_state(&x[..6])));
    assert!(is_length(enc.frame(&targets[1..])));
    let q = enc.encode(&x, &frame).unwrap();
    let mut out = vec![0.0; x.len()];
    assert!(is_length(enc.decode_into(&q[1..], &frame, &targets, &mut out)));
    assert!(is_length(enc.decode_into(&q, &frame, &targets[3..], &mut out)));
    assert!(is_length(enc.decode_into(&q, &frame, &targets, &mut out[1..])));
    let mut no_origin = frame.clone();
    no_origin.origins.clear();
    assert!(is_length(enc.decode_into(&q, &no_origin, &targets, &mut out)));
    assert!(is_length(best_fit_rotation(&[0.0; 6], &[0.0; 3], 3)));
    assert!(is_length(best_fit_rotation(&[0.0; 4], &[0.0; 4], 3)));
    let mut traj = Trajectory {
        scene: "beam".into(),
        dt: 0.1,
        dim: 2,
        positions: vec![x.clone()],
        bc_signal: vec![vec![]],
        energy_names: vec![],
        energies: vec![vec![]],
        newton_iterations: vec![0],
        step_seconds: vec![0.0],
        meta: vec![],
        obstacles: None,
        colliders: None,
    };
    assert!(is_length(enc.encode_trajectory(&traj)));
    traj.dim = 3;
    traj.positions.push(x[3..].to_vec());
    assert!(is_length(enc.encode_trajectory(&traj)));

    // The cloth's two corners cannot fix a rotation.
    let cloth = Recipe::load("cloth").unwrap().build().unwrap();
    assert!(!Encoding::new(&cloth, RodEncoding::Positions).unwrap().rotates());
    assert_eq!(
        Encoding::from_parts(&cloth.mesh, &cloth.handles, true),
        Err(EncodingError::DegenerateHandles { count: 2, span: 1 })
    );
    // Handles that do not fit the mesh.
    let mut handles = problem.handles.clone();
    handles[0].vertices[0] = problem.mesh.num_vertices();
    assert!(matches!(
        Encoding::from_parts(&problem.mesh, &handles, true),
        Err(EncodingError::BadHandle { .. })
    ));
    let mut handles = problem.handles.clone();
    handles.push(handles[0].clone());
    assert!(matches!(
        Encoding::from_parts(&problem.mesh, &handles, false),
        Err(EncodingError::BadHandle { .. })
    ));
    let mut handles = problem.handles.clone();
    handles[0].reference.pop();
    assert!(matches!(
        Encoding::from_parts(&problem.mesh, &handles, false),
        Err(EncodingError::BadHandle { .. })
    ));
}

#[test]
fn encoding_without_handles_is_the_identity() {
    let problem = Recipe::load("beam").unwrap().build().unwrap();
    let enc = Encoding::from_parts(&problem.mesh, &[], false).unwrap();
    assert_eq!(enc.encoded_len(), problem.mesh.rest.len());
    let q = enc.encode_state(&problem.mesh.rest).unwrap();
    assert_eq!(q, problem.mesh.rest);
    assert_eq!(enc.decode(&q, &[]).unwrap(), problem.mesh.rest);
}
