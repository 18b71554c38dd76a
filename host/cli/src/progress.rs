//! Progress on stderr for the library's long stages ([`vltm::Progress`]): an indicatif bar
//! on a terminal, or plain throttled lines (`vltm: indirect: columns 120/411 (29 %), 9 s
//! left`) for logs, `nohup` and notebooks; chosen by `--progress auto|bar|plain|none`.
//! Nothing here ever writes to stdout.
//!
//! Plain lines come at most every [`INTERVAL`] (`VLTM_PROGRESS_INTERVAL_MS` overrides it);
//! under `auto` the first comes only once the command has run for [`FIRST`] (the same
//! variable overrides it), so quick commands stay quiet.

use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal as _;
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};
use vltm::Progress;

/// The default time between two plain lines.
pub const INTERVAL: Duration = Duration::from_secs(5);
/// Under `--progress auto` off a terminal: no plain line before the command has run this long.
pub const FIRST: Duration = Duration::from_secs(3);

/// `--progress`: how the long stages report.
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) enum Mode {
    /// A bar when stderr is a terminal, plain lines otherwise (after a first few seconds).
    #[default]
    Auto,
    /// A progress bar (drawn only when stderr is a terminal).
    Bar,
    /// A plain line every few seconds.
    Plain,
    /// No progress (warnings are still printed).
    None,
}

/// One stage's bookkeeping: name, total, position and when it started.
#[derive(Debug)]
pub(crate) struct Stage {
    /// The stage's name (`indirect: columns`).
    pub(crate) label: String,
    /// Units in the stage.
    pub(crate) total: u64,
    /// Units done.
    pub(crate) pos: u64,
    started: Instant,
}

impl Stage {
    /// The stage's line at `now`: `label pos/total (pct %), N s left` (the estimate from the
    /// rate so far, once some units are done).
    pub(crate) fn line(&self, now: Instant) -> String {
        let pos = self.pos.min(self.total);
        let pct = (pos * 100).checked_div(self.total).unwrap_or(100);
        let mut line = format!("{} {pos}/{} ({pct} %)", self.label, self.total);
        if pos > 0 && pos < self.total {
            let spent = now.saturating_duration_since(self.started).as_secs_f64();
            let left = spent / pos as f64 * (self.total - pos) as f64;
            line.push_str(&format!(", {} s left", left.round() as u64));
        }
        line
    }
}

/// The plain printer: stage bookkeeping and the throttle (a line at most every `interval`,
/// none before `first` since `origin`). The clock is passed in, so it is testable.
#[derive(Debug)]
pub(crate) struct Plain {
    interval: Duration,
    first: Duration,
    origin: Instant,
    last: Option<Instant>,
    /// The current stage, if one is running.
    pub(crate) stage: Option<Stage>,
}

impl Plain {
    /// A printer whose clock starts at `origin`.
    pub(crate) fn new(interval: Duration, first: Duration, origin: Instant) -> Self {
        Self {
            interval,
            first,
            origin,
            last: None,
            stage: None,
        }
    }

    /// A stage named `label` over `total` units begins at `now`.
    pub(crate) fn start(&mut self, label: &str, total: u64, now: Instant) {
        self.stage = Some(Stage {
            label: label.to_owned(),
            total,
            pos: 0,
            started: now,
        });
    }

    /// `n` more units are done at `now`; the line to print, if one is due.
    pub(crate) fn advance(&mut self, n: u64, now: Instant) -> Option<String> {
        let stage = self.stage.as_mut()?;
        stage.pos = stage.pos.saturating_add(n);
        if now.saturating_duration_since(self.origin) < self.first {
            return None;
        }
        if self
            .last
            .is_some_and(|t| now.saturating_duration_since(t) < self.interval)
        {
            return None;
        }
        self.last = Some(now);
        Some(stage.line(now))
    }

    /// The stage ended.
    pub(crate) fn finish(&mut self) {
        self.stage = None;
    }
}

enum Sink {
    /// Not yet chosen: [`Bars::set_mode`] not called (as `auto`).
    Unset,
    Bar(Option<ProgressBar>),
    Plain(Plain),
    None,
}

/// The command line's progress: one stage at a time.
pub struct Bars(Mutex<Sink>);

/// The process's progress.
pub static BARS: Bars = Bars(Mutex::new(Sink::Unset));

/// `VLTM_PROGRESS_INTERVAL_MS`, if set to a number.
fn interval_env() -> Option<Duration> {
    std::env::var("VLTM_PROGRESS_INTERVAL_MS")
        .ok()?
        .trim()
        .parse()
        .ok()
        .map(Duration::from_millis)
}

impl Bars {
    fn sink(&self) -> MutexGuard<'_, Sink> {
        let mut s = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if matches!(*s, Sink::Unset) {
            *s = Self::resolve(Mode::Auto);
        }
        s
    }

    fn resolve(mode: Mode) -> Sink {
        let env = interval_env();
        let interval = env.unwrap_or(INTERVAL);
        let terminal = std::io::stderr().is_terminal();
        match mode {
            Mode::Auto if terminal => Sink::Bar(None),
            Mode::Auto => Sink::Plain(Plain::new(interval, env.unwrap_or(FIRST), Instant::now())),
            Mode::Bar => Sink::Bar(None),
            Mode::Plain => Sink::Plain(Plain::new(interval, Duration::ZERO, Instant::now())),
            Mode::None => Sink::None,
        }
    }

    /// Chooses how progress is shown (`--progress`); call once, before any work.
    pub(crate) fn set_mode(&self, mode: Mode) {
        *self.0.lock().unwrap_or_else(|e| e.into_inner()) = Self::resolve(mode);
    }
}

impl Progress for Bars {
    fn start(&self, label: &str, total: u64) {
        let label = vltm::error::respell(label, crate::console::flag);
        match &mut *self.sink() {
            Sink::Bar(slot) => {
                let bar = ProgressBar::new(total);
                bar.set_style(
                    ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len}, {eta} left")
                        .unwrap_or_else(|_| ProgressStyle::default_bar()),
                );
                bar.set_message(label);
                if let Some(old) = slot.replace(bar) {
                    old.finish_and_clear();
                }
            }
            Sink::Plain(p) => p.start(&label, total, Instant::now()),
            Sink::Unset | Sink::None => {}
        }
    }

    fn advance(&self, n: u64) {
        match &mut *self.sink() {
            Sink::Bar(Some(b)) => b.inc(n),
            Sink::Plain(p) => {
                if let Some(line) = p.advance(n, Instant::now()) {
                    crate::console::tell!("vltm: {line}");
                }
            }
            _ => {}
        }
    }

    fn warn(&self, message: &str) {
        let message = vltm::error::respell(message, crate::console::flag);
        let line = || crate::console::tell!("vltm: warning: {message}");
        match &*self.sink() {
            Sink::Bar(Some(b)) => b.suspend(line),
            _ => line(),
        }
    }

    fn finish(&self) {
        match &mut *self.sink() {
            Sink::Bar(slot) => {
                if let Some(b) = slot.take() {
                    b.finish_and_clear();
                }
            }
            Sink::Plain(p) => p.finish(),
            Sink::Unset | Sink::None => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn plain_lines_are_throttled_and_wait_for_the_first_interval() {
        let t0 = Instant::now();
        let mut p = Plain::new(100 * MS, 250 * MS, t0);
        // No stage: nothing to say.
        assert_eq!(p.advance(1, t0), None);
        p.start("indirect: columns", 10, t0);
        // Before the first interval: quiet, but the position counts.
        assert_eq!(p.advance(1, t0 + 100 * MS), None);
        assert_eq!(p.advance(1, t0 + 200 * MS), None);
        assert_eq!(p.stage.as_ref().map(|s| s.pos), Some(2));
        // The first line once `first` has passed: 3 of 10 in 300 ms → 700 ms left (rounds to 1 s).
        assert_eq!(
            p.advance(1, t0 + 300 * MS).as_deref(),
            Some("indirect: columns 3/10 (30 %), 1 s left")
        );
        // Then at most one line per interval.
        assert_eq!(p.advance(1, t0 + 350 * MS), None);
        assert_eq!(p.advance(1, t0 + 399 * MS), None);
        assert_eq!(
            p.advance(1, t0 + 400 * MS).as_deref(),
            Some("indirect: columns 6/10 (60 %), 0 s left")
        );
    }

    #[test]
    fn stages_keep_their_own_count_and_estimate() {
        let t0 = Instant::now();
        let mut p = Plain::new(Duration::ZERO, Duration::ZERO, t0);
        p.start("indirect", 64, t0);
        assert_eq!(
            p.advance(16, t0 + Duration::from_secs(2)).as_deref(),
            Some("indirect 16/64 (25 %), 6 s left")
        );
        // A new stage starts from zero with its own clock and total.
        let t1 = t0 + Duration::from_secs(3);
        p.start("indirect: columns", 400, t1);
        assert_eq!(
            p.advance(100, t1 + Duration::from_secs(10)).as_deref(),
            Some("indirect: columns 100/400 (25 %), 30 s left")
        );
        // Past the total: clamped, no estimate.
        assert_eq!(
            p.advance(400, t1 + Duration::from_secs(11)).as_deref(),
            Some("indirect: columns 400/400 (100 %)")
        );
        p.finish();
        assert!(p.stage.is_none());
        assert_eq!(p.advance(1, t1 + Duration::from_secs(12)), None);
    }
}
