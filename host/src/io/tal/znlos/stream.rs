//! Blocks of Z-NLOS rows read by the `HDF5_TAL` reader's background thread
//! ([`ReadAhead`](super::super::block::ReadAhead), through [`ReadBlocks`]): colours and
//! bounces summed while the file's values are reordered into vltm's SPAD-major rows, so that
//! reading and summing overlap the probes' work (module docs of [`znlos`](super), *Memory
//! and cost*).
//!
//! * **Laser-first orders** (`Rows7`, `Rows5`): the last three axes of `data` are
//!   `(bounces, t, colours)`, so each histogram is one run of `B·Nt·C` values and a row's
//!   histograms follow one another. A block is as many consecutive rows as fit in
//!   [`BLOCK_BYTES`](super::super::BLOCK_BYTES) of `data` as stored (at least one); its histograms are read with
//!   positional reads of whole runs of adjacent histograms (at most `BLOCK_BYTES`, at least
//!   one histogram each) when `data` is contiguous little-endian, else one hyperslab per row
//!   through the crate, and each histogram is summed over bounces and colours into its place.
//! * **Time-first orders** (`Time7`, `Time5`): every row has values in every part of the
//!   file, so the first block waits for one pass over the whole file: `data` is read in file
//!   order (`BLOCK_BYTES` of whole `(sy, sx, ly, lx)` planes per positional read, or one
//!   hyperslab per `(colour, bin)` through the crate) and summed into a time-major copy of the
//!   capture `[t][s·Kl + l]` (each plane scattered through an index table, within one bin's
//!   plane); the blocks are then cut from it in tiles of [`GROUP`] bins, one cache line of
//!   consecutive rows read per bin and SPAD.
//!
//! Sums are taken in the file's order starting from 0, as the reader always did: the rows are
//! bit-identical whatever the path. Memory: stated by [`Source::memory`].

use super::super::block::{GROUP, ReadBlocks};
use super::super::fields::Elem;
use super::super::fields::{h5_error, into_vec};
use crate::error::{Error, Result};
use hdf5_reader::{Dataset, SliceInfo, SliceInfoElem};
use std::io::{Read, Seek, SeekFrom};
use std::path::PathBuf;

/// Everything the background reader needs to read Z-NLOS blocks on its own.
pub(super) struct Source {
    /// The file.
    pub(super) path: PathBuf,
    /// `data`.
    pub(super) h: Dataset,
    /// Its element type.
    pub(super) elem: Elem,
    /// Its shape.
    pub(super) dims: Vec<usize>,
    /// File address of a contiguous little-endian `data` (positional reads), else `None`.
    pub(super) raw: Option<u64>,
    /// Whether the layout is laser-first (`Rows7`, `Rows5`).
    pub(super) streams: bool,
    /// Rows.
    pub(super) kl: usize,
    /// SPADs per row.
    pub(super) ks: usize,
    /// Time bins.
    pub(super) nt: usize,
    /// For each axis of `data`: the row axis it is (0 x, 1 y), if any.
    pub(super) row_axis: Vec<Option<usize>>,
    /// For each axis of `data`: its stride in a row `[s][n]` (0 for colours, bounces and the
    /// row axes).
    pub(super) strides: Vec<usize>,
    /// Rows per row-x index.
    pub(super) row_ny: usize,
    /// Bytes of `data` read at once: `BLOCK_BYTES` (smaller in tests, to make many blocks).
    pub(super) block_bytes: usize,
}

impl Source {
    fn elem_bytes(&self) -> usize {
        if self.elem == Elem::F32 { 4 } else { 8 }
    }

    /// Values of one histogram as stored: `bounces · Nt · colours` (laser-first orders).
    fn hist(&self) -> usize {
        self.dims[self.dims.len() - 3..].iter().product()
    }

    /// Values of the plane of one `(colour, bin, bounce)` (time-first orders): every axis
    /// after the bounces.
    fn plane(&self) -> usize {
        self.dims[3..].iter().product()
    }

    /// Rows per block.
    pub(super) fn block_rows(&self) -> usize {
        let row_bytes = if self.streams {
            self.ks * self.hist() * self.elem_bytes()
        } else {
            self.ks * self.nt * 4
        };
        (self.block_bytes / row_bytes.max(1)).max(1)
    }

    /// Bytes the reading holds at most: three blocks of rows (one handed out, one queued, one
    /// being read), the staging buffers of a read (at most `BLOCK_BYTES` of `data`, or one
    /// histogram or plane when larger, as read and as f32) and, time-first, the summed
    /// capture (`4·Kl·Ks·Nt` bytes) and its index table (`4·Kl·Ks`); through the crate, the
    /// hyperslab it returns (a row as stored, or a `(colour, bin)` slab of planes).
    pub(super) fn memory(&self) -> u128 {
        let eb = self.elem_bytes() as u128;
        let row = (self.ks * self.nt) as u128 * 4;
        let blocks = 3 * row * self.block_rows().min(self.kl) as u128;
        let unit = if self.streams {
            self.hist()
        } else {
            self.plane()
        } as u128;
        let stage = (self.block_bytes as u128).max(unit * eb) * (1 + 4 / eb);
        let crate_slab = if self.raw.is_some() {
            0
        } else if self.streams {
            self.ks as u128 * self.hist() as u128 * (eb + 4)
        } else {
            unit * self.dims[2] as u128 * (eb + 4)
        };
        let whole = if self.streams {
            0
        } else {
            (self.kl * self.ks) as u128 * (self.nt as u128 * 4 + 4)
        };
        blocks + stage + crate_slab + whole
    }

    /// The value index of `data` of the element whose axes are `idx` (C order).
    fn offset(&self, idx: impl Iterator<Item = usize>) -> usize {
        self.dims.iter().zip(idx).fold(0, |o, (&n, i)| o * n + i)
    }

    /// For each index of the non-row axes among `axes` (C order): its file offset (every
    /// other axis at 0) and the SPAD `s` it is in the row.
    fn spads_of(&self, axes: std::ops::Range<usize>) -> Vec<(usize, usize)> {
        let free: Vec<usize> = axes.filter(|&a| self.row_axis[a].is_none()).collect();
        let count: usize = free.iter().map(|&a| self.dims[a]).product();
        let mut out = Vec::with_capacity(count);
        let mut idx = vec![0usize; self.dims.len()];
        for _ in 0..count {
            let s = free
                .iter()
                .map(|&a| idx[a] * self.strides[a])
                .sum::<usize>()
                / self.nt;
            out.push((self.offset(idx.iter().copied()), s));
            for &a in free.iter().rev() {
                idx[a] += 1;
                if idx[a] < self.dims[a] {
                    break;
                }
                idx[a] = 0;
            }
        }
        out
    }

    /// The file offset (values) of row `l`'s row axes.
    fn row_offset(&self, l: usize) -> usize {
        let ri = [l / self.row_ny, l % self.row_ny];
        self.offset(self.row_axis.iter().map(|r| r.map_or(0, |r| ri[r])))
    }

    /// The hyperslab of row `l` (row axes indexed, the others whole), through the crate.
    fn read_row_slab(&self, l: usize) -> Result<Vec<f32>> {
        let ri = [l / self.row_ny, l % self.row_ny];
        let sel = (0..self.dims.len())
            .map(|a| match self.row_axis[a] {
                Some(r) => SliceInfoElem::Index(ri[r] as u64),
                None => span(0, self.dims[a]),
            })
            .collect();
        let v = self.read_slab(sel)?;
        self.check_len(&v, self.ks * self.hist())?;
        Ok(v)
    }

    /// The hyperslab `sel` of `data` as f32, through the crate.
    fn read_slab(&self, selections: Vec<SliceInfoElem>) -> Result<Vec<f32>> {
        let sel = SliceInfo { selections };
        let field = |e| h5_error(&self.path, "data", e);
        Ok(match self.elem {
            Elem::F32 => into_vec(self.h.read_slice::<f32>(&sel).map_err(field)?),
            Elem::F64 => into_vec(self.h.read_slice::<f64>(&sel).map_err(field)?)
                .into_iter()
                .map(|x| x as f32)
                .collect(),
        })
    }

    fn check_len(&self, v: &[f32], want: usize) -> Result<()> {
        if v.len() == want {
            Ok(())
        } else {
            Err(Error::format(
                &self.path,
                "data",
                format!("{want} values in the hyperslab"),
                v.len(),
            ))
        }
    }
}

fn span(a: usize, b: usize) -> SliceInfoElem {
    SliceInfoElem::Slice {
        start: a as u64,
        end: b as u64,
        step: 1,
    }
}

/// The background reader's state: the source, the open file and the staging buffers, and
/// for the time-first orders the summed capture once read.
pub(super) struct Blocks {
    src: Source,
    file: Option<(std::fs::File, u64)>,
    stage: Vec<f32>,
    stage64: Vec<f64>,
    /// Laser-first: `(offset with the row axes at 0, s)` of each histogram of a row, in file
    /// order.
    hists: Vec<(usize, usize)>,
    /// Time-first: the capture summed, `[t][s·Kl + l]`, once read.
    sum: Option<Vec<f32>>,
}

impl Blocks {
    /// A reader of `src`'s blocks.
    pub(super) fn new(src: Source) -> Self {
        let hists = if src.streams {
            src.spads_of(0..src.dims.len() - 3)
        } else {
            Vec::new()
        };
        Self {
            src,
            file: None,
            stage: Vec::new(),
            stage64: Vec::new(),
            hists,
            sum: None,
        }
    }

    /// Reads `len` values of a contiguous `data` from value `offset` into `stage` (as f32).
    fn read_raw(&mut self, address: u64, offset: usize, len: usize) -> Result<()> {
        let src = &self.src;
        let eb = src.elem_bytes() as u64;
        let io = |e| Error::io(&src.path, e);
        if self.file.is_none() {
            self.file = Some((std::fs::File::open(&src.path).map_err(io)?, 0));
        }
        let (file, pos) = self.file.as_mut().expect("opened above");
        let at = address + offset as u64 * eb;
        if *pos != at {
            file.seek(SeekFrom::Start(at)).map_err(io)?;
        }
        self.stage.resize(len, 0.0);
        match src.elem {
            Elem::F32 => {
                file.read_exact(bytemuck::cast_slice_mut(&mut self.stage))
                    .map_err(io)?;
                if cfg!(target_endian = "big") {
                    self.stage
                        .iter_mut()
                        .for_each(|x| *x = f32::from_bits(x.to_bits().swap_bytes()));
                }
            }
            Elem::F64 => {
                self.stage64.resize(len, 0.0);
                file.read_exact(bytemuck::cast_slice_mut(&mut self.stage64))
                    .map_err(io)?;
                self.stage
                    .iter_mut()
                    .zip(&self.stage64)
                    .for_each(|(d, &x)| {
                        *d = f64::from_le_bytes(x.to_ne_bytes()) as f32;
                    });
            }
        }
        *pos = at + len as u64 * eb;
        Ok(())
    }

    /// Laser-first: rows `first..first + out.len()`.
    fn read_rows(&mut self, first: usize, out: &mut [&mut [f32]]) -> Result<()> {
        let (nt, hist) = (self.src.nt, self.src.hist().max(1));
        let colours = self.src.dims[self.src.dims.len() - 1];
        let per_read = (self.src.block_bytes / (hist * self.src.elem_bytes())).max(1);
        let Some(address) = self.src.raw else {
            for (r, dst) in out.iter_mut().enumerate() {
                let v = self.src.read_row_slab(first + r)?;
                for (&(_, s), h) in self.hists.iter().zip(v.chunks_exact(hist)) {
                    sum_hist(h, colours, &mut dst[s * nt..(s + 1) * nt]);
                }
            }
            return Ok(());
        };
        // Every histogram of the block, in row order: (file offset, row, s).
        let all: Vec<(usize, usize, usize)> = (0..out.len())
            .flat_map(|r| {
                let base = self.src.row_offset(first + r);
                self.hists.iter().map(move |&(o, s)| (base + o, r, s))
            })
            .collect();
        let mut i = 0;
        while i < all.len() {
            // A run of adjacent histograms.
            let mut j = i + 1;
            while j < all.len() && j - i < per_read && all[j].0 == all[j - 1].0 + hist {
                j += 1;
            }
            self.read_raw(address, all[i].0, (j - i) * hist)?;
            for (&(_, r, s), h) in all[i..j].iter().zip(self.stage.chunks_exact(hist)) {
                sum_hist(h, colours, &mut out[r][s * nt..(s + 1) * nt]);
            }
            i = j;
        }
        Ok(())
    }

    /// Time-first: `data` summed over colours and bounces into `[t][s·Kl + l]`, read in file
    /// order.
    fn read_sum(&mut self) -> Result<Vec<f32>> {
        let src = &self.src;
        let (nc, nt, nb) = (src.dims[0], src.dims[1], src.dims[2]);
        let plane = src.plane();
        let kl = src.kl;
        // Plane element q (C order over the axes after the bounces) → s·Kl + l.
        let map: Vec<usize> = {
            let spads = src.spads_of(3..src.dims.len());
            let rows: Vec<usize> = (0..kl).map(|l| src.row_offset(l)).collect();
            // offset(row) + offset(spad) is the element's offset in a plane at c = t = b = 0.
            let mut map = vec![0usize; plane];
            for (l, &ro) in rows.iter().enumerate() {
                for &(so, s) in &spads {
                    map[ro + so] = s * kl + l;
                }
            }
            map
        };
        let mut sum = vec![0.0f32; nt * plane];
        let add = |sum: &mut [f32], g: usize, v: &[f32]| {
            // Plane g = (c·Nt + t)·B + b.
            let t = g / nb % nt;
            let dst = &mut sum[t * plane..(t + 1) * plane];
            for (&x, &m) in v.iter().zip(&map) {
                dst[m] += x;
            }
        };
        let planes = nc * nt * nb;
        match src.raw {
            Some(address) => {
                let per_read =
                    (src.block_bytes / (plane * src.elem_bytes()).max(1)).clamp(1, planes.max(1));
                for g0 in (0..planes).step_by(per_read) {
                    let g1 = (g0 + per_read).min(planes);
                    self.read_raw(address, g0 * plane, (g1 - g0) * plane)?;
                    for (k, v) in self.stage.chunks_exact(plane.max(1)).enumerate() {
                        add(&mut sum, g0 + k, v);
                    }
                }
            }
            None => {
                for c in 0..nc {
                    for t in 0..nt {
                        let mut sel = vec![span(c, c + 1), span(t, t + 1)];
                        sel.extend(src.dims[2..].iter().map(|&n| span(0, n)));
                        let v = src.read_slab(sel)?;
                        src.check_len(&v, nb * plane)?;
                        for (b, p) in v.chunks_exact(plane.max(1)).enumerate() {
                            add(&mut sum, (c * nt + t) * nb + b, p);
                        }
                    }
                }
            }
        }
        Ok(sum)
    }
}

/// `h` = `(bounces, Nt, colours)` of one histogram summed over bounces and colours, in that
/// order from 0, into `dst` (`Nt` values).
fn sum_hist(h: &[f32], colours: usize, dst: &mut [f32]) {
    dst.fill(0.0);
    for bounce in h.chunks_exact((dst.len() * colours).max(1)) {
        if colours == 1 {
            dst.iter_mut().zip(bounce).for_each(|(d, &x)| *d += x);
        } else {
            for (d, c) in dst.iter_mut().zip(bounce.chunks_exact(colours.max(1))) {
                for &x in c {
                    *d += x;
                }
            }
        }
    }
}

impl ReadBlocks for Blocks {
    fn rows(&self) -> usize {
        self.src.kl
    }

    fn row_len(&self) -> usize {
        self.src.ks * self.src.nt
    }

    fn range(&self, l: usize) -> (usize, usize) {
        let b = self.src.block_rows();
        let first = l / b * b;
        (first, (first + b).min(self.src.kl))
    }

    fn read(&mut self, first: usize, out: &mut [&mut [f32]]) -> Result<()> {
        if self.src.dims.contains(&0) {
            // No values to sum (an empty colour or bounce axis).
            out.iter_mut().for_each(|r| r.fill(0.0));
            return Ok(());
        }
        if self.src.streams {
            return self.read_rows(first, out);
        }
        if self.sum.is_none() {
            self.sum = Some(self.read_sum()?);
        }
        let sum = self.sum.as_deref().unwrap_or_default();
        let (kl, ks, nt) = (self.src.kl, self.src.ks, self.src.nt);
        let plane = kl * ks;
        let rows = out.len();
        for t0 in (0..nt).step_by(GROUP) {
            let nn = GROUP.min(nt - t0);
            for s in 0..ks {
                let runs: [&[f32]; GROUP] = std::array::from_fn(|k| {
                    let at = (t0 + k.min(nn - 1)) * plane + s * kl + first;
                    &sum[at..at + rows]
                });
                for (r, dst) in out.iter_mut().enumerate() {
                    let d = &mut dst[s * nt + t0..s * nt + t0 + nn];
                    for (k, x) in d.iter_mut().enumerate() {
                        *x = runs[k][r];
                    }
                }
            }
        }
        Ok(())
    }
}
