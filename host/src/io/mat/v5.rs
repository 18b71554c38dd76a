//! The MAT-file level 5 parser (MATLAB `save -v5`/`-v6`/`-v7`): the 128-byte header, top-level
//! data elements, `miCOMPRESSED` (zlib) elements and `miMATRIX` arrays.
//!
//! Format (MathWorks, *MAT-File Format*, R2024a, ch. 1): a 116-byte text header, 8 bytes of
//! subsystem offset, a 2-byte version (0x0100) and the 2-byte endian indicator `IM` (`MI` =
//! big-endian, both read). Then data elements: an 8-byte tag (u32 type, u32 byte count; the
//! *small* form packs a count ≤ 4 into the upper 16 bits of the type and the data into the
//! next 4 bytes), the data, padding to 8 bytes (none after a compressed element). A
//! `miCOMPRESSED` (15) element is a zlib stream holding one uncompressed element. A `miMATRIX`
//! (14) holds: array flags (class in the low byte, complex 0x0800, logical 0x0200), dimensions
//! (`miINT32`), the name (`miINT8`), then by class: real (and imaginary) parts for numeric
//! classes, any numeric storage type (`miUINT16` data of a `double` array, as MATLAB writes
//! integer-valued doubles), UTF-16/UTF-8 text for `char`, field-name length and names then one
//! `miMATRIX` per field and element for `struct`, one `miMATRIX` per element for `cell`.
//!
//! Numeric values keep MATLAB's column-major order: element `(i, j, k)` of dims `(a, b, c)` is
//! at `i + a·(j + b·k)`. Arrays of more than [`F32_ABOVE`] elements are decoded to f32 (the
//! histograms), smaller ones to f64 (grids, scalars). Complex arrays keep the real part only,
//! sparse and object arrays are recorded by class with no data. [`Mat5::read`] reads a
//! variable whole; [`Mat5::stream_f32`] hands a numeric one over in chunks inflated and
//! decoded by a background thread (the Stanford captures' `rect_data`, transposed as it
//! arrives).
//!
//! Every size comes from the file and is checked before it is used: a sub-element larger than
//! its enclosing element is an error, and every allocation is checked against
//! [`budget::check`] first (a zlib stream may claim 4 GiB in 40 bytes). A stream that ends
//! early or does not inflate is an error naming the variable.

use crate::budget;
use crate::error::{Error, Result};
use flate2::read::ZlibDecoder;
use std::io::{BufReader, Read, Seek, SeekFrom};
use std::path::Path;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};

/// Arrays with more elements than this are decoded to f32, smaller ones to f64.
pub const F32_ABOVE: usize = 1 << 16;

/// Chunks waiting in the queue of [`Mat5::stream_f32`] (besides the one in use and the one
/// being decoded).
pub const STREAM_QUEUE: usize = 2;

const MI_INT8: u32 = 1;
const MI_UINT8: u32 = 2;
const MI_INT16: u32 = 3;
const MI_UINT16: u32 = 4;
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_SINGLE: u32 = 7;
const MI_DOUBLE: u32 = 9;
const MI_INT64: u32 = 12;
const MI_UINT64: u32 = 13;
const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;
const MI_UTF8: u32 = 16;
const MI_UTF16: u32 = 17;

/// A MATLAB array class (`mxCLASS`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Class {
    /// `cell`.
    Cell,
    /// `struct`.
    Struct,
    /// An object (not decoded).
    Object,
    /// `char`.
    Char,
    /// A sparse array (not decoded).
    Sparse,
    /// A numeric or logical class, by its MATLAB name (`double`, `uint16`, `logical`, …).
    Numeric(&'static str),
}

impl Class {
    /// The MATLAB name of the class.
    pub fn name(self) -> &'static str {
        match self {
            Self::Cell => "cell",
            Self::Struct => "struct",
            Self::Object => "object",
            Self::Char => "char",
            Self::Sparse => "sparse",
            Self::Numeric(n) => n,
        }
    }

    fn from_code(c: u8, logical: bool) -> Option<Self> {
        Some(match c {
            1 => Self::Cell,
            2 => Self::Struct,
            3 | 16 | 17 => Self::Object,
            4 => Self::Char,
            5 => Self::Sparse,
            _ if logical => Self::Numeric("logical"),
            6 => Self::Numeric("double"),
            7 => Self::Numeric("single"),
            8 => Self::Numeric("int8"),
            9 => Self::Numeric("uint8"),
            10 => Self::Numeric("int16"),
            11 => Self::Numeric("uint16"),
            12 => Self::Numeric("int32"),
            13 => Self::Numeric("uint32"),
            14 => Self::Numeric("int64"),
            15 => Self::Numeric("uint64"),
            _ => return None,
        })
    }
}

/// Decoded values of an array, column-major.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// Numeric values of at most [`F32_ABOVE`] elements (real part).
    F64(Vec<f64>),
    /// Numeric values of more than [`F32_ABOVE`] elements (real part).
    F32(Vec<f32>),
    /// Text of a `char` array (column-major characters).
    Text(String),
    /// Fields of a 1×1 struct, in file order (a struct array keeps its first element).
    Struct(Vec<Var>),
    /// The elements of a cell array.
    Cell(Vec<Var>),
    /// Not decoded: only the header was read, or a sparse/object array.
    Skipped,
}

/// A MATLAB variable (or a struct field, or a cell element).
#[derive(Clone, Debug, PartialEq)]
pub struct Var {
    /// The name (empty for cell elements).
    pub name: String,
    /// The class.
    pub class: Class,
    /// Dimensions, MATLAB order (at least 2).
    pub dims: Vec<usize>,
    /// The values.
    pub value: Value,
}

impl Var {
    /// Number of elements (product of the dimensions, saturating).
    pub fn len(&self) -> usize {
        self.dims
            .iter()
            .try_fold(1usize, |a, &d| a.checked_mul(d))
            .unwrap_or(usize::MAX)
    }

    /// Whether the array has no element.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// A field of a struct by name.
    pub fn field(&self, name: &str) -> Option<&Self> {
        match &self.value {
            Value::Struct(f) => f.iter().find(|v| v.name == name),
            _ => None,
        }
    }

    /// `name[dims]` with the class, e.g. `rect_data 64x64x2048 double`.
    pub fn describe(&self) -> String {
        let dims: Vec<String> = self.dims.iter().map(ToString::to_string).collect();
        format!("{} {} {}", self.name, dims.join("x"), self.class.name())
    }
}

/// Where a top-level variable lives in a v5 file.
#[derive(Clone, Debug)]
pub struct Entry {
    /// The variable's header (value [`Value::Skipped`]).
    pub header: Var,
    offset: u64,
    size: u64,
    compressed: bool,
}

/// An open MAT v5 file: its top-level variables (headers only) and the means to read one.
#[derive(Debug)]
pub struct Mat5 {
    path: std::path::PathBuf,
    big_endian: bool,
    /// The top-level variables in file order.
    pub entries: Vec<Entry>,
}

/// Whether `head` (the first 128 bytes or more) is a MAT v5 header.
pub fn is_v5(head: &[u8]) -> bool {
    head.len() >= 128 && matches!(&head[126..128], b"IM" | b"MI") && head[124..126] != [0, 0]
}

impl Mat5 {
    /// Reads the header and the header of each top-level variable (for a compressed element,
    /// only its first bytes are inflated).
    ///
    /// # Errors
    /// [`Error::Io`]; [`Error::Format`] for a bad header or element tag.
    pub fn open(path: &Path) -> Result<Self> {
        let mut f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        let len = f.metadata().map_err(|e| Error::io(path, e))?.len();
        let mut head = [0u8; 128];
        f.read_exact(&mut head)
            .map_err(|_| Error::format(path, "(header)", "a 128-byte MAT v5 header", "less"))?;
        if !is_v5(&head) {
            return Err(Error::format(
                path,
                "(header)",
                "a MAT v5 header (endian indicator IM)",
                "something else",
            ));
        }
        let big_endian = &head[126..128] == b"MI";
        let mut me = Self {
            path: path.to_path_buf(),
            big_endian,
            entries: Vec::new(),
        };
        let mut off = 128u64;
        let mut r = BufReader::new(f);
        while off + 8 <= len {
            r.seek(SeekFrom::Start(off))
                .map_err(|e| Error::io(path, e))?;
            let mut tag = [0u8; 8];
            r.read_exact(&mut tag).map_err(|e| Error::io(path, e))?;
            let (ty, size) = (me.u32(&tag[0..4]), u64::from(me.u32(&tag[4..8])));
            let what = format!("(variable at byte {off})");
            let avail = size.min(len - off - 8);
            let header = match ty {
                MI_COMPRESSED => {
                    let mut z = ZlibDecoder::new((&mut r).take(avail));
                    let mut p = Parser::new(&mut z, big_endian, path, u64::MAX);
                    p.var.clone_from(&what);
                    p.top_level(false)
                }
                MI_MATRIX => {
                    let mut p = Parser::new(&mut r, big_endian, path, avail);
                    p.var.clone_from(&what);
                    p.matrix_body(size, String::new(), false)
                }
                _ => {
                    return Err(Error::format(
                        path,
                        &what,
                        "a matrix or compressed element (type 14 or 15)",
                        format!("type {ty}"),
                    ));
                }
            };
            if avail < size {
                // Name the variable if its header is there.
                let name = header.as_ref().map_or(what, |h| h.name.clone());
                return Err(Error::format(
                    path,
                    &name,
                    format!("{size} bytes of data"),
                    format!("{avail} bytes left in the file (truncated)"),
                ));
            }
            let header = header?;
            me.entries.push(Entry {
                header,
                offset: off + 8,
                size,
                compressed: ty == MI_COMPRESSED,
            });
            off += 8 + if ty == MI_COMPRESSED {
                size
            } else {
                size.div_ceil(8) * 8
            };
        }
        Ok(me)
    }

    /// Reads one top-level variable whole.
    ///
    /// # Errors
    /// [`Error::Format`] naming the variable for a corrupt or truncated element; an
    /// [`Error::Memory`] if it does not fit the budget.
    pub fn read(&self, name: &str) -> Result<Var> {
        let e = self
            .entries
            .iter()
            .find(|e| e.header.name == name)
            .ok_or_else(|| Error::format(&self.path, name, "a variable of this name", "none"))?;
        let mut f = std::fs::File::open(&self.path).map_err(|err| Error::io(&self.path, err))?;
        f.seek(SeekFrom::Start(e.offset))
            .map_err(|err| Error::io(&self.path, err))?;
        let r = BufReader::with_capacity(1 << 16, f).take(e.size);
        if e.compressed {
            let mut z = ZlibDecoder::new(r);
            Parser::new(&mut z, self.big_endian, &self.path, u64::MAX).top_level(true)
        } else {
            let mut r = r;
            Parser::new(&mut r, self.big_endian, &self.path, e.size).matrix_body(
                e.size,
                String::new(),
                true,
            )
        }
    }

    /// The header of top-level variable `name` (its value [`Value::Skipped`]), if there is
    /// one.
    pub fn header(&self, name: &str) -> Option<&Var> {
        self.entries
            .iter()
            .find(|e| e.header.name == name)
            .map(|e| &e.header)
    }

    /// Streams the real part of numeric top-level variable `name` as f32 values in file
    /// (column-major) order, `chunk` values at a time (the last chunk shorter): a background
    /// thread inflates and decodes the element while the caller uses the chunks already sent,
    /// through a queue of [`STREAM_QUEUE`] chunks. Values are converted as [`Mat5::read`]
    /// converts them (through f64), so they are bit-identical to its. Memory: the queued
    /// chunks, the one being decoded and its raw bytes, and the inflater's window.
    ///
    /// # Errors
    /// [`Error::Format`] if there is no such variable; errors of the stream (a corrupt or
    /// truncated element, non-numeric data, a value count that does not match the dims)
    /// arrive through the receiver, naming the variable, after which it closes.
    pub fn stream_f32(&self, name: &str, chunk: usize) -> Result<Receiver<Result<Vec<f32>>>> {
        let e = self
            .entries
            .iter()
            .find(|e| e.header.name == name)
            .ok_or_else(|| Error::format(&self.path, name, "a variable of this name", "none"))?;
        let (path, be, name) = (self.path.clone(), self.big_endian, name.to_string());
        let (offset, size, compressed, count) = (e.offset, e.size, e.compressed, e.header.len());
        let chunk = chunk.max(1);
        let (tx, rx) = sync_channel(STREAM_QUEUE);
        std::thread::spawn(move || {
            let run = |tx: &SyncSender<Result<Vec<f32>>>| -> Result<()> {
                let mut f = std::fs::File::open(&path).map_err(|err| Error::io(&path, err))?;
                f.seek(SeekFrom::Start(offset))
                    .map_err(|err| Error::io(&path, err))?;
                let mut r = BufReader::with_capacity(1 << 16, f).take(size);
                let mut z;
                let mut p = if compressed {
                    z = ZlibDecoder::new(r);
                    let mut p = Parser::new(&mut z, be, &path, u64::MAX);
                    p.top_level(false)?;
                    p
                } else {
                    let mut p = Parser::new(&mut r, be, &path, size);
                    p.matrix_body(size, String::new(), false)?;
                    p
                };
                p.var.clone_from(&name);
                let (ty, n, small) = p.tag()?;
                let width: usize = match ty {
                    MI_INT8 | MI_UINT8 | MI_UTF8 => 1,
                    MI_INT16 | MI_UINT16 => 2,
                    MI_INT32 | MI_UINT32 | MI_SINGLE => 4,
                    MI_DOUBLE | MI_INT64 | MI_UINT64 => 8,
                    _ => return Err(p.err("numeric data", format!("data type {ty}"))),
                };
                if n != (count as u64).saturating_mul(width as u64) {
                    return Err(p.err(
                        format!("{count} values"),
                        format!("{n} bytes of {width}-byte values"),
                    ));
                }
                if let Some(s) = small {
                    let v = numbers(ty, be, &s[..n as usize], |x| x as f32);
                    let _ = tx.send(Ok(v));
                    return Ok(());
                }
                let mut raw = Vec::new();
                let mut left = count;
                while left > 0 {
                    let k = left.min(chunk);
                    raw.resize(k * width, 0);
                    p.bytes(&mut raw)?;
                    if tx.send(Ok(numbers(ty, be, &raw, |x| x as f32))).is_err() {
                        return Ok(());
                    }
                    left -= k;
                }
                Ok(())
            };
            if let Err(err) = run(&tx) {
                let _ = tx.send(Err(err));
            }
        });
        Ok(rx)
    }

    fn u32(&self, b: &[u8]) -> u32 {
        let w = [b[0], b[1], b[2], b[3]];
        if self.big_endian {
            u32::from_be_bytes(w)
        } else {
            u32::from_le_bytes(w)
        }
    }
}

/// A reader of elements from a byte stream, tracking the variable being read for errors.
struct Parser<'a> {
    r: &'a mut dyn Read,
    be: bool,
    path: &'a Path,
    /// The variable (path of names) being read.
    var: String,
    /// Bytes consumed so far.
    pos: u64,
    /// Bytes available (the element's size; `u64::MAX` for an inflated stream).
    limit: u64,
}

impl<'a> Parser<'a> {
    fn new(r: &'a mut dyn Read, be: bool, path: &'a Path, limit: u64) -> Self {
        Self {
            r,
            be,
            path,
            var: String::new(),
            pos: 0,
            limit,
        }
    }

    fn err(&self, expected: impl ToString, found: impl ToString) -> Error {
        let var = if self.var.is_empty() {
            "(variable)"
        } else {
            &self.var
        };
        Error::format(self.path, var, expected, found)
    }

    fn bytes(&mut self, buf: &mut [u8]) -> Result<()> {
        if self.pos.saturating_add(buf.len() as u64) > self.limit {
            return Err(self.err("data within its element", "an element overrunning it"));
        }
        self.r.read_exact(buf).map_err(|e| {
            let found = if e.kind() == std::io::ErrorKind::UnexpectedEof {
                "the end of the data (truncated)".to_string()
            } else {
                format!("a corrupt stream ({e})")
            };
            self.err("the rest of the variable's data", found)
        })?;
        self.pos += buf.len() as u64;
        Ok(())
    }

    fn skip(&mut self, n: u64) -> Result<()> {
        let mut buf = [0u8; 4096];
        let mut left = n;
        while left > 0 {
            let k = left.min(buf.len() as u64) as usize;
            self.bytes(&mut buf[..k])?;
            left -= k as u64;
        }
        Ok(())
    }

    fn u32(&self, b: [u8; 4]) -> u32 {
        if self.be {
            u32::from_be_bytes(b)
        } else {
            u32::from_le_bytes(b)
        }
    }

    /// Reads a tag: `(type, byte count, small)`; small elements carry their ≤ 4 data bytes
    /// in the tag's second word (returned in `small`).
    fn tag(&mut self) -> Result<(u32, u64, Option<[u8; 4]>)> {
        let mut t = [0u8; 8];
        self.bytes(&mut t)?;
        let w0 = self.u32([t[0], t[1], t[2], t[3]]);
        let hi = w0 >> 16;
        if hi != 0 {
            if hi > 4 {
                return Err(self.err("a small data element of at most 4 bytes", hi));
            }
            return Ok((w0 & 0xFFFF, u64::from(hi), Some([t[4], t[5], t[6], t[7]])));
        }
        Ok((w0, u64::from(self.u32([t[4], t[5], t[6], t[7]])), None))
    }

    /// Reads a sub-element's raw bytes (and its padding).
    fn element(&mut self) -> Result<(u32, Vec<u8>)> {
        let (ty, n, small) = self.tag()?;
        if let Some(s) = small {
            return Ok((ty, s[..n as usize].to_vec()));
        }
        if self.pos.saturating_add(n) > self.limit {
            return Err(self.err("a sub-element within its element", format!("{n} bytes")));
        }
        let path = self.path.display().to_string();
        let var = self.var.clone();
        budget::check(|| format!("{path}: variable `{var}` ({n} bytes)"), n.into())?;
        let mut v = vec![0u8; usize::try_from(n).unwrap_or(usize::MAX)];
        self.bytes(&mut v)?;
        self.skip(n.div_ceil(8) * 8 - n)?;
        Ok((ty, v))
    }

    /// An inflated top-level element: a matrix.
    fn top_level(&mut self, full: bool) -> Result<Var> {
        let (ty, n, small) = self.tag()?;
        if ty != MI_MATRIX || small.is_some() {
            return Err(self.err("a matrix element (type 14) inside the compressed one", ty));
        }
        self.limit = n.saturating_add(8);
        self.matrix_body(n, String::new(), full)
    }

    /// The body of a `miMATRIX` element of `n` bytes (after its tag). `name` is the field
    /// name for struct fields (their own name is empty).
    fn matrix_body(&mut self, n: u64, name: String, full: bool) -> Result<Var> {
        let end = self.pos + n;
        if n == 0 {
            return Ok(Var {
                name,
                class: Class::Numeric("double"),
                dims: vec![0, 0],
                value: Value::F64(Vec::new()),
            });
        }
        let (_, flags) = self.element()?;
        if flags.len() < 4 {
            return Err(self.err("array flags", format!("{} bytes", flags.len())));
        }
        let w = self.u32([flags[0], flags[1], flags[2], flags[3]]);
        let (code, bits) = ((w & 0xFF) as u8, ((w >> 8) & 0xFF) as u8);
        let class = Class::from_code(code, bits & 0x02 != 0)
            .ok_or_else(|| self.err("a MATLAB array class", format!("class code {code}")))?;
        let (dty, dbytes) = self.element()?;
        if dty != MI_INT32 || dbytes.len() < 8 || dbytes.len() % 4 != 0 {
            return Err(self.err("int32 dimensions", format!("type {dty}")));
        }
        let dims: Vec<usize> = dbytes
            .chunks_exact(4)
            .map(|c| {
                let d = self.u32([c[0], c[1], c[2], c[3]]) as i32;
                usize::try_from(d).unwrap_or(usize::MAX)
            })
            .collect();
        if dims.contains(&usize::MAX) {
            return Err(self.err("non-negative dimensions", format!("{dims:?}")));
        }
        let (_, nbytes) = self.element()?;
        let own = String::from_utf8_lossy(&nbytes).into_owned();
        let name = if name.is_empty() { own } else { name };
        let outer = std::mem::take(&mut self.var);
        self.var = if outer.is_empty() || outer.starts_with('(') {
            name.clone()
        } else {
            format!("{outer}.{name}")
        };
        let mut var = Var {
            name,
            class,
            dims,
            value: Value::Skipped,
        };
        if full {
            var.value = self.values(&var, end)?;
        }
        // Whatever is left of the element (imaginary parts, the header-only case).
        if full && self.pos < end {
            self.skip(end - self.pos)?;
        }
        self.var = outer;
        Ok(var)
    }

    fn values(&mut self, var: &Var, end: u64) -> Result<Value> {
        let count = var.len();
        match var.class {
            Class::Numeric(_) => {
                let path = self.path.display().to_string();
                budget::check(
                    || format!("{path}: values of `{}` (dims {:?})", self.var, var.dims),
                    budget::bytes(count, 4),
                )?;
                let (ty, raw) = self.element()?;
                let size = match ty {
                    MI_INT8 | MI_UINT8 | MI_UTF8 => 1,
                    MI_INT16 | MI_UINT16 => 2,
                    MI_INT32 | MI_UINT32 | MI_SINGLE => 4,
                    MI_DOUBLE | MI_INT64 | MI_UINT64 => 8,
                    _ => return Err(self.err("numeric data", format!("data type {ty}"))),
                };
                if raw.len() != count.saturating_mul(size) {
                    return Err(self.err(
                        format!("{count} values for dims {:?}", var.dims),
                        format!("{} bytes of {size}-byte values", raw.len()),
                    ));
                }
                let bytes = if count > F32_ABOVE { 4 } else { 8 };
                budget::check(
                    || format!("{path}: values of `{}`", self.var),
                    budget::bytes(count, bytes),
                )?;
                Ok(if count > F32_ABOVE {
                    Value::F32(numbers(ty, self.be, &raw, |x| x as f32))
                } else {
                    Value::F64(numbers(ty, self.be, &raw, |x| x))
                })
            }
            Class::Char => {
                let (ty, raw) = self.element()?;
                let text = match ty {
                    MI_UTF16 | MI_UINT16 => {
                        let u: Vec<u16> = raw
                            .chunks_exact(2)
                            .map(|c| {
                                if self.be {
                                    u16::from_be_bytes([c[0], c[1]])
                                } else {
                                    u16::from_le_bytes([c[0], c[1]])
                                }
                            })
                            .collect();
                        String::from_utf16_lossy(&u)
                    }
                    _ => String::from_utf8_lossy(&raw).into_owned(),
                };
                Ok(Value::Text(text))
            }
            Class::Struct => {
                let (_, len) = self.element()?;
                let flen = if len.len() >= 4 {
                    self.u32([len[0], len[1], len[2], len[3]]) as usize
                } else {
                    0
                };
                let (_, names) = self.element()?;
                if flen == 0 || names.len() % flen != 0 {
                    return Err(self.err("struct field names", format!("{} bytes", names.len())));
                }
                let names: Vec<String> = names
                    .chunks_exact(flen)
                    .map(|c| {
                        let z = c.iter().position(|&b| b == 0).unwrap_or(c.len());
                        String::from_utf8_lossy(&c[..z]).into_owned()
                    })
                    .collect();
                let mut fields = Vec::new();
                // The first element's fields (a struct array keeps only them).
                for (k, fname) in names.iter().enumerate() {
                    if count == 0 || self.pos >= end {
                        break;
                    }
                    let _ = k;
                    let (ty, n, small) = self.tag()?;
                    if ty != MI_MATRIX || small.is_some() {
                        return Err(self.err(format!("field `{fname}` as a matrix"), ty));
                    }
                    fields.push(self.matrix_body(n, fname.clone(), true)?);
                }
                Ok(Value::Struct(fields))
            }
            Class::Cell => {
                let mut cells = Vec::new();
                for _ in 0..count {
                    if self.pos >= end {
                        break;
                    }
                    let (ty, n, small) = self.tag()?;
                    if ty != MI_MATRIX || small.is_some() {
                        return Err(self.err("cell elements as matrices", ty));
                    }
                    cells.push(self.matrix_body(n, String::new(), true)?);
                }
                Ok(Value::Cell(cells))
            }
            Class::Sparse | Class::Object => Ok(Value::Skipped),
        }
    }
}

/// The values of a numeric element of type `ty` (`be`: big-endian), each through `to`; one
/// loop per type (the 16 M values of a Stanford capture convert in milliseconds).
fn numbers<T>(ty: u32, be: bool, raw: &[u8], to: impl Fn(f64) -> T) -> Vec<T> {
    fn each<const N: usize, T>(
        raw: &[u8],
        be: bool,
        get: impl Fn([u8; N]) -> f64,
        to: impl Fn(f64) -> T,
    ) -> Vec<T> {
        raw.chunks_exact(N)
            .map(|c| {
                let mut w = [0u8; N];
                w.copy_from_slice(c);
                if be {
                    w.reverse();
                }
                to(get(w))
            })
            .collect()
    }
    match ty {
        MI_INT8 => each(raw, be, |w: [u8; 1]| f64::from(w[0] as i8), to),
        MI_UINT8 | MI_UTF8 => each(raw, be, |w: [u8; 1]| f64::from(w[0]), to),
        MI_INT16 => each(raw, be, |w| f64::from(i16::from_le_bytes(w)), to),
        MI_UINT16 => each(raw, be, |w| f64::from(u16::from_le_bytes(w)), to),
        MI_INT32 => each(raw, be, |w| f64::from(i32::from_le_bytes(w)), to),
        MI_UINT32 => each(raw, be, |w| f64::from(u32::from_le_bytes(w)), to),
        MI_SINGLE => each(raw, be, |w| f64::from(f32::from_le_bytes(w)), to),
        MI_DOUBLE => each(raw, be, f64::from_le_bytes, to),
        MI_INT64 => each(raw, be, |w| i64::from_le_bytes(w) as f64, to),
        _ => each(raw, be, |w| u64::from_le_bytes(w) as f64, to),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every numeric type decodes to its value in both byte orders.
    #[test]
    fn numbers_decode_every_type_in_both_byte_orders() {
        let cases: [(u32, Vec<u8>, f64); 10] = [
            (MI_INT8, vec![0xfe], -2.0),
            (MI_UINT8, vec![0xfe], 254.0),
            (MI_INT16, (-300i16).to_le_bytes().to_vec(), -300.0),
            (MI_UINT16, 60_000u16.to_le_bytes().to_vec(), 60_000.0),
            (MI_INT32, (-70_000i32).to_le_bytes().to_vec(), -70_000.0),
            (MI_UINT32, 4_000_000_000u32.to_le_bytes().to_vec(), 4e9),
            (MI_SINGLE, 1.5f32.to_le_bytes().to_vec(), 1.5),
            (MI_DOUBLE, (-2.25f64).to_le_bytes().to_vec(), -2.25),
            (MI_INT64, (-5i64).to_le_bytes().to_vec(), -5.0),
            (MI_UINT64, 7u64.to_le_bytes().to_vec(), 7.0),
        ];
        for (ty, le, want) in cases {
            // Two values each, so that the per-value stride is exercised.
            let two: Vec<u8> = le.iter().chain(&le).copied().collect();
            assert_eq!(
                numbers(ty, false, &two, |x| x),
                [want, want],
                "type {ty} LE"
            );
            let be: Vec<u8> = le.iter().rev().copied().collect();
            let two: Vec<u8> = be.iter().chain(&be).copied().collect();
            assert_eq!(numbers(ty, true, &two, |x| x), [want, want], "type {ty} BE");
        }
        assert_eq!(numbers(MI_UINT16, false, &[1, 0, 2], |x| x as f32), [1.0]);
    }
}
