//! T3 records: decoding one 32-bit record ([`Decoder`]) and streaming the events of a file
//! ([`Records`], [`open`]).

use std::fs::File;
use std::io::{self, BufRead, BufReader};
use std::path::{Path, PathBuf};

use super::header::*;
use crate::error::{Error, Result};

/// A decoded T3 event.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Event {
    /// A detected photon.
    Photon {
        /// Detector channel, 0-based.
        channel: u8,
        /// Arrival bin after the sync (units of `MeasDesc_Resolution`).
        dtime: u16,
        /// Sync period, overflow-corrected (units of `MeasDesc_GlobalResolution`).
        sync: u64,
    },
    /// A marker (TTL input) record.
    Marker {
        /// Marker bits: bit `m − 1` set for marker input `m` (1..=4).
        bits: u8,
        /// Sync period, overflow-corrected (coarser timing than photons).
        sync: u64,
    },
}

/// What one record is, as seen by a [`Decoder`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Decoded {
    /// A photon or a marker.
    Event(Event),
    /// An overflow record: the sync counter moved on by `syncs`.
    Overflow {
        /// Sync periods added (1024 or 1024·n; 65536 for PicoHarp).
        syncs: u64,
    },
    /// A special record that is neither an overflow nor a marker: no photon, skipped.
    Reserved,
    /// A PicoHarp photon record on channel 0 or 5..14 (PicoQuant: "should not occur").
    IllegalChannel {
        /// The raw 4-bit channel.
        channel: u8,
    },
}

/// Decodes T3 records one at a time, keeping the overflow count.
#[derive(Clone, Debug)]
pub struct Decoder {
    kind: RecordType,
    overflow: u64,
}

impl Decoder {
    /// A decoder at the start of a record stream.
    pub fn new(kind: RecordType) -> Self {
        Self { kind, overflow: 0 }
    }

    /// The sync periods added by the overflow records so far.
    pub fn overflow_syncs(&self) -> u64 {
        self.overflow
    }

    /// Decodes one record (the `u32` read little-endian from the file).
    pub fn decode(&mut self, record: u32) -> Decoded {
        if self.kind == RecordType::PicoHarpT3 {
            let channel = (record >> 28) as u8;
            let dtime = ((record >> 16) & 0x0FFF) as u16;
            let nsync = u64::from(record & 0xFFFF);
            if channel == 0x0F {
                if dtime == 0 {
                    self.overflow = self.overflow.saturating_add(65_536);
                    return Decoded::Overflow { syncs: 65_536 };
                }
                let bits = (dtime & 0x0F) as u8;
                if bits == 0 {
                    return Decoded::Reserved;
                }
                return Decoded::Event(Event::Marker {
                    bits,
                    sync: self.overflow.saturating_add(nsync),
                });
            }
            if channel == 0 || channel > 4 {
                return Decoded::IllegalChannel { channel };
            }
            return Decoded::Event(Event::Photon {
                channel: channel - 1,
                dtime,
                sync: self.overflow.saturating_add(nsync),
            });
        }
        let special = record >> 31 == 1;
        let channel = ((record >> 25) & 0x3F) as u8;
        let dtime = ((record >> 10) & 0x7FFF) as u16;
        let nsync = u64::from(record & 0x03FF);
        let sync = self.overflow.saturating_add(nsync);
        if !special {
            return Decoded::Event(Event::Photon {
                channel,
                dtime,
                sync,
            });
        }
        match channel {
            0x3F => {
                let n = if nsync == 0 || self.kind == RecordType::HydraHarpV1T3 {
                    1
                } else {
                    nsync
                };
                self.overflow = self.overflow.saturating_add(1024 * n);
                Decoded::Overflow { syncs: 1024 * n }
            }
            1..=15 => Decoded::Event(Event::Marker {
                bits: channel,
                sync,
            }),
            _ => Decoded::Reserved,
        }
    }
}

/// A stream of decoded [`Event`]s read from a [`BufRead`] positioned at the first record.
///
/// Reads exactly `TTResult_NumberOfRecords` 4-byte records, one at a time. Overflow and
/// reserved records update the decoder and counters but are not yielded. Ends with an error
/// (field `records`) if the data ends early (a partial last record included) or goes on after
/// the last record, or on an illegal PicoHarp channel; after an error it yields nothing more.
#[derive(Debug)]
pub struct Records<R> {
    pub(super) reader: R,
    pub(super) decoder: Decoder,
    pub(super) total: u64,
    pub(super) read: u64,
    pub(super) path: PathBuf,
    pub(super) done: bool,
    pub(super) overflow_records: u64,
    pub(super) reserved_records: u64,
}

impl<R: BufRead> Records<R> {
    /// Records of `header`'s type and count from `reader`, which must be positioned right
    /// after the header. `path` names the file in errors.
    pub fn new(reader: R, header: &Header, path: impl Into<PathBuf>) -> Self {
        Self {
            reader,
            decoder: Decoder::new(header.record_type),
            total: header.num_records,
            read: 0,
            path: path.into(),
            done: false,
            overflow_records: 0,
            reserved_records: 0,
        }
    }

    /// Records read so far (of every kind); the index of the next one.
    pub fn records_read(&self) -> u64 {
        self.read
    }

    /// Overflow records read so far.
    pub fn overflow_records(&self) -> u64 {
        self.overflow_records
    }

    /// Reserved special records (no photon, no marker, no overflow) read so far.
    pub fn reserved_records(&self) -> u64 {
        self.reserved_records
    }

    /// The decoder (its overflow count).
    pub fn decoder(&self) -> &Decoder {
        &self.decoder
    }

    /// The underlying reader.
    pub fn into_inner(self) -> R {
        self.reader
    }

    /// Starts again at the first record, which `reader` must now be positioned at.
    pub(super) fn restart(&mut self) {
        self.decoder = Decoder::new(self.decoder.kind);
        self.read = 0;
        self.done = false;
        self.overflow_records = 0;
        self.reserved_records = 0;
    }

    /// Reads up to 4 bytes: the count read (< 4 only at the end of the data) and the bytes.
    pub(super) fn read4(&mut self) -> io::Result<(usize, [u8; 4])> {
        let mut buf = [0u8; 4];
        let mut got = 0;
        while got < 4 {
            let avail = match self.reader.fill_buf() {
                Ok(b) => b,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(e),
            };
            if avail.is_empty() {
                break;
            }
            let n = avail.len().min(4 - got);
            buf[got..got + n].copy_from_slice(&avail[..n]);
            self.reader.consume(n);
            got += n;
        }
        Ok((got, buf))
    }

    /// The next event, `None` at the end of the records.
    ///
    /// # Errors
    /// As in the type's description; [`Error::Io`] if reading fails.
    pub fn next_event(&mut self) -> Result<Option<Event>> {
        let r = self.next_inner();
        if r.is_err() {
            self.done = true;
        }
        r
    }

    pub(super) fn next_inner(&mut self) -> Result<Option<Event>> {
        loop {
            if self.done {
                return Ok(None);
            }
            if self.read == self.total {
                self.done = true;
                let more = !self
                    .reader
                    .fill_buf()
                    .map_err(|e| Error::io(&self.path, e))?
                    .is_empty();
                if more {
                    return Err(Error::format(
                        &self.path,
                        "records",
                        format!(
                            "{} records (TTResult_NumberOfRecords), then the end of the file",
                            self.total
                        ),
                        format!("more data after record {}", self.total),
                    ));
                }
                return Ok(None);
            }
            let (n, buf) = self.read4().map_err(|e| Error::io(&self.path, e))?;
            if n < 4 {
                let stray = if n > 0 {
                    format!(" and a partial record of {n} bytes")
                } else {
                    String::new()
                };
                return Err(Error::format(
                    &self.path,
                    "records",
                    format!(
                        "{} records of 4 bytes (TTResult_NumberOfRecords)",
                        self.total
                    ),
                    format!("end of file after {} records{stray}", self.read),
                ));
            }
            let index = self.read;
            self.read += 1;
            match self.decoder.decode(u32::from_le_bytes(buf)) {
                Decoded::Event(e) => return Ok(Some(e)),
                Decoded::Overflow { .. } => self.overflow_records += 1,
                Decoded::Reserved => self.reserved_records += 1,
                Decoded::IllegalChannel { channel } => {
                    return Err(Error::format(
                        &self.path,
                        "records",
                        "PicoHarp T3 photons on channels 1..4",
                        format!("a photon on channel {channel} at record {index}"),
                    ));
                }
            }
        }
    }
}

impl<R: BufRead> Iterator for Records<R> {
    type Item = Result<Event>;
    fn next(&mut self) -> Option<Self::Item> {
        self.next_event().transpose()
    }
}

/// Opens a PTU file: its checked header and the stream of its events.
///
/// # Errors
/// [`Error::Io`] if the file cannot be opened or read; header errors of [`Header::read`].
pub fn open(path: impl AsRef<Path>) -> Result<(Header, Records<BufReader<File>>)> {
    let path = path.as_ref();
    let mut r = BufReader::new(File::open(path).map_err(|e| Error::io(path, e))?);
    let header = Header::read(&mut r, path)?;
    let records = Records::new(r, &header, path);
    Ok((header, records))
}
