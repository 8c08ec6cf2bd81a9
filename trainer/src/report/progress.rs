//! Progress bars on the terminal for the simulator's [`Progress`] reports.

use indicatif::{ProgressBar, ProgressStyle};
use mochi_sim::Progress;

/// A terminal bar counting frames, labelled with what is being simulated; hidden when
/// `visible` is false.
pub struct FramesBar {
    bar: ProgressBar,
}

impl FramesBar {
    /// A bar labelled `message`, drawn only when `visible`.
    pub fn new(message: &str, visible: bool) -> Self {
        let bar = if visible {
            ProgressBar::new(0)
        } else {
            ProgressBar::hidden()
        };
        bar.set_style(
            ProgressStyle::with_template("{msg:24} [{bar:40}] {pos}/{len} frames, {elapsed} (eta {eta})")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        bar.set_message(message.to_string());
        FramesBar { bar }
    }
}

impl Progress for FramesBar {
    fn start(&self, total: u64) {
        self.bar.set_length(total);
    }
    fn message(&self, message: &str) {
        self.bar.set_message(message.to_string());
    }
    fn advance(&self, steps: u64) {
        self.bar.inc(steps);
    }
    fn finish(&self) {
        self.bar.finish_and_clear();
    }
}
