//! What long library calls (`mochi train`, `mochi eval`, `mochi demo`) tell their user: the
//! library prints nothing itself; it reports stages, messages and progress to a [`Reporter`]
//! chosen by the caller. The `mochi` binary prints them and draws terminal bars; tests and
//! examples pass [`Quiet`].

use indicatif::{ProgressBar, ProgressStyle};
use mochi_sim::Progress;

/// Receives what a long library call has to say. Every method has a default that says
/// nothing and draws no bar, so [`Quiet`] implements none.
pub trait Reporter: Sync {
    /// Stage `name` of the call starts (e.g. "dataset (train split)", "pca").
    fn stage(&self, _name: &str) {}
    /// A line of news: a measured error, a decision taken, a result.
    fn message(&self, _text: &str) {}
    /// Whether simulations and training epochs draw progress bars on the terminal.
    fn bars(&self) -> bool {
        false
    }
    /// Progress of a simulation labelled `label`, counted in frames: a terminal bar, hidden
    /// unless [`Reporter::bars`].
    fn frames(&self, label: &str) -> FramesBar {
        FramesBar::new(label, self.bars())
    }
}

/// Reports nothing.
#[derive(Clone, Copy, Debug, Default)]
pub struct Quiet;

impl Reporter for Quiet {}

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

/// A terminal bar counting the epochs of a training run, showing the last epoch's loss;
/// hidden when `visible` is false.
pub(crate) struct EpochsBar {
    bar: ProgressBar,
}

impl EpochsBar {
    /// A bar for run `name` of `epochs` epochs, `done` of them already done (a resumed run).
    pub(crate) fn new(name: &str, epochs: usize, done: usize, visible: bool) -> Self {
        if !visible {
            return EpochsBar {
                bar: ProgressBar::hidden(),
            };
        }
        let bar = ProgressBar::new(epochs as u64).with_position(done as u64);
        let style =
            ProgressStyle::with_template("{prefix} epoch {pos}/{len} [{bar:30}] loss {msg} ({elapsed}, eta {eta})")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> ");
        bar.set_style(style);
        bar.set_prefix(name.to_string());
        EpochsBar { bar }
    }

    /// One more epoch is done, with mean loss `loss`.
    pub(crate) fn epoch(&self, loss: f64) {
        self.bar.set_message(format!("{loss:.4e}"));
        self.bar.inc(1);
    }

    /// The run has ended (the bar stays on the terminal).
    pub(crate) fn finish(&self) {
        self.bar.finish();
    }
}
