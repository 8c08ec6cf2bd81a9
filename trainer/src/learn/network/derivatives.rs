//! A frozen MLP in `f64` with exact derivatives, for solvers that minimise energies of a
//! decoder's output over its latent input.
//!
//! # Maths
//!
//! With the layout of [`super`] and its activation `s` (Swish or ELU; `s'` and `s''` from
//! [`Activation::parts`]). For Swish, with `σ(u) = 1 / (1 + e^-u)` and `s(u) = u σ(u)`:
//!
//! ```text
//! s'(u)  = σ + u σ (1 - σ)
//! s''(u) = σ (1 - σ) (2 + u (1 - 2σ))
//! ```
//!
//! The sweeps below are written for residual blocks; a plain hidden layer `h = W a(h)` is the
//! same block with the identity as its inner layer (`u = h`) and the residual addition
//! replaced by an assignment, forward (`h`, its tangents) and backward (`h̄`, `∂h̄`).
//!
//! **Jacobian.** Every hidden vector `a` carries its tangents `∂a/∂x` (a `hidden × input`
//! array, one row per unit). A dense layer `a ↦ W a + b` maps tangents by `W` alone, Swish by
//! `s'(u) ⊙`, and the residual addition adds them: `∂h = W_in`, then for each block
//! `∂u = W_in_j ∂h`, `∂h += W_out_j (s'(u) ⊙ ∂u)`, and finally `J = W_o (s'(h) ⊙ ∂h)`. The output
//! layer dominates (`output × hidden × input` products): row `o` of `J` accumulates
//! `W_o[o, j] ∂g_j` over the units `j`, so `W_o` streams once, row by row, while the small
//! tangent array stays in cache and the innermost loop runs over the inputs.
//!
//! **Contracted Hessian.** `Σ_i w_i ∇²y_i` is the Hessian of `φ(x) = wᵀ f(x)`. Reverse mode
//! gives `∇φ`: the adjoint of `swish(h)` is `c = W_oᵀ w`, then `h̄ = s'(h) ⊙ c`; back through
//! each block `ū = s'(u) ⊙ W_out_jᵀ h̄`, `h̄ += W_in_jᵀ ū`; and `∇φ = W_inᵀ h̄`. Differentiating
//! this sweep in every input direction (forward over reverse), with the tangents `∂h`, `∂u` of
//! the forward pass, gives `∂h̄ = s''(h) ⊙ ∂h ⊙ c`, `∂ū = s''(u) ⊙ ∂u ⊙ W_out_jᵀ h̄ + s'(u) ⊙
//! W_out_jᵀ ∂h̄`, `∂h̄ += W_in_jᵀ ∂ū`, and the Hessian is `W_inᵀ ∂h̄`. This uses the
//! hidden units' second derivatives and `W_oᵀ w` only, so it costs about two hidden-layer
//! Jacobians and one product with `W_oᵀ`, never a per-output Hessian. The result is symmetric up
//! to rounding and is returned symmetrised.
//!
//! **Second directional derivative.** Along the line `x + t v`, every hidden vector carries its
//! first and second derivatives in `t`: a dense layer maps both by `W`, and Swish maps
//! `(u, u̇, ü)` to `(s, s' u̇, s'' u̇² + s' ü)`.
//!
//! All calls check their sizes and run without allocating once their [`Mlp64Workspace`] has
//! the network's sizes.

use super::error::{invalid, ModelResult};
use super::exported::ExportedMlp;
use super::layout::{Activation, MlpStyle};
use dense64::{dot, Dense64};

/// An error naming `what` unless it has `expected` values.
pub(crate) fn check_len(what: &str, got: usize, expected: usize) -> ModelResult<()> {
    if got != expected {
        return invalid(format!("{what} has {got} values, expected {expected}"));
    }
    Ok(())
}

/// A frozen MLP (layout in [`super`]) with its weights in `f64`, evaluating its value,
/// Jacobian, contracted Hessian and second directional derivatives exactly.
#[derive(Debug, Clone, PartialEq)]
pub struct Mlp64 {
    input: Dense64,
    /// `(inner, outer)` of each block; no inner layer in a plain one.
    blocks: Vec<(Option<Dense64>, Dense64)>,
    output: Dense64,
    /// A fixed map after the output layer (a PCA basis), kept apart: `outputs x modes` costs
    /// less than the product with the output layer folded in.
    projection: Option<Dense64>,
    activation: Activation,
    residual: bool,
}

/// Scratch space of [`Mlp64`]'s calls. Any workspace fits any network: a call first resizes it
/// to the network's sizes, so only the first call with a new size allocates.
#[derive(Debug, Clone, Default)]
pub struct Mlp64Workspace {
    h: Vec<f64>,
    act: Vec<f64>,
    pre: Vec<f64>,
    dpre: Vec<f64>,
    tan: Vec<f64>,
    dact: Vec<f64>,
    bar: Vec<f64>,
    dbar: Vec<f64>,
    abar: Vec<f64>,
    dabar: Vec<f64>,
    curv: Vec<f64>,
    /// The output layer's values, tangents and weights before the projection.
    py: Vec<f64>,
    pjac: Vec<f64>,
    pw: Vec<f64>,
}

impl Mlp64Workspace {
    /// A workspace sized for `mlp`.
    pub fn new(mlp: &Mlp64) -> Self {
        let mut ws = Self::default();
        ws.fit(mlp);
        ws
    }

    fn fit(&mut self, mlp: &Mlp64) {
        let (n, r, b) = (mlp.hidden(), mlp.input_len(), mlp.blocks.len());
        let p = mlp.projection.as_ref().map_or(0, |_| mlp.output.rows);
        let sizes = [
            (&mut self.h, n),
            (&mut self.act, n),
            (&mut self.pre, b * n),
            (&mut self.dpre, b * r * n),
            (&mut self.tan, r * n),
            (&mut self.dact, r * n),
            (&mut self.bar, n),
            (&mut self.dbar, r * n),
            (&mut self.abar, n),
            (&mut self.dabar, r * n),
            (&mut self.curv, 2 * n),
            (&mut self.py, p),
            (&mut self.pjac, p * r),
            (&mut self.pw, p),
        ];
        for (buffer, len) in sizes {
            buffer.resize(len, 0.0);
        }
    }
}

impl Mlp64 {
    /// Converts the weights of `mlp` to `f64`, an input projection folded into the input
    /// layer (`W_in (P x + c) + b_in`).
    pub fn new(mlp: &ExportedMlp) -> Self {
        let MlpStyle {
            activation, residual, ..
        } = mlp.style();
        let mut input = Dense64::new(mlp.input());
        if let Some(projection) = mlp.input_projection() {
            let p = Dense64::new(projection);
            let mut weights = vec![0.0; input.rows * p.cols];
            for (i, row) in weights.chunks_exact_mut(p.cols).enumerate() {
                for (k, &w) in input.row(i).iter().enumerate() {
                    row.iter_mut().zip(p.row(k)).for_each(|(o, &v)| *o += w * v);
                }
                input.bias[i] += dot(input.row(i), &p.bias);
            }
            input = Dense64 {
                cols: p.cols,
                weights,
                ..input
            };
        }
        Mlp64 {
            input,
            blocks: mlp
                .blocks()
                .iter()
                .map(|b| (b.inner.as_ref().map(Dense64::new), Dense64::new(&b.outer)))
                .collect(),
            output: Dense64::new(mlp.output()),
            projection: mlp.output_projection().map(Dense64::new),
            activation,
            residual,
        }
    }

    /// The same network with only the given output rows (in the given order), for callers that
    /// need a few outputs of a large one.
    pub fn rows(&self, rows: &[usize]) -> ModelResult<Mlp64> {
        let out = self.projection.as_ref().unwrap_or(&self.output);
        if let Some(&bad) = rows.iter().find(|&&r| r >= out.rows) {
            return invalid(format!("output row {bad} of a network with {} outputs", out.rows));
        }
        let selected = Dense64 {
            rows: rows.len(),
            cols: out.cols,
            weights: rows.iter().flat_map(|&r| out.row(r).iter().copied()).collect(),
            bias: rows.iter().map(|&r| out.bias[r]).collect(),
        };
        let (output, projection) = match self.projection {
            Some(_) => (self.output.clone(), Some(selected)),
            None => (selected, None),
        };
        Ok(Mlp64 {
            input: self.input.clone(),
            blocks: self.blocks.clone(),
            output,
            projection,
            ..*self
        })
    }

    /// Number of inputs.
    pub fn input_len(&self) -> usize {
        self.input.cols
    }

    /// Number of outputs.
    pub fn output_len(&self) -> usize {
        self.projection.as_ref().unwrap_or(&self.output).rows
    }

    /// Width of the hidden layers.
    pub fn hidden(&self) -> usize {
        self.input.rows
    }

    /// `y = f(x)`.
    pub fn value(&self, x: &[f64], y: &mut [f64], ws: &mut Mlp64Workspace) -> ModelResult<()> {
        check_len("input", x.len(), self.input_len())?;
        check_len("output", y.len(), self.output_len())?;
        ws.fit(self);
        self.hidden_pass(x, false, ws);
        let activation = self.activation;
        ws.act
            .iter_mut()
            .zip(&ws.h)
            .for_each(|(a, &h)| *a = activation.apply(h));
        match &self.projection {
            Some(p) => {
                let py = &mut ws.py;
                self.output.matvec(&ws.act, |o, v| py[o] = self.output.bias[o] + v);
                p.matvec(py, |o, v| y[o] = p.bias[o] + v);
            }
            None => self.output.matvec(&ws.act, |o, v| y[o] = self.output.bias[o] + v),
        }
        Ok(())
    }

    /// `y = f(x)` and the Jacobian `jac = ∂y/∂x` (`output × input`, row-major).
    pub fn jacobian(&self, x: &[f64], y: &mut [f64], jac: &mut [f64], ws: &mut Mlp64Workspace) -> ModelResult<()> {
        let (n, r) = (self.hidden(), self.input_len());
        check_len("input", x.len(), r)?;
        check_len("output", y.len(), self.output_len())?;
        check_len("Jacobian", jac.len(), self.output_len() * r)?;
        ws.fit(self);
        self.hidden_pass(x, true, ws);
        let Mlp64Workspace {
            h, act, tan, py, pjac, ..
        } = ws;
        for i in 0..n {
            let (s, first, _) = self.activation.parts(h[i]);
            act[i] = s;
            tan[i * r..(i + 1) * r].iter_mut().for_each(|t| *t *= first);
        }
        match &self.projection {
            Some(p) => {
                self.output.with_tangents(act, tan, py, pjac, false);
                p.with_tangents(py, pjac, y, jac, false);
            }
            None => self.output.with_tangents(act, tan, y, jac, false),
        }
        Ok(())
    }

    /// `wᵀ ∂y/∂x` (one value per input): the gradient of `φ(x) = wᵀ f(x)` by reverse mode, for
    /// `w = ∂E/∂y` the gradient of `E(f(x))`. It costs two products with the output layer
    /// (one forward, one transposed) where [`Mlp64::jacobian`] costs one per input.
    pub fn pulled_back(&self, x: &[f64], w: &[f64], out: &mut [f64], ws: &mut Mlp64Workspace) -> ModelResult<()> {
        check_len("input", x.len(), self.input_len())?;
        ws.fit(self);
        self.hidden_pass(x, false, ws);
        self.pulled_back_after_value(w, out, ws)
    }

    /// [`Mlp64::pulled_back`] at the input of this network's last [`Mlp64::value`] call on
    /// `ws`, reusing the hidden pass that call left there (bit for bit the same result). The
    /// caller vouches that no other call has used `ws` since: a workspace does not know which
    /// network or input it last served.
    pub fn pulled_back_after_value(&self, w: &[f64], out: &mut [f64], ws: &mut Mlp64Workspace) -> ModelResult<()> {
        let n = self.hidden();
        check_len("output weights", w.len(), self.output_len())?;
        check_len("gradient", out.len(), self.input_len())?;
        ws.fit(self);
        let Mlp64Workspace {
            h, pre, bar, abar, pw, ..
        } = ws;
        let w = self.before_projection(w, pw);
        abar.fill(0.0);
        self.output.add_transposed(w, abar);
        for i in 0..n {
            bar[i] = self.activation.parts(h[i]).1 * abar[i];
        }
        for (j, (inner, outer)) in self.blocks.iter().enumerate().rev() {
            abar.fill(0.0);
            outer.add_transposed(bar, abar);
            for (a, &u) in abar.iter_mut().zip(&pre[j * n..(j + 1) * n]) {
                *a *= self.activation.parts(u).1;
            }
            self.block_adjoint(inner.as_ref(), abar, bar);
        }
        out.fill(0.0);
        self.input.add_transposed(bar, out);
        Ok(())
    }

    /// `Σ_i w_i ∂²y_i/∂x∂x` (`input × input`, symmetric, row-major): the second-order term of the
    /// Hessian of `E(f(x))` when `w = ∂E/∂y` (`w` has one value per output).
    pub fn contracted_hessian(
        &self,
        x: &[f64],
        w: &[f64],
        out: &mut [f64],
        ws: &mut Mlp64Workspace,
    ) -> ModelResult<()> {
        let (n, r) = (self.hidden(), self.input_len());
        check_len("input", x.len(), r)?;
        check_len("output weights", w.len(), self.output_len())?;
        check_len("Hessian", out.len(), r * r)?;
        ws.fit(self);
        self.hidden_pass(x, true, ws);
        let Mlp64Workspace {
            h,
            pre,
            dpre,
            tan,
            bar,
            dbar,
            abar,
            dabar,
            pw,
            ..
        } = ws;
        let w = self.before_projection(w, pw);
        abar.fill(0.0);
        self.output.add_transposed(w, abar);
        for i in 0..n {
            let (_, first, second) = self.activation.parts(h[i]);
            bar[i] = first * abar[i];
            (0..r).for_each(|k| dbar[i * r + k] = second * tan[i * r + k] * abar[i]);
        }
        for (j, (inner, outer)) in self.blocks.iter().enumerate().rev() {
            abar.fill(0.0);
            outer.add_transposed(bar, abar);
            dabar.fill(0.0);
            outer.add_transposed(dbar, dabar);
            let (u, du) = (&pre[j * n..(j + 1) * n], &dpre[j * r * n..(j + 1) * r * n]);
            for i in 0..n {
                let (_, first, second) = self.activation.parts(u[i]);
                for k in 0..r {
                    dabar[i * r + k] = second * du[i * r + k] * abar[i] + first * dabar[i * r + k];
                }
                abar[i] *= first;
            }
            self.block_adjoint(inner.as_ref(), abar, bar);
            self.block_adjoint(inner.as_ref(), dabar, dbar);
        }
        out.fill(0.0);
        self.input.add_transposed(dbar, out);
        for k in 0..r {
            for l in k + 1..r {
                let mean = 0.5 * (out[k * r + l] + out[l * r + k]);
                out[k * r + l] = mean;
                out[l * r + k] = mean;
            }
        }
        Ok(())
    }

    /// `d²/dt² f(x + t v)` at `t = 0` (one value per output).
    pub fn second_directional(
        &self,
        x: &[f64],
        v: &[f64],
        out: &mut [f64],
        ws: &mut Mlp64Workspace,
    ) -> ModelResult<()> {
        let n = self.hidden();
        check_len("input", x.len(), self.input_len())?;
        check_len("direction", v.len(), self.input_len())?;
        check_len("output", out.len(), self.output_len())?;
        ws.fit(self);
        let Mlp64Workspace {
            h,
            act,
            tan,
            dact,
            curv,
            ..
        } = ws;
        let (d, du) = (&mut tan[..n], &mut dact[..n]);
        let (dd, ddu) = curv.split_at_mut(n);
        self.input.matvec(x, |i, s| h[i] = self.input.bias[i] + s);
        self.input.matvec(v, |i, s| d[i] = s);
        dd.fill(0.0);
        for (inner, outer) in &self.blocks {
            match inner {
                Some(inner) => {
                    inner.matvec(h, |i, s| act[i] = inner.bias[i] + s);
                    inner.matvec(d, |i, s| du[i] = s);
                    inner.matvec(dd, |i, s| ddu[i] = s);
                }
                None => {
                    act.copy_from_slice(h);
                    du.copy_from_slice(d);
                    ddu.copy_from_slice(dd);
                }
            }
            for i in 0..n {
                let (s, first, second) = self.activation.parts(act[i]);
                act[i] = s;
                ddu[i] = second * du[i] * du[i] + first * ddu[i];
                du[i] *= first;
            }
            outer.matvec(act, |i, s| h[i] = self.join(h[i], outer.bias[i] + s));
            outer.matvec(du, |i, s| d[i] = self.join(d[i], s));
            outer.matvec(ddu, |i, s| dd[i] = self.join(dd[i], s));
        }
        for i in 0..n {
            let (_, first, second) = self.activation.parts(h[i]);
            ddu[i] = second * d[i] * d[i] + first * dd[i];
        }
        match &self.projection {
            Some(p) => {
                let py = &mut ws.py;
                self.output.matvec(ddu, |o, s| py[o] = s);
                p.matvec(py, |o, s| out[o] = s);
            }
            None => self.output.matvec(ddu, |o, s| out[o] = s),
        }
        Ok(())
    }

    /// Runs the hidden layers at `x` (sizes checked by the caller), leaving the last hidden
    /// vector in `ws.h` and every block's pre-activation in `ws.pre`; with `tangents`, also
    /// their tangents in every input direction (`ws.tan`, `ws.dpre`).
    fn hidden_pass(&self, x: &[f64], tangents: bool, ws: &mut Mlp64Workspace) {
        let (n, r) = (self.hidden(), self.input_len());
        let Mlp64Workspace {
            h,
            act,
            pre,
            dpre,
            tan,
            dact,
            ..
        } = ws;
        self.input.matvec(x, |i, v| h[i] = self.input.bias[i] + v);
        if tangents {
            tan.copy_from_slice(&self.input.weights);
        }
        for (j, (inner, outer)) in self.blocks.iter().enumerate() {
            let u = &mut pre[j * n..(j + 1) * n];
            let du = &mut dpre[j * r * n..(j + 1) * r * n];
            match (inner, tangents) {
                (Some(inner), true) => inner.with_tangents(h, tan, u, du, false),
                (Some(inner), false) => inner.matvec(h, |i, v| u[i] = inner.bias[i] + v),
                (None, _) => {
                    u.copy_from_slice(h);
                    if tangents {
                        du.copy_from_slice(tan);
                    }
                }
            }
            for i in 0..n {
                let (s, first, _) = self.activation.parts(u[i]);
                act[i] = s;
                if tangents {
                    (0..r).for_each(|k| dact[i * r + k] = first * du[i * r + k]);
                }
            }
            if tangents {
                outer.with_tangents(act, dact, h, tan, self.residual);
            } else {
                outer.matvec(act, |i, v| h[i] = self.join(h[i], outer.bias[i] + v));
            }
        }
    }

    /// A block's output from its input `old` and its layers' `new`: their sum in a residual
    /// block, `new` in a plain one.
    #[inline(always)]
    fn join(&self, old: f64, new: f64) -> f64 {
        if self.residual {
            old + new
        } else {
            new
        }
    }

    /// The output weights `w` pulled back through the projection (`P^T w`, in `scratch`), or
    /// `w` itself without one.
    fn before_projection<'w>(&self, w: &'w [f64], scratch: &'w mut [f64]) -> &'w [f64] {
        match &self.projection {
            Some(p) => {
                scratch.fill(0.0);
                p.add_transposed(w, scratch);
                scratch
            }
            None => w,
        }
    }

    /// The adjoint of a block's input from `abar`, the adjoint of its activation's input:
    /// `bar (+)= inner^T abar`, `bar (+)= abar` without an inner layer (`+=` in a residual
    /// block, where the input also reaches the output directly).
    fn block_adjoint(&self, inner: Option<&Dense64>, abar: &[f64], bar: &mut [f64]) {
        if !self.residual {
            bar.fill(0.0);
        }
        match inner {
            Some(inner) => inner.add_transposed(abar, bar),
            None => bar.iter_mut().zip(abar).for_each(|(b, &a)| *b += a),
        }
    }
}

mod dense64;
#[cfg(test)]
mod tests;
#[allow(unsafe_code)]
mod wide;
