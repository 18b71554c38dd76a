//! Blocks of laser rows read from `H` by a background thread (module docs of
//! [`io::tal`](super), *Reading*): which rows form a block ([`block_range`]), how a block is
//! read — positional reads of whole time-bin runs for a contiguous little-endian `H`, the
//! crate's hyperslab reader otherwise — and transposed from tal's time-first order to vltm's
//! SPAD-major rows, and the bounded queue that hands the blocks over ([`ReadAhead`]).
//!
//! Units: values are `f32` histogram samples as stored (f64 files are rounded to f32). A
//! chunked `H` that `chunks` decodes is read a band at a time (see there). Cost:
//! a contiguous `H` is read with one positional read per time bin and block (`Nt` reads of
//! `B·Ks` values, `B` rows per block; one read of [`GROUP`] bins when a block holds every
//! row), staged [`GROUP`] bins at a time in a buffer of `GROUP·B·Ks` values that stays in
//! cache while it is transposed. Memory: at most three blocks of rows (one handed out, one
//! queued, one being filled) plus the staging buffer; row buffers are recycled through
//! [`ReadAhead::recycle`], so a pass over the capture allocates about three blocks' worth.

use super::chunks::ChunkMap;
use super::fields::{Elem, h5_error, into_vec};
use super::format::HFormat;
use crate::error::{Error, Result};
use hdf5_reader::{Dataset, SliceInfo, SliceInfoElem};
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender, channel, sync_channel};

/// Rows read from `H` at once (module docs of [`io::tal`](super), *Reading*): at most this
/// many bytes (whole laser lines when a line fits), or one row.
pub const BLOCK_BYTES: usize = 16 << 20;

/// Time bins staged and transposed at once: two 64-byte cache lines of a row per SPAD.
pub(super) const GROUP: usize = 32;

/// Blocks waiting in the read-ahead queue (besides the one in use and the one being read).
const QUEUE: usize = 1;

/// The block of consecutive rows (flattened row axes) holding row `l`, `first..end`: whole
/// laser lines when a line fits in [`BLOCK_BYTES`] (as many as fit), else at most
/// [`BLOCK_BYTES`] of one line (at least one row). With `band` (rows per band of a chunked
/// `H` decoded chunk by chunk, whole lines), blocks are cut the same way inside each band.
pub(super) fn block_range(
    dims: &[usize],
    format: HFormat,
    ks: usize,
    band: Option<usize>,
    l: usize,
) -> (usize, usize) {
    let nt = dims[0];
    let row_bytes = (ks * nt * 4).max(1);
    let fit = (BLOCK_BYTES / row_bytes).max(1);
    let r = format.row_axes();
    let kl: usize = dims[1..=r].iter().product();
    let (lo, hi) = match band {
        Some(b) => {
            let lo = l / b.max(1) * b.max(1);
            (lo, (lo + b.max(1)).min(kl))
        }
        None => (0, kl),
    };
    let (l, n) = (l - lo, hi - lo);
    let line = if r == 2 { dims[2].max(1) } else { n.max(1) };
    let (a, b) = if r == 2 && fit >= line {
        let b = fit / line * line;
        let first = l / b * b;
        (first, (first + b).min(n))
    } else {
        let b = fit.min(line);
        let (ix, iy) = (l / line, l % line);
        let y0 = iy / b * b;
        (ix * line + y0, ix * line + (y0 + b).min(line))
    };
    (lo + a, lo + b)
}

/// Rows `first..first + rows.len()` in vltm's order, each `rows[r][s·Nt + n]`; a row handed
/// out by [`take`](Block::take) leaves `None`.
#[derive(Default)]
pub(super) struct Block {
    /// First row of the block.
    pub(super) first: usize,
    /// The rows, `None` once handed out.
    pub(super) rows: Vec<Option<Vec<f32>>>,
}

impl Block {
    /// Whether row `l` is in the block and not handed out yet.
    pub(super) fn holds(&self, l: usize) -> bool {
        l.checked_sub(self.first)
            .and_then(|r| self.rows.get(r))
            .is_some_and(Option::is_some)
    }

    /// Hands row `l` out (swapped into `out`) and returns the buffer `out` held before.
    pub(super) fn take(&mut self, l: usize, out: &mut Vec<f32>) -> Option<Vec<f32>> {
        let row = self.rows.get_mut(l.checked_sub(self.first)?)?.take()?;
        Some(std::mem::replace(out, row))
    }
}

/// Everything the background reader needs to read blocks on its own.
pub(super) struct Plan {
    pub(super) path: PathBuf,
    pub(super) h: Dataset,
    pub(super) elem: Elem,
    pub(super) dims: Vec<usize>,
    pub(super) format: HFormat,
    pub(super) ks: usize,
    pub(super) kl: usize,
    /// File address of a contiguous little-endian `H` (positional reads), else `None`.
    pub(super) raw: Option<u64>,
    /// The chunk index of a chunked `H` read chunk by chunk ([`ChunkMap`]), else `None`.
    pub(super) chunks: Option<Arc<ChunkMap>>,
}

impl Plan {
    /// The block holding row `l` ([`block_range`]).
    pub(super) fn block_range(&self, l: usize) -> (usize, usize) {
        let band = self.chunks.as_ref().map(|c| c.band_rows());
        block_range(&self.dims, self.format, self.ks, band, l)
    }
}

/// What a background reader ([`ReadAhead`]) reads: the rows, how they form blocks, and how
/// a block is read into row buffers. `HDF5_TAL`'s `H` is one ([`Reader`]), the Z-NLOS reader
/// another.
pub(super) trait ReadBlocks: Send + 'static {
    /// The number of rows.
    fn rows(&self) -> usize;
    /// The values of a row.
    fn row_len(&self) -> usize;
    /// The block holding row `l`, `first..end`.
    fn range(&self, l: usize) -> (usize, usize);
    /// Reads rows `first..first + out.len()` (one [`range`](Self::range)) into `out`, every
    /// value written (the buffers hold an earlier block's values).
    fn read(&mut self, first: usize, out: &mut [&mut [f32]]) -> Result<()>;
}

/// The reader thread's state: the open file (positional path) and its staging buffers.
pub(super) struct Reader {
    plan: Plan,
    file: Option<(std::fs::File, u64)>,
    stage: Vec<f32>,
    stage64: Vec<f64>,
    /// The rows of the chunk band decoded last (a chunked `H` read chunk by chunk), from
    /// row `band_first`; `band` is empty before the first band. Reused for every band.
    band: Vec<Vec<f32>>,
    band_first: usize,
}

impl Reader {
    /// A reader of `plan`'s blocks.
    pub(super) fn new(plan: Plan) -> Self {
        Self {
            plan,
            file: None,
            stage: Vec::new(),
            stage64: Vec::new(),
            band: Vec::new(),
            band_first: 0,
        }
    }
}

impl ReadBlocks for Reader {
    fn rows(&self) -> usize {
        self.plan.kl
    }

    fn row_len(&self) -> usize {
        self.plan.ks * self.plan.dims[0]
    }

    fn range(&self, l: usize) -> (usize, usize) {
        self.plan.block_range(l)
    }

    fn read(&mut self, first: usize, out: &mut [&mut [f32]]) -> Result<()> {
        let (nt, ks, rows) = (self.plan.dims[0], self.plan.ks, out.len());
        let end = first + rows;
        if let Some(chunks) = &self.plan.chunks {
            // A block lies inside one band (`block_range`): decode the band when it is not
            // the one held, then copy the block's rows out of it.
            let held = self.band_first..self.band_first + self.band.len();
            if !(held.contains(&first) && end <= held.end) {
                let b = chunks.band_rows().max(1);
                let (lo, hi) = (first / b * b, (first / b * b + b).min(self.plan.kl));
                self.band.resize_with(hi - lo, Vec::new);
                for row in &mut self.band {
                    row.resize(ks * nt, 0.0);
                }
                self.band_first = lo;
                if let Err(e) = chunks.read_band(&self.plan.path, first / b, &mut self.band) {
                    self.band.clear();
                    return Err(e);
                }
            }
            for (dst, src) in out.iter_mut().zip(&self.band[first - self.band_first..]) {
                dst.copy_from_slice(src);
            }
            return Ok(());
        }
        match self.plan.raw {
            Some(address) => {
                for n0 in (0..nt).step_by(GROUP) {
                    let nn = GROUP.min(nt - n0);
                    self.read_group(address, first, rows, n0, nn)?;
                    transpose(&self.stage, rows, ks, nt, n0, nn, out);
                }
            }
            None => {
                let v = self.plan.read_slice(first, end)?;
                for n0 in (0..nt).step_by(GROUP) {
                    let nn = GROUP.min(nt - n0);
                    let src = &v[n0 * rows * ks..(n0 + nn) * rows * ks];
                    transpose(src, rows, ks, nt, n0, nn, out);
                }
            }
        }
        Ok(())
    }
}

impl Reader {
    /// Reads time bins `n0..n0 + nn` of rows `first..first + rows` of a contiguous `H` at
    /// `address` into `stage[(k·rows + r)·Ks + s]`: one read per bin, or one for all of them
    /// when the rows are every row.
    fn read_group(
        &mut self,
        address: u64,
        first: usize,
        rows: usize,
        n0: usize,
        nn: usize,
    ) -> Result<()> {
        let plan = &self.plan;
        let (ks, kl) = (plan.ks, plan.kl);
        let run = rows * ks;
        let eb: u64 = if plan.elem == Elem::F32 { 4 } else { 8 };
        let io = |e| Error::io(&plan.path, e);
        if self.file.is_none() {
            self.file = Some((std::fs::File::open(&plan.path).map_err(io)?, 0));
        }
        let (file, pos) = self.file.as_mut().expect("opened above");
        self.stage.resize(nn * run, 0.0);
        let whole = rows == kl;
        let reads = if whole { 1 } else { nn };
        let len = if whole { nn * run } else { run };
        for k in 0..reads {
            let n = n0 + k;
            // Element (n, l, s) of the flattened (Nt, Kl, Ks) array.
            let offset = address + ((n * kl + first) * ks) as u64 * eb;
            if *pos != offset {
                file.seek(SeekFrom::Start(offset)).map_err(io)?;
            }
            let dst = &mut self.stage[k * run..k * run + len];
            match plan.elem {
                Elem::F32 => {
                    file.read_exact(bytemuck::cast_slice_mut(dst)).map_err(io)?;
                    if cfg!(target_endian = "big") {
                        dst.iter_mut()
                            .for_each(|x| *x = f32::from_bits(x.to_bits().swap_bytes()));
                    }
                }
                Elem::F64 => {
                    self.stage64.resize(len, 0.0);
                    file.read_exact(bytemuck::cast_slice_mut(&mut self.stage64))
                        .map_err(io)?;
                    dst.iter_mut().zip(&self.stage64).for_each(|(d, &x)| {
                        *d = f64::from_le_bytes(x.to_ne_bytes()) as f32;
                    });
                }
            }
            *pos = offset + len as u64 * eb;
        }
        Ok(())
    }
}

impl Plan {
    /// Reads rows `first..end` as one hyperslab through the crate, time-major: `v[(n·rows +
    /// r)·Ks + s]`.
    fn read_slice(&self, first: usize, end: usize) -> Result<Vec<f32>> {
        let span = |a: usize, b: usize| SliceInfoElem::Slice {
            start: a as u64,
            end: b as u64,
            step: 1,
        };
        let r = self.format.row_axes();
        let mut selections = vec![span(0, self.dims[0])];
        if r == 2 {
            let line = self.dims[2].max(1);
            if first.is_multiple_of(line)
                && (end.is_multiple_of(line) || end == self.kl)
                && end - first >= line
            {
                selections.push(span(first / line, end.div_ceil(line)));
                selections.push(span(0, line));
            } else {
                selections.push(SliceInfoElem::Index((first / line) as u64));
                selections.push(span(first % line, first % line + (end - first)));
            }
        } else {
            selections.push(span(first, end));
        }
        selections.extend(self.dims[1 + r..].iter().map(|&n| span(0, n)));
        let sel = SliceInfo { selections };
        let field = |e| h5_error(&self.path, "H", e);
        let v: Vec<f32> = match self.elem {
            Elem::F32 => into_vec(self.h.read_slice::<f32>(&sel).map_err(field)?),
            Elem::F64 => into_vec(self.h.read_slice::<f64>(&sel).map_err(field)?)
                .into_iter()
                .map(|x| x as f32)
                .collect(),
        };
        let want = self.dims[0] * (end - first) * self.ks;
        if v.len() != want {
            return Err(Error::format(
                &self.path,
                "H",
                format!("{want} values in laser rows {first}..{end}"),
                v.len(),
            ));
        }
        Ok(v)
    }
}

/// SPADs per tile of [`transpose`].
const TILE: usize = 16;

/// Time bins `n0..n0 + nn` of `rows` rows, time-major `src[(k·rows + r)·Ks + s]`, into
/// vltm's rows `out[r][s·Nt + n0 + k]`, in tiles of [`GROUP`] bins × [`TILE`] SPADs held in
/// registers and the stack: [`GROUP`] source runs read across, two cache lines written per
/// SPAD. A partial group (the last bins) or the SPADs past the last whole tile go one value
/// at a time.
fn transpose(
    src: &[f32],
    rows: usize,
    ks: usize,
    nt: usize,
    n0: usize,
    nn: usize,
    out: &mut [&mut [f32]],
) {
    for (r, dst) in out.iter_mut().enumerate().take(rows) {
        let runs: [&[f32]; GROUP] = std::array::from_fn(|k| {
            let k = k.min(nn - 1);
            &src[(k * rows + r) * ks..(k * rows + r + 1) * ks]
        });
        let tiled = if nn == GROUP { ks / TILE * TILE } else { 0 };
        for s0 in (0..tiled).step_by(TILE) {
            let tile: [[f32; TILE]; GROUP] = std::array::from_fn(|k| {
                let run = &runs[k][s0..s0 + TILE];
                std::array::from_fn(|j| run[j])
            });
            let spads = dst[s0 * nt..(s0 + TILE) * nt].chunks_exact_mut(nt);
            for (j, d) in spads.enumerate() {
                let column: [f32; GROUP] = std::array::from_fn(|k| tile[k][j]);
                d[n0..n0 + GROUP].copy_from_slice(&column);
            }
        }
        for s in tiled..ks {
            let d = &mut dst[s * nt + n0..s * nt + n0 + nn];
            for (k, x) in d.iter_mut().enumerate() {
                *x = runs[k][s];
            }
        }
    }
}

/// The background reader: a thread that reads the blocks in row order from a start block
/// and hands them over through a queue of [`QUEUE`] blocks, so that reading (and the
/// decompression of a chunked `H`) overlaps the probes' work on the rows already read. It
/// stops at the last row, at the first error (which it passes on) or when dropped.
pub(super) struct ReadAhead {
    /// The blocks, in row order.
    pub(super) rx: Receiver<Result<Block>>,
    /// Row buffers handed back for reuse.
    free: Sender<Vec<f32>>,
    /// First row of the next block the queue will deliver.
    pub(super) next: usize,
}

impl ReadAhead {
    /// Starts the reader at the block holding row `first`.
    pub(super) fn start<R: ReadBlocks>(mut reader: R, first: usize) -> Self {
        let (tx, rx) = sync_channel(QUEUE);
        let (free, free_rx) = channel::<Vec<f32>>();
        std::thread::spawn(move || {
            let len = reader.row_len();
            // A row buffer: a recycled one when there is one, else a new one.
            let buffer = || {
                while let Ok(mut v) = free_rx.try_recv() {
                    if v.capacity() >= len {
                        v.resize(len, 0.0);
                        return v;
                    }
                }
                vec![0.0; len]
            };
            let mut l = first;
            while l < reader.rows() {
                let (a, b) = reader.range(l);
                let mut block = Block {
                    first: a,
                    rows: (a..b).map(|_| Some(buffer())).collect(),
                };
                let mut out: Vec<&mut [f32]> = block
                    .rows
                    .iter_mut()
                    .map(|r| r.as_deref_mut().unwrap_or_default())
                    .collect();
                let read = reader.read(a, &mut out);
                drop(out);
                let failed = read.is_err();
                if tx.send(read.map(|()| block)).is_err() || failed {
                    return;
                }
                l = b;
            }
        });
        Self {
            rx,
            free,
            next: first,
        }
    }

    /// Hands a row buffer back to the reader for a later block.
    pub(super) fn recycle(&self, buffer: Vec<f32>) {
        if buffer.capacity() > 0 {
            // The reader may have stopped (last row, error): the buffer is then dropped.
            let _ = self.free.send(buffer);
        }
    }
}

/// A row source's end of a background reader: the block in hand and the [`ReadAhead`],
/// restarted when rows are not read in order.
#[derive(Default)]
pub(super) struct Cursor {
    /// The rows read last.
    block: Block,
    /// The background reader, once rows are read.
    ahead: Option<ReadAhead>,
}

impl Cursor {
    /// Swaps row `l` into `out` (no copy; the old buffer of `out` goes back to the reader).
    /// Its block, whose first row is `first`, comes from the queue when the rows are read in
    /// order, else from a reader made by `reader` and started at that block; a row read a
    /// second time is read again with its block. A stopped reader is an error naming `path`
    /// and `field`.
    pub(super) fn take<R: ReadBlocks>(
        &mut self,
        l: usize,
        first: usize,
        out: &mut Vec<f32>,
        reader: impl FnOnce() -> R,
        path: &Path,
        field: &str,
    ) -> Result<()> {
        if !self.block.holds(l) {
            // Free the previous block first (the queue holds at most one more).
            self.block = Block::default();
            if self.ahead.as_ref().is_none_or(|a| a.next != first) {
                self.ahead = None;
                self.ahead = Some(ReadAhead::start(reader(), first));
            }
            let ahead = self.ahead.as_mut().expect("started above");
            let block = ahead.rx.recv().unwrap_or_else(|_| {
                Err(Error::format(
                    path,
                    field,
                    "a readable dataset",
                    "the background reader stopped",
                ))
            });
            match block {
                Ok(b) => {
                    ahead.next = b.first + b.rows.len();
                    self.block = b;
                }
                Err(e) => {
                    self.ahead = None;
                    return Err(e);
                }
            }
        }
        let old = self.block.take(l, out).unwrap_or_default();
        if let Some(ahead) = &self.ahead {
            ahead.recycle(old);
        }
        Ok(())
    }
}
