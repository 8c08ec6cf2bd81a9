//! Analytic colliders: exact distances on every feature, finite-difference checks of the
//! squared distances and of the barrier potential, and the CCD bound on random motions.

use super::{assert_fd, fd, random_vec, rng};
use crate::contact::collider::{Collider, ColliderPose, ColliderShape};
use crate::contact::collider_barrier::ColliderBarrier;
use crate::contact::collider_ccd::{collider_max_step, colliders_max_step};
use crate::energy::fd::assert_all_stencils;
use crate::energy::{Local, StencilEnergy, Want};
use nalgebra::Vector3;
use rand::Rng;

type V3 = Vector3<f64>;

fn sphere() -> Collider {
    Collider {
        shape: ColliderShape::Sphere { radius: 0.2 },
        pose: ColliderPose::new([0.1, -0.3, 0.2], [0.4, -0.2, 0.9]),
    }
}

fn capsule() -> Collider {
    Collider {
        shape: ColliderShape::Capsule {
            radius: 0.1,
            half_length: 0.3,
        },
        pose: ColliderPose::new([-0.2, 0.1, 0.05], [0.7, 0.3, -0.5]),
    }
}

fn cuboid() -> Collider {
    Collider {
        shape: ColliderShape::Box {
            half_extents: [0.3, 0.2, 0.1],
        },
        pose: ColliderPose::new([0.3, 0.0, -0.1], [-0.3, 0.8, 0.2]),
    }
}

/// The world point at local coordinates `q` of `c`'s frame.
fn world(c: &Collider, q: [f64; 3]) -> [f64; 3] {
    (c.pose.center + c.pose.rotation * V3::from(q)).into()
}

/// Local points of every feature of each shape with their exact distance: sphere; capsule
/// side and both end caps (one just past the end of the segment, and one inside the cap);
/// box face, edge, corner.
fn features() -> Vec<(Collider, [f64; 3], f64)> {
    let (s, c, b) = (sphere(), capsule(), cuboid());
    let diag = |x: f64, y: f64| (x * x + y * y).sqrt();
    vec![
        (s, [0.3, 0.0, 0.4], 0.5 - 0.2),
        (s, [-0.1, 0.2, -0.05], diag(diag(0.1, 0.2), 0.05) - 0.2),
        (c, [0.15, 0.1, 0.0], 0.05),
        (c, [0.0, 0.45, 0.0], 0.05),
        (c, [0.12, 0.305, 0.0], diag(0.12, 0.005) - 0.1),
        (c, [0.03, 0.31, -0.04], diag(diag(0.03, 0.01), 0.04) - 0.1),
        (c, [0.1, -0.4, 0.1], diag(diag(0.1, 0.1), 0.1) - 0.1),
        (b, [0.1, 0.25, 0.0], 0.05),
        (b, [0.4, 0.3, 0.05], diag(0.1, 0.1)),
        (b, [-0.32, -0.23, 0.14], diag(diag(0.02, 0.03), 0.04)),
    ]
}

#[test]
fn distances_are_exact_on_every_feature_of_every_shape() {
    let mut out = Local::default();
    for (k, (c, q, d)) in features().into_iter().enumerate() {
        let p = world(&c, q);
        let got = c.signed_distance(&p);
        assert!((got - d).abs() < 1e-12, "feature {k}: {got} vs {d}");
        let d2 = c.squared_distance(&p, Want::Value, &mut out);
        assert!((d2 - d.max(0.0).powi(2)).abs() < 1e-12, "feature {k}: squared {d2}");
    }
    // Inside: a negative signed distance (the depth), a zero distance, zero derivatives.
    let b = cuboid();
    let p = world(&b, [0.25, 0.0, 0.02]);
    assert!((b.signed_distance(&p) + 0.05).abs() < 1e-12);
    assert_eq!(b.distance(&p), 0.0);
    let d2 = b.squared_distance(&p, Want::Hessian { project: false }, &mut out);
    assert_eq!(d2, 0.0);
    assert!(out.grad[..3].iter().chain(&out.hess[..9]).all(|v| *v == 0.0));
}

#[test]
fn squared_distance_derivatives_match_finite_differences_on_every_feature() {
    for (k, (c, q, d)) in features().into_iter().enumerate() {
        if d <= 0.0 {
            continue;
        }
        let p = world(&c, q);
        let r = fd(3, &p, 1e-7, |x: &[f64], want, out: &mut Local| {
            c.squared_distance(x, want, out)
        });
        assert_fd(r, 1e-6, &format!("feature {k} of {:?}", c.shape));
    }
    // Random points outside each shape (in every region).
    let mut g = rng(11);
    for c in [sphere(), capsule(), cuboid()] {
        let mut checked = 0;
        while checked < 40 {
            let q: Vec<f64> = random_vec(&mut g, 3).iter().map(|v| 0.6 * v).collect();
            let p = world(&c, [q[0], q[1], q[2]]);
            if c.signed_distance(&p) < 1e-3 {
                continue;
            }
            let r = fd(3, &p, 1e-7, |x: &[f64], want, out: &mut Local| {
                c.squared_distance(x, want, out)
            });
            assert_fd(r, 1e-5, &format!("{:?} at {q:?}", c.shape));
            checked += 1;
        }
    }
}

#[test]
fn the_barrier_potential_matches_finite_differences_for_every_shape() {
    let dhat = 0.08;
    let colliders = vec![sphere(), capsule(), cuboid()];
    // Vertices within dhat of each feature: features at distances up to 0.05 and points
    // moved towards the surface.
    let mut x = Vec::new();
    for (c, q, d) in features() {
        if d <= 0.0 {
            continue;
        }
        x.extend_from_slice(&world(&c, q));
    }
    let n = x.len() / 3;
    let barrier = ColliderBarrier::new((0..n).collect(), colliders, dhat);
    assert_eq!(barrier.len(), 3 * n);
    let mut out = Local::default();
    let active = (0..barrier.len())
        .filter(|&s| {
            let v = barrier.pair(s).0;
            barrier.eval(s, &x[3 * v..3 * v + 3], Want::Value, &mut out) > 0.0
        })
        .count();
    assert!(active >= 6, "only {active} active pairs");
    assert_all_stencils(&barrier, &x, 1e-8, 1e-5);
    // The projected Hessian is positive semi-definite and the gradient pushes out.
    for s in 0..barrier.len() {
        let (v, c) = barrier.pair(s);
        let p = &x[3 * v..3 * v + 3];
        barrier.eval(s, p, Want::Hessian { project: true }, &mut out);
        let h = nalgebra::Matrix3::from_row_slice(&out.hess[..9]);
        assert!(h.symmetric_eigenvalues().min() > -1e-9 * h.norm().max(1.0));
        let outward = barrier.colliders()[c].signed_distance(&[p[0] + 1e-6, p[1], p[2]])
            - barrier.colliders()[c].signed_distance(&[p[0] - 1e-6, p[1], p[2]]);
        assert!(out.grad[0] * outward <= 1e-12, "stencil {s} pulls inwards");
    }
}

/// A random pose near the origin.
fn random_pose(g: &mut rand_chacha::ChaCha8Rng) -> ColliderPose {
    let c = random_vec(g, 3);
    let r = random_vec(g, 3);
    ColliderPose::new([0.3 * c[0], 0.3 * c[1], 0.3 * c[2]], [r[0], r[1], r[2]])
}

#[test]
fn the_step_bound_never_lets_a_vertex_into_a_moving_collider() {
    let mut g = rng(5);
    let (mut bounded, mut crossing) = (0, 0);
    for case in 0..600 {
        let shape = [sphere(), capsule(), cuboid()][case % 3].shape;
        let c = Collider {
            shape,
            pose: random_pose(&mut g),
        };
        let to = random_pose(&mut g);
        let p0: Vec<f64> = random_vec(&mut g, 3).iter().map(|v| 0.8 * v).collect();
        if c.signed_distance(&p0) <= 1e-4 {
            continue;
        }
        let p1: Vec<f64> = random_vec(&mut g, 3).iter().map(|v| 0.8 * v).collect();
        let t = collider_max_step(&c, &to, &p0, &p1);
        assert!(t > 0.0, "case {case}: no step from outside");
        let at = |s: f64| {
            let pose = c.pose.towards(&to, s);
            let p: Vec<f64> = (0..3).map(|i| p0[i] + s * (p1[i] - p0[i])).collect();
            Collider { shape, pose }.signed_distance(&p)
        };
        for k in 0..=200 {
            let s = t * k as f64 / 200.0;
            assert!(at(s) > 0.0, "case {case}: inside at {s} of bound {t}");
        }
        let crosses = (0..=400).any(|k| at(k as f64 / 400.0) <= 0.0);
        if crosses {
            crossing += 1;
            assert!(t < 1.0, "case {case}: a crossing step is not bounded");
        }
        bounded += (t < 1.0) as usize;
    }
    assert!(crossing > 50, "only {crossing} crossing cases");
    assert!(bounded >= crossing);
}

#[test]
fn the_step_bound_of_a_vertex_set_is_the_smallest_and_refuses_a_start_inside() {
    let c = sphere();
    let to = ColliderPose {
        center: c.pose.center + V3::new(0.0, 0.5, 0.0),
        ..c.pose
    };
    // Vertex 0 sits still far away; vertex 1 sits in the sphere's way.
    let x0 = [5.0, 5.0, 5.0, 0.1, 0.1, 0.2];
    let t = colliders_max_step(&[c], &[to], &[0, 1], &x0, &x0);
    // The sphere reaches it at 0.4 of the step; the bound stops short of that.
    assert!(t > 0.3 && t < 0.4, "bound {t}");
    assert_eq!(colliders_max_step(&[c], &[to], &[0], &x0, &x0), 1.0);
    let inside = [0.1, -0.3, 0.2];
    assert_eq!(collider_max_step(&c, &to, &inside, &inside), 0.0);
    let mut g = rng(3);
    let nan = [f64::NAN, g.random_range(0.0..1.0), 0.0];
    assert_eq!(collider_max_step(&c, &to, &x0[..3], &nan), 0.0);
}

#[test]
fn shape_parameters_round_trip_and_poses_interpolate_at_a_constant_rate() {
    for c in [sphere(), capsule(), cuboid()] {
        assert_eq!(ColliderShape::from_parameters(c.shape.parameters()), Some(c.shape));
    }
    assert_eq!(ColliderShape::from_parameters([7.0, 1.0, 0.0, 0.0]), None);
    let a = ColliderPose::new([0.0; 3], [0.0, 0.0, 0.2]);
    let b = ColliderPose::new([1.0, 0.0, 0.0], [0.0, 0.0, 1.0]);
    let half = a.towards(&b, 0.5);
    assert!((half.center.x - 0.5).abs() < 1e-15);
    assert!((half.rotation.angle() - 0.6).abs() < 1e-12);
    assert!((a.angle_to(&b) - 0.8).abs() < 1e-12);
    assert_eq!(a.towards(&b, 1.0), b);
    // A point fixed to the shape is carried rigidly.
    let p = V3::new(0.3, 0.1, 0.0);
    let q = a.carry(p, &b);
    assert!(((q - b.center).norm() - (p - a.center).norm()).abs() < 1e-12);
}

#[test]
fn collider_friction_matches_finite_differences_and_resists_slip() {
    use crate::contact::collider_friction::ColliderFriction;
    let dhat = 0.08;
    let colliders = vec![sphere(), capsule(), cuboid()];
    let mut x = Vec::new();
    for (c, q, d) in features() {
        if d > 0.0 {
            x.extend_from_slice(&world(&c, q));
        }
    }
    let n = x.len() / 3;
    let barrier = ColliderBarrier::new((0..n).collect(), colliders, dhat);
    // Each collider moves and turns a little over the step.
    let goals: Vec<ColliderPose> = barrier
        .poses()
        .iter()
        .map(|p| ColliderPose {
            center: p.center + V3::new(0.01, -0.02, 0.005),
            rotation: nalgebra::UnitQuaternion::from_scaled_axis(V3::new(0.0, 0.05, 0.02)) * p.rotation,
        })
        .collect();
    let eps_u = 1e-3;
    let friction = ColliderFriction::lagged(&barrier, &x, &goals, 10.0, 0.4, eps_u);
    assert!(friction.len() >= 6, "{} stencils", friction.len());
    assert_eq!(
        ColliderFriction::lagged(&barrier, &x, &goals, 10.0, 0.0, eps_u).len(),
        0
    );
    // Slipping vertices (beyond eps_u) and nearly sticking ones.
    let mut g = rng(9);
    for scale in [0.03, 3e-4] {
        let moved: Vec<f64> = x
            .iter()
            .zip(random_vec(&mut g, x.len()))
            .map(|(a, r)| a + scale * r)
            .collect();
        assert_all_stencils(&friction, &moved, 1e-9, 1e-5);
    }
    // One vertex on a capsule's side that moves 2 cm along its axis: left behind, the
    // vertex feels friction that pulls it along; carried with the capsule, none beyond the
    // smoothing's floor.
    let c = capsule();
    let p = world(&c, [0.12, 0.0, 0.0]);
    let axis = c.pose.rotation * V3::y();
    let goal = ColliderPose {
        center: c.pose.center + 0.02 * axis,
        ..c.pose
    };
    let one = ColliderBarrier::new(vec![0], vec![c], 0.05);
    let friction = ColliderFriction::lagged(&one, &p, &[goal], 10.0, 0.4, eps_u);
    assert_eq!(friction.len(), 1);
    let mut out = Local::default();
    let behind = friction.eval(0, &p, Want::Gradient, &mut out);
    let pull = -V3::new(out.grad[0], out.grad[1], out.grad[2]);
    assert!(
        pull.dot(&axis) > 0.9 * pull.norm() && pull.norm() > 0.0,
        "pull {pull:?}"
    );
    let along: Vec<f64> = (0..3).map(|i| p[i] + 0.02 * axis[i]).collect();
    let carried = friction.eval(0, &along, Want::Value, &mut out);
    // The floor is `mu N f0(0) = mu N eps_u / 3`, a sixtieth of 2 cm of slip here.
    assert!(carried < 0.02 * behind, "carried {carried} vs behind {behind}");
}

/// The floored barrier of a training loss is `B` where every pair is at least `floor` apart,
/// finite with a finite-difference gradient everywhere else (inside each shape too), and its
/// gradient pushes every vertex out of the collider, harder the deeper it is.
#[test]
fn the_floored_barrier_is_the_barrier_above_its_floor_and_pushes_out_below() {
    let dhat = 0.08;
    let floor = 0.01;
    let colliders = vec![sphere(), capsule(), cuboid()];
    // Points along a ray out of each feature, from inside to beyond dhat.
    let mut rays = Vec::new();
    for (c, q, _) in features() {
        let (_, n) = c.signed_distance_and_gradient(&world(&c, q));
        let surface: [f64; 3] = (V3::from(world(&c, q)) - c.signed_distance(&world(&c, q)) * n).into();
        rays.push((c, surface, n));
    }
    let mut g = rng(11);
    let mut checked = 0;
    for (c, surface, n) in &rays {
        let at = |t: f64| -> Vec<f64> { (V3::from(*surface) + t * n).as_slice().to_vec() };
        let barrier = ColliderBarrier::new(vec![0], vec![*c], dhat);
        let value = |x: &[f64]| {
            let mut sink = vec![0.0; 3];
            barrier.floored_value_and_gradient(x, floor, 1.0, &mut sink)
        };
        // Above the floor: the barrier itself.
        for t in [0.011, 0.03, 0.07, 0.09] {
            let x = at(t);
            let exact = crate::energy::value(&barrier, &x);
            assert!((value(&x) - exact).abs() <= 1e-12 * exact.abs().max(1e-30), "t {t}");
        }
        // Below it and inside: finite, larger the deeper, gradient against finite differences
        // and pointing out.
        let mut last = value(&at(floor));
        for t in [0.005, 0.0005, -0.01, -0.03] {
            let x = at(t);
            let v = value(&x);
            assert!(v.is_finite() && v > last, "t {t}: {v} after {last}");
            last = v;
            let mut grad = vec![0.0; 3];
            barrier.floored_value_and_gradient(&x, floor, 1.0, &mut grad);
            assert!(V3::from_column_slice(&grad).dot(n) < 0.0, "t {t}: does not push out");
            let dir = random_vec(&mut g, 3);
            let h = 1e-7;
            let shifted = |s: f64| -> Vec<f64> { x.iter().zip(&dir).map(|(a, b)| a + s * b).collect() };
            // Inside a box, on the bisector of two faces the signed distance has a crease.
            let normal_at = |s: f64| c.signed_distance_and_gradient(&shifted(s)).1;
            if (normal_at(h) - normal_at(-h)).norm() > 1e-2 {
                continue;
            }
            let fd = (value(&shifted(h)) - value(&shifted(-h))) / (2.0 * h);
            let analytic: f64 = grad.iter().zip(&dir).map(|(a, b)| a * b).sum();
            assert!(
                (fd - analytic).abs() <= 1e-5 * analytic.abs().max(1e-12),
                "t {t}: {fd} vs {analytic}"
            );
            checked += 1;
        }
    }
    assert!(checked >= 30, "{checked} finite-difference checks");
    // Over many vertices and every shape at once: the sum over pairs, weighted.
    let x: Vec<f64> = (0..40)
        .flat_map(|_| random_vec(&mut g, 3).iter().map(|v| 0.4 * v).collect::<Vec<_>>())
        .collect();
    let all = ColliderBarrier::new((0..40).collect(), colliders, dhat);
    let mut grad = vec![0.0; x.len()];
    let total = all.floored_value_and_gradient(&x, floor, 2.0, &mut grad);
    let mut single = vec![0.0; x.len()];
    let sum: f64 = (0..40)
        .map(|v| {
            ColliderBarrier::new(vec![v], all.colliders().to_vec(), dhat).floored_value_and_gradient(
                &x,
                floor,
                2.0,
                &mut single,
            )
        })
        .sum();
    assert!((total - sum).abs() <= 1e-9 * total.abs().max(1.0));
    assert!(grad
        .iter()
        .zip(&single)
        .all(|(a, b)| (a - b).abs() <= 1e-9 * a.abs().max(1.0)));
}
