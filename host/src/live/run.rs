//! A live run's state ([`LiveRun`]): the rows received and stored, the probes' [`Partial`]
//! states and the rows they hold, the summed transient; rows are received one at a time and
//! folded into every probe in batches.

use std::ops::Range;
use std::path::{Path, PathBuf};

use super::probes::{LiveOptions, LiveProbe, exec, probes};
use super::source::Arrival;
use crate::budget;
use crate::error::{Error, Result};
use crate::io::capture::{Capture, Geometry};
use crate::probe::partial::{self, Finished, Partial};
use crate::probe::{ColumnGate, window_coverage};
use vltm_kernel::Point;

/// What the end's surface model ([`LiveOptions::model`]) came to.
#[derive(Clone, Debug, PartialEq)]
pub enum EndModel {
    /// Subtracted from the stored rows before the indirect light and the corrected columns.
    Used {
        /// Its lit facets.
        facets: usize,
        /// Its surfels.
        surfels: usize,
        /// The fraction of the capture's energy (`Σ H²`) it explains.
        explained: f64,
        /// The share of that energy the photon noise of a capture of counts holds
        /// ([`crate::probe::SurfaceModel::photon_noise`]).
        photon_noise: Option<f64>,
        /// The model's time (s).
        seconds: f64,
    },
    /// Not used: the time windows instead. Why, one line (other parameters written `$name`).
    Unused(String),
}

/// The state of a live run: the rows received, the probes' states, the summed transient.
#[derive(Debug)]
pub struct LiveRun {
    pub(super) opts: LiveOptions,
    pub(super) capture: Capture,
    pub(super) received: usize,
    /// Rows in the probes' states (the resumed states' rows included).
    pub(super) folded: usize,
    /// The rows the resumed states hold (ascending, disjoint).
    pub(super) held: Vec<Range<usize>>,
    /// Rows below this are folded or held.
    pub(super) next: usize,
    /// Rows below this were not stored (passed over by a resumed run).
    pub(super) stored_from: usize,
    pub(super) probes: Vec<LiveProbe>,
    pub(super) transient: Vec<f64>,
    pub(super) photons: f64,
    pub(super) dwell: Vec<f64>,
    pub(super) warnings: Vec<String>,
    /// What the end's surface model came to (set at the end when one was asked for).
    pub(super) end_model: Option<EndModel>,
}

impl LiveRun {
    /// A run over a capture of geometry `g`; `resume`: the states of an interrupted run, one
    /// per probe (direct light first, then the columns), all over the same rows: rows `0..k`
    /// for a live run's states, any rows for the states of `--partial` or of the firmware
    /// (e.g. the scan's last rows). The rows the states hold are not folded again.
    ///
    /// # Errors
    /// [`Error::Argument`] (`--resume`) for states that do not match the probes, the capture
    /// or the parameters, or hold different rows; the probes' configuration errors; the
    /// memory budget for the stored rows.
    pub fn new(g: &Geometry, opts: LiveOptions, resume: Vec<(PathBuf, Partial)>) -> Result<Self> {
        let n = g.lasers.len() * g.spads_per_row() * g.nt;
        budget::check(
            || "the live run's rows (kept for the in-focus indirect light)".to_string(),
            budget::bytes(n, 4),
        )?;
        let mut capture = Capture::new(g.clone(), vec![0.0; n], Path::new("live"))?;
        let (probes, held) = probes(&mut capture, &opts, resume)?;
        // The probes' window rule (an empty window already failed above, in the probes' own
        // set-up, with the one line every probe gives): the warnings for few paths in it.
        let base = opts.wave.config(g)?;
        let mut warnings = Vec::new();
        let mut warn = |foci: Option<&[Point]>| -> Result<()> {
            let c = window_coverage(g, &base, foci, &opts.volume.points, ColumnGate::TwoBounce)?;
            if let Some(w) = c.warning()
                && !warnings.contains(&w)
            {
                warnings.push(w);
            }
            Ok(())
        };
        warn(None)?;
        for a in &opts.focus {
            warn(Some(std::slice::from_ref(a)))?;
        }
        let nt = g.nt;
        Ok(Self {
            opts,
            capture,
            received: 0,
            folded: held.iter().map(ExactSizeIterator::len).sum(),
            held,
            next: 0,
            stored_from: 0,
            probes,
            transient: vec![0.0; nt],
            photons: 0.0,
            dwell: Vec::new(),
            warnings,
            end_model: None,
        })
    }

    /// The probes' warnings of the window rule ([`window_coverage`]: few of the paths through
    /// the volume lie in the capture's time window), as `direct` and `column` give them.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// What the end's surface model ([`LiveOptions::model`]) came to: `None` before the end or
    /// when none was asked for.
    pub fn end_model(&self) -> Option<&EndModel> {
        self.end_model.as_ref()
    }

    /// The geometry.
    pub fn geometry(&self) -> &Geometry {
        &self.capture.geometry
    }

    /// The options.
    pub fn options(&self) -> &LiveOptions {
        &self.opts
    }

    /// Laser rows of the scan.
    pub fn total_rows(&self) -> usize {
        self.capture.geometry.lasers.len()
    }

    /// Rows received.
    pub fn received(&self) -> usize {
        self.received
    }

    /// Rows folded into the probes (those of resumed states included).
    pub fn folded(&self) -> usize {
        self.folded
    }

    /// Photons received (since the start of this run).
    pub fn photons(&self) -> f64 {
        self.photons
    }

    /// The median acquisition time of a row (s) among the rows that carried one.
    pub fn dwell(&self) -> Option<f64> {
        let mut d = self.dwell.clone();
        if d.is_empty() {
            return None;
        }
        d.sort_by(f64::total_cmp);
        Some(d[d.len() / 2])
    }

    /// The capture's summed transient so far: counts per bin over every row and SPAD.
    pub fn transient(&self) -> &[f64] {
        &self.transient
    }

    /// The probes.
    pub fn probes(&self) -> &[LiveProbe] {
        &self.probes
    }

    /// The rows received (zeros for rows not yet received).
    pub fn capture(&self) -> &Capture {
        &self.capture
    }

    /// Stores a row.
    ///
    /// # Errors
    /// [`Error::Format`] (`rows`) for a row out of order or of the wrong length.
    pub fn receive(&mut self, a: Arrival) -> Result<()> {
        let per_row = self.capture.geometry.spads_per_row() * self.capture.geometry.nt;
        if a.index != self.received || a.data.len() != per_row {
            return Err(Error::format(
                Path::new(&self.opts.capture_name),
                "rows",
                format!("row {} of {per_row} values", self.received),
                format!("row {} of {} values", a.index, a.data.len()),
            ));
        }
        self.store(&a);
        self.photons += a.photons;
        if let Some(d) = a.dwell.filter(|d| d.is_finite() && *d > 0.0) {
            self.dwell.push(d);
        }
        self.received += 1;
        Ok(())
    }

    /// The rows at the start of the scan that the resumed states hold (`0..k`: `k`, else 0):
    /// a source may pass over them ([`LiveRun::skip_received`]).
    pub fn held_prefix(&self) -> usize {
        match self.held.first() {
            Some(r) if r.start == 0 => r.end,
            _ => 0,
        }
    }

    /// Rows `0..k` (held by the resumed states, `k ≤` [`LiveRun::held_prefix`]) will not
    /// arrive: the next row received is row `k`. Their values are not stored until
    /// [`LiveRun::refill`].
    ///
    /// # Errors
    /// [`Error::Argument`] (`resume`) after rows arrived, or for rows the states do not hold.
    pub fn skip_received(&mut self, k: usize) -> Result<()> {
        if self.received > 0 || k > self.held_prefix() {
            return Err(Error::arg(
                "resume",
                format!(
                    "cannot pass over rows 0:{k} (the states hold 0:{})",
                    self.held_prefix()
                ),
            ));
        }
        self.received = k;
        self.next = k;
        self.stored_from = k;
        Ok(())
    }

    /// Rows received but not folded yet (waiting for the next fold).
    pub fn pending(&self) -> usize {
        self.received.saturating_sub(self.next)
    }

    /// Rows below this were passed over and are not stored (0 once every row is).
    pub fn stored_from(&self) -> usize {
        self.stored_from
    }

    /// Stores rows passed over by [`LiveRun::skip_received`] (read again after the stream's
    /// end), for the in-focus indirect light; adds them to the summed transient.
    ///
    /// # Errors
    /// [`Error::Format`] (`rows`) unless `rows` are exactly rows `0..stored_from`, in order.
    pub fn refill(&mut self, rows: Vec<Arrival>) -> Result<()> {
        let per_row = self.capture.geometry.spads_per_row() * self.capture.geometry.nt;
        let k = self.stored_from;
        if rows.len() != k
            || rows
                .iter()
                .enumerate()
                .any(|(i, a)| a.index != i || a.data.len() != per_row)
        {
            return Err(Error::format(
                Path::new(&self.opts.capture_name),
                "rows",
                format!("rows 0:{k} read again, of {per_row} values"),
                format!("{} rows", rows.len()),
            ));
        }
        for a in rows {
            self.store(&a);
        }
        self.stored_from = 0;
        Ok(())
    }

    fn store(&mut self, a: &Arrival) {
        let per_row = self.capture.geometry.spads_per_row() * self.capture.geometry.nt;
        let nt = self.capture.geometry.nt;
        for h in a.data.chunks(nt) {
            for (t, &x) in self.transient.iter_mut().zip(h) {
                *t += f64::from(x);
            }
        }
        self.capture.data[a.index * per_row..(a.index + 1) * per_row].copy_from_slice(&a.data);
    }

    /// Folds the rows received but neither folded nor held into every probe; returns how
    /// many.
    ///
    /// # Errors
    /// The probes' errors.
    pub fn fold(&mut self) -> Result<usize> {
        let upto = self.received;
        if upto <= self.next {
            return Ok(0);
        }
        // next..upto less the held rows.
        let mut ranges = Vec::new();
        let mut a = self.next;
        for h in &self.held {
            if h.end <= a {
                continue;
            }
            if h.start >= upto {
                break;
            }
            if h.start > a {
                ranges.push(a..h.start);
            }
            a = a.max(h.end);
        }
        if a < upto {
            ranges.push(a..upto);
        }
        let mut n = 0;
        for rows in ranges {
            for p in &mut self.probes {
                let part = partial::accumulate(
                    &mut self.capture,
                    self.opts.file_bytes,
                    &self.opts.capture_name,
                    &self.opts.volume,
                    &p.task,
                    &self.opts.wave,
                    exec(self.opts.path),
                    rows.clone(),
                )?;
                let state = std::mem::replace(&mut p.state, part.clone());
                p.state = Partial::merge(vec![state, part], &[])?;
            }
            n += rows.len();
        }
        self.next = upto;
        self.folded += n;
        Ok(n)
    }

    /// Whether every row is folded.
    pub fn complete(&self) -> bool {
        self.folded == self.total_rows()
    }

    /// The probe `i`'s volume from the rows folded so far.
    ///
    /// # Errors
    /// As [`Partial::preview`].
    pub fn preview(&self, i: usize) -> Result<Finished> {
        self.probes[i].state.preview()
    }
}
