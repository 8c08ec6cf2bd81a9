//! Model selection over cost (docs/design.md, decision 6): `mochi train` trains the decoder
//! families of `latent.selection` from the cheapest up, gives every decoder that meets the
//! reconstruction tolerance a self-supervised integrator of each width, rolls every such
//! model out over the validation sequences, times it in the runtime, and keeps the cheapest
//! one whose validation error is within `slack` of the best candidate's.
//!
//! The rule: a candidate qualifies when every validation rollout ran its whole window without
//! diverging; among those, with `best` the lowest mean validation error, the kept model is
//! the one with the fewest multiply-adds per frame (then the fewest bytes) whose error is at
//! most `(1 + slack) * best`. When no candidate qualifies, the one that stayed stable the
//! longest (then the most accurate) is kept, and the training says so.

use crate::artifact::{Artifact, CandidateRow, Method};
use crate::error::{TrainerError, TrainerResult};
use crate::learn::network::DecoderShape;
use crate::learn::recipe::{DecoderCandidate, LatentSpec};
use crate::learn::samples::IntegratorData;
use crate::pipeline::assemble::{self, build_artifact, Trained};
use crate::pipeline::distilled::distilled_candidates;
use crate::pipeline::measure::{measure, SelectionInputs};
use crate::pipeline::stages::{
    self, DecoderFamily, IntegratorShape, PcaFit, SelectedAutoencoder, StageTimes, TrainedIntegrator, TrainingFrames,
    Workspace,
};
use crate::progress::Reporter;
use mochi_sim::dataset::{self, Split};
use mochi_sim::trajectory::Trajectory;
use mochi_sim::BuiltScene;

/// A decoder trained (or fitted) for selection.
pub(crate) struct DecoderTrial {
    /// Its family.
    pub(crate) family: DecoderCandidate,
    /// The autoencoder kept for this family.
    pub(crate) selected: SelectedAutoencoder,
    /// RMS vertex error / diagonal of its reconstruction of the training frames.
    pub(crate) reconstruction: f64,
}

impl DecoderTrial {
    fn shape(&self) -> DecoderShape {
        self.selected.autoencoder.spec().shape
    }

    /// Family, latent, modes and decoder width, as the candidates table lists them.
    fn row(&self, integrator_width: usize) -> CandidateRow {
        let spec = self.selected.autoencoder.spec();
        let (modes, width) = match spec.shape {
            DecoderShape::Basis { modes, hidden, .. } => (modes, hidden),
            DecoderShape::Mlp => (0, spec.hidden),
        };
        CandidateRow {
            decoder: spec.shape.family().into(),
            latent: spec.latent as u32,
            modes: modes as u32,
            decoder_width: width as u32,
            integrator_width: integrator_width as u32,
            reconstruction: self.reconstruction,
            validation_error: f64::INFINITY,
            stable_frames: 0,
            validation_frames: 0,
            storages: Vec::new(),
            multiply_adds: 0,
            candle_microseconds: f64::NAN,
            kept: false,
        }
    }
}

/// The fewest components among `sizes` whose PCA meets `tolerance`, if any does.
fn modes_meeting(pca: &PcaFit, sizes: &[usize], tolerance: f64) -> Option<usize> {
    sizes.iter().copied().find(|&k| pca.error(k) <= tolerance)
}

/// Stage 3: one decoder per family of `latent.selection.decoders`, in order.
pub(crate) fn train_decoders(
    problem: &BuiltScene,
    spec: &LatentSpec,
    frames: &TrainingFrames,
    pca: &PcaFit,
    sizes: &[usize],
    work: &Workspace,
    times: &mut StageTimes,
    report: &dyn Reporter,
) -> TrainerResult<Vec<DecoderTrial>> {
    let largest = *sizes.iter().max().unwrap_or(&1);
    let modes = modes_meeting(pca, sizes, spec.tolerance);
    let mut trials = Vec::new();
    for &family in &spec.selection.decoders {
        let (sizes_tried, decoder_family) = match family {
            DecoderCandidate::Mlp => (sizes.to_vec(), DecoderFamily::mlp()),
            DecoderCandidate::Linear => {
                let Some(m) = modes else {
                    report.message(&format!(
                        "linear decoder: PCA misses the tolerance {:.1e} at every size up to {largest}; not tried",
                        spec.tolerance
                    ));
                    continue;
                };
                let shape = move |_| DecoderShape::Basis {
                    modes: m,
                    hidden: 0,
                    blocks: 0,
                };
                (vec![m], linear_family(shape))
            }
            DecoderCandidate::Basis(width) => {
                let m = modes.unwrap_or(largest).min(pca.full.num_components().max(1));
                let smaller: Vec<usize> = sizes.iter().copied().filter(|&k| k < m).collect();
                if smaller.is_empty() {
                    report.message(&format!(
                        "decoder mlp({width}) + basis: no latent size below the {m} modes; not tried"
                    ));
                    continue;
                }
                let shape = move |_| DecoderShape::Basis {
                    modes: m,
                    hidden: width,
                    blocks: 1,
                };
                let family = DecoderFamily {
                    shape: Box::new(shape),
                    tag: format!("basis{width}-m{m}"),
                };
                (smaller, family)
            }
        };
        let selected = if family == DecoderCandidate::Linear {
            stages::pca_autoencoder(spec, frames, pca, sizes_tried[0], &decoder_family)?
        } else {
            stages::select_autoencoder(
                problem,
                spec,
                frames,
                pca,
                &sizes_tried,
                &decoder_family,
                work,
                times,
                report,
            )?
        };
        let reconstruction = selected
            .trials
            .last()
            .and_then(|t| t.autoencoder_error)
            .unwrap_or(f64::INFINITY);
        trials.push(DecoderTrial {
            family,
            selected,
            reconstruction,
        });
    }
    if trials.is_empty() {
        return Err(TrainerError::invalid(
            "latent.selection.decoders: no decoder family could be tried (see the messages above)",
        ));
    }
    Ok(trials)
}

/// The linear family: the PCA basis itself (`linear-m6` in stage names).
fn linear_family(shape: impl Fn(usize) -> DecoderShape + 'static) -> DecoderFamily {
    let tag = match shape(0) {
        DecoderShape::Basis { modes, .. } => format!("linear-m{modes}"),
        DecoderShape::Mlp => String::new(),
    };
    DecoderFamily {
        shape: Box::new(shape),
        tag,
    }
}

/// The validation split, simulated into the workspace's dataset if missing.
pub(crate) fn validation_split(
    problem: &mut BuiltScene,
    work: &Workspace,
    report: &dyn Reporter,
) -> TrainerResult<Vec<(dataset::SequencePlan, Trajectory)>> {
    dataset::generate(
        problem,
        &work.dataset,
        Some(Split::Validation),
        false,
        &report.frames("dataset (validation)"),
    )?;
    Ok(dataset::load(problem, &work.dataset, Split::Validation)?)
}

/// One trained candidate: its decoder, its integrator and what it measured.
pub(crate) struct Candidate {
    /// Index of its decoder in the trials.
    pub(crate) decoder: usize,
    /// The self-supervised integrator.
    pub(crate) integrator: TrainedIntegrator,
    /// The integrator's shape.
    pub(crate) shape: IntegratorShape,
    /// Its row of the candidates table.
    pub(crate) row: CandidateRow,
    /// For a distilled candidate, its model: the written artifacts take its decoder
    /// ([`crate::pipeline::distill::adopt_decoder`]).
    pub(crate) distilled: Option<Artifact>,
}

/// Stage 4: a self-supervised integrator of every width for every decoder that meets the
/// tolerance (the most accurate decoder when none does), each measured; returns the
/// candidates, the rows of decoders that got none, and the index of the kept candidate.
pub(crate) fn train_candidates(
    inputs: &SelectionInputs<'_>,
    decoders: &[DecoderTrial],
    times: &mut StageTimes,
    report: &dyn Reporter,
) -> TrainerResult<(Vec<Candidate>, Vec<CandidateRow>, usize)> {
    let spec = &inputs.recipe.latent;
    let tolerance = spec.tolerance;
    let mut chosen: Vec<usize> = (0..decoders.len())
        .filter(|&i| decoders[i].reconstruction <= tolerance)
        .collect();
    if chosen.is_empty() {
        let best = (0..decoders.len())
            .min_by(|&a, &b| decoders[a].reconstruction.total_cmp(&decoders[b].reconstruction))
            .unwrap_or(0);
        report.message(&format!(
            "no decoder meets the tolerance {tolerance:.1e}; the most accurate ({}, {:.2e}) gets the integrators",
            decoders[best].shape().family(),
            decoders[best].reconstruction
        ));
        chosen.push(best);
    }
    let skipped: Vec<CandidateRow> = (0..decoders.len())
        .filter(|i| !chosen.contains(i))
        .map(|i| decoders[i].row(0))
        .collect();
    let mut candidates = Vec::new();
    for &d in &chosen {
        let trial = &decoders[d];
        let ae = &trial.selected.autoencoder;
        let colliders = spec.collider_slots(&inputs.problem.scene);
        let data = IntegratorData::new(
            inputs.problem,
            &inputs.frames.encoding,
            ae,
            &inputs.frames.sequences,
            &inputs.frames.rows,
            colliders,
        )?;
        for width in spec.selection.widths(spec.integrator.hidden) {
            let default = trial.family == DecoderCandidate::Mlp && width == spec.integrator.hidden;
            let tag = if default {
                String::new()
            } else {
                format!("-w{width}-{}", decoder_tag(trial))
            };
            let shape = IntegratorShape { width, tag };
            let name = format!("integrator ({}, width {width})", decoder_name(trial));
            report.stage(&name);
            let clock = std::time::Instant::now();
            let integrator = stages::train_integrator(
                inputs.problem,
                spec,
                &data,
                ae,
                Method::SelfSupervised,
                &shape,
                inputs.work,
            )?;
            times.record_resumed(name, clock, integrator.earlier_seconds);
            let mut row = trial.row(width);
            let artifact = build_artifact(
                inputs.recipe,
                inputs.problem,
                &inputs.frames.encoding,
                ae,
                &integrator.integrator,
                &data,
                &trial.selected.pca,
                Method::SelfSupervised,
                assemble::summary(
                    &Trained {
                        recipe: inputs.recipe,
                        problem: inputs.problem,
                        frames: inputs.frames,
                        autoencoder: &trial.selected,
                        data: &data,
                    },
                    &integrator,
                    times,
                ),
            )?;
            measure(&artifact, inputs, &mut row)?;
            // Every candidate is kept on disk, so another trade-off can be evaluated and shipped.
            let file = format!(
                "{}{}",
                inputs.recipe.scene.name,
                if shape.tag.is_empty() { "-mlp" } else { &shape.tag }
            );
            crate::error::fs::create_dir_all(inputs.candidates_dir)?;
            artifact.write(&inputs.candidates_dir.join(format!("{file}.mochi")))?;
            report.message(&format!(
                "{}: validation error {:.3}% (stable {} of {} frames), {} multiply-adds, {:.1} µs/frame",
                decoder_name(trial),
                100.0 * row.validation_error,
                row.stable_frames,
                row.validation_frames,
                row.multiply_adds,
                row.storages.first().map_or(f64::NAN, |s| s.2)
            ));
            let distill = &spec.selection.distill;
            let distilled = match trial.family == DecoderCandidate::Mlp || distill.strand_positions {
                true => distilled_candidates(&artifact, &row, inputs, times, report)?,
                false => Vec::new(),
            };
            for (model, row) in distilled {
                model.write(
                    &inputs
                        .candidates_dir
                        .join(format!("{file}-distilled-m{}.mochi", row.modes)),
                )?;
                candidates.push(Candidate {
                    decoder: d,
                    integrator: integrator.clone(),
                    shape: shape.clone(),
                    row,
                    distilled: Some(model),
                });
            }
            candidates.push(Candidate {
                decoder: d,
                integrator,
                shape,
                row,
                distilled: None,
            });
        }
    }
    let rows: Vec<&CandidateRow> = candidates.iter().map(|c| &c.row).collect();
    let (kept, qualified) = keep(&rows, spec.selection.slack);
    if !qualified {
        report.message("no candidate stayed stable over every validation frame; keeping the one that lasted longest");
    }
    candidates[kept].row.kept = true;
    Ok((candidates, skipped, kept))
}

/// The selection rule of the module docs over `rows`: the kept index, and whether it
/// qualified (stable over every validation frame).
pub(crate) fn keep(rows: &[&CandidateRow], slack: f64) -> (usize, bool) {
    let stable = |r: &CandidateRow| r.stable_frames >= r.validation_frames && r.validation_error.is_finite();
    let best = rows
        .iter()
        .filter(|r| stable(r))
        .map(|r| r.validation_error)
        .fold(f64::INFINITY, f64::min);
    let cost = |r: &CandidateRow| (r.multiply_adds, r.storages.first().map_or(0, |s| s.1));
    let qualified = (0..rows.len())
        .filter(|&i| stable(rows[i]) && rows[i].validation_error <= (1.0 + slack) * best)
        .min_by_key(|&i| cost(rows[i]));
    match qualified {
        Some(i) => (i, true),
        None => {
            let longest = (0..rows.len())
                .max_by(|&a, &b| {
                    (rows[a].stable_frames, -rows[a].validation_error)
                        .partial_cmp(&(rows[b].stable_frames, -rows[b].validation_error))
                        .unwrap_or(std::cmp::Ordering::Equal)
                })
                .unwrap_or(0);
            (longest, false)
        }
    }
}

/// Short name of a decoder trial for stage names.
fn decoder_name(trial: &DecoderTrial) -> String {
    let spec = trial.selected.autoencoder.spec();
    match spec.shape {
        DecoderShape::Mlp => format!("mlp({}) k={}", spec.hidden, spec.latent),
        DecoderShape::Basis { modes, hidden: 0, .. } => format!("linear k={modes}"),
        DecoderShape::Basis { modes, hidden, .. } => format!("mlp({hidden}) + basis({modes}) k={}", spec.latent),
    }
}

/// Tag of a decoder trial in checkpoint names.
fn decoder_tag(trial: &DecoderTrial) -> String {
    let spec = trial.selected.autoencoder.spec();
    match spec.shape {
        DecoderShape::Mlp => format!("mlp-k{}", spec.latent),
        DecoderShape::Basis { modes, hidden: 0, .. } => format!("linear-m{modes}"),
        DecoderShape::Basis { modes, hidden, .. } => format!("basis{hidden}-m{modes}-k{}", spec.latent),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(error: f64, stable: u64, macs: u64) -> CandidateRow {
        CandidateRow {
            decoder: "linear".into(),
            latent: 2,
            modes: 2,
            decoder_width: 0,
            integrator_width: 8,
            reconstruction: 1e-4,
            validation_error: error,
            stable_frames: stable,
            validation_frames: 100,
            storages: vec![("f32".into(), 4 * macs, 1.0)],
            multiply_adds: macs,
            candle_microseconds: 2.0,
            kept: false,
        }
    }

    #[test]
    fn the_cheapest_stable_candidate_within_the_slack_is_kept() {
        let rows = [
            row(0.0105, 100, 50),
            row(0.010, 100, 400),
            row(0.002, 40, 10),
            row(0.0125, 100, 20),
        ];
        let refs: Vec<&CandidateRow> = rows.iter().collect();
        // Best stable: 0.010; within 10%: 0.0105 (50) and 0.010 (400); the unstable one and
        // the one 25% above are out.
        assert_eq!(keep(&refs, 0.1), (0, true));
        assert_eq!(keep(&refs, 0.3), (3, true));
        assert_eq!(keep(&refs, 0.0), (1, true));
        // None stable: the one that lasted longest.
        let rows = [row(0.01, 40, 10), row(0.02, 60, 20)];
        let refs: Vec<&CandidateRow> = rows.iter().collect();
        assert_eq!(keep(&refs, 0.1), (1, false));
    }
}
