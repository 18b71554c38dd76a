//! A stored (uncompressed) `.npz` capture streamed row by row by positional reads, its CRC-32
//! checked as rows are read.

use super::read::{MAX_NPY_HEADER, check_members, geometry, npy_prefix, npy_shape};
use crate::error::{Error, Result};
use crate::io::capture::{Geometry, RowSource, check_row};
use ndarray_npy::NpzReader;
use std::fs::File;
use std::path::Path;

/// An uncompressed `.npz` capture (`vltm simulate --uncompressed`, `numpy.savez`) read
/// **row by row** straight from the file: memory O(Ks·Nt) whatever the number of rows,
/// and no decoding of the whole `H` before the first row is processed.
///
/// Integrity: the archive's CRC-32 of `H` is checked as the rows are read. Rows read in order
/// (as every probe reads them) are hashed on the way, at no extra I/O; reading the last row
/// completes the check, and a mismatch is an error on that row, so no pass over the whole
/// capture ends with corrupted data unnoticed. A pass that skips around is checked by one
/// extra sequential read of the entry when its last row is requested.
#[derive(Debug)]
pub struct NpzStream {
    path: std::path::PathBuf,
    geometry: Geometry,
    file: File,
    /// Byte offset of `H[0, …]` in the file.
    start: u64,
    bytes: Vec<u8>,
    crc: Crc,
}

/// The CRC-32 check of the stored `H.npy` entry, computed as rows are read (see
/// [`NpzStream`]'s [`RowSource::read_row`]).
#[derive(Debug)]
struct Crc {
    /// The entry's first byte (its `.npy` header) and its length in the file.
    entry: (u64, u64),
    /// The CRC-32 the archive records for the entry.
    expected: u32,
    /// Running hash of the entry's bytes `entry.0 .. hashed_to`.
    hasher: crc32fast::Hasher,
    hashed_to: u64,
    /// Set once the whole entry matched.
    verified: bool,
}

/// Opens `path` as an [`NpzStream`] if its `H` is stored uncompressed as little-endian
/// C-order `f32` (`Ok(None)` otherwise: read it with [`read`](fn@super::read)).
///
/// # Errors
/// [`Error::Io`], or [`Error::Format`] for a malformed archive, field or a truncated `H`.
pub fn open_stream(path: &Path) -> Result<Option<NpzStream>> {
    use std::io::{Read, Seek, SeekFrom};
    let io = |e: std::io::Error| Error::io(path, e);
    let bad = |what: &str, found: String| Error::format(path, "H", what.to_string(), found);
    let f = File::open(path).map_err(io)?;
    let mut z = zip::ZipArchive::new(f)
        .map_err(|e| Error::format(path, "(archive)", "a NumPy .npz archive", e.to_string()))?;
    let (data_start, len, crc32) = match z.by_name("H.npy") {
        Ok(e) if e.compression() == zip::CompressionMethod::Stored => {
            (e.data_start(), e.size(), e.crc32())
        }
        Ok(_) => return Ok(None),
        Err(e) => return Err(bad("an array H", e.to_string())),
    };
    let mut file = z.into_inner();
    file.seek(SeekFrom::Start(data_start)).map_err(io)?;
    let mut pre = [0u8; 12];
    file.read_exact(&mut pre).map_err(io)?;
    let (hlen, skip) = npy_prefix(&pre).map_err(|e| bad(".npy version 1-3", e))?;
    if hlen > MAX_NPY_HEADER {
        return Err(bad("a .npy header under 64 KiB", format!("{hlen} bytes")));
    }
    file.seek(SeekFrom::Start(data_start + skip)).map_err(io)?;
    let mut header = vec![0u8; hlen as usize];
    file.read_exact(&mut header).map_err(io)?;
    let header = String::from_utf8_lossy(&header).replace(' ', "");
    if !header.contains("'descr':'<f4'") || !header.contains("'fortran_order':False") {
        return Ok(None);
    }
    let shape = npy_shape(&header)
        .ok_or_else(|| bad("a shape tuple in the .npy header", header.clone()))?;
    let start = data_start + skip + hlen;
    let need = shape
        .iter()
        .try_fold(4u64, |a, &x| a.checked_mul(x as u64))
        .and_then(|b| b.checked_add(start));
    // Exactly the shape's bytes, as `read` (and NumPy) require: a truncated entry, or one
    // with bytes after its data, is refused by every command alike.
    if need != Some(data_start + len) {
        let have = (data_start + len).saturating_sub(start);
        let what = if need.is_some_and(|end| end < data_start + len) {
            "extra bytes after the data"
        } else {
            "truncated"
        };
        return Err(bad(
            &format!(
                "{} bytes of f32 data",
                need.map_or("more than 2^64".into(), |e| (e - start).to_string())
            ),
            format!("{have} bytes ({what})"),
        ));
    }
    check_members(path)?;
    let mut r = NpzReader::new(File::open(path).map_err(io)?)
        .map_err(|e| Error::format(path, "(archive)", "a NumPy .npz archive", e.to_string()))?;
    let geometry = geometry(&mut r, path, &shape)?;
    // Hash the entry's .npy header now; rows are hashed as they are read.
    let mut hasher = crc32fast::Hasher::new();
    let mut head = vec![
        0u8;
        usize::try_from(start - data_start)
            .map_err(|_| bad("a small header", String::new()))?
    ];
    file.seek(SeekFrom::Start(data_start)).map_err(io)?;
    file.read_exact(&mut head).map_err(io)?;
    hasher.update(&head);
    Ok(Some(NpzStream {
        path: path.to_path_buf(),
        geometry,
        file,
        start,
        bytes: Vec::new(),
        crc: Crc {
            entry: (data_start, len),
            expected: crc32,
            hasher,
            hashed_to: start,
            verified: false,
        },
    }))
}

impl NpzStream {
    /// Completes the CRC-32 check of `H` from `hashed_to` to the end of the entry.
    fn finish_crc(&mut self) -> Result<()> {
        use std::io::{Read, Seek, SeekFrom};
        let (first, len) = self.crc.entry;
        let end = first + len;
        let io = |e: std::io::Error| Error::io(&self.path, e);
        self.file
            .seek(SeekFrom::Start(self.crc.hashed_to))
            .map_err(io)?;
        let mut buf = vec![0u8; 1 << 20];
        let mut left = end.saturating_sub(self.crc.hashed_to);
        while left > 0 {
            let k = left.min(buf.len() as u64) as usize;
            self.file.read_exact(&mut buf[..k]).map_err(io)?;
            self.crc.hasher.update(&buf[..k]);
            left -= k as u64;
        }
        self.crc.hashed_to = end;
        let got = self.crc.hasher.clone().finalize();
        if got != self.crc.expected {
            return Err(Error::format(
                &self.path,
                "H",
                format!("CRC-32 {:08x} as the archive records", self.crc.expected),
                format!("{got:08x}: the file is corrupted"),
            ));
        }
        self.crc.verified = true;
        Ok(())
    }
}

impl RowSource for NpzStream {
    fn geometry(&self) -> &Geometry {
        &self.geometry
    }
    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<vltm_kernel::Point> {
        use std::io::{Read, Seek, SeekFrom};
        let g = &self.geometry;
        let n = g.spads_per_row() * g.nt;
        check_row(l, g.lasers.len())?;
        let x = g.lasers[l];
        self.bytes.resize(4 * n, 0);
        let offset = self.start + (4 * n * l) as u64;
        self.file
            .seek(SeekFrom::Start(offset))
            .and_then(|_| self.file.read_exact(&mut self.bytes))
            .map_err(|e| Error::io(&self.path, e))?;
        if !self.crc.verified {
            if self.crc.hashed_to == offset {
                self.crc.hasher.update(&self.bytes);
                self.crc.hashed_to += self.bytes.len() as u64;
            }
            if l + 1 == g.lasers.len() {
                self.finish_crc()?;
            }
        }
        out.clear();
        out.extend(
            self.bytes
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        );
        Ok(x)
    }

    /// The rows of a batch by positional reads in parallel (one per row); the entry's
    /// CRC-32 is still checked, each row hashed on its own thread and the hashes combined in
    /// row order.
    #[cfg(unix)]
    fn read_rows(
        &mut self,
        first: usize,
        out: &mut [(vltm_kernel::Point, Vec<f32>)],
    ) -> Result<()> {
        use rayon::prelude::*;
        use std::os::unix::fs::FileExt;
        let g = &self.geometry;
        let n = g.spads_per_row() * g.nt;
        if out.is_empty() {
            return Ok(());
        }
        check_row(first, g.lasers.len())?;
        check_row(first + out.len() - 1, g.lasers.len())?;
        let hash = !self.crc.verified;
        let (file, path, start) = (&self.file, &self.path, self.start);
        let hashes = out
            .par_iter_mut()
            .enumerate()
            .map(|(i, (x, h))| {
                let l = first + i;
                // Straight into the row's buffer (kept from the batch before: no fill, no
                // copy), the stored little-endian bytes hashed as read.
                h.resize(n, 0.0);
                let bytes: &mut [u8] = bytemuck::cast_slice_mut(&mut h[..]);
                file.read_exact_at(bytes, start + (4 * n * l) as u64)
                    .map_err(|e| Error::io(path, e))?;
                let hs = hash.then(|| {
                    let mut hs = crc32fast::Hasher::new();
                    hs.update(bytes);
                    hs
                });
                if cfg!(target_endian = "big") {
                    h.iter_mut()
                        .for_each(|v| *v = f32::from_bits(v.to_bits().swap_bytes()));
                }
                *x = g.lasers[l];
                Ok(hs)
            })
            .collect::<Result<Vec<_>>>()?;
        if hash {
            if self.crc.hashed_to == start + (4 * n * first) as u64 {
                for hs in hashes.iter().flatten() {
                    self.crc.hasher.combine(hs);
                }
                self.crc.hashed_to += (4 * n * out.len()) as u64;
            }
            if first + out.len() == g.lasers.len() {
                self.finish_crc()?;
            }
        }
        Ok(())
    }

    #[cfg(unix)]
    fn reads_in_parallel(&self) -> bool {
        true
    }
}
