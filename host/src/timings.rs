//! Section timings of the probes' passes, for finding their serial parts: enabled by the
//! environment variable `VLTM_TIMINGS=1` (the CLI prints the table on standard error at the
//! end of a command), off otherwise (one relaxed atomic load per section).
//!
//! A section is a stretch of wall time inside a pass, marked **serial** (one thread works:
//! reading rows, folding sums) or **parallel** (split over the thread pool: stage 1 of a batch
//! of rows, the probes' per-row pushes, imaging). Sections do not nest. With `--threads 1`
//! the time in serial sections over the whole command's wall time is the measured serial
//! fraction `f` of Amdahl's law (`speed-up(n) = 1 / (f + (1 − f)/n)`); the time in no section
//! (start-up, planning, writing the outputs) is reported apart, as a bound on what `f` misses.
//! The figures do not depend on the machine's load the way wall-clock speed-ups do (a
//! section's wall time grows with the load, but serial and parallel sections alike).
//!
//! Cost: two `Instant::now()` and one mutex lock per section when enabled (a few hundred per
//! pass); memory: one entry per section name.

use std::sync::Mutex;
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU8, Ordering};
use std::time::Instant;

/// Whether a section runs on one thread or on the pool.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// One thread works; the others wait.
    Serial,
    /// Split over the thread pool.
    Parallel,
}

/// Accumulated wall time per section: (name, kind, seconds, count).
static TABLE: Mutex<Vec<(&'static str, Kind, f64, u64)>> = Mutex::new(Vec::new());
/// 0 unknown, 1 off, 2 on.
static STATE: AtomicU8 = AtomicU8::new(0);
static START: OnceLock<Instant> = OnceLock::new();

/// Whether timings are collected (`VLTM_TIMINGS` set, not empty and not `0`).
pub fn enabled() -> bool {
    match STATE.load(Ordering::Relaxed) {
        1 => false,
        2 => true,
        _ => {
            let on = std::env::var("VLTM_TIMINGS").is_ok_and(|v| !v.is_empty() && v != "0");
            STATE.store(if on { 2 } else { 1 }, Ordering::Relaxed);
            on
        }
    }
}

/// Marks the start of the measured command (the total of [`report`] runs from here).
pub fn start() {
    if enabled() {
        let _ = START.set(Instant::now());
    }
}

/// A running section; its wall time is added to the table when dropped.
#[derive(Debug)]
#[must_use = "a section is timed until the guard is dropped"]
pub struct Section {
    t: Option<(Instant, &'static str, Kind)>,
}

/// Starts timing a section named `name` (nothing when timings are off).
pub fn section(name: &'static str, kind: Kind) -> Section {
    Section {
        t: enabled().then(|| (Instant::now(), name, kind)),
    }
}

impl Drop for Section {
    fn drop(&mut self) {
        if let Some((t, name, kind)) = self.t {
            let s = t.elapsed().as_secs_f64();
            let mut tab = TABLE.lock().unwrap_or_else(|e| e.into_inner());
            match tab.iter_mut().find(|e| e.0 == name && e.1 == kind) {
                Some(e) => {
                    e.2 += s;
                    e.3 += 1;
                }
                None => tab.push((name, kind, s, 1)),
            }
        }
    }
}

/// The measured sections and the serial fraction, as text lines (`None` when off).
pub fn report() -> Option<String> {
    if !enabled() {
        return None;
    }
    let total = START.get().map_or(0.0, |t| t.elapsed().as_secs_f64());
    let tab = TABLE.lock().unwrap_or_else(|e| e.into_inner()).clone();
    let sum = |k: Kind| tab.iter().filter(|e| e.1 == k).map(|e| e.2).sum::<f64>();
    let (ser, par) = (sum(Kind::Serial), sum(Kind::Parallel));
    let pct = |x: f64| (100.0 * x / total.max(f64::MIN_POSITIVE)).max(0.0);
    let mut s = format!(
        "timings ({} threads): {total:.3} s in all\n",
        rayon::current_num_threads()
    );
    for (name, kind, secs, n) in &tab {
        let k = if *kind == Kind::Serial {
            "serial"
        } else {
            "parallel"
        };
        s.push_str(&format!(
            "  {k:<8} {name:<28} {secs:>8.3} s {:>5.1} % ({n}x)\n",
            pct(*secs)
        ));
    }
    let other = (total - ser - par).max(0.0);
    s.push_str(&format!(
        "  serial sections {:.1} %, parallel {:.1} %, outside any section {:.1} % (serial fraction {:.1} %, at most {:.1} %)",
        pct(ser),
        pct(par),
        pct(other),
        pct(ser),
        pct(ser + other)
    ));
    Some(s)
}
