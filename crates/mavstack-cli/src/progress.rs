//! Progress on stderr for the long file commands (indicatif): a bar over a file's bytes
//! (`decode`, `log ...`: files of 4 MB or more), a bar over bytes coming over a link (`log
//! download`), a bar over frames (`replay`), a counter (`record`). Drawn only when stderr is
//! a terminal: never when piped, redirected or in tests.

use std::io::IsTerminal as _;

use indicatif::{ProgressBar, ProgressStyle};

/// Files smaller than this finish before a bar would be worth drawing.
const MIN_BYTES: u64 = 4 << 20;

/// A bar or a counter (nothing at all off a terminal).
pub(crate) struct Progress {
    bar: Option<ProgressBar>,
}

impl Progress {
    /// A bar labelled `what` for `total` bytes (hidden off a terminal or for small files).
    pub(crate) fn new(what: &str, total: u64) -> Self {
        Self::drawn(
            what,
            total >= MIN_BYTES,
            Some(total),
            "{msg} [{bar:32}] {binary_bytes}/{binary_total_bytes} {binary_bytes_per_sec} {eta}",
        )
    }

    /// A bar labelled `what` for `total` bytes coming over a link (drawn whatever the size:
    /// a link is slow).
    pub(crate) fn transfer(what: &str, total: u64) -> Self {
        Self::drawn(
            what,
            true,
            Some(total),
            "{msg} [{bar:32}] {binary_bytes}/{binary_total_bytes} {binary_bytes_per_sec} {eta}",
        )
    }

    /// A bar labelled `what` for `total` frames.
    pub(crate) fn frames(what: &str, total: u64) -> Self {
        Self::drawn(
            what,
            true,
            Some(total),
            "{msg} [{bar:32}] {human_pos}/{human_len} frames {per_sec} {eta}",
        )
    }

    /// A count of frames without an end, labelled `what`.
    pub(crate) fn counter(what: &str) -> Self {
        Self::drawn(
            what,
            true,
            None,
            "{spinner} {msg} {human_pos} frames {per_sec}",
        )
    }

    fn drawn(what: &str, worth_it: bool, total: Option<u64>, template: &str) -> Self {
        let on = worth_it && std::io::stderr().is_terminal();
        let bar = on.then(|| {
            let bar = total.map_or_else(ProgressBar::new_spinner, ProgressBar::new);
            let style = ProgressStyle::with_template(template).map_or_else(
                |_| ProgressStyle::default_bar(),
                |s| s.progress_chars("=> "),
            );
            bar.set_style(style);
            bar.set_message(what.to_owned());
            bar.enable_steady_tick(core::time::Duration::from_millis(200));
            bar
        });
        Self { bar }
    }

    /// `done` (bytes or frames) so far.
    pub(crate) fn set(&mut self, done: u64) {
        if let Some(bar) = &self.bar {
            bar.set_position(done);
        }
    }

    /// Removes the bar.
    pub(crate) fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
