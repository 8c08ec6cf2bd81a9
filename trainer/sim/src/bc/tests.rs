//! Tests of [`crate::bc`].

use super::*;

#[test]
fn constant_rotation_track_matches_closed_form() {
    let seg = Segment {
        frames: 30,
        velocity: [0.3, 0.0, 0.0],
        angular_velocity: [0.0, 0.0, 1.2],
    };
    let dt = 1.0 / 30.0;
    let track = Track::from_segments(&[seg], 40, dt);
    let p = track.poses[30];
    assert!((p.translation.x - 0.3).abs() < 1e-12);
    assert!((p.rotation.angle() - 1.2).abs() < 1e-12);
    // After the script ends the handle holds still.
    assert_eq!(track.poses[40], track.poses[30]);
    assert_eq!(track.velocities[35], [0.0; 6]);
    let h = Handle {
        name: "h".into(),
        vertices: vec![0],
        reference: vec![[1.0, 0.0, 0.0]],
        pivot: [0.0; 3],
    };
    let frames = track.poses.len() - 1;
    let seq = BcSequence {
        tracks: vec![track],
        frames,
        colliders: Vec::new(),
    };
    let t = seq.targets(&[h], 30, 3);
    assert!((t[0] - (0.3 + 1.2f64.cos())).abs() < 1e-12 && (t[1] - 1.2f64.sin()).abs() < 1e-12);
    assert_eq!(seq.signal(10).len(), SIGNAL_PER_HANDLE);
}

#[test]
fn every_keeps_the_poses_of_every_stride_th_frame_and_averages_velocities() {
    let segments = [
        Segment {
            frames: 3,
            velocity: [0.3, 0.0, 0.0],
            angular_velocity: [0.0, 0.0, 1.2],
        },
        Segment {
            frames: 4,
            velocity: [0.0, -0.6, 0.0],
            angular_velocity: [0.0; 3],
        },
    ];
    let track = Track::from_segments(&segments, 10, 0.1);
    let seq = BcSequence {
        tracks: vec![track.clone()],
        frames: 10,
        colliders: Vec::new(),
    };
    let strided = seq.every(3);
    assert_eq!(strided.frames(), 3);
    let t = &strided.tracks[0];
    assert_eq!(t.poses, [0, 3, 6, 9].map(|f| track.poses[f]));
    assert_eq!(t.velocities[0], [0.0; 6]);
    // Frames 1-3 all move with the first segment; frames 4-6 with the second.
    let first = [0.3, 0.0, 0.0, 0.0, 0.0, 1.2];
    assert!(t.velocities[1].iter().zip(first).all(|(a, b)| (a - b).abs() < 1e-15));
    assert!((t.velocities[2][1] + 0.6).abs() < 1e-15 && t.velocities[2][5] == 0.0);
    // Frames 7-9: the second segment's last step (7), then standing still (8, 9).
    assert!((t.velocities[3][1] + 0.2).abs() < 1e-15);
    assert_eq!(seq.every(1), seq);
    assert_eq!(seq.every(0), seq);
}

#[test]
fn refined_steps_the_same_motion_in_smaller_steps() {
    let segments = [
        Segment {
            frames: 3,
            velocity: [0.3, 0.1, 0.0],
            angular_velocity: [0.2, 0.0, 1.2],
        },
        Segment {
            frames: 4,
            velocity: [0.0, -0.6, 0.0],
            angular_velocity: [0.0, 0.5, 0.0],
        },
    ];
    let dt = 0.1;
    let seq = BcSequence {
        tracks: vec![Track::from_segments(&segments, 10, dt)],
        frames: 10,
        colliders: Vec::new(),
    };
    let fine = seq.refined(4, dt);
    assert_eq!(fine.frames(), 40);
    // The fine track integrated directly from the segments at dt / 4 (each segment's
    // frames times four) has the same poses up to rounding.
    let direct = Track::from_segments(
        &segments.map(|s| Segment {
            frames: 4 * s.frames,
            ..s
        }),
        40,
        dt / 4.0,
    );
    for (a, b) in fine.tracks[0].poses.iter().zip(&direct.poses) {
        assert!((a.translation - b.translation).norm() < 1e-12);
        assert!(a.rotation.angle_to(&b.rotation) < 1e-12);
    }
    assert_eq!(fine.tracks[0].velocities, direct.velocities);
    // Every fourth frame is the coarse sequence's, exactly.
    assert_eq!(fine.every(4).tracks[0].poses, seq.tracks[0].poses);
    assert_eq!(seq.refined(1, dt), seq);
}

#[test]
fn resampled_is_refined_and_every_at_whole_ratios_and_integrates_the_motion_between() {
    let segments = [
        Segment {
            frames: 3,
            velocity: [0.3, 0.1, 0.0],
            angular_velocity: [0.0, 0.0, 1.2],
        },
        Segment {
            frames: 4,
            velocity: [0.0, -0.6, 0.0],
            angular_velocity: [0.0, 0.0, -0.5],
        },
    ];
    let dt = 0.1;
    // A collider moving along x at 1 unit/s while turning about z at 0.5 rad/s.
    let collider = ColliderTrack::from_poses(
        (0..=10)
            .map(|f| crate::contact::ColliderPose::new([0.1 * f as f64, 0.0, 0.0], [0.0, 0.0, 0.05 * f as f64]))
            .collect(),
        dt,
    );
    let seq = BcSequence {
        tracks: vec![Track::from_segments(&segments, 10, dt)],
        frames: 10,
        colliders: vec![collider],
    };
    let close = |a: &BcSequence, b: &BcSequence| {
        assert_eq!(a.frames(), b.frames());
        for (ta, tb) in a.tracks.iter().zip(&b.tracks) {
            for (pa, pb) in ta.poses.iter().zip(&tb.poses) {
                assert!((pa.translation - pb.translation).norm() < 1e-12);
                assert!(pa.rotation.angle_to(&pb.rotation) < 1e-12);
            }
            for (va, vb) in ta.velocities.iter().zip(&tb.velocities) {
                assert!(
                    va.iter().zip(vb).all(|(a, b)| (a - b).abs() < 1e-12),
                    "{va:?} vs {vb:?}"
                );
            }
        }
    };
    close(&seq.resampled(dt, dt / 4.0, 40), &seq.refined(4, dt));
    close(&seq.resampled(dt, 3.0 * dt, 3), &seq.every(3));
    close(&seq.resampled(dt, dt, 10), &seq);
    close(&seq.resampled(dt, dt, 6), &seq.first(6));
    assert_eq!(seq.first(99), seq);
    // A ratio that is not whole (30 -> 72 frames per second): the poses are the motion's
    // closed form (rotation about one axis, constant velocities per segment) at each time.
    let new_dt = dt * 30.0 / 72.0;
    let frames = 30;
    let fine = seq.resampled(dt, new_dt, frames);
    let exact = |time: f64| {
        let first = time.min(0.3);
        let second = (time - 0.3).clamp(0.0, 0.4);
        let x = 0.3 * first;
        let y = 0.1 * first - 0.6 * second;
        (x, y, 1.2 * first - 0.5 * second)
    };
    for f in 0..=frames {
        let (x, y, angle) = exact(f as f64 * new_dt);
        let p = &fine.tracks[0].poses[f];
        assert!(
            (p.translation.x - x).abs() < 1e-12 && (p.translation.y - y).abs() < 1e-12,
            "frame {f}"
        );
        let turned = p.rotation.scaled_axis().z;
        assert!((turned - angle).abs() < 1e-12, "frame {f}: {turned} vs {angle}");
    }
    // Each new step's mean velocity moves the pose from one new frame to the next.
    for f in 1..=frames {
        let v = fine.tracks[0].velocities[f];
        let (x0, _, a0) = exact((f - 1) as f64 * new_dt);
        let (x1, _, a1) = exact(f as f64 * new_dt);
        assert!((v[0] * new_dt - (x1 - x0)).abs() < 1e-12 && (v[5] * new_dt - (a1 - a0)).abs() < 1e-12);
    }
    // The collider at each new frame's time, on its straight path and steady turn.
    for (f, pose) in fine.colliders[0].poses.iter().enumerate() {
        let time = (f as f64 * new_dt).min(1.0);
        assert!((pose.center.x - time).abs() < 1e-12, "frame {f}");
        assert!((pose.rotation_vector()[2] - 0.5 * time).abs() < 1e-12, "frame {f}");
    }
    assert_eq!(seq.first(6).colliders[0].poses, seq.colliders[0].poses[..=6]);
    // Past the end (frame 10 at 1 s) the handles hold still.
    let long = seq.resampled(dt, new_dt, 40);
    assert_eq!(long.tracks[0].poses[40], long.tracks[0].poses[30]);
    assert_eq!(long.tracks[0].velocities[40], [0.0; 6]);
}

#[test]
fn back_and_forth_motion_returns_and_is_seeded() {
    let spec = MotionSpec {
        segment_frames: [5, 9],
        directions: vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        rotation_axes: vec![[0.0, 0.0, 1.0]],
        rotation_share: 0.3,
        speed: [0.1, 0.5],
        angular_speed: [0.5, 1.0],
        back_and_forth: true,
    };
    spec.validate().unwrap();
    let speeds = |_| spec.speeds_at(0.5);
    let a = spec.sample(100, &speeds, &mut rng(3));
    let b = spec.sample(100, &speeds, &mut rng(3));
    let c = spec.sample(100, &speeds, &mut rng(4));
    assert_eq!(a, b);
    assert_ne!(a, c);
    let total: usize = a.iter().map(|s| s.frames).sum();
    let track = Track::from_segments(&a, total, 0.1);
    let end = track.poses[total];
    assert!(end.translation.norm() < 1e-12 && end.rotation.angle() < 1e-9, "{end:?}");
    for s in &a {
        let v = V3::from(s.velocity).norm();
        let w = V3::from(s.angular_velocity).norm();
        assert!((v - 0.3).abs() < 1e-12 || (w - 0.75).abs() < 1e-12);
    }
}

#[test]
fn steady_motion_keeps_one_segment_length() {
    let spec = MotionSpec {
        segment_frames: [10, 20],
        directions: vec![[0.0, 0.0, 1.0]],
        rotation_axes: vec![],
        rotation_share: 0.0,
        speed: [0.2, 1.0],
        angular_speed: [0.0, 0.0],
        back_and_forth: true,
    };
    assert_eq!(spec.steady(0.0).segment_frames, [10, 10]);
    assert_eq!(spec.steady(0.5).segment_frames, [15, 15]);
    assert_eq!(spec.steady(7.0).segment_frames, [20, 20]);
    let speeds = |_| spec.speeds_at(1.0);
    let segments = spec.steady(0.5).sample(200, &speeds, &mut rng(5));
    assert!(segments.len() > 10);
    assert!(segments.iter().all(|s| s.frames == 15));
    // Random lengths, from the same seed, do vary.
    let random = spec.sample(200, &speeds, &mut rng(5));
    assert!(random.iter().any(|s| s.frames != random[0].frames));
}

#[test]
fn invalid_motion_names_the_field() {
    let mut spec = MotionSpec {
        segment_frames: [5, 2],
        directions: vec![],
        rotation_axes: vec![],
        rotation_share: 0.0,
        speed: [0.0, 1.0],
        angular_speed: [0.0, 0.0],
        back_and_forth: true,
    };
    assert_eq!(spec.validate().unwrap_err().0, "segment_frames");
    spec.segment_frames = [2, 5];
    spec.speed = [f64::NAN, 1.0];
    assert_eq!(spec.validate().unwrap_err().0, "speed");
}
