//! PicoQuant PTU photon streams (T3 mode) → laser rows, without Python.
//!
//! A time-correlated single-photon counter (HydraHarp, TimeHarp 260, MultiHarp, PicoHarp) in
//! **T3 mode** writes one 32-bit record per detected photon: the detector channel, the sync
//! period it fell in (`nsync`, a counter that wraps around and is extended by *overflow*
//! records) and its arrival time after the sync (`dtime`, in bins of `MeasDesc_Resolution`).
//! *Marker* records carry the scanner's TTL signals. This module
//!
//! 1. parses the PTU header ([`Header::read`]) and streams decoded [`Event`]s from any
//!    [`BufRead`] ([`Records`], [`open`]), one record at a time, never loading the file;
//! 2. bins the stream into laser rows for the kernel ([`PtuSource`], a [`RowSource`];
//!    [`read_all`] for a whole [`Capture`]), guided by a small JSON **sidecar** ([`Sidecar`])
//!    that describes the scan;
//! 3. writes synthetic HydraHarp V2 T3 files and their sidecars from a [`Capture`]
//!    ([`write_t3`], [`write_t3_to`]), so that capture → PTU → rows gives back the capture's
//!    histograms rounded to whole photons, exactly.
//!
//! # File format
//!
//! As in PicoQuant's public demo code (`Read_PTU.py`, `apx_tttrrecords`), all little-endian:
//!
//! * 8-byte magic `"PQTTTR\0\0"`, 8-byte NUL-padded version string;
//! * tags up to and including the one named `Header_End`, each a 32-byte NUL-padded ident,
//!   an `i32` index (−1 outside arrays), a `u32` type ([`tag_type`]) and an 8-byte value. For
//!   `Float8Array`, `AnsiString`, `WideString` and `BinaryBlob` the value is a byte length and
//!   that many bytes follow: strings are kept ([`TagValue`]), arrays and blobs skipped by length;
//! * then `TTResult_NumberOfRecords` records of `TTResultFormat_BitsPerRecord` = 32 bits.
//!
//! Records ([`RecordType`], [`Decoder`]):
//!
//! | record type | layout from the MSB | overflow | marker |
//! |---|---|---|---|
//! | HydraHarp V1 `0x00010304` | `special:1 channel:6 dtime:15 nsync:10` | special, channel 63: +1024 syncs | special, channel 1..15 = marker bits |
//! | HydraHarp V2 `0x01010304`, TimeHarp 260 N/P `0x00010305`/`0x00010306` (also `0x01010305`/`0x01010306`), MultiHarp `0x00010307` | same | special, channel 63: +1024·nsync syncs (nsync 0 counts as 1) | same |
//! | PicoHarp `0x00010303` | `channel:4 dtime:12 nsync:16` | channel 15, dtime 0: +65536 syncs | channel 15, marker bits = dtime & 15 |
//!
//! A photon's sync period is `sync = overflows + nsync` ([`Event::Photon`]); its time is
//! `sync·MeasDesc_GlobalResolution + dtime·MeasDesc_Resolution`. Photon channels are
//! **0-based**: HydraHarp-family channels as recorded, PicoHarp channels 1..4 as 0..3 (a PicoHarp
//! photon on channel 0 or 5..14 is an error, [`Decoded::IllegalChannel`]). Special records that
//! are neither overflows nor markers (HydraHarp channel 0 or 16..62, PicoHarp markers with no
//! bit in the low nibble) carry no photon; they are counted ([`Records::reserved_records`]) and
//! skipped, as `Read_PTU.py` does.
//!
//! # From photons to laser rows
//!
//! Conventions (a [`PtuSource`] enforces them, naming the violated one in its error):
//!
//! * **Row markers start rows.** Every marker record whose bits include the sidecar's
//!   `row_marker` (marker input `m` in 1..=4, bit `1 << (m − 1)`, PicoQuant's numbering as in
//!   `ImgHdr_LineStart`) starts the next laser row; row `l` is every photon **in file order**
//!   after the `(l+1)`-th row marker and before the next one (or the end of the records for the
//!   last row). Markers have coarser timing than photons and may sit a few records out of order:
//!   the split follows file order, not sync times. Markers without the row bit are counted
//!   ([`Counts::other_markers`]) and ignored.
//! * Photons **before the first row marker** are dropped and counted
//!   ([`Counts::before_first_marker`]).
//! * Exactly `rows` row markers: a file that ends before the row marker of a row the sidecar
//!   expects, or has a row marker after the last row's, is an error (field `markers`). The
//!   count is checked as the stream is read: reading every row (as [`read_all`] and the probes
//!   do) detects both cases; the last row is read up to the end of the records.
//! * Photon channel `c` goes to SPAD `s` where `channels[s] = c`. A photon on a channel no SPAD
//!   maps is an error (field `channels`) unless the sidecar says `"unmapped_channels": "drop"`,
//!   then it is dropped and counted ([`Counts::unmapped`]).
//! * Raw dtime bin `k` is the path length `t0 + k·bin_width` (metres; `t0` after every cable
//!   and electronic delay). Histogram bin `n` of a row sums the raw bins
//!   `first_dtime + n·rebin ..= first_dtime + n·rebin + rebin − 1`; photons outside
//!   `first_dtime .. first_dtime + nt·rebin` are dropped and counted
//!   ([`Counts::outside_window`]). The capture's time axis is then `dt = rebin·bin_width` and
//!   `t0' = t0 + (first_dtime + (rebin − 1)/2)·bin_width` (the centre of the merged bins: capture
//!   bins are point samples). `bin_width` defaults to `MeasDesc_Resolution·c`, c = 299 792 458
//!   m/s ([`SPEED_OF_LIGHT`]).
//! * **Streaming.** `read_row(l)` for `l = 0, 1, 2, …` reads the file once, keeping the reader
//!   where the previous row ended; memory is `O(Ks·Nt)` (one `u32` histogram per SPAD). Asking
//!   for a later row skips the rows between (their photons counted in
//!   [`Counts::skipped_rows`]); asking for an **earlier** row (or the same one again) rewinds to
//!   the first record and rescans from there, which costs a pass over the file up to that row
//!   (the counts then restart too: they describe the current pass).
//! * Counts are summed as `u32` per bin (saturating) and handed out as `f32` (exact up to
//!   2^24 photons per bin).
//!
//! # Sidecar
//!
//! A JSON object; unknown fields are rejected. Every field, with the defaults of the optional
//! ones (the hidden lines make it a doctest):
//!
//! ```
//! # let json = r#"
//! {
//!   "rows": 6,
//!   "row_marker": 1,
//!   "lasers": {"grid": [3, 2], "size": [0.4, 0.2], "center": [0.0, 0.0]},
//!   "spads": {"points": [[0.1, 0.0, 0.0], [0.2, 0.0, 0.0]], "shape": [2, 1]},
//!   "confocal": false,
//!   "channels": [0, 1],
//!   "unmapped_channels": "error",
//!   "nt": 50,
//!   "t0": 1.25,
//!   "bin_width": 0.01,
//!   "rebin": 1,
//!   "first_dtime": 0,
//!   "laser_origin": [-0.5, 0.0, 0.25],
//!   "sensor_origin": [-0.5, 0.0, 0.25],
//!   "legs_in_time": false
//! }
//! # "#;
//! # let s = vltm::ptu::Sidecar::from_json_str(json, "doc.json").unwrap();
//! # assert_eq!((s.nt, s.rows, s.channels.as_deref()), (50, Some(6), Some(&[0, 1][..])));
//! ```
//!
//! * `lasers`, `spads`: the laser and SPAD spots, in the scene files' form (`vltm::sim`): a wall
//!   grid `{"grid": [nx, ny], "size": [sx, sy], "center": [cx, cy]}` (inclusive end points, C
//!   order over (x, y), like tal) or explicit spots `{"points": [[x, y, z], …], "shape": [nx,
//!   ny]}`. Laser row `l` is laser spot `l` in that order. `spads` may be left out when
//!   `confocal` (default false) is true: one histogram per row, for a SPAD at the laser spot.
//! * `rows` (default: the number of laser spots) must equal the number of laser spots.
//! * `row_marker` (default 1): the marker input, 1..=4, whose markers start rows.
//! * `channels` (default `[0, 1, …, Ks − 1]`): the 0-based detector channel of each SPAD, one
//!   per SPAD (one in all for confocal), distinct, each < 64. `unmapped_channels`: `"error"`
//!   (default) or `"drop"`.
//! * `nt` ≥ 1 histogram bins per SPAD; `t0` (required) the path length (m) of raw dtime bin 0;
//!   `bin_width` (m, > 0) of one raw dtime bin (default `MeasDesc_Resolution·c`); `rebin` ≥ 1
//!   raw bins per histogram bin (default 1); `first_dtime` the first raw bin kept (default 0).
//! * `laser_origin`, `sensor_origin` (default `[-0.5, 0, 0.25]`), `legs_in_time` (default
//!   false): as in the capture's [`Geometry`].
//!
//! # Errors
//!
//! Malformed input is an [`Error::Format`] naming the file and a field, never a panic:
//!
//! | problem | field |
//! |---|---|
//! | not a PTU file | `magic` |
//! | the file ends inside the header | `header` |
//! | unknown tag type | the tag's ident |
//! | missing or mistyped required tag, unknown or T2 record type, `BitsPerRecord` ≠ 32, negative record count, non-finite or non-positive resolution | the tag's ident (`TTResultFormat_TTTRRecType`, `TTResultFormat_BitsPerRecord`, `MeasDesc_Resolution`, …) |
//! | fewer records than `TTResult_NumberOfRecords` (a partial last record included), or data after them | `records` |
//! | a PicoHarp photon on channel 0 or 5..14 | `records` |
//! | fewer or more row markers than rows | `markers` |
//! | a photon on a channel no SPAD maps (with `"unmapped_channels": "error"`) | `channels` |
//! | bad sidecar values (`row_marker` outside 1..=4, `rows`, `channels`, `bin_width`, …) | the sidecar's field; JSON errors: `sidecar` |
//!
//! I/O failures are [`Error::Io`].
//!
//! # Example
//!
//! ```no_run
//! use vltm::capture::RowSource;
//! # fn main() -> vltm::Result<()> {
//! let mut src = vltm::ptu::PtuSource::open("scan.ptu", "scan.json")?;
//! let mut row = Vec::new();
//! for l in 0..src.geometry().lasers.len() {
//!     let laser = src.read_row(l, &mut row)?; // Ks·Nt photon counts, SPAD-major
//!     # let _ = laser;
//! }
//! println!("{:?}", src.counts());
//! # Ok(()) }
//! ```

use std::fs::File;
use std::io::{self, BufRead, BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use vltm_kernel::Point;

use crate::capture::{Capture, Geometry, RowSource};
use crate::error::{Error, Result};
use crate::sim::{Aperture, DEFAULT_LASER_ORIGIN, DEFAULT_SENSOR_ORIGIN};

/// The speed of light (m/s): converts `MeasDesc_Resolution` (s) to metres of path.
pub const SPEED_OF_LIGHT: f64 = 299_792_458.0;

/// The 8-byte magic at the start of every PTU file.
pub const MAGIC: [u8; 8] = *b"PQTTTR\0\0";

/// The highest marker input (`row_marker`): T3 records carry 4 marker bits.
pub const MAX_MARKER: u32 = 4;

/// Tags before `Header_End` beyond which a header is considered corrupt.
pub const MAX_TAGS: usize = 100_000;

/// Strings longer than this (bytes) are skipped by length instead of kept.
const MAX_STRING: u64 = 1 << 20;

/// Detector channels a T3 record can name (6 bits).
const CHANNELS: usize = 64;

/// The PTU tag type codes (the `u32` after a tag's ident and index).
pub mod tag_type {
    /// No value (`Header_End` has this type).
    pub const EMPTY8: u32 = 0xFFFF_0008;
    /// Boolean, `i64` ≠ 0.
    pub const BOOL8: u32 = 0x0000_0008;
    /// Signed 64-bit integer.
    pub const INT8: u32 = 0x1000_0008;
    /// 64-bit set.
    pub const BITSET64: u32 = 0x1100_0008;
    /// A colour, 64 bits.
    pub const COLOR8: u32 = 0x1200_0008;
    /// IEEE `f64`.
    pub const FLOAT8: u32 = 0x2000_0008;
    /// `f64` days since 1899-12-30 (Unix seconds = (v − 25569)·86400).
    pub const DATETIME: u32 = 0x2100_0008;
    /// Array of `f64`: the value is the byte length of the data that follows.
    pub const FLOAT8_ARRAY: u32 = 0x2001_FFFF;
    /// 8-bit string (UTF-8 or Latin-1), NUL-padded: the value is its byte length.
    pub const ANSI_STRING: u32 = 0x4001_FFFF;
    /// UTF-16LE string, NUL-padded: the value is its byte length.
    pub const WIDE_STRING: u32 = 0x4002_FFFF;
    /// Opaque bytes: the value is their length.
    pub const BINARY_BLOB: u32 = 0xFFFF_FFFF;
}

// ---------------------------------------------------------------------------------------------
// Header
// ---------------------------------------------------------------------------------------------

/// The value of one header tag.
#[derive(Clone, Debug, PartialEq)]
pub enum TagValue {
    /// `Empty8`.
    Empty,
    /// `Bool8`.
    Bool(bool),
    /// `Int8`.
    Int(i64),
    /// `BitSet64`.
    BitSet(u64),
    /// `Color8`.
    Color(u64),
    /// `Float8`.
    Float(f64),
    /// `TDateTime`: days since 1899-12-30.
    DateTime(f64),
    /// `Float8Array`, skipped: its byte length.
    Float8Array {
        /// Bytes of `f64` data that followed the tag.
        len: u64,
    },
    /// `AnsiString` up to its first NUL (UTF-8, or Latin-1 if not valid UTF-8).
    AnsiString(String),
    /// `WideString` (UTF-16LE) up to its first NUL.
    WideString(String),
    /// `BinaryBlob`, skipped: its byte length.
    Blob {
        /// Bytes that followed the tag.
        len: u64,
    },
    /// A string longer than 1 MiB, skipped by length.
    LongString {
        /// The tag type ([`tag_type::ANSI_STRING`] or [`tag_type::WIDE_STRING`]).
        type_code: u32,
        /// Its byte length.
        len: u64,
    },
}

impl TagValue {
    fn type_name(&self) -> &'static str {
        match self {
            Self::Empty => "Empty8",
            Self::Bool(_) => "Bool8",
            Self::Int(_) => "Int8",
            Self::BitSet(_) => "BitSet64",
            Self::Color(_) => "Color8",
            Self::Float(_) => "Float8",
            Self::DateTime(_) => "TDateTime",
            Self::Float8Array { .. } => "Float8Array",
            Self::AnsiString(_) => "AnsiString",
            Self::WideString(_) => "WideString",
            Self::Blob { .. } => "BinaryBlob",
            Self::LongString { .. } => "a long string",
        }
    }
}

/// One header tag.
#[derive(Clone, Debug, PartialEq)]
pub struct Tag {
    /// The ident, e.g. `MeasDesc_Resolution`.
    pub name: String,
    /// The array index, −1 for a plain tag.
    pub index: i32,
    /// The value.
    pub value: TagValue,
}

/// The T3 record types vltm decodes (`TTResultFormat_TTTRRecType`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum RecordType {
    /// PicoHarp 300 T3, `0x00010303`.
    PicoHarpT3,
    /// HydraHarp 400 V1 T3, `0x00010304`: one wrap-around per overflow record.
    HydraHarpV1T3,
    /// HydraHarp 400 V2 T3, `0x01010304`: overflow records carry a count.
    HydraHarpV2T3,
    /// TimeHarp 260 N T3, `0x00010305` (the demo docs' `0x01010305` is accepted too).
    TimeHarp260NT3,
    /// TimeHarp 260 P T3, `0x00010306` (and `0x01010306`).
    TimeHarp260PT3,
    /// MultiHarp T3, `0x00010307`.
    MultiHarpT3,
}

impl RecordType {
    /// The record type of a `TTResultFormat_TTTRRecType` value, if vltm decodes it.
    pub fn from_code(code: u32) -> Option<Self> {
        Some(match code {
            0x0001_0303 => Self::PicoHarpT3,
            0x0001_0304 => Self::HydraHarpV1T3,
            0x0101_0304 => Self::HydraHarpV2T3,
            0x0001_0305 | 0x0101_0305 => Self::TimeHarp260NT3,
            0x0001_0306 | 0x0101_0306 => Self::TimeHarp260PT3,
            0x0001_0307 => Self::MultiHarpT3,
            _ => return None,
        })
    }

    /// The canonical `TTResultFormat_TTTRRecType` code (as `Read_PTU.py` spells it).
    pub fn code(self) -> u32 {
        match self {
            Self::PicoHarpT3 => 0x0001_0303,
            Self::HydraHarpV1T3 => 0x0001_0304,
            Self::HydraHarpV2T3 => 0x0101_0304,
            Self::TimeHarp260NT3 => 0x0001_0305,
            Self::TimeHarp260PT3 => 0x0001_0306,
            Self::MultiHarpT3 => 0x0001_0307,
        }
    }

    /// A human-readable name.
    pub fn name(self) -> &'static str {
        match self {
            Self::PicoHarpT3 => "PicoHarp T3",
            Self::HydraHarpV1T3 => "HydraHarp V1 T3",
            Self::HydraHarpV2T3 => "HydraHarp V2 T3",
            Self::TimeHarp260NT3 => "TimeHarp 260 N T3",
            Self::TimeHarp260PT3 => "TimeHarp 260 P T3",
            Self::MultiHarpT3 => "MultiHarp T3",
        }
    }

    /// The largest `dtime` a record can hold (`2^15 − 1`, PicoHarp `2^12 − 1`).
    pub fn max_dtime(self) -> u16 {
        match self {
            Self::PicoHarpT3 => 0x0FFF,
            _ => 0x7FFF,
        }
    }
}

/// Names of record types vltm knows but does not decode (T2 mode), for error messages.
fn unsupported_record_type(code: u32) -> Option<&'static str> {
    Some(match code {
        0x0001_0203 => "PicoHarp T2",
        0x0001_0204 => "HydraHarp V1 T2",
        0x0101_0204 => "HydraHarp V2 T2",
        0x0001_0205 | 0x0101_0205 => "TimeHarp 260 N T2",
        0x0001_0206 | 0x0101_0206 => "TimeHarp 260 P T2",
        0x0001_0207 => "MultiHarp T2",
        _ => return None,
    })
}

/// Image-scan tags, if the file has them (`ImgHdr_*`, integers).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ImageTags {
    /// `ImgHdr_LineStart`: the marker input of line starts.
    pub line_start: Option<i64>,
    /// `ImgHdr_LineStop`: the marker input of line stops.
    pub line_stop: Option<i64>,
    /// `ImgHdr_Frame`: the marker input of frame starts.
    pub frame: Option<i64>,
    /// `ImgHdr_PixX`: pixels per line.
    pub pix_x: Option<i64>,
    /// `ImgHdr_PixY`: lines per frame.
    pub pix_y: Option<i64>,
}

/// A parsed and checked PTU header.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    /// The version string after the magic (e.g. `1.0.00`).
    pub version: String,
    /// Every tag in file order, `Header_End` last.
    pub tags: Vec<Tag>,
    /// `TTResultFormat_TTTRRecType`, decoded.
    pub record_type: RecordType,
    /// `TTResultFormat_TTTRRecType` as written (both TimeHarp 260 spellings map to one type).
    pub record_type_code: u32,
    /// `TTResult_NumberOfRecords`.
    pub num_records: u64,
    /// `MeasDesc_GlobalResolution`: the sync period, the unit of `sync` (s), finite and > 0.
    pub global_resolution: f64,
    /// `MeasDesc_Resolution`: the dtime bin (s), finite and > 0.
    pub resolution: f64,
    /// `TTResultFormat_BitsPerRecord` (always 32 once checked).
    pub bits_per_record: u32,
    /// The `ImgHdr_*` tags present.
    pub image: ImageTags,
    /// Header length in bytes: the records start this far after where the header started.
    pub data_offset: u64,
}

/// Reads bytes of a header, counting them, turning an early end of file into a `header` error.
struct HeaderReader<'a, R> {
    r: &'a mut R,
    pos: u64,
    path: &'a Path,
}

impl<R: Read> HeaderReader<'_, R> {
    fn eof(&self, what: &str) -> Error {
        Error::format(
            self.path,
            "header",
            format!("a complete PTU header (reading {what})"),
            format!("end of file at byte {}", self.pos),
        )
    }

    fn bytes<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        let mut buf = [0u8; N];
        let mut got = 0;
        while got < N {
            match self.r.read(&mut buf[got..]) {
                Ok(0) => return Err(self.eof(what)),
                Ok(n) => {
                    got += n;
                    self.pos += n as u64;
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(Error::io(self.path, e)),
            }
        }
        Ok(buf)
    }

    /// Reads (`keep`, at most [`MAX_STRING`] bytes) or skips the `len` bytes after a tag.
    fn payload(&mut self, raw_len: i64, name: &str, keep: bool) -> Result<(u64, Option<Vec<u8>>)> {
        let len = u64::try_from(raw_len)
            .map_err(|_| Error::format(self.path, name, "a payload length ≥ 0", raw_len))?;
        let what = format!("the {len}-byte value of tag `{name}`");
        let mut take = (&mut *self.r).take(len);
        let (n, data) = if keep && len <= MAX_STRING {
            let mut v = Vec::with_capacity(len as usize);
            let n = take
                .read_to_end(&mut v)
                .map_err(|e| Error::io(self.path, e))?;
            (n as u64, Some(v))
        } else {
            let n = io::copy(&mut take, &mut io::sink()).map_err(|e| Error::io(self.path, e))?;
            (n, None)
        };
        self.pos += n;
        if n < len {
            return Err(self.eof(&what));
        }
        Ok((len, data))
    }
}

fn until_nul(b: &[u8]) -> &[u8] {
    b.iter().position(|&c| c == 0).map_or(b, |i| &b[..i])
}

fn ansi(b: &[u8]) -> String {
    let b = until_nul(b);
    match std::str::from_utf8(b) {
        Ok(s) => s.to_owned(),
        Err(_) => b.iter().map(|&c| char::from(c)).collect(),
    }
}

fn wide(b: &[u8]) -> String {
    let units: Vec<u16> = b
        .chunks_exact(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .take_while(|&u| u != 0)
        .collect();
    char::decode_utf16(units)
        .map(|c| c.unwrap_or(char::REPLACEMENT_CHARACTER))
        .collect()
}

impl Header {
    /// Reads and checks a header from `r`, leaving `r` at the first record.
    ///
    /// Checks: the magic; every tag type known; `TTResultFormat_TTTRRecType` a T3 type vltm
    /// decodes; `TTResultFormat_BitsPerRecord` = 32; `TTResult_NumberOfRecords` ≥ 0;
    /// `MeasDesc_GlobalResolution` and `MeasDesc_Resolution` finite and > 0; the `ImgHdr_*`
    /// tags, when present, integers. `path` names the file in errors.
    ///
    /// # Errors
    /// [`Error::Format`] as in the module's table; [`Error::Io`] if reading fails.
    pub fn read<R: Read>(r: &mut R, path: &Path) -> Result<Self> {
        let mut h = HeaderReader { r, pos: 0, path };
        let magic = h.bytes::<8>("the magic")?;
        if magic != MAGIC {
            return Err(Error::format(
                path,
                "magic",
                "\"PQTTTR\" (a PicoQuant PTU file)",
                format!("{:?}", String::from_utf8_lossy(&magic)),
            ));
        }
        let version = ansi(&h.bytes::<8>("the version")?);
        let mut tags = Vec::new();
        loop {
            if tags.len() >= MAX_TAGS {
                return Err(Error::format(
                    path,
                    "header",
                    format!("`Header_End` within {MAX_TAGS} tags"),
                    "more tags",
                ));
            }
            let ident = h.bytes::<32>("a tag ident")?;
            let name = ansi(&ident);
            let what = format!("tag `{name}`");
            let index = i32::from_le_bytes(h.bytes::<4>(&what)?);
            let ty = u32::from_le_bytes(h.bytes::<4>(&what)?);
            let raw = h.bytes::<8>(&what)?;
            let int = i64::from_le_bytes(raw);
            let float = f64::from_le_bytes(raw);
            let value = match ty {
                tag_type::EMPTY8 => TagValue::Empty,
                tag_type::BOOL8 => TagValue::Bool(int != 0),
                tag_type::INT8 => TagValue::Int(int),
                tag_type::BITSET64 => TagValue::BitSet(int as u64),
                tag_type::COLOR8 => TagValue::Color(int as u64),
                tag_type::FLOAT8 => TagValue::Float(float),
                tag_type::DATETIME => TagValue::DateTime(float),
                tag_type::FLOAT8_ARRAY => TagValue::Float8Array {
                    len: h.payload(int, &name, false)?.0,
                },
                tag_type::BINARY_BLOB => TagValue::Blob {
                    len: h.payload(int, &name, false)?.0,
                },
                tag_type::ANSI_STRING | tag_type::WIDE_STRING => {
                    match h.payload(int, &name, true)? {
                        (_, Some(b)) if ty == tag_type::ANSI_STRING => {
                            TagValue::AnsiString(ansi(&b))
                        }
                        (_, Some(b)) => TagValue::WideString(wide(&b)),
                        (len, None) => TagValue::LongString { type_code: ty, len },
                    }
                }
                _ => {
                    return Err(Error::format(
                        path,
                        &name,
                        "a PTU tag type (Empty8, Bool8, Int8, BitSet64, Color8, Float8, \
                         TDateTime, Float8Array, AnsiString, WideString, BinaryBlob)",
                        format!("type 0x{ty:08X}"),
                    ));
                }
            };
            let end = name == "Header_End";
            tags.push(Tag { name, index, value });
            if end {
                break;
            }
        }
        let data_offset = h.pos;
        Self::from_tags(version, tags, data_offset, path)
    }

    /// Builds the checked header from its tags (see [`Header::read`]).
    fn from_tags(version: String, tags: Vec<Tag>, data_offset: u64, path: &Path) -> Result<Self> {
        let find = |name: &str| tags.iter().find(|t| t.name == name).map(|t| &t.value);
        let int = |name: &str| -> Result<Option<i64>> {
            match find(name) {
                None => Ok(None),
                Some(TagValue::Int(v)) => Ok(Some(*v)),
                Some(v) => Err(Error::format(
                    path,
                    name,
                    "an Int8 tag",
                    format!("a {} tag", v.type_name()),
                )),
            }
        };
        let need = |name: &str, v: Option<i64>| {
            v.ok_or_else(|| Error::format(path, name, "this tag in the header", "no such tag"))
        };
        let seconds = |name: &str| -> Result<f64> {
            let v = match find(name) {
                None => {
                    return Err(Error::format(
                        path,
                        name,
                        "this tag in the header",
                        "no such tag",
                    ));
                }
                Some(TagValue::Float(v)) => *v,
                Some(v) => {
                    return Err(Error::format(
                        path,
                        name,
                        "a Float8 tag",
                        format!("a {} tag", v.type_name()),
                    ));
                }
            };
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                Err(Error::format(path, name, "a finite time > 0 (s)", v))
            }
        };

        const REC_TYPE: &str = "TTResultFormat_TTTRRecType";
        let code = need(REC_TYPE, int(REC_TYPE)?)?;
        let code32 = u32::try_from(code).ok();
        let record_type = code32.and_then(RecordType::from_code).ok_or_else(|| {
            let what = code32
                .and_then(unsupported_record_type)
                .map_or(String::new(), |n| {
                    format!(" ({n}: T2 mode is not supported)")
                });
            Error::format(
                path,
                REC_TYPE,
                "a T3 record type (PicoHarp 0x00010303, HydraHarp 0x00010304/0x01010304, \
                 TimeHarp 260 0x00010305/0x00010306, MultiHarp 0x00010307)",
                format!("0x{code:08X}{what}"),
            )
        })?;

        const BITS: &str = "TTResultFormat_BitsPerRecord";
        let bits = need(BITS, int(BITS)?)?;
        if bits != 32 {
            return Err(Error::format(path, BITS, 32, bits));
        }
        const NUM: &str = "TTResult_NumberOfRecords";
        let num = need(NUM, int(NUM)?)?;
        let num_records =
            u64::try_from(num).map_err(|_| Error::format(path, NUM, "a record count ≥ 0", num))?;
        let global_resolution = seconds("MeasDesc_GlobalResolution")?;
        let resolution = seconds("MeasDesc_Resolution")?;
        let image = ImageTags {
            line_start: int("ImgHdr_LineStart")?,
            line_stop: int("ImgHdr_LineStop")?,
            frame: int("ImgHdr_Frame")?,
            pix_x: int("ImgHdr_PixX")?,
            pix_y: int("ImgHdr_PixY")?,
        };
        Ok(Self {
            version,
            record_type,
            record_type_code: code as u32,
            num_records,
            global_resolution,
            resolution,
            bits_per_record: 32,
            image,
            data_offset,
            tags,
        })
    }

    /// The value of the first tag named `name` (any index).
    pub fn get(&self, name: &str) -> Option<&TagValue> {
        self.tags.iter().find(|t| t.name == name).map(|t| &t.value)
    }

    /// The value of tag `name` with array index `index` (−1 for a plain tag).
    pub fn get_indexed(&self, name: &str, index: i32) -> Option<&TagValue> {
        self.tags
            .iter()
            .find(|t| t.name == name && t.index == index)
            .map(|t| &t.value)
    }
}

// ---------------------------------------------------------------------------------------------
// Records
// ---------------------------------------------------------------------------------------------

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
    reader: R,
    decoder: Decoder,
    total: u64,
    read: u64,
    path: PathBuf,
    done: bool,
    overflow_records: u64,
    reserved_records: u64,
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
    fn restart(&mut self) {
        self.decoder = Decoder::new(self.decoder.kind);
        self.read = 0;
        self.done = false;
        self.overflow_records = 0;
        self.reserved_records = 0;
    }

    /// Reads up to 4 bytes: the count read (< 4 only at the end of the data) and the bytes.
    fn read4(&mut self) -> io::Result<(usize, [u8; 4])> {
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

    fn next_inner(&mut self) -> Result<Option<Event>> {
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

// ---------------------------------------------------------------------------------------------
// Sidecar and rows
// ---------------------------------------------------------------------------------------------

/// What to do with photons on channels that no SPAD maps.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Unmapped {
    /// Fail with an error naming the channel and the record (default).
    #[default]
    Error,
    /// Drop them, counted in [`Counts::unmapped`].
    Drop,
}

fn default_marker() -> u32 {
    1
}
fn default_rebin() -> u32 {
    1
}
fn default_laser_origin() -> [f64; 3] {
    DEFAULT_LASER_ORIGIN
}
fn default_sensor_origin() -> [f64; 3] {
    DEFAULT_SENSOR_ORIGIN
}

/// The scan description that goes with a PTU file (a JSON file; format in the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sidecar {
    /// Number of laser rows (= laser spots); `None`: the number of laser spots.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rows: Option<usize>,
    /// The marker input (1..=4) whose markers start laser rows.
    #[serde(default = "default_marker")]
    pub row_marker: u32,
    /// Laser spots; row `l` is spot `l`.
    pub lasers: Aperture,
    /// SPAD spots; `None` only for a confocal scan.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spads: Option<Aperture>,
    /// Confocal scan: one histogram per row, SPAD at the laser spot.
    #[serde(default)]
    pub confocal: bool,
    /// 0-based detector channel of each SPAD; `None`: SPAD `s` on channel `s`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub channels: Option<Vec<u32>>,
    /// What to do with photons on channels no SPAD maps.
    #[serde(default)]
    pub unmapped_channels: Unmapped,
    /// Histogram bins per SPAD (≥ 1).
    pub nt: usize,
    /// Path length (m) of raw dtime bin 0, after all delays.
    pub t0: f64,
    /// Width of one raw dtime bin (m of path); `None`: `MeasDesc_Resolution·c`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bin_width: Option<f64>,
    /// Raw dtime bins per histogram bin (≥ 1).
    #[serde(default = "default_rebin")]
    pub rebin: u32,
    /// The first raw dtime bin kept.
    #[serde(default)]
    pub first_dtime: u32,
    /// Laser device position (m).
    #[serde(default = "default_laser_origin")]
    pub laser_origin: [f64; 3],
    /// Sensor device position (m).
    #[serde(default = "default_sensor_origin")]
    pub sensor_origin: [f64; 3],
    /// Whether path lengths include the device legs.
    #[serde(default)]
    pub legs_in_time: bool,
}

/// The sidecar resolved against a header: everything the binning loop needs.
#[derive(Clone, Debug)]
struct Plan {
    geometry: Geometry,
    rows: usize,
    ks: usize,
    row_bits: u8,
    spad_of_channel: [Option<usize>; CHANNELS],
    first: u64,
    rebin: u64,
    end: u64,
    unmapped_error: bool,
}

fn spots_of(a: &Aperture, path: &Path, field: &str) -> Result<(Vec<Point>, [usize; 2])> {
    let shape = a.shape();
    let spots = a.spots();
    if spots.is_empty() || shape[0].checked_mul(shape[1]) != Some(spots.len()) {
        return Err(Error::format(
            path,
            field,
            "a non-empty grid or point list whose shape matches its spots",
            format!("shape {shape:?} with {} spots", spots.len()),
        ));
    }
    if let Aperture::Grid {
        shape,
        size,
        center,
    } = a
    {
        let ok = (0..2).all(|i| size[i].is_finite() && (shape[i] == 1 || size[i] > 0.0))
            && center.iter().all(|c| c.is_finite());
        if !ok {
            return Err(Error::format(
                path,
                field,
                "finite sizes (> 0 on axes with more than one spot) and centre",
                format!("size {size:?}, center {center:?}"),
            ));
        }
    }
    if let Some(i) = spots.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        return Err(Error::format(
            path,
            field,
            "finite coordinates",
            format!("{:?} at spot {i}", spots[i]),
        ));
    }
    Ok((spots.iter().map(|p| p.map(|c| c as f32)).collect(), shape))
}

impl Sidecar {
    /// Parses a sidecar; `path` names it in errors.
    ///
    /// # Errors
    /// [`Error::Format`] (field `sidecar`) for malformed JSON, unknown or missing fields.
    pub fn from_json_str(json: &str, path: impl AsRef<Path>) -> Result<Self> {
        serde_json::from_str(json).map_err(|e| {
            Error::format(
                path.as_ref(),
                "sidecar",
                "a PTU sidecar (JSON, see vltm::ptu)",
                e.to_string(),
            )
        })
    }

    /// Reads a sidecar file.
    ///
    /// # Errors
    /// [`Error::Io`] if unreadable, else as [`Sidecar::from_json_str`].
    pub fn load(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        let json = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
        Self::from_json_str(&json, path)
    }

    /// The sidecar as pretty-printed JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a sidecar always serialises")
    }

    /// The capture geometry the rows will have, for a file with this `header`.
    ///
    /// # Errors
    /// [`Error::Format`] naming the sidecar's field for invalid values (module docs).
    pub fn geometry(&self, header: &Header, path: &Path) -> Result<Geometry> {
        Ok(self.plan(header, path)?.geometry)
    }

    fn plan(&self, header: &Header, path: &Path) -> Result<Plan> {
        let (lasers, laser_shape) = spots_of(&self.lasers, path, "lasers")?;
        let (spads, spad_shape) = match (&self.spads, self.confocal) {
            (Some(a), false) => spots_of(a, path, "spads")?,
            (None, false) => {
                return Err(Error::format(
                    path,
                    "spads",
                    "SPAD spots (required unless confocal)",
                    "none",
                ));
            }
            (Some(a), true) => {
                let s = spots_of(a, path, "spads")?;
                if s.0 != lasers {
                    return Err(Error::format(
                        path,
                        "spads",
                        "the laser spots (confocal) or no `spads`",
                        "different spots",
                    ));
                }
                s
            }
            (None, true) => (lasers.clone(), laser_shape),
        };
        let rows = lasers.len();
        if let Some(r) = self.rows
            && r != rows
        {
            return Err(Error::format(
                path,
                "rows",
                format!("the number of laser spots, {rows}"),
                r,
            ));
        }
        if !(1..=MAX_MARKER).contains(&self.row_marker) {
            return Err(Error::format(
                path,
                "row_marker",
                format!("a marker input 1..={MAX_MARKER}"),
                self.row_marker,
            ));
        }
        let ks = if self.confocal { 1 } else { spads.len() };
        if self.nt == 0 {
            return Err(Error::format(path, "nt", "at least one bin", 0));
        }
        if self.rebin == 0 {
            return Err(Error::format(path, "rebin", "at least 1", 0));
        }
        if !self.t0.is_finite() {
            return Err(Error::format(
                path,
                "t0",
                "a finite path length (m)",
                self.t0,
            ));
        }
        let width = match self.bin_width {
            Some(w) if w.is_finite() && w > 0.0 => w,
            Some(w) => {
                return Err(Error::format(
                    path,
                    "bin_width",
                    "a finite width > 0 (m)",
                    w,
                ));
            }
            None => header.resolution * SPEED_OF_LIGHT,
        };
        for (name, v) in [
            ("laser_origin", &self.laser_origin),
            ("sensor_origin", &self.sensor_origin),
        ] {
            if !v.iter().all(|c| c.is_finite()) {
                return Err(Error::format(
                    path,
                    name,
                    "finite coordinates",
                    format!("{v:?}"),
                ));
            }
        }
        let channels: Vec<u32> = match &self.channels {
            Some(c) => c.clone(),
            None => (0..ks as u32).collect(),
        };
        if channels.len() != ks {
            return Err(Error::format(
                path,
                "channels",
                format!("one channel per SPAD ({ks})"),
                format!("{} channels", channels.len()),
            ));
        }
        let mut spad_of_channel = [None; CHANNELS];
        for (s, &c) in channels.iter().enumerate() {
            let slot = spad_of_channel.get_mut(c as usize).ok_or_else(|| {
                Error::format(
                    path,
                    "channels",
                    format!("detector channels 0..{CHANNELS}"),
                    format!("channel {c} for SPAD {s}"),
                )
            })?;
            if slot.is_some() {
                return Err(Error::format(
                    path,
                    "channels",
                    "one SPAD per channel",
                    format!("channel {c} given twice"),
                ));
            }
            *slot = Some(s);
        }
        let rebin = u64::from(self.rebin);
        let first = u64::from(self.first_dtime);
        let nt = self.nt as u64;
        let end = nt
            .checked_mul(rebin)
            .and_then(|n| n.checked_add(first))
            .ok_or_else(|| Error::format(path, "nt", "a window that fits in 64 bits", nt))?;
        let geometry = Geometry {
            lasers,
            laser_shape,
            spads,
            spad_shape,
            laser_origin: self.laser_origin,
            sensor_origin: self.sensor_origin,
            legs_in_time: self.legs_in_time,
            confocal: self.confocal,
            nt: self.nt,
            dt: width * f64::from(self.rebin),
            t0: self.t0 + (f64::from(self.first_dtime) + f64::from(self.rebin - 1) / 2.0) * width,
        };
        geometry.validate(path)?;
        Ok(Plan {
            geometry,
            rows,
            ks,
            row_bits: 1 << (self.row_marker - 1),
            spad_of_channel,
            first,
            rebin,
            end,
            unmapped_error: self.unmapped_channels == Unmapped::Error,
        })
    }
}

/// What happened to the records of the current pass over a file ([`PtuSource::counts`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counts {
    /// Photons binned into rows that were read.
    pub binned: u64,
    /// Photons before the first row marker (dropped).
    pub before_first_marker: u64,
    /// Photons of rows passed over to reach a later row (not binned).
    pub skipped_rows: u64,
    /// Photons with dtime outside the kept window (dropped).
    pub outside_window: u64,
    /// Photons on unmapped channels (dropped, with `"unmapped_channels": "drop"`).
    pub unmapped: u64,
    /// Marker records without the row bit (ignored).
    pub other_markers: u64,
    /// Overflow records.
    pub overflow_records: u64,
    /// Reserved special records (ignored).
    pub reserved_records: u64,
}

/// Laser rows binned from a PTU file's photons: a [`RowSource`] (conventions in the module
/// docs). Rows are read in one streaming pass; an earlier row rewinds and rescans.
#[derive(Debug)]
pub struct PtuSource<R = BufReader<File>> {
    path: PathBuf,
    header: Header,
    sidecar: Sidecar,
    plan: Plan,
    records: Records<R>,
    data_start: u64,
    /// Row markers consumed: the reader is just after the `markers_seen`-th one.
    markers_seen: usize,
    /// The reader is past the last row or an error: the next row rewinds.
    exhausted: bool,
    counts: Counts,
    hist: Vec<u32>,
}

impl PtuSource<BufReader<File>> {
    /// Opens a PTU file with its sidecar.
    ///
    /// # Errors
    /// [`Error::Io`] if a file cannot be read; header and sidecar errors (module docs).
    pub fn open(ptu: impl AsRef<Path>, sidecar: impl AsRef<Path>) -> Result<Self> {
        let (ptu, sidecar_path) = (ptu.as_ref(), sidecar.as_ref());
        let sidecar = Sidecar::load(sidecar_path)?;
        let f = File::open(ptu).map_err(|e| Error::io(ptu, e))?;
        Self::from_reader(BufReader::new(f), ptu, sidecar, sidecar_path)
    }
}

impl<R: BufRead + Seek> PtuSource<R> {
    /// A source over `reader`, positioned at the start of a PTU header. `path` and
    /// `sidecar_path` name the file and the sidecar in errors.
    ///
    /// # Errors
    /// As [`PtuSource::open`].
    pub fn from_reader(
        mut reader: R,
        path: impl Into<PathBuf>,
        sidecar: Sidecar,
        sidecar_path: &Path,
    ) -> Result<Self> {
        let path = path.into();
        let start = reader.stream_position().map_err(|e| Error::io(&path, e))?;
        let header = Header::read(&mut reader, &path)?;
        let plan = sidecar.plan(&header, sidecar_path)?;
        let records = Records::new(reader, &header, path.clone());
        let hist = vec![0; plan.ks * plan.geometry.nt];
        Ok(Self {
            data_start: start + header.data_offset,
            path,
            header,
            sidecar,
            plan,
            records,
            markers_seen: 0,
            exhausted: false,
            counts: Counts::default(),
            hist,
        })
    }

    /// The file's header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// The sidecar.
    pub fn sidecar(&self) -> &Sidecar {
        &self.sidecar
    }

    /// Laser rows (= laser spots).
    pub fn rows(&self) -> usize {
        self.plan.rows
    }

    /// Counts of the current pass over the file (restart when a row rewinds it).
    pub fn counts(&self) -> Counts {
        Counts {
            overflow_records: self.records.overflow_records(),
            reserved_records: self.records.reserved_records(),
            ..self.counts
        }
    }

    fn rewind(&mut self) -> Result<()> {
        self.records
            .reader
            .seek(SeekFrom::Start(self.data_start))
            .map_err(|e| Error::io(&self.path, e))?;
        self.records.restart();
        self.markers_seen = 0;
        self.exhausted = false;
        self.counts = Counts::default();
        Ok(())
    }

    fn too_few_markers(&self) -> Error {
        Error::format(
            &self.path,
            "markers",
            format!(
                "{} row markers (marker input {}), one per laser row of the sidecar",
                self.plan.rows, self.sidecar.row_marker
            ),
            format!("{} before the end of the records", self.markers_seen),
        )
    }

    fn read_row_counts(&mut self, l: usize) -> Result<()> {
        if l >= self.plan.rows {
            return Err(Error::arg(
                "row",
                format!("laser row {l} of a {}-row PTU capture", self.plan.rows),
            ));
        }
        if self.exhausted || self.markers_seen > l + 1 {
            self.rewind()?;
        }
        let r = self.bin_row(l);
        // After an error or the last row the reader is not at a row start: rewind next time.
        self.exhausted = r.is_err() || l + 1 == self.plan.rows;
        r
    }

    /// Bins row `l` from a position at or before its row marker.
    fn bin_row(&mut self, l: usize) -> Result<()> {
        let bits = self.plan.row_bits;
        // Skip to the start of row l.
        while self.markers_seen <= l {
            match self.records.next_event()? {
                None => return Err(self.too_few_markers()),
                Some(Event::Marker { bits: b, .. }) if b & bits != 0 => self.markers_seen += 1,
                Some(Event::Marker { .. }) => self.counts.other_markers += 1,
                Some(Event::Photon { .. }) if self.markers_seen == 0 => {
                    self.counts.before_first_marker += 1;
                }
                Some(Event::Photon { .. }) => self.counts.skipped_rows += 1,
            }
        }
        self.hist.fill(0);
        let nt = self.plan.geometry.nt;
        loop {
            match self.records.next_event()? {
                None if l + 1 < self.plan.rows => return Err(self.too_few_markers()),
                None => return Ok(()),
                Some(Event::Marker { bits: b, .. }) if b & bits != 0 => {
                    if l + 1 == self.plan.rows {
                        return Err(Error::format(
                            &self.path,
                            "markers",
                            format!(
                                "{} row markers (marker input {}), one per laser row of the \
                                 sidecar",
                                self.plan.rows, self.sidecar.row_marker
                            ),
                            format!(
                                "more: an extra row marker at record {}",
                                self.records.records_read() - 1
                            ),
                        ));
                    }
                    self.markers_seen += 1;
                    return Ok(());
                }
                Some(Event::Marker { .. }) => self.counts.other_markers += 1,
                Some(Event::Photon { channel, dtime, .. }) => {
                    let Some(s) = self.plan.spad_of_channel[usize::from(channel) % CHANNELS] else {
                        if self.plan.unmapped_error {
                            return Err(Error::format(
                                &self.path,
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
                                    "a photon on channel {channel} at record {}",
                                    self.records.records_read() - 1
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
                }
            }
        }
    }
}

impl<R: BufRead + Seek> RowSource for PtuSource<R> {
    fn geometry(&self) -> &Geometry {
        &self.plan.geometry
    }

    /// Bins laser row `l` (see the module docs for the streaming order and its costs).
    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        self.read_row_counts(l)?;
        out.clear();
        out.extend(self.hist.iter().map(|&c| c as f32));
        Ok(self.plan.geometry.lasers[l])
    }
}

/// Reads a whole PTU capture: every laser row, in one pass.
///
/// # Errors
/// As [`PtuSource::open`] and [`RowSource::read_row`].
pub fn read_all(ptu: impl AsRef<Path>, sidecar: impl AsRef<Path>) -> Result<Capture> {
    let ptu = ptu.as_ref();
    let mut src = PtuSource::open(ptu, sidecar)?;
    collect(&mut src, ptu)
}

fn collect<R: BufRead + Seek>(src: &mut PtuSource<R>, path: &Path) -> Result<Capture> {
    let mut data = Vec::with_capacity(src.rows() * src.hist.len());
    let mut row = Vec::new();
    for l in 0..src.rows() {
        src.read_row(l, &mut row)?;
        data.extend_from_slice(&row);
    }
    Capture::new(src.geometry().clone(), data, path)
}

// ---------------------------------------------------------------------------------------------
// Writer
// ---------------------------------------------------------------------------------------------

/// Writes PTU header tags.
struct TagWriter<W> {
    w: W,
}

impl<W: Write> TagWriter<W> {
    fn raw(&mut self, name: &str, index: i32, ty: u32, value: [u8; 8]) -> io::Result<()> {
        let mut ident = [0u8; 32];
        let n = name.len().min(31);
        ident[..n].copy_from_slice(&name.as_bytes()[..n]);
        self.w.write_all(&ident)?;
        self.w.write_all(&index.to_le_bytes())?;
        self.w.write_all(&ty.to_le_bytes())?;
        self.w.write_all(&value)
    }
    fn int(&mut self, name: &str, v: i64) -> io::Result<()> {
        self.raw(name, -1, tag_type::INT8, v.to_le_bytes())
    }
    fn float(&mut self, name: &str, v: f64) -> io::Result<()> {
        self.raw(name, -1, tag_type::FLOAT8, v.to_le_bytes())
    }
    /// An `AnsiString`, NUL-terminated and padded to a multiple of 8 bytes as PicoQuant does.
    fn string(&mut self, name: &str, s: &str) -> io::Result<()> {
        let len = (s.len() + 1).div_ceil(8) * 8;
        self.raw(name, -1, tag_type::ANSI_STRING, (len as i64).to_le_bytes())?;
        self.w.write_all(s.as_bytes())?;
        self.w.write_all(&vec![0u8; len - s.len()])
    }
}

/// A HydraHarp-family T3 record from its fields.
fn ht3(special: bool, channel: u8, dtime: u16, nsync: u16) -> u32 {
    (u32::from(special) << 31)
        | (u32::from(channel & 0x3F) << 25)
        | (u32::from(dtime & 0x7FFF) << 10)
        | u32::from(nsync & 0x03FF)
}

/// Options of [`write_t3`].
#[derive(Clone, Debug, PartialEq)]
pub struct T3WriteOptions {
    /// Sync period, `MeasDesc_GlobalResolution` (s). Default 50 ns (20 MHz).
    pub sync_period: f64,
    /// Marker input (1..=4) of the row markers. Default 1.
    pub row_marker: u32,
    /// Sync periods between consecutive photons of a row. Default 1.
    pub syncs_per_photon: u32,
    /// Sync periods between the last photon of a row and the next row's marker (exercises
    /// multi-overflow records). Default 5000.
    pub syncs_between_rows: u64,
    /// Where [`write_t3`] writes the sidecar; `None`: the PTU path with extension `.json`.
    pub sidecar: Option<PathBuf>,
}

impl Default for T3WriteOptions {
    fn default() -> Self {
        Self {
            sync_period: 50e-9,
            row_marker: 1,
            syncs_per_photon: 1,
            syncs_between_rows: 5000,
            sidecar: None,
        }
    }
}

/// What [`write_t3`] / [`write_t3_to`] wrote.
#[derive(Clone, Debug, PartialEq)]
pub struct T3Written {
    /// The sidecar that reads the file back as the capture.
    pub sidecar: Sidecar,
    /// Where [`write_t3`] wrote the sidecar (`None` from [`write_t3_to`]).
    pub sidecar_path: Option<PathBuf>,
    /// Records in the file (`TTResult_NumberOfRecords`).
    pub records: u64,
    /// Photon records.
    pub photons: u64,
    /// Row marker records (one per laser row).
    pub markers: u64,
    /// Overflow records.
    pub overflow_records: u64,
}

/// Emits the records of a capture, keeping the overflow state.
struct Emitter<'a> {
    overflow: u64,
    records: u64,
    overflow_records: u64,
    sink: &'a mut dyn FnMut(u32) -> Result<()>,
}

impl Emitter<'_> {
    /// Emits overflow records up to sync `t`, then `make(t − overflow)`.
    fn at(&mut self, t: u64, make: impl Fn(u16) -> u32) -> Result<()> {
        while t - self.overflow >= 1024 {
            let n = ((t - self.overflow) / 1024).min(1023);
            (self.sink)(ht3(true, 0x3F, 0, n as u16))?;
            self.overflow += 1024 * n;
            self.records += 1;
            self.overflow_records += 1;
        }
        (self.sink)(make((t - self.overflow) as u16))?;
        self.records += 1;
        Ok(())
    }
}

fn emit(
    capture: &Capture,
    opts: &T3WriteOptions,
    path: &Path,
    sink: &mut dyn FnMut(u32) -> Result<()>,
) -> Result<T3Written> {
    let g = &capture.geometry;
    let (ks, nt) = (g.spads_per_row(), g.nt);
    let bits = 1u8 << (opts.row_marker - 1);
    let mut e = Emitter {
        overflow: 0,
        records: 0,
        overflow_records: 0,
        sink,
    };
    let (mut t, mut photons) = (0u64, 0u64);
    for l in 0..g.lasers.len() {
        e.at(t, |nsync| ht3(true, bits, 0, nsync))?;
        t += 1;
        for (i, &v) in capture.row(l).iter().enumerate() {
            let r = v.round();
            if !(0.0..=u32::MAX as f32).contains(&r) {
                return Err(Error::format(
                    path,
                    "H",
                    "finite photon counts ≥ 0 (rounded) below 2^32",
                    format!("{v} at laser {l}, SPAD {}, bin {}", i / nt, i % nt),
                ));
            }
            let (s, n) = ((i / nt) as u8, (i % nt) as u16);
            for _ in 0..r as u64 {
                e.at(t, |nsync| ht3(false, s, n, nsync))?;
                t += u64::from(opts.syncs_per_photon);
                photons += 1;
            }
        }
        t += opts.syncs_between_rows;
    }
    let to64 = |p: &Point| p.map(f64::from);
    let sidecar = Sidecar {
        rows: Some(g.lasers.len()),
        row_marker: opts.row_marker,
        lasers: Aperture::Points {
            points: g.lasers.iter().map(to64).collect(),
            shape: g.laser_shape,
        },
        spads: (!g.confocal).then(|| Aperture::Points {
            points: g.spads.iter().map(to64).collect(),
            shape: g.spad_shape,
        }),
        confocal: g.confocal,
        channels: Some((0..ks as u32).collect()),
        unmapped_channels: Unmapped::Error,
        nt,
        t0: g.t0,
        bin_width: Some(g.dt),
        rebin: 1,
        first_dtime: 0,
        laser_origin: g.laser_origin,
        sensor_origin: g.sensor_origin,
        legs_in_time: g.legs_in_time,
    };
    Ok(T3Written {
        sidecar,
        sidecar_path: None,
        records: e.records,
        photons,
        markers: g.lasers.len() as u64,
        overflow_records: e.overflow_records,
    })
}

/// Writes `capture` as a synthetic HydraHarp V2 T3 PTU stream to `w` and returns the
/// matching sidecar (not written) and record counts. `path` names the output in errors.
///
/// Each laser row is a row marker (input `opts.row_marker`) followed by, for every SPAD `s`
/// (on channel `s`) and bin `n`, `round(H[l][s][n])` photon records with `dtime = n`, one every
/// `opts.syncs_per_photon` sync periods; overflow records (V2, with counts) are emitted
/// whenever the 10-bit `nsync` would wrap. `MeasDesc_Resolution` is `dt/c`; the sidecar gives
/// the bin width `dt` and `t0` explicitly, so the rows read back equal the rounded histograms
/// and the geometry equals the capture's.
///
/// # Errors
/// [`Error::Argument`] for a capture the format cannot hold (more than 64 SPADs per row, more
/// than 32768 bins) or bad options; [`Error::Format`] (field `H`) for a count that is not
/// finite, negative or ≥ 2^32 after rounding; [`Error::Io`] if writing fails.
pub fn write_t3_to<W: Write>(
    capture: &Capture,
    w: W,
    opts: &T3WriteOptions,
    path: &Path,
) -> Result<T3Written> {
    let g = &capture.geometry;
    g.validate(path)?;
    let want = g.lasers.len() * g.spads_per_row() * g.nt;
    if capture.data.len() != want {
        return Err(Error::format(
            path,
            "H",
            format!("{want} values"),
            capture.data.len(),
        ));
    }
    if g.spads_per_row() > CHANNELS {
        return Err(Error::arg(
            "capture",
            format!(
                "{} SPADs per row: a T3 file has at most {CHANNELS} channels",
                g.spads_per_row()
            ),
        ));
    }
    if g.nt > 0x8000 {
        return Err(Error::arg(
            "capture",
            format!("{} bins: a HydraHarp T3 record holds at most 32768", g.nt),
        ));
    }
    if !(opts.sync_period.is_finite() && opts.sync_period > 0.0) {
        return Err(Error::arg(
            "sync_period",
            format!("a finite period > 0 (s), not {}", opts.sync_period),
        ));
    }
    if !(1..=MAX_MARKER).contains(&opts.row_marker) {
        return Err(Error::arg(
            "row_marker",
            format!("a marker input 1..={MAX_MARKER}, not {}", opts.row_marker),
        ));
    }
    let resolution = g.dt / SPEED_OF_LIGHT;
    // Pass 1 counts the records (and checks the counts); pass 2 writes them.
    let written = emit(capture, opts, path, &mut |_| Ok(()))?;

    let io = |e: io::Error| Error::io(path, e);
    let mut tw = TagWriter {
        w: BufWriter::new(w),
    };
    tw.w.write_all(&MAGIC).map_err(io)?;
    tw.w.write_all(b"1.0.00\0\0").map_err(io)?;
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64());
    let max_channel = g.spads_per_row() as i64;
    (|| -> io::Result<()> {
        tw.string(
            "File_Comment",
            "synthetic HydraHarp V2 T3 capture written by vltm (see its .json sidecar)",
        )?;
        tw.raw(
            "File_CreatingTime",
            -1,
            tag_type::DATETIME,
            (now / 86_400.0 + 25_569.0).to_le_bytes(),
        )?;
        tw.string("CreatorSW_Name", "vltm")?;
        tw.string("CreatorSW_Version", env!("CARGO_PKG_VERSION"))?;
        tw.string("HW_Type", "HydraHarp")?;
        tw.int("HW_InpChannels", max_channel + 1)?;
        tw.int("Measurement_Mode", 3)?;
        tw.int("Measurement_SubMode", 0)?;
        tw.int("HWSync_Divider", 1)?;
        tw.int("TTResult_SyncRate", (1.0 / opts.sync_period).round() as i64)?;
        tw.float("MeasDesc_GlobalResolution", opts.sync_period)?;
        tw.float("MeasDesc_Resolution", resolution)?;
        tw.int("MeasDesc_BinningFactor", 1)?;
        tw.int(
            "TTResultFormat_TTTRRecType",
            i64::from(RecordType::HydraHarpV2T3.code()),
        )?;
        tw.int("TTResultFormat_BitsPerRecord", 32)?;
        tw.int("TTResult_NumberOfRecords", written.records as i64)?;
        tw.raw("Header_End", -1, tag_type::EMPTY8, [0; 8])
    })()
    .map_err(io)?;
    let out = &mut tw.w;
    emit(capture, opts, path, &mut |rec| {
        out.write_all(&rec.to_le_bytes()).map_err(io)
    })?;
    tw.w.flush().map_err(io)?;
    Ok(written)
}

/// Writes `capture` as a synthetic HydraHarp V2 T3 PTU file at `path` (see [`write_t3_to`])
/// and its sidecar (`opts.sidecar`, default `path` with extension `.json`), so that
/// [`read_all`]`(path, sidecar)` gives back the capture with its histograms rounded to whole
/// photons.
///
/// # Errors
/// As [`write_t3_to`]; [`Error::Argument`] if the sidecar path is the PTU path.
pub fn write_t3(
    capture: &Capture,
    path: impl AsRef<Path>,
    opts: &T3WriteOptions,
) -> Result<T3Written> {
    let path = path.as_ref();
    let sidecar_path = opts
        .sidecar
        .clone()
        .unwrap_or_else(|| path.with_extension("json"));
    if sidecar_path == path {
        return Err(Error::arg(
            "sidecar",
            format!(
                "{}: the sidecar would overwrite the PTU file",
                path.display()
            ),
        ));
    }
    let f = File::create(path).map_err(|e| Error::io(path, e))?;
    let mut written = write_t3_to(capture, f, opts, path)?;
    std::fs::write(&sidecar_path, written.sidecar.to_json() + "\n")
        .map_err(|e| Error::io(&sidecar_path, e))?;
    written.sidecar_path = Some(sidecar_path);
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    // ----- helpers ---------------------------------------------------------------------------

    fn field(e: &Error) -> &str {
        match e {
            Error::Format { field, .. } => field,
            other => panic!("expected a format error, got: {other}"),
        }
    }

    fn found(e: &Error) -> &str {
        match e {
            Error::Format { found, .. } => found,
            other => panic!("expected a format error, got: {other}"),
        }
    }

    fn pt3(channel: u8, dtime: u16, nsync: u16) -> u32 {
        (u32::from(channel & 0x0F) << 28) | (u32::from(dtime & 0x0FFF) << 16) | u32::from(nsync)
    }

    /// Header fields of a test file; `omit` leaves one tag out.
    #[derive(Clone)]
    struct H {
        rec_type: i64,
        bits: i64,
        n: i64,
        global: f64,
        res: f64,
        omit: &'static str,
    }

    impl H {
        fn new(rec_type: u32, n: usize) -> Self {
            Self {
                rec_type: i64::from(rec_type),
                bits: 32,
                n: n as i64,
                global: 50e-9,
                res: 4e-12,
                omit: "",
            }
        }
    }

    fn header(h: &H) -> Vec<u8> {
        let mut v = Vec::new();
        v.extend_from_slice(&MAGIC);
        v.extend_from_slice(b"1.0.00\0\0");
        let mut tw = TagWriter { w: &mut v };
        let mut int = |name: &str, x: i64| {
            if name != h.omit {
                tw.int(name, x).unwrap();
            }
        };
        int("TTResultFormat_TTTRRecType", h.rec_type);
        int("TTResultFormat_BitsPerRecord", h.bits);
        int("TTResult_NumberOfRecords", h.n);
        let mut tw = TagWriter { w: &mut v };
        for (name, x) in [
            ("MeasDesc_GlobalResolution", h.global),
            ("MeasDesc_Resolution", h.res),
        ] {
            if name != h.omit {
                tw.float(name, x).unwrap();
            }
        }
        tw.raw("Header_End", -1, tag_type::EMPTY8, [0; 8]).unwrap();
        v
    }

    fn file(h: &H, records: &[u32]) -> Vec<u8> {
        let mut v = header(h);
        for r in records {
            v.extend_from_slice(&r.to_le_bytes());
        }
        v
    }

    fn hh2(records: &[u32]) -> Vec<u8> {
        file(&H::new(0x0101_0304, records.len()), records)
    }

    fn read_header(bytes: &[u8]) -> Result<Header> {
        Header::read(&mut Cursor::new(bytes), Path::new("t.ptu"))
    }

    fn events(bytes: &[u8]) -> Result<Vec<Event>> {
        let mut c = Cursor::new(bytes);
        let h = Header::read(&mut c, Path::new("t.ptu"))?;
        Records::new(c, &h, "t.ptu").collect()
    }

    fn sidecar(rows: usize, ks: usize, nt: usize) -> Sidecar {
        Sidecar {
            rows: None,
            row_marker: 1,
            lasers: Aperture::grid([rows, 1], [1.0, 0.0], [0.0, 0.0]),
            spads: Some(Aperture::points(
                (0..ks).map(|s| [0.1 * s as f64, 0.0, 0.0]).collect(),
            )),
            confocal: false,
            channels: None,
            unmapped_channels: Unmapped::Error,
            nt,
            t0: 0.5,
            bin_width: None,
            rebin: 1,
            first_dtime: 0,
            laser_origin: DEFAULT_LASER_ORIGIN,
            sensor_origin: DEFAULT_SENSOR_ORIGIN,
            legs_in_time: false,
        }
    }

    fn source(bytes: Vec<u8>, sc: Sidecar) -> Result<PtuSource<Cursor<Vec<u8>>>> {
        PtuSource::from_reader(Cursor::new(bytes), "t.ptu", sc, Path::new("t.json"))
    }

    fn all_rows(src: &mut PtuSource<Cursor<Vec<u8>>>) -> Result<Vec<Vec<f32>>> {
        let mut rows = Vec::new();
        for l in 0..src.rows() {
            let mut row = Vec::new();
            src.read_row(l, &mut row)?;
            rows.push(row);
        }
        Ok(rows)
    }

    /// 3 lasers × 2 SPADs × 50 bins of small counts, some fractional (to test rounding).
    fn tiny(confocal: bool) -> Capture {
        let lasers: Vec<Point> = (0..3).map(|l| [0.1 * l as f32 - 0.1, 0.05, 0.0]).collect();
        let spads: Vec<Point> = if confocal {
            lasers.clone()
        } else {
            vec![[0.3, -0.2, 0.0], [0.35, -0.2, 0.0]]
        };
        let ks = if confocal { 1 } else { 2 };
        let nt = 50;
        let data = (0..3 * ks * nt)
            .map(|i| {
                let base = ((i * 7 + i / 13) % 5) as f32;
                match i % 11 {
                    0 => base + 0.4,
                    5 => base + 0.6,
                    _ => base,
                }
            })
            .collect();
        let geometry = Geometry {
            laser_shape: [3, 1],
            spad_shape: if confocal { [3, 1] } else { [2, 1] },
            lasers,
            spads,
            laser_origin: [-0.5, 0.0, 0.25],
            sensor_origin: [-0.4, 0.1, 0.25],
            legs_in_time: true,
            confocal,
            nt,
            dt: 0.0123,
            t0: 0.75,
        };
        Capture::new(geometry, data, Path::new("tiny")).unwrap()
    }

    fn rounded(c: &Capture) -> Vec<f32> {
        c.data.iter().map(|v| v.round()).collect()
    }

    fn written(c: &Capture, opts: &T3WriteOptions) -> (Vec<u8>, T3Written) {
        let mut bytes = Vec::new();
        let w = write_t3_to(c, &mut bytes, opts, Path::new("mem.ptu")).unwrap();
        (bytes, w)
    }

    // ----- header ----------------------------------------------------------------------------

    /// A header with every tag type, indexed tags and image tags; returns (bytes, header length).
    fn hand_built(records: &[u32]) -> (Vec<u8>, usize) {
        let mut v = Vec::new();
        v.extend_from_slice(b"PQTTTR\0\0");
        v.extend_from_slice(b"1.0.00\0\0");
        let mut tw = TagWriter { w: &mut v };
        tw.raw("Fancy_Empty", -1, tag_type::EMPTY8, [0; 8]).unwrap();
        tw.raw("Fancy_Bool", -1, tag_type::BOOL8, 1i64.to_le_bytes())
            .unwrap();
        tw.raw("Fancy_Int", -1, tag_type::INT8, (-5i64).to_le_bytes())
            .unwrap();
        tw.raw("Fancy_Bits", -1, tag_type::BITSET64, 0xF0u64.to_le_bytes())
            .unwrap();
        tw.raw("Fancy_Color", -1, tag_type::COLOR8, 0xFF00u64.to_le_bytes())
            .unwrap();
        tw.raw("Fancy_Float", -1, tag_type::FLOAT8, 2.5f64.to_le_bytes())
            .unwrap();
        tw.raw(
            "File_CreatingTime",
            -1,
            tag_type::DATETIME,
            45000.5f64.to_le_bytes(),
        )
        .unwrap();
        tw.raw(
            "Fancy_Array",
            -1,
            tag_type::FLOAT8_ARRAY,
            24i64.to_le_bytes(),
        )
        .unwrap();
        for x in [1.0f64, 2.0, 3.0] {
            tw.w.write_all(&x.to_le_bytes()).unwrap();
        }
        tw.string("File_Comment", "hello PTU").unwrap();
        let wide: Vec<u8> = "Wide ü\0\0"
            .encode_utf16()
            .flat_map(u16::to_le_bytes)
            .collect();
        tw.raw(
            "Fancy_Wide",
            -1,
            tag_type::WIDE_STRING,
            (wide.len() as i64).to_le_bytes(),
        )
        .unwrap();
        tw.w.write_all(&wide).unwrap();
        tw.raw("Fancy_Blob", -1, tag_type::BINARY_BLOB, 5i64.to_le_bytes())
            .unwrap();
        tw.w.write_all(&[9, 8, 7, 6, 5]).unwrap();
        tw.raw("HW_Markers", 0, tag_type::BOOL8, 1i64.to_le_bytes())
            .unwrap();
        tw.raw("HW_Markers", 1, tag_type::BOOL8, 0i64.to_le_bytes())
            .unwrap();
        tw.int("ImgHdr_LineStart", 1).unwrap();
        tw.int("ImgHdr_PixX", 64).unwrap();
        tw.int("TTResultFormat_TTTRRecType", 0x0101_0304).unwrap();
        tw.int("TTResultFormat_BitsPerRecord", 32).unwrap();
        tw.int("TTResult_NumberOfRecords", records.len() as i64)
            .unwrap();
        tw.float("MeasDesc_GlobalResolution", 25e-9).unwrap();
        tw.float("MeasDesc_Resolution", 1e-12).unwrap();
        tw.raw("Header_End", -1, tag_type::EMPTY8, [0; 8]).unwrap();
        let len = v.len();
        for r in records {
            v.extend_from_slice(&r.to_le_bytes());
        }
        (v, len)
    }

    #[test]
    fn ptu_header_hand_built() {
        let recs = [ht3(true, 1, 0, 3), ht3(false, 2, 77, 9)];
        let (bytes, len) = hand_built(&recs);
        let h = read_header(&bytes).unwrap();
        assert_eq!(h.version, "1.0.00");
        assert_eq!(h.data_offset, len as u64);
        assert_eq!(h.record_type, RecordType::HydraHarpV2T3);
        assert_eq!(h.record_type_code, 0x0101_0304);
        assert_eq!((h.num_records, h.bits_per_record), (2, 32));
        assert_eq!((h.global_resolution, h.resolution), (25e-9, 1e-12));
        assert_eq!(
            h.image,
            ImageTags {
                line_start: Some(1),
                pix_x: Some(64),
                ..ImageTags::default()
            }
        );
        assert_eq!(h.get("Fancy_Empty"), Some(&TagValue::Empty));
        assert_eq!(h.get("Fancy_Bool"), Some(&TagValue::Bool(true)));
        assert_eq!(h.get("Fancy_Int"), Some(&TagValue::Int(-5)));
        assert_eq!(h.get("Fancy_Bits"), Some(&TagValue::BitSet(0xF0)));
        assert_eq!(h.get("Fancy_Color"), Some(&TagValue::Color(0xFF00)));
        assert_eq!(h.get("Fancy_Float"), Some(&TagValue::Float(2.5)));
        assert_eq!(
            h.get("File_CreatingTime"),
            Some(&TagValue::DateTime(45000.5))
        );
        assert_eq!(
            h.get("Fancy_Array"),
            Some(&TagValue::Float8Array { len: 24 })
        );
        assert_eq!(
            h.get("File_Comment"),
            Some(&TagValue::AnsiString("hello PTU".into()))
        );
        assert_eq!(
            h.get("Fancy_Wide"),
            Some(&TagValue::WideString("Wide ü".into()))
        );
        assert_eq!(h.get("Fancy_Blob"), Some(&TagValue::Blob { len: 5 }));
        assert_eq!(h.get_indexed("HW_Markers", 1), Some(&TagValue::Bool(false)));
        assert_eq!(h.tags.last().unwrap().name, "Header_End");
        assert_eq!(h.get("Nope"), None);
        // The records follow the header.
        assert_eq!(
            events(&bytes).unwrap(),
            vec![
                Event::Marker { bits: 1, sync: 3 },
                Event::Photon {
                    channel: 2,
                    dtime: 77,
                    sync: 9
                }
            ]
        );
    }

    #[test]
    fn ptu_header_latin1_and_long_string() {
        let mut v = header(&H::new(0x0101_0304, 0));
        // Insert two tags before the required ones: rebuild by hand.
        v.truncate(16);
        let mut tw = TagWriter { w: &mut v };
        tw.raw("Latin", -1, tag_type::ANSI_STRING, 8i64.to_le_bytes())
            .unwrap();
        tw.w.write_all(b"caf\xe9\0\0\0\0").unwrap();
        let long = MAX_STRING + 8;
        tw.raw(
            "Long",
            -1,
            tag_type::ANSI_STRING,
            (long as i64).to_le_bytes(),
        )
        .unwrap();
        tw.w.write_all(&vec![b'x'; long as usize]).unwrap();
        let rest = header(&H::new(0x0101_0304, 0));
        v.extend_from_slice(&rest[16..]);
        let h = read_header(&v).unwrap();
        assert_eq!(h.get("Latin"), Some(&TagValue::AnsiString("café".into())));
        assert_eq!(
            h.get("Long"),
            Some(&TagValue::LongString {
                type_code: tag_type::ANSI_STRING,
                len: long
            })
        );
        assert_eq!(h.data_offset, v.len() as u64);
    }

    // ----- record decoding -------------------------------------------------------------------

    fn photon(channel: u8, dtime: u16, sync: u64) -> Decoded {
        Decoded::Event(Event::Photon {
            channel,
            dtime,
            sync,
        })
    }

    fn marker(bits: u8, sync: u64) -> Decoded {
        Decoded::Event(Event::Marker { bits, sync })
    }

    #[test]
    fn ptu_record_bits() {
        // Independent of `ht3`: special:1 channel:6 dtime:15 nsync:10 from the MSB.
        assert_eq!(ht3(false, 5, 1234, 1000), 0x0A13_4BE8);
        assert_eq!(ht3(true, 63, 0, 3), 0xFE00_0003);
        assert_eq!(ht3(true, 2, 0, 7), 0x8400_0007);
        assert_eq!(pt3(15, 0, 0), 0xF000_0000);
        assert_eq!(pt3(2, 0xABC, 0x1234), 0x2ABC_1234);
        // Byte order: records are little-endian in the file.
        let bytes = hh2(&[0x0A13_4BE8]);
        assert_eq!(&bytes[bytes.len() - 4..], &[0xE8, 0x4B, 0x13, 0x0A]);
        assert_eq!(
            events(&bytes).unwrap(),
            vec![Event::Photon {
                channel: 5,
                dtime: 1234,
                sync: 1000
            }]
        );
    }

    /// The same records under V1 and V2 overflow semantics.
    fn overflow_sequence() -> [u32; 7] {
        [
            ht3(false, 5, 1234, 1000),
            ht3(true, 63, 0, 3), // V1: +1024, V2: +3·1024
            ht3(false, 0, 32767, 5),
            ht3(true, 63, 0, 0), // +1024 in both
            ht3(true, 2, 0, 7),  // marker 2
            ht3(true, 0, 0, 9),  // reserved
            ht3(true, 40, 3, 9), // reserved
        ]
    }

    #[test]
    fn ptu_decode_hydraharp_v1_v2() {
        let seq = overflow_sequence();
        let mut v1 = Decoder::new(RecordType::HydraHarpV1T3);
        let got: Vec<Decoded> = seq.iter().map(|&r| v1.decode(r)).collect();
        assert_eq!(
            got,
            vec![
                photon(5, 1234, 1000),
                Decoded::Overflow { syncs: 1024 },
                photon(0, 32767, 1029),
                Decoded::Overflow { syncs: 1024 },
                marker(2, 2055),
                Decoded::Reserved,
                Decoded::Reserved,
            ]
        );
        assert_eq!(v1.overflow_syncs(), 2048);
        for code in [
            0x0101_0304,
            0x0001_0305,
            0x0001_0306,
            0x0101_0305,
            0x0101_0306,
            0x0001_0307,
        ] {
            let kind = RecordType::from_code(code).unwrap();
            let mut d = Decoder::new(kind);
            let got: Vec<Decoded> = seq.iter().map(|&r| d.decode(r)).collect();
            assert_eq!(
                got,
                vec![
                    photon(5, 1234, 1000),
                    Decoded::Overflow { syncs: 3072 },
                    photon(0, 32767, 3077),
                    Decoded::Overflow { syncs: 1024 },
                    marker(2, 4103),
                    Decoded::Reserved,
                    Decoded::Reserved,
                ],
                "{}",
                kind.name()
            );
        }
        // Marker bits 1..15 all decode; 1023 overflows at once.
        let mut d = Decoder::new(RecordType::MultiHarpT3);
        for b in 1..=15u8 {
            assert_eq!(d.decode(ht3(true, b, 0, 1)), marker(b, 1));
        }
        assert_eq!(
            d.decode(ht3(true, 63, 0, 1023)),
            Decoded::Overflow { syncs: 1023 * 1024 }
        );
        assert_eq!(
            d.decode(ht3(false, 63, 1, 1023)),
            photon(63, 1, 1024 * 1024 - 1)
        );
    }

    #[test]
    fn ptu_decode_picoharp() {
        let mut d = Decoder::new(RecordType::PicoHarpT3);
        assert_eq!(d.decode(pt3(1, 4000, 65535)), photon(0, 4000, 65535));
        assert_eq!(d.decode(pt3(15, 0, 17)), Decoded::Overflow { syncs: 65536 });
        assert_eq!(d.decode(pt3(4, 4095, 1)), photon(3, 4095, 65537));
        assert_eq!(d.decode(pt3(15, 4, 7)), marker(4, 65543));
        assert_eq!(d.decode(pt3(15, 0x013, 7)), marker(3, 65543));
        assert_eq!(d.decode(pt3(15, 0x010, 7)), Decoded::Reserved);
        assert_eq!(
            d.decode(pt3(0, 5, 5)),
            Decoded::IllegalChannel { channel: 0 }
        );
        assert_eq!(
            d.decode(pt3(5, 5, 5)),
            Decoded::IllegalChannel { channel: 5 }
        );
        assert_eq!(d.overflow_syncs(), 65536);
    }

    /// PicoQuant's `Read_PTU.py` logic, transcribed literally (binary-string slicing), as an
    /// independent cross-check: lines "CHN ch sync dtime" / "MAR bits sync".
    fn read_ptu_py(records: &[u32], pico: bool, version: u32) -> Vec<String> {
        let mut out = Vec::new();
        let mut ofl: u64 = 0;
        let bits = |s: &str| u64::from_str_radix(s, 2).unwrap();
        for &r in records {
            let rd = format!("{r:032b}");
            if pico {
                let (channel, dtime, nsync) =
                    (bits(&rd[0..4]), bits(&rd[4..16]), bits(&rd[16..32]));
                if channel == 0xF {
                    if dtime == 0 {
                        ofl += 65536;
                    } else {
                        out.push(format!("MAR {dtime} {}", ofl + nsync));
                    }
                } else {
                    out.push(format!("CHN {channel} {} {dtime}", ofl + nsync));
                }
            } else {
                let special = bits(&rd[0..1]);
                let channel = bits(&rd[1..7]);
                let dtime = bits(&rd[7..22]);
                let nsync = bits(&rd[22..32]);
                if special == 1 {
                    if channel == 0x3F {
                        if nsync == 0 || version == 1 {
                            ofl += 1024;
                        } else {
                            ofl += 1024 * nsync;
                        }
                    }
                    if (1..=15).contains(&channel) {
                        out.push(format!("MAR {channel} {}", ofl + nsync));
                    }
                } else {
                    out.push(format!("CHN {channel} {} {dtime}", ofl + nsync));
                }
            }
        }
        out
    }

    #[test]
    fn ptu_decode_matches_read_ptu_py() {
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut rand = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 32) as u32
        };
        for (code, pico, version) in [
            (0x0001_0304u32, false, 1),
            (0x0101_0304, false, 2),
            (0x0001_0305, false, 2),
            (0x0001_0307, false, 2),
            (0x0001_0303, true, 0),
        ] {
            let records: Vec<u32> = (0..5000)
                .map(|_| {
                    let r = rand();
                    if pico {
                        // Legal channels 1..4 and specials with markers in the low nibble.
                        match r % 6 {
                            0 => pt3(15, 0, r as u16),
                            1 => pt3(15, ((r >> 16) % 15 + 1) as u16, r as u16),
                            _ => pt3((r % 4 + 1) as u8, (r >> 8) as u16, (r >> 12) as u16),
                        }
                    } else {
                        match r % 7 {
                            0 => ht3(true, 63, 0, (r >> 10) as u16 % 4),
                            1 => ht3(true, (r >> 8) as u8, 0, (r >> 16) as u16),
                            _ => r & 0x7FFF_FFFF,
                        }
                    }
                })
                .collect();
            let bytes = file(&H::new(code, records.len()), &records);
            let ours: Vec<String> = events(&bytes)
                .unwrap()
                .into_iter()
                .map(|e| match e {
                    Event::Photon {
                        channel,
                        dtime,
                        sync,
                    } => format!(
                        "CHN {} {sync} {dtime}",
                        u32::from(channel) + u32::from(pico)
                    ),
                    Event::Marker { bits, sync } => format!("MAR {bits} {sync}"),
                })
                .collect();
            let theirs = read_ptu_py(&records, pico, version);
            assert_eq!(ours.len(), theirs.len(), "0x{code:08X}");
            assert_eq!(ours, theirs, "0x{code:08X}");
            assert!(ours.iter().any(|s| s.starts_with("MAR")));
        }
    }

    // ----- round trip ------------------------------------------------------------------------

    #[test]
    fn ptu_round_trip_in_memory() {
        let c = tiny(false);
        let (bytes, w) = written(&c, &T3WriteOptions::default());
        let photons: f32 = rounded(&c).iter().sum();
        assert_eq!(w.photons, photons as u64);
        assert_eq!(w.markers, 3);
        assert_eq!(w.records, w.photons + w.markers + w.overflow_records);
        assert!(w.overflow_records >= 2, "{w:?}");
        let h = read_header(&bytes).unwrap();
        assert_eq!(h.record_type, RecordType::HydraHarpV2T3);
        assert_eq!(h.num_records, w.records);
        assert_eq!(h.resolution, c.geometry.dt / SPEED_OF_LIGHT);
        assert_eq!(h.global_resolution, 50e-9);
        assert_eq!(bytes.len() as u64, h.data_offset + 4 * w.records);

        let mut src = source(bytes.clone(), w.sidecar.clone()).unwrap();
        let back = collect(&mut src, Path::new("mem.ptu")).unwrap();
        assert_eq!(back.geometry, c.geometry);
        assert_eq!(back.data, rounded(&c));
        let n = src.counts();
        assert_eq!(n.binned, w.photons);
        assert_eq!(n.overflow_records, w.overflow_records);
        assert_eq!(
            (
                n.before_first_marker,
                n.outside_window,
                n.unmapped,
                n.skipped_rows
            ),
            (0, 0, 0, 0)
        );

        // Multi-overflow records (V2) are there: 5000 syncs between rows.
        let mut c2 = Cursor::new(&bytes[..]);
        let h = Header::read(&mut c2, Path::new("mem.ptu")).unwrap();
        let mut recs = Records::new(c2, &h, "mem.ptu");
        let mut markers = Vec::new();
        while let Some(e) = recs.next_event().unwrap() {
            if let Event::Marker { bits, sync } = e {
                assert_eq!(bits, 1);
                markers.push(sync);
            }
        }
        let per_row: Vec<u64> = (0..3)
            .map(|l| c.row(l).iter().map(|v| v.round() as u64).sum())
            .collect();
        assert_eq!(
            markers,
            vec![0, per_row[0] + 5001, per_row[0] + per_row[1] + 10002]
        );
        assert_eq!(recs.decoder().overflow_syncs() % 1024, 0);
    }

    #[test]
    fn ptu_round_trip_options_and_confocal() {
        for (confocal, opts) in [
            (
                false,
                T3WriteOptions {
                    syncs_per_photon: 700,
                    syncs_between_rows: 0,
                    row_marker: 3,
                    ..T3WriteOptions::default()
                },
            ),
            (
                true,
                T3WriteOptions {
                    syncs_per_photon: 0,
                    syncs_between_rows: 3_000_000,
                    ..T3WriteOptions::default()
                },
            ),
        ] {
            let c = tiny(confocal);
            let (bytes, w) = written(&c, &opts);
            assert_eq!(w.sidecar.row_marker, opts.row_marker);
            assert!(w.overflow_records > 0);
            let mut src = source(bytes, w.sidecar).unwrap();
            let back = collect(&mut src, Path::new("mem.ptu")).unwrap();
            assert_eq!(back.geometry, c.geometry);
            assert_eq!(back.data, rounded(&c));
        }
    }

    #[test]
    fn ptu_round_trip_files() {
        let dir = std::env::temp_dir().join(format!("vltm-ptu-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let ptu = dir.join("tiny.ptu");
        let c = tiny(false);
        let w = write_t3(&c, &ptu, &T3WriteOptions::default()).unwrap();
        let sc_path = w.sidecar_path.clone().unwrap();
        assert_eq!(sc_path, dir.join("tiny.json"));
        assert_eq!(Sidecar::load(&sc_path).unwrap(), w.sidecar);

        let back = read_all(&ptu, &sc_path).unwrap();
        assert_eq!(back.data, rounded(&c));
        let (g, h) = (&back.geometry, &c.geometry);
        assert_eq!((&g.lasers, &g.spads, g.nt), (&h.lasers, &h.spads, h.nt));
        assert_eq!((g.laser_shape, g.spad_shape), (h.laser_shape, h.spad_shape));
        assert_eq!((g.confocal, g.legs_in_time), (h.confocal, h.legs_in_time));
        // JSON floats: equal up to the parser's last bit.
        assert!((g.dt - h.dt).abs() <= 1e-15 * h.dt && (g.t0 - h.t0).abs() <= 1e-15 * h.t0);
        for (a, b) in [
            (g.laser_origin, h.laser_origin),
            (g.sensor_origin, h.sensor_origin),
        ] {
            assert!(a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-15));
        }

        // The event stream of the file.
        let (hd, recs) = open(&ptu).unwrap();
        assert_eq!(hd.num_records, w.records);
        let ev: Vec<Event> = recs.collect::<Result<_>>().unwrap();
        assert_eq!(ev.len() as u64, w.photons + w.markers);

        // Rows in any order: forward skips, backward rewinds.
        let mut src = PtuSource::open(&ptu, &sc_path).unwrap();
        let mut row = Vec::new();
        for l in [2, 0, 1, 1, 0, 2, 2, 1, 2] {
            src.read_row(l, &mut row).unwrap();
            assert_eq!(row, back.row(l), "row {l}");
        }
        let mut src = PtuSource::open(&ptu, &sc_path).unwrap();
        src.read_row(2, &mut row).unwrap();
        let per_row = |l: usize| c.row(l).iter().map(|v| v.round() as u64).sum::<u64>();
        assert_eq!(src.counts().skipped_rows, per_row(0) + per_row(1));
        assert_eq!(src.counts().binned, per_row(2));
        src.read_row(0, &mut row).unwrap(); // rewinds: counts restart
        assert_eq!(src.counts().binned, per_row(0));
        assert_eq!(src.counts().skipped_rows, 0);

        // The sidecar must not overwrite the PTU file.
        let e = write_t3(&c, dir.join("x.json"), &T3WriteOptions::default()).unwrap_err();
        assert!(matches!(e, Error::Argument { .. }), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn ptu_rebin_window_and_channel_map() {
        let c = tiny(false);
        let (bytes, w) = written(&c, &T3WriteOptions::default());
        let r = rounded(&c);
        let (first, rebin, nt) = (10usize, 3usize, 12usize);
        let sc = Sidecar {
            first_dtime: first as u32,
            rebin: rebin as u32,
            nt,
            bin_width: None,
            channels: Some(vec![1, 0]), // SPAD 0 on channel 1, SPAD 1 on channel 0
            ..w.sidecar.clone()
        };
        let mut src = source(bytes, sc).unwrap();
        let width = src.header().resolution * SPEED_OF_LIGHT;
        let g = src.geometry().clone();
        assert_eq!(g.nt, nt);
        assert_eq!(g.dt, 3.0 * width);
        assert_eq!(g.t0, c.geometry.t0 + 11.0 * width);
        let rows = all_rows(&mut src).unwrap();
        let mut kept = 0.0;
        for (l, row) in rows.iter().enumerate() {
            for s in 0..2 {
                let ch = 1 - s;
                for n in 0..nt {
                    let want: f32 = (0..rebin)
                        .map(|j| r[(l * 2 + ch) * 50 + first + n * rebin + j])
                        .sum();
                    assert_eq!(row[s * nt + n], want, "l {l} s {s} n {n}");
                    kept += want;
                }
            }
        }
        let n = src.counts();
        assert_eq!(n.binned, kept as u64);
        assert_eq!(n.binned + n.outside_window, w.photons);
        assert!(n.outside_window > 0);
    }

    #[test]
    fn ptu_rows_markers_and_drops() {
        // photon, photon, M1, photon, M2 (other marker), M1|M2, photon ch 3, photon
        let recs = [
            ht3(false, 0, 1, 1),
            ht3(false, 1, 2, 2),
            ht3(true, 1, 0, 3),
            ht3(false, 1, 3, 4),
            ht3(true, 2, 0, 5),
            ht3(true, 3, 0, 6),
            ht3(false, 3, 4, 7),
            ht3(false, 0, 9, 8),
            ht3(true, 0, 0, 8), // reserved
        ];
        let mut sc = sidecar(2, 2, 8);
        sc.unmapped_channels = Unmapped::Drop;
        let mut src = source(hh2(&recs), sc.clone()).unwrap();
        let rows = all_rows(&mut src).unwrap();
        let mut want0 = vec![0.0; 16];
        want0[8 + 3] = 1.0;
        assert_eq!(rows, vec![want0, vec![0.0; 16]]);
        let n = src.counts();
        assert_eq!(n.before_first_marker, 2);
        assert_eq!(n.other_markers, 1);
        assert_eq!(n.unmapped, 1);
        assert_eq!(n.outside_window, 1); // dtime 9 ≥ nt = 8
        assert_eq!(n.reserved_records, 1);
        assert_eq!(n.binned, 1);

        // The same with unmapped channels an error.
        sc.unmapped_channels = Unmapped::Error;
        let mut src = source(hh2(&recs), sc).unwrap();
        let e = all_rows(&mut src).unwrap_err();
        assert_eq!(field(&e), "channels");
        assert!(found(&e).contains("channel 3 at record 6"), "{e}");

        // Out-of-range rows are an argument error, not a panic.
        let mut src = source(hh2(&recs), sidecar(2, 2, 8)).unwrap();
        assert!(matches!(
            src.read_row(2, &mut Vec::new()),
            Err(Error::Argument { .. })
        ));
    }

    #[test]
    fn ptu_picoharp_rows() {
        let recs = [
            pt3(15, 1, 0),  // marker 1: row 0
            pt3(1, 3, 10),  // channel 0, bin 3
            pt3(15, 0, 0),  // overflow
            pt3(2, 1, 10),  // channel 1, bin 1
            pt3(15, 2, 11), // marker 2: ignored
            pt3(15, 1, 12), // row 1
            pt3(2, 2, 13),  // channel 1, bin 2
        ];
        let bytes = file(&H::new(0x0001_0303, recs.len()), &recs);
        let mut src = source(bytes, sidecar(2, 2, 4)).unwrap();
        assert_eq!(src.header().record_type, RecordType::PicoHarpT3);
        let rows = all_rows(&mut src).unwrap();
        assert_eq!(
            rows,
            vec![
                vec![0., 0., 0., 1., 0., 1., 0., 0.],
                vec![0., 0., 0., 0., 0., 0., 1., 0.]
            ]
        );
        assert_eq!(src.counts().overflow_records, 1);
        assert_eq!(src.counts().other_markers, 1);
        // Default bin width: MeasDesc_Resolution·c.
        assert_eq!(src.geometry().dt, 4e-12 * SPEED_OF_LIGHT);
        // An illegal PicoHarp channel is an error.
        let bytes = file(&H::new(0x0001_0303, 2), &[pt3(15, 1, 0), pt3(7, 1, 1)]);
        let e = all_rows(&mut source(bytes, sidecar(1, 2, 4)).unwrap()).unwrap_err();
        assert_eq!(field(&e), "records");
        assert!(found(&e).contains("channel 7"), "{e}");
    }

    // ----- malformed input -------------------------------------------------------------------

    #[test]
    fn ptu_bad_magic() {
        let mut bytes = hh2(&[]);
        bytes[5] = b'X';
        assert_eq!(field(&read_header(&bytes).unwrap_err()), "magic");
        let e = read_header(b"\x89PNG\r\n\x1a\n0000000000000000").unwrap_err();
        assert_eq!(field(&e), "magic");
    }

    #[test]
    fn ptu_truncated_header_every_length() {
        let (bytes, len) = hand_built(&[ht3(true, 1, 0, 0)]);
        for cut in 0..len {
            let e = read_header(&bytes[..cut]).unwrap_err();
            assert_eq!(field(&e), "header", "cut at {cut}: {e}");
            assert!(
                found(&e).contains(&format!("byte {cut}")),
                "cut at {cut}: {e}"
            );
        }
        assert!(read_header(&bytes[..len]).is_ok());
        // The written files too.
        let (bytes, _) = written(&tiny(false), &T3WriteOptions::default());
        let len = read_header(&bytes).unwrap().data_offset as usize;
        for cut in 0..len {
            assert_eq!(field(&read_header(&bytes[..cut]).unwrap_err()), "header");
        }
    }

    #[test]
    fn ptu_unknown_tag_type_and_bad_lengths() {
        let mut v = Vec::new();
        v.extend_from_slice(&MAGIC);
        v.extend_from_slice(b"1.0.00\0\0");
        let mut tw = TagWriter { w: &mut v };
        tw.raw("Weird_Tag", -1, 0x1234_5678, [0; 8]).unwrap();
        let e = read_header(&v).unwrap_err();
        assert_eq!(field(&e), "Weird_Tag");
        assert!(found(&e).contains("0x12345678"), "{e}");

        for ty in [
            tag_type::ANSI_STRING,
            tag_type::WIDE_STRING,
            tag_type::FLOAT8_ARRAY,
            tag_type::BINARY_BLOB,
        ] {
            let mut v = v[..16].to_vec();
            let mut tw = TagWriter { w: &mut v };
            tw.raw("Neg_Len", -1, ty, (-8i64).to_le_bytes()).unwrap();
            assert_eq!(field(&read_header(&v).unwrap_err()), "Neg_Len");
            // A length past the end of the file is a truncated header.
            let mut v = v[..16].to_vec();
            let mut tw = TagWriter { w: &mut v };
            tw.raw("Huge_Len", -1, ty, i64::MAX.to_le_bytes()).unwrap();
            assert_eq!(field(&read_header(&v).unwrap_err()), "header");
        }
    }

    #[test]
    fn ptu_bad_required_tags() {
        let ok = H::new(0x0101_0304, 0);
        assert!(read_header(&header(&ok)).is_ok());
        let check = |h: H, want_field: &str, want_found: &str| {
            let e = read_header(&header(&h)).unwrap_err();
            assert_eq!(field(&e), want_field, "{e}");
            assert!(found(&e).contains(want_found), "{e}");
        };
        // Unknown and T2 record types.
        for (code, what) in [
            (0x0001_0204i64, "HydraHarp V1 T2"),
            (0x0101_0204, "T2 mode"),
            (0x0001_0203, "PicoHarp T2"),
            (0x0000_DEAD, "0x0000DEAD"),
            (-1, "0xFFFFFFFFFFFFFFFF"),
        ] {
            check(
                H {
                    rec_type: code,
                    ..ok.clone()
                },
                "TTResultFormat_TTTRRecType",
                what,
            );
        }
        for bits in [16, 64, 0] {
            check(
                H { bits, ..ok.clone() },
                "TTResultFormat_BitsPerRecord",
                &bits.to_string(),
            );
        }
        check(
            H {
                n: -3,
                ..ok.clone()
            },
            "TTResult_NumberOfRecords",
            "-3",
        );
        for tag in [
            "TTResultFormat_TTTRRecType",
            "TTResultFormat_BitsPerRecord",
            "TTResult_NumberOfRecords",
            "MeasDesc_GlobalResolution",
            "MeasDesc_Resolution",
        ] {
            check(
                H {
                    omit: tag,
                    ..ok.clone()
                },
                tag,
                "no such tag",
            );
        }
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, -1e-12, 0.0] {
            check(
                H {
                    res: bad,
                    ..ok.clone()
                },
                "MeasDesc_Resolution",
                "",
            );
            check(
                H {
                    global: bad,
                    ..ok.clone()
                },
                "MeasDesc_GlobalResolution",
                "",
            );
        }
        // A mistyped tag.
        let mut v = header(&H {
            omit: "MeasDesc_Resolution",
            ..ok.clone()
        });
        let end = v.len() - 48;
        v.truncate(end);
        let mut tw = TagWriter { w: &mut v };
        tw.int("MeasDesc_Resolution", 4).unwrap();
        tw.raw("Header_End", -1, tag_type::EMPTY8, [0; 8]).unwrap();
        let e = read_header(&v).unwrap_err();
        assert_eq!(field(&e), "MeasDesc_Resolution");
        assert!(found(&e).contains("Int8"), "{e}");
    }

    #[test]
    fn ptu_truncated_and_overlong_records() {
        let c = tiny(false);
        let (bytes, w) = written(&c, &T3WriteOptions::default());
        for cut in 1..=4 {
            let short = bytes[..bytes.len() - cut].to_vec();
            let e = events(&short).unwrap_err();
            assert_eq!(field(&e), "records", "cut {cut}");
            let partial = format!("partial record of {} bytes", 4 - cut);
            assert_eq!(found(&e).contains(&partial), cut < 4, "{e}");
            let e = collect(
                &mut source(short, w.sidecar.clone()).unwrap(),
                Path::new("t"),
            )
            .unwrap_err();
            assert_eq!(field(&e), "records");
        }
        let mut long = bytes.clone();
        long.extend_from_slice(&[0, 0]);
        let e = events(&long).unwrap_err();
        assert_eq!(field(&e), "records");
        assert!(found(&e).contains("more data"), "{e}");
        // After an error the stream ends.
        let mut c2 = Cursor::new(&bytes[..bytes.len() - 2]);
        let h = Header::read(&mut c2, Path::new("t")).unwrap();
        let mut recs = Records::new(c2, &h, "t");
        assert!(recs.by_ref().any(|e| e.is_err()));
        assert!(recs.next().is_none());
    }

    #[test]
    fn ptu_marker_count_mismatch() {
        let c = tiny(false);
        let (bytes, w) = written(&c, &T3WriteOptions::default());
        let with_lasers = |k: usize| Sidecar {
            rows: Some(k),
            lasers: Aperture::points((0..k).map(|l| [0.1 * l as f64, 0.0, 0.0]).collect()),
            ..w.sidecar.clone()
        };
        // Fewer markers (3) than rows (4).
        let mut src = source(bytes.clone(), with_lasers(4)).unwrap();
        let e = collect(&mut src, Path::new("t")).unwrap_err();
        assert_eq!(field(&e), "markers");
        assert!(found(&e).contains('3'), "{e}");
        // Asking directly for the missing row.
        let mut src = source(bytes.clone(), with_lasers(5)).unwrap();
        let e = src.read_row(4, &mut Vec::new()).unwrap_err();
        assert_eq!(field(&e), "markers");
        // More markers (3) than rows (2).
        let mut src = source(bytes.clone(), with_lasers(2)).unwrap();
        let e = collect(&mut src, Path::new("t")).unwrap_err();
        assert_eq!(field(&e), "markers");
        assert!(found(&e).contains("extra row marker"), "{e}");
        // A different marker input: no row markers at all.
        let sc = Sidecar {
            row_marker: 2,
            ..w.sidecar.clone()
        };
        let e = collect(&mut source(bytes.clone(), sc).unwrap(), Path::new("t")).unwrap_err();
        assert_eq!(field(&e), "markers");
        assert!(found(&e).contains('0'), "{e}");
        // A file with no records at all.
        let e = collect(&mut source(hh2(&[]), w.sidecar).unwrap(), Path::new("t")).unwrap_err();
        assert_eq!(field(&e), "markers");
    }

    #[test]
    fn ptu_bad_sidecars() {
        let bytes = hh2(&[ht3(true, 1, 0, 0)]);
        let check = |sc: Sidecar, want: &str| {
            let e = source(bytes.clone(), sc).unwrap_err();
            assert_eq!(field(&e), want, "{e}");
        };
        let ok = sidecar(1, 2, 8);
        assert!(source(bytes.clone(), ok.clone()).is_ok());
        for m in [0, 5, 16] {
            check(
                Sidecar {
                    row_marker: m,
                    ..ok.clone()
                },
                "row_marker",
            );
        }
        check(
            Sidecar {
                rows: Some(2),
                ..ok.clone()
            },
            "rows",
        );
        check(
            Sidecar {
                channels: Some(vec![0]),
                ..ok.clone()
            },
            "channels",
        );
        check(
            Sidecar {
                channels: Some(vec![1, 1]),
                ..ok.clone()
            },
            "channels",
        );
        check(
            Sidecar {
                channels: Some(vec![0, 64]),
                ..ok.clone()
            },
            "channels",
        );
        for w in [f64::NAN, -0.01, 0.0, f64::INFINITY] {
            check(
                Sidecar {
                    bin_width: Some(w),
                    ..ok.clone()
                },
                "bin_width",
            );
        }
        check(
            Sidecar {
                t0: f64::NAN,
                ..ok.clone()
            },
            "t0",
        );
        check(
            Sidecar {
                nt: 0,
                ..ok.clone()
            },
            "nt",
        );
        check(
            Sidecar {
                rebin: 0,
                ..ok.clone()
            },
            "rebin",
        );
        check(
            Sidecar {
                spads: None,
                ..ok.clone()
            },
            "spads",
        );
        check(
            Sidecar {
                lasers: Aperture::grid([0, 1], [1.0, 1.0], [0.0, 0.0]),
                ..ok.clone()
            },
            "lasers",
        );
        check(
            Sidecar {
                spads: Some(Aperture::points(vec![[f64::NAN, 0.0, 0.0]])),
                channels: Some(vec![0]),
                ..ok.clone()
            },
            "spads",
        );
        check(
            Sidecar {
                confocal: true,
                ..ok.clone()
            },
            "spads",
        );
        check(
            Sidecar {
                laser_origin: [0.0, f64::NAN, 0.0],
                ..ok.clone()
            },
            "laser_origin",
        );
        // Confocal without spads is fine: one histogram per row.
        let sc = Sidecar {
            confocal: true,
            spads: None,
            ..ok.clone()
        };
        let src = source(bytes.clone(), sc).unwrap();
        assert!(src.geometry().confocal);
        assert_eq!(src.geometry().spads_per_row(), 1);

        // JSON-level errors.
        let json = ok.to_json();
        assert_eq!(Sidecar::from_json_str(&json, "s.json").unwrap(), ok);
        let bad = json.replacen('{', "{\"colour\": 1,", 1);
        let e = Sidecar::from_json_str(&bad, "s.json").unwrap_err();
        assert_eq!(field(&e), "sidecar");
        assert!(found(&e).contains("colour"), "{e}");
        let e = Sidecar::from_json_str(r#"{"lasers": {"grid": [1, 1]}, "nt": 5}"#, "s.json")
            .unwrap_err();
        assert_eq!(field(&e), "sidecar");
        assert!(found(&e).contains("t0"), "{e}");
        let e = Sidecar::from_json_str("{", "s.json").unwrap_err();
        assert_eq!(field(&e), "sidecar");
        let minimal = r#"{"lasers": {"grid": [1, 1]}, "confocal": true, "nt": 5, "t0": 0.5}"#;
        let s = Sidecar::from_json_str(minimal, "s.json").unwrap();
        assert_eq!((s.row_marker, s.rebin, s.first_dtime), (1, 1, 0));
        assert_eq!(s.unmapped_channels, Unmapped::Error);
        let e = Sidecar::load("/nonexistent/vltm/s.json").unwrap_err();
        assert!(matches!(e, Error::Io { .. }), "{e}");
    }

    #[test]
    fn ptu_writer_rejects_bad_captures() {
        let mut c = tiny(false);
        for bad in [f32::NAN, f32::INFINITY, -1.0, 5e9] {
            c.data[7] = bad;
            let e = write_t3_to(&c, Vec::new(), &T3WriteOptions::default(), Path::new("w"))
                .unwrap_err();
            assert_eq!(field(&e), "H", "{bad}");
        }
        c.data[7] = -0.4; // rounds to (−)0 photons: accepted
        assert!(write_t3_to(&c, Vec::new(), &T3WriteOptions::default(), Path::new("w")).is_ok());
        for opts in [
            T3WriteOptions {
                row_marker: 0,
                ..T3WriteOptions::default()
            },
            T3WriteOptions {
                row_marker: 5,
                ..T3WriteOptions::default()
            },
            T3WriteOptions {
                sync_period: f64::NAN,
                ..T3WriteOptions::default()
            },
            T3WriteOptions {
                sync_period: 0.0,
                ..T3WriteOptions::default()
            },
        ] {
            let e = write_t3_to(&c, Vec::new(), &opts, Path::new("w")).unwrap_err();
            assert!(matches!(e, Error::Argument { .. }), "{e}");
        }
        let mut big = tiny(false);
        big.geometry.spads = vec![[0.0; 3]; 65];
        big.geometry.spad_shape = [65, 1];
        big.data = vec![0.0; 3 * 65 * 50];
        let e =
            write_t3_to(&big, Vec::new(), &T3WriteOptions::default(), Path::new("w")).unwrap_err();
        assert!(matches!(e, Error::Argument { .. }), "{e}");
        let mut short = tiny(false);
        short.data.pop();
        let e = write_t3_to(
            &short,
            Vec::new(),
            &T3WriteOptions::default(),
            Path::new("w"),
        )
        .unwrap_err();
        assert_eq!(field(&e), "H");
    }
}
