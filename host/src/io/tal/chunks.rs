//! A chunked `H` read chunk by chunk without the crate's hyperslab reader (module docs of
//! [`io::tal`](super), *Reading*): the chunk index ([`ChunkMap::new`], walked once at open
//! through `hdf5_reader`'s public index collectors: version 1 B-tree, as h5py writes by
//! default, fixed and extensible arrays, version 2 B-tree, single chunk), the stored bytes
//! read with one positional read per chunk, inflated with libdeflate, unshuffled, and written
//! straight into vltm's SPAD-major rows of a **band** ([`ChunkMap::read_band`]): the rows whose
//! laser (first row axis) lies in one chunk along that axis, so that each chunk is read and
//! decoded once.
//!
//! Supported: little-endian `f32`/`f64` values, a filter pipeline of deflate and/or shuffle
//! (each at most once, in any order, honouring each chunk's filter mask), every chunk of the
//! dataset written. Anything else (other filters, fill-valued missing chunks, big-endian
//! values, the implicit index, a band larger than [`BAND_BYTES`], chunks larger than
//! [`BAND_BYTES`], more than [`MAX_CHUNKS`] chunks) returns `None` from [`ChunkMap::new`] and is
//! read through the crate as before.
//!
//! Units: values are `f32` histogram samples as stored (`f64` rounded to `f32`), bit-identical
//! to the crate's reading. Cost: one read, one inflate and one scatter per chunk, the band's
//! chunks split by time between [`ChunkMap::workers`] threads, as many as the thread pool
//! that opened the file has (`--threads`), at most one per time chunk: each inflates its own
//! time chunks and writes its own part of every row's time axis, so the rows are the same
//! bytes whatever the number of workers. Memory: the band being filled (at most [`BAND_BYTES`]), per worker one stored
//! chunk and two decoded-chunk buffers (each at most the chunk's size, itself at most
//! [`BAND_BYTES`]), and the index: 24 bytes per chunk (at most [`MAX_CHUNKS`]).
//!
//! Every index entry is checked before any read: chunk offsets on the chunk grid (entries
//! wholly past the extent are stale and skipped, as the crate does), no chunk twice, the
//! stored bytes inside the file and at most the chunk's size plus deflate's worst-case
//! overhead; a chunk that does not inflate to exactly its size is an [`Error::Format`] on `H`
//! naming the chunk.

use super::fields::{Elem, h5_error};
use super::format::HFormat;
use crate::error::{Error, Result};
use hdf5_reader::messages::HdfMessage;
use hdf5_reader::messages::filter_pipeline::{FILTER_DEFLATE, FILTER_SHUFFLE};
use hdf5_reader::messages::layout::{ChunkIndexing, DataLayout};
use hdf5_reader::{ByteOrder, Dataset, Datatype, Hdf5File};
use std::io::{Read, Seek, SeekFrom};
use std::path::Path;

/// Largest band of rows (`f32` bytes) and largest chunk decoded by this path.
pub const BAND_BYTES: usize = 64 << 20;

/// Most chunks indexed by this path (the index takes 24 bytes per chunk).
pub const MAX_CHUNKS: usize = 1 << 20;

/// A filter of the pipeline this path decodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Filter {
    Deflate,
    Shuffle,
}

/// Where one chunk's stored bytes are.
#[derive(Clone, Copy, Debug)]
struct Entry {
    address: u64,
    len: usize,
    mask: u32,
}

/// The chunk grid of a chunked `H` and where every chunk lies (module docs).
#[derive(Debug)]
pub(super) struct ChunkMap {
    /// `H`'s shape padded to `(Nt, A, B, C, D)`: rows `A·B` (`B` = 1 for one row axis),
    /// SPADs `C·D` (1 where absent).
    dims: [usize; 5],
    /// The chunk shape, padded the same way.
    chunk: [usize; 5],
    /// Chunks along each padded axis.
    grid: [usize; 5],
    /// Every chunk, in C order of `grid`.
    entries: Vec<Entry>,
    elem: Elem,
    /// The pipeline in the order it was applied when writing.
    filters: Vec<Filter>,
    /// Bytes of one decoded (whole, unclipped) chunk.
    chunk_bytes: usize,
    /// Threads decoding a band: the opening thread pool's size, at most one per time chunk.
    workers: usize,
}

impl ChunkMap {
    /// The chunk map of `h` (shape `dims`, `format`), or `None` when this path does not apply
    /// (module docs).
    ///
    /// # Errors
    /// [`Error::Format`] on `H` for an index that cannot be walked or entries that are
    /// misaligned, repeated or outside the file.
    pub(super) fn new(
        path: &Path,
        file: &Hdf5File,
        h: &Dataset,
        dims: &[usize],
        format: HFormat,
        elem: Elem,
        file_len: u64,
    ) -> Result<Option<Self>> {
        if cfg!(target_endian = "big")
            || !matches!(
                h.dtype(),
                Datatype::FloatingPoint {
                    byte_order: ByteOrder::LittleEndian,
                    ..
                }
            )
        {
            return Ok(None);
        }
        let header = file
            .get_or_parse_header(h.address())
            .map_err(|e| h5_error(path, "H", e))?;
        let (mut layout, mut pipeline) = (None, Vec::new());
        for m in &header.messages {
            match m {
                HdfMessage::DataLayout(m) => layout = Some(&m.layout),
                HdfMessage::FilterPipeline(p) => pipeline.extend(p.filters.iter().cloned()),
                _ => {}
            }
        }
        let Some(DataLayout::Chunked {
            address,
            chunk_indexing,
            ..
        }) = layout
        else {
            return Ok(None);
        };
        // The dataset's chunk shape (a trailing element-size entry of the layout dropped).
        let Some(cdims) = h.chunks() else {
            return Ok(None);
        };
        let cdims = &cdims[..];
        let rank = dims.len();
        if cdims.len() != rank || cdims.contains(&0) {
            return Ok(None);
        }
        let eb = if elem == Elem::F32 { 4 } else { 8 };
        let mut filters = Vec::new();
        for f in &pipeline {
            let filter = match f.id {
                FILTER_DEFLATE => Filter::Deflate,
                FILTER_SHUFFLE if f.client_data.first().is_none_or(|&s| s as usize == eb) => {
                    Filter::Shuffle
                }
                _ => return Ok(None),
            };
            if filters.contains(&filter) {
                return Ok(None);
            }
            filters.push(filter);
        }
        // Padded axes: time, the row axes (A, B) and the SPAD axes (C, D).
        let r = format.row_axes();
        let axis: Vec<usize> = (0..rank)
            .map(|i| match i {
                0 => 0,
                i if i <= r => i,
                i => 3 + (i - 1 - r),
            })
            .collect();
        let (mut pd, mut pc) = ([1usize; 5], [1usize; 5]);
        for (i, &a) in axis.iter().enumerate() {
            pd[a] = dims[i];
            pc[a] = cdims[i] as usize;
        }
        let chunk_elems = pc.iter().try_fold(1usize, |a, &c| a.checked_mul(c));
        let chunk_bytes = match chunk_elems.and_then(|n| n.checked_mul(eb)) {
            Some(b) if b <= BAND_BYTES => b,
            _ => return Ok(None),
        };
        let grid: [usize; 5] = std::array::from_fn(|a| pd[a].div_ceil(pc[a]));
        let total = grid.iter().try_fold(1usize, |a, &g| a.checked_mul(g));
        let band_bytes = [pc[1].min(pd[1]), pd[2], pd[3], pd[4], pd[0], 4]
            .iter()
            .try_fold(1usize, |a, &d| a.checked_mul(d));
        let total = match (total, band_bytes) {
            (Some(t), Some(b)) if t <= MAX_CHUNKS && b <= BAND_BYTES && t > 0 => t,
            _ => return Ok(None),
        };

        let storage = file.storage();
        let (os, ls) = (file.superblock().offset_size, file.superblock().length_size);
        let shape: Vec<u64> = dims.iter().map(|&d| d as u64).collect();
        use hdf5_reader::{btree_v1, chunk_index, extensible_array, fixed_array};
        let field = |e| h5_error(path, "H", e);
        let found = match chunk_indexing {
            None => btree_v1::collect_btree_v1_leaves_storage(
                storage,
                *address,
                os,
                ls,
                Some(rank as u32),
                cdims,
                None,
            )
            .map_err(field)?
            .into_iter()
            .map(|(key, address)| match key {
                btree_v1::BTreeV1Key::RawData {
                    chunk_size,
                    filter_mask,
                    offsets,
                } => Ok(chunk_index::ChunkEntry {
                    address,
                    size: u64::from(chunk_size),
                    filter_mask,
                    offsets,
                }),
                btree_v1::BTreeV1Key::Group { .. } => Err(Error::format(
                    path,
                    "H",
                    "a chunk index (B-tree of raw data chunks)",
                    "a B-tree of group entries",
                )),
            })
            .collect::<Result<Vec<_>>>()?,
            Some(ChunkIndexing::FixedArray { .. }) => {
                fixed_array::collect_fixed_array_chunk_entries_storage(
                    storage, *address, os, ls, &shape, cdims, None,
                )
                .map_err(field)?
            }
            Some(ChunkIndexing::ExtensibleArray { .. }) => {
                extensible_array::collect_extensible_array_chunk_entries_storage(
                    storage,
                    *address,
                    os,
                    ls,
                    &shape,
                    h.max_dims(),
                    cdims,
                    None,
                )
                .map_err(field)?
            }
            Some(ChunkIndexing::BTreeV2) => chunk_index::collect_v2_chunk_entries_storage(
                storage,
                *address,
                os,
                ls,
                rank as u32,
                cdims,
                None,
            )
            .map_err(field)?,
            Some(ChunkIndexing::SingleChunk {
                filtered_size,
                filters: mask,
            }) => {
                let size = if filters.is_empty() {
                    chunk_bytes as u64
                } else {
                    *filtered_size
                };
                vec![chunk_index::single_chunk_entry(*address, size, *mask, rank)]
            }
            Some(ChunkIndexing::Implicit) => return Ok(None),
        };

        let mut slots: Vec<Option<Entry>> = vec![None; total];
        // Deflate stores incompressible data in blocks of 65 535 bytes with 5 bytes of header
        // each, plus zlib's 6 bytes: no valid stream of a chunk is longer than this.
        let max_stored = chunk_bytes + chunk_bytes / 8192 + 1024;
        for e in found {
            let bad = |what: String| {
                Error::format(
                    path,
                    "H",
                    "a valid chunk index",
                    format!("chunk at {:?}: {what}", &e.offsets),
                )
            };
            if e.offsets.len() < rank {
                return Err(bad(format!("{} offsets for rank {rank}", e.offsets.len())));
            }
            let mut p = [0usize; 5];
            let mut stale = false;
            for (i, &a) in axis.iter().enumerate() {
                let o = usize::try_from(e.offsets[i]).unwrap_or(usize::MAX);
                if o % pc[a] != 0 {
                    return Err(bad(format!("not on the chunk grid {cdims:?}")));
                }
                stale |= o >= pd[a];
                p[a] = o / pc[a];
            }
            // Stale (wholly past the extent) or never written (read as fill values).
            if stale || e.address == u64::MAX >> (64 - 8 * u32::from(os.clamp(1, 8))) {
                continue;
            }
            let k = p.iter().zip(&grid).fold(0, |k, (&p, &g)| k * g + p);
            let filtered = filters
                .iter()
                .enumerate()
                .any(|(i, _)| e.filter_mask & (1 << i) == 0);
            let len = if filtered {
                usize::try_from(e.size).unwrap_or(usize::MAX)
            } else {
                chunk_bytes
            };
            if len == 0 || len > max_stored {
                return Err(bad(format!(
                    "{len} stored bytes for a chunk of {chunk_bytes} bytes"
                )));
            }
            if e.address < 48
                || e.address
                    .checked_add(len as u64)
                    .is_none_or(|x| x > file_len)
            {
                return Err(bad(format!(
                    "{len} bytes at address {:#x}: outside the file ({file_len} bytes)",
                    e.address
                )));
            }
            if slots[k].is_some() {
                return Err(bad("listed twice".to_string()));
            }
            slots[k] = Some(Entry {
                address: e.address,
                len,
                mask: e.filter_mask,
            });
        }
        // Missing chunks read as fill values: the crate's path handles them.
        let Some(entries) = slots.into_iter().collect::<Option<Vec<_>>>() else {
            return Ok(None);
        };
        Ok(Some(Self {
            dims: pd,
            chunk: pc,
            grid,
            entries,
            elem,
            filters,
            chunk_bytes,
            workers: rayon::current_num_threads().clamp(1, grid[0].max(1)),
        }))
    }

    /// Rows per band: one chunk along the first row axis, whole along the second.
    pub(super) fn band_rows(&self) -> usize {
        self.chunk[1].min(self.dims[1]) * self.dims[2]
    }

    /// Where each chunk's stored bytes lie, `(address, length)`, in C order of the grid.
    #[cfg(test)]
    pub(super) fn stored_spans(&self) -> Vec<(u64, usize)> {
        self.entries.iter().map(|e| (e.address, e.len)).collect()
    }

    /// Bytes of one decoded chunk.
    pub(super) fn chunk_bytes(&self) -> usize {
        self.chunk_bytes
    }

    /// Threads that decode a band ([`ChunkMap::read_band`]): the size of the thread pool that
    /// opened the file (the reader thread and `workers − 1` helpers), at most one per chunk
    /// along the time axis.
    pub(super) fn workers(&self) -> usize {
        self.workers
    }

    /// Fills `rows` (band `band`'s rows, each `Ks·Nt` values, SPAD-major) from its chunks,
    /// split by time between [`ChunkMap::workers`] threads.
    ///
    /// # Errors
    /// [`Error::Io`] if the file cannot be read, [`Error::Format`] on `H` for a chunk that
    /// does not decode to its size.
    pub(super) fn read_band(&self, path: &Path, band: usize, rows: &mut [Vec<f32>]) -> Result<()> {
        let [nt, _, _, c, d] = self.dims;
        let ks = c * d;
        let workers = self.workers.clamp(1, self.grid[0].max(1));
        // Worker w owns time chunks tc[w]..tc[w + 1], i.e. bins tc[w]·ct.., of every row.
        let tc: Vec<usize> = (0..=workers).map(|w| w * self.grid[0] / workers).collect();
        let cut: Vec<usize> = tc.iter().map(|&t| (t * self.chunk[0]).min(nt)).collect();
        let mut views: Vec<Vec<&mut [f32]>> = (0..workers).map(|_| Vec::new()).collect();
        for row in rows.iter_mut() {
            for mut spad in row.chunks_exact_mut(nt).take(ks) {
                for (w, view) in views.iter_mut().enumerate() {
                    let (mine, rest) = spad.split_at_mut(cut[w + 1] - cut[w]);
                    view.push(mine);
                    spad = rest;
                }
            }
        }
        std::thread::scope(|scope| {
            let mut views = views.into_iter().enumerate();
            let (w0, view0) = views.next().expect("at least one worker");
            let helpers: Vec<_> = views
                .map(|(w, view)| {
                    let (t0, t1, b0) = (tc[w], tc[w + 1], cut[w]);
                    scope.spawn(move || self.decode(path, band, t0..t1, b0, view))
                })
                .collect();
            let first = self.decode(path, band, tc[w0]..tc[w0 + 1], cut[w0], view0);
            helpers
                .into_iter()
                .map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
                .fold(first, Result::and)
        })
    }

    /// Decodes the chunks of band `band` with time-chunk index in `times` into `view`
    /// (`view[r·Ks + s]` holds bins `bin0..` of row `r`, SPAD `s`): for each chunk position
    /// off the time axis, runs of up to [`STAGE_BYTES`] of consecutive time chunks are decoded
    /// into a staging buffer and then written out, so that each (row, SPAD) receives one
    /// contiguous run of bins at a time.
    fn decode(
        &self,
        path: &Path,
        band: usize,
        times: std::ops::Range<usize>,
        bin0: usize,
        mut view: Vec<&mut [f32]>,
    ) -> Result<()> {
        let io = |e| Error::io(path, e);
        let mut file = std::fs::File::open(path).map_err(io)?;
        let mut buffers = Buffers {
            inflater: libdeflater::Decompressor::new(),
            stored: Vec::new(),
            mid: Vec::new(),
            wide: Vec::new(),
        };
        let words = self.chunk_bytes / 4;
        let elems = self.chunk.iter().product::<usize>();
        let run = (STAGE_BYTES / self.chunk_bytes).clamp(1, times.len().max(1));
        let mut stage = vec![0.0f32; run * words];
        let [_, _, gb, gc, gd] = self.grid;
        for gy in 0..gb {
            for gz in 0..gc {
                for gw in 0..gd {
                    for t0 in times.clone().step_by(run) {
                        let n = run.min(times.end - t0);
                        for j in 0..n {
                            let g = [t0 + j, band, gy, gz, gw];
                            let out = &mut stage[j * words..j * words + elems];
                            self.load(path, &mut file, &mut buffers, g, out)?;
                        }
                        let g = [t0, band, gy, gz, gw];
                        self.scatter(&stage, words, n, g, bin0, &mut view);
                    }
                }
            }
        }
        Ok(())
    }

    /// Reads chunk `g` (grid position) and decodes it into `out` (its values as `f32`).
    fn load(
        &self,
        path: &Path,
        file: &mut std::fs::File,
        buffers: &mut Buffers,
        g: [usize; 5],
        out: &mut [f32],
    ) -> Result<()> {
        let io = |e| Error::io(path, e);
        let k = g.iter().zip(&self.grid).fold(0, |k, (&p, &n)| k * n + p);
        let e = self.entries[k];
        let bad = |what: String| {
            let at: Vec<usize> = (0..5).map(|i| g[i] * self.chunk[i]).collect();
            Error::format(
                path,
                "H",
                format!("chunks that decode to {} bytes", self.chunk_bytes),
                format!(
                    "chunk at {at:?} (padded axes; {} bytes at {:#x}): {what}",
                    e.len, e.address
                ),
            )
        };
        let es = if self.elem == Elem::F32 { 4 } else { 8 };
        // The pipeline undone: last filter first, skipping those the chunk's mask skips.
        let ops: Vec<Filter> = (0..self.filters.len())
            .rev()
            .filter(|&i| e.mask & (1 << i) == 0)
            .map(|i| self.filters[i])
            .collect();
        let Buffers {
            inflater,
            stored,
            mid,
            wide,
        } = buffers;
        let cb = self.chunk_bytes;
        let fin: &mut [u8] = match self.elem {
            Elem::F32 => bytemuck::cast_slice_mut(out),
            Elem::F64 => {
                wide.resize(cb, 0);
                wide
            }
        };
        file.seek(SeekFrom::Start(e.address)).map_err(io)?;
        if ops.is_empty() {
            file.read_exact(fin).map_err(io)?;
        } else {
            stored.resize(e.len, 0);
            file.read_exact(stored).map_err(io)?;
            let mut apply = |op: Filter, input: &[u8], output: &mut [u8]| match op {
                Filter::Deflate => match inflater.zlib_decompress(input, output) {
                    Ok(n) if n == output.len() => Ok(()),
                    Ok(n) => Err(bad(format!("inflates to {n} bytes"))),
                    Err(err) => Err(bad(format!("deflate: {err}"))),
                },
                Filter::Shuffle if input.len() == output.len() => {
                    unshuffle(input, output, es);
                    Ok(())
                }
                Filter::Shuffle => Err(bad(format!("{} bytes to unshuffle", input.len()))),
            };
            if let [op] = ops[..] {
                apply(op, stored, fin)?;
            } else {
                mid.resize(cb, 0);
                apply(ops[0], stored, mid)?;
                apply(ops[1], mid, fin)?;
            }
        }
        if self.elem == Elem::F64 {
            for (x, w) in out.iter_mut().zip(wide.chunks_exact(8)) {
                *x = f64::from_le_bytes(w.try_into().expect("8 bytes")) as f32;
            }
        }
        Ok(())
    }

    /// Writes `n` decoded chunks consecutive in time (`stage[j·words..]`, the first at grid
    /// position `g`) into `view` (rows of the band, bins from `bin0`), clipped to the
    /// dataset's extent.
    fn scatter(
        &self,
        stage: &[f32],
        words: usize,
        n: usize,
        g: [usize; 5],
        bin0: usize,
        view: &mut [&mut [f32]],
    ) {
        // Chunk C order: element (k, a, b, c, d) at (((k·C1 + a)·C2 + b)·C3 + c)·C4 + d.
        let [ct, c1, c2, c3, c4] = self.chunk;
        let [nt, _, b_len, _, d_len] = self.dims;
        let o: [usize; 5] = std::array::from_fn(|i| g[i] * self.chunk[i]);
        let ext: [usize; 5] = std::array::from_fn(|i| self.chunk[i].min(self.dims[i] - o[i]));
        let ks = self.dims[3] * d_len;
        let stride = c1 * c2 * c3 * c4;
        let band_a0 = g[1] * c1;
        let e4 = ext[4];
        // Bins of chunk j: from (o[0] + j·ct) − bin0, as many as lie before Nt.
        let bins = |j: usize| (o[0] + j * ct - bin0, ct.min(nt - (o[0] + j * ct)));
        for a in 0..ext[1] {
            for b in 0..ext[2] {
                let row = (o[1] + a - band_a0) * b_len + o[2] + b;
                for c in 0..ext[3] {
                    let s0 = (o[3] + c) * d_len + o[4];
                    let base = ((a * c2 + b) * c3 + c) * c4;
                    let dsts = &mut view[row * ks + s0..row * ks + s0 + e4];
                    // Tiles of TILE_T bins × TILE_S SPADs through registers, chunk after chunk
                    // along time for the same SPADs; the rest one value at a time.
                    let whole = e4 / TILE_S * TILE_S;
                    for d0 in (0..whole).step_by(TILE_S) {
                        for j in 0..n {
                            let values = &stage[j * words..(j + 1) * words];
                            let (t0, et) = bins(j);
                            for k0 in (0..et).step_by(TILE_T) {
                                let kk = TILE_T.min(et - k0);
                                if kk < TILE_T {
                                    for (d, dst) in dsts[d0..d0 + TILE_S].iter_mut().enumerate() {
                                        for k in 0..kk {
                                            dst[t0 + k0 + k] =
                                                values[base + d0 + d + (k0 + k) * stride];
                                        }
                                    }
                                    continue;
                                }
                                let tile: [[f32; TILE_S]; TILE_T] = std::array::from_fn(|k| {
                                    let i = base + (k0 + k) * stride + d0;
                                    let run = &values[i..i + TILE_S];
                                    std::array::from_fn(|j| run[j])
                                });
                                for (j, dst) in dsts[d0..d0 + TILE_S].iter_mut().enumerate() {
                                    let column: [f32; TILE_T] = std::array::from_fn(|k| tile[k][j]);
                                    dst[t0 + k0..t0 + k0 + TILE_T].copy_from_slice(&column);
                                }
                            }
                        }
                    }
                    for (d, dst) in dsts.iter_mut().enumerate().skip(whole) {
                        for j in 0..n {
                            let values = &stage[j * words..(j + 1) * words];
                            let (t0, et) = bins(j);
                            for (k, x) in dst[t0..t0 + et].iter_mut().enumerate() {
                                *x = values[base + d + k * stride];
                            }
                        }
                    }
                }
            }
        }
    }
}

/// A worker's buffers: the inflater, one chunk's stored bytes, and a decoded chunk's bytes
/// between two filters (`mid`) or before an `f64` → `f32` conversion (`wide`).
struct Buffers {
    inflater: libdeflater::Decompressor,
    stored: Vec<u8>,
    mid: Vec<u8>,
    wide: Vec<u8>,
}

/// Decoded chunks staged per worker before they are written out (at least one chunk).
pub const STAGE_BYTES: usize = 1 << 20;

/// Bins per tile of [`ChunkMap::scatter`].
const TILE_T: usize = 16;

/// SPADs per tile of [`ChunkMap::scatter`].
const TILE_S: usize = 16;

/// HDF5's shuffle filter undone: byte `j` of element `i` is `input[j·n + i]` (`n` whole
/// elements of `es` bytes); trailing bytes are copied as they are.
fn unshuffle(input: &[u8], output: &mut [u8], es: usize) {
    let n = input.len() / es;
    for j in 0..es {
        let plane = &input[j * n..(j + 1) * n];
        for (i, &x) in plane.iter().enumerate() {
            output[i * es + j] = x;
        }
    }
    output[n * es..].copy_from_slice(&input[n * es..]);
}
