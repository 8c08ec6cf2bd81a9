//! Training sequences encoded relative to their boundary conditions, and the error of
//! rebuilt encodings measured where it counts: on the decoded positions.

use crate::learn::encoding::{Encoding, EncodingError, Frame};
use mochi_sim::trajectory::Trajectory;

/// One training sequence, encoded.
#[derive(Clone, Debug)]
pub struct EncodedSequence {
    /// The full-space trajectory.
    pub trajectory: Trajectory,
    /// Handle targets of every frame.
    pub targets: Vec<Vec<f64>>,
    /// Boundary-condition frame of every frame.
    pub frames: Vec<Frame>,
    /// Encoded state of every frame.
    pub encoded: Vec<Vec<f64>>,
}

/// Encodes trajectories of `problem`'s body.
pub fn encode_sequences(
    encoding: &Encoding,
    trajectories: Vec<Trajectory>,
) -> Result<Vec<EncodedSequence>, EncodingError> {
    trajectories
        .into_iter()
        .map(|trajectory| {
            let targets = trajectory
                .positions
                .iter()
                .map(|x| encoding.handle_targets(x))
                .collect::<Result<Vec<_>, _>>()?;
            let frames = targets
                .iter()
                .map(|t| encoding.frame(t))
                .collect::<Result<Vec<_>, _>>()?;
            let encoded = trajectory
                .positions
                .iter()
                .zip(&frames)
                .map(|(x, f)| encoding.encode(x, f))
                .collect::<Result<Vec<_>, _>>()?;
            Ok(EncodedSequence {
                trajectory,
                targets,
                frames,
                encoded,
            })
        })
        .collect()
}

/// The RMS vertex error of rebuilt encodings, measured where it counts: on the positions
/// decoded from them against those decoded from the frames' own encodings, summed a frame at
/// a time.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct DecodedError {
    sum: f64,
    count: usize,
}

impl DecodedError {
    /// Adds one frame: its exact encoding, the rebuilt one, its boundary-condition frame and
    /// handle targets.
    pub(crate) fn add(
        &mut self,
        encoding: &Encoding,
        exact: &[f64],
        rebuilt: &[f64],
        frame: &Frame,
        targets: &[f64],
    ) -> Result<(), EncodingError> {
        let mut a = vec![0.0; encoding.state_len()];
        let mut b = vec![0.0; encoding.state_len()];
        encoding.decode_into(exact, frame, targets, &mut a)?;
        encoding.decode_into(rebuilt, frame, targets, &mut b)?;
        self.sum += a.iter().zip(&b).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        self.count += encoding.free_vertices().len();
        Ok(())
    }

    /// RMS vertex error over the frames added, as a fraction of `diagonal`.
    pub(crate) fn rms(&self, diagonal: f64) -> f64 {
        (self.sum / self.count.max(1) as f64).sqrt() / diagonal
    }
}
