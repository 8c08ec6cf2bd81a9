//! One row of the stability matrix ([`super::conditions`]): the full-space reference under a
//! condition, how far the same discretisation at a tighter Newton tolerance parts from it
//! (where a condition puts the body at a bifurcation, such as a squeezed body escaping to one
//! side or the other, round-off decides the branch and the other methods' errors there
//! measure which branch they took), then one setting per family against the reference.

use mochi_sim::bc::BcSequence;
use mochi_sim::{Scene, SolverSpec};

use super::conditions::Condition;
use super::lineup::{self, Budgets, Entry, Trained};
use super::{case, page, slug, Cell, CompareOptions, MatrixRow, CHECK_TOLERANCE};
use crate::error::{fs, TrainerResult};
use crate::methods::method::{run_sequence, SequenceRun};
use crate::methods::simulated::Simulated;
use crate::progress::Reporter;

/// One condition of the matrix: the full-space reference under it and how far its check run
/// parts from it ([`reference_check`]), then one setting per family.
pub fn matrix_row(
    condition: &Condition,
    trained: &Trained,
    options: &CompareOptions,
    report: &dyn Reporter,
) -> TrainerResult<MatrixRow> {
    let mut reference_scene = condition.scene.clone();
    reference_scene.solver = SolverSpec::FullSpace;
    let mut full = Simulated::new(&reference_scene, 1, "1 step(s) per frame")?;
    let (dim, diagonal) = (full.problem().mesh.dim, full.problem().mesh.rest_diagonal());
    let frames = condition.bc.frames();
    let mut cells = Vec::new();
    let mut reference = Vec::new();
    let run = run_sequence(
        &mut full,
        &condition.bc,
        frames,
        &[],
        dim,
        diagonal,
        // A peer's case carries the reference over every frame, as does a condition measured
        // again at its end.
        Some((
            &mut reference,
            if options.cases.is_some() || condition.last_window > 0 {
                frames + 1
            } else {
                condition.measured + 1
            },
        )),
    )?;
    // The scene as built for the reference serves every other method too (the solver aside,
    // it is the condition's scene).
    let problem = full.problem();
    // Where full space itself fails under the condition (a fast rod folding back in one
    // step), the others are measured over the frames it reached and stepped on for stability.
    let measured = condition.measured.min(reference.len() - 1);
    // The window at the end (its last `last_window` frames), where the reference reaches it.
    let last_window = if reference.len() == frames + 1 {
        condition.last_window.min(frames.saturating_sub(measured))
    } else {
        0
    };
    let reference_end = if last_window > 0 { frames } else { measured };
    cells.push(Cell {
        method: "full space".into(),
        text: reference_cell(&run, frames, None),
    });
    if let Some(dir) = &options.cases {
        let name = slug(&condition.name);
        fs::create_dir_all(dir)?;
        case::write_case(&dir.join(format!("{name}.npz")), problem, &condition.bc, &reference)?;
        if options.cases_only {
            return Ok(MatrixRow {
                condition: condition.name.clone(),
                frames: (frames, condition.measured),
                cells,
            });
        }
    }
    let check = reference_check(
        &reference_scene,
        &condition.bc,
        &reference[..=reference_end],
        dim,
        diagonal,
    )?;
    let spread = page::window_errors(&check, measured, last_window);
    cells[0].text = reference_cell(&run, frames, Some(&spread));
    report.message(&format!(
        "{} {}: full space at a Newton tolerance {CHECK_TOLERANCE} times the scene's parts from the reference by {spread}",
        problem.scene.name, condition.name,
    ));
    // The other methods on the condition's scene with the scene's own solver.
    let scene = &condition.scene;
    let mut entries: Vec<Entry> = lineup::simulated(scene, problem, Budgets::One)
        .into_iter()
        .skip(1)
        .collect();
    entries.extend(lineup::reduced(trained, problem, condition.change));
    entries.extend(lineup::learned(trained, condition.change, Budgets::One));
    entries.extend(lineup::peers(
        trained,
        &slug(&condition.name),
        problem.mesh.num_vertices(),
        dim,
    ));
    for entry in entries {
        let cell = match entry {
            Entry::Cannot { family, reason } => Cell {
                method: family,
                text: reason,
            },
            Entry::Runs(mut method) => {
                let refs: [&[Vec<f64>]; 1] = [&reference[..=reference_end]];
                let run = run_sequence(method.as_mut(), &condition.bc, frames, &refs, dim, diagonal, None)?;
                Cell {
                    method: format!("{} {}", method.family(), method.setting()),
                    text: page::matrix_cell(&run, measured, last_window),
                }
            }
        };
        report.message(&format!(
            "{} {}: {}: {}",
            problem.scene.name, condition.name, cell.method, cell.text
        ));
        cells.push(cell);
    }
    Ok(MatrixRow {
        condition: condition.name.clone(),
        frames: (frames, measured),
        cells,
    })
}

/// The full-space cell: its stable frames, where it fails, and how far its check run parts
/// from it ([`page::window_errors`] of [`reference_check`]) when measured.
fn reference_cell(run: &SequenceRun, frames: usize, spread: Option<&str>) -> String {
    let failure = run
        .failure
        .as_ref()
        .map_or(String::new(), |f| format!("; fails at {f}"));
    let check = spread.map_or(String::new(), |s| {
        format!("; tolerance / {}: {s}", (1.0 / CHECK_TOLERANCE).round())
    });
    format!("{} / {frames} (the reference{failure}{check})", run.stable_frames)
}

/// Full space with the Newton tolerance [`CHECK_TOLERANCE`] times the scene's, stepped under
/// `bc` over the frames of `reference` (the full-space reference of `scene`, positions of
/// frames `0..`) and measured against it (mean distance per frame, a fraction of the rest
/// diagonal): how much the reference is fixed by the discretisation alone. Where it is
/// small, a method's error against the reference is its own; where it is not, the condition
/// sits at a bifurcation (round-off picks the branch) and a method's error there also
/// measures which branch it took. A long condition's reference runs to its end, so the
/// check is read over the last window as over the first ([`page::window_errors`]).
pub fn reference_check(
    scene: &Scene,
    bc: &BcSequence,
    reference: &[Vec<f64>],
    dim: usize,
    diagonal: f64,
) -> TrainerResult<SequenceRun> {
    let mut tight = scene.clone();
    tight.solver = SolverSpec::FullSpace;
    tight.newton.tolerance *= CHECK_TOLERANCE;
    let mut check = Simulated::new(&tight, 1, "")?;
    let frames = reference.len().saturating_sub(1);
    run_sequence(&mut check, bc, frames, &[reference], dim, diagonal, None)
}
