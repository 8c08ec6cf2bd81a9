//! Cubature of a decoder's subspace (Lyu et al. 2024, Sec. 4.3): the training matrix of
//! [`mochi_sim::cubature`] built from decoded latent samples of the vanilla subspace, and the
//! fitted rule.
//!
//! Per sample `z_i` the rows are the element's energy `P_e(f(z_i))` and its reduced force
//! `J_i^T grad P_e(f(z_i))` (`r` values), each sample's rows divided by the norm of their sum
//! over all elements, so every sample counts alike.

use mochi_sim::cubature::{fit_cubature, ColumnMatrix, Cubature, CubatureEnergy, CubatureFit, CubatureSettings};
use mochi_sim::energy::{gather, Local, StencilEnergy, Want, MAX_DOF};
use mochi_sim::BuiltScene;

use super::loss::LatentSample;
use crate::artifact::reduced::CubatureData;
use crate::error::{TrainerError, TrainerResult};
use crate::learn::encoding::Encoding;
use crate::learn::network::ExportedMlp;
use crate::methods::reduced::subspace::DecoderSubspace;

/// Energy terms whose cost a cubature cuts and whose subspace Hessian the Lipschitz loss
/// regularises (every element and bending term); the others (gravity, loads, collision) are
/// cheap per-vertex terms.
pub const ELASTIC_TERMS: [&str; 5] = ["elastic", "membrane", "bending", "stretch", "bend"];

/// The elastic terms among `potentials` (those the Lipschitz loss and the cubature cover).
pub fn elastic_terms<'a>(potentials: &[&'a dyn StencilEnergy]) -> Vec<&'a dyn StencilEnergy> {
    potentials
        .iter()
        .copied()
        .filter(|p| ELASTIC_TERMS.contains(&p.name()))
        .collect()
}

/// Samples decoded: their world states, their Jacobians (`n x r` each) and `r`.
struct Decoded {
    states: Vec<Vec<f64>>,
    jacobians: Vec<Vec<f64>>,
    latent: usize,
}

/// The decoded states and Jacobians of `samples` in `decoder`'s subspace.
fn decode_samples(decoder: &ExportedMlp, encoding: &Encoding, samples: &[LatentSample]) -> TrainerResult<Decoded> {
    let first = samples
        .first()
        .ok_or_else(|| TrainerError::invalid("a cubature needs at least one latent sample"))?;
    let mut subspace = DecoderSubspace::new(decoder, encoding, &first.targets)?;
    let (n, r) = (subspace.state_len(), subspace.latent_len());
    let mut states = Vec::with_capacity(samples.len());
    let mut jacobians = Vec::with_capacity(samples.len());
    for s in samples {
        subspace.set_frame(&encoding.frame(&s.targets)?, &s.targets);
        let (mut x, mut j) = (vec![0.0; n], vec![0.0; n * r]);
        subspace.positions_and_jacobian(&s.z, &mut x, &mut j)?;
        states.push(x);
        jacobians.push(j);
    }
    Ok(Decoded {
        states,
        jacobians,
        latent: r,
    })
}

/// The training matrix of `energy` on `samples` decoded by `decoder` (module documentation).
pub fn cubature_matrix(
    decoder: &ExportedMlp,
    encoding: &Encoding,
    energy: &dyn StencilEnergy,
    samples: &[LatentSample],
) -> TrainerResult<ColumnMatrix> {
    let Decoded {
        states,
        jacobians,
        latent: r,
    } = decode_samples(decoder, encoding, samples)?;
    let dim = encoding.dim();
    let per_sample = r + 1;
    let rows = samples.len() * per_sample;
    let mut local = Local::default();
    let mut xl = [0.0; MAX_DOF];
    let mut a = ColumnMatrix::from_columns(rows, energy.len(), |e, column| {
        let verts = energy.stencil(e);
        for (i, (x, jac)) in states.iter().zip(&jacobians).enumerate() {
            let nl = gather(energy, e, x, &mut xl);
            let out = &mut column[i * per_sample..(i + 1) * per_sample];
            out[0] = energy.eval(e, &xl[..nl], Want::Gradient, &mut local);
            for (k, &v) in verts.iter().enumerate() {
                for c in 0..dim {
                    let g = local.grad[k * dim + c];
                    let row = &jac[(v * dim + c) * r..(v * dim + c + 1) * r];
                    out[1..].iter_mut().zip(row).for_each(|(o, j)| *o += g * j);
                }
            }
        }
    });
    let sums = a.row_sums();
    let norms: Vec<f64> = sums
        .chunks_exact(per_sample)
        .map(|s| s.iter().map(|v| v * v).sum::<f64>().sqrt())
        .collect();
    for e in 0..a.cols() {
        for (rows, &norm) in a.column_mut(e).chunks_exact_mut(per_sample).zip(&norms) {
            if norm > 0.0 {
                rows.iter_mut().for_each(|v| *v /= norm);
            }
        }
    }
    Ok(a)
}

/// Fits a cubature of `energy` to `decoder`'s subspace on `samples`.
pub fn fit_subspace_cubature(
    decoder: &ExportedMlp,
    encoding: &Encoding,
    energy: &dyn StencilEnergy,
    samples: &[LatentSample],
    settings: &CubatureSettings,
) -> TrainerResult<(Cubature, CubatureFit)> {
    let a = cubature_matrix(decoder, encoding, energy, samples)?;
    fit_cubature(&a, settings).map_err(|e| TrainerError::invalid(format!("cubature of `{}`: {e}", energy.name())))
}

/// A Monte Carlo cubature of each of `potentials`: `size` of its elements drawn uniformly
/// without replacement, each weighted `len / size` (every element at weight 1 when it has at
/// most `size`). Its Hessian is an unbiased estimate of the full one, and with one draw for
/// all samples of a minibatch so is every difference `H_i - H_j` of Eq. 9: a loss on fresh
/// draws sees every element in turn, where a decoder optimised against one fixed rule can
/// move its curvature into the elements the rule leaves out.
pub(crate) fn sampled_cubature<'a>(
    potentials: &[&'a dyn StencilEnergy],
    size: usize,
    rng: &mut impl rand::Rng,
) -> TrainerResult<Vec<CubatureEnergy<'a>>> {
    potentials
        .iter()
        .map(|&energy| {
            let len = energy.len();
            let take = size.min(len);
            let mut elements = rand::seq::index::sample(rng, len, take).into_vec();
            elements.sort_unstable();
            let weight = len as f64 / take.max(1) as f64;
            let rule = mochi_sim::cubature::Cubature {
                weights: vec![weight; elements.len()],
                elements,
            };
            CubatureEnergy::new(energy, rule)
                .map_err(|e| TrainerError::invalid(format!("sampled cubature of `{}`: {e}", energy.name())))
        })
        .collect()
}

/// The potential of the Lipschitz loss: each elastic term through its cubature.
pub(crate) fn cubature_energies<'a>(
    problem: &'a BuiltScene,
    cubatures: &[CubatureData],
) -> TrainerResult<Vec<CubatureEnergy<'a>>> {
    cubatures
        .iter()
        .map(|c| {
            let energy = problem
                .simulator
                .potentials()
                .iter()
                .find(|p| p.name() == c.term)
                .ok_or_else(|| TrainerError::invalid(format!("the scene has no energy term `{}`", c.term)))?;
            let rule = mochi_sim::cubature::Cubature {
                elements: c.elements.clone(),
                weights: c.weights.clone(),
            };
            CubatureEnergy::new(energy.as_ref(), rule)
                .map_err(|e| TrainerError::invalid(format!("cubature of `{}`: {e}", c.term)))
        })
        .collect()
}
