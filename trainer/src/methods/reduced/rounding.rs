//! The arithmetic a reduced solve's numbers are rounded to: double precision (the solver's
//! own), or single precision emulated, to see what a subspace costs a solver whose numbers
//! are `f32` (as the paper's JAX solver's are by default, and as a device's would be).
//!
//! The single-precision emulation rounds at the boundaries between stages, not inside them:
//! the decoded positions, each stencil's energy and gradient, every running sum of them, the
//! scaled objective and reduced gradient, and the line search's sufficient-decrease bound.
//! Arithmetic inside a stencil and inside the decoder stays double, so a solver written in
//! `f32` throughout rounds at least this much. Newton's Hessian is not rounded.
//!
//! Where rounding hides the decrease a step makes, an accepted step leaves E unchanged; the
//! solve then ends there as `Saddle` (JAX's L-BFGS stops on insufficient progress, its
//! status 4, which the paper's convergence table counts as a saddle point).

/// How the numbers of a reduced solve are rounded (module documentation).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Rounding {
    /// Double precision throughout (the default).
    #[default]
    Double,
    /// Single precision emulated at stage boundaries.
    Single,
}

impl Rounding {
    /// `v` rounded to this arithmetic.
    #[inline]
    pub fn round(self, v: f64) -> f64 {
        match self {
            Rounding::Double => v,
            Rounding::Single => v as f32 as f64,
        }
    }

    /// `a + b`, each operand and the sum rounded to this arithmetic (`a` is a running sum,
    /// already rounded).
    #[inline]
    pub fn add(self, a: f64, b: f64) -> f64 {
        match self {
            Rounding::Double => a + b,
            Rounding::Single => (a as f32 + b as f32) as f64,
        }
    }

    /// Rounds every entry of `v` in place.
    pub fn round_all(self, v: &mut [f64]) {
        if self == Rounding::Single {
            v.iter_mut().for_each(|x| *x = self.round(*x));
        }
    }

    /// A name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Rounding::Double => "double precision",
            Rounding::Single => "single precision (emulated)",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn single_rounds_to_f32_and_double_keeps_every_bit() {
        let v = 1.0 + 1e-10;
        assert_eq!(Rounding::Double.round(v), v);
        assert_eq!(Rounding::Single.round(v), 1.0);
        assert_eq!(Rounding::Double.add(1e8, 1.0), 1e8 + 1.0);
        // 1e8 + 1 is not an f32: the sum rounds back to 1e8.
        assert_eq!(Rounding::Single.add(1e8, 1.0), 1e8);
        let mut all = [0.1, 1.0 / 3.0];
        Rounding::Single.round_all(&mut all);
        assert_eq!(all, [0.1f32 as f64, (1.0f32 / 3.0) as f64]);
        assert_ne!(all[0], 0.1);
        assert_eq!(Rounding::default(), Rounding::Double);
    }
}
