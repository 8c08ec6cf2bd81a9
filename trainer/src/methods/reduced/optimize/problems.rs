//! Test problems both reduced solvers are checked on.

use super::Objective;

type Value = Box<dyn Fn(&[f64]) -> f64>;
type Fill = Box<dyn Fn(&[f64], &mut [f64])>;

/// An objective made of closures (E, gradient, Hessian) that records every E it returns.
pub struct Problem {
    r: usize,
    value: Value,
    grad: Fill,
    hess: Fill,
    /// Every E returned, in order.
    pub values: Vec<f64>,
}

impl Problem {
    pub fn new(
        r: usize,
        value: impl Fn(&[f64]) -> f64 + 'static,
        grad: impl Fn(&[f64], &mut [f64]) + 'static,
        hess: impl Fn(&[f64], &mut [f64]) + 'static,
    ) -> Self {
        let (value, grad, hess) = (Box::new(value), Box::new(grad), Box::new(hess));
        Problem {
            r,
            value,
            grad,
            hess,
            values: Vec::new(),
        }
    }
}

impl Objective for Problem {
    fn dim(&self) -> usize {
        self.r
    }
    fn value(&mut self, z: &[f64]) -> f64 {
        let value = (self.value)(z);
        self.values.push(value);
        value
    }
    fn gradient(&mut self, z: &[f64], grad: &mut [f64]) -> f64 {
        (self.grad)(z, grad);
        self.value(z)
    }
    fn hessian(&mut self, z: &[f64], grad: &mut [f64], hess: &mut [f64]) -> f64 {
        (self.hess)(z, hess);
        self.gradient(z, grad)
    }
}

/// `0.5 sum a_i (z_i - m_i)^2`; its Hessian is reported as `hessian` (row-major) when
/// given, `diag(a)` otherwise.
pub fn quadratic(a: &[f64], m: &[f64], hessian: Option<Vec<f64>>) -> Problem {
    let r = a.len();
    let diagonal = || {
        (0..r * r)
            .map(|k| if k % (r + 1) == 0 { a[k / r] } else { 0.0 })
            .collect()
    };
    let h = hessian.unwrap_or_else(diagonal);
    let (a, m) = (a.to_vec(), m.to_vec());
    let (a2, m2) = (a.clone(), m.clone());
    Problem::new(
        r,
        move |z| (0..r).map(|i| 0.5 * a[i] * (z[i] - m[i]).powi(2)).sum(),
        move |z, g| (0..r).for_each(|i| g[i] = a2[i] * (z[i] - m2[i])),
        move |_, out| out.copy_from_slice(&h),
    )
}

/// r = 8, eigenvalues from 1 to 1e4 (condition number 1e4); with its minimiser.
pub fn ill_conditioned() -> (Problem, Vec<f64>) {
    let a: Vec<f64> = (0..8).map(|i| 10f64.powf(4.0 * i as f64 / 7.0)).collect();
    let m: Vec<f64> = (0..8).map(|i| 1.0 - 0.25 * i as f64).collect();
    (quadratic(&a, &m, None), m)
}

/// `(1 - x)^2 + 100 (y - x^2)^2`, minimiser (1, 1); the Hessian is the Gauss-Newton one
/// `2 J^T J` of the residuals `(1 - x, 10 (y - x^2))`, positive definite everywhere.
pub fn rosenbrock() -> Problem {
    Problem::new(
        2,
        |z| (1.0 - z[0]).powi(2) + 100.0 * (z[1] - z[0] * z[0]).powi(2),
        |z, g| {
            let t = z[1] - z[0] * z[0];
            g[0] = -2.0 * (1.0 - z[0]) - 400.0 * z[0] * t;
            g[1] = 200.0 * t;
        },
        |z, h| h.copy_from_slice(&[2.0 + 800.0 * z[0] * z[0], -400.0 * z[0], -400.0 * z[0], 200.0]),
    )
}

/// `problem` with E lifted by 1000 and, when `round`, rounded to `f32` (the gradient and
/// Hessian as they were): E's spacing there is 6.1e-5, so once a step's decrease is smaller
/// than that it rounds away, while the gradient may still be far above 1e-5.
pub fn lifted(mut problem: Problem, round: bool) -> Problem {
    let inner = std::mem::replace(&mut problem.value, Box::new(|_: &[f64]| 0.0));
    problem.value = Box::new(move |z: &[f64]| {
        let v = 1000.0 + inner(z);
        if round {
            v as f32 as f64
        } else {
            v
        }
    });
    problem
}

/// `0.5 k |z - c|^2` with `c = (0.6, -0.8)`, NaN outside the ball of radius 1.5 about
/// the origin; its Hessian is reported as `hessian_k I`.
pub fn walled(k: f64, hessian_k: f64) -> Problem {
    Problem::new(
        2,
        move |z| match z[0].hypot(z[1]) > 1.5 {
            true => f64::NAN,
            false => 0.5 * k * ((z[0] - 0.6).powi(2) + (z[1] + 0.8).powi(2)),
        },
        move |z, g| g.copy_from_slice(&[k * (z[0] - 0.6), k * (z[1] + 0.8)]),
        move |_, h| h.copy_from_slice(&[hessian_k, 0.0, 0.0, hessian_k]),
    )
}

/// E is `|z|^2` but the gradient is reported as `-2 z`: steepest descent climbs E.
pub fn uphill() -> Problem {
    Problem::new(
        2,
        |z| z[0] * z[0] + z[1] * z[1],
        |z, g| g.copy_from_slice(&[-2.0 * z[0], -2.0 * z[1]]),
        |_, h| h.copy_from_slice(&[2.0, 0.0, 0.0, 2.0]),
    )
}

/// `-(z_0 + z_1)`: unbounded below, zero Hessian.
pub fn slope() -> Problem {
    Problem::new(2, |z| -(z[0] + z[1]), |_, g| g.fill(-1.0), |_, h| h.fill(0.0))
}
