//! Progress of long work (simulating a dataset), reported to whoever drives it: the
//! simulator prints nothing itself. The trainer's command line draws bars from these calls.

/// Receives progress of a long computation counted in steps (frames).
///
/// Every method has an empty default, so a caller that does not care passes [`Silent`].
pub trait Progress: Sync {
    /// Work of `total` steps starts.
    fn start(&self, _total: u64) {}
    /// What is being worked on now (e.g. the sequence's name).
    fn message(&self, _message: &str) {}
    /// `steps` more steps are done.
    fn advance(&self, _steps: u64) {}
    /// The work has ended.
    fn finish(&self) {}
}

/// Reports nothing.
#[derive(Clone, Copy, Debug, Default)]
pub struct Silent;

impl Progress for Silent {}
