//! External energies on single vertices: gravity and loads, the quadratic Dirichlet penalty and a
//! smooth collision energy against analytic obstacles (plane, sphere, capsule).

use super::{psd::project_psd, Local, StencilEnergy, Want};
use serde::{Deserialize, Serialize};

/// A constant force on vertices, `-sum_i f_i . x_i`: gravity (`f_i = m_i g`) or a load.
#[derive(Clone, Debug)]
pub struct ConstantForce {
    name: &'static str,
    dim: usize,
    forces: Vec<f64>,
    ids: Vec<usize>,
}

impl ConstantForce {
    /// Gravity with acceleration `g` on vertices of the given masses (first `dim`
    /// components of `g` are used).
    pub fn gravity(dim: usize, masses: &[f64], g: [f64; 3]) -> Self {
        let forces = masses.iter().flat_map(|m| (0..dim).map(move |i| m * g[i])).collect();
        ConstantForce {
            name: "gravity",
            dim,
            forces,
            ids: (0..masses.len()).collect(),
        }
    }
    /// A load: `total` force spread evenly over the vertices `verts`.
    pub fn load(dim: usize, verts: Vec<usize>, total: [f64; 3]) -> Self {
        let share = 1.0 / verts.len().max(1) as f64;
        let forces = verts
            .iter()
            .flat_map(|_| (0..dim).map(move |i| total[i] * share))
            .collect();
        ConstantForce {
            name: "load",
            dim,
            forces,
            ids: verts,
        }
    }
}

impl StencilEnergy for ConstantForce {
    fn name(&self) -> &'static str {
        self.name
    }
    fn dim(&self) -> usize {
        self.dim
    }
    fn len(&self) -> usize {
        self.ids.len()
    }
    fn stencil(&self, s: usize) -> &[usize] {
        &self.ids[s..s + 1]
    }
    fn eval(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        let d = self.dim;
        let f = &self.forces[s * d..(s + 1) * d];
        let mut value = 0.0;
        for i in 0..d {
            value -= f[i] * x[i];
            if want.gradient() {
                out.grad[i] = -f[i];
            }
        }
        if want.hessian().is_some() {
            out.clear_hessian(d);
        }
        value
    }
}

/// Quadratic Dirichlet penalty `w * sum_v |x_v - x*_v|^2` pulling vertices to targets.
#[derive(Clone, Debug)]
pub struct Penalty {
    dim: usize,
    weight: f64,
    verts: Vec<usize>,
    targets: Vec<f64>,
}

impl Penalty {
    /// Penalty of weight `weight` on `verts`; targets start at zero.
    pub fn new(dim: usize, weight: f64, verts: Vec<usize>) -> Self {
        let targets = vec![0.0; verts.len() * dim];
        Penalty {
            dim,
            weight,
            verts,
            targets,
        }
    }
    /// Sets the targets, `dim` numbers per penalised vertex in `verts` order.
    pub fn set_targets(&mut self, targets: &[f64]) {
        self.targets.copy_from_slice(targets);
    }
    /// Penalised vertices.
    pub fn vertices(&self) -> &[usize] {
        &self.verts
    }
}

impl StencilEnergy for Penalty {
    fn name(&self) -> &'static str {
        "penalty"
    }
    fn dim(&self) -> usize {
        self.dim
    }
    fn len(&self) -> usize {
        self.verts.len()
    }
    fn stencil(&self, s: usize) -> &[usize] {
        &self.verts[s..s + 1]
    }
    fn eval(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        let d = self.dim;
        let t = &self.targets[s * d..(s + 1) * d];
        let mut value = 0.0;
        for i in 0..d {
            let r = x[i] - t[i];
            value += self.weight * r * r;
            if want.gradient() {
                out.grad[i] = 2.0 * self.weight * r;
            }
        }
        if want.hessian().is_some() {
            out.clear_hessian(d);
            for i in 0..d {
                out.hess[i * d + i] = 2.0 * self.weight;
            }
        }
        value
    }
}

/// An analytic obstacle, described by its signed distance (positive outside).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum Obstacle {
    /// Half-space `{x : n . (x - point) >= 0}` is free.
    Plane {
        /// A point on the plane.
        point: [f64; 3],
        /// Normal pointing into free space (normalised on use).
        normal: [f64; 3],
    },
    /// Solid ball.
    Sphere {
        /// Centre.
        center: [f64; 3],
        /// Radius.
        radius: f64,
    },
    /// Solid capsule: points within `radius` of the segment `a`-`b`.
    Capsule {
        /// First end of the axis.
        a: [f64; 3],
        /// Second end of the axis.
        b: [f64; 3],
        /// Radius.
        radius: f64,
    },
}

type V3 = nalgebra::Vector3<f64>;
type M3 = nalgebra::Matrix3<f64>;

impl Obstacle {
    /// Checks the parameters are finite and sizes positive; returns a message otherwise.
    pub fn validate(&self) -> Result<(), String> {
        let finite = |v: &[f64]| v.iter().all(|c| c.is_finite());
        match self {
            Obstacle::Plane { point, normal } => {
                if !finite(point) || !finite(normal) || V3::from(*normal).norm() < 1e-12 {
                    return Err("plane needs a finite point and a non-zero finite normal".into());
                }
            }
            Obstacle::Sphere { center, radius } => {
                if !(finite(center) && radius.is_finite() && *radius > 0.0) {
                    return Err("sphere needs a finite centre and a positive radius".into());
                }
            }
            Obstacle::Capsule { a, b, radius } => {
                if !(finite(a) && finite(b) && radius.is_finite() && *radius > 0.0) {
                    return Err("capsule needs finite end points and a positive radius".into());
                }
            }
        }
        Ok(())
    }

    /// Signed distance of `p`, its gradient and its Hessian.
    pub fn signed_distance(&self, p: V3) -> (f64, V3, M3) {
        match self {
            Obstacle::Plane { point, normal } => {
                let n = V3::from(*normal).normalize();
                (n.dot(&(p - V3::from(*point))), n, M3::zeros())
            }
            Obstacle::Sphere { center, radius } => ball_distance(p, V3::from(*center), *radius, None),
            Obstacle::Capsule { a, b, radius } => {
                let (a, b) = (V3::from(*a), V3::from(*b));
                let axis = b - a;
                let len2 = axis.norm_squared();
                let t = if len2 > 0.0 { (p - a).dot(&axis) / len2 } else { 0.0 };
                if t <= 0.0 {
                    ball_distance(p, a, *radius, None)
                } else if t >= 1.0 {
                    ball_distance(p, b, *radius, None)
                } else {
                    // Distance to the infinite axis line: curvature only across the axis.
                    ball_distance(p, a + axis * t, *radius, Some(axis / len2.sqrt()))
                }
            }
        }
    }
}

/// Distance to a ball of `radius` around `c`; with `axis`, `c` is the closest point on a
/// line of that direction, so the Hessian has no curvature along the axis.
fn ball_distance(p: V3, c: V3, radius: f64, axis: Option<V3>) -> (f64, V3, M3) {
    let r = p - c;
    let rho = r.norm();
    if rho < 1e-12 {
        // At the centre the distance is not differentiable; any unit direction is valid.
        return (-radius, V3::new(0.0, 1.0, 0.0), M3::zeros());
    }
    let u = r / rho;
    let mut proj = M3::identity() - u * u.transpose();
    if let Some(a) = axis {
        proj -= a * a.transpose();
    }
    (rho - radius, u, proj / rho)
}

/// Smooth one-sided collision energy against obstacles: for each vertex and obstacle with
/// signed distance `d < margin`, `stiffness * m_i * (margin - d)^3 / 3`. It is C2, so
/// Newton sees a continuous Hessian, and mass-weighting makes `stiffness` an acceleration
/// scale independent of the mesh resolution.
#[derive(Clone, Debug)]
pub struct Collision {
    dim: usize,
    masses: Vec<f64>,
    obstacles: Vec<Obstacle>,
    stiffness: f64,
    margin: f64,
    ids: Vec<usize>,
}

impl Collision {
    /// Collision of every vertex against `obstacles`.
    pub fn new(dim: usize, masses: Vec<f64>, obstacles: Vec<Obstacle>, stiffness: f64, margin: f64) -> Self {
        let ids = (0..masses.len()).collect();
        Collision {
            dim,
            masses,
            obstacles,
            stiffness,
            margin,
            ids,
        }
    }
    /// The obstacles.
    pub fn obstacles(&self) -> &[Obstacle] {
        &self.obstacles
    }
}

impl StencilEnergy for Collision {
    fn name(&self) -> &'static str {
        "collision"
    }
    fn dim(&self) -> usize {
        self.dim
    }
    fn len(&self) -> usize {
        self.masses.len()
    }
    fn stencil(&self, s: usize) -> &[usize] {
        &self.ids[s..s + 1]
    }
    fn eval(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        let d = self.dim;
        let p = V3::from_fn(|i, _| if i < d { x[i] } else { 0.0 });
        let k = self.stiffness * self.masses[s];
        let mut value = 0.0;
        let mut grad = V3::zeros();
        let mut hess = M3::zeros();
        for obstacle in &self.obstacles {
            let (dist, n, h) = obstacle.signed_distance(p);
            let gap = self.margin - dist;
            if gap <= 0.0 {
                continue;
            }
            value += k * gap.powi(3) / 3.0;
            grad -= k * gap * gap * n;
            hess += k * (2.0 * gap * n * n.transpose() - gap * gap * h);
        }
        if want.gradient() {
            out.grad[..d].copy_from_slice(&grad.as_slice()[..d]);
        }
        if let Some(project) = want.hessian() {
            for i in 0..d {
                for j in 0..d {
                    out.hess[i * d + j] = hess[(i, j)];
                }
            }
            if project {
                project_psd(&mut out.hess[..d * d], d);
            }
        }
        value
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::energy::fd;

    #[test]
    fn gravity_and_penalty_derivatives_match_finite_differences() {
        let x = [0.3, -0.7, 1.1, 0.2, 0.5, -0.4];
        fd::assert_all_stencils(
            &ConstantForce::gravity(3, &[1.5, 0.5], [0.0, -9.8, 0.0]),
            &x,
            1e-6,
            1e-7,
        );
        fd::assert_all_stencils(&ConstantForce::load(3, vec![1], [0.0, 2.0, -1.0]), &x, 1e-6, 1e-7);
        let mut p = Penalty::new(3, 1e5, vec![1, 0]);
        p.set_targets(&[0.0, 0.0, 0.0, 1.0, 1.0, 1.0]);
        fd::assert_all_stencils(&p, &x, 1e-6, 1e-7);
    }

    #[test]
    fn collision_derivatives_match_finite_differences_for_every_obstacle() {
        let obstacles = vec![
            Obstacle::Plane {
                point: [0.0, -0.1, 0.0],
                normal: [0.2, 1.0, 0.1],
            },
            Obstacle::Sphere {
                center: [0.3, 0.2, 0.0],
                radius: 0.4,
            },
            Obstacle::Capsule {
                a: [-0.5, 0.0, 0.2],
                b: [0.5, 0.1, -0.2],
                radius: 0.25,
            },
        ];
        // Points inside the margin of each obstacle: near the capsule's side and end caps,
        // inside the sphere, just above the plane.
        let pts = [
            [0.0, 0.2, 0.05],
            [0.62, 0.1, -0.25],
            [-0.6, 0.05, 0.25],
            [0.45, 0.35, 0.1],
            [-0.2, -0.08, 0.4],
        ];
        for obstacle in obstacles {
            let c = Collision::new(3, vec![2.0; pts.len()], vec![obstacle.clone()], 50.0, 0.1);
            let x: Vec<f64> = pts.iter().flatten().copied().collect();
            fd::assert_all_stencils(&c, &x, 1e-6, 1e-5);
            let mut out = Local::default();
            let active = (0..pts.len())
                .filter(|&s| c.eval(s, &pts[s], Want::Value, &mut out) > 0.0)
                .count();
            assert!(active > 0, "test points must touch {obstacle:?}");
        }
    }

    #[test]
    fn collision_is_zero_away_from_obstacles_and_pushes_out_inside() {
        let plane = Obstacle::Plane {
            point: [0.0; 3],
            normal: [0.0, 1.0, 0.0],
        };
        let c = Collision::new(3, vec![1.0], vec![plane], 100.0, 0.01);
        let mut out = Local::default();
        assert_eq!(c.eval(0, &[0.0, 0.5, 0.0], Want::Gradient, &mut out), 0.0);
        assert_eq!(out.grad[1], 0.0);
        assert!(c.eval(0, &[0.0, -0.05, 0.0], Want::Gradient, &mut out) > 0.0);
        assert!(out.grad[1] < 0.0, "energy decreases when moving out of the obstacle");
    }

    #[test]
    fn capsule_distance_is_exact_on_side_and_caps() {
        let cap = Obstacle::Capsule {
            a: [0.0; 3],
            b: [1.0, 0.0, 0.0],
            radius: 0.1,
        };
        assert!((cap.signed_distance(V3::new(0.5, 0.3, 0.0)).0 - 0.2).abs() < 1e-12);
        assert!((cap.signed_distance(V3::new(1.3, 0.0, 0.4)).0 - 0.4).abs() < 1e-12);
        assert!((cap.signed_distance(V3::new(-0.5, 0.0, 0.0)).0 - 0.4).abs() < 1e-12);
    }
}
