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
//! A pipe that stops sending without closing (a relay that hangs) is read on a thread of its
//! own ([`Follower::stream`]): when nothing arrives for the idle timeout the stream ends
//! there too ([`Ended::Idle`]), and the rows it did not complete are an error naming the byte
//! position. (A reader given to [`Follower::reader`] says so by returning
//! [`io::ErrorKind::TimedOut`].)
//!
//! # Resuming
//!
//! [`Follower::skip_rows`] passes over the first rows of the scan without binning them
//! (their records are decoded, only to count the row markers), for a run that resumes from
//! states that already hold them.
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

use super::binning::{Binner, Counts};
use super::decode::*;
use super::header::*;
use super::sidecar::*;
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
    /// A file stopped growing, or a pipe stopped sending, for the idle timeout.
    Idle,
}

/// A pipe read on a thread of its own, so that a read can give up after the idle timeout:
/// a read that waits longer than `timeout` for the next chunk returns
/// [`io::ErrorKind::TimedOut`]. Holds at most four 64 KiB chunks in flight.
struct Relay {
    rx: std::sync::mpsc::Receiver<io::Result<Vec<u8>>>,
    chunk: Vec<u8>,
    at: usize,
    timeout: Duration,
    done: bool,
}

impl Relay {
    fn spawn(mut inner: Box<dyn Read + Send>, timeout: Duration) -> Self {
        let (tx, rx) = std::sync::mpsc::sync_channel(4);
        // The thread ends at the end of the stream, on an error, or when the follower is
        // dropped (the next send fails); a pipe that never sends again keeps it blocked in
        // `read` until the process ends.
        std::thread::spawn(move || {
            loop {
                let mut buf = vec![0u8; 1 << 16];
                let r = match inner.read(&mut buf) {
                    Ok(n) => {
                        buf.truncate(n);
                        Ok(buf)
                    }
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                    Err(e) => Err(e),
                };
                let stop = !matches!(&r, Ok(b) if !b.is_empty());
                if tx.send(r).is_err() || stop {
                    return;
                }
            }
        });
        Self {
            rx,
            chunk: Vec::new(),
            at: 0,
            timeout,
            done: false,
        }
    }
}

impl Read for Relay {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        while self.at >= self.chunk.len() {
            if self.done {
                return Ok(0);
            }
            match self.rx.recv_timeout(self.timeout) {
                Ok(Ok(c)) if c.is_empty() => self.done = true,
                Ok(Ok(c)) => (self.chunk, self.at) = (c, 0),
                Ok(Err(e)) => {
                    self.done = true;
                    return Err(e);
                }
                Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                    return Err(io::ErrorKind::TimedOut.into());
                }
                Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => self.done = true,
            }
        }
        let n = buf.len().min(self.chunk.len() - self.at);
        buf[..n].copy_from_slice(&self.chunk[self.at..self.at + n]);
        self.at += n;
        Ok(n)
    }
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
            self.end = records_end(&h);
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
                // The source waited the idle timeout for data (a pipe that stopped sending).
                Err(e) if e.kind() == io::ErrorKind::TimedOut => {
                    self.ended = Ended::Idle;
                    return Ok(0);
                }
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

/// The byte position in the stream of the next byte `reader` hands out.
fn position(reader: &BufReader<Tail>) -> u64 {
    reader.get_ref().pos - reader.buffer().len() as u64
}

/// Where the header's counted records end (`None`: past byte 2^64, a corrupt count).
fn records_end(h: &Header) -> Option<u64> {
    h.num_records
        .checked_mul(4)
        .and_then(|b| b.checked_add(h.data_offset))
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
    bins: Binner,
    finished: bool,
    /// Rows `0..skip` are passed over without binning ([`Follower::skip_rows`]).
    skip: usize,
    sidecar_path: PathBuf,
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
    /// `name` names it in errors. The stream ends at its end of file, at the header's record
    /// count, or when it sends nothing for `opts.idle_timeout` (it is read on a thread of its
    /// own, so a pipe that stops sending without closing cannot hang the follower).
    ///
    /// # Errors
    /// As [`Follower::file`].
    pub fn stream(
        stream: Box<dyn Read + Send>,
        name: &Path,
        sidecar: Sidecar,
        sidecar_path: &Path,
        opts: FollowOptions,
    ) -> Result<Self> {
        let relay = Relay::spawn(stream, opts.idle_timeout);
        Self::reader(Box::new(relay), None, name, sidecar, sidecar_path, opts)
    }

    /// Follows the bytes `source` gives, as they come, on the calling thread (the building
    /// block of [`Follower::file`] and [`Follower::stream`], and of tests and fuzzing):
    ///
    /// * `file: None` — a pipe: `Ok(0)` is its end;
    /// * `file: Some(path)` — a growing file: `Ok(0)` is its current end, more may come
    ///   (polled every `opts.poll`, the header re-read from `path` for a patched record
    ///   count, the stream ended after `opts.idle_timeout` without growth);
    /// * either way, an [`io::ErrorKind::TimedOut`] error means the source waited the idle
    ///   timeout itself: the stream ends there ([`Ended::Idle`]).
    ///
    /// # Errors
    /// As [`Follower::file`].
    pub fn reader(
        source: Box<dyn Read + Send>,
        file: Option<&Path>,
        name: &Path,
        sidecar: Sidecar,
        sidecar_path: &Path,
        opts: FollowOptions,
    ) -> Result<Self> {
        let tail = Tail {
            inner: source,
            file: file.map(Path::to_path_buf),
            opts,
            pos: 0,
            end: None,
            data_start: None,
            ended: Ended::No,
            last_header_check: None,
        };
        Self::new(tail, name, sidecar, sidecar_path)
    }

    /// Passes over rows `0..k` without binning them (their records are decoded, to count the
    /// row markers and check them): [`Follower::next_row`] then hands out row `k` first. For
    /// a run resuming from states that hold those rows. Call it before the first row.
    pub fn skip_rows(&mut self, k: usize) {
        self.skip = k.min(self.plan.rows);
    }

    fn new(tail: Tail, name: &Path, sidecar: Sidecar, sidecar_path: &Path) -> Result<Self> {
        let mut reader = BufReader::with_capacity(1 << 16, tail);
        let header = Header::read(&mut reader, name)?;
        let plan = sidecar.plan(&header, sidecar_path)?;
        let bins = Binner::new(&plan, &sidecar, sidecar_path)?;
        let t = reader.get_mut();
        t.data_start = Some(header.data_offset);
        if header.num_records > 0 {
            t.end = Some(records_end(&header).ok_or_else(|| {
                Error::format(
                    name,
                    "TTResult_NumberOfRecords",
                    "a record count whose 4-byte records end before byte 2^64",
                    header.num_records,
                )
            })?);
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
            bins,
            finished: false,
            skip: 0,
            sidecar_path: sidecar_path.to_path_buf(),
        })
    }

    /// A new follower of the same file from its start (the same sidecar and options);
    /// `None` for a pipe, which cannot be read again.
    ///
    /// # Errors
    /// As [`Follower::file`].
    pub fn reopen(&self) -> Result<Option<Self>> {
        let t = self.reader.get_ref();
        match &t.file {
            Some(f) => Self::file(f, &self.sidecar_path, t.opts).map(Some),
            None => Ok(None),
        }
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

    /// Counts of the records read so far (`skipped_rows`: the photons of the rows passed
    /// over by [`Follower::skip_rows`]).
    pub fn counts(&self) -> Counts {
        self.counts
    }

    /// Bytes read from the stream so far.
    pub fn position(&self) -> u64 {
        position(&self.reader)
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
                "the {} for {:.1} s",
                if self.reader.get_ref().file.is_some() {
                    "file stopped growing"
                } else {
                    "stream sent nothing"
                },
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
        loop {
            let skipped = self.handed < self.skip;
            let r = self.bin_row(!skipped)?;
            if !skipped || r.is_none() {
                return Ok(r);
            }
        }
    }

    /// The next row; `bin: false` passes over its photons (the row is returned empty).
    fn bin_row(&mut self, bin: bool) -> Result<Option<FollowedRow>> {
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
        if bin {
            self.bins.clear();
        }
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
                    if !bin {
                        self.counts.skipped_rows += 1;
                        continue;
                    }
                    let (records, reader) = (self.records, &self.reader);
                    let at = || format!("record {} (byte {})", records - 1, position(reader) - 4);
                    let binned = self
                        .bins
                        .photon(channel, dtime, &mut self.counts, &self.name, at);
                    photons += u64::from(binned?);
                }
            }
        };
        self.handed += 1;
        Ok(Some(FollowedRow {
            index: l,
            data: if bin {
                self.bins.values().collect()
            } else {
                Vec::new()
            },
            photons,
            seconds: Some(seconds),
            position: self.position(),
        }))
    }
}
