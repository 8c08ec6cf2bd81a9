//! The candidates of the selection over cost (`mochi train`'s `latent.selection`): a table and
//! Pareto charts of cost against validation error, every candidate in every weight storage.

use std::path::Path;

use crate::artifact::CandidateRow;
use crate::error::TrainerResult;
use crate::report::chart::{scatter_chart, LabelledPoint};

/// Short description of a candidate's networks: `linear k=6, int 64`.
pub fn candidate_name(r: &CandidateRow) -> String {
    let decoder = match r.decoder.as_str() {
        "linear" => format!("linear k={}", r.latent),
        "mlp" => format!("mlp({}) k={}", r.decoder_width, r.latent),
        "distilled" => format!("distilled mlp({}) + basis({}) k={}", r.decoder_width, r.modes, r.latent),
        _ => format!("mlp({}) + basis({}) k={}", r.decoder_width, r.modes, r.latent),
    };
    if r.integrator_width == 0 {
        decoder
    } else {
        format!("{decoder}, int {}", r.integrator_width)
    }
}

/// The candidates as a Markdown table: family, widths, bytes and multiply-adds, µs per frame
/// per storage, candle's µs, reconstruction and validation error, stable frames, kept.
pub fn candidates_table(rows: &[CandidateRow]) -> String {
    let mut s = String::from(
        "| candidate | bytes (f32) | multiply-adds | µs/frame f32 / f16 / int8 | candle µs | reconstruction | validation error % | stable frames | kept |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let (bytes, times) = if r.storages.is_empty() {
            ("-".to_string(), "-".to_string())
        } else {
            let times: Vec<String> = r.storages.iter().map(|s| format!("{:.1}", s.2)).collect();
            (r.storages[0].1.to_string(), times.join(" / "))
        };
        let (error, stable) = if r.integrator_width == 0 {
            (
                "not trained (decoder misses the tolerance)".to_string(),
                "-".to_string(),
            )
        } else {
            (
                format!("{:.3}", 100.0 * r.validation_error),
                format!("{} / {}", r.stable_frames, r.validation_frames),
            )
        };
        s.push_str(&format!(
            "| {} | {bytes} | {} | {times} | {:.1} | {:.2e} | {error} | {stable} | {} |\n",
            candidate_name(r),
            r.multiply_adds,
            r.candle_microseconds,
            r.reconstruction,
            if r.kept { "**kept**" } else { "" }
        ));
    }
    s
}

/// Writes `pareto-time.png` (µs per frame against validation error) and `pareto-bytes.png`
/// (bytes of weights against it) into `dir`: one point per candidate and weight storage,
/// coloured by storage and labelled with the candidate. The error is the `f32` model's
/// (`mochi eval`'s storage table measures what each storage adds to it).
pub fn pareto_charts(dir: &Path, scene: &str, rows: &[CandidateRow]) -> TrainerResult<()> {
    let mut time = Vec::new();
    let mut bytes = Vec::new();
    for r in rows.iter().filter(|r| r.integrator_width > 0) {
        for (storage, b, us) in &r.storages {
            let label = if r.kept {
                format!("{} (kept)", candidate_name(r))
            } else {
                candidate_name(r)
            };
            let point = |x: f64| LabelledPoint {
                group: storage.clone(),
                label: label.clone(),
                emphasis: r.kept,
                x,
                y: 100.0 * r.validation_error,
            };
            time.push(point(*us));
            bytes.push(point(*b as f64));
        }
    }
    let title = |what: &str| format!("{scene}: {what} against validation error, every candidate");
    scatter_chart(
        &dir.join("pareto-time.png"),
        &title("time per frame"),
        "µs per frame (runtime step + full decode, one thread)",
        "mean validation error (% of diagonal)",
        &time,
        true,
        true,
    )?;
    scatter_chart(
        &dir.join("pareto-bytes.png"),
        &title("weight bytes"),
        "bytes of weights",
        "mean validation error (% of diagonal)",
        &bytes,
        true,
        true,
    )
}
