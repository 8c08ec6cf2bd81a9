//! Stages 1 and 2 of `mochi train` ([`super::stages`]) on the training frames: the training
//! split loaded and encoded relative to its boundary conditions ([`encode_training_split`]),
//! held in memory or, past the memory budget (`mochi train --frame-memory`), written once to
//! a file and read back a block or a minibatch at a time by every later stage
//! ([`crate::learn::frame_rows`]); and its PCA with the error of every size ([`fit_pca`]:
//! a thin SVD in memory, a randomized one in passes over the file).

use crate::error::{TrainerError, TrainerResult};
use crate::learn::encoding::{Encoding, Frame};
use crate::learn::frame_rows::{FrameRows, RowWriter, Rows};
use crate::learn::pca::{self, Pca};
use crate::learn::pca_streamed::StreamedSettings;
use crate::learn::recipe::LatentSpec;
use crate::learn::sequences::{encode_sequences, DecodedError, EncodedSequence};
use crate::progress::Reporter;
use mochi_sim::dataset::{self, Split};
use mochi_sim::BuiltScene;

use super::stages::Workspace;

/// The training split, encoded.
pub(crate) struct TrainingFrames {
    /// The encoding of the scene's body.
    pub(crate) encoding: Encoding,
    /// Every training sequence, encoded. When the frames are read from disk, a sequence keeps
    /// its boundary conditions, frames and targets, the positions of its first frame only and
    /// no encoded states.
    pub(crate) sequences: Vec<EncodedSequence>,
    /// Every encoded frame, sequence after sequence: in memory, or read from
    /// [`Workspace::frames`] a batch at a time.
    pub(crate) rows: FrameRows,
    /// Largest kinetic energy between two consecutive training frames.
    pub(crate) max_kinetic_energy: f64,
    /// Largest length of an encoded vertex over the training frames.
    pub(crate) max_radius: f64,
}

/// Loads the training split and encodes every frame relative to its boundary conditions.
/// A split whose files hold more than `work.frame_memory` bytes is encoded one sequence at a
/// time into `work.frames` and read back from there in batches by every later stage; `report`
/// says which.
pub(crate) fn encode_training_split(
    problem: &BuiltScene,
    spec: &LatentSpec,
    work: &Workspace,
    report: &dyn Reporter,
) -> TrainerResult<TrainingFrames> {
    let encoding = Encoding::new(problem, spec.rods)?;
    let files = dataset::split_paths(problem, &work.dataset, Split::Train);
    let bytes: u64 = files
        .iter()
        .filter_map(|f| std::fs::metadata(f).ok())
        .map(|m| m.len())
        .sum();
    let mut frames = TrainingFrames {
        encoding,
        sequences: Vec::new(),
        rows: FrameRows::Memory(Vec::new()),
        max_kinetic_energy: 0.0,
        max_radius: 0.0,
    };
    // The positions and their encodings each take about the files' size in memory.
    let mut writer = if 2 * bytes <= work.frame_memory {
        None
    } else {
        report.message(&format!(
            "training frames: {:.0} MiB of sequence files, over the {:.0} MiB held in memory (--frame-memory); \
             encoded into {} and read back in batches",
            bytes as f64 / MIB,
            work.frame_memory as f64 / MIB,
            work.frames.display()
        ));
        Some(
            RowWriter::create(&work.frames, frames.encoding.encoded_len())
                .map_err(|e| TrainerError::io(&work.frames, e))?,
        )
    };
    dataset::load_each(problem, &work.dataset, Split::Train, |_, trajectory| {
        let sequence = encode_sequences(&frames.encoding, vec![trajectory])?.remove(0);
        frames.add(problem, sequence, writer.is_none(), |rows, q| {
            match (&mut writer, rows) {
                (Some(writer), _) => writer.push(q).map_err(|e| TrainerError::io(&work.frames, e))?,
                (None, FrameRows::Memory(rows)) => rows.push(q.to_vec()),
                (None, FrameRows::Disk(_)) => {}
            }
            Ok(())
        })
    })?;
    if let Some(writer) = writer {
        frames.rows = FrameRows::Disk(writer.finish().map_err(|e| TrainerError::io(&work.frames, e))?);
    }
    Ok(frames)
}

const MIB: f64 = 1024.0 * 1024.0;

impl TrainingFrames {
    /// Takes in one encoded sequence: its frames go to `keep` (with the rows), its extremes
    /// into the frames' own; unless `hold`, the sequence keeps only its first frame's
    /// positions and no encoded states from here on.
    fn add(
        &mut self,
        problem: &BuiltScene,
        mut sequence: EncodedSequence,
        hold: bool,
        mut keep: impl FnMut(&mut FrameRows, &[f64]) -> TrainerResult<()>,
    ) -> TrainerResult<()> {
        let per_vertex = self.encoding.values_per_vertex();
        let masses = problem.simulator.masses();
        let positions = &sequence.trajectory.positions;
        for w in positions.windows(2) {
            let energy = mochi_sim::measure::kinetic_energy(masses, &w[1], &w[0], problem.scene.dt, problem.mesh.dim);
            self.max_kinetic_energy = self.max_kinetic_energy.max(energy);
        }
        for q in &sequence.encoded {
            for c in q.chunks_exact(per_vertex) {
                self.max_radius = self.max_radius.max(c.iter().map(|v| v * v).sum::<f64>().sqrt());
            }
            keep(&mut self.rows, q)?;
        }
        if !hold {
            sequence.trajectory.positions.truncate(1);
            sequence.trajectory.positions.shrink_to_fit();
            sequence.encoded = Vec::new();
        }
        self.sequences.push(sequence);
        Ok(())
    }

    /// The frame and handle targets of every training frame, in row order.
    pub(crate) fn steps(&self) -> Vec<(&Frame, &[f64])> {
        self.sequences
            .iter()
            .flat_map(|s| s.frames.iter().zip(s.targets.iter().map(Vec::as_slice)))
            .collect()
    }

    /// The RMS vertex error, as a fraction of `diagonal`, of the positions decoded from
    /// `rebuild(block)` (a block of encoded frames, row after row, rebuilt) against those
    /// decoded from the frames' own encodings, reading the frames a block at a time.
    pub(crate) fn decoded_rms_error(
        &self,
        diagonal: f64,
        mut rebuild: impl FnMut(&[f64]) -> TrainerResult<Vec<Vec<f64>>>,
    ) -> TrainerResult<f64> {
        let steps = self.steps();
        let mut error = DecodedError::default();
        let width = self.encoding.encoded_len();
        self.rows.for_each_block(BLOCK, |first, block| {
            let rebuilt = rebuild(block)?;
            for (i, (exact, approx)) in block.chunks_exact(width).zip(&rebuilt).enumerate() {
                let (frame, targets) = steps[first + i];
                error.add(&self.encoding, exact, approx, frame, targets)?;
            }
            Ok::<(), TrainerError>(())
        })?;
        Ok(error.rms(diagonal))
    }
}

/// Frames per block when the stages pass over every training frame.
pub(crate) const BLOCK: usize = 256;

/// The PCA of the encoded training frames and its error at every size.
pub(crate) struct PcaFit {
    /// Components up to the largest candidate size (fewer if there are fewer frames).
    pub(crate) full: Pca,
    /// RMS vertex error / diagonal with `k` components, `k` from 0 to the largest size.
    pub(crate) errors: Vec<f64>,
}

impl PcaFit {
    /// The error with `k` components (0 past the fitted sizes).
    pub(crate) fn error(&self, k: usize) -> f64 {
        self.errors.get(k).copied().unwrap_or(0.0)
    }

    /// The PCA truncated to `k` components (all of them if there are fewer).
    pub(crate) fn truncated(&self, k: usize) -> TrainerResult<Pca> {
        Ok(self.full.clone().truncated(k.min(self.full.num_components()))?)
    }
}

/// Stage 2: the PCA of `frames` up to the largest of `sizes` and its error at every size.
/// Encoded positions: the error follows from the singular values. Strand bends: the error
/// is measured on the decoded positions, where it counts.
pub(crate) fn fit_pca(
    frames: &TrainingFrames,
    sizes: &[usize],
    tolerance: f64,
    diagonal: f64,
    report: &dyn Reporter,
) -> TrainerResult<PcaFit> {
    let largest = *sizes.iter().max().unwrap_or(&1);
    let encoding = &frames.encoding;
    let count = frames.rows.count();
    let (full, errors) = match &frames.rows {
        FrameRows::Memory(rows) => {
            let errors = if encoding.strand_bends() {
                Vec::new()
            } else {
                pca::smallest_k_for(tolerance, rows, encoding.values_per_vertex(), diagonal)?.errors
            };
            (Pca::fit(rows, largest.min(count))?, errors)
        }
        FrameRows::Disk(_) => {
            let k = largest.min(count).min(frames.rows.width());
            let streamed = Pca::fit_streamed(&frames.rows, k, &StreamedSettings::default())?;
            let vertices = (count * frames.rows.width() / encoding.values_per_vertex()) as f64;
            let errors = (0..=k)
                .map(|k| (streamed.residual_squares(k) / vertices).sqrt() / diagonal)
                .collect();
            (streamed.pca, errors)
        }
    };
    let mut fit = PcaFit { full, errors };
    if encoding.strand_bends() {
        fit.errors = (0..=largest)
            .map(|k| {
                let pca_k = fit.truncated(k)?;
                let width = frames.rows.width();
                frames.decoded_rms_error(diagonal, |block| {
                    Ok(block
                        .chunks_exact(width)
                        .map(|q| pca_k.reconstruct(&pca_k.project(q)?))
                        .collect::<Result<Vec<_>, _>>()?)
                })
            })
            .collect::<TrainerResult<Vec<f64>>>()?;
    }
    let listed: Vec<String> = (1..=largest).map(|k| format!("{k}: {:.2e}", fit.error(k))).collect();
    report.message(&format!(
        "PCA RMS vertex error / diagonal by size: {}",
        listed.join(", ")
    ));
    Ok(fit)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::network::{Autoencoder, AutoencoderSpec, DecoderShape};
    use crate::learn::recipe::Recipe;
    use crate::learn::samples::IntegratorData;
    use crate::progress::Quiet;

    /// A 8x2x2-cell cantilever whose clamp translates and rotates (3 training sequences of
    /// 41 frames).
    const SCENE: &str = include_str!("../../sim/tests/fixtures/tiny-train.toml");

    /// The scene and its training split simulated into `dir/dataset`, encoded with every
    /// frame in memory and with the frames in a file (a budget of 0 bytes), with the
    /// workspaces of the two.
    fn both_ways(dir: &std::path::Path) -> (BuiltScene, [(TrainingFrames, Workspace); 2]) {
        let recipe = Recipe::parse(SCENE, std::path::Path::new("frames.toml")).unwrap();
        let mut problem = recipe.build().unwrap();
        let silent = &mochi_sim::Silent;
        dataset::generate(&mut problem, &dir.join("dataset"), Some(Split::Train), false, silent).unwrap();
        let encoded = [u64::MAX, 0].map(|frame_memory| {
            let work = Workspace {
                dataset: dir.join("dataset"),
                frames: dir.join(format!("frames-{frame_memory}.f64")),
                frame_memory,
                checkpoints: dir.join("checkpoints"),
                resume: false,
                bars: false,
            };
            (
                encode_training_split(&problem, &recipe.latent, &work, &Quiet).unwrap(),
                work,
            )
        });
        (problem, encoded)
    }

    fn all_rows(rows: &FrameRows) -> Vec<f64> {
        let mut out = Vec::new();
        rows.gather_f64(&(0..rows.count()).collect::<Vec<_>>(), &mut out)
            .unwrap();
        out
    }

    /// Past the budget the frames go to a file and come back bit for bit; the sequences keep
    /// what the later stages read, and the extremes are the same.
    #[test]
    fn frames_read_from_disk_are_the_frames_held_in_memory() {
        let dir = tempfile::tempdir().unwrap();
        let (_, [(memory, memory_work), (disk, disk_work)]) = both_ways(dir.path());
        assert!(!memory.rows.on_disk() && disk.rows.on_disk());
        assert!(!memory_work.frames.exists() && disk_work.frames.exists());
        assert_eq!(memory.rows.count(), 3 * 41);
        assert_eq!(all_rows(&memory.rows), all_rows(&disk.rows));
        assert_eq!(memory.max_radius, disk.max_radius);
        assert_eq!(memory.max_kinetic_energy, disk.max_kinetic_energy);
        assert!(memory.max_kinetic_energy > 0.0);
        for (m, d) in memory.sequences.iter().zip(&disk.sequences) {
            assert_eq!(m.frames.len(), d.frames.len());
            assert_eq!(m.targets, d.targets);
            assert_eq!(d.trajectory.positions.len(), 1, "the first frame only");
            assert_eq!(m.trajectory.positions[0], d.trajectory.positions[0]);
            assert!(d.encoded.is_empty());
        }
        assert_eq!(memory.steps().len(), memory.rows.count());
    }

    /// The randomized PCA in passes over the file meets the thin SVD: the same errors by
    /// size, the same leading components; and the integrator's samples are the same.
    #[test]
    fn pca_and_samples_from_disk_match_those_from_memory() {
        let dir = tempfile::tempdir().unwrap();
        let (problem, [(memory, _), (disk, _)]) = both_ways(dir.path());
        let diagonal = problem.mesh.rest_diagonal();
        let sizes = [2, 4];
        let a = fit_pca(&memory, &sizes, 2e-3, diagonal, &Quiet).unwrap();
        let b = fit_pca(&disk, &sizes, 2e-3, diagonal, &Quiet).unwrap();
        for k in 0..=4 {
            let (x, y) = (a.error(k), b.error(k));
            assert!((x - y).abs() <= 1e-6 * x.max(1e-9), "size {k}: {x:.6e} against {y:.6e}");
        }
        for (u, v) in a.full.basis.iter().zip(&b.full.basis).take(2) {
            let cos: f64 = u.iter().zip(v).map(|(u, v)| u * v).sum();
            assert!((cos - 1.0).abs() < 1e-6, "cos {cos}");
        }
        let pca = a.truncated(2).unwrap();
        let spec = AutoencoderSpec {
            input: memory.encoding.encoded_len(),
            latent: 2,
            hidden: 8,
            blocks: 1,
            shape: DecoderShape::Mlp,
        };
        let ae = Autoencoder::new_pca_init(spec, &pca.mean, &pca.basis, 1).unwrap();
        let from_memory =
            IntegratorData::new(&problem, &memory.encoding, &ae, &memory.sequences, &memory.rows, 0).unwrap();
        let from_disk = IntegratorData::new(&problem, &disk.encoding, &ae, &disk.sequences, &disk.rows, 0).unwrap();
        assert_eq!(from_memory.inputs, from_disk.inputs);
        assert_eq!(from_memory.latents, from_disk.latents);
    }
}
