//! Adaptive barrier stiffness (Li et al. 2020, Sec. 4.3 and its supplement), with the
//! conventions of IPC's toolkit (squared distances, no minimum distance).

use super::barrier::barrier_second_derivative;

/// Default scale of the smallest stiffness, relative to the average mass.
pub const MIN_STIFFNESS_SCALE: f64 = 1e11;

/// Default fraction of the bounding-box diagonal below which a shrinking distance doubles
/// the stiffness.
pub const UPDATE_DISTANCE_FRACTION: f64 = 1e-9;

/// An initial stiffness and the largest stiffness updates may reach.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BarrierStiffness {
    /// The stiffness to start with.
    pub kappa: f64,
    /// The smallest stiffness.
    pub min: f64,
    /// The largest stiffness (100 times the smallest).
    pub max: f64,
}

/// The initial stiffness: the one that best balances the barrier gradient `grad_barrier`
/// (of the unscaled barrier potential) against the gradient of the rest of the incremental
/// potential `grad_energy` (`kappa = -g_b.g_e / |g_b|^2`, or one if `g_b` is zero), clamped to
/// `[kappa_min, 100 kappa_min]` with
/// `kappa_min = min_scale * average_mass / (4 d0 b''(d0, dhat^2))` and
/// `d0 = (1e-8 bbox_diagonal)^2` (or `dhat^2 / 2` if that is not below `dhat^2`).
pub fn initial_barrier_stiffness(
    bbox_diagonal: f64,
    dhat: f64,
    average_mass: f64,
    grad_energy: &[f64],
    grad_barrier: &[f64],
    min_scale: f64,
) -> BarrierStiffness {
    let dhat2 = dhat * dhat;
    let mut d0 = (1e-8 * bbox_diagonal).powi(2);
    if d0 >= dhat2 {
        d0 = 0.5 * dhat2;
    }
    let min = min_scale * average_mass / (4.0 * d0 * barrier_second_derivative(d0, dhat2));
    let max = 100.0 * min;
    let norm2: f64 = grad_barrier.iter().map(|g| g * g).sum();
    let balance = if norm2 > 0.0 {
        -grad_barrier.iter().zip(grad_energy).map(|(b, e)| b * e).sum::<f64>() / norm2
    } else {
        1.0
    };
    BarrierStiffness {
        kappa: balance.max(min).min(max),
        min,
        max,
    }
}

/// The stiffness after a solve: doubled (up to `max`) when the smallest squared distance
/// shrank from `prev_min_d2` to `min_d2` while both are below
/// `(distance_fraction * bbox_diagonal)^2`, unchanged otherwise.
pub fn update_barrier_stiffness(
    prev_min_d2: f64,
    min_d2: f64,
    max: f64,
    kappa: f64,
    bbox_diagonal: f64,
    distance_fraction: f64,
) -> f64 {
    let eps = (distance_fraction * bbox_diagonal).powi(2);
    if prev_min_d2 < eps && min_d2 < eps && min_d2 < prev_min_d2 {
        (2.0 * kappa).min(max)
    } else {
        kappa
    }
}
