//! The reduced objective of Eq. 2, `E(z) = s (1/(2 dt^2) |f(z) - xhat|_M^2 + P(f(z)))`, on the
//! scene's own energies (one definition of each, summed stencil by stencil on the calling
//! thread: a reduced step is timed single-threaded).
//!
//! - gradient: `J^T grad_x E` with `J = df/dz`, exact, by reverse mode through the decoder
//!   without forming `J` (see [`DecoderSubspace`]);
//! - Newton's Hessian: `sum_s J_s^T H_s J_s` over stencils `s`, each stencil Hessian `H_s`
//!   projected onto the PSD cone (positive semi-definite by construction);
//! - the exact Hessian: the same sum with unprojected `H_s`, plus the map's curvature term
//!   `sum_i (grad_x E)_i d^2 x_i / dz^2` (for derivative checks and Lipschitz estimates).
//!
//! `s` is a fixed scale that makes the objective's gradient tolerance unit-free (chosen by
//! the caller, e.g. `dt^2 / (total mass * diagonal^2)` for dynamics). Without inertia
//! (quasi-static steps, potential-only Lipschitz estimates) the first term is left out.
//!
//! E and its gradient are computed in double precision, or rounded to single precision at
//! each stage ([`ReducedObjective::with_rounding`], [`super::rounding`]).

use mochi_sim::energy::inertia::Inertia;
use mochi_sim::energy::{gather, Local, StencilEnergy, Want, MAX_DOF};

use super::optimize::Objective;
use super::rounding::Rounding;
use super::subspace::DecoderSubspace;
use crate::error::TrainerResult;

/// The inertia term of a dynamic step: masses, the predicted positions and `1/dt^2`.
pub struct InertiaTerm {
    energy: Inertia,
    weight: f64,
}

impl InertiaTerm {
    /// The term `1/(2 dt^2) |x - xhat|_M^2` for lumped vertex masses `masses`; `xhat` starts
    /// at zero (set it each step with [`InertiaTerm::set_prediction`]).
    pub fn new(dim: usize, masses: Vec<f64>, dt: f64) -> Self {
        InertiaTerm {
            energy: Inertia::new(dim, masses),
            weight: 1.0 / (dt * dt),
        }
    }

    /// Sets the predicted positions `xhat` (implicit Euler: `x_t + dt v_t`).
    pub fn set_prediction(&mut self, xhat: &[f64]) {
        self.energy.set_target(xhat);
    }
}

/// The buffers of a [`ReducedObjective`], kept between steps so that a step allocates nothing.
pub struct ObjectiveBuffers {
    x: Vec<f64>,
    jac: Vec<f64>,
    gx: Vec<f64>,
    curvature: Vec<f64>,
    local: Local,
    local_x: [f64; MAX_DOF],
    local_j: Vec<f64>,
    product: Vec<f64>,
}

impl ObjectiveBuffers {
    /// Buffers for world states of `n` values and latents of `r`.
    pub fn new(n: usize, r: usize) -> Self {
        ObjectiveBuffers {
            x: vec![0.0; n],
            jac: vec![0.0; n * r],
            gx: vec![0.0; n],
            curvature: vec![0.0; r * r],
            local: Local::default(),
            local_x: [0.0; MAX_DOF],
            local_j: vec![0.0; MAX_DOF * r],
            product: vec![0.0; MAX_DOF * r],
        }
    }

    fn fits(&self, n: usize, r: usize) -> bool {
        self.x.len() == n && self.jac.len() == n * r
    }
}

/// The reduced objective of one step (module documentation).
pub struct ReducedObjective<'a> {
    subspace: &'a mut DecoderSubspace,
    potentials: &'a [&'a dyn StencilEnergy],
    inertia: Option<&'a InertiaTerm>,
    scale: f64,
    rounding: Rounding,
    buf: &'a mut ObjectiveBuffers,
}

impl<'a> ReducedObjective<'a> {
    /// The objective over `subspace` of `potentials` (and `inertia` for dynamic steps),
    /// multiplied by `scale`, evaluated in `buffers` (resized if they do not fit).
    pub fn new(
        subspace: &'a mut DecoderSubspace,
        potentials: &'a [&'a dyn StencilEnergy],
        inertia: Option<&'a InertiaTerm>,
        scale: f64,
        buffers: &'a mut ObjectiveBuffers,
    ) -> Self {
        let (n, r) = (subspace.state_len(), subspace.latent_len());
        if !buffers.fits(n, r) {
            *buffers = ObjectiveBuffers::new(n, r);
        }
        ReducedObjective {
            subspace,
            potentials,
            inertia,
            scale,
            rounding: Rounding::Double,
            buf: buffers,
        }
    }

    /// The same objective with E and its gradient rounded as `rounding` says (in every call;
    /// the Hessians themselves stay double).
    pub fn with_rounding(mut self, rounding: Rounding) -> Self {
        self.rounding = rounding;
        self
    }

    /// The world state of the last evaluation.
    pub fn positions(&self) -> &[f64] {
        &self.buf.x
    }

    /// The decoder Jacobian `dx/dz` (`n x r`, row-major) of the last Hessian evaluation.
    pub fn jacobian(&self) -> &[f64] {
        &self.buf.jac
    }

    /// The subspace map.
    pub fn subspace(&mut self) -> &mut DecoderSubspace {
        self.subspace
    }

    /// Sum of every term (inertia first, weighted by `1/dt^2`) at `self.x`; with
    /// `Want::Gradient` or `Want::Hessian` also the world gradient into `self.gx`, and with
    /// `Want::Hessian` the reduced Hessian `sum J_s^T H_s J_s` into `hess` (`r x r`).
    fn accumulate(&mut self, want: Want, mut hess: Option<&mut [f64]>) -> f64 {
        if want.gradient() {
            self.buf.gx.fill(0.0);
        }
        if let Some(h) = hess.as_deref_mut() {
            h.fill(0.0);
        }
        self.rounding.round_all(&mut self.buf.x);
        let mut total = 0.0;
        if let Some(term) = self.inertia {
            total = self.accumulate_term(&term.energy, term.weight, want, hess.as_deref_mut());
        }
        for k in 0..self.potentials.len() {
            let energy = self.potentials[k];
            total = self
                .rounding
                .add(total, self.accumulate_term(energy, 1.0, want, hess.as_deref_mut()));
        }
        total
    }

    /// [`ReducedObjective::accumulate`] of one term.
    fn accumulate_term(
        &mut self,
        energy: &dyn StencilEnergy,
        weight: f64,
        want: Want,
        mut hess: Option<&mut [f64]>,
    ) -> f64 {
        let dim = self.subspace.dim();
        let rounding = self.rounding;
        let mut total = 0.0;
        for s in 0..energy.len() {
            let verts = energy.stencil(s);
            let nl = gather(energy, s, &self.buf.x, &mut self.buf.local_x);
            let value = weight * energy.eval(s, &self.buf.local_x[..nl], want, &mut self.buf.local);
            total = rounding.add(total, value);
            if !want.gradient() {
                continue;
            }
            for (a, &v) in verts.iter().enumerate() {
                for i in 0..dim {
                    let slot = &mut self.buf.gx[v * dim + i];
                    *slot = rounding.add(*slot, weight * self.buf.local.grad[a * dim + i]);
                }
            }
            if let Some(h) = hess.as_deref_mut() {
                self.add_stencil_hessian(verts, weight, h);
            }
        }
        total
    }

    /// Adds `weight J_s^T H_s J_s` of the stencil in `self.local` into `hess`.
    fn add_stencil_hessian(&mut self, verts: &[usize], weight: f64, hess: &mut [f64]) {
        let r = self.subspace.latent_len();
        let dim = self.subspace.dim();
        let nl = verts.len() * dim;
        for (a, &v) in verts.iter().enumerate() {
            let rows = &self.buf.jac[v * dim * r..(v + 1) * dim * r];
            self.buf.local_j[a * dim * r..(a + 1) * dim * r].copy_from_slice(rows);
        }
        // product = H_s J_s (nl x r)
        for i in 0..nl {
            let out = &mut self.buf.product[i * r..(i + 1) * r];
            out.fill(0.0);
            for k in 0..nl {
                let h = self.buf.local.hess[i * nl + k];
                if h != 0.0 {
                    out.iter_mut()
                        .zip(&self.buf.local_j[k * r..(k + 1) * r])
                        .for_each(|(o, j)| *o += h * j);
                }
            }
        }
        // hess += weight J_s^T product
        for i in 0..nl {
            let ji = &self.buf.local_j[i * r..(i + 1) * r];
            let pi = &self.buf.product[i * r..(i + 1) * r];
            for (a, &ja) in ji.iter().enumerate() {
                if ja == 0.0 {
                    continue;
                }
                let row = &mut hess[a * r..(a + 1) * r];
                row.iter_mut().zip(pi).for_each(|(o, p)| *o += weight * ja * p);
            }
        }
    }

    /// `grad = J^T self.gx`, scaled.
    fn pull_back_gradient(&self, grad: &mut [f64]) {
        let r = self.subspace.latent_len();
        grad.fill(0.0);
        for (row, &g) in self.buf.jac.chunks_exact(r).zip(&self.buf.gx) {
            if g != 0.0 {
                grad.iter_mut().zip(row).for_each(|(o, j)| *o += g * j);
            }
        }
        grad.iter_mut().for_each(|g| *g *= self.scale);
    }

    /// The exact Hessian of the objective at `z` into `hess` (`r x r`), with its gradient into
    /// `grad`; returns the value.
    pub fn exact_hessian(&mut self, z: &[f64], grad: &mut [f64], hess: &mut [f64]) -> TrainerResult<f64> {
        self.subspace
            .positions_and_jacobian(z, &mut self.buf.x, &mut self.buf.jac)?;
        let value = self.accumulate(Want::Hessian { project: false }, Some(hess));
        self.subspace
            .contracted_hessian(z, &self.buf.gx, &mut self.buf.curvature)?;
        hess.iter_mut()
            .zip(&self.buf.curvature)
            .for_each(|(h, c)| *h = self.scale * (*h + c));
        self.pull_back_gradient(grad);
        Ok(self.scale * value)
    }
}

impl Objective for ReducedObjective<'_> {
    fn dim(&self) -> usize {
        self.subspace.latent_len()
    }

    fn value(&mut self, z: &[f64]) -> f64 {
        if self.subspace.positions(z, &mut self.buf.x).is_err() {
            return f64::NAN;
        }
        self.rounding.round(self.scale * self.accumulate(Want::Value, None))
    }

    fn gradient(&mut self, z: &[f64], grad: &mut [f64]) -> f64 {
        if self.subspace.positions(z, &mut self.buf.x).is_err() {
            grad.fill(f64::NAN);
            return f64::NAN;
        }
        let value = self.accumulate(Want::Gradient, None);
        if self.subspace.gradient(z, &self.buf.gx, grad).is_err() {
            grad.fill(f64::NAN);
            return f64::NAN;
        }
        grad.iter_mut().for_each(|g| *g = self.rounding.round(*g * self.scale));
        self.rounding.round(self.scale * value)
    }

    fn hessian(&mut self, z: &[f64], grad: &mut [f64], hess: &mut [f64]) -> f64 {
        if self
            .subspace
            .positions_and_jacobian(z, &mut self.buf.x, &mut self.buf.jac)
            .is_err()
        {
            grad.fill(f64::NAN);
            hess.fill(f64::NAN);
            return f64::NAN;
        }
        let value = self.accumulate(Want::Hessian { project: true }, Some(hess));
        hess.iter_mut().for_each(|h| *h *= self.scale);
        self.pull_back_gradient(grad);
        self.rounding.round_all(grad);
        self.rounding.round(self.scale * value)
    }
}
