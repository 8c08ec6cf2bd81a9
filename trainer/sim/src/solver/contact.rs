//! IPC contact in the incremental potential (`docs/design.md`, decision 8): the barrier
//! `kappa B(x)` and lagged friction `D(x)` over the contact surface of the body and of
//! obstacle meshes, the barrier between the body's surface vertices and analytic colliders
//! (`colliders`), the adaptive stiffness `kappa`, and the collision-free bound on every
//! line-search step.
//!
//! The body's positions `x` and the obstacles' fixed positions are stacked into one
//! *extended* vector (obstacle vertices numbered after the body's), over which the contact
//! surface, the broad phase, CCD and the contact energies work; only the body's part of a
//! gradient or Hessian reaches the solver. Obstacle vertices are never free.
//!
//! Contact stencils change with the positions, unlike the element stencils the solver's
//! sparse pattern is built from, so contact has its own assembly path: its energies are
//! [`StencilEnergy`]s whose stencil lists are rebuilt from the broad phase (once at the
//! start of a solve, then for every Newton step from the boxes swept over that step, which
//! hold every pair within `dhat` anywhere along it), and their local Hessians are added
//! through the pattern's slot lookup. Pairs between the body and an obstacle only couple
//! vertices of one element, which the pattern already holds; self-contact pairs may couple
//! vertices no element joins, and the pattern then grows (see `Simulator::assemble`).
//!
//! As in IPC, the barrier enters the incremental potential unscaled by `h^2`
//! (`E = 1/2 |x - xhat|_M^2 + h^2 Psi + kappa B + D`), which is what the adaptive stiffness
//! of [`crate::contact::stiffness`] balances. Its initial value is computed at the start of
//! every solve and never lowered below the value reached before; after every Newton step it
//! doubles when the smallest distance keeps shrinking while tiny.

use crate::contact::barrier_potential::BarrierPotential;
use crate::contact::broad_phase::Candidates;
use crate::contact::ccd::{max_step_over, AdditiveCcd};
use crate::contact::friction_potential::FrictionPotential;
use crate::contact::stiffness::{
    initial_barrier_stiffness, update_barrier_stiffness, MIN_STIFFNESS_SCALE, UPDATE_DISTANCE_FRACTION,
};
use crate::contact::{Collider, ColliderPose, ContactSurface};
use crate::energy::{self, Local, StencilEnergy};
use colliders::MovingColliders;
use serde::{Deserialize, Serialize};
use std::time::Instant;

mod colliders;
mod obstacles;
pub use obstacles::ContactObstacle;
use obstacles::ObstacleScript;

/// Contact parameters (the scene's `[contact]` table).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ContactSettings {
    /// Barrier activation distance `dhat` (m): the barrier acts on pairs closer than this.
    pub dhat: f64,
    /// Coulomb friction coefficient `mu` (0: frictionless).
    pub friction: f64,
    /// Friction's smoothing velocity `eps_v` (m/s): below it, sticking is a stiff spring.
    pub epsv: f64,
    /// Whether the body's surface also contacts itself.
    #[serde(rename = "self")]
    pub self_contact: bool,
}

impl Default for ContactSettings {
    fn default() -> Self {
        ContactSettings {
            dhat: 1e-3,
            friction: 0.0,
            epsv: 1e-3,
            self_contact: false,
        }
    }
}

impl ContactSettings {
    /// Checks the ranges; the error names the field.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if !(self.dhat.is_finite() && self.dhat > 0.0) {
            return Err(("dhat", format!("must be positive and finite, got {}", self.dhat)));
        }
        if !(self.friction.is_finite() && self.friction >= 0.0) {
            return Err((
                "friction",
                format!("must be non-negative and finite, got {}", self.friction),
            ));
        }
        if !(self.epsv.is_finite() && self.epsv > 0.0) {
            return Err(("epsv", format!("must be positive and finite, got {}", self.epsv)));
        }
        Ok(())
    }
}

/// What contact is built from.
#[derive(Clone, Debug, PartialEq)]
pub struct ContactConfig {
    /// Parameters.
    pub settings: ContactSettings,
    /// The body's contact surface.
    pub surface: ContactSurface,
    /// Obstacle meshes, static or moved by a script.
    pub obstacles: Vec<ContactObstacle>,
    /// Analytic kinematic colliders at their initial poses (3D bodies), moved by
    /// [`super::Simulator::set_collider_poses`].
    pub colliders: Vec<Collider>,
}

/// What contact carries from one solve to the next (see [`Contact::carried`]).
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Carried {
    obstacles: Vec<f64>,
    kappa: f64,
    prev_min_d2: f64,
    colliders: Vec<ColliderPose>,
}

/// Where the moving obstacles and colliders were when an iteration began, for the line
/// search to move them from.
pub(super) struct KinematicStart {
    obstacles: Option<Vec<f64>>,
    colliders: Option<Vec<ColliderPose>>,
}

/// Contact state of a [`super::Simulator`].
pub(super) struct Contact {
    settings: ContactSettings,
    dim: usize,
    body_len: usize,
    /// The obstacles' current positions (after their motion so far).
    obstacle_positions: Vec<f64>,
    /// The obstacles before any motion, and their scripts (empty if none moves).
    obstacle_rest: Vec<f64>,
    obstacle_scripts: Vec<ObstacleScript>,
    /// Where moving obstacles must be at the end of the current solve, when they are not yet.
    obstacle_goal: Option<Vec<f64>>,
    barrier: BarrierPotential,
    /// The colliders' barrier and their goal.
    colliders: MovingColliders,
    friction: Option<FrictionPotential>,
    kappa: f64,
    prev_min_d2: f64,
    ccd: AdditiveCcd,
    average_mass: f64,
    bbox_diagonal: f64,
    /// Seconds in the broad phase and in CCD since the solve began.
    broad_phase_seconds: f64,
    ccd_seconds: f64,
}

impl Contact {
    /// Contact for a body at rest positions `rest` with lumped `masses`.
    pub(super) fn new(config: ContactConfig, rest: &[f64], masses: &[f64]) -> Self {
        let ContactConfig {
            settings,
            mut surface,
            obstacles,
            colliders,
        } = config;
        let dim = surface.dim;
        let colliders = MovingColliders::new(surface.vertices.clone(), colliders, settings.dhat);
        let body_len = rest.len();
        let mut obstacle_positions = Vec::new();
        let mut obstacle_scripts = Vec::new();
        for o in &obstacles {
            surface.append(&o.surface, (body_len + obstacle_positions.len()) / dim);
            if !o.keyframes.is_empty() {
                let start = obstacle_positions.len();
                obstacle_scripts.push(ObstacleScript {
                    range: start..start + o.positions.len(),
                    obstacle: o.clone(),
                });
            }
            obstacle_positions.extend_from_slice(&o.positions);
        }
        let obstacle_rest = obstacle_positions.clone();
        let mut placed = obstacle_positions.clone();
        for script in &obstacle_scripts {
            script.place(&obstacle_rest, 0.0, &mut placed);
        }
        let obstacle_positions = placed;
        let ext: Vec<f64> = rest.iter().chain(&obstacle_positions).copied().collect();
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for p in ext.chunks(dim) {
            for i in 0..dim {
                lo[i] = lo[i].min(p[i]);
                hi[i] = hi[i].max(p[i]);
            }
        }
        let bbox_diagonal = (0..dim).map(|i| (hi[i] - lo[i]).powi(2)).sum::<f64>().sqrt();
        let average_mass = masses.iter().sum::<f64>() / masses.len().max(1) as f64;
        Contact {
            settings,
            dim,
            body_len,
            obstacle_positions,
            obstacle_rest,
            obstacle_scripts,
            obstacle_goal: None,
            barrier: BarrierPotential::new(surface, ext, settings.dhat),
            colliders,
            friction: None,
            kappa: 0.0,
            prev_min_d2: f64::INFINITY,
            ccd: AdditiveCcd::default(),
            average_mass,
            bbox_diagonal,
            broad_phase_seconds: 0.0,
            ccd_seconds: 0.0,
        }
    }

    /// What carries from one solve to the next: obstacle positions, barrier stiffness, the
    /// last minimum squared distance and the colliders' poses.
    pub(super) fn carried(&self) -> Carried {
        Carried {
            obstacles: self.obstacle_positions.clone(),
            kappa: self.kappa,
            prev_min_d2: self.prev_min_d2,
            colliders: self.colliders.barrier.poses(),
        }
    }

    /// A lower bound of the distance between any two contact primitives at the last
    /// iterate: the smallest distance of the pairs within `dhat`, or `dhat` when none is.
    pub(super) fn min_distance(&self) -> f64 {
        self.prev_min_d2.sqrt().min(self.settings.dhat)
    }

    /// Restores what [`Contact::carried`] returned.
    pub(super) fn restore(&mut self, carried: Carried) {
        if carried.obstacles.len() == self.obstacle_positions.len() {
            self.obstacle_positions = carried.obstacles;
        }
        if carried.colliders.len() == self.num_colliders() {
            self.place_colliders(&carried.colliders);
        }
        self.kappa = carried.kappa;
        self.prev_min_d2 = carried.prev_min_d2;
    }

    /// Asks the moving obstacles to be where their scripts put them at `time` by the end of
    /// the next solve; false when none has to move.
    pub(super) fn set_obstacle_goal(&mut self, time: f64) -> bool {
        let mut goal = self.obstacle_positions.clone();
        for script in &self.obstacle_scripts {
            script.place(&self.obstacle_rest, time, &mut goal);
        }
        let moves = goal != self.obstacle_positions;
        self.obstacle_goal = moves.then_some(goal);
        moves
    }

    /// What is left of the moving obstacles' motion in this solve (`None` once they are
    /// where they must be).
    pub(super) fn obstacle_step(&self) -> Option<Vec<f64>> {
        let goal = self.obstacle_goal.as_ref()?;
        Some(goal.iter().zip(&self.obstacle_positions).map(|(g, p)| g - p).collect())
    }

    /// Places the moving obstacles `alpha` of the way from `from` to their goal; at
    /// `alpha = 1` they are at the goal exactly, which is then reached.
    pub(super) fn move_obstacles(&mut self, from: &[f64], alpha: f64) {
        let Some(goal) = &self.obstacle_goal else { return };
        if alpha >= 1.0 {
            self.obstacle_positions.copy_from_slice(goal);
        } else {
            for ((p, f), g) in self.obstacle_positions.iter_mut().zip(from).zip(goal) {
                *p = f + alpha * (g - f);
            }
        }
    }

    /// Marks the goal reached when the obstacles are there.
    pub(super) fn settle_obstacles(&mut self) {
        if self.obstacle_goal.as_ref() == Some(&self.obstacle_positions) {
            self.obstacle_goal = None;
        }
    }

    /// Where the moving obstacles and colliders are now, when any has yet to reach its goal
    /// in this solve (`None` when nothing moves).
    pub(super) fn kinematic_start(&self) -> Option<KinematicStart> {
        let obstacles = self.obstacle_goal.as_ref().map(|_| self.obstacle_positions.clone());
        let colliders = self.colliders.goal.as_ref().map(|_| self.colliders.barrier.poses());
        (obstacles.is_some() || colliders.is_some()).then_some(KinematicStart { obstacles, colliders })
    }

    /// Moves the moving obstacles and colliders `alpha` of the way from `from` to their
    /// goals; at `alpha = 1` they are there, which is then reached.
    pub(super) fn move_kinematic(&mut self, from: &KinematicStart, alpha: f64) {
        if let Some(o) = &from.obstacles {
            self.move_obstacles(o, alpha);
            self.settle_obstacles();
        }
        if let Some(c) = &from.colliders {
            self.move_colliders(c, alpha);
        }
    }

    /// Whether an obstacle or a collider has yet to reach its goal in this solve.
    pub(super) fn kinematic_pending(&self) -> bool {
        self.obstacle_goal.is_some() || self.colliders.goal.is_some()
    }

    /// Adds into `out` (body-length) how the contact Hessian couples the body to what is
    /// left of the obstacles' and colliders' motion (their linearised push).
    pub(super) fn add_kinematic_coupling(&self, x: &[f64], out: &mut [f64]) {
        if let Some(d_o) = self.obstacle_step() {
            self.add_obstacle_coupling(x, &d_o, out);
        }
        self.add_collider_coupling(x, out);
    }

    /// Places the obstacles where their scripts put them at `time`, at once (no solve).
    /// Back to the state before the first solve: obstacles at their start, the barrier
    /// stiffness to be chosen anew, no closest distance known.
    pub(super) fn start_over(&mut self) {
        self.place_obstacles_at(0.0);
        self.kappa = 0.0;
        self.prev_min_d2 = f64::INFINITY;
    }

    pub(super) fn place_obstacles_at(&mut self, time: f64) {
        for script in &self.obstacle_scripts {
            script.place(&self.obstacle_rest, time, &mut self.obstacle_positions);
        }
        self.obstacle_goal = None;
    }

    /// The body's part of `H_bo d_o`: how the contact Hessian couples the body to the
    /// obstacles' step `d_o` (the linearised push of a moving obstacle), added into `out`
    /// (a body-length vector).
    pub(super) fn add_obstacle_coupling(&self, x: &[f64], d_o: &[f64], out: &mut [f64]) {
        let (dim, body) = (self.dim, self.body_len / self.dim);
        self.for_each_hessian(x, true, |verts, local, weight| {
            let n = verts.len() * dim;
            for (a, &va) in verts.iter().enumerate().filter(|(_, &v)| v < body) {
                for (b, &vb) in verts.iter().enumerate().filter(|(_, &v)| v >= body) {
                    let o = (vb - body) * dim;
                    for i in 0..dim {
                        let row = &local.hess[(a * dim + i) * n + b * dim..][..dim];
                        out[va * dim + i] += weight * row.iter().zip(&d_o[o..o + dim]).map(|(h, d)| h * d).sum::<f64>();
                    }
                }
            }
        });
    }

    /// The obstacles' current positions.
    pub(super) fn obstacle_positions(&self) -> &[f64] {
        &self.obstacle_positions
    }

    /// Seconds spent in the broad phase and in CCD since the current solve began.
    pub(super) fn phase_seconds(&self) -> (f64, f64) {
        (self.broad_phase_seconds, self.ccd_seconds)
    }

    /// The contact surface over the extended vertices.
    pub(super) fn surface(&self) -> &ContactSurface {
        self.barrier.surface()
    }

    /// The current barrier stiffness.
    pub(super) fn kappa(&self) -> f64 {
        self.kappa
    }

    /// Number of barrier stencils loaded (candidate pairs).
    pub(super) fn pairs(&self) -> usize {
        self.barrier.len()
    }

    /// The body positions `x` followed by the obstacles'.
    pub(super) fn extended(&self, x: &[f64]) -> Vec<f64> {
        let mut ext = Vec::with_capacity(x.len() + self.obstacle_positions.len());
        ext.extend_from_slice(x);
        ext.extend_from_slice(&self.obstacle_positions);
        ext
    }

    /// Leaves out pairs between obstacles, and pairs within the body unless self-contact is on.
    fn filtered(&self, mut c: Candidates) -> Candidates {
        let nb = self.body_len / self.dim;
        let s = self.surface();
        let keep = |verts: &mut dyn Iterator<Item = usize>| {
            let (mut body, mut obstacle) = (false, false);
            for v in verts {
                if v < nb {
                    body = true;
                } else {
                    obstacle = true;
                }
            }
            body && (obstacle || self.settings.self_contact)
        };
        c.point_triangle
            .retain(|&[v, f]| keep(&mut std::iter::once(v).chain(s.faces[f])));
        c.edge_edge
            .retain(|&[i, j]| keep(&mut s.edges[i].into_iter().chain(s.edges[j])));
        c.point_edge
            .retain(|&[v, e]| keep(&mut std::iter::once(v).chain(s.edges[e])));
        c
    }

    /// Loads the pairs within `dhat` of positions `x`.
    fn load_pairs_at(&mut self, x: &[f64]) {
        let ext = self.extended(x);
        let clock = Instant::now();
        let c = self.filtered(Candidates::within(self.surface(), &ext, self.settings.dhat));
        self.broad_phase_seconds += clock.elapsed().as_secs_f64();
        self.barrier.set_candidates(&c);
    }

    /// Starts a solve from positions `x`: loads the pairs there, raises the stiffness to
    /// IPC's initial value for the gradient `rest_gradient` of the rest of the objective
    /// (both gradients taken over the dofs where `free` holds), and lags friction at `x`
    /// when `friction_dt` (the time step) is given.
    pub(super) fn begin_solve(&mut self, x: &[f64], rest_gradient: &[f64], free: &[bool], friction_dt: Option<f64>) {
        (self.broad_phase_seconds, self.ccd_seconds) = (0.0, 0.0);
        self.load_pairs_at(x);
        let ext = self.extended(x);
        let mut gb = vec![0.0; ext.len()];
        energy::add_gradient(&self.barrier, 1.0, &ext, &mut gb);
        energy::add_gradient(&self.colliders.barrier, 1.0, &ext, &mut gb);
        gb.truncate(self.body_len);
        let mut ge = rest_gradient.to_vec();
        for (k, &f) in free.iter().enumerate() {
            if !f {
                gb[k] = 0.0;
                ge[k] = 0.0;
            }
        }
        let init = initial_barrier_stiffness(
            self.bbox_diagonal,
            self.settings.dhat,
            self.average_mass,
            &ge,
            &gb,
            MIN_STIFFNESS_SCALE,
        );
        self.kappa = self.kappa.max(init.kappa).min(init.max);
        self.prev_min_d2 = self
            .barrier
            .min_squared_distance(&ext)
            .min(self.collider_min_squared_distance(x));
        let mu = self.settings.friction;
        self.lag_collider_friction(
            x,
            friction_dt.filter(|_| mu > 0.0).map(|dt| (mu, self.settings.epsv * dt)),
        );
        self.friction = friction_dt.filter(|_| self.settings.friction > 0.0).map(|dt| {
            FrictionPotential::lagged(
                &self.barrier,
                &ext,
                self.kappa,
                self.settings.friction,
                self.settings.epsv * dt,
            )
        });
    }

    /// The largest fraction of the step from `x0` to `x1` that keeps the surface free of
    /// intersections (additive CCD over the pairs the swept boxes bring together), and loads
    /// the pairs that come within `dhat` anywhere along the step for the line search.
    pub(super) fn line_search_bound(&mut self, x0: &[f64], x1: &[f64]) -> f64 {
        let e0 = self.extended(x0);
        let mut e1 = x1.to_vec();
        e1.extend_from_slice(self.obstacle_goal.as_ref().unwrap_or(&self.obstacle_positions));
        if e1.iter().any(|v| !v.is_finite()) {
            return 0.0;
        }
        let clock = Instant::now();
        let c = self.filtered(Candidates::swept(self.surface(), &e0, &e1, self.settings.dhat));
        self.broad_phase_seconds += clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        let t = max_step_over(&c, self.surface(), &e0, &e1, 0.0, &self.ccd).min(self.collider_bound(x0, x1));
        self.ccd_seconds += clock.elapsed().as_secs_f64();
        self.barrier.set_candidates(&c);
        t
    }

    /// Updates the stiffness after a Newton step that ended at `x`.
    pub(super) fn end_iteration(&mut self, x: &[f64]) {
        let min_d2 = self
            .barrier
            .min_squared_distance(&self.extended(x))
            .min(self.collider_min_squared_distance(x));
        let max = initial_barrier_stiffness(
            self.bbox_diagonal,
            self.settings.dhat,
            self.average_mass,
            &[],
            &[],
            MIN_STIFFNESS_SCALE,
        )
        .max;
        self.kappa = update_barrier_stiffness(
            self.prev_min_d2,
            min_d2,
            max,
            self.kappa,
            self.bbox_diagonal,
            UPDATE_DISTANCE_FRACTION,
        );
        self.prev_min_d2 = min_d2;
    }

    fn terms(&self) -> impl Iterator<Item = (&dyn StencilEnergy, f64)> {
        [
            (&self.barrier as &dyn StencilEnergy, self.kappa),
            (&self.colliders.barrier as &dyn StencilEnergy, self.kappa),
        ]
        .into_iter()
        .chain(self.friction.iter().map(|f| (f as &dyn StencilEnergy, 1.0)))
        .chain(self.colliders.friction.iter().map(|f| (f as &dyn StencilEnergy, 1.0)))
    }

    /// `kappa B(x) + D(x)` over the loaded pairs (infinite where a pair touches).
    pub(super) fn value(&self, x: &[f64]) -> f64 {
        let ext = self.extended(x);
        self.terms().map(|(e, w)| w * energy::value(e, &ext)).sum()
    }

    /// The barrier's share `kappa B(x)` alone (for energy reports), over the pairs the last
    /// solve loaded (which hold every pair within `dhat` of its result; none before the
    /// first solve).
    pub(super) fn barrier_value(&self, x: &[f64]) -> f64 {
        let ext = self.extended(x);
        self.kappa * (energy::value(&self.barrier, &ext) + energy::value(&self.colliders.barrier, &ext))
    }

    /// Adds the gradient of [`Self::value`] over the body's dofs into `grad`; returns the value.
    pub(super) fn add_gradient(&self, x: &[f64], grad: &mut [f64]) -> f64 {
        let ext = self.extended(x);
        let mut g = vec![0.0; ext.len()];
        let e = self
            .terms()
            .map(|(t, w)| energy::add_gradient(t, w, &ext, &mut g))
            .sum();
        grad.iter_mut().zip(&g).for_each(|(a, b)| *a += b);
        e
    }

    /// Hands every contact stencil's (optionally projected) Hessian, its extended vertices
    /// and its weight to `sink`.
    pub(super) fn for_each_hessian(&self, x: &[f64], project: bool, mut sink: impl FnMut(&[usize], &Local, f64)) {
        let ext = self.extended(x);
        for (term, weight) in self.terms() {
            energy::for_each_hessian(term, &ext, project, |s, _, local| sink(term.stencil(s), local, weight));
        }
    }

    /// Coordinates of the body (the extended vertices before the obstacles').
    pub(super) fn body_len(&self) -> usize {
        self.body_len
    }
}
