//! Where a live run's rows come from: a [`LiveSource`] is a PTU file still being written or a
//! pipe ([`Follower`]), or any capture replayed at a fixed rate ([`Replay`]); each row arrives
//! as an [`Arrival`].

use std::ops::Range;
use std::path::Path;
use std::time::{Duration, Instant};

use crate::budget;
use crate::error::{Error, Result};
use crate::io::capture::{Capture, Geometry, RowSource};
use crate::io::ptu::{FollowedRow, Follower};

/// One laser row as it arrives.
#[derive(Clone, Debug, PartialEq)]
pub struct Arrival {
    /// Laser row index (rows arrive in order 0, 1, 2, …).
    pub index: usize,
    /// Histograms, `Ks·Nt` values, SPAD-major.
    pub data: Vec<f32>,
    /// Photons (the sum of the histograms for a replayed capture).
    pub photons: f64,
    /// The row's acquisition time (s), when the source knows it (the PTU sync clock).
    pub dwell: Option<f64>,
    /// Byte position in the stream after the row, for a T3 stream.
    pub position: Option<u64>,
}

impl From<FollowedRow> for Arrival {
    fn from(r: FollowedRow) -> Self {
        Self {
            index: r.index,
            photons: r.photons as f64,
            data: r.data,
            dwell: r.seconds,
            position: Some(r.position),
        }
    }
}

/// Where rows come from, in scan order, as they are acquired.
pub trait LiveSource: Send {
    /// The capture's geometry (known before the first row).
    fn geometry(&self) -> &Geometry;
    /// The next row, waiting for it; `None` after the last row.
    ///
    /// # Errors
    /// The source's read and format errors.
    fn next_row(&mut self) -> Result<Option<Arrival>>;
    /// Passes over rows `0..k` (before the first row is read): the next row is row `k`.
    /// Returns whether the source did (the default: it cannot, every row is read).
    fn skip_rows(&mut self, k: usize) -> bool {
        let _ = k;
        false
    }
    /// Whether [`LiveSource::reread`] can read rows again (a file; not a pipe).
    fn can_reread(&self) -> bool {
        false
    }
    /// Rows `rows` again, after the stream's end (the rows skipped by a resumed run, for the
    /// in-focus indirect light).
    ///
    /// # Errors
    /// [`Error::Argument`] for a source that cannot ([`LiveSource::can_reread`]); the
    /// source's read and format errors.
    fn reread(&mut self, rows: Range<usize>) -> Result<Vec<Arrival>> {
        let _ = rows;
        Err(Error::arg("resume", "this source cannot be read again"))
    }
}

impl LiveSource for Follower {
    fn geometry(&self) -> &Geometry {
        Self::geometry(self)
    }
    fn next_row(&mut self) -> Result<Option<Arrival>> {
        Ok(Self::next_row(self)?.map(Arrival::from))
    }
    fn skip_rows(&mut self, k: usize) -> bool {
        Self::skip_rows(self, k);
        true
    }
    fn can_reread(&self) -> bool {
        matches!(self.reopen(), Ok(Some(_)))
    }
    fn reread(&mut self, rows: Range<usize>) -> Result<Vec<Arrival>> {
        let Some(mut f) = self.reopen()? else {
            return Err(Error::arg(
                "resume",
                "a stream on standard input cannot be read again",
            ));
        };
        f.skip_rows(rows.start);
        let mut out = Vec::with_capacity(rows.len());
        while out.len() < rows.len() {
            match f.next_row()? {
                Some(r) => out.push(Arrival::from(r)),
                None => break,
            }
        }
        Ok(out)
    }
}

/// A capture replayed row by row at a fixed rate (demos and tests).
#[derive(Debug)]
pub struct Replay {
    capture: Capture,
    interval: Duration,
    next: usize,
    skipped: usize,
    start: Option<Instant>,
}

impl Replay {
    /// Replays `capture` at `rows_per_second` (> 0; infinite: as fast as it is read).
    ///
    /// # Errors
    /// [`Error::Argument`] (`--replay-rate`) for a rate that is not > 0.
    pub fn new(capture: Capture, rows_per_second: f64) -> Result<Self> {
        if rows_per_second.is_nan() || rows_per_second <= 0.0 {
            return Err(Error::arg(
                "replay_rate",
                format!("expected a rate > 0 rows/s, found {rows_per_second}"),
            ));
        }
        let interval = Duration::try_from_secs_f64(1.0 / rows_per_second).unwrap_or_default();
        Ok(Self {
            capture,
            interval,
            next: 0,
            skipped: 0,
            start: None,
        })
    }

    /// Reads every row of `src` into memory (checked against the memory budget), then replays
    /// them as [`Replay::new`].
    ///
    /// # Errors
    /// As [`Replay::new`]; the source's read errors; the budget.
    pub fn from_source(src: &mut dyn RowSource, rows_per_second: f64, what: &Path) -> Result<Self> {
        let g = src.geometry().clone();
        let n = g.lasers.len() * g.spads_per_row() * g.nt;
        budget::check(
            || format!("the replayed capture {} in memory", what.display()),
            budget::bytes(n, 4),
        )?;
        let mut data = Vec::with_capacity(n);
        let mut row = Vec::new();
        for l in 0..g.lasers.len() {
            src.read_row(l, &mut row)?;
            data.extend_from_slice(&row);
        }
        Self::new(Capture::new(g, data, what)?, rows_per_second)
    }
}

impl LiveSource for Replay {
    fn geometry(&self) -> &Geometry {
        &self.capture.geometry
    }
    fn next_row(&mut self) -> Result<Option<Arrival>> {
        let l = self.next;
        if l >= self.capture.geometry.lasers.len() {
            return Ok(None);
        }
        let start = *self.start.get_or_insert_with(Instant::now);
        // Row l is complete at (l + 1) intervals after the start (of the rows replayed).
        let due = start
            + self
                .interval
                .saturating_mul(u32::try_from(l + 1 - self.skipped).unwrap_or(u32::MAX));
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
        self.next += 1;
        let data = self.capture.row(l).to_vec();
        Ok(Some(Arrival {
            index: l,
            photons: data.iter().map(|&x| f64::from(x)).sum(),
            data,
            dwell: Some(self.interval.as_secs_f64()),
            position: None,
        }))
    }
    fn skip_rows(&mut self, k: usize) -> bool {
        if self.next == 0 {
            self.next = k.min(self.capture.geometry.lasers.len());
            self.skipped = self.next;
        }
        true
    }
    fn can_reread(&self) -> bool {
        true
    }
    fn reread(&mut self, rows: Range<usize>) -> Result<Vec<Arrival>> {
        let n = self.capture.geometry.lasers.len();
        Ok((rows.start.min(n)..rows.end.min(n))
            .map(|l| {
                let data = self.capture.row(l).to_vec();
                Arrival {
                    index: l,
                    photons: data.iter().map(|&x| f64::from(x)).sum(),
                    data,
                    dwell: None,
                    position: None,
                }
            })
            .collect())
    }
}
