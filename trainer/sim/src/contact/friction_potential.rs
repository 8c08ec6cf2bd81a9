//! Lagged friction over a contact surface (IPC, Li et al. 2020, Sec. 5): the potential
//! `D(x) = sum_k mu N_k f0(|T_k^T Gamma_k (x - x^t)|, eps_v h)` over the contact pairs active
//! at the start of a solve, as a [`StencilEnergy`].
//!
//! At the lagged positions `x^t` (the start of the time step) every barrier stencil closer
//! than `dhat` gives one friction stencil: its closest features (point-triangle interior,
//! point-edge, point-point, edge-edge interior) fix which vertices take part, the tangent
//! basis `T`, the closest-point weights `Gamma` and the normal force
//! `N = -kappa 2 d b'(d^2, dhat^2)` are computed there once; the potential is then a smooth
//! function of the displacement `x - x^t` of those vertices. Edge-edge normal forces leave
//! out the mollifier (it only matters for nearly parallel edges).

use super::barrier::barrier_force_magnitude;
use super::barrier_potential::{BarrierPotential, PairKind};
use super::distance::{
    edge_edge_type, point_edge_type, point_triangle_type, EdgeEdgeType, PointEdgeType, PointTriangleType,
};
use super::friction::{
    edge_edge_closest_point, edge_edge_tangent_basis, point_edge_closest_point, point_edge_tangent_basis,
    point_point_tangent_basis, point_triangle_closest_point, point_triangle_tangent_basis, FrictionStencil,
    RelativeVelocity,
};
use crate::energy::{gather, Local, StencilEnergy, Want, MAX_DOF};

/// Lagged friction stencils.
pub struct FrictionPotential {
    dim: usize,
    eps_u: f64,
    verts: Vec<[usize; 4]>,
    count: Vec<usize>,
    lagged: Vec<[f64; MAX_DOF]>,
    stencils: Vec<FrictionStencil>,
}

impl FrictionPotential {
    /// Friction with coefficient `mu` for the pairs of `barrier` within `dhat` at the lagged
    /// positions `x` (stiffness `kappa`), smoothed below the displacement `eps_u`
    /// (`eps_v` times the time step).
    pub fn lagged(barrier: &BarrierPotential, x: &[f64], kappa: f64, mu: f64, eps_u: f64) -> Self {
        let dim = barrier.dim();
        let mut out = FrictionPotential {
            dim,
            eps_u,
            verts: Vec::new(),
            count: Vec::new(),
            lagged: Vec::new(),
            stencils: Vec::new(),
        };
        if mu <= 0.0 {
            return out;
        }
        let dhat = barrier.dhat();
        let mut xl = [0.0; MAX_DOF];
        for s in 0..barrier.len() {
            let n = gather(barrier, s, x, &mut xl);
            let d2 = barrier.squared_distance(s, &xl[..n]);
            if d2.is_nan() || d2 >= dhat * dhat {
                continue;
            }
            let normal_force = barrier_force_magnitude(d2, dhat, kappa);
            if normal_force <= 0.0 {
                continue;
            }
            let v = barrier.stencil(s);
            // (local vertices taking part, basis, weights)
            let (local, basis, relative): (Vec<usize>, _, _) = match barrier.kind(s) {
                PairKind::PointTriangle => match point_triangle_type(&xl[..n]) {
                    PointTriangleType::Interior => {
                        let (c, _) = point_triangle_closest_point(&xl[..n]);
                        (
                            vec![0, 1, 2, 3],
                            point_triangle_tangent_basis(&xl[..n]),
                            RelativeVelocity::point_triangle(c),
                        )
                    }
                    PointTriangleType::E0 => point_edge(&xl, dim, [0, 1, 2]),
                    PointTriangleType::E1 => point_edge(&xl, dim, [0, 2, 3]),
                    PointTriangleType::E2 => point_edge(&xl, dim, [0, 3, 1]),
                    PointTriangleType::T0 => point_point(&xl, dim, [0, 1]),
                    PointTriangleType::T1 => point_point(&xl, dim, [0, 2]),
                    PointTriangleType::T2 => point_point(&xl, dim, [0, 3]),
                },
                PairKind::EdgeEdge { .. } => match edge_edge_type(&xl[..n]) {
                    EdgeEdgeType::AB => {
                        let (c, _) = edge_edge_closest_point(&xl[..n]);
                        (
                            vec![0, 1, 2, 3],
                            edge_edge_tangent_basis(&xl[..n]),
                            RelativeVelocity::edge_edge(c),
                        )
                    }
                    EdgeEdgeType::AB0 => point_edge(&xl, dim, [2, 0, 1]),
                    EdgeEdgeType::AB1 => point_edge(&xl, dim, [3, 0, 1]),
                    EdgeEdgeType::A0B => point_edge(&xl, dim, [0, 2, 3]),
                    EdgeEdgeType::A1B => point_edge(&xl, dim, [1, 2, 3]),
                    EdgeEdgeType::A0B0 => point_point(&xl, dim, [0, 2]),
                    EdgeEdgeType::A0B1 => point_point(&xl, dim, [0, 3]),
                    EdgeEdgeType::A1B0 => point_point(&xl, dim, [1, 2]),
                    EdgeEdgeType::A1B1 => point_point(&xl, dim, [1, 3]),
                },
                PairKind::PointEdge => match point_edge_type(&xl[..n], dim) {
                    PointEdgeType::Interior => point_edge(&xl, dim, [0, 1, 2]),
                    PointEdgeType::E0 => point_point(&xl, dim, [0, 1]),
                    PointEdgeType::E1 => point_point(&xl, dim, [0, 2]),
                },
            };
            let mut verts = [usize::MAX; 4];
            let mut lagged = [0.0; MAX_DOF];
            for (a, &l) in local.iter().enumerate() {
                verts[a] = v[l];
                lagged[a * dim..(a + 1) * dim].copy_from_slice(&xl[l * dim..(l + 1) * dim]);
            }
            out.verts.push(verts);
            out.count.push(local.len());
            out.lagged.push(lagged);
            out.stencils.push(FrictionStencil {
                basis,
                relative,
                normal_force,
                mu,
            });
        }
        out
    }
}

type Lagged = (Vec<usize>, super::friction::TangentBasis, RelativeVelocity);

/// Gathers the local vertices `pick` of the stencil positions `xl` into one vector.
fn pick_vertices<const K: usize>(xl: &[f64; MAX_DOF], dim: usize, pick: [usize; K]) -> [f64; MAX_DOF] {
    let mut y = [0.0; MAX_DOF];
    for (a, &l) in pick.iter().enumerate() {
        y[a * dim..(a + 1) * dim].copy_from_slice(&xl[l * dim..(l + 1) * dim]);
    }
    y
}

fn point_edge(xl: &[f64; MAX_DOF], dim: usize, pick: [usize; 3]) -> Lagged {
    let y = pick_vertices(xl, dim, pick);
    let (alpha, _) = point_edge_closest_point(&y[..3 * dim], dim);
    (
        pick.to_vec(),
        point_edge_tangent_basis(&y[..3 * dim], dim),
        RelativeVelocity::point_edge(alpha),
    )
}

fn point_point(xl: &[f64; MAX_DOF], dim: usize, pick: [usize; 2]) -> Lagged {
    let y = pick_vertices(xl, dim, pick);
    (
        pick.to_vec(),
        point_point_tangent_basis(&y[..2 * dim], dim),
        RelativeVelocity::point_point(),
    )
}

impl StencilEnergy for FrictionPotential {
    fn name(&self) -> &'static str {
        "contact friction"
    }
    fn dim(&self) -> usize {
        self.dim
    }
    fn len(&self) -> usize {
        self.stencils.len()
    }
    fn stencil(&self, s: usize) -> &[usize] {
        &self.verts[s][..self.count[s]]
    }
    fn eval(&self, s: usize, x: &[f64], want: Want, out: &mut Local) -> f64 {
        let mut u = [0.0; MAX_DOF];
        for (k, uk) in u[..x.len()].iter_mut().enumerate() {
            *uk = x[k] - self.lagged[s][k];
        }
        self.stencils[s].eval(&u[..x.len()], self.eps_u, want, out)
    }
}
