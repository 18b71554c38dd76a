//! Following a T3 stream while it is being acquired: [`Follower`] bins the rows of a PTU file
//! that is still being written (like `tail -f`) or of a pipe (a T3 record stream, header
//! first), handing out each laser row as soon as the next row marker closes it.
//!
//! # How the stream ends
//!
//! The binning conventions are [`PtuSource`](super::PtuSource)'s (module docs: rows start at
//! row markers, the sidecar maps channels and the time window), except for the record count:
//! acquisition software writes the header before the records it counts, with
//! `TTResult_NumberOfRecords` 0, and patches the count when the measurement stops. So:
//!
//! * a **non-zero count** in the header ends the records there, as in a finished file (data
//!   after them is an error, field `records`, as offline);
//! * a **zero count**: the records go on until the end of the stream. For a pipe that is its
//!   end of file; for a file, while it has not grown the follower re-reads the header every
//!   poll: once the count is patched in, the records end at that count. A file that stops
//!   growing for the idle timeout ends the stream where it stands.
//!
//! The scan's last row is every photon after its row marker up to the end of the records; a
//! stream that ends (or stops growing) before the last row marker is an error (field
//! `markers`, naming the byte position), and so is one that stops inside a 4-byte record
//! (field `records`). The rows handed out before an error stay valid.
//!
//! Waiting: at the end of a growing file the follower sleeps `poll` (default 20 ms) between
//! checks; it holds the PTU header, a 64 KiB read buffer and one row's histograms
//! (`Ks·Nt` `u32`), whatever the length of the scan.

use std::fs::File;
use std::io::{self, BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use super::decode::*;
use super::header::*;
use super::sidecar::*;
use super::source::Counts;
use crate::budget;
use crate::error::{Error, Result};
use crate::io::capture::Geometry;

/// How a [`Follower`] waits at the end of a growing file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FollowOptions {
    /// A file that has not grown for this long ends the stream (default 10 s).
    pub idle_timeout: Duration,
    /// Sleep between checks at the end of a growing file (default 20 ms).
    pub poll: Duration,
}

impl Default for FollowOptions {
    fn default() -> Self {
        Self {
            idle_timeout: Duration::from_secs(10),
            poll: Duration::from_millis(20),
        }
    }
}

/// Why the stream's bytes ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ended {
    /// Not yet.
    No,
    /// The header's record count was reached.
    Count,
    /// A pipe (or other stream) reached its end of file.
    Eof,
    /// A file stopped growing for the idle timeout.
    Idle,
}

/// The bytes of a growing file or a stream, counting the position; at the end of a growing
/// file it waits for more (see the module docs).
struct Tail {
    inner: Box<dyn Read + Send>,
    /// The file being followed (`None` for a pipe).
    file: Option<PathBuf>,
    opts: FollowOptions,
    pos: u64,
    /// Where the records end, once known (header count).
    end: Option<u64>,
    /// Where the records start (set after the header).
    data_start: Option<u64>,
    ended: Ended,
    last_header_check: Option<Instant>,
}

impl Tail {
    /// Re-reads the header of the followed file: the end of the records once the count is in.
    fn check_count(&mut self) {
        let (Some(path), Some(start)) = (&self.file, self.data_start) else {
            return;
        };
        let Ok(f) = File::open(path) else { return };
        if let Ok(h) = Header::read(&mut BufReader::new(f), path)
            && h.num_records > 0
            && h.data_offset == start
        {
            self.end = Some(start + 4 * h.num_records);
        }
    }
}

impl Read for Tail {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        if self.ended != Ended::No || buf.is_empty() {
            return Ok(0);
        }
        let want = match self.end {
            Some(e) if self.pos >= e => {
                self.ended = Ended::Count;
                return Ok(0);
            }
            Some(e) => buf
                .len()
                .min(usize::try_from(e - self.pos).unwrap_or(usize::MAX)),
            None => buf.len(),
        };
        let mut idle_since = Instant::now();
        loop {
            let n = match self.inner.read(&mut buf[..want]) {
                Ok(n) => n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e),
            };
            if n > 0 {
                self.pos += n as u64;
                return Ok(n);
            }
            if self.file.is_none() {
                self.ended = Ended::Eof;
                return Ok(0);
            }
            // The end of a growing file: has the count been patched in?
            let due = self
                .last_header_check
                .is_none_or(|t| t.elapsed() >= Duration::from_millis(200));
            if self.end.is_none() && due {
                self.last_header_check = Some(Instant::now());
                self.check_count();
                if let Some(e) = self.end {
                    if self.pos >= e {
                        self.ended = Ended::Count;
                        return Ok(0);
                    }
                    idle_since = Instant::now();
                    continue;
                }
            }
            if idle_since.elapsed() >= self.opts.idle_timeout {
                self.ended = Ended::Idle;
                return Ok(0);
            }
            std::thread::sleep(self.opts.poll);
        }
    }
}

/// One laser row handed out by a [`Follower`].
#[derive(Clone, Debug, PartialEq)]
pub struct FollowedRow {
    /// Laser row index.
    pub index: usize,
    /// Histograms, `Ks·Nt` photon counts as `f32`, SPAD-major.
    pub data: Vec<f32>,
    /// Photons binned into the row.
    pub photons: u64,
    /// The row's acquisition time from the sync clock (s): from its row marker to the next
    /// (the last row: to its last record), `None` before it is known.
    pub seconds: Option<f64>,
    /// Byte position in the stream after the row.
    pub position: u64,
}

/// Bins the rows of a T3 stream that is still being written (module docs).
pub struct Follower {
    name: PathBuf,
    header: Header,
    sidecar: Sidecar,
    plan: Plan,
    reader: BufReader<Tail>,
    decoder: Decoder,
    records: u64,
    markers_seen: usize,
    /// Rows handed out.
    handed: usize,
    marker_sync: u64,
    last_sync: u64,
    counts: Counts,
    hist: Vec<u32>,
    finished: bool,
}

impl std::fmt::Debug for Follower {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Follower")
            .field("name", &self.name)
            .field("records", &self.records)
            .field("markers_seen", &self.markers_seen)
            .finish_non_exhaustive()
    }
}

impl Follower {
    /// Follows the PTU file `ptu`, which may still be growing (its header included), with
    /// its sidecar.
    ///
    /// # Errors
    /// [`Error::Io`] if a file cannot be read; header errors (a header that is not T3, or a
    /// file that stops growing inside its header) and sidecar errors as
    /// [`PtuSource::open`](super::PtuSource::open).
    pub fn file(ptu: &Path, sidecar: &Path, opts: FollowOptions) -> Result<Self> {
        let side = Sidecar::load(sidecar)?;
        let f = File::open(ptu).map_err(|e| Error::io(ptu, e))?;
        let tail = Tail {
            inner: Box::new(f),
            file: Some(ptu.to_path_buf()),
            opts,
            pos: 0,
            end: None,
            data_start: None,
            ended: Ended::No,
            last_header_check: None,
        };
        Self::new(tail, ptu, side, sidecar)
    }

    /// Follows a T3 record stream (header first) read from `stream`, e.g. standard input;
    /// `name` names it in errors. The stream ends at its end of file or at the header's
    /// record count.
    ///
    /// # Errors
    /// As [`Follower::file`].
    pub fn stream(
        stream: Box<dyn Read + Send>,
        name: &Path,
        sidecar: Sidecar,
        sidecar_path: &Path,
    ) -> Result<Self> {
        let tail = Tail {
            inner: stream,
            file: None,
            opts: FollowOptions::default(),
            pos: 0,
            end: None,
            data_start: None,
            ended: Ended::No,
            last_header_check: None,
        };
        Self::new(tail, name, sidecar, sidecar_path)
    }

    fn new(tail: Tail, name: &Path, sidecar: Sidecar, sidecar_path: &Path) -> Result<Self> {
        let mut reader = BufReader::with_capacity(1 << 16, tail);
        let header = Header::read(&mut reader, name)?;
        let plan = sidecar.plan(&header, sidecar_path)?;
        let row = plan.ks.saturating_mul(plan.geometry.nt);
        budget::check(
            || {
                format!(
                    "a laser row of {} bins ({} SPADs × nt {}) described by {}",
                    budget::count(row as u128),
                    plan.ks,
                    plan.geometry.nt,
                    sidecar_path.display()
                )
            },
            budget::bytes(row, 8),
        )?;
        let t = reader.get_mut();
        t.data_start = Some(header.data_offset);
        if header.num_records > 0 {
            t.end = Some(header.data_offset + 4 * header.num_records);
        }
        Ok(Self {
            name: name.to_path_buf(),
            decoder: Decoder::new(header.record_type),
            header,
            sidecar,
            plan,
            reader,
            records: 0,
            markers_seen: 0,
            handed: 0,
            marker_sync: 0,
            last_sync: 0,
            counts: Counts::default(),
            hist: vec![0; row],
            finished: false,
        })
    }

    /// The capture's geometry (from the sidecar and the header).
    pub fn geometry(&self) -> &Geometry {
        &self.plan.geometry
    }

    /// The stream's header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The sidecar.
    pub fn sidecar(&self) -> &Sidecar {
        &self.sidecar
    }

    /// Laser rows of the scan.
    pub fn rows(&self) -> usize {
        self.plan.rows
    }

    /// Counts of the records read so far (`skipped_rows` stays 0: every row is binned).
    pub fn counts(&self) -> Counts {
        self.counts
    }

    /// Bytes read from the stream so far.
    pub fn position(&self) -> u64 {
        self.reader.get_ref().pos - self.reader.buffer().len() as u64
    }

    /// Records read so far.
    pub fn records_read(&self) -> u64 {
        self.records
    }

    /// Why the stream's bytes ended ([`Ended::No`] while it goes on).
    pub fn ended(&self) -> Ended {
        self.reader.get_ref().ended
    }

    fn where_(&self) -> String {
        let why = match self.ended() {
            Ended::No | Ended::Count => "the end of the records".to_string(),
            Ended::Eof => "the end of the stream".to_string(),
            Ended::Idle => format!(
                "the file stopped growing for {:.1} s",
                self.reader.get_ref().opts.idle_timeout.as_secs_f64()
            ),
        };
        format!(
            "{why}, at byte {} (record {})",
            self.position(),
            self.records
        )
    }

    fn markers_error(&self) -> Error {
        Error::format(
            &self.name,
            "markers",
            format!(
                "{} row markers (marker input {}), one per laser row of the sidecar",
                self.plan.rows, self.sidecar.row_marker
            ),
            format!("{} before {}", self.markers_seen, self.where_()),
        )
    }

    /// The next record's event; `None` at the end of the records.
    fn next_event(&mut self) -> Result<Option<Event>> {
        loop {
            let mut b = [0u8; 4];
            let mut got = 0;
            while got < 4 {
                let avail = match self.reader.fill_buf() {
                    Ok(a) => a,
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                    Err(e) => return Err(Error::io(&self.name, e)),
                };
                if avail.is_empty() {
                    break;
                }
                let n = avail.len().min(4 - got);
                b[got..got + n].copy_from_slice(&avail[..n]);
                self.reader.consume(n);
                got += n;
            }
            if got == 0 {
                return self.at_end().map(|()| None);
            }
            if got < 4 {
                return Err(Error::format(
                    &self.name,
                    "records",
                    "whole 4-byte T3 records",
                    format!(
                        "a partial record of {got} bytes (from byte {}) before {}",
                        self.position() - got as u64,
                        self.where_()
                    ),
                ));
            }
            let index = self.records;
            self.records += 1;
            match self.decoder.decode(u32::from_le_bytes(b)) {
                Decoded::Event(e) => return Ok(Some(e)),
                Decoded::Overflow { .. } => self.counts.overflow_records += 1,
                Decoded::Reserved => self.counts.reserved_records += 1,
                Decoded::IllegalChannel { channel } => {
                    return Err(Error::format(
                        &self.name,
                        "records",
                        "PicoHarp T3 photons on channels 1..4",
                        format!(
                            "a photon on channel {channel} at record {index} (byte {})",
                            self.position() - 4
                        ),
                    ));
                }
            }
        }
    }

    /// At the end of the records: data after a counted end is an error, as offline.
    fn at_end(&mut self) -> Result<()> {
        let t = self.reader.get_ref();
        if t.ended == Ended::Count
            && let (Some(path), Some(end)) = (&t.file, t.end)
        {
            let len = std::fs::metadata(path)
                .map_err(|e| Error::io(path, e))?
                .len();
            if len > end {
                return Err(Error::format(
                    &self.name,
                    "records",
                    format!(
                        "{} records (TTResult_NumberOfRecords), then the end of the file",
                        self.records
                    ),
                    format!("more data after record {} (byte {end})", self.records),
                ));
            }
        }
        Ok(())
    }

    /// The next laser row, waiting for it to be complete; `None` after the last row.
    ///
    /// # Errors
    /// The binning errors of [`PtuSource`](super::PtuSource) (markers, channels, records),
    /// naming the byte position; [`Error::Io`] on a read error. After an error the follower
    /// yields nothing more.
    pub fn next_row(&mut self) -> Result<Option<FollowedRow>> {
        if self.finished {
            return Ok(None);
        }
        let r = self.bin_next();
        if !matches!(r, Ok(Some(_))) {
            self.finished = true;
        }
        r
    }

    fn bin_next(&mut self) -> Result<Option<FollowedRow>> {
        let bits = self.plan.row_bits;
        let rows = self.plan.rows;
        if self.handed >= rows {
            return Ok(None);
        }
        // Before the first row marker.
        while self.markers_seen == 0 {
            match self.next_event()? {
                None => return Err(self.markers_error()),
                Some(Event::Marker { bits: b, sync }) if b & bits != 0 => {
                    self.markers_seen = 1;
                    self.marker_sync = sync;
                    self.last_sync = sync;
                }
                Some(Event::Marker { .. }) => self.counts.other_markers += 1,
                Some(Event::Photon { .. }) => self.counts.before_first_marker += 1,
            }
        }
        let l = self.markers_seen - 1;
        self.hist.fill(0);
        let nt = self.plan.geometry.nt;
        let mut photons = 0u64;
        let seconds = loop {
            match self.next_event()? {
                None if l + 1 < rows => return Err(self.markers_error()),
                None => {
                    break (self.last_sync.saturating_sub(self.marker_sync) as f64)
                        * self.header.global_resolution;
                }
                Some(Event::Marker { bits: b, sync }) if b & bits != 0 => {
                    if l + 1 == rows {
                        return Err(Error::format(
                            &self.name,
                            "markers",
                            format!(
                                "{rows} row markers (marker input {}), one per laser row of the \
                                 sidecar",
                                self.sidecar.row_marker
                            ),
                            format!(
                                "more: an extra row marker at record {} (byte {})",
                                self.records - 1,
                                self.position() - 4
                            ),
                        ));
                    }
                    let s = sync.saturating_sub(self.marker_sync) as f64;
                    self.markers_seen += 1;
                    self.marker_sync = sync;
                    self.last_sync = sync;
                    break s * self.header.global_resolution;
                }
                Some(Event::Marker { sync, .. }) => {
                    self.last_sync = self.last_sync.max(sync);
                    self.counts.other_markers += 1;
                }
                Some(Event::Photon {
                    channel,
                    dtime,
                    sync,
                }) => {
                    self.last_sync = self.last_sync.max(sync);
                    let Some(s) = self.plan.spad_of_channel[usize::from(channel) % CHANNELS] else {
                        if self.plan.unmapped_error {
                            return Err(Error::format(
                                &self.name,
                                "channels",
                                format!(
                                    "photons only on the sidecar's channels {:?} (or \
                                     \"unmapped_channels\": \"drop\")",
                                    self.sidecar
                                        .channels
                                        .clone()
                                        .unwrap_or_else(|| (0..self.plan.ks as u32).collect())
                                ),
                                format!(
                                    "a photon on channel {channel} at record {} (byte {})",
                                    self.records - 1,
                                    self.position() - 4
                                ),
                            ));
                        }
                        self.counts.unmapped += 1;
                        continue;
                    };
                    let k = u64::from(dtime);
                    if k < self.plan.first || k >= self.plan.end {
                        self.counts.outside_window += 1;
                        continue;
                    }
                    let n = ((k - self.plan.first) / self.plan.rebin) as usize;
                    let bin = &mut self.hist[s * nt + n];
                    *bin = bin.saturating_add(1);
                    self.counts.binned += 1;
                    photons += 1;
                }
            }
        };
        self.handed += 1;
        Ok(Some(FollowedRow {
            index: l,
            data: self.hist.iter().map(|&c| c as f32).collect(),
            photons,
            seconds: Some(seconds),
            position: self.position(),
        }))
    }
}
