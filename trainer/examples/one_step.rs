//! Diagnostic: one step of a trained model's integrator from ground-truth latents of its own
//! training sequences, against the encoded truth and against not moving at all.
//!
//! ```sh
//! cargo run --release -p mochi-trainer --example one_step -- ARTIFACT.mochi DATASET_DIR
//! ```
//!
//! For frames of every other training sequence it prints the mean vertex error (% of the
//! diagonal) of the decoded truth, of the prediction and of the previous frame's latent kept
//! ("stay"), and the incremental potential the integrator was trained on ([`PhysicsLoss`],
//! unbalanced) at each: a model that cannot even fit its training steps shows up here before
//! any rollout. A second line splits the scene's potentials (elastic, gravity, ...) at the
//! reference frame itself, the decoded truth and the prediction, with the whole incremental
//! potential at the reference frame: where the decoded truth has far more elastic energy
//! than the reference, the decoder's small errors stretch the body and the loss pulls the
//! integrator towards states that relieve that stretch instead of following the truth.

use mochi_sim::dataset::{self, Split};
use mochi_sim::energy;
use mochi_sim::measure::vertex_errors;
use mochi_sim::mesh::Elements;
use mochi_trainer::artifact::Artifact;
use mochi_trainer::eval::{rebuild_problem, LoadedModel};
use mochi_trainer::learn::encoding::{collider_inputs, decode_world};
use mochi_trainer::learn::loss::PhysicsLoss;
use mochi_trainer::learn::network::forward_exported;
use mochi_trainer::learn::pack;
use mochi_trainer::learn::recipe::PAPER_BC_WEIGHT;
use mochi_trainer::learn::sequences::encode_sequences;

fn main() -> anyhow::Result<()> {
    mochi_trainer::configure_threads();
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        anyhow::bail!("usage: one_step ARTIFACT.mochi DATASET_DIR");
    }
    let model = LoadedModel::new(Artifact::read(std::path::Path::new(&args[1]))?)?;
    let dir = std::path::PathBuf::from(&args[2]);
    let a = &model.artifact;
    let (problem, encoding) = rebuild_problem(a)?;
    let encoder = a.encoder().map_err(anyhow::Error::msg)?;
    let train = dataset::load(&problem, &dir, Split::Train)?
        .into_iter()
        .map(|(_, t)| t)
        .collect();
    let sequences = encode_sequences(&encoding, train)?;
    let penalty = (!matches!(problem.mesh.elements, Elements::Rods(_))).then_some(PAPER_BC_WEIGHT);
    let mut loss = PhysicsLoss::new(&problem.scene, &problem.mesh, &problem.handles, penalty)?;
    let potentials = problem.scene.build_energies(&problem.mesh)?.potentials;
    let terms = |x: &[f64]| -> String {
        potentials
            .iter()
            .map(|p| format!("{} {:.4e}", p.name(), energy::value(p.as_ref(), x)))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let dim = problem.mesh.dim;
    let mut grad = vec![0.0; encoding.state_len()];
    for (s, seq) in sequences.iter().enumerate().step_by(2) {
        let latents = seq
            .encoded
            .iter()
            .map(|q| forward_exported(&encoder, &q.iter().map(|&v| v as f32).collect::<Vec<_>>()))
            .collect::<Result<Vec<_>, _>>()?;
        let world = |z: &[f32], t: usize| -> anyhow::Result<Vec<f64>> {
            let q = model.decoder.decode(z)?;
            Ok(decode_world(&encoding, &q, &seq.frames[t], &seq.targets[t])?)
        };
        let last = seq.encoded.len() - 1;
        for t in [2, 5, 20, 60, 100, 140].into_iter().filter(|&t| t <= last) {
            let (prev, prev2) = (world(&latents[t - 1], t - 1)?, world(&latents[t - 2], t - 2)?);
            let dt = model.artifact.timed().then_some(seq.trajectory.dt);
            let states = seq.trajectory.colliders.as_ref().map_or(&[][..], |c| &c.states[t][..]);
            let colliders = collider_inputs(
                model.artifact.colliders(),
                &seq.frames[t],
                &seq.targets[t],
                dim,
                a.diagonal,
                states,
            );
            let predicted = model.integrator.step(&pack(
                &latents[t - 1],
                &latents[t - 2],
                &seq.trajectory.bc_signal,
                &colliders,
                t,
                dt,
            ))?;
            let (truth_x, pred_x, stay_x) = (
                world(&latents[t], t)?,
                world(&predicted, t)?,
                world(&latents[t - 1], t)?,
            );
            let mut measure = |x: &[f64]| -> (f64, f64) {
                let error = vertex_errors(x, &seq.trajectory.positions[t], dim, a.diagonal).sum::<f64>()
                    / problem.mesh.num_vertices() as f64;
                let energy = loss.value_and_gradient(x, &prev, &prev2, &seq.targets[t], &mut grad);
                (100.0 * error, energy)
            };
            let (truth, pred, stay) = (measure(&truth_x), measure(&pred_x), measure(&stay_x));
            println!(
                "train-{s:02} frame {t}: error % truth {:.3}, predicted {:.3}, stay {:.3} | potential truth {:.4e}, \
                 predicted {:.4e}, stay {:.4e}",
                truth.0, pred.0, stay.0, truth.1, pred.1, stay.1
            );
            let reference = &seq.trajectory.positions[t];
            let reference_potential = loss.value_and_gradient(reference, &prev, &prev2, &seq.targets[t], &mut grad);
            println!(
                "    potential reference {reference_potential:.4e} | terms: reference {}; truth {}; predicted {}",
                terms(reference),
                terms(&truth_x),
                terms(&pred_x)
            );
        }
    }
    Ok(())
}
