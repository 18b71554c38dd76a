//! Progress bars on stderr for the library's long passes ([`vltm::Progress`], drawn with
//! indicatif; indicatif hides them when stderr is not a terminal).

use indicatif::{ProgressBar, ProgressStyle};
use std::sync::{Mutex, MutexGuard};
use vltm::Progress;

/// The command line's progress bar: one pass at a time.
pub struct Bars(Mutex<Option<ProgressBar>>);

/// The process's progress bar.
pub static BARS: Bars = Bars(Mutex::new(None));

impl Bars {
    fn bar(&self) -> MutexGuard<'_, Option<ProgressBar>> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Progress for Bars {
    fn start(&self, label: &str, total: u64) {
        let bar = ProgressBar::new(total);
        bar.set_style(
            ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len} rows, {eta} left")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        bar.set_message(vltm::error::respell(label, crate::console::flag));
        if let Some(old) = self.bar().replace(bar) {
            old.finish_and_clear();
        }
    }

    fn advance(&self, n: u64) {
        if let Some(b) = self.bar().as_ref() {
            b.inc(n);
        }
    }

    fn warn(&self, message: &str) {
        let message = vltm::error::respell(message, crate::console::flag);
        let line = || crate::console::tell!("vltm: warning: {message}");
        match self.bar().as_ref() {
            Some(b) => b.suspend(line),
            None => line(),
        }
    }

    fn finish(&self) {
        if let Some(b) = self.bar().take() {
            b.finish_and_clear();
        }
    }
}
