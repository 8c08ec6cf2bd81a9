//! Full-space time stepping as optimisation: implicit Euler and BDF2 incremental
//! potentials minimised by Newton's method with backtracking line search.
//!
//! Dirichlet boundary conditions eliminate the prescribed degrees of freedom: those
//! vertices are placed at their scripted positions and only the free DOF are solved for.
//! The free-free Hessian block is assembled (in parallel) into a fixed sparse pattern and
//! factorised with faer's sparse Cholesky, whose symbolic analysis is computed once and
//! reused across iterations and steps.

#[cfg(test)]
mod collider_tests;
mod contact;
#[cfg(test)]
mod contact_tests;
mod direction;
mod potential;
mod prescribed;
mod report;
mod settings;
mod state;
mod vbd;

pub(crate) use crate::dofs::{free_dof_index, NOT_FREE};
use crate::energy::{self, inertia::Inertia, StencilEnergy};
pub use crate::error::{Quantity, StepError};
use crate::hessian::HessianPattern;
use contact::Contact;
pub use contact::{ContactConfig, ContactObstacle, ContactSettings};
pub(crate) use potential::incremental_potential;
pub(crate) use prescribed::{check_targets, place_fixed};
pub use report::{SolvePhases, StepReport};
pub use settings::{HessianMode, NewtonSettings, TimeScheme};
pub use state::SimState;
use std::time::Instant;
pub use vbd::VbdUnsupported;

/// A full-space simulator of one body.
pub struct Simulator {
    dim: usize,
    dt: f64,
    integrator: TimeScheme,
    settings: NewtonSettings,
    length_scale: f64,
    inertia: Inertia,
    potentials: Vec<Box<dyn StencilEnergy>>,
    fixed_vertices: Vec<usize>,
    free_index: Vec<usize>,
    num_free: usize,
    hessian: HessianPattern,
    /// Free-dof couplings beyond the energy terms' stencils (from self-contact pairs).
    extra_couplings: Vec<[u32; 2]>,
    contact: Option<Contact>,
    /// The adaptive model that gives each Newton direction, if attached.
    adaptive: Option<crate::adaptive::solver::AdaptiveSolver>,
    /// The adaptive model as attached, which [`Simulator::start_over`] goes back to.
    adaptive_initial: Option<Box<crate::adaptive::solver::AdaptiveSolver>>,
    /// Vertex Block Descent, which steps instead of Newton, if attached.
    vbd: Option<crate::vbd::VertexBlockDescent>,
    x: Vec<f64>,
    v: Vec<f64>,
    x_prev: Vec<f64>,
    v_prev: Vec<f64>,
    steps: usize,
}

/// What a [`Simulator`] is built from.
pub struct SimulatorConfig {
    /// Spatial dimension (2 or 3).
    pub dim: usize,
    /// Initial positions (`dim` per vertex); the body starts at rest there.
    pub x0: Vec<f64>,
    /// Lumped vertex masses; the inertia term is built from them.
    pub masses: Vec<f64>,
    /// Conservative terms (elastic, gravity, loads, collision).
    pub potentials: Vec<Box<dyn StencilEnergy>>,
    /// Vertices that follow the targets passed to [`Simulator::step`].
    pub fixed_vertices: Vec<usize>,
    /// Time step in seconds.
    pub dt: f64,
    /// Implicit Euler or BDF2.
    pub scheme: TimeScheme,
    /// Newton's tolerance, iteration cap and Hessian choice.
    pub settings: NewtonSettings,
    /// Length that makes the convergence tolerance unit-free (the rest bounding-box
    /// diagonal).
    pub length_scale: f64,
    /// IPC contact (barrier, friction, CCD-filtered line search), if any.
    pub contact: Option<ContactConfig>,
}

impl Simulator {
    /// Builds a simulator starting at rest at `config.x0`.
    pub fn new(config: SimulatorConfig) -> Self {
        let SimulatorConfig {
            dim,
            x0,
            masses,
            potentials,
            fixed_vertices,
            dt,
            scheme: integrator,
            settings,
            length_scale,
            contact,
        } = config;
        let n = x0.len();
        let (free_index, num_free) = free_dof_index(dim, n, &fixed_vertices);
        let contact = contact.map(|c| Contact::new(c, &x0, &masses));
        let inertia = Inertia::new(dim, masses);
        let terms: Vec<&dyn StencilEnergy> = std::iter::once(&inertia as &dyn StencilEnergy)
            .chain(potentials.iter().map(|p| p.as_ref()))
            .collect();
        let hessian = HessianPattern::new(&terms, &free_index, num_free, &[]);
        Simulator {
            dim,
            dt,
            integrator,
            settings,
            length_scale,
            inertia,
            potentials,
            fixed_vertices,
            free_index,
            num_free,
            hessian,
            extra_couplings: Vec::new(),
            contact,
            adaptive: None,
            adaptive_initial: None,
            vbd: None,
            v: vec![0.0; n],
            x_prev: x0.clone(),
            v_prev: vec![0.0; n],
            x: x0,
            steps: 0,
        }
    }

    /// Current positions.
    pub fn positions(&self) -> &[f64] {
        &self.x
    }
    /// Current velocities.
    pub fn velocities(&self) -> &[f64] {
        &self.v
    }
    /// Vertices whose positions are prescribed, in the order targets are given.
    pub fn fixed_vertices(&self) -> &[usize] {
        &self.fixed_vertices
    }
    /// Number of free degrees of freedom.
    pub fn num_free_dofs(&self) -> usize {
        self.num_free
    }
    /// Time step.
    pub fn dt(&self) -> f64 {
        self.dt
    }
    /// Lumped vertex masses.
    pub fn masses(&self) -> &[f64] {
        self.inertia.masses()
    }
    /// The conservative energy terms.
    pub fn potentials(&self) -> &[Box<dyn StencilEnergy>] {
        &self.potentials
    }
    /// Mutable access to the conservative terms (e.g. to move obstacles).
    pub fn potentials_mut(&mut self) -> &mut [Box<dyn StencilEnergy>] {
        &mut self.potentials
    }

    /// The contact surface (body vertices first, then the obstacles') and its positions at
    /// the current state, if the simulator has contact.
    pub fn contact_state(&self) -> Option<(&crate::contact::ContactSurface, Vec<f64>)> {
        self.contact.as_ref().map(|c| (c.surface(), c.extended(&self.x)))
    }

    /// The contact obstacle meshes' triangles over the obstacle vertices, if there are any.
    pub fn obstacle_faces(&self) -> Option<Vec<[u32; 3]>> {
        self.obstacle_positions()?;
        let c = self.contact.as_ref()?;
        let first = (c.body_len() / self.dim) as u32;
        let faces = c
            .surface()
            .faces
            .iter()
            .filter(|f| f.iter().all(|&v| v as u32 >= first))
            .map(|f| f.map(|v| v as u32 - first))
            .collect();
        Some(faces)
    }

    /// The obstacle vertices' current positions (scripted obstacles move), if there are any.
    pub fn obstacle_positions(&self) -> Option<&[f64]> {
        let positions = self.contact.as_ref()?.obstacle_positions();
        (!positions.is_empty()).then_some(positions)
    }

    /// The current barrier stiffness (0 without contact or before the first solve).
    pub fn contact_stiffness(&self) -> f64 {
        self.contact.as_ref().map_or(0.0, Contact::kappa)
    }

    /// Forgets what the solver carried over from earlier steps: the contact barrier's
    /// stiffness and closest distance, and the adaptive model's active blocks, enrichment
    /// and BFGS matrices (back to how it was attached). A motion started after this is the
    /// same bits as in a freshly built simulator, whatever ran before it (a dataset's
    /// sequences are then independent of their order and of the process making them).
    pub fn start_over(&mut self) {
        if let Some(c) = &mut self.contact {
            c.start_over();
        }
        if let Some(initial) = &self.adaptive_initial {
            self.adaptive = Some(initial.as_ref().clone());
        }
    }

    /// Resets the state to positions `x` at rest.
    pub fn reset(&mut self, x: &[f64]) {
        self.restart(x, x);
    }

    /// Restarts mid-motion: positions `x`, with the velocity of one implicit-Euler step
    /// from `x_prev` (`(x - x_prev) / dt`). The next step is an implicit-Euler step also
    /// under BDF2, as after [`Simulator::reset`]. Both slices hold every vertex.
    pub fn restart(&mut self, x: &[f64], x_prev: &[f64]) {
        self.x.copy_from_slice(x);
        self.x_prev.copy_from_slice(x_prev);
        for k in 0..self.v.len() {
            self.v[k] = (x[k] - x_prev[k]) / self.dt;
        }
        self.v_prev.copy_from_slice(&self.v);
        self.steps = 0;
        if let Some(c) = &mut self.contact {
            c.place_obstacles_at(0.0);
        }
    }

    /// Kinetic energy and the value of each potential at the current state.
    pub fn energies(&self) -> Vec<(&'static str, f64)> {
        let mut out = vec![("kinetic", self.inertia.kinetic_energy(&self.v))];
        out.extend(
            self.potentials
                .iter()
                .map(|p| (p.name(), energy::value(p.as_ref(), &self.x))),
        );
        if let Some(c) = &self.contact {
            out.push(("contact barrier", c.barrier_value(&self.x)));
        }
        out
    }

    /// Total mechanical energy (kinetic plus all potentials) at the current state.
    pub fn total_energy(&self) -> f64 {
        self.energies().iter().map(|(_, e)| e).sum()
    }

    /// Advances one time step with the prescribed vertices moved to `targets`
    /// (`dim` numbers per vertex of [`Simulator::fixed_vertices`]).
    pub fn step(&mut self, targets: &[f64]) -> Result<StepReport, StepError> {
        check_targets(&self.fixed_vertices, self.dim, targets)?;
        if self.vbd.is_some() {
            return self.step_vbd(targets, None);
        }
        if self.integrator == TimeScheme::QuasiStatic {
            return self.step_quasi_static(targets);
        }
        let start = Instant::now();
        let h = self.dt;
        let bdf2 = self.integrator == TimeScheme::Bdf2 && self.steps > 0;
        // Predicted positions and the weight of the potentials in the incremental potential.
        let (xhat, weight): (Vec<f64>, f64) = if bdf2 {
            let xhat = (0..self.x.len())
                .map(|k| (4.0 * self.x[k] - self.x_prev[k]) / 3.0 + h * (8.0 * self.v[k] - 2.0 * self.v_prev[k]) / 9.0)
                .collect();
            (xhat, 4.0 / 9.0 * h * h)
        } else {
            ((0..self.x.len()).map(|k| self.x[k] + h * self.v[k]).collect(), h * h)
        };
        self.inertia.set_target(&xhat);
        // With contact, Newton starts from the last positions (intersection-free, which the
        // prediction need not be), as IPC does; CCD then keeps every iterate so.
        // The adaptive model starts there too (its Algorithm 1): its modal step is then the
        // step's whole motion, which downdating measures.
        let mut x = if self.contact.is_some() || self.adaptive.is_some() {
            self.x.clone()
        } else {
            xhat
        };
        place_fixed(&self.fixed_vertices, self.dim, &mut x, targets);
        // Moving obstacles reach where their scripts put them at the end of the step
        // during the solve, CCD-bounded like the body (see `minimize`).
        let end_time = (self.steps + 1) as f64 * h;
        if let Some(c) = &mut self.contact {
            c.set_obstacle_goal(end_time);
        }
        let x_start = x.clone();
        if let Some(a) = &mut self.adaptive {
            a.begin_step();
        }
        let frame = self.steps + 1;
        let mut report = self.minimize(&mut x, 1.0, weight, h * self.length_scale, Some(h), frame)?;
        report.adaptive = self.adaptive.as_mut().map(|a| a.end_step(&x_start, &x, h));
        let v_new: Vec<f64> = if bdf2 {
            (0..x.len())
                .map(|k| (3.0 * x[k] - 4.0 * self.x[k] + self.x_prev[k]) / (2.0 * h))
                .collect()
        } else {
            (0..x.len()).map(|k| (x[k] - self.x[k]) / h).collect()
        };
        self.x_prev = std::mem::replace(&mut self.x, x);
        self.v_prev = std::mem::replace(&mut self.v, v_new);
        self.steps += 1;
        report.seconds = start.elapsed().as_secs_f64();
        Ok(report)
    }

    /// Finds a static equilibrium of the potentials (no inertia) with the prescribed
    /// vertices at `targets`, starting from the current positions; velocities are zeroed.
    pub fn solve_static(&mut self, targets: &[f64]) -> Result<StepReport, StepError> {
        check_targets(&self.fixed_vertices, self.dim, targets)?;
        let start = Instant::now();
        let mut x = self.x.clone();
        place_fixed(&self.fixed_vertices, self.dim, &mut x, targets);
        let mut report = self.minimize(&mut x, 0.0, 1.0, self.length_scale, None, 0)?;
        self.reset(&x);
        report.seconds = start.elapsed().as_secs_f64();
        Ok(report)
    }

    fn step_quasi_static(&mut self, targets: &[f64]) -> Result<StepReport, StepError> {
        let start = Instant::now();
        let mut x = self.x.clone();
        place_fixed(&self.fixed_vertices, self.dim, &mut x, targets);
        let end_time = (self.steps + 1) as f64 * self.dt;
        if let Some(c) = &mut self.contact {
            c.set_obstacle_goal(end_time);
        }
        let dt = self.dt;
        let x_start = x.clone();
        if let Some(a) = &mut self.adaptive {
            a.begin_step();
        }
        let frame = self.steps + 1;
        let mut report = self.minimize(&mut x, 0.0, 1.0, self.length_scale, Some(dt), frame)?;
        report.adaptive = self.adaptive.as_mut().map(|a| a.end_step(&x_start, &x, dt));
        let v_new: Vec<f64> = x.iter().zip(&self.x).map(|(a, b)| (a - b) / self.dt).collect();
        self.x_prev = std::mem::replace(&mut self.x, x);
        self.v_prev = std::mem::replace(&mut self.v, v_new);
        self.steps += 1;
        report.seconds = start.elapsed().as_secs_f64();
        Ok(report)
    }

    /// The time integration scheme.
    pub fn scheme(&self) -> TimeScheme {
        self.integrator
    }

    /// Objective `w_inertia * inertia + w_potential * sum(potentials)`, plus contact's
    /// `kappa B + D` when there is contact, and its gradient.
    fn objective(&self, x: &[f64], w_inertia: f64, w_potential: f64, grad: Option<&mut Vec<f64>>) -> f64 {
        let Some(contact) = &self.contact else {
            return self.objective_without_contact(x, w_inertia, w_potential, grad);
        };
        match grad {
            None => self.objective_without_contact(x, w_inertia, w_potential, None) + contact.value(x),
            Some(g) => {
                let e = self.objective_without_contact(x, w_inertia, w_potential, Some(&mut *g));
                e + contact.add_gradient(x, g)
            }
        }
    }

    /// The objective's inertia and potential terms and their gradient.
    fn objective_without_contact(
        &self,
        x: &[f64],
        w_inertia: f64,
        w_potential: f64,
        grad: Option<&mut Vec<f64>>,
    ) -> f64 {
        incremental_potential(&self.inertia, &self.potentials, w_inertia, w_potential, x, grad)
    }

    /// Newton with backtracking line search over the free DOF of `x`, for the step to
    /// `frame` (0: the initial static equilibrium), which errors name. A NaN or infinite
    /// objective, gradient or Hessian stops it with [`StepError::NonFinite`].
    fn minimize(
        &mut self,
        x: &mut [f64],
        w_inertia: f64,
        w_potential: f64,
        norm_scale: f64,
        friction_dt: Option<f64>,
        frame: usize,
    ) -> Result<StepReport, StepError> {
        let mut report = StepReport::default();
        let mut grad = Vec::new();
        let mut rhs = vec![0.0; self.num_free];
        let mut trial = x.to_vec();
        if self.contact.is_some() {
            self.objective_without_contact(x, w_inertia, w_potential, Some(&mut grad));
            let free: Vec<bool> = self.free_index.iter().map(|&f| f != NOT_FREE).collect();
            if let Some(c) = &mut self.contact {
                c.begin_solve(x, &grad, &free, friction_dt);
            }
        }
        for iteration in 0..self.settings.max_iterations {
            let e = self.objective(x, w_inertia, w_potential, Some(&mut grad));
            let non_finite = |quantity| StepError::NonFinite {
                frame,
                iteration,
                quantity,
            };
            if !e.is_finite() {
                return Err(non_finite(Quantity::Energy));
            }
            if grad.iter().any(|g| !g.is_finite()) {
                return Err(non_finite(Quantity::Gradient));
            }
            report.objective = e;
            if self.num_free == 0 {
                report.converged = true;
                break;
            }
            // Moving obstacles' and colliders' remaining step `d_o` is part of this
            // iteration's step; the body's Newton direction then answers
            // `H_ff d_f = -g_f - H_fo d_o`.
            let moving = self.contact.as_ref().and_then(Contact::kinematic_start);
            let mut push = Vec::new();
            if let (Some(c), Some(_)) = (&self.contact, &moving) {
                push = vec![0.0; x.len()];
                c.add_kinematic_coupling(x, &mut push);
            }
            for (k, &f) in self.free_index.iter().enumerate() {
                if f != NOT_FREE {
                    rhs[f] = -grad[k] - push.get(k).copied().unwrap_or(0.0);
                }
            }
            let at = (frame, iteration);
            self.newton_direction(x, &grad, &mut rhs, (w_inertia, w_potential), at, &mut report)?;
            let dir = &rhs;
            let step_norm = dir.iter().fold(0.0f64, |m, d| m.max(d.abs())) / norm_scale;
            if !step_norm.is_finite() {
                return Err(StepError::Diverged { frame, iteration });
            }
            report.step_norms.push(step_norm);
            report.iterations = iteration + 1;
            // Backtracking line search on the objective (Armijo condition).
            let slope: f64 = self
                .free_index
                .iter()
                .enumerate()
                .filter(|(_, &f)| f != NOT_FREE)
                .map(|(k, &f)| grad[k] * dir[f])
                .sum();
            // At the round-off floor the predicted decrease is below what the objective can
            // resolve: the iterate cannot get better, so stop there.
            if -slope <= 1e-14 * e.abs() && moving.is_none() {
                report.converged = true;
                break;
            }
            // With contact, the step starts at the largest collision-free fraction (CCD), so
            // no iterate the line search tries intersects.
            let mut alpha = 1.0;
            if let Some(contact) = &mut self.contact {
                for (k, &f) in self.free_index.iter().enumerate() {
                    trial[k] = if f != NOT_FREE { x[k] + dir[f] } else { x[k] };
                }
                alpha = contact.line_search_bound(x, &trial);
            }
            // While obstacles or colliders move, the objective is not the one being minimised
            // yet (it changes with them): any collision-free step with a finite objective is
            // taken.
            while alpha > 0.0 {
                for (k, &f) in self.free_index.iter().enumerate() {
                    if f != NOT_FREE {
                        trial[k] = x[k] + alpha * dir[f];
                    }
                }
                if let (Some(c), Some(from)) = (&mut self.contact, &moving) {
                    c.move_kinematic(from, alpha);
                }
                let et = self.objective(&trial, w_inertia, w_potential, None);
                let accept = if moving.is_some() {
                    et.is_finite()
                } else {
                    et.is_finite() && et <= e + 1e-4 * alpha * slope.min(0.0)
                };
                if accept {
                    break;
                }
                alpha *= 0.5;
                if alpha < 1e-12 {
                    alpha = 0.0;
                    break;
                }
            }
            for (k, &f) in self.free_index.iter().enumerate() {
                if f != NOT_FREE {
                    x[k] += alpha * dir[f];
                }
            }
            if let Some(a) = &mut self.adaptive {
                a.accept(alpha);
            }
            if let Some(c) = &mut self.contact {
                if let Some(from) = &moving {
                    c.move_kinematic(from, alpha);
                }
                c.end_iteration(x);
            }
            let obstacles_moving = self.contact.as_ref().is_some_and(Contact::kinematic_pending);
            if (step_norm < self.settings.tolerance && !obstacles_moving) || alpha == 0.0 {
                report.converged = step_norm < self.settings.tolerance && !obstacles_moving;
                report.objective = self.objective(x, w_inertia, w_potential, None);
                break;
            }
        }
        if x.iter().any(|c| !c.is_finite()) {
            return Err(StepError::Diverged {
                frame,
                iteration: report.iterations,
            });
        }
        if let Some(c) = &self.contact {
            report.contact_pairs = c.pairs();
            (report.phases.broad_phase, report.phases.ccd) = c.phase_seconds();
        }
        Ok(report)
    }

    /// Assembles the free-free Hessian of the objective, optionally with every stencil
    /// Hessian projected to PSD. Contact stencils that couple free dofs the pattern lacks
    /// (self-contact) grow the pattern, which is then assembled anew.
    fn assemble(&mut self, x: &[f64], w_inertia: f64, w_potential: f64, project: bool) {
        self.assemble_terms(x, w_inertia, w_potential, project);
        let Some(contact) = &self.contact else {
            return;
        };
        let (dim, body_len) = (self.dim, contact.body_len());
        let free_index = &self.free_index;
        let hessian = &mut self.hessian;
        let mut missing = Vec::new();
        let mut dofs = [NOT_FREE; energy::MAX_DOF];
        contact.for_each_hessian(x, project, |verts, local, weight| {
            let n = verts.len() * dim;
            for (a, &v) in verts.iter().enumerate() {
                for i in 0..dim {
                    let k = v * dim + i;
                    dofs[a * dim + i] = if k < body_len { free_index[k] } else { NOT_FREE };
                }
            }
            for r in 0..n {
                for c in 0..n {
                    let (fr, fc) = (dofs[r], dofs[c]);
                    if fr == NOT_FREE || fc == NOT_FREE || fr < fc {
                        continue;
                    }
                    match hessian.slot(fr, fc) {
                        Some(slot) => hessian.values[slot] += weight * local.hess[r * n + c],
                        None => missing.push([fr as u32, fc as u32]),
                    }
                }
            }
        });
        if !missing.is_empty() {
            self.extra_couplings.extend(missing);
            self.extra_couplings.sort_unstable();
            self.extra_couplings.dedup();
            let terms: Vec<&dyn StencilEnergy> = std::iter::once(&self.inertia as &dyn StencilEnergy)
                .chain(self.potentials.iter().map(|p| p.as_ref()))
                .collect();
            self.hessian = HessianPattern::new(&terms, &self.free_index, self.num_free, &self.extra_couplings);
            self.assemble(x, w_inertia, w_potential, project);
        }
    }

    /// Assembles the energy terms' share of the free-free Hessian.
    fn assemble_terms(&mut self, x: &[f64], w_inertia: f64, w_potential: f64, project: bool) {
        // With the adaptive model's per-subdomain BFGS, the elastic terms (the first
        // potentials) only over the subdomains it evaluates exactly.
        let exact: Vec<Vec<usize>> = match self.adaptive.as_mut().and_then(|a| a.elastic_subspace_mut()) {
            Some(e) => {
                e.take_newly_exact();
                (0..e.num_terms()).map(|t| e.exact_stencils(t)).collect()
            }
            None => Vec::new(),
        };
        let terms = std::iter::once((&self.inertia as &dyn StencilEnergy, w_inertia, None)).chain(
            self.potentials
                .iter()
                .enumerate()
                .map(|(i, p)| (p.as_ref(), w_potential, exact.get(i).map(Vec::as_slice))),
        );
        self.hessian.assemble_stencils(terms, x, project);
    }
}
