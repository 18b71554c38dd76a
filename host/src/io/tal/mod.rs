//! Reader of y-tal / mitransient `HDF5_TAL` captures (`tal render` output), streaming by laser
//! row. The Zaragoza Z-NLOS layout is read by [`znlos`], through the same geometry
//! (`tal/scan.rs` builds it from tal's fields); [`detect`] tells the two apart as y-tal does
//! (a root dataset `data` is Z-NLOS, `H` is `HDF5_TAL`), [`open_any`] and [`read_any`] open
//! either.
//!
//! # Reading
//!
//! [`open`] parses the metadata and returns a [`TalReader`], a [`RowSource`] that reads laser
//! rows on demand straight from the file, never all of `H`: for `T_Lx_Ly_Sx_Sy` the row of laser
//! `(ix, iy)` is the hyperslab `H[:, ix, iy, :, :]`, `Nt` strided runs of `Ks` values. Rows are
//! read in **blocks** of consecutive rows (`block`): whole laser lines `H[:, ix0..ix1, :, :, :]`
//! (as many as fit in [`BLOCK_BYTES`], 16 MiB), or, when one line is larger, at most
//! [`BLOCK_BYTES`] of one line (at least one row). A contiguous little-endian `H` (what tal
//! writes) is read with plain positional reads of the file, one per time bin of the block's
//! `B·Ks` values (one per 32 bins when a block holds every row): a 16×16 × 16×16 × 800
//! capture takes 16 blocks, 12 800 reads of 16 kB, instead of one 1 kB read per (row, bin).
//! A **chunked** `H` (compressed with deflate, optionally shuffled, little-endian floats,
//! every chunk written: what h5py writes with `compression="gzip"`) is decoded chunk by
//! chunk by `tal/chunks.rs`: its chunk index is walked once at open (version 1 B-tree, fixed
//! or extensible array, version 2 B-tree, single chunk, through `hdf5_reader`'s index
//! collectors) and every entry checked against the chunk grid and the file's length; the
//! reader then decodes one **band** at a time, the rows whose laser lies in one chunk along
//! the first row axis (each chunk read once, with one positional read, inflated with
//! libdeflate, unshuffled), on as many threads as the thread pool that opened the file has
//! (`--threads`; each owns its share of the time chunks, so the rows are the same bytes for
//! any number of threads), writing each
//! run of decoded chunks straight into the band's SPAD-major rows in tiles of 16 bins × 16
//! SPADs, and keeps the band while its blocks (cut as above, inside the band) are copied out
//! of it into the background reader's recycled row buffers. The exh16 copy with chunks of
//! (16, 4, 4, 16, 16) decodes 4 bands of 64 rows (52 MB each), 200 chunks each.
//! Anything else (other filters such as fletcher32 or szip, missing chunks read as fill
//! values, a band over 64 MiB, big-endian values, a compact layout) goes through the
//! pure-Rust [`hdf5_reader`] crate's `Dataset::read_slice`, one hyperslab per block (the
//! crate decompresses the overlapping chunks and keeps them in its chunk cache).
//! A **background reader** thread reads the blocks in row order, transposes each in memory to
//! vltm's SPAD-major rows `[r][s][n]` (in tiles of 32 time bins × 16 SPADs, staged in a
//! buffer that stays in cache), and hands them over through a bounded queue of one block, so
//! that reading, decompression and the transpose overlap the probes' work on the rows
//! already read. [`RowSource::read_row`] swaps the row into the caller's buffer (no copy) and
//! hands the caller's old buffer back to the reader for a later block. A row out of order, or
//! read a second time, restarts the reader at its block. For the one-histogram-per-point
//! formats (confocal, single) a row is a single value per time bin, so blocks are what keeps
//! the number of reads at `Nt` per block instead of `Nt` per row. The background reader is
//! generic over what it reads (`block::ReadBlocks`: the rows, their blocks, how a block is
//! read): [`znlos`] reads its blocks through the same thread, queue and recycled buffers.
//!
//! **Memory** is bounded whatever the size of `H`: at most three blocks (the one in use, one
//! queued, one being read and transposed: `3 ×` [`BLOCK_BYTES`] = 48 MiB, or three rows when
//! a row is larger) and a staging buffer of 32 time bins of the block; for a chunked `H`
//! decoded chunk by chunk, also the band its blocks are copied from (at most 64 MiB, reused
//! from band to band), plus per thread one stored chunk, a 1 MiB staging run of decoded chunks and two
//! decoded-chunk buffers, and the chunk index (24 bytes per chunk), all checked against the
//! memory budget at open; through the crate, its copy of the block being read and, for a
//! chunked `H`, its cache of decoded chunks (up to
//! 64 MiB). [`read_all`] reads every row into a [`Capture`] (needed by `--swap-roles` and by
//! [`io::open`](crate::io::open)). Peak resident set of `vltm column` on the exh16 capture
//! (210 MB of `f32`): see docs/performance.md, *Reading y-tal HDF5*; on the small captures of `fixtures/ytal`
//! (two_patches, 6.6 MB) a block holds the whole `H`.
//!
//! tal writes `H` contiguous and uncompressed (checked with h5py on every capture it rendered for `fixtures/ytal`); a
//! chunked `H` streams too. Reading times against the uncompressed `.npz` of the same
//! capture: docs/performance.md, *Reading y-tal HDF5*.
//!
//! # Fields
//!
//! | dataset | used as |
//! |---|---|
//! | `H` (f32 or f64, time axis **first**) | the histograms, laid out by `H_format` |
//! | `H_format` (tal `HFormat`, integer or enum) | 1 `T_Sx_Sy`, 2 `T_Lx_Ly_Sx_Sy`, 3 `T_Si`, 4 `T_Li_Si`; 0 `UNKNOWN` or any other value is an error, and so is an enum member name that disagrees with this numbering |
//! | `laser_grid_xyz`, `sensor_grid_xyz` | laser and SPAD spots: `(X, Y, 3)` flattened in C order (`l = ix·Y + iy`), or `(N, 3)` (shape `[N, 1]`) |
//! | `laser_grid_format`, `sensor_grid_format` | tal `GridFormat` 1 `N_3`, 2 `X_Y_3`, checked against the grid's rank (optional: the rank decides when absent) |
//! | `laser_xyz`, `sensor_xyz` | [`Geometry::laser_origin`], [`Geometry::sensor_origin`] (device positions: device legs, `--compensate-laser`) |
//! | `delta_t` | [`Geometry::dt`] (m of optical path; finite and > 0) |
//! | `t_start` | [`Geometry::t0`], see *Time axis* |
//! | `t_accounts_first_and_last_bounces` | [`Geometry::legs_in_time`] |
//! | `laser_grid_normals`, `sensor_grid_normals` (optional) | relay-surface normals at the spots, of their grid's format and shape (absent, or a null dataset as y-tal writes `None`: +z); checked (finite, non-zero length) and used by `--compensate-laser` and `--weights cos` |
//! | `volume_format`, `scene_info` | not used |
//!
//! Shapes: `T_Lx_Ly_Sx_Sy` is `(Nt, Lx, Ly, Sx, Sy)` with grids of `Lx·Ly` and `Sx·Sy` points
//! (an `X_Y_3` grid must be exactly `(Lx, Ly, 3)`, resp. `(Sx, Sy, 3)`); `T_Li_Si` is
//! `(Nt, Li, Si)`, the grid shapes come from the grids; `T_Sx_Sy` `(Nt, Sx, Sy)` and `T_Si`
//! `(Nt, Si)` hold one histogram per sensor point.
//!
//! # Scan types
//!
//! HDF5_TAL files do not store tal's `scan_type` as a dataset (only inside the `scene_info`
//! YAML, which is not parsed). It is inferred from `H_format` and the grids as tal's
//! `NLOSCaptureData.is_confocal()` does ([`ScanType`]):
//!
//! * `T_Lx_Ly_Sx_Sy`, `T_Li_Si`: **exhaustive**, Kl = the laser grid, Ks = the sensor grid.
//! * `T_Sx_Sy`, `T_Si` with `laser_grid_xyz` ≈ `sensor_grid_xyz` (numpy `allclose`):
//!   **confocal**, one histogram per row ([`Geometry::confocal`]).
//! * `T_Sx_Sy`, `T_Si` with one laser point `x0`: tal **`single`** (one laser spot, the SPAD grid
//!   scanned). By Helmholtz reciprocity (path reversal keeps the optical length and the
//!   geometry terms; all BSDFs are Lambertian) it is presented as **Kl = the sensor grid's
//!   points as lasers × one SPAD at `x0`** (the 2-D aperture must be the
//!   projector to focus), with the device positions swapped ([`Geometry::laser_origin`] =
//!   `sensor_xyz`, [`Geometry::sensor_origin`] = `laser_xyz`) so the device legs stay right.
//!   mitransient multiplies every path by the physical laser's falloff
//!   `c(x) = cos θ / |laser_xyz − x|²` at its spot `x0` and by nothing on the SPAD side, while a
//!   laser scan of the swapped setup would carry the falloff at each new laser spot. Row `l` is
//!   therefore `H[:, l] · c'(S_l) / c(x0)`, with `c'` the falloff from the swapped laser origin
//!   ([`Geometry::laser_falloff_at`] of the returned geometry; both falloffs take the spots'
//!   normals where the file has `*_grid_normals`, +z otherwise). Then
//!   `--compensate-laser` (÷ `c'(S_l)`) gives exactly y-tal's `compensate_laser_cos_dsqr` result
//!   `H / c(x0)` (`fixtures/ytal/single/README.md`; there `c(x0)` = 0.47982 m⁻²).
//! * `T_Sx_Sy`, `T_Si` with any other laser grid (a paired, non-confocal custom scan): not
//!   representable by [`Geometry`]; [`Error::Format`] on `laser_grid_xyz`.
//!
//! # Time axis
//!
//! mitransient's bin `k` accumulates paths with optical length in
//! `[t_start + k·Δt, t_start + (k+1)·Δt)` (a box filter); vltm's [`Geometry`] holds point
//! samples at `t0 + n·Δt`. [`TalOptions::bin_centre`] chooses:
//!
//! * `false` (**the default**, [`TalOptions::YTAL`]): `t0 = t_start`, the bin start, as y-tal's
//!   `pf_dev` reads these files (`fixtures/ytal/README.md`: "pf_dev treats bin k as OPL
//!   t_start + k·delta_t").
//! * `true` ([`TalOptions::BIN_CENTRE`]): `t0 = t_start + Δt/2`, the centre of the box, the rule
//!   for interval bins and the unbiased choice for the kernel's exact gates.
//!
//! The default follows y-tal because the reason to read these files is to compare with y-tal
//! and with the captures' published references, and a deliberate half-bin offset would show up
//! there. Comparing vltm's direct and column volumes with y-tal's `ref_direct.npy` /
//! `ref_ltmcol_focusA.npy` (y-tal's conventions otherwise: weights one, σ = λ, laser falloff
//! compensated; Pearson correlation of the max-normalised intensities), the bin start
//! gives Pearson 0.99993 (two_patches), 0.99989 (line), 0.99970 (single), 0.99998 (column) and
//! the same peak voxel everywhere; the bin centre gives 0.99973, 0.99954, 0.99881, 0.99993 and
//! moves the two_patches peak one slice deeper (z 0.65 → 0.70 m, both on patch A, which spans
//! z 0.60–0.80 m). For |·|² intensities a constant shift of every histogram only moves each
//! gate's envelope by Δt/2 (its carrier phase `e^{iΩΔt/2}` is common to all laser–SPAD pairs
//! and cancels), so the difference is small whenever σ ≫ Δt. A user who wants the physically
//! centred samples opens the file with [`TalOptions::BIN_CENTRE`] ([`open_with`],
//! [`read_all_with`]).
//!
//! # Errors and robustness
//!
//! Every problem is an [`Error::Format`] naming the file and the dataset (`(file)` when the HDF5
//! structure itself cannot be parsed): a missing dataset, wrong rank or shape, grids that do not
//! match `H`, non-numeric types, an unknown `H_format` or grid format, a non-finite or
//! non-positive `delta_t`, non-finite `t_start` or positions, a contiguous `H` larger than the
//! file, a layout of `H` that holds no data or points outside the file (size 0, an undefined
//! address or address 0, past the end, shorter than the shape; a chunked `H` without a chunk
//! index: read as fill values, it gave all-zero output), a chunk index whose entries are off
//! the chunk grid, repeated, or point outside the file, a chunk that does not inflate to its
//! size (named by its offsets and address), a row or capture over the memory
//! budget ([`crate::budget`]; every read through the crate is capped at it too), truncated or corrupt files (the crate's own message is kept). A file that cannot be
//! opened or read is [`Error::Io`].
//!
//! `hdf5_reader` bounds every offset and length it reads with checked arithmetic and reports
//! errors; it is not documented as panic-free, so this module was fuzzed (no `catch_unwind` is
//! used in it): [`read_all`] over 65 420 corrupt copies of `single.hdf5` (a truncation every
//! 97 bytes, each byte of the superblock/header region 0..2048 and of the metadata after `H`
//! flipped three ways, 3 000 random 4-byte corruptions of those regions) returned an error or
//! a capture every time, with no panic and no allocation beyond a 4 GB address-space limit;
//! the same over `line.hdf5` (73 962 copies): no panic either. The unit tests repeat a small
//! part of it.
//!
//! # Writing
//!
//! Not provided: `hdf5_reader` is read-only and vltm's outputs are `.npy` volumes. (The unit
//! tests build format variants with the pure-Rust writer `hdf5-pure`, a dev-dependency.)

use self::fields::*;
use crate::budget;
use crate::error::{Error, Result};
use crate::io::capture::{Capture, Geometry, RowSource, check_row};
use hdf5_reader::{ByteOrder, Dataset, Datatype, Hdf5File, OpenOptions};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use vltm_kernel::Point;

/// An open `HDF5_TAL` capture that reads laser rows on demand ([`RowSource`]).
pub struct TalReader {
    path: PathBuf,
    h: Dataset,
    elem: Elem,
    dims: Vec<usize>,
    format: HFormat,
    scan: ScanType,
    geometry: Geometry,
    options: TalOptions,
    /// `c(x0)` of a single scan (the physical laser's falloff at its one spot), else `None`.
    single_falloff: Option<f64>,
    /// File address of a contiguous little-endian `H`, read with positional reads; `None`
    /// reads through the crate.
    raw: Option<u64>,
    /// The chunk index of a chunked `H` decoded chunk by chunk; `None` reads through the
    /// crate (or positionally, `raw`).
    chunks: Option<Arc<ChunkMap>>,
    /// The rows read last and the background reader.
    rows: Cursor,
}

impl std::fmt::Debug for TalReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TalReader")
            .field("path", &self.path)
            .field("dims", &self.dims)
            .field("format", &self.format)
            .field("scan", &self.scan)
            .field("options", &self.options)
            .finish_non_exhaustive()
    }
}

/// Opens an `HDF5_TAL` capture for streaming, with the default [`TalOptions`].
///
/// # Errors
/// [`Error::Io`] if the file cannot be opened, [`Error::Format`] naming the dataset for anything
/// malformed (module docs, *Errors and robustness*).
pub fn open(path: &Path) -> Result<TalReader> {
    open_with(path, TalOptions::default())
}

/// Opens an `HDF5_TAL` capture for streaming.
///
/// # Errors
/// As [`open`].
pub fn open_with(path: &Path, options: TalOptions) -> Result<TalReader> {
    TalReader::new(path, options)
}

/// Reads a whole `HDF5_TAL` capture into memory, with the default [`TalOptions`].
///
/// # Errors
/// As [`open`], plus read errors of any row.
pub fn read_all(path: &Path) -> Result<Capture> {
    read_all_with(path, TalOptions::default())
}

/// Reads a whole `HDF5_TAL` capture into memory, row by row (peak: the capture plus one row).
///
/// # Errors
/// As [`read_all`].
pub fn read_all_with(path: &Path, options: TalOptions) -> Result<Capture> {
    open_with(path, options)?.into_capture()
}

/// Reads every row of an HDF5 capture's reader into a [`Capture`] (peak: the capture plus
/// one row), its size checked against the memory budget first (`scratch` bytes per sample on
/// top of the f32 result): the one `into_capture` of both layouts.
///
/// # Errors
/// [`Error::Memory`](crate::Error) over the budget; [`Error::Format`] on `dataset` (of shape
/// `dims`) if the capture does not fit in memory; read errors.
pub(crate) fn read_whole(
    src: &mut dyn RowSource,
    path: &Path,
    dataset: &str,
    dims: &[usize],
    scratch: u128,
) -> Result<Capture> {
    let g = src.geometry().clone();
    let row_len = g.spads_per_row() * g.nt;
    let total = g.lasers.len().checked_mul(row_len);
    budget::check(
        || {
            format!(
                "{dataset} of {} samples in {}",
                budget::count(total.map_or(u128::MAX, |n| n as u128)),
                path.display()
            )
        },
        budget::bytes(total.unwrap_or(usize::MAX), 4 + scratch),
    )?;
    let mut data: Vec<f32> = Vec::new();
    if total.is_none_or(|n| data.try_reserve_exact(n).is_err()) {
        return Err(Error::format(
            path,
            dataset,
            "a capture that fits in memory",
            format!("shape {dims:?}"),
        ));
    }
    let mut row = Vec::with_capacity(row_len);
    for l in 0..g.lasers.len() {
        src.read_row(l, &mut row)?;
        data.extend_from_slice(&row);
    }
    Capture::new(g, data, path)
}

/// The capture layouts of the HDF5 files vltm reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Hdf5Layout {
    /// y-tal / mitransient `HDF5_TAL` (dataset `H`): [`TalReader`].
    Tal,
    /// Zaragoza Z-NLOS (dataset `data`): [`znlos::ZnlosReader`].
    Znlos,
}

/// Which layout an HDF5 capture holds, decided as y-tal's `detect_dict_format` does: a root
/// dataset `data` is Z-NLOS, else `H` is `HDF5_TAL`.
///
/// # Errors
/// [`Error::Io`] if the file cannot be opened; [`Error::Format`] on `(layout)` listing the
/// root datasets when neither is there, or on `(file)` when it is not HDF5.
pub fn detect(path: &Path) -> Result<Hdf5Layout> {
    let (_, names) = open_file(path)?;
    if names.iter().any(|n| n == "data") {
        Ok(Hdf5Layout::Znlos)
    } else if names.iter().any(|n| n == "H") {
        Ok(Hdf5Layout::Tal)
    } else {
        Err(Error::format(
            path,
            "(layout)",
            "a y-tal HDF5_TAL capture (dataset H) or a Z-NLOS capture (dataset data)",
            format!(
                "root datasets: {}",
                if names.is_empty() {
                    "none".to_string()
                } else {
                    names.join(", ")
                }
            ),
        ))
    }
}

/// Opens an HDF5 capture of either layout ([`detect`]) as a row source, streamed by row.
///
/// # Errors
/// As [`detect`], [`open`] and [`znlos::open`].
pub fn open_any(path: &Path) -> Result<Box<dyn RowSource>> {
    Ok(match detect(path)? {
        Hdf5Layout::Tal => Box::new(open(path)?),
        Hdf5Layout::Znlos => Box::new(znlos::open(path)?),
    })
}

/// Reads an HDF5 capture of either layout ([`detect`]) whole.
///
/// # Errors
/// As [`open_any`].
pub fn read_any(path: &Path) -> Result<Capture> {
    match detect(path)? {
        Hdf5Layout::Tal => read_all(path),
        Hdf5Layout::Znlos => znlos::read_all(path),
    }
}

/// A grid-shaped dataset the file may lack (`laser_grid_normals`): `None` when absent or
/// stored as a null dataset (y-tal's `write_capture` of a field that is `None`).
fn optional_grid(f: &Fields<'_>, name: &'static str, format_name: &str) -> Result<Option<Grid>> {
    if f.has(name) && !f.is_null(name) {
        f.grid(name, format_name).map(Some)
    } else {
        Ok(None)
    }
}

/// Opens an HDF5 capture and lists its root datasets. No single read of the file may exceed
/// the memory budget (grids, blocks: the crate refuses it before allocating).
///
/// # Errors
/// [`Error::Format`] on `(file)` when it is not HDF5 (or cannot be read), on `(root group)`
/// when its root group cannot be listed.
fn open_file(path: &Path) -> Result<(Hdf5File, Vec<String>)> {
    let limit = usize::try_from(budget::get()).unwrap_or(usize::MAX);
    let file = Hdf5File::open_with_options(path, OpenOptions::default().with_max_read_bytes(limit))
        .map_err(|e| h5_error(path, "(file)", e))?;
    let names = file
        .root_group()
        .and_then(|g| g.member_names())
        .map_err(|e| h5_error(path, "(root group)", e))?
        .1;
    Ok((file, names))
}

impl TalReader {
    fn new(path: &Path, options: TalOptions) -> Result<Self> {
        let (file, names) = open_file(path)?;
        let f = Fields {
            path,
            file: &file,
            names: &names,
            kind: "HDF5_TAL",
        };

        // H: format, rank, element type, size.
        let h = f.dataset("H")?;
        let (fmt_value, fmt_name) = f.enum_scalar("H_format")?;
        let format = HFormat::from_tal(fmt_value).ok_or_else(|| {
            Error::format(
                path,
                "H_format",
                "a tal HFormat: 1 T_Sx_Sy, 2 T_Lx_Ly_Sx_Sy, 3 T_Si or 4 T_Li_Si",
                fmt_value,
            )
        })?;
        if let Some(name) = fmt_name.filter(|n| n != format.tal_name()) {
            return Err(Error::format(
                path,
                "H_format",
                format!("tal's numbering ({fmt_value} = {})", format.tal_name()),
                format!("{fmt_value} named {name}"),
            ));
        }
        let dims: Vec<usize> = h.shape().iter().map(|&d| usize_of(d)).collect();
        if dims.len() != format.rank() {
            return Err(Error::format(
                path,
                "H",
                format!("rank {} for H_format {}", format.rank(), format.tal_name()),
                format!("shape {dims:?}"),
            ));
        }
        let elem = Elem::of(&h, path, "H")?;
        let elem_bytes: usize = if elem == Elem::F32 { 4 } else { 8 };
        let h_bytes = dims.iter().try_fold(elem_bytes, |a, &d| a.checked_mul(d));
        let file_len = std::fs::metadata(path)
            .map_err(|e| Error::io(path, e))?
            .len();
        // A contiguous (or compact) H lies inside the file: refuse a declared size that cannot,
        // before any buffer is sized from it. Chunked data may be compressed; its chunks are
        // bounded by the crate's per-chunk limit.
        if h.chunks().is_none() && h_bytes.is_none_or(|b| b as u64 > file_len) {
            return Err(Error::format(
                path,
                "H",
                format!("at most {file_len} bytes of data (the file's size)"),
                format!("shape {dims:?} of {elem_bytes}-byte values"),
            ));
        }
        let contiguous = check_layout(path, &file, &h, h_bytes, file_len)?;
        // Positional reads of a contiguous little-endian H (module docs, *Reading*); anything
        // else goes through the crate.
        let raw = match h.dtype() {
            Datatype::FloatingPoint {
                byte_order: ByteOrder::LittleEndian,
                ..
            } => contiguous,
            _ => None,
        };
        let chunks = match raw {
            Some(_) => None,
            None => ChunkMap::new(path, &file, &h, &dims, format, elem, file_len)?.map(Arc::new),
        };
        let nt = dims[0];
        let lead = &dims[1..];

        // Grids, devices, time axis.
        let lgrid = f.grid("laser_grid_xyz", "laser_grid_format")?;
        let sgrid = f.grid("sensor_grid_xyz", "sensor_grid_format")?;
        let laser_xyz = f.xyz("laser_xyz")?;
        let sensor_xyz = f.xyz("sensor_xyz")?;
        let dt = f.float_scalar("delta_t")?;
        let t_start = f.float_scalar("t_start")?;
        let legs_in_time = f.enum_scalar("t_accounts_first_and_last_bounces")?.0 != 0;

        let scan::Scan {
            scan,
            geometry,
            single_falloff,
        } = scan::build(
            path,
            scan::Meta {
                format,
                lead: lead.to_vec(),
                nt,
                lgrid,
                sgrid,
                laser_xyz,
                sensor_xyz,
                dt,
                t_start,
                legs_in_time,
                xyz_names: ["laser_xyz", "sensor_xyz"],
                normals: [
                    optional_grid(&f, "laser_grid_normals", "laser_grid_format")?,
                    optional_grid(&f, "sensor_grid_normals", "sensor_grid_format")?,
                ],
            },
            options,
        )?;
        // A block of rows, the crate's raw copy of it and the row handed out.
        let row = geometry.spads_per_row().saturating_mul(nt);
        budget::check(
            || {
                format!(
                    "a laser row of H ({} samples) read from {}",
                    budget::count(row as u128),
                    path.display()
                )
            },
            budget::bytes(row, 8 + 2 * elem_bytes as u128).max(BLOCK_BYTES as u128 * 3),
        )?;
        // A band of chunks being decoded, three blocks copied out of it (in use, queued,
        // being filled), and each worker's stored and decoded chunks.
        if let Some(c) = &chunks {
            let band = c.band_rows() as u128 * row as u128 * 4;
            let need =
                band + 3 * BLOCK_BYTES as u128 + 4 * c.workers() as u128 * c.chunk_bytes() as u128;
            budget::check(
                || {
                    format!(
                        "a band of chunks of H ({band} bytes) read from {}",
                        path.display()
                    )
                },
                need,
            )?;
        }

        Ok(Self {
            path: path.to_path_buf(),
            h,
            elem,
            dims,
            format,
            scan,
            geometry,
            options,
            single_falloff,
            raw,
            chunks,
            rows: Cursor::default(),
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// tal's `H_format` of the file.
    pub fn h_format(&self) -> HFormat {
        self.format
    }

    /// The scan type inferred from `H_format` and the grids.
    pub fn scan_type(&self) -> ScanType {
        self.scan
    }

    /// The shape of `H` as stored (time first).
    pub fn h_shape(&self) -> &[usize] {
        &self.dims
    }

    /// The options the file was opened with.
    pub fn options(&self) -> TalOptions {
        self.options
    }

    /// Reads every row into a [`Capture`] (peak memory: the capture plus one row).
    ///
    /// # Errors
    /// Read errors of any row; [`Error::Format`] if the capture does not fit in memory.
    pub fn into_capture(mut self) -> Result<Capture> {
        let (path, dims) = (self.path.clone(), self.dims.clone());
        read_whole(&mut self, &path, "H", &dims, 8)
    }

    /// The block of consecutive rows holding row `l`: `first..end` (module docs, *Reading*).
    fn block_range(&self, l: usize) -> (usize, usize) {
        let band = self.chunks.as_ref().map(|c| c.band_rows());
        block_range(
            &self.dims,
            self.format,
            self.geometry.spads_per_row(),
            band,
            l,
        )
    }

    /// What the background reader needs.
    fn plan(&self) -> Plan {
        Plan {
            path: self.path.clone(),
            h: self.h.clone(),
            elem: self.elem,
            dims: self.dims.clone(),
            format: self.format,
            ks: self.geometry.spads_per_row(),
            kl: self.geometry.lasers.len(),
            raw: self.raw,
            chunks: self.chunks.clone(),
        }
    }
}

/// Checks where `H`'s data lies: a contiguous layout must lie inside the file and hold at
/// least `h_bytes` (a size of 0 or an undefined address means the data was never written,
/// which the reader would silently return as fill values); a compact one must hold
/// `h_bytes`; a chunked one must have its chunk index written.
fn check_layout(
    path: &Path,
    file: &Hdf5File,
    h: &Dataset,
    h_bytes: Option<usize>,
    file_len: u64,
) -> Result<Option<u64>> {
    use hdf5_reader::messages::{HdfMessage, layout::DataLayout};
    let header = file
        .get_or_parse_header(h.address())
        .map_err(|e| h5_error(path, "H", e))?;
    let os = u32::from(file.superblock().offset_size.clamp(1, 8));
    let undefined = |a: u64| a == u64::MAX >> (64 - 8 * os);
    let bad = |expected: &str, found: String| Error::format(path, "H", expected, found);
    let need = h_bytes.map_or(u64::MAX, |b| b as u64);
    let mut contiguous = None;
    for m in &header.messages {
        let HdfMessage::DataLayout(m) = m else {
            continue;
        };
        match &m.layout {
            DataLayout::Contiguous { address, size } => {
                if undefined(*address) || *size == 0 {
                    return Err(bad(
                        "a data layout that holds the values",
                        format!(
                            "a contiguous layout at address {address:#x} of {size} bytes: no data was written"
                        ),
                    ));
                }
                // The superblock is at address 0 (at least 48 bytes): data never starts there.
                if *address < 48 || address.checked_add(*size).is_none_or(|end| end > file_len) {
                    return Err(bad(
                        &format!("data inside the file ({file_len} bytes)"),
                        format!("{size} bytes at address {address:#x}: outside the file"),
                    ));
                }
                if *size < need {
                    return Err(bad(
                        &format!("{need} bytes of data for its shape"),
                        format!("a contiguous layout of {size} bytes"),
                    ));
                }
                contiguous = Some(*address);
            }
            DataLayout::Compact { data } if (data.len() as u64) < need => {
                return Err(bad(
                    &format!("{need} bytes of data for its shape"),
                    format!("a compact layout of {} bytes", data.len()),
                ));
            }
            DataLayout::Chunked { address, .. } if undefined(*address) => {
                return Err(bad(
                    "written chunks",
                    "a chunked layout with no chunk written (no data)".to_string(),
                ));
            }
            DataLayout::Chunked { address, .. } if *address >= file_len => {
                return Err(bad(
                    &format!("a chunk index inside the file ({file_len} bytes)"),
                    format!("address {address:#x}: outside the file"),
                ));
            }
            _ => {}
        }
    }
    Ok(contiguous)
}

impl RowSource for TalReader {
    fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        check_row(l, self.geometry.lasers.len())?;
        // The background reader transposed the block to rows of SPAD-major histograms: the
        // row is swapped into `out`, whose old buffer goes back to the reader.
        let (first, _) = self.block_range(l);
        // The plan (clones of the dataset handle and shape) is made only when a reader starts.
        let mut rows = std::mem::take(&mut self.rows);
        let taken = rows.take(l, first, out, || Reader::new(self.plan()), &self.path, "H");
        self.rows = rows;
        taken?;
        let x_l = self.geometry.lasers[l];
        if let Some(c0) = self.single_falloff {
            let k = self.geometry.laser_falloff_at(l) / c0;
            out.iter_mut().for_each(|h| *h = (f64::from(*h) * k) as f32);
        }
        Ok(x_l)
    }

    /// A chunked `H` decoded chunk by chunk is inflated on the opening pool's threads
    /// (`ChunkMap::workers` of them); a contiguous `H` or one read through the crate is read by one
    /// thread.
    fn reads_in_parallel(&self) -> bool {
        self.chunks.is_some()
    }
}

mod block;
mod chunks;
mod fields;
mod format;
mod scan;
pub mod znlos;

pub use block::BLOCK_BYTES;
use block::{Cursor, Plan, Reader, block_range};
use chunks::ChunkMap;

pub use format::{HFormat, ScanType, TalOptions};

#[cfg(test)]
mod tests;
