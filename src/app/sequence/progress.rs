//! The progress display of a run: a terminal bar (with the `cli` feature) or plain lines.

use std::io::IsTerminal;
use std::time::{Duration, Instant};

/// How progress is shown.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ProgressStyle {
    /// A bar on a terminal (with the `cli` feature), plain lines otherwise.
    #[default]
    Auto,
    /// Plain lines (about every 10 % or 10 s).
    Lines,
    /// Nothing until the summary.
    Quiet,
}

pub(super) struct Progress {
    total: usize,
    done: usize,
    start: Instant,
    last_line: Instant,
    last_decile: usize,
    bar: Option<Bar>,
    lines: bool,
}

/// The terminal progress bar (with the `cli` feature).
#[cfg(feature = "cli")]
type Bar = indicatif::ProgressBar;

/// Without the `cli` feature there is no terminal progress bar: [`ProgressStyle::Auto`]
/// prints lines.
#[cfg(not(feature = "cli"))]
enum Bar {}

#[cfg(not(feature = "cli"))]
impl Bar {
    fn set_position(&self, _: u64) {
        match *self {}
    }
    fn finish_and_clear(&self) {
        match *self {}
    }
}

/// A progress bar of `total` frames on the terminal, where the `cli` feature has one.
fn terminal_bar(total: usize) -> Option<Bar> {
    #[cfg(feature = "cli")]
    {
        let bar = indicatif::ProgressBar::new(total as u64);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{bar:40.cyan/blue} {pos}/{len} frames  {per_sec}  ETA {eta}  {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        Some(bar)
    }
    #[cfg(not(feature = "cli"))]
    {
        let _ = total;
        None
    }
}

impl Progress {
    pub(super) fn new(total: usize, style: ProgressStyle) -> Progress {
        let tty = std::io::stderr().is_terminal();
        let bar = (style == ProgressStyle::Auto && tty)
            .then(|| terminal_bar(total))
            .flatten();
        Progress {
            total,
            done: 0,
            start: Instant::now(),
            last_line: Instant::now(),
            last_decile: 0,
            lines: bar.is_none() && style != ProgressStyle::Quiet,
            bar,
        }
    }

    pub(super) fn frame_done(&mut self) {
        self.done += 1;
        if let Some(bar) = &self.bar {
            bar.set_position(self.done as u64);
            return;
        }
        let decile = self.done * 10 / self.total.max(1);
        let due = decile > self.last_decile || self.last_line.elapsed() >= Duration::from_secs(10);
        if self.lines && due {
            self.last_decile = decile;
            self.last_line = Instant::now();
            let elapsed = self.start.elapsed().as_secs_f64();
            let rate = self.done as f64 / elapsed.max(1e-9);
            let eta = (self.total - self.done) as f64 / rate.max(1e-9);
            crate::core::console::note!(
                "{}/{} frames ({:.0} %), {rate:.2} frames/s, ETA {eta:.0} s",
                self.done,
                self.total,
                100.0 * self.done as f64 / self.total.max(1) as f64
            );
        }
    }

    pub(super) fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
