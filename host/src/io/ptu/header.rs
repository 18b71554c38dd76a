//! The PTU file header: magic, version, tags up to `Header_End`, the record type and the
//! time resolutions (see the [module doc](super) for the layout).

use std::io::{self, Read};
use std::path::Path;

use crate::error::{Error, Result};

/// The speed of light (m/s): converts `MeasDesc_Resolution` (s) to metres of path.
pub const SPEED_OF_LIGHT: f64 = 299_792_458.0;

/// The 8-byte magic at the start of every PTU file.
pub const MAGIC: [u8; 8] = *b"PQTTTR\0\0";

/// The highest marker input (`row_marker`): T3 records carry 4 marker bits.
pub const MAX_MARKER: u32 = 4;

/// Tags before `Header_End` beyond which a header is considered corrupt.
pub const MAX_TAGS: usize = 100_000;

/// Strings longer than this (bytes) are skipped by length instead of kept.
pub(super) const MAX_STRING: u64 = 1 << 20;

/// Detector channels a T3 record can name (6 bits).
pub(super) const CHANNELS: usize = 64;

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
pub(super) fn unsupported_record_type(code: u32) -> Option<&'static str> {
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
pub(super) struct HeaderReader<'a, R> {
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

pub(super) fn until_nul(b: &[u8]) -> &[u8] {
    b.iter().position(|&c| c == 0).map_or(b, |i| &b[..i])
}

pub(super) fn ansi(b: &[u8]) -> String {
    let b = until_nul(b);
    match std::str::from_utf8(b) {
        Ok(s) => s.to_owned(),
        Err(_) => b.iter().map(|&c| char::from(c)).collect(),
    }
}

pub(super) fn wide(b: &[u8]) -> String {
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
