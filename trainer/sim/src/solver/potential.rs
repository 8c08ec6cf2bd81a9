//! The incremental potential of a time step without contact: the one objective Newton's
//! iterates, VBD's blocks and the line searches evaluate.

use crate::energy::{self, inertia::Inertia, StencilEnergy};

/// The incremental potential without contact, `w_inertia * inertia + w_potential *
/// sum(potentials)` at `x`, and its gradient over all dofs into `grad` when asked (the
/// inertia term is skipped where its weight is 0, as in static solves).
pub(crate) fn incremental_potential(
    inertia: &Inertia,
    potentials: &[Box<dyn StencilEnergy>],
    w_inertia: f64,
    w_potential: f64,
    x: &[f64],
    grad: Option<&mut Vec<f64>>,
) -> f64 {
    match grad {
        None => {
            let mut e = 0.0;
            if w_inertia != 0.0 {
                e += w_inertia * energy::value(inertia, x);
            }
            e + w_potential * potentials.iter().map(|p| energy::value(p.as_ref(), x)).sum::<f64>()
        }
        Some(g) => {
            g.clear();
            g.resize(x.len(), 0.0);
            let mut e = 0.0;
            if w_inertia != 0.0 {
                e += energy::add_gradient(inertia, w_inertia, x, g);
            }
            for p in potentials {
                e += energy::add_gradient(p.as_ref(), w_potential, x, g);
            }
            e
        }
    }
}
