//! The progress bar of the long commands (`simulate`, `replay`, `view`): drawn on stderr only
//! when it is a terminal and the job has enough frames to be worth one, nothing otherwise.

use std::io::IsTerminal;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Frames below which no progress bar is drawn (a short job is done before it would show).
const PROGRESS_MIN_FRAMES: u64 = 2_000;

/// Bytes below which no progress bar is drawn (a log of 16 MiB replays in seconds).
const PROGRESS_MIN_BYTES: u64 = 16 << 20;

/// A counter shown as a bar, `VERB [====>   ] done/total frames, eta` (or bytes).
pub(crate) struct FrameProgress {
    bar: ProgressBar,
    verb: &'static str,
    bytes: bool,
    terminal: bool,
    shown: bool,
}

impl FrameProgress {
    /// A hidden bar counting frames, shown at the first update of a long job on a terminal.
    pub(crate) fn new(verb: &'static str) -> Self {
        Self {
            bar: ProgressBar::with_draw_target(None, ProgressDrawTarget::hidden()),
            verb,
            bytes: false,
            terminal: std::io::stderr().is_terminal(),
            shown: false,
        }
    }

    /// The same counting bytes of a file (a job that streams it).
    pub(crate) fn bytes(verb: &'static str) -> Self {
        Self {
            bytes: true,
            ..Self::new(verb)
        }
    }

    /// `done` of `total` frames (or bytes).
    pub(crate) fn update(&mut self, done: u64, total: u64) {
        let min = if self.bytes {
            PROGRESS_MIN_BYTES
        } else {
            PROGRESS_MIN_FRAMES
        };
        if !self.shown && self.terminal && total >= min {
            self.shown = true;
            self.bar.set_length(total);
            let counts = if self.bytes {
                "{bytes}/{total_bytes}"
            } else {
                "{pos}/{len} frames"
            };
            let template = format!("{} [{{bar:30}}] {counts}, {{eta}} left", self.verb);
            self.bar.set_style(
                ProgressStyle::with_template(&template)
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

    /// Removes the bar from the terminal.
    pub(crate) fn finish(&self) {
        self.bar.finish_and_clear();
    }
}
