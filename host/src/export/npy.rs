//! NumPy `.npy` files of `f32` volumes (format versions 1.0–3.0).
//!
//! [`write_f32`] writes a float32, little-endian, C-order array that `numpy.load` reads with
//! the given shape; [`read_f32`] reads float32 (`<f4`) or float64 (`<f8`, converted) C-order
//! arrays. Anything else (Fortran order, other dtypes, malformed headers, truncated or
//! over-long data) is an [`Error::Format`] naming the header field, never a panic.

use std::io::Write;
use std::path::Path;

use crate::atomic::Transaction;
use crate::error::{Error, Result};

/// The `.npy` magic string.
const MAGIC: &[u8; 6] = b"\x93NUMPY";
/// numpy aligns the start of the data to this many bytes.
const ALIGN: usize = 64;

/// Writes `data` as a float32 little-endian C-order `.npy` array of shape `shape`.
///
/// `shape` may have any rank (`[]` is a scalar holding one value).
///
/// # Errors
///
/// `data.len()` is not the product of `shape` ([`Error::Argument`] `shape`); the file cannot
/// be written ([`Error::Io`]).
pub fn write_f32(path: impl AsRef<Path>, data: &[f32], shape: &[usize]) -> Result<()> {
    let mut t = Transaction::new();
    stage_f32(&mut t, path.as_ref(), data, shape)?;
    t.commit()
}

/// [`write_f32`] as one file of a [`Transaction`] (written on its commit, all or nothing with
/// the transaction's other files).
///
/// # Errors
///
/// As [`write_f32`].
pub fn stage_f32(t: &mut Transaction, path: &Path, data: &[f32], shape: &[usize]) -> Result<()> {
    let count = element_count(shape);
    if count != Some(data.len()) {
        return Err(Error::arg(
            "shape",
            format!(
                "{} holds {} values but the data has {}",
                shape_text(shape),
                count_text(count),
                data.len()
            ),
        ));
    }
    let mut bytes = header_bytes(shape);
    bytes.reserve(4 * data.len());
    for v in data {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    t.stage(path, |f| {
        f.write_all(&bytes).map_err(|e| Error::io(path, e))
    })
}

/// Reads a float32 (`<f4`) or float64 (`<f8`, converted to f32) C-order `.npy` array.
///
/// Returns the values in C order and the shape.
///
/// # Errors
///
/// The file cannot be read ([`Error::Io`]). [`Error::Format`] naming the field: bad magic or
/// header (`magic`, `version`, `header`), a dtype other than `<f4`/`<f8` (`descr`), Fortran
/// order (`fortran_order`), a malformed shape (`shape`), or a data section of the wrong length
/// (`data`, "expected N bytes, found M").
pub fn read_f32(path: impl AsRef<Path>) -> Result<(Vec<f32>, Vec<usize>)> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let (header, data) = split_header(path, &bytes)?;
    let header = Header::parse(path, header)?;
    let count = element_count(&header.shape).ok_or_else(|| {
        Error::format(
            path,
            "shape",
            "a shape whose size fits in memory",
            shape_text(&header.shape),
        )
    })?;
    let expected = count.checked_mul(header.dtype.size()).ok_or_else(|| {
        Error::format(
            path,
            "shape",
            "a shape whose size fits in memory",
            shape_text(&header.shape),
        )
    })?;
    if data.len() != expected {
        return Err(Error::format(
            path,
            "data",
            format!("{expected} bytes for shape {}", shape_text(&header.shape)),
            format!("{} bytes", data.len()),
        ));
    }
    let values = match header.dtype {
        Dtype::F4 => data
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect(),
        Dtype::F8 => data
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]) as f32)
            .collect(),
    };
    Ok((values, header.shape))
}

/// The product of `shape`, or `None` on overflow.
fn element_count(shape: &[usize]) -> Option<usize> {
    shape.iter().try_fold(1usize, |acc, &n| acc.checked_mul(n))
}

fn count_text(count: Option<usize>) -> String {
    count.map_or_else(|| "more than usize::MAX".to_string(), |n| n.to_string())
}

/// A shape as a Python tuple: `()`, `(3,)`, `(2, 3)`.
fn shape_text(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// Magic, version, header length and the padded header dict, ready for the data.
fn header_bytes(shape: &[usize]) -> Vec<u8> {
    let dict = format!(
        "{{'descr': '<f4', 'fortran_order': False, 'shape': {}, }}",
        shape_text(shape)
    );
    // Version 1.0 has a u16 header length; longer headers (huge ranks) need version 2.0.
    let (version, prefix) = if pad_to(10 + dict.len() + 1) - 10 <= usize::from(u16::MAX) {
        (1, 10)
    } else {
        (2, 12)
    };
    let total = pad_to(prefix + dict.len() + 1);
    let header_len = total - prefix;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[version, 0]);
    if version == 1 {
        out.extend_from_slice(&(header_len as u16).to_le_bytes());
    } else {
        out.extend_from_slice(&(header_len as u32).to_le_bytes());
    }
    out.extend_from_slice(dict.as_bytes());
    out.resize(total - 1, b' ');
    out.push(b'\n');
    out
}

fn pad_to(n: usize) -> usize {
    n.div_ceil(ALIGN) * ALIGN
}

/// Splits a file into its header text and its data bytes.
fn split_header<'b>(path: &Path, bytes: &'b [u8]) -> Result<(&'b str, &'b [u8])> {
    if bytes.len() < 8 || &bytes[..6] != MAGIC {
        let found = String::from_utf8_lossy(&bytes[..bytes.len().min(6)]).into_owned();
        return Err(Error::format(
            path,
            "magic",
            "\\x93NUMPY (a .npy file)",
            format!("{found:?}"),
        ));
    }
    let (major, minor) = (bytes[6], bytes[7]);
    let len_size = match major {
        1 => 2,
        2 | 3 => 4,
        _ => {
            return Err(Error::format(
                path,
                "version",
                "1.0, 2.0 or 3.0",
                format!("{major}.{minor}"),
            ));
        }
    };
    let start = 8 + len_size;
    let Some(len_bytes) = bytes.get(8..start) else {
        return Err(Error::format(
            path,
            "header",
            format!("at least {start} bytes"),
            format!("{} bytes", bytes.len()),
        ));
    };
    let header_len = len_bytes
        .iter()
        .rev()
        .fold(0usize, |acc, &b| (acc << 8) | usize::from(b));
    let end = start.saturating_add(header_len);
    let Some(header) = bytes.get(start..end) else {
        return Err(Error::format(
            path,
            "header",
            format!("{end} bytes"),
            format!("{} bytes", bytes.len()),
        ));
    };
    let header = std::str::from_utf8(header).map_err(|e| {
        Error::format(
            path,
            "header",
            "a text dict",
            format!("invalid UTF-8 ({e})"),
        )
    })?;
    Ok((header, &bytes[end..]))
}

/// The supported element types.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Dtype {
    F4,
    F8,
}

impl Dtype {
    fn size(self) -> usize {
        match self {
            Self::F4 => 4,
            Self::F8 => 8,
        }
    }
}

/// The parsed header dict.
#[derive(Debug)]
struct Header {
    dtype: Dtype,
    shape: Vec<usize>,
}

/// A value of the header dict.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Value {
    Str(String),
    Bool(bool),
    Tuple(Vec<String>),
    /// Anything else (lists of structured dtypes, numbers), as written.
    Other(String),
}

impl Value {
    fn text(&self) -> String {
        match self {
            Self::Str(s) => format!("'{s}'"),
            Self::Bool(b) => if *b { "True" } else { "False" }.to_string(),
            Self::Tuple(items) => format!("({})", items.join(", ")),
            Self::Other(s) => s.clone(),
        }
    }
}

impl Header {
    fn parse(path: &Path, text: &str) -> Result<Self> {
        let entries = DictParser {
            s: text.as_bytes(),
            i: 0,
        }
        .dict()
        .ok_or_else(|| {
            Error::format(
                path,
                "header",
                "a Python dict literal",
                format!("{:?}", text.trim_end()),
            )
        })?;
        let get = |key: &str, expected: &str| {
            entries
                .iter()
                .find(|(k, _)| k == key)
                .map(|(_, v)| v)
                .ok_or_else(|| Error::format(path, key, expected, "no such key"))
        };
        const DESCR: &str = "'<f4' or '<f8'";
        let dtype = match get("descr", DESCR)? {
            Value::Str(s) if s == "<f4" => Dtype::F4,
            Value::Str(s) if s == "<f8" => Dtype::F8,
            v => return Err(Error::format(path, "descr", DESCR, v.text())),
        };
        match get("fortran_order", "False")? {
            Value::Bool(false) => {}
            v => {
                return Err(Error::format(
                    path,
                    "fortran_order",
                    "False (C order)",
                    v.text(),
                ));
            }
        }
        const SHAPE: &str = "a tuple of non-negative integers";
        let shape_value = get("shape", SHAPE)?;
        let shape = match shape_value {
            Value::Tuple(items) => items
                .iter()
                .map(|s| parse_dim(s))
                .collect::<Option<Vec<_>>>(),
            _ => None,
        };
        let shape = shape.ok_or_else(|| Error::format(path, "shape", SHAPE, shape_value.text()))?;
        Ok(Self { dtype, shape })
    }
}

/// One dimension: a decimal integer, optionally with Python 2's `L` suffix.
fn parse_dim(s: &str) -> Option<usize> {
    let s = s.strip_suffix(['L', 'l']).unwrap_or(s);
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

/// A minimal parser of the Python dict literal of a `.npy` header.
struct DictParser<'s> {
    s: &'s [u8],
    i: usize,
}

impl DictParser<'_> {
    fn peek(&self) -> Option<u8> {
        self.s.get(self.i).copied()
    }

    fn skip_ws(&mut self) {
        while self.peek().is_some_and(|b| b.is_ascii_whitespace()) {
            self.i += 1;
        }
    }

    /// Skips whitespace and consumes `b` if it is next.
    fn eat(&mut self, b: u8) -> bool {
        self.skip_ws();
        let found = self.peek() == Some(b);
        if found {
            self.i += 1;
        }
        found
    }

    /// `{ 'key': value, ... }` followed by nothing but whitespace.
    fn dict(mut self) -> Option<Vec<(String, Value)>> {
        let mut entries = Vec::new();
        if !self.eat(b'{') {
            return None;
        }
        while !self.eat(b'}') {
            self.skip_ws();
            let key = self.string()?;
            if !self.eat(b':') {
                return None;
            }
            let value = self.value()?;
            entries.push((key, value));
            if !self.eat(b',') {
                if !self.eat(b'}') {
                    return None;
                }
                break;
            }
        }
        self.skip_ws();
        (self.i == self.s.len()).then_some(entries)
    }

    /// A quoted string (no escapes: numpy never writes any in the keys we read).
    fn string(&mut self) -> Option<String> {
        let quote = self.peek().filter(|q| matches!(q, b'\'' | b'"'))?;
        let start = self.i + 1;
        let len = self.s.get(start..)?.iter().position(|&b| b == quote)?;
        self.i = start + len + 1;
        Some(String::from_utf8_lossy(&self.s[start..start + len]).into_owned())
    }

    fn value(&mut self) -> Option<Value> {
        self.skip_ws();
        match self.peek()? {
            b'\'' | b'"' => self.string().map(Value::Str),
            b'(' => self.tuple(),
            _ => {
                let raw = self.raw();
                match raw.as_str() {
                    "True" => Some(Value::Bool(true)),
                    "False" => Some(Value::Bool(false)),
                    "" => None,
                    _ => Some(Value::Other(raw)),
                }
            }
        }
    }

    /// `(a, b, ...)` of bare items (kept as text).
    fn tuple(&mut self) -> Option<Value> {
        self.i += 1; // '('
        let mut items = Vec::new();
        loop {
            if self.eat(b')') {
                return Some(Value::Tuple(items));
            }
            let item = self.raw();
            if item.is_empty() {
                return None;
            }
            items.push(item);
            if !self.eat(b',') {
                return self.eat(b')').then_some(Value::Tuple(items));
            }
        }
    }

    /// Text up to the next `,`, `)` or `}` outside brackets, trimmed.
    fn raw(&mut self) -> String {
        self.skip_ws();
        let start = self.i;
        let mut depth = 0usize;
        while let Some(b) = self.peek() {
            match b {
                b'(' | b'[' | b'{' => depth += 1,
                b')' | b']' | b'}' if depth > 0 => depth -= 1,
                b',' | b')' | b'}' if depth == 0 => break,
                _ => {}
            }
            self.i += 1;
        }
        String::from_utf8_lossy(&self.s[start..self.i])
            .trim()
            .to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> crate::scratch::Scratch {
        crate::scratch::Scratch::file("npy-test", name)
    }

    /// A raw `.npy` file with the given header dict and data bytes (version 1.0).
    fn raw_npy(dict: &str, data: &[u8]) -> Vec<u8> {
        let mut out = MAGIC.to_vec();
        out.extend_from_slice(&[1, 0]);
        let len = pad_to(10 + dict.len() + 1) - 10;
        out.extend_from_slice(&(len as u16).to_le_bytes());
        out.extend_from_slice(dict.as_bytes());
        out.resize(10 + len - 1, b' ');
        out.push(b'\n');
        out.extend_from_slice(data);
        out
    }

    fn format_field(e: &Error) -> &str {
        match e {
            Error::Format { field, .. } => field,
            other => panic!("expected a format error, got {other}"),
        }
    }

    #[test]
    fn round_trip_3d() {
        let path = tmp("rt3.npy");
        let data: Vec<f32> = (0..24).map(|i| i as f32 * 0.5 - 3.0).collect();
        write_f32(&path, &data, &[2, 3, 4]).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
        let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        assert_eq!((10 + header_len) % 64, 0, "data aligned to 64 bytes");
        assert_eq!(bytes[9 + header_len], b'\n');
        let header = std::str::from_utf8(&bytes[10..10 + header_len]).unwrap();
        assert!(
            header.starts_with("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3, 4), }"),
            "{header}"
        );
        assert_eq!(bytes.len(), 10 + header_len + 4 * 24);
        let (back, shape) = read_f32(&path).unwrap();
        assert_eq!(shape, vec![2, 3, 4]);
        assert_eq!(back, data);
    }

    #[test]
    fn round_trip_ranks_0_1_and_empty() {
        for (shape, n) in [
            (vec![], 1),
            (vec![5], 5),
            (vec![0, 3], 0),
            (vec![1, 1, 1, 1, 2], 2),
        ] {
            let path = tmp("rank.npy");
            let data: Vec<f32> = (0..n).map(|i| i as f32).collect();
            write_f32(&path, &data, &shape).unwrap();
            assert_eq!(read_f32(&path).unwrap(), (data, shape));
        }
    }

    #[test]
    fn special_values_survive() {
        let path = tmp("special.npy");
        let data = [f32::NAN, f32::INFINITY, -0.0, f32::MIN_POSITIVE, 1.0e-42];
        write_f32(&path, &data, &[5]).unwrap();
        let (back, _) = read_f32(&path).unwrap();
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back), bits(&data));
    }

    #[test]
    fn write_rejects_shape_mismatch() {
        let err = write_f32(tmp("bad.npy"), &[1.0, 2.0, 3.0], &[2, 2]).unwrap_err();
        assert!(
            matches!(err, Error::Argument { ref arg, .. } if arg == "shape"),
            "{err}"
        );
        let err = write_f32(tmp("bad.npy"), &[1.0], &[usize::MAX, 2]).unwrap_err();
        assert!(matches!(err, Error::Argument { .. }), "{err}");
    }

    #[test]
    fn reads_f8_and_v2_headers() {
        let vals = [1.5f64, -2.25, 1e300];
        let data: Vec<u8> = vals.iter().flat_map(|v| v.to_le_bytes()).collect();
        let path = tmp("f8.npy");
        std::fs::write(
            &path,
            raw_npy(
                "{'descr': '<f8', 'fortran_order': False, 'shape': (3,), }",
                &data,
            ),
        )
        .unwrap();
        let (back, shape) = read_f32(&path).unwrap();
        assert_eq!(shape, vec![3]);
        assert_eq!(back, vec![1.5, -2.25, f32::INFINITY]);

        // Version 2.0: u32 header length; keys in another order, double quotes, `L` suffixes.
        let dict = "{\"shape\": (1L, 2L), \"fortran_order\": False, \"descr\": \"<f4\"}";
        let mut bytes = MAGIC.to_vec();
        bytes.extend_from_slice(&[2, 0]);
        bytes.extend_from_slice(&(dict.len() as u32 + 1).to_le_bytes());
        bytes.extend_from_slice(dict.as_bytes());
        bytes.push(b'\n');
        bytes.extend_from_slice(&3.0f32.to_le_bytes());
        bytes.extend_from_slice(&4.0f32.to_le_bytes());
        std::fs::write(&path, bytes).unwrap();
        assert_eq!(read_f32(&path).unwrap(), (vec![3.0, 4.0], vec![1, 2]));
    }

    #[test]
    fn rejects_fortran_order_and_other_dtypes() {
        let path = tmp("reject.npy");
        let cases = [
            (
                "{'descr': '<f4', 'fortran_order': True, 'shape': (2,), }",
                "fortran_order",
            ),
            (
                "{'descr': '<i4', 'fortran_order': False, 'shape': (2,), }",
                "descr",
            ),
            (
                "{'descr': '>f4', 'fortran_order': False, 'shape': (2,), }",
                "descr",
            ),
            (
                "{'descr': [('a', '<f4')], 'fortran_order': False, 'shape': (2,), }",
                "descr",
            ),
            (
                "{'descr': '<f4', 'fortran_order': False, 'shape': (2, -1), }",
                "shape",
            ),
            (
                "{'descr': '<f4', 'fortran_order': False, 'shape': 2, }",
                "shape",
            ),
            (
                "{'descr': '<f4', 'fortran_order': False, 'shape': (99999999999, 99999999999, 99999999999), }",
                "shape",
            ),
            ("{'descr': '<f4', 'fortran_order': False}", "shape"),
            (
                "{'descr': '<f4', 'fortran_order': False, 'shape': (2,), ",
                "header",
            ),
            ("not a dict", "header"),
        ];
        for (dict, field) in cases {
            std::fs::write(&path, raw_npy(dict, &[0; 8])).unwrap();
            let err = read_f32(&path).unwrap_err();
            assert_eq!(format_field(&err), field, "{dict}: {err}");
        }
    }

    #[test]
    fn rejects_truncated_and_overlong_files() {
        let path = tmp("trunc.npy");
        write_f32(&path, &[1.0; 6], &[2, 3]).unwrap();
        let full = std::fs::read(&path).unwrap();
        let data_start = full.len() - 24;
        // Truncated data: expected 24 bytes, found 21.
        std::fs::write(&path, &full[..full.len() - 3]).unwrap();
        let err = read_f32(&path).unwrap_err();
        assert_eq!(format_field(&err), "data");
        let msg = err.to_string();
        assert!(
            msg.contains("expected 24 bytes") && msg.contains("found 21 bytes"),
            "{msg}"
        );
        // Trailing garbage.
        let mut long = full.clone();
        long.push(0);
        std::fs::write(&path, long).unwrap();
        assert_eq!(format_field(&read_f32(&path).unwrap_err()), "data");
        // Every prefix, down to the empty file, is an error and never a panic.
        for n in 0..data_start {
            std::fs::write(&path, &full[..n]).unwrap();
            let err = read_f32(&path).unwrap_err();
            assert!(
                matches!(format_field(&err), "magic" | "header"),
                "prefix {n}: {err}"
            );
        }
    }

    #[test]
    fn rejects_bad_magic_version_and_missing_file() {
        let path = tmp("magic.npy");
        std::fs::write(&path, b"PK\x03\x04 not npy at all").unwrap();
        assert_eq!(format_field(&read_f32(&path).unwrap_err()), "magic");
        let mut bytes = raw_npy(
            "{'descr': '<f4', 'fortran_order': False, 'shape': (0,), }",
            &[],
        );
        bytes[6] = 9;
        std::fs::write(&path, bytes).unwrap();
        assert_eq!(format_field(&read_f32(&path).unwrap_err()), "version");
        let err = read_f32(tmp("does-not-exist.npy")).unwrap_err();
        assert!(matches!(err, Error::Io { .. }), "{err}");
    }

    #[test]
    fn garbage_headers_never_panic() {
        let path = tmp("fuzz.npy");
        let base = raw_npy(
            "{'descr': '<f4', 'fortran_order': False, 'shape': (2,), }",
            &[0; 8],
        );
        // Flip every header byte to a handful of troublesome values.
        for i in 10..base.len() - 8 {
            for b in [b'(', b')', b'{', b'}', b'\'', b',', b':', 0xff, b'['] {
                let mut bytes = base.clone();
                bytes[i] = b;
                std::fs::write(&path, &bytes).unwrap();
                let _ = read_f32(&path);
            }
        }
    }
}
