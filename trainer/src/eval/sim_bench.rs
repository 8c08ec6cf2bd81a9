//! `mochi bench sim`: the full-space simulator's time per step and Newton iterations per
//! scene, where the time of contact scenes went, and, for scenes whose `[solver]` is
//! adaptive, the adaptive solver against full space (see [`super::adaptive_bench`]).

use std::path::PathBuf;

use mochi_sim::dataset::SpeedPlan;
use mochi_sim::solver::{SolvePhases, StepReport};
use mochi_sim::{Scene, SolverSpec};

use super::adaptive_bench::{self, SweepKey};
use crate::error::{fs, TrainerResult};

/// What `mochi bench sim` runs.
#[derive(Clone, Debug, Default)]
pub struct SimBenchOptions {
    /// Frames per scene.
    pub frames: usize,
    /// Adaptive scenes: also the per-step difference to full space.
    pub per_step: bool,
    /// Adaptive scenes: also time the three linear solvers on the largest system.
    pub linear_solvers: bool,
    /// Adaptive scenes: the setting to sweep, over `values`.
    pub sweep: Option<SweepKey>,
    /// The swept values.
    pub values: Vec<f64>,
    /// Where adaptive tables and sweep charts go (`DIR/SCENE.md`, `DIR/SCENE/*.png`).
    pub out: Option<PathBuf>,
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

/// Runs the benchmark on `scenes`, printing its tables; `log` gets progress lines.
pub fn bench(scenes: &[Scene], options: &SimBenchOptions, log: &mut dyn FnMut(String)) -> TrainerResult<()> {
    println!(
        "{:14} {:>8} {:>10} {:>12} {:>10}",
        "scene", "DOF", "ms/step", "Newton it.", "max it."
    );
    let mut contact_rows = Vec::new();
    let mut adaptive_scenes = Vec::new();
    for scene in scenes {
        if matches!(scene.solver, SolverSpec::Adaptive(_)) {
            adaptive_scenes.push(scene);
            continue;
        }
        let mut problem = scene.build()?;
        let seq = problem.sequence(&SpeedPlan::constant(0.5), options.frames, scene.dataset.seed);
        let mut reports = Vec::new();
        let traj = problem.run_reporting(&seq, &mochi_sim::Silent, &mut |r| reports.push(r.clone()))?;
        if scene.contact.is_some() {
            contact_rows.push(contact_row(&scene.name, &reports));
        }
        let iters: Vec<f64> = traj.newton_iterations[1..].iter().map(|&i| i as f64).collect();
        println!(
            "{:14} {:>8} {:>10.2} {:>12.2} {:>10}",
            scene.name,
            problem.simulator.num_free_dofs(),
            1e3 * mean(&traj.step_seconds[1..]),
            mean(&iters),
            iters.iter().fold(0.0f64, |m, &i| m.max(i))
        );
    }
    if !contact_rows.is_empty() {
        println!(
            "\ncontact scenes: pairs per step, and the share of each solve's time per phase\n\
             {:14} {:>10} {:>10} {:>12} {:>8} {:>8} {:>9} {:>7} {:>7}",
            "scene", "ms/step", "Newton it.", "pairs mean", "max", "broad %", "CCD %", "assem %", "solve %"
        );
        for row in contact_rows {
            println!("{row}");
        }
    }
    for scene in adaptive_scenes {
        let frames = options.frames;
        let rows = match options.sweep {
            Some(key) => adaptive_bench::sweep(scene, key, &options.values, frames, options.per_step, log)?,
            None => vec![adaptive_bench::compare(
                scene,
                frames,
                options.per_step,
                options.linear_solvers,
                log,
            )?],
        };
        let mut table = adaptive_bench::table(&scene.name, options.sweep, &rows);
        if options.sweep.is_none() && options.linear_solvers {
            table.push('\n');
            table.push_str(&adaptive_bench::linear_solver_table(&scene.name, &rows[0]));
        }
        println!(
            "\n{}: adaptive solver against full space, {frames} frames\n{table}",
            scene.name
        );
        if let Some(dir) = &options.out {
            fs::create_dir_all(dir)?;
            let suffix = options.sweep.map_or(String::new(), |k| format!("-{}", k.slug()));
            let path = dir.join(format!("{}{suffix}.md", scene.name));
            fs::write(&path, &table)?;
            if let Some(key) = options.sweep {
                adaptive_bench::charts(&dir.join(format!("{}{suffix}", scene.name)), &scene.name, key, &rows)?;
            }
            log(format!("-> {}", path.display()));
        }
    }
    Ok(())
}

/// One row of the contact table: mean time and iterations per step, contact pairs, and
/// each phase's share of the solves' time.
fn contact_row(scene: &str, reports: &[StepReport]) -> String {
    let seconds: f64 = reports.iter().map(|r| r.seconds).sum::<f64>().max(f64::MIN_POSITIVE);
    let share = |f: &dyn Fn(&SolvePhases) -> f64| 100.0 * reports.iter().map(|r| f(&r.phases)).sum::<f64>() / seconds;
    let pairs: Vec<f64> = reports.iter().map(|r| r.contact_pairs as f64).collect();
    let iterations: Vec<f64> = reports.iter().map(|r| r.iterations as f64).collect();
    format!(
        "{:14} {:>10.2} {:>10.2} {:>12.1} {:>8} {:>8.1} {:>9.1} {:>7.1} {:>7.1}",
        scene,
        1e3 * seconds / reports.len().max(1) as f64,
        mean(&iterations),
        mean(&pairs),
        pairs.iter().fold(0.0f64, |m, &p| m.max(p)),
        share(&|p| p.broad_phase),
        share(&|p| p.ccd),
        share(&|p| p.assembly),
        share(&|p| p.linear_solve),
    )
}
