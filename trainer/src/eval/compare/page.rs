//! The page `mochi compare` writes: the speed-accuracy charts against both references with
//! the Pareto front marked, the table behind them, the learned runtime against the cheapest
//! setting of each alternative that reaches its error, and the stability matrix.

use std::path::Path;

use super::{ChartPoint, Comparison, CHECK_TOLERANCE};
use crate::error::{fs, TrainerResult};
use crate::methods::method::SequenceRun;
use crate::report::chart::{self, LabelledPoint};

/// The references, as the page names them.
const REFERENCES: [&str; 2] = ["implicit Euler at the frame time", "time-converged"];

/// Families a user would pick instead of the learned model.
const ALTERNATIVES: [&str; 3] = ["VBD", "XPBD (pypbd)", "coarse mesh"];

/// Writes `DIR/SCENE.md` and its charts `DIR/SCENE/speed-accuracy-{implicit,converged}.png`
/// (a comparison without a chart: the page of its matrix alone); `command` is the line that
/// reproduces it.
pub fn write(dir: &Path, c: &Comparison, command: &str) -> TrainerResult<()> {
    if c.sequences.is_empty() {
        fs::create_dir_all(dir)?;
        return fs::write(&dir.join(format!("{}.md", c.scene)), markdown(c, command));
    }
    let charts = dir.join(&c.scene);
    fs::create_dir_all(&charts)?;
    for (r, file) in ["speed-accuracy-implicit.png", "speed-accuracy-converged.png"]
        .iter()
        .enumerate()
    {
        let front = pareto(&c.points, r);
        let points: Vec<LabelledPoint> = c
            .points
            .iter()
            .enumerate()
            .map(|(i, p)| LabelledPoint {
                group: p.family.clone(),
                label: format!("{}{}", p.setting, if front.contains(&i) { " *" } else { "" }),
                emphasis: front.contains(&i),
                x: 1e3 * p.seconds(),
                y: 100.0 * p.error(r),
            })
            .collect();
        chart::scatter_chart(
            &charts.join(file),
            &format!(
                "{}: time per frame against error ({}; * Pareto front)",
                c.scene, REFERENCES[r]
            ),
            "ms per frame (one thread)",
            "mean vertex error (% of diagonal)",
            &points,
            true,
            true,
        )?;
    }
    fs::write(&dir.join(format!("{}.md", c.scene)), markdown(c, command))?;
    Ok(())
}

/// Indices of the points on the Pareto front against reference `r`: no other point is both
/// cheaper and more accurate.
fn pareto(points: &[ChartPoint], r: usize) -> Vec<usize> {
    (0..points.len())
        .filter(|&i| {
            let (t, e) = (points[i].seconds(), points[i].error(r));
            e.is_finite()
                && !points.iter().any(|q| {
                    let (tq, eq) = (q.seconds(), q.error(r));
                    tq <= t && eq <= e && (tq < t || eq < e)
                })
        })
        .collect()
}

/// The page's text.
pub fn markdown(c: &Comparison, command: &str) -> String {
    if c.sequences.is_empty() {
        return format!(
            "# {}: stability matrix\n\n```sh\n{command}\n```\n\n{} vertices; every method through the one \
             interface and the one measuring loop, one thread, one process.\n{}",
            c.scene,
            c.vertices,
            matrix(c)
        );
    }
    let mut s = format!(
        "# {}: every method on one chart\n\n```sh\n{command}\n```\n\n{} vertices. The chart's sequences: {}, {} \
         frames each; every method through the one interface and the one measuring loop, one thread, one process. \
         Errors are mean vertex distances as % of the rest bounding-box diagonal, averaged over frames and \
         sequences, against {} and against the {} reference.\n\n",
        c.scene,
        c.vertices,
        c.sequences
            .iter()
            .map(|p| format!("`{}` ({})", p.name, p.description))
            .collect::<Vec<_>>()
            .join(", "),
        c.frames,
        REFERENCES[0],
        REFERENCES[1],
    );
    for r in &c.converged {
        s += &if r.substeps == 1 {
            format!(
                "- `{}`: a quasi-static scene has no time step to converge in; both references are its own\n",
                r.sequence
            )
        } else {
            format!(
                "- time-converged reference of `{}`: BDF2 at {} substeps per frame (the last halving moved it \
                 {:.4}% of the diagonal at most)\n",
                r.sequence,
                r.substeps,
                100.0 * r.change
            )
        };
        for f in &r.failures {
            s += &format!(
                "  - on `{}`, {f}: methods are measured over the frames it reached\n",
                r.sequence
            );
        }
    }
    s += &format!(
        "\n![against implicit Euler]({0}/speed-accuracy-implicit.png)\n\n![against the time-converged \
         reference]({0}/speed-accuracy-converged.png)\n\n",
        c.scene
    );
    s += &summary(c);
    s += "\n| method | budget | ms/frame | iterations/frame | error % (implicit Euler) | error % (converged) | \
          stable |\n|---|---|---|---|---|---|---|\n";
    let front: Vec<usize> = pareto(&c.points, 0);
    for (i, p) in c.points.iter().enumerate() {
        let stable = p.runs.iter().filter(|r| r.stable()).count();
        s += &format!(
            "| {} | {}{} | {:.4} | {} | {} | {} | {stable} of {} |\n",
            p.family,
            p.setting,
            if front.contains(&i) { " *" } else { "" },
            1e3 * p.seconds(),
            if p.iterations().is_finite() {
                format!("{:.1}", p.iterations())
            } else {
                "-".into()
            },
            percent(p.error(0)),
            percent(p.error(1)),
            p.runs.len()
        );
    }
    if !c.unavailable.is_empty() {
        s += "\nNot on the chart:\n\n";
        for u in &c.unavailable {
            s += &format!("- {}: {}\n", u.method, u.text);
        }
    }
    if !c.matrix.is_empty() {
        s += &matrix(c);
    }
    s
}

fn percent(e: f64) -> String {
    if e.is_finite() {
        format!("{:.3}", 100.0 * e)
    } else {
        "blew up".into()
    }
}

/// The learned runtime's time per frame against the cheapest setting of each alternative
/// that reaches its error (against implicit Euler, what it imitates), or the best error each
/// reached.
fn summary(c: &Comparison) -> String {
    let Some(learned) = c
        .points
        .iter()
        .filter(|p| p.family == "learned (runtime)" && p.error(0).is_finite())
        .min_by(|a, b| a.seconds().total_cmp(&b.seconds()))
    else {
        return String::new();
    };
    let (t, e) = (learned.seconds(), learned.error(0));
    let mut parts = Vec::new();
    for family in ALTERNATIVES {
        let options: Vec<&ChartPoint> = c.points.iter().filter(|p| p.family == family).collect();
        if options.is_empty() {
            let why = c.unavailable.iter().find(|u| u.method == family);
            parts.push(format!("{family}: {}", why.map_or("not run", |u| u.text.as_str())));
            continue;
        }
        let reaching = options
            .iter()
            .filter(|p| p.error(0) <= e)
            .min_by(|a, b| a.seconds().total_cmp(&b.seconds()));
        parts.push(match reaching {
            Some(p) => format!(
                "{family} {} reaches it at {:.3} ms ({:.0}x the learned runtime's time)",
                p.setting,
                1e3 * p.seconds(),
                p.seconds() / t
            ),
            None => {
                let best = options
                    .iter()
                    .min_by(|a, b| a.error(0).total_cmp(&b.error(0)))
                    .expect("not empty");
                format!(
                    "{family} does not: its best is {}% ({}, {:.3} ms)",
                    percent(best.error(0)),
                    best.setting,
                    1e3 * best.seconds()
                )
            }
        });
    }
    format!(
        "**The learned runtime** ({}) steps a frame in {:.4} ms at {}% mean error; {}.\n",
        learned.setting,
        1e3 * t,
        percent(e),
        parts.join("; ")
    )
}

/// A cell's text: stable frames of all, then [`window_errors`].
pub(super) fn matrix_cell(run: &SequenceRun, measured: usize, last_window: usize) -> String {
    let (frames, stable) = (run.frames, run.stable_frames);
    if stable < measured {
        return format!("{stable} / {frames}, blew up");
    }
    format!("{stable} / {frames}, {}", window_errors(run, measured, last_window))
}

/// The mean error of `run` over its first `measured` frames (`blew up at frame N` when it did
/// inside them), then over its last `last_window` frames if any (or where it blew up after
/// the first window).
pub fn window_errors(run: &SequenceRun, measured: usize, last_window: usize) -> String {
    let (frames, stable) = (run.frames, run.stable_frames);
    let mean = |errors: &[f64]| {
        format!(
            "{:.3}%",
            100.0 * errors.iter().sum::<f64>() / errors.len().max(1) as f64
        )
    };
    let curve = &run.error_curves[0];
    if stable < measured {
        return format!("blew up at frame {}", stable + 1);
    }
    let first = mean(&curve[..measured]);
    if last_window == 0 {
        return first;
    }
    let last = if stable < frames {
        format!("blew up at frame {}", stable + 1)
    } else {
        format!(
            "{} (frames {}-{frames})",
            mean(&curve[frames - last_window..]),
            frames - last_window + 1
        )
    };
    format!("{first} (frames 1-{measured}), {last}")
}

fn matrix(c: &Comparison) -> String {
    let mut columns: Vec<String> = Vec::new();
    for row in &c.matrix {
        for cell in &row.cells {
            if !columns.contains(&cell.method) {
                columns.push(cell.method.clone());
            }
        }
    }
    let mut s = format!(
        "\n## Stability matrix\n\nOne setting per method under each condition; a cell gives the frames stepped \
         before a blow-up (a vertex moving more than a rest diagonal in one frame, a non-finite position or a \
         refused step) and the mean error against full space under the same condition over the measured frames \
         (the long condition's first {} frames, and its last as many where it is longer). The full-space cell \
         gives how far full space at a Newton tolerance {} times tighter parts from the reference over the \
         same frames (the long condition's first and last): near zero, the reference is fixed by the scene's discretisation; where it is not, the \
         condition puts the body at a bifurcation (round-off picks the branch) and the row's errors say which \
         branch each method took as much as how accurate it is.\n\n| condition | {} \
         |\n|---|{}\n",
        c.matrix.first().map_or(0, |r| r.frames.1),
        (1.0 / CHECK_TOLERANCE).round(),
        columns.join(" | "),
        "---|".repeat(columns.len())
    );
    for row in &c.matrix {
        let cells: Vec<String> = columns
            .iter()
            .map(|m| {
                row.cells
                    .iter()
                    .find(|c| &c.method == m)
                    .map_or("-".into(), |c| c.text.clone())
            })
            .collect();
        s += &format!("| {} | {} |\n", row.condition, cells.join(" | "));
    }
    s
}
