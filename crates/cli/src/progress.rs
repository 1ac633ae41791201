//! The progress bars of the long commands (`simulate` by frames; `replay`, `view`, `log check`,
//! `log recover` by bytes of the log): drawn on stderr only when it is a terminal and the job
//! is big enough to be worth one, nothing otherwise.

use std::io::IsTerminal;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Frames below which no progress bar is drawn (a short job is done before it would show).
const PROGRESS_MIN_FRAMES: u64 = 2_000;

/// Bytes below which no progress bar is drawn (a log replayed in seconds).
const PROGRESS_MIN_BYTES: u64 = 16 << 20;

/// A bar that stays hidden until the first update of a big enough job on a terminal.
struct LazyBar {
    bar: ProgressBar,
    /// The template, with the verb in it.
    template: String,
    /// Totals below which it stays hidden.
    min_total: u64,
    terminal: bool,
    shown: bool,
}

impl LazyBar {
    fn new(template: String, min_total: u64) -> Self {
        Self {
            bar: ProgressBar::with_draw_target(None, ProgressDrawTarget::hidden()),
            template,
            min_total,
            terminal: std::io::stderr().is_terminal(),
            shown: false,
        }
    }

    fn update(&mut self, done: u64, total: u64) {
        if !self.shown && self.terminal && total >= self.min_total {
            self.shown = true;
            self.bar.set_length(total);
            self.bar.set_style(
                ProgressStyle::with_template(&self.template)
                    .unwrap_or_else(|_| ProgressStyle::default_bar())
                    .progress_chars("=> "),
            );
            self.bar.set_draw_target(ProgressDrawTarget::stderr());
            self.bar.enable_steady_tick(Duration::from_millis(200));
        }
        if self.shown {
            self.bar.set_position(done);
        }
    }

    fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

/// A frame counter shown as a bar, `VERB [====>   ] done/total frames, eta`.
pub(crate) struct FrameProgress(LazyBar);

impl FrameProgress {
    /// A hidden bar, shown at the first update of a long job on a terminal.
    pub(crate) fn new(verb: &'static str) -> Self {
        Self(LazyBar::new(
            format!("{verb} [{{bar:30}}] {{pos}}/{{len}} frames, {{eta}} left"),
            PROGRESS_MIN_FRAMES,
        ))
    }

    /// `done` of `total` frames.
    pub(crate) fn update(&mut self, done: u64, total: u64) {
        self.0.update(done, total);
    }

    /// Removes the bar from the terminal.
    pub(crate) fn finish(&self) {
        self.0.finish();
    }
}

/// A byte counter of a file being read, `VERB [====>   ] 1.2 GiB/3.4 GiB, eta`.
pub(crate) struct ByteProgress(LazyBar);

impl ByteProgress {
    /// A hidden bar, shown at the first update of a big file on a terminal.
    pub(crate) fn new(verb: &'static str) -> Self {
        Self(LazyBar::new(
            format!("{verb} [{{bar:30}}] {{bytes}}/{{total_bytes}}, {{eta}} left"),
            PROGRESS_MIN_BYTES,
        ))
    }

    /// `done` of `total` bytes.
    pub(crate) fn update(&mut self, done: u64, total: u64) {
        self.0.update(done, total);
    }

    /// Removes the bar from the terminal.
    pub(crate) fn finish(&self) {
        self.0.finish();
    }
}
