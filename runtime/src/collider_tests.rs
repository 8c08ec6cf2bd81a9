//! Tests of [`crate::collider`]: exact distances of each shape, the push-out's shortest move
//! (to `margin` outside, nothing else moved) over points around turned shapes, and refusals
//! that change nothing.

use std::vec::Vec;

use super::*;

/// A small deterministic generator (no dependency for a test's points): xorshift64*.
struct Points(u64);

impl Points {
    fn unit(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let bits = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40;
        bits as f32 / (1u64 << 24) as f32
    }
    fn around(&mut self, center: [f32; 3], half: f32) -> [f32; 3] {
        center.map(|c| c + half * (2.0 * self.unit() - 1.0))
    }
}

fn shapes() -> [Collider; 4] {
    [
        Collider {
            shape: SPHERE,
            size: [0.2, 0.0, 0.0],
            center: [0.1, -0.3, 0.5],
            rotation: [0.0; 3],
        },
        Collider {
            shape: CAPSULE,
            size: [0.05, 0.15, 0.0],
            center: [-0.2, 0.1, 0.0],
            rotation: [0.3, -0.8, 0.4],
        },
        Collider {
            shape: CAPSULE,
            size: [0.1, 0.0, 0.0],
            center: [0.0; 3],
            rotation: [0.0; 3],
        },
        Collider {
            shape: BOX,
            size: [0.3, 0.05, 0.1],
            center: [0.4, 0.0, -0.2],
            rotation: [1.1, 0.2, -0.5],
        },
    ]
}

fn distance(a: [f32; 3], b: [f32; 3]) -> f32 {
    (V3::from(a) - V3::from(b)).norm()
}

#[test]
fn distances_are_exact_for_each_shape() {
    let [sphere, capsule, _, boxed] = shapes();
    assert!((sphere.signed_distance([0.1, -0.3, 0.9]) - 0.2).abs() < 1e-6);
    assert!((sphere.signed_distance([0.1, -0.3, 0.5]) + 0.2).abs() < 1e-6);
    // The capsule's end: a point beyond its cap along its axis.
    let axis: [f32; 3] = (rotation(&capsule.rotation) * V3::y()).into();
    let beyond = [0, 1, 2].map(|i| capsule.center[i] + 0.3 * axis[i]);
    assert!((capsule.signed_distance(beyond) - (0.3 - 0.15 - 0.05)).abs() < 1e-6);
    // A box corner seen from outside along its diagonal, in its own frame.
    let frame = rotation(&boxed.rotation);
    let corner = V3::new(0.3, 0.05, 0.1) + V3::new(0.03, 0.04, 0.0);
    let world: [f32; 3] = (V3::from(boxed.center) + frame * corner).into();
    assert!((boxed.signed_distance(world) - 0.05).abs() < 1e-6);
    let inside: [f32; 3] = (V3::from(boxed.center) + frame * V3::new(0.0, 0.04, 0.0)).into();
    assert!((boxed.signed_distance(inside) + 0.01).abs() < 1e-6);
}

#[test]
fn push_out_moves_the_shortest_way_to_the_margin_and_nothing_else() {
    let mut points = Points(0x9e37_79b9_7f4a_7c15);
    for c in shapes() {
        for margin in [0.0, 0.02] {
            // Points in a cube around the shape (a few percent of them inside the thin box).
            let [a, b, e] = c.size;
            let bound = match c.shape {
                SPHERE => a,
                CAPSULE => a + b,
                _ => V3::new(a, b, e).norm(),
            };
            let before: Vec<f32> = (0..2000).flat_map(|_| points.around(c.center, 1.2 * bound)).collect();
            let mut after = before.clone();
            let moved = push_out(&mut after, 3, &[c], margin).unwrap();
            let mut counted = 0;
            for (p, q) in before.chunks_exact(3).zip(after.chunks_exact(3)) {
                let (p, q) = ([p[0], p[1], p[2]], [q[0], q[1], q[2]]);
                let d = c.signed_distance(p);
                if d >= margin {
                    assert_eq!(p, q, "a vertex {d} outside was moved");
                    continue;
                }
                counted += 1;
                let now = c.signed_distance(q);
                assert!((now - margin).abs() < 2e-5, "shape {} at {d}: now {now}", c.shape);
                // The shortest way: as far as the distance was short of the margin.
                assert!(
                    (distance(p, q) - (margin - d)).abs() < 2e-5,
                    "shape {}: moved {} for a shortfall of {}",
                    c.shape,
                    distance(p, q),
                    margin - d
                );
            }
            assert_eq!(moved, counted);
            assert!(counted > 30, "shape {}: only {counted} points were inside", c.shape);
        }
    }
}

#[test]
fn points_at_a_centre_or_on_an_axis_still_go_out() {
    let [sphere, capsule, ball, boxed] = shapes();
    for (c, p) in [
        (sphere, sphere.center),
        (capsule, capsule.center),
        (ball, [0.0; 3]),
        (boxed, boxed.center),
    ] {
        let q = c.pushed(p, 0.01).unwrap();
        assert!((c.signed_distance(q) - 0.01).abs() < 1e-5 && q.iter().all(|v| v.is_finite()));
    }
}

#[test]
fn two_dimensional_vertices_keep_their_plane() {
    let c = Collider {
        shape: SPHERE,
        size: [0.5, 0.0, 0.0],
        center: [0.0, 0.0, 0.0],
        rotation: [0.0; 3],
    };
    let mut xy = [0.1, 0.2, 2.0, 2.0];
    assert_eq!(push_out(&mut xy, 2, &[c], 0.0), Ok(1));
    assert!((V3::new(xy[0], xy[1], 0.0).norm() - 0.5).abs() < 1e-6);
    assert_eq!(&xy[2..], &[2.0, 2.0]);
}

#[test]
fn bad_colliders_and_arguments_are_refused_and_change_nothing() {
    let good = shapes()[0];
    let bad = [
        Collider { shape: 7, ..good },
        Collider {
            size: [0.0, 0.0, 0.0],
            ..good
        },
        Collider {
            center: [f32::NAN, 0.0, 0.0],
            ..good
        },
        Collider {
            shape: CAPSULE,
            size: [0.1, -0.1, 0.0],
            ..good
        },
        Collider {
            shape: BOX,
            size: [0.1, 0.1, 0.0],
            ..good
        },
        Collider {
            rotation: [0.0, f32::INFINITY, 0.0],
            ..good
        },
    ];
    let start = [0.1, -0.3, 0.5, 9.0, 9.0, 9.0];
    for b in bad {
        let mut p = start;
        assert_eq!(
            push_out(&mut p, 3, &[good, b], 0.0),
            Err(ColliderError::Invalid { index: 1 })
        );
        assert_eq!(p, start);
    }
    let mut p = start;
    assert_eq!(push_out(&mut p, 4, &[good], 0.0), Err(ColliderError::Arguments));
    assert_eq!(push_out(&mut p[..5], 3, &[good], 0.0), Err(ColliderError::Arguments));
    assert_eq!(push_out(&mut p, 3, &[good], -1.0), Err(ColliderError::Arguments));
    assert_eq!(push_out(&mut p, 3, &[good], f32::NAN), Err(ColliderError::Arguments));
    assert_eq!(p, start);
    assert_eq!(push_out(&mut p, 3, &[], 0.0), Ok(0));
}

/// The integrator's collider inputs: the centre and velocity in the encoding frame, the
/// shape's axes continuous through a half turn (a capsule pointing straight down, turned a
/// hair either way, reads almost the same), and a far or absent collider reads alike.
#[test]
fn features_are_the_pose_in_the_encoding_frame_and_continuous_through_a_half_turn() {
    let quarter = core::f32::consts::FRAC_PI_2;
    // The encoding frame turned a quarter about z, its origin at (1, 0, 0).
    let frame = *crate::frame::rotation(&[0.0, 0.0, quarter]).matrix();
    let origin = V3::new(1.0, 0.0, 0.0);
    let state = |rotation: [f32; 3]| ColliderState {
        center: [1.0, 0.5, 0.0],
        rotation,
        linear_velocity: [0.0, 2.0, 0.0],
        angular_velocity: [0.0; 3],
    };
    let f = features(&frame, &origin, 1.0, Some(&state([0.0; 3])));
    let close = |a: &[f32], b: &[f32], tol: f32| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol);
    // Centre (0, 0.5, 0) seen from a frame turned +90 degrees about z: (0.5, 0, 0); the shape's
    // x and y axes likewise; the velocity (0, 2, 0) as (2, 0, 0).
    let want = [0.5, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0];
    assert!(close(&f, &want, 1e-6), "{f:?}");
    // Half a turn about x, a hair less and a hair more (the rotation vector flips sign there).
    let pi = core::f32::consts::PI;
    let below = features(&frame, &origin, 1.0, Some(&state([pi - 1e-3, 0.0, 0.0])));
    let above = features(&frame, &origin, 1.0, Some(&state([-(pi - 1e-3), 0.0, 0.0])));
    assert!(close(&below, &above, 3e-3), "{below:?} / {above:?}");
    // Absent and far away read the same, the axes those of the frame.
    let absent = features(&frame, &origin, 1.0, None);
    let mut far = state([0.3, 0.2, 0.1]);
    far.center = [1.0, 0.0, 5.0];
    assert_eq!(absent, features(&frame, &origin, 1.0, Some(&far)));
    assert_eq!(&absent[3..9], &[1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
}
