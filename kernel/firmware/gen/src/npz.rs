//! Just enough of an uncompressed `.npz` reader (a zip archive of stored `.npy` members, as
//! `vltm simulate --uncompressed` writes) for the fixture capture, so that `gen` needs no
//! dependency beyond the kernel. Every malformed input is an `Err` naming what is wrong.

use std::collections::HashMap;

/// An array of a `.npy` member: its shape and its values as `f64` (from `<f4` or `<f8`).
#[derive(Debug)]
pub struct Array {
    pub shape: Vec<usize>,
    pub values: Vec<f64>,
}

fn u16_at(b: &[u8], i: usize) -> Result<usize, String> {
    b.get(i..i + 2)
        .map(|s| u16::from_le_bytes([s[0], s[1]]) as usize)
        .ok_or_else(|| format!("truncated at byte {i}"))
}

fn u32_at(b: &[u8], i: usize) -> Result<usize, String> {
    b.get(i..i + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]) as usize)
        .ok_or_else(|| format!("truncated at byte {i}"))
}

/// Every member of the archive `bytes`, by name without `.npy`: the array, or why it could not
/// be decoded (e.g. a `u8` flag, which the fixture does not need).
pub fn read(bytes: &[u8]) -> Result<HashMap<String, Result<Array, String>>, String> {
    // End of central directory: the last "PK\x05\x06".
    let eocd = (0..bytes.len().saturating_sub(21))
        .rev()
        .find(|&i| bytes[i..i + 4] == [0x50, 0x4b, 0x05, 0x06])
        .ok_or("no zip end-of-central-directory record")?;
    let count = u16_at(bytes, eocd + 10)?;
    let mut at = u32_at(bytes, eocd + 16)?;
    let mut out = HashMap::new();
    for _ in 0..count {
        if bytes.get(at..at + 4) != Some(&[0x50, 0x4b, 0x01, 0x02]) {
            return Err(format!("bad central directory entry at byte {at}"));
        }
        let method = u16_at(bytes, at + 10)?;
        let size = u32_at(bytes, at + 20)?;
        let (nlen, xlen, clen) = (
            u16_at(bytes, at + 28)?,
            u16_at(bytes, at + 30)?,
            u16_at(bytes, at + 32)?,
        );
        let local = u32_at(bytes, at + 42)?;
        let name = bytes
            .get(at + 46..at + 46 + nlen)
            .map(|n| String::from_utf8_lossy(n).into_owned())
            .ok_or("truncated member name")?;
        at += 46 + nlen + xlen + clen;
        if method != 0 {
            return Err(format!(
                "{name}: compressed (method {method}); write the capture with --uncompressed"
            ));
        }
        if bytes.get(local..local + 4) != Some(&[0x50, 0x4b, 0x03, 0x04]) {
            return Err(format!("{name}: bad local header"));
        }
        let start = local + 30 + u16_at(bytes, local + 26)? + u16_at(bytes, local + 28)?;
        let data = bytes
            .get(start..start + size)
            .ok_or_else(|| format!("{name}: truncated data"))?;
        let key = name.strip_suffix(".npy").unwrap_or(&name).to_string();
        out.insert(key, npy(data).map_err(|e| format!("{name}: {e}")));
    }
    Ok(out)
}

/// One `.npy` array (format 1.0–3.0, C order, `<f4` or `<f8`).
pub fn npy(b: &[u8]) -> Result<Array, String> {
    if b.get(..6) != Some(b"\x93NUMPY") {
        return Err("not a .npy array".into());
    }
    let (hlen, start) = match b.get(6) {
        Some(1) => (u16_at(b, 8)?, 10),
        Some(2 | 3) => (u32_at(b, 8)?, 12),
        v => return Err(format!("unknown .npy version {v:?}")),
    };
    let header = b
        .get(start..start + hlen)
        .map(String::from_utf8_lossy)
        .ok_or("truncated header")?;
    if !header.contains("'fortran_order': False") {
        return Err("Fortran order".into());
    }
    let width = if header.contains("'descr': '<f4'") {
        4
    } else if header.contains("'descr': '<f8'") {
        8
    } else {
        return Err(format!("dtype other than <f4/<f8 in {header}"));
    };
    let dims = header
        .split("'shape': (")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .ok_or("no shape")?;
    let shape = dims
        .split(',')
        .map(str::trim)
        .filter(|d| !d.is_empty())
        .map(|d| {
            d.parse::<usize>()
                .map_err(|_| format!("bad shape `{dims}`"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let n: usize = shape.iter().product();
    let data = b
        .get(start + hlen..start + hlen + n * width)
        .ok_or("truncated data")?;
    let values = data
        .chunks_exact(width)
        .map(|c| match width {
            4 => f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]])),
            _ => f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]),
        })
        .collect();
    Ok(Array { shape, values })
}
