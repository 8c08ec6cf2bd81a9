//! The self-supervised physics loss of the latent integrator (Li et al. 2025, Eq. 4 and 6):
//! the full-space implicit Euler incremental potential of a predicted state,
//!
//! `E(x) = 1 / (2 dt^2) sum_i m_i |x_i - (2 x_{t-1} - x_{t-2})_i|^2 + Psi(x) + w_bc sum_h |x_h - x*_h|^2`,
//!
//! with `Psi` the scene's own conservative energies (elastic, gravity, loads, collision,
//! built by [`Scene::build_energies`], the same definitions the solver minimises) and the
//! quadratic penalty pulling handle vertices to their targets `x*`. Rods leave the penalty
//! out: their roots are placed exactly on decode (hard constraints).

use mochi_sim::bc::Handle;
use mochi_sim::energy::{self, external::Penalty, inertia::Inertia, StencilEnergy};
use mochi_sim::error::InputError;
use mochi_sim::mesh::Mesh;
use mochi_sim::scene::{Energies, Scene};

/// The incremental potential of one body, evaluated for predicted states.
pub struct PhysicsLoss {
    dim: usize,
    dt: f64,
    inertia: Inertia,
    potentials: Vec<Box<dyn StencilEnergy>>,
    penalty: Option<Penalty>,
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
        })
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

    #[test]
    fn balance_is_the_mean_speed_with_a_floor() {
        let (problem, traj, _) = beam_frames();
        let loss = PhysicsLoss::new(&problem.scene, &problem.mesh, &problem.handles, None).unwrap();
        let b = loss.balance(&traj.positions[5], &traj.positions[4], 1e-6);
        assert!(b > 1e-3, "the beam moves: {b}");
        assert_eq!(loss.balance(&traj.positions[0], &traj.positions[0], 0.25), 0.25);
    }
}
