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

/// RMS vertex error over all frames of `sequences`, as a fraction of `diagonal`, of the
/// positions decoded from `rebuilt` (one encoded vector per frame, in sequence order) against
/// the positions decoded from the frames' own encodings.
pub(crate) fn decoded_rms_error(
    encoding: &Encoding,
    sequences: &[EncodedSequence],
    rebuilt: &[Vec<f64>],
    diagonal: f64,
) -> Result<f64, EncodingError> {
    let frames = sequences
        .iter()
        .flat_map(|s| s.encoded.iter().zip(&s.frames).zip(&s.targets));
    let (mut sum, mut count) = (0.0, 0usize);
    let mut exact = vec![0.0; encoding.state_len()];
    let mut approx = vec![0.0; encoding.state_len()];
    for (((q, frame), targets), r) in frames.zip(rebuilt) {
        encoding.decode_into(q, frame, targets, &mut exact)?;
        encoding.decode_into(r, frame, targets, &mut approx)?;
        sum += exact.iter().zip(&approx).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        count += encoding.free_vertices().len();
    }
    Ok((sum / count.max(1) as f64).sqrt() / diagonal)
}
