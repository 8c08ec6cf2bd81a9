//! Diagnostic: where the body goes under one stability condition of `mochi compare`, stepped by
//! full space at several perturbations of the same discretisation (the Newton tolerance
//! tightened, two substeps a frame), the adaptive solver and the coarse mesh.
//!
//! ```sh
//! cargo run --release -p mochi-trainer --example condition_paths -- SCENE CONDITION [FRAMES] [RUNS]
//! ```
//!
//! RUNS (default all five) keeps the first RUNS of them: `2` steps full space and full space
//! at the tighter tolerance only (the matrix's reference check), for long conditions.
//!
//! CONDITION is a file stem of the matrix's conditions (`10x-stiffer`, `in-range`, ...). Every
//! tenth frame (and every frame where a path jumps) it prints each run's centre of mass and
//! its distance, as % of the rest diagonal, from the first run (full space as the matrix steps
//! it). A condition whose reference sits at a bifurcation (a squeezed body escaping to one side
//! or the other) shows runs that agree to round-off and then part by the body's width.

use mochi_sim::measure::mean_and_max_error;
use mochi_sim::{AdaptiveSettings, SolverSpec};
use mochi_trainer::eval::compare::conditions::{conditions, MatrixSpan};
use mochi_trainer::eval::compare::{slug, CHECK_TOLERANCE};
use mochi_trainer::learn::recipe::Recipe;
use mochi_trainer::methods::method::Method;
use mochi_trainer::methods::simulated::Simulated;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(scene_name), Some(condition)) = (args.first(), args.get(1)) else {
        return Err("usage: condition_paths SCENE CONDITION [FRAMES] [RUNS]".into());
    };
    let frames: usize = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(150);
    let kept: usize = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(usize::MAX).max(1);
    let problem = Recipe::load(scene_name)?.build()?;
    let span = MatrixSpan {
        frames,
        long_frames: 2 * frames,
    };
    let condition = conditions(&problem, span)
        .into_iter()
        .find(|c| slug(&c.name) == *condition)
        .ok_or_else(|| format!("`{condition}` is no condition of {scene_name}'s matrix"))?;
    let cscene = condition.scene.clone();
    let mut full = cscene.clone();
    full.solver = SolverSpec::FullSpace;
    let mut tight = full.clone();
    tight.newton.tolerance *= CHECK_TOLERANCE;
    let mut adaptive = cscene.clone();
    adaptive.solver = SolverSpec::Adaptive(AdaptiveSettings {
        modal_error: 1e-4,
        nodal_error: 1e-4,
        ..AdaptiveSettings::default()
    });
    let mut runs: Vec<(&str, Box<dyn Method>)> = vec![
        ("full space", Box::new(Simulated::new(&full, 1, "1")?)),
        ("tighter tolerance", Box::new(Simulated::new(&tight, 1, "1")?)),
        ("2 substeps", Box::new(Simulated::new(&full, 2, "2")?)),
        ("adaptive 1e-4", Box::new(Simulated::new(&adaptive, 1, "1e-4")?)),
        ("coarse", Box::new(Simulated::coarse(&full, &problem)?)),
    ];
    runs.truncate(kept);
    let bc = &condition.bc;
    for (_, m) in runs.iter_mut() {
        m.reset(bc)?;
    }
    let diagonal = problem.mesh.rest_diagonal();
    let dim = problem.mesh.dim;
    let mut last: Vec<Vec<f64>> = runs.iter().map(|(_, m)| centre(m.positions(), dim)).collect();
    print!("frame");
    for (name, _) in &runs {
        print!(" | {name}: centre (m), error %");
    }
    println!();
    for frame in 1..=condition.measured.min(bc.frames()) {
        for (_, m) in runs.iter_mut() {
            m.step(bc, frame)?;
        }
        let centres: Vec<Vec<f64>> = runs.iter().map(|(_, m)| centre(m.positions(), dim)).collect();
        let jumped = centres
            .iter()
            .zip(&last)
            .any(|(c, l)| c.iter().zip(l).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max) > 0.01);
        last = centres.clone();
        if frame % 10 != 0 && !jumped {
            continue;
        }
        print!("{frame:5}");
        let first = runs[0].1.positions().to_vec();
        for ((_, m), c) in runs.iter().zip(&centres) {
            let (mean, _) = mean_and_max_error(m.positions(), &first, dim, diagonal);
            print!(
                " | ({:+.4}, {:+.4}, {:+.4}) {:7.3}",
                c[0],
                c[1],
                c.get(2).copied().unwrap_or(0.0),
                100.0 * mean
            );
        }
        println!();
    }
    Ok(())
}

fn centre(x: &[f64], dim: usize) -> Vec<f64> {
    let n = (x.len() / dim) as f64;
    (0..dim)
        .map(|d| x.iter().skip(d).step_by(dim).sum::<f64>() / n)
        .collect()
}
