//! The self-supervised physics loss of the latent integrator (Li et al. 2025, Eq. 4 and 6):
//! the full-space implicit Euler incremental potential of a predicted state,
//!
//! `E(x) = 1 / (2 dt^2) sum_i m_i |x_i - (2 x_{t-1} - x_{t-2})_i|^2 + Psi(x) + w_bc sum_h |x_h - x*_h|^2`,
//!
//! with `Psi` the scene's own conservative energies (elastic, gravity, loads, collision,
//! built by [`Scene::build_energies`], the same definitions the solver minimises) and the
//! quadratic penalty pulling handle vertices to their targets `x*`. Rods leave the penalty
//! out: their roots are placed exactly on decode (hard constraints).
//!
//! With run-time colliders the loss adds, as the solver's objective does (divided by `dt^2`),
//! IPC's barrier `kappa B(x)` between the surface vertices and the colliders at the predicted
//! frame's poses, and their lagged friction where the scene has it: the simulator's own
//! [`ColliderBarrier`] and [`ColliderFriction`], held at [`COLLIDER_FLOOR`] so that a
//! prediction inside a collider costs a finite, growing amount instead of an infinite one
//! (docs/design.md, decision 11).

use mochi_sim::bc::Handle;
use mochi_sim::contact::collider_friction::ColliderFriction;
use mochi_sim::contact::{ColliderBarrier, ColliderPose};
use mochi_sim::energy::{self, external::Penalty, inertia::Inertia, StencilEnergy};
use mochi_sim::error::InputError;
use mochi_sim::mesh::Mesh;
use mochi_sim::scene::{Energies, Scene};

/// Where the loss's collider barrier stops following IPC's barrier, as a fraction of `dhat`:
/// nearer than this (or inside) it continues by its second-order expansion. With the stiffest
/// barrier the solver uses ([`ColliderContact::kappa`]) this makes a millimetre of penetration
/// of the `poke` block cost a force several times its elastic stiffness's, instead of the
/// unbounded one of the barrier itself, which a network's millimetre-sized errors near a
/// collider would meet as infinite losses.
pub const COLLIDER_FLOOR: f64 = 0.1;

/// The colliders' part of the loss.
#[derive(Clone, Debug)]
pub struct ColliderContact {
    /// The surface vertices and the colliders (the simulator's barrier), posed per sample.
    pub barrier: ColliderBarrier,
    /// Barrier stiffness: the largest the simulator raises it to for this body (IPC's
    /// `kappa_max`).
    pub kappa: f64,
    /// Friction coefficient and smoothing velocity (`[contact] friction`, `epsv`); `None`
    /// without friction.
    pub friction: Option<(f64, f64)>,
    /// The same barrier posed at the frame before the predicted one (friction's lagged start).
    start: ColliderBarrier,
}

impl ColliderContact {
    /// The colliders of `barrier` with stiffness `kappa` and friction `(mu, epsv)`.
    pub fn new(barrier: ColliderBarrier, kappa: f64, friction: Option<(f64, f64)>) -> Self {
        ColliderContact {
            start: barrier.clone(),
            barrier,
            kappa,
            friction,
        }
    }
}

/// The incremental potential of one body, evaluated for predicted states.
pub struct PhysicsLoss {
    dim: usize,
    dt: f64,
    inertia: Inertia,
    potentials: Vec<Box<dyn StencilEnergy>>,
    penalty: Option<Penalty>,
    colliders: Option<ColliderContact>,
}

impl PhysicsLoss {
    /// Builds the loss of `scene`'s body; `bc_weight` is the penalty weight on the
    /// handle vertices, or `None` when they are imposed exactly by the decoder.
    pub fn new(scene: &Scene, mesh: &Mesh, handles: &[Handle], bc_weight: Option<f64>) -> Result<Self, InputError> {
        let Energies { masses, potentials } = scene.build_energies(mesh)?;
        let dim = mesh.dim;
        let penalty = bc_weight.map(|w| {
            let verts = handles.iter().flat_map(|h| h.vertices.iter().copied()).collect();
            Penalty::new(dim, w, verts)
        });
        Ok(PhysicsLoss {
            dim,
            dt: scene.dt,
            inertia: Inertia::new(dim, masses),
            potentials,
            penalty,
            colliders: None,
        })
    }

    /// The same loss with the colliders' barrier and friction.
    pub fn with_colliders(mut self, colliders: ColliderContact) -> Self {
        self.colliders = Some(colliders);
        self
    }

    /// Poses the colliders for the samples that follow: `previous` at the frame before the
    /// predicted one (friction's lagged start), `current` at the predicted frame. Ignored
    /// without colliders; poses beyond the loss's colliders are ignored.
    pub fn set_collider_poses(&mut self, previous: &[ColliderPose], current: &[ColliderPose]) {
        if let Some(c) = &mut self.colliders {
            let k = c.barrier.colliders().len();
            if previous.len() >= k && current.len() >= k {
                c.start.set_poses(&previous[..k]);
                c.barrier.set_poses(&current[..k]);
            }
        }
    }

    /// Sets the frame time of the samples that follow (a dataset over a range of frame rates
    /// has one per sequence; the scene's `dt` until set).
    pub fn set_dt(&mut self, dt: f64) {
        self.dt = dt;
    }

    /// Value of the loss at `x` given the two previous states and the handle targets
    /// (`dim` numbers per handle vertex, handles concatenated); writes `dE/dx` into `grad`.
    /// Runs on the calling thread (training evaluates one sample per thread) with a fixed
    /// summation order.
    pub fn value_and_gradient(
        &mut self,
        x: &[f64],
        prev: &[f64],
        prev2: &[f64],
        targets: &[f64],
        grad: &mut [f64],
    ) -> f64 {
        let xhat: Vec<f64> = prev.iter().zip(prev2).map(|(a, b)| 2.0 * a - b).collect();
        self.inertia.set_target(&xhat);
        grad.fill(0.0);
        let mut value = energy::add_gradient_sequential(&self.inertia, 1.0 / (self.dt * self.dt), x, grad);
        for p in &self.potentials {
            value += energy::add_gradient_sequential(p.as_ref(), 1.0, x, grad);
        }
        if let Some(penalty) = &mut self.penalty {
            penalty.set_targets(targets);
            value += energy::add_gradient_sequential(penalty, 1.0, x, grad);
        }
        if let Some(c) = &self.colliders {
            value += collider_terms(c, self.dt, x, prev, grad);
        }
        value
    }

    /// The data-balancing divisor of Eq. 6: the norm of the mean vertex velocity between
    /// the two previous states, floored at `min_speed` so resting states keep a finite weight.
    pub(crate) fn balance(&self, prev: &[f64], prev2: &[f64], min_speed: f64) -> f64 {
        let n = prev.len() / self.dim;
        let mut mean = [0.0; 3];
        for v in 0..n {
            for i in 0..self.dim {
                mean[i] += (prev[v * self.dim + i] - prev2[v * self.dim + i]) / (self.dt * n as f64);
            }
        }
        mean.iter().map(|c| c * c).sum::<f64>().sqrt().max(min_speed)
    }
}

/// `(kappa B(x) + D(x)) / dt^2` of the colliders at their poses, and its gradient added into
/// `grad`: the floored barrier, and friction lagged at `prev` with the colliders moving from
/// their previous poses to the current ones.
fn collider_terms(c: &ColliderContact, dt: f64, x: &[f64], prev: &[f64], grad: &mut [f64]) -> f64 {
    let weight = c.kappa / (dt * dt);
    let floor = COLLIDER_FLOOR * c.barrier.dhat();
    let mut value = weight * c.barrier.floored_value_and_gradient(x, floor, weight, grad);
    if let Some((mu, epsv)) = c.friction {
        let goals = c.barrier.poses();
        let friction = ColliderFriction::lagged_floored(&c.start, prev, &goals, (c.kappa, mu, epsv * dt), floor);
        value += energy::add_gradient_sequential(&friction, 1.0 / (dt * dt), x, grad);
    }
    value
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::recipe::{Recipe, PAPER_BC_WEIGHT};
    use mochi_sim::dataset::SpeedPlan;

    fn beam_frames() -> (
        mochi_sim::BuiltScene,
        mochi_sim::trajectory::Trajectory,
        mochi_sim::bc::BcSequence,
    ) {
        let mut scene = Recipe::load("beam").unwrap().scene;
        scene.mesh = mochi_sim::scene::MeshSpec::Box {
            min: [0.0, -0.075, -0.075],
            max: [1.0, 0.075, 0.075],
            cells: [8, 2, 2],
        };
        scene.newton.tolerance = 1e-9;
        let mut problem = scene.build().unwrap();
        let seq = problem.sequence(&SpeedPlan::constant(1.0), 6, 5);
        let traj = problem.run(&seq, &mochi_sim::Silent).unwrap();
        (problem, traj, seq)
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let (problem, traj, seq) = beam_frames();
        let mut loss =
            PhysicsLoss::new(&problem.scene, &problem.mesh, &problem.handles, Some(PAPER_BC_WEIGHT)).unwrap();
        let targets = seq.targets(&problem.handles, 5, 3);
        let mut x = traj.positions[5].clone();
        x.iter_mut()
            .enumerate()
            .for_each(|(k, c)| *c += 1e-3 * ((k as f64) * 0.7).sin());
        let mut grad = vec![0.0; x.len()];
        loss.value_and_gradient(&x, &traj.positions[4], &traj.positions[3], &targets, &mut grad);
        let mut scratch = vec![0.0; x.len()];
        let h = 1e-6;
        for k in (0..x.len()).step_by(17) {
            let mut xp = x.clone();
            xp[k] += h;
            let ep = loss.value_and_gradient(&xp, &traj.positions[4], &traj.positions[3], &targets, &mut scratch);
            xp[k] -= 2.0 * h;
            let em = loss.value_and_gradient(&xp, &traj.positions[4], &traj.positions[3], &targets, &mut scratch);
            let fd = (ep - em) / (2.0 * h);
            assert!(
                (fd - grad[k]).abs() <= 1e-5 * grad[k].abs().max(1.0),
                "dof {k}: {fd} vs {}",
                grad[k]
            );
        }
    }

    #[test]
    fn the_simulators_solution_is_stationary_for_the_free_dofs() {
        // The solver minimises the same incremental potential (times dt^2) over the free
        // DOF, so its result must have zero loss gradient there.
        let (problem, traj, seq) = beam_frames();
        let mut loss =
            PhysicsLoss::new(&problem.scene, &problem.mesh, &problem.handles, Some(PAPER_BC_WEIGHT)).unwrap();
        let mut grad = vec![0.0; traj.positions[5].len()];
        let targets = seq.targets(&problem.handles, 5, 3);
        loss.value_and_gradient(
            &traj.positions[5],
            &traj.positions[4],
            &traj.positions[3],
            &targets,
            &mut grad,
        );
        let mut fixed = vec![false; problem.mesh.num_vertices()];
        problem
            .handles
            .iter()
            .flat_map(|h| &h.vertices)
            .for_each(|&v| fixed[v] = true);
        let max_free = (0..grad.len())
            .filter(|k| !fixed[k / 3])
            .map(|k| grad[k].abs())
            .fold(0.0, f64::max);
        let max_all = grad.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        let scale = problem.simulator.masses().iter().sum::<f64>() * 9.81;
        assert!(max_free < 1e-6 * scale, "free-DOF gradient {max_free} (weight {scale})");
        // Handle vertices sit exactly on their targets: the penalty adds nothing, but the
        // elastic reaction force of the clamp remains.
        assert!(max_all > 1e3 * max_free);
    }

    /// The colliders' barrier and friction in the loss: finite-difference gradients with a
    /// vertex inside the capsule, below the barrier's floor, and between the floor and `dhat`
    /// while the capsule drags sideways; and the loss grows as the capsule presses deeper.
    #[test]
    fn collider_terms_match_finite_differences_inside_and_near_a_collider() {
        let mut scene = Recipe::load("poke").unwrap().scene;
        scene.mesh = mochi_sim::scene::MeshSpec::Box {
            min: [-0.05, 0.0, -0.05],
            max: [0.05, 0.08, 0.05],
            cells: [2, 2, 2],
        };
        scene.contact.as_mut().unwrap().friction = 0.3;
        let problem = scene.build().unwrap();
        let contact = crate::learn::integrator::collider_contact(&problem).unwrap();
        assert!(contact.friction.is_some());
        let mut loss = PhysicsLoss::new(&problem.scene, &problem.mesh, &problem.handles, Some(PAPER_BC_WEIGHT))
            .unwrap()
            .with_colliders(contact);
        let rest = problem.mesh.rest.clone();
        let targets: Vec<f64> = problem
            .handles
            .iter()
            .flat_map(|h| h.vertices.iter().flat_map(|&v| rest[3 * v..3 * v + 3].to_vec()))
            .collect();
        // The top centre vertex (0, 0.08, 0) under the capsule's lower tip (radius 0.012,
        // half length 0.015, axis vertical): `gap` above the tip, negative inside.
        let tip = 0.012 + 0.015;
        let pose = |gap: f64, dx: f64| ColliderPose::new([dx, 0.08 + tip + gap, 0.0], [0.0; 3]);
        let dhat = 1e-3;
        let mut values = Vec::new();
        for gap in [0.4 * dhat, 0.05 * dhat, -2e-3, -6e-3] {
            // The capsule drags 1 mm along x over the step.
            loss.set_collider_poses(&[pose(gap, -1e-3)], &[pose(gap, 0.0)]);
            let mut x = rest.clone();
            x.iter_mut()
                .enumerate()
                .for_each(|(k, c)| *c += 1e-5 * ((k as f64) * 0.7).sin());
            let mut grad = vec![0.0; x.len()];
            let value = loss.value_and_gradient(&x, &rest, &rest, &targets, &mut grad);
            values.push(value);
            let mut scratch = vec![0.0; x.len()];
            let h = 1e-8;
            for k in 0..x.len() {
                let mut xp = x.clone();
                xp[k] += h;
                let ep = loss.value_and_gradient(&xp, &rest, &rest, &targets, &mut scratch);
                xp[k] -= 2.0 * h;
                let em = loss.value_and_gradient(&xp, &rest, &rest, &targets, &mut scratch);
                let fd = (ep - em) / (2.0 * h);
                assert!(
                    (fd - grad[k]).abs() <= 1e-4 * grad[k].abs().max(1.0),
                    "gap {gap}, dof {k}: {fd} vs {}",
                    grad[k]
                );
            }
        }
        assert!(values.windows(2).all(|w| w[1] > w[0]), "{values:?}");
    }

    #[test]
    fn balance_is_the_mean_speed_with_a_floor() {
        let (problem, traj, _) = beam_frames();
        let loss = PhysicsLoss::new(&problem.scene, &problem.mesh, &problem.handles, None).unwrap();
        let b = loss.balance(&traj.positions[5], &traj.positions[4], 1e-6);
        assert!(b > 1e-3, "the beam moves: {b}");
        assert_eq!(loss.balance(&traj.positions[0], &traj.positions[0], 0.25), 0.25);
    }
}
