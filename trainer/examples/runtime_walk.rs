//! Diagnostic: a learned model stepped by the runtime over the long condition of
//! `mochi compare` (the in-range motion continued as a random walk) to its end, past any frame
//! the matrix counts as a blow-up, with what the runtime reported on each frame.
//!
//! ```sh
//! cargo run --release -p mochi-trainer --example runtime_walk -- ARTIFACT.mochi [FRAMES] [EVERY] [CASE.npz]
//! ```
//!
//! CASE.npz is the condition's peer case as `mochi compare SCENE --cases DIR` writes it
//! (`DIR/FRAMES-frames.npz`, `scripts/compare.sh` puts it in `target/compare/SCENE/cases`);
//! with it each line also gives the mean vertex error against its full-space reference
//! (% of the rest diagonal, frames of the window).
//!
//! FRAMES (default 10,000) is the walk's length; every EVERY frames (default 500) it prints,
//! over the frames since the last line: how many steps the runtime clamped the latent to the
//! trained range ([`mochi_runtime::RANGE_MARGIN`]) or held it (a non-finite latent), the
//! largest latent coordinate as a multiple of its trained range's half-width from the range's
//! centre, the largest distance a vertex moved in one frame and the largest distance of a
//! vertex from its rest position (both in rest diagonals; beside it, how far the handles' targets
//! themselves went from their first positions), and the frames where a vertex moved
//! more than a rest diagonal in one frame (what the matrix calls a blow-up). Bounded output
//! and a blow-up in the matrix's sense can both hold: the clamp bounds the latent, so the
//! decoded positions stay in a bounded set, while a latent crossing that set in one frame
//! moves vertices by more than a diagonal.

use std::path::Path;

use mochi_runtime::{AnyInstance, OwnedModel, Stepped, ValidModel};
use mochi_sim::measure::mean_and_max_error;
use mochi_sim::npz::NpzFile;
use mochi_trainer::artifact::Artifact;
use mochi_trainer::eval::compare::conditions::{conditions, MatrixSpan};
use mochi_trainer::learn::recipe::Recipe;
use mochi_trainer::methods::learned::{collider_states, motions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(path) = args.first() else {
        return Err("usage: runtime_walk ARTIFACT.mochi [FRAMES] [EVERY] [CASE.npz]".into());
    };
    let frames: usize = args.get(1).map(|s| s.parse()).transpose()?.unwrap_or(10_000);
    let every: usize = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(500).max(1);
    let artifact = Artifact::read(Path::new(path))?;
    let problem = Recipe::parse(&artifact.scene_toml, Path::new(&artifact.scene_path))?.build()?;
    let long_name = format!("{frames} frames");
    let walk = conditions(
        &problem,
        MatrixSpan {
            frames: 60,
            long_frames: frames,
        },
    )
    .into_iter()
    .find(|c| c.name == long_name)
    .ok_or_else(|| format!("{}'s matrix has no `{long_name}` condition", problem.scene.name))?;

    let reference = match args.get(3) {
        Some(case) => {
            let mut npz = NpzFile::open(Path::new(case))?;
            // The case must be of this walk: its handles' targets are the condition's.
            let targets = npz.array("targets")?.into_vec::<f64>("handle targets")?;
            let dim = problem.mesh.dim;
            let ours: Vec<f64> = (0..=walk.bc.frames())
                .flat_map(|f| walk.bc.targets(&problem.handles, f, dim))
                .collect();
            if targets.len() != ours.len() || targets.iter().zip(&ours).any(|(a, b)| (a - b).abs() > 1e-9) {
                return Err(format!("{case}: its handle targets are not this model's `{long_name}` walk").into());
            }
            Some(npz.array("reference")?.into_vec::<f64>("reference positions")?)
        }
        None => None,
    };
    let bytes = std::fs::read(path)?;
    let mut owned = OwnedModel::default();
    let model: ValidModel = owned.load(&bytes).map_err(|e| format!("{path}: {e:?}"))?;
    let m = model.model();
    let mut body = AnyInstance::new(&model).map_err(|e| format!("{e:?}"))?;
    let (dim, diagonal) = (problem.mesh.dim, problem.mesh.rest_diagonal());
    let mut x = vec![0.0f32; m.state_len()];
    body.decode_into(&model, &mut x).map_err(|e| format!("{e:?}"))?;
    let rest = x.clone();
    let mut last = x.clone();
    let handles0 = walk.bc.targets(&problem.handles, 0, dim);
    let (centre, half): (Vec<f32>, Vec<f32>) = m
        .latent_min()
        .iter()
        .zip(m.latent_max())
        .map(|(lo, hi)| (0.5 * (lo + hi), 0.5 * (hi - lo).max(f32::MIN_POSITIVE)))
        .unzip();
    println!(
        "{}: {} frames of `{long_name}`; per line, over the frames since the last one",
        problem.scene.name,
        walk.bc.frames().min(frames)
    );
    println!("frames | clamped | held | largest |z - centre| / half range | largest jump (diag) | farthest from rest (diag) | handles' farthest (diag) | error % | jumps > 1 diagonal at");
    let (mut clamped, mut held, mut reach, mut jump, mut far, mut driven) = (0, 0, 0.0f32, 0.0f64, 0.0f64, 0.0f64);
    let (mut error, mut measured) = (0.0f64, 0usize);
    let mut pops: Vec<usize> = Vec::new();
    let mut from = 1;
    for frame in 1..=walk.bc.frames().min(frames) {
        let motion = motions(&walk.bc, frame);
        let colliders = collider_states(&walk.bc, frame, m.colliders());
        match body
            .step_with(&model, &motion, &colliders, m.dt)
            .map_err(|e| format!("frame {frame}: {e:?}"))?
        {
            Stepped::Ok => {}
            Stepped::Clamped => clamped += 1,
            Stepped::Held => held += 1,
        }
        body.decode_into(&model, &mut x).map_err(|e| format!("{e:?}"))?;
        for ((z, c), h) in body.latent().iter().zip(&centre).zip(&half) {
            reach = reach.max((z - c).abs() / h);
        }
        let step = largest_distance(&x, &last, dim) / diagonal;
        jump = jump.max(step);
        far = far.max(largest_distance(&x, &rest, dim) / diagonal);
        let targets = walk.bc.targets(&problem.handles, frame, dim);
        driven = driven.max(largest_distance(&targets, &handles0, dim) / diagonal);
        if let Some(r) = reference
            .as_ref()
            .and_then(|r| r.get(frame * x.len()..(frame + 1) * x.len()))
        {
            error += mean_and_max_error(&x, r, dim, diagonal).0;
            measured += 1;
        }
        if step > 1.0 {
            pops.push(frame);
        }
        last.copy_from_slice(&x);
        if frame % every == 0 || frame == walk.bc.frames().min(frames) {
            let shown: Vec<String> = pops.iter().take(8).map(|f| f.to_string()).collect();
            let more = pops.len().saturating_sub(8);
            println!(
                "{from:>5}-{frame:<5} | {clamped:7} | {held:4} | {reach:8.2} | {jump:8.3} | {far:8.3} | {driven:8.3} | {} | {}{}",
                if measured > 0 { format!("{:8.3}", 100.0 * error / measured as f64) } else { "-".into() },
                if shown.is_empty() { "-".into() } else { shown.join(", ") },
                if more > 0 { format!(" and {more} more") } else { String::new() }
            );
            (clamped, held, reach, jump, far, driven) = (0, 0, 0.0, 0.0, 0.0, 0.0);
            (error, measured) = (0.0, 0);
            pops.clear();
            from = frame + 1;
        }
    }
    Ok(())
}

/// The largest distance between matching vertices of `a` and `b` (`dim` coordinates each).
/// (`mean_and_max_error` would do but passes over a NaN; this counts it as infinitely far.)
fn largest_distance<T: Copy + Into<f64>>(a: &[T], b: &[T], dim: usize) -> f64 {
    a.chunks_exact(dim)
        .zip(b.chunks_exact(dim))
        .map(|(p, q)| {
            p.iter()
                .zip(q)
                .map(|(&p, &q)| (p.into() - q.into()).powi(2))
                .sum::<f64>()
        })
        .fold(0.0f64, |m, d| if d.is_nan() { f64::INFINITY } else { m.max(d) })
        .sqrt()
}
