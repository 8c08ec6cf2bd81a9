//! Diagnostic: how far the full-space simulation itself carries a small error in its
//! initial state, on a scene's test sequences.
//!
//! ```sh
//! cargo run --release -p mochi-trainer --example sensitivity -- SCENE K DATASET_DIR [FRAMES] [SEQUENCE,...]
//! ```
//!
//! For each test sequence the full-space solver is run again from two perturbed starts
//! against the stored reference: (a) the reference's first frame projected onto the
//! `K`-dimensional PCA subspace of the training frames (where a latent rollout starts),
//! (b) the first frame with every free vertex moved by 1e-6 of the diagonal. Any latent
//! model starts at least as far off as (a), so the error (a) grows to bounds from below
//! what a latent rollout can reach; (b) shows whether the motion itself amplifies errors.
//! (c) restarts mid-sequence, at each of [`RESTART_FRAMES`], from the reference's frame
//! there and the one before (so with its velocity), both projected onto the subspace: the
//! error a latent rollout carries at that point, and whether the motion that follows sends
//! the full-space solver itself off the reference.
//! The dataset (both splits) is generated in `DATASET_DIR` if missing.

mod common;

use common::{curve_samples, subspace_from_args, test_sequences};
use mochi_sim::measure::mean_and_max_error;
use mochi_trainer::eval::OFF_REFERENCE;

/// Frames of the (c) restarts.
const RESTART_FRAMES: [usize; 5] = [30, 60, 90, 100, 105];

fn main() -> anyhow::Result<()> {
    mochi_trainer::configure_threads();
    let (args, pca) = subspace_from_args("sensitivity")?;
    let (mut problem, encoding, k, frames) = (args.problem, args.encoding, args.k, args.frames);
    let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
    println!("{}: starts perturbed in full space", problem.scene.name);
    for (plan, reference) in test_sequences(&problem, &args.dir, &args.only)? {
        let n = frames.min(reference.num_frames() - 1);
        let seq = problem.sequence(&plan.speeds, reference.num_frames() - 1, plan.seed);
        // The reference's frame `t` projected onto the PCA subspace (handles exact).
        let projected = |t: usize| -> anyhow::Result<Vec<f64>> {
            let x = &reference.positions[t];
            let targets = encoding.handle_targets(x)?;
            Ok(encoding.decode(&pca.reconstruct(&pca.project(&encoding.encode_state(x)?)?)?, &targets)?)
        };
        // A fixed pattern of tiny displacements on the free vertices (handles stay exact).
        let mut nudged = reference.positions[0].clone();
        for (i, &v) in encoding.free_vertices().iter().enumerate() {
            for c in 0..dim {
                let sign = if (i * 7 + c * 3) % 5 < 2 { -1.0 } else { 1.0 };
                nudged[v * dim + c] += sign * 1e-6 * diagonal;
            }
        }
        // (label, first frame, its positions, the positions one frame before)
        let mut starts = vec![
            (format!("PCA k={k} start"), 0, projected(0)?, None),
            ("1e-6 nudge".to_string(), 0, nudged, None),
        ];
        for &t in RESTART_FRAMES.iter().filter(|&&t| t < n) {
            starts.push((
                format!("PCA k={k} restart at frame {t}"),
                t,
                projected(t)?,
                Some(projected(t - 1)?),
            ));
        }
        for (label, from, start, before) in starts {
            match &before {
                Some(before) => problem.simulator.restart(&start, before),
                None => problem.simulator.reset(&start),
            }
            let mut errors = Vec::with_capacity(n - from);
            let error = |x: &[f64], t: usize| mean_and_max_error(x, &reference.positions[t], dim, diagonal);
            // The first frame `mochi eval` would count a latent model as diverged at.
            let mut first_over_half = None;
            let start_error = error(&start, from).0;
            for t in from + 1..=n {
                problem.simulator.step(&seq.targets(&problem.handles, t, dim))?;
                let (mean, max) = error(problem.simulator.positions(), t);
                errors.push(mean);
                if max > OFF_REFERENCE && first_over_half.is_none() {
                    first_over_half = Some(t);
                }
            }
            println!(
                "{} ({}), {label}: start {:.4}%, mean vertex error {:.3}% of the diagonal over frames {}-{n}, \
                 max of frame means {:.3}%, first vertex half a diagonal off at frame {}; by frame (%) {}",
                plan.name,
                plan.description,
                100.0 * start_error,
                100.0 * errors.iter().sum::<f64>() / errors.len() as f64,
                from + 1,
                100.0 * errors.iter().copied().fold(0.0, f64::max),
                first_over_half.map_or("none".to_string(), |t| t.to_string()),
                curve_samples(&errors, 4)
            );
        }
    }
    Ok(())
}
