//! The file format of partial states ([`crate::probe::Partial`]): a container of a JSON
//! header, three point sections and the accumulators, checked by a CRC-32. What the header
//! and the accumulators mean (capture identity, probe parameters, row ranges, state per
//! probe) is the probes' business (`probe::partial`); this module only writes and reads the
//! bytes, beside the other file formats.
//!
//! # Binary format (version 1, little-endian)
//!
//! | bytes | content |
//! |---|---|
//! | 8 | magic `VLTMPART` |
//! | 4 | format version, `u32` (1) |
//! | 4 | header length `h`, `u32` |
//! | `h` | header: UTF-8 JSON — `capture` (identity), `probe` (kind and parameters), `rows` (row ranges `[a, b)`), `report` (counters), `legs` (per factorised column: projector leg range or null), `n_spads`, `n_points`, `n_from`, `n_acc`, `crc32` (of the bytes that follow, 8 hex digits), `capture_name` (informational) |
//! | `12·n_spads` | SPAD spots, `f32` x, y, z (columns and indirect light image with them) |
//! | `12·n_points` | volume points, `f32` (point lists only; grids are rebuilt from `probe.volume.axes`) |
//! | `12·n_from` | the matrix's foci `x_a`, `f32` (`n_from` absent = 0: parts written before it read the same) |
//! | `8·n_acc` | the accumulators, `f64` (complex numbers as re, im pairs) |
//!
//! Cost: one copy of the state each way; the CRC runs over the sections.

use crate::error::{Error, Result};
use serde::Deserialize;
use std::path::Path;
use vltm_kernel::Point;

/// The first bytes of a partial-state file.
pub const MAGIC: &[u8; 8] = b"VLTMPART";
/// The format version written (and the only one read).
pub const VERSION: u32 = 1;

/// The sections of a state after its header.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sections {
    /// SPAD spots.
    pub spads: Vec<Point>,
    /// Volume points (point lists only).
    pub points: Vec<Point>,
    /// A matrix's foci.
    pub from: Vec<Point>,
    /// The accumulators.
    pub acc: Vec<f64>,
}

/// The header fields this module reads: the section sizes and the checksum (the rest of the
/// header belongs to the probes).
#[derive(Deserialize)]
struct Sizes {
    n_spads: usize,
    n_points: usize,
    #[serde(default)]
    n_from: usize,
    n_acc: usize,
    crc32: String,
}

fn point_bytes(pts: &[Point]) -> impl Iterator<Item = u8> + '_ {
    pts.iter().flatten().flat_map(|c| c.to_le_bytes())
}

/// The file's length: `points` the three point sections, `n_acc` accumulators, a header of
/// `header_len` bytes.
pub fn byte_len(points: [&[Point]; 3], n_acc: usize, header_len: usize) -> usize {
    16 + header_len + 12 * points.iter().map(|p| p.len()).sum::<usize>() + 8 * n_acc
}

/// A state file of the point sections `points` (SPAD spots, volume points, a matrix's foci)
/// and the accumulators `acc`: `header(crc32)` is the JSON header given the CRC-32 of the
/// sections (its `n_*` fields must give their sizes). One copy of the state.
pub fn encode(points: [&[Point]; 3], acc: &[f64], header: impl FnOnce(u32) -> Vec<u8>) -> Vec<u8> {
    // The accumulators as little-endian f64 (the byte order of every supported target is
    // checked at compile time).
    const _: () = assert!(cfg!(target_endian = "little"));
    let acc: &[u8] = bytemuck::cast_slice(acc);
    let mut crc = crc32fast::Hasher::new();
    for p in points {
        crc.update(&point_bytes(p).collect::<Vec<u8>>());
    }
    crc.update(acc);
    let head = header(crc.finalize());
    let n = 12 * points.iter().map(|p| p.len()).sum::<usize>();
    let mut out = Vec::with_capacity(16 + head.len() + n + acc.len());
    out.extend_from_slice(MAGIC);
    out.extend(VERSION.to_le_bytes());
    out.extend((head.len() as u32).to_le_bytes());
    out.extend(head);
    for p in points {
        out.extend(point_bytes(p));
    }
    out.extend_from_slice(acc);
    out
}

/// The JSON header and the sections of a state file; `what` names its origin in errors.
///
/// # Errors
/// [`Error::Format`] for another magic or version, a header that does not parse, a size that
/// does not match or a CRC that fails.
pub fn decode<'b>(bytes: &'b [u8], what: &Path) -> Result<(&'b [u8], Sections)> {
    let bad =
        |field: &str, expected: &str, found: String| Error::format(what, field, expected, found);
    if bytes.len() < 16 || bytes[..8] != MAGIC[..] {
        return Err(bad(
            "magic",
            "a vltm partial state (VLTMPART)",
            format!("{} bytes of something else", bytes.len()),
        ));
    }
    let word = |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    let version = word(8);
    if version != VERSION {
        return Err(bad("version", "1", version.to_string()));
    }
    let h = word(12) as usize;
    let rest = &bytes[16..];
    if rest.len() < h {
        return Err(bad(
            "header",
            &format!("{h} bytes"),
            format!("{} (truncated)", rest.len()),
        ));
    }
    let (head, body) = rest.split_at(h);
    let sizes: Sizes = serde_json::from_slice(head)
        .map_err(|e| bad("header", "the JSON header of format 1", e.to_string()))?;
    let want = sizes
        .n_spads
        .checked_add(sizes.n_points)
        .and_then(|n| n.checked_add(sizes.n_from))
        .and_then(|n| n.checked_mul(12))
        .and_then(|n| sizes.n_acc.checked_mul(8).and_then(|a| a.checked_add(n)));
    if want != Some(body.len()) {
        return Err(bad(
            "body",
            &format!(
                "{} SPADs, {} + {} points and {} accumulators",
                sizes.n_spads, sizes.n_points, sizes.n_from, sizes.n_acc
            ),
            format!("{} bytes (truncated or padded)", body.len()),
        ));
    }
    let crc = format!("{:08x}", crc32fast::hash(body));
    if crc != sizes.crc32 {
        return Err(bad(
            "crc32",
            &sizes.crc32,
            format!("{crc} (the state is corrupted)"),
        ));
    }
    let pts = |b: &[u8]| -> Vec<Point> {
        b.chunks_exact(12)
            .map(|p| {
                core::array::from_fn(|i| {
                    f32::from_le_bytes([p[4 * i], p[4 * i + 1], p[4 * i + 2], p[4 * i + 3]])
                })
            })
            .collect()
    };
    let (sp, rest) = body.split_at(12 * sizes.n_spads);
    let (pt, rest) = rest.split_at(12 * sizes.n_points);
    let (fr, acc) = rest.split_at(12 * sizes.n_from);
    let acc = acc
        .chunks_exact(8)
        .map(|b| f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]))
        .collect();
    let sections = Sections {
        spads: pts(sp),
        points: pts(pt),
        from: pts(fr),
        acc,
    };
    Ok((head, sections))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_corruption() {
        let s = Sections {
            spads: vec![[0.1, 0.2, 0.3]],
            points: vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]],
            from: Vec::new(),
            acc: vec![1.5, -2.25, 1e300],
        };
        let header = |crc: u32| {
            format!(r#"{{"n_spads":1,"n_points":2,"n_acc":3,"crc32":"{crc:08x}","extra":true}}"#)
                .into_bytes()
        };
        let pts = [&s.spads[..], &s.points[..], &s.from[..]];
        let bytes = encode(pts, &s.acc, header);
        assert_eq!(bytes.len(), byte_len(pts, s.acc.len(), header(0).len()));
        let (h, back) = decode(&bytes, Path::new("t")).unwrap();
        assert_eq!(back, s);
        assert!(std::str::from_utf8(h).unwrap().contains("\"extra\":true"));
        let mut bad = bytes.clone();
        *bad.last_mut().unwrap() ^= 1;
        let e = decode(&bad, Path::new("t")).unwrap_err();
        assert!(e.to_string().contains("crc32"), "{e}");
        let e = decode(&bytes[..bytes.len() - 1], Path::new("t")).unwrap_err();
        assert!(e.to_string().contains("body"), "{e}");
        let e = decode(b"VLTMPARX\x01\0\0\0\0\0\0\0", Path::new("t")).unwrap_err();
        assert!(e.to_string().contains("magic"), "{e}");
    }
}
