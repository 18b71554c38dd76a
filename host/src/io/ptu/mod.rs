//! PicoQuant PTU photon streams (T3 mode) → laser rows, without Python.
//!
//! A time-correlated single-photon counter (HydraHarp, TimeHarp 260, MultiHarp, PicoHarp) in
//! **T3 mode** writes one 32-bit record per detected photon: the detector channel, the sync
//! period it fell in (`nsync`, a counter that wraps around and is extended by *overflow*
//! records) and its arrival time after the sync (`dtime`, in bins of `MeasDesc_Resolution`).
//! *Marker* records carry the scanner's TTL signals. This module
//!
//! 1. parses the PTU header ([`Header::read`]) and streams decoded [`Event`]s from any
//!    [`BufRead`](std::io::BufRead) ([`Records`], [`open`]), one record at a time, never loading the file;
//! 2. bins the stream into laser rows for the kernel ([`PtuSource`], a [`RowSource`](crate::io::RowSource);
//!    [`read_all`] for a whole [`Capture`](crate::io::Capture)), guided by a small JSON **sidecar** ([`Sidecar`])
//!    that describes the scan;
//! 3. follows a stream that is still being written (a growing file, a pipe) and hands out
//!    each row once the next row marker closes it ([`Follower`], module `follow`);
//! 4. writes synthetic HydraHarp V2 T3 files and their sidecars from a [`Capture`](crate::io::Capture)
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
//! # let s = vltm::io::ptu::Sidecar::from_json_str(json, "doc.json").unwrap();
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
//!   false): as in the capture's [`Geometry`](crate::io::Geometry).
//!
//! # Errors
//!
//! Malformed input is an [`Error::Format`](crate::Error::Format) naming the file and a field, never a panic:
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
//! I/O failures are [`Error::Io`](crate::Error::Io).
//!
//! # Example
//!
//! ```no_run
//! use vltm::io::RowSource;
//! # fn main() -> vltm::Result<()> {
//! let mut src = vltm::io::ptu::PtuSource::open("scan.ptu", "scan.json")?;
//! let mut row = Vec::new();
//! for l in 0..src.geometry().lasers.len() {
//!     let laser = src.read_row(l, &mut row)?; // Ks·Nt photon counts, SPAD-major
//!     # let _ = laser;
//! }
//! println!("{:?}", src.counts());
//! # Ok(()) }
//! ```

mod binning;
mod decode;
mod follow;
mod header;
mod sidecar;
mod source;
mod template;
mod write;

pub use binning::Counts;
pub use decode::{Decoded, Decoder, Event, Records, open};
pub use follow::{Ended, FollowOptions, FollowedRow, Follower};
pub use header::{
    Header, ImageTags, MAGIC, MAX_MARKER, MAX_TAGS, RecordType, SPEED_OF_LIGHT, Tag, TagValue,
    tag_type,
};
pub use sidecar::{Sidecar, Unmapped};
pub use source::{PtuSource, read_all};
pub use template::template;
pub use write::{T3WriteOptions, T3Written, stage_t3, write_t3, write_t3_to};

#[cfg(test)]
mod tests;
