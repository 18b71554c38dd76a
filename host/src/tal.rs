//! Reader of y-tal / mitransient `HDF5_TAL` captures (`tal render` output), streaming by laser
//! row.
//!
//! # Reading
//!
//! [`open`] parses the metadata and returns a [`TalReader`], a [`RowSource`] that reads laser
//! rows on demand straight from the file, never all of `H`: for `T_Lx_Ly_Sx_Sy` the row of laser
//! `(ix, iy)` is the hyperslab `H[:, ix, iy, :, :]`, `Nt` strided runs of `Ks` values. Rows are
//! read a small block at a time, `H[:, ix, iy0..iy0+B, :, :]` with `B` consecutive rows of one
//! laser line such that the block holds at most [`BLOCK_BYTES`] (256 KiB) or one row, through
//! the pure-Rust [`hdf5_reader`] crate's `Dataset::read_slice` (for a contiguous dataset: one
//! positional read per time bin of exactly the `B·Ks` values; for a chunked one: the
//! overlapping chunks). The block is cached, so rows of the same block cost no I/O, and each
//! row is transposed to vltm's SPAD-major order `[s][n]`. For the one-histogram-per-point
//! formats (confocal, single) a row is a single value per time bin, so blocks are what keeps
//! the number of reads at `Nt` per laser line instead of `Nt` per row. Memory is
//! O(max(Ks·Nt, [`BLOCK_BYTES`])) whatever the size of `H`. [`read_all`] reads every row into a
//! [`Capture`] (needed by `--swap-roles` and by [`capture::open`](crate::capture::open)).
//!
//! **Peak memory**, measured with a counting global allocator around streaming every row (the
//! reader, its metadata, the block, the crate's raw copy of the block during a read, one row):
//! `two_patches` (the largest shared capture, H = 400×8×8×8×8 f32 = 6.6 MB; 64 rows of
//! 102 kB, blocks of 2 rows) **0.58 MB** of heap, 3.3 MB maximum resident set of the whole
//! process (`/usr/bin/time`); `line` 0.55 MB; `single` 0.11 MB. [`read_all`] of `two_patches`
//! peaks at 7.1 MB of heap (the 6.55 MB capture plus a block). Streaming `two_patches` takes
//! 10–30 ms. tal writes `H` contiguous and uncompressed (checked with h5py on every shared
//! capture); a chunked `H` streams too, but the crate keeps up to 64 MiB of decoded chunks in its
//! cache.
//!
//! # Fields
//!
//! | dataset | used as |
//! |---|---|
//! | `H` (f32 or f64, time axis **first**) | the histograms, laid out by `H_format` |
//! | `H_format` (tal `HFormat`, integer or enum) | 1 `T_Sx_Sy`, 2 `T_Lx_Ly_Sx_Sy`, 3 `T_Si`, 4 `T_Li_Si`; 0 `UNKNOWN` or any other value is an error, and so is an enum member name that disagrees with this numbering |
//! | `laser_grid_xyz`, `sensor_grid_xyz` | laser and SPAD spots: `(X, Y, 3)` flattened in C order (`l = ix·Y + iy`, DESIGN §B.0), or `(N, 3)` (shape `[N, 1]`) |
//! | `laser_grid_format`, `sensor_grid_format` | tal `GridFormat` 1 `N_3`, 2 `X_Y_3`, checked against the grid's rank (optional: the rank decides when absent) |
//! | `laser_xyz`, `sensor_xyz` | [`Geometry::laser_origin`], [`Geometry::sensor_origin`] (device positions: device legs, `--compensate-laser`) |
//! | `delta_t` | [`Geometry::dt`] (m of optical path; finite and > 0) |
//! | `t_start` | [`Geometry::t0`], see *Time axis* |
//! | `t_accounts_first_and_last_bounces` | [`Geometry::legs_in_time`] |
//! | `*_grid_normals`, `volume_format`, `scene_info` | not used (the wall is z = 0 with normal +z, DESIGN §B.0) |
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
//!   points as lasers × one SPAD at `x0`** (DESIGN §B.3.7: the 2-D aperture must be the
//!   projector to focus), with the device positions swapped ([`Geometry::laser_origin`] =
//!   `sensor_xyz`, [`Geometry::sensor_origin`] = `laser_xyz`) so the device legs stay right.
//!   mitransient multiplies every path by the physical laser's falloff
//!   `c(x) = cos θ / |laser_xyz − x|²` at its spot `x0` and by nothing on the SPAD side, while a
//!   laser scan of the swapped setup would carry the falloff at each new laser spot. Row `l` is
//!   therefore `H[:, l] · c'(S_l) / c(x0)`, with `c'` the falloff from the swapped laser origin
//!   ([`laser_falloff`](crate::ltm::laser_falloff) of the returned geometry). Then
//!   `--compensate-laser` (÷ `c'(S_l)`) gives exactly y-tal's `compensate_laser_cos_dsqr` result
//!   `H / c(x0)` (`../shared/data/single/README.md`; there `c(x0)` = 0.47982 m⁻²).
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
//!   `pf_dev` reads these files (DESIGN §B.7; shared data README: "pf_dev treats bin k as OPL
//!   t_start + k·delta_t").
//! * `true` ([`TalOptions::BIN_CENTRE`]): `t0 = t_start + Δt/2`, the centre of the box, the rule
//!   of DESIGN §B.0 for interval bins and the unbiased choice for the kernel's exact gates.
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
//! file, truncated or corrupt files (the crate's own message is kept). A file that cannot be
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

use crate::capture::{Capture, Geometry, RowSource};
use crate::error::{Error, Result};
use hdf5_reader::error::Error as H5Error;
use hdf5_reader::{ByteOrder, Dataset, Datatype, Hdf5File, SliceInfo, SliceInfoElem};
use std::path::{Path, PathBuf};
use vltm_kernel::Point;

/// How to map a tal capture onto vltm's conventions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TalOptions {
    /// Put sample `n` at the centre of tal's bin `n` (`t0 = t_start + Δt/2`, DESIGN §B.0) instead
    /// of its start (`t0 = t_start`, y-tal's `pf_dev`, DESIGN §B.7). Default `false`; see the
    /// module docs, *Time axis*.
    pub bin_centre: bool,
}

impl TalOptions {
    /// y-tal's reading, bin `k` at `t_start + k·Δt` (the default).
    pub const YTAL: Self = Self { bin_centre: false };
    /// Box-filter centres, bin `k` at `t_start + (k + ½)·Δt`.
    pub const BIN_CENTRE: Self = Self { bin_centre: true };
}

impl Default for TalOptions {
    fn default() -> Self {
        Self::YTAL
    }
}

/// tal's `HFormat`: the axis order of `H` (time first in every format).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HFormat {
    /// `T_Sx_Sy` = 1: `(Nt, Sx, Sy)`, one histogram per sensor point (confocal or single).
    TSxSy,
    /// `T_Lx_Ly_Sx_Sy` = 2: `(Nt, Lx, Ly, Sx, Sy)`, exhaustive.
    TLxLySxSy,
    /// `T_Si` = 3: `(Nt, Si)`, one histogram per sensor point (confocal or single).
    TSi,
    /// `T_Li_Si` = 4: `(Nt, Li, Si)`, exhaustive over point lists.
    TLiSi,
}

impl HFormat {
    /// The format of tal's enum value `v` (`tal.enums.HFormat`), if known (0 is `UNKNOWN`).
    pub fn from_tal(v: i64) -> Option<Self> {
        match v {
            1 => Some(Self::TSxSy),
            2 => Some(Self::TLxLySxSy),
            3 => Some(Self::TSi),
            4 => Some(Self::TLiSi),
            _ => None,
        }
    }

    /// tal's enum value of the format.
    pub fn tal_value(self) -> i64 {
        match self {
            Self::TSxSy => 1,
            Self::TLxLySxSy => 2,
            Self::TSi => 3,
            Self::TLiSi => 4,
        }
    }

    /// tal's name of the format (`T_Lx_Ly_Sx_Sy`, ...).
    pub fn tal_name(self) -> &'static str {
        match self {
            Self::TSxSy => "T_Sx_Sy",
            Self::TLxLySxSy => "T_Lx_Ly_Sx_Sy",
            Self::TSi => "T_Si",
            Self::TLiSi => "T_Li_Si",
        }
    }

    /// Rank of `H` in this format.
    pub fn rank(self) -> usize {
        match self {
            Self::TLxLySxSy => 5,
            Self::TSxSy | Self::TLiSi => 3,
            Self::TSi => 2,
        }
    }

    /// Number of `H` axes after time that index a row (the laser, or the sensor point of the
    /// one-histogram-per-point formats).
    fn row_axes(self) -> usize {
        match self {
            Self::TLxLySxSy | Self::TSxSy => 2,
            Self::TLiSi | Self::TSi => 1,
        }
    }
}

/// tal's `scan_type`, as inferred from `H_format` and the grids (module docs, *Scan types*).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScanType {
    /// Every laser spot × every SPAD spot.
    Exhaustive,
    /// One laser spot, the SPAD grid scanned; presented by reciprocity as the SPAD grid's spots
    /// as lasers × one SPAD at the laser spot.
    Single,
    /// The SPAD looks at the laser spot.
    Confocal,
}

/// Element type of `H`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Elem {
    F32,
    F64,
}

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
    /// The rows read last.
    block: Block,
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

impl TalReader {
    fn new(path: &Path, options: TalOptions) -> Result<Self> {
        let file = Hdf5File::open(path).map_err(|e| h5_error(path, "(file)", e))?;
        let names = file
            .root_group()
            .and_then(|g| g.member_names())
            .map_err(|e| h5_error(path, "(root group)", e))?
            .1;
        let f = Fields {
            path,
            file: &file,
            names: &names,
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
        let elem = match h.dtype() {
            Datatype::FloatingPoint { size: 4, .. } => Elem::F32,
            Datatype::FloatingPoint { size: 8, .. } => Elem::F64,
            other => {
                return Err(Error::format(
                    path,
                    "H",
                    "float32 or float64 values",
                    format!("{other:?}"),
                ));
            }
        };
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

        let (scan, lasers, laser_shape, spads, spad_shape) = match format {
            HFormat::TLxLySxSy => {
                let l = lgrid.fit(path, [lead[0], lead[1]])?;
                let s = sgrid.fit(path, [lead[2], lead[3]])?;
                (ScanType::Exhaustive, lgrid.points, l, sgrid.points, s)
            }
            HFormat::TLiSi => {
                let l = lgrid.count(path, lead[0])?;
                let s = sgrid.count(path, lead[1])?;
                (ScanType::Exhaustive, lgrid.points, l, sgrid.points, s)
            }
            HFormat::TSxSy | HFormat::TSi => {
                let s = if format == HFormat::TSxSy {
                    sgrid.fit(path, [lead[0], lead[1]])?
                } else {
                    sgrid.count(path, lead[0])?
                };
                if allclose(&sgrid.points, &lgrid.points) {
                    let pts = sgrid.points;
                    (ScanType::Confocal, pts.clone(), s, pts, s)
                } else if lgrid.points.len() == 1 {
                    (ScanType::Single, sgrid.points, s, lgrid.points, [1, 1])
                } else {
                    return Err(Error::format(
                        path,
                        "laser_grid_xyz",
                        format!(
                            "one point (tal scan_type single) or the sensor grid (confocal) for H_format {}",
                            format.tal_name()
                        ),
                        format!(
                            "{} points that differ from the sensor grid (a paired scan, not supported)",
                            lgrid.points.len()
                        ),
                    ));
                }
            }
        };
        let single = scan == ScanType::Single;
        let (laser_origin, sensor_origin) = if single {
            (sensor_xyz, laser_xyz)
        } else {
            (laser_xyz, sensor_xyz)
        };
        let geometry = Geometry {
            lasers,
            laser_shape,
            spads,
            spad_shape,
            laser_origin,
            sensor_origin,
            legs_in_time,
            confocal: scan == ScanType::Confocal,
            nt,
            dt,
            t0: if options.bin_centre {
                t_start + 0.5 * dt
            } else {
                t_start
            },
        };
        geometry.validate(path)?;

        let single_falloff = if single {
            let physical = Geometry {
                laser_origin: laser_xyz,
                ..geometry.clone()
            };
            let c0 = crate::ltm::laser_falloff(&physical, geometry.spads[0]);
            if !(c0.is_finite() && c0 > 0.0) {
                return Err(Error::format(
                    path,
                    "laser_xyz",
                    "a laser off the wall plane (the single-scan reciprocity factor divides by its cos θ / d²)",
                    format!("{laser_xyz:?}"),
                ));
            }
            let sensor_ok = geometry.lasers.iter().all(|&x| {
                let c = crate::ltm::laser_falloff(&geometry, x);
                c.is_finite() && c > 0.0
            });
            if !sensor_ok {
                return Err(Error::format(
                    path,
                    "sensor_xyz",
                    "a sensor off the wall plane (it is the laser of the reciprocal single scan)",
                    format!("{sensor_xyz:?}"),
                ));
            }
            Some(c0)
        } else {
            None
        };

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
            block: Block::default(),
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
        let g = self.geometry.clone();
        let row_len = g.spads_per_row() * g.nt;
        let mut data: Vec<f32> = Vec::new();
        let total = g.lasers.len().checked_mul(row_len);
        if total.is_none_or(|n| data.try_reserve_exact(n).is_err()) {
            return Err(Error::format(
                &self.path,
                "H",
                "a capture that fits in memory",
                format!("shape {:?}", self.dims),
            ));
        }
        let mut row = Vec::with_capacity(row_len);
        for l in 0..g.lasers.len() {
            self.read_row(l, &mut row)?;
            data.extend_from_slice(&row);
        }
        Capture::new(g, data, &self.path)
    }

    /// Rows per block: consecutive rows along the last row axis whose hyperslab is read at
    /// once, within [`BLOCK_BYTES`] (at least one row).
    fn block_len(&self) -> usize {
        let g = &self.geometry;
        let row_bytes = (g.spads_per_row() * g.nt * 4).max(1);
        let line = self.dims[self.format.row_axes()];
        (BLOCK_BYTES / row_bytes).clamp(1, line.max(1))
    }

    /// Reads the block holding row `l` into `self.block`: `H[:, ix, iy0..iy0+B, ...]` (or
    /// `H[:, l0..l0+B, ...]`), time-major.
    fn load_block(&mut self, l: usize) -> Result<()> {
        let all = |n: usize| SliceInfoElem::Slice {
            start: 0,
            end: n as u64,
            step: 1,
        };
        let span = |a: usize, b: usize| SliceInfoElem::Slice {
            start: a as u64,
            end: b as u64,
            step: 1,
        };
        let r = self.format.row_axes();
        let line = self.dims[r];
        let (ix, iy) = (l / line, l % line);
        let b = self.block_len();
        let y0 = iy / b * b;
        let y1 = (y0 + b).min(line);
        let mut selections = vec![all(self.dims[0])];
        if r == 2 {
            selections.push(SliceInfoElem::Index(ix as u64));
        }
        selections.push(span(y0, y1));
        selections.extend(self.dims[1 + r..].iter().map(|&n| all(n)));
        let sel = SliceInfo { selections };
        // Free the previous block first: the read holds the raw bytes and the decoded values.
        self.block = Block::default();
        let field = |e| h5_error(&self.path, "H", e);
        let v: Vec<f32> = match self.elem {
            Elem::F32 => into_vec(self.h.read_slice::<f32>(&sel).map_err(field)?),
            Elem::F64 => into_vec(self.h.read_slice::<f64>(&sel).map_err(field)?)
                .into_iter()
                .map(|x| x as f32)
                .collect(),
        };
        let want = self.geometry.nt * (y1 - y0) * self.geometry.spads_per_row();
        if v.len() != want {
            return Err(Error::format(
                &self.path,
                "H",
                format!(
                    "{want} values in laser rows {}..{}",
                    l - iy + y0,
                    l - iy + y1
                ),
                v.len(),
            ));
        }
        self.block = Block {
            first: l - iy + y0,
            rows: y1 - y0,
            data: v,
        };
        Ok(())
    }
}

/// Rows read from `H` at once (module docs, *Reading*): at most this many bytes, or one row.
pub const BLOCK_BYTES: usize = 1 << 18;

/// The cached hyperslab of consecutive rows `first..first + rows`, time-major:
/// `data[(n·rows + r)·Ks + s]`.
#[derive(Default)]
struct Block {
    first: usize,
    rows: usize,
    data: Vec<f32>,
}

impl RowSource for TalReader {
    fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        let kl = self.geometry.lasers.len();
        if l >= kl {
            return Err(Error::arg(
                "laser row",
                format!("{l} is out of range: the capture has {kl} rows"),
            ));
        }
        if !(self.block.first..self.block.first + self.block.rows).contains(&l) {
            self.load_block(l)?;
        }
        let (nt, ks) = (self.geometry.nt, self.geometry.spads_per_row());
        let (r, rows) = (l - self.block.first, self.block.rows);
        out.clear();
        out.resize(nt * ks, 0.0);
        // H is time-major: block[(n·rows + r)·Ks + s] → out[s·Nt + n].
        for (n, t) in self.block.data.chunks_exact(rows * ks).enumerate() {
            for (s, &x) in t[r * ks..(r + 1) * ks].iter().enumerate() {
                out[s * nt + n] = x;
            }
        }
        let x_l = self.geometry.lasers[l];
        if let Some(c0) = self.single_falloff {
            let k = crate::ltm::laser_falloff(&self.geometry, x_l) / c0;
            out.iter_mut().for_each(|h| *h = (f64::from(*h) * k) as f32);
        }
        Ok(x_l)
    }
}

/// The elements of an array in logical (C) order.
fn into_vec<T: Clone>(a: ndarray::ArrayD<T>) -> Vec<T> {
    if a.is_standard_layout() {
        a.into_raw_vec_and_offset().0
    } else {
        a.iter().cloned().collect()
    }
}

fn usize_of(d: u64) -> usize {
    usize::try_from(d).unwrap_or(usize::MAX)
}

/// numpy's `allclose` (rtol 1e-5, atol 1e-8) of two point lists of the same length.
fn allclose(a: &[Point], b: &[Point]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(p, q)| {
            p.iter().zip(q).all(|(&x, &y)| {
                let (x, y) = (f64::from(x), f64::from(y));
                (x - y).abs() <= 1e-8 + 1e-5 * y.abs()
            })
        })
}

/// Wraps an `hdf5_reader` error: I/O stays I/O, anything else is a format error of `field`.
fn h5_error(path: &Path, field: &str, e: H5Error) -> Error {
    match e {
        H5Error::Io(io) => Error::io(path, io),
        other => Error::format(path, field, "a readable HDF5_TAL field", other),
    }
}

/// A grid of points with its shape `[nx, ny]` (`[N, 1]` for an `N_3` list).
struct Grid {
    points: Vec<Point>,
    shape: [usize; 2],
    /// Stored as `(X, Y, 3)`.
    xy: bool,
    field: &'static str,
}

impl Grid {
    /// Checks the grid against `H`'s two axes `want` and returns them as the grid shape.
    fn fit(&self, path: &Path, want: [usize; 2]) -> Result<[usize; 2]> {
        let ok = if self.xy {
            self.shape == want
        } else {
            Some(self.points.len()) == want[0].checked_mul(want[1])
        };
        if !ok {
            let found = if self.xy {
                format!("shape ({}, {}, 3)", self.shape[0], self.shape[1])
            } else {
                format!("{} points", self.points.len())
            };
            return Err(Error::format(
                path,
                self.field,
                format!("a ({}, {}, 3) grid to match H", want[0], want[1]),
                found,
            ));
        }
        Ok(want)
    }

    /// Checks the grid holds `n` points (one `H` axis) and returns its own shape.
    fn count(&self, path: &Path, n: usize) -> Result<[usize; 2]> {
        if self.points.len() != n {
            return Err(Error::format(
                path,
                self.field,
                format!("{n} points to match H"),
                self.points.len(),
            ));
        }
        Ok(self.shape)
    }
}

/// Typed access to the root datasets of one file.
struct Fields<'a> {
    path: &'a Path,
    file: &'a Hdf5File,
    names: &'a [String],
}

impl Fields<'_> {
    fn has(&self, name: &str) -> bool {
        self.names.iter().any(|n| n == name)
    }

    fn dataset(&self, name: &str) -> Result<Dataset> {
        if !self.has(name) {
            return Err(Error::format(
                self.path,
                name,
                "a dataset of this name (HDF5_TAL)",
                "none",
            ));
        }
        self.file
            .dataset(name)
            .map_err(|e| h5_error(self.path, name, e))
    }

    /// All values of a numeric (float, integer or integer-enum) dataset as f64, with its shape
    /// and datatype.
    fn numbers(&self, name: &str) -> Result<(Vec<f64>, Vec<usize>, Datatype)> {
        let ds = self.dataset(name)?;
        let shape: Vec<usize> = ds.shape().iter().map(|&d| usize_of(d)).collect();
        let dtype = ds.dtype().clone();
        let raw = ds
            .read_raw_bytes()
            .map_err(|e| h5_error(self.path, name, e))?;
        let v = decode_numbers(&raw, &dtype).ok_or_else(|| {
            Error::format(
                self.path,
                name,
                "numeric values",
                format!("{dtype:?} ({} bytes)", raw.len()),
            )
        })?;
        let n = shape.iter().try_fold(1usize, |a, &d| a.checked_mul(d));
        if n != Some(v.len()) {
            return Err(Error::format(
                self.path,
                name,
                format!("the values of shape {shape:?}"),
                format!("{} values", v.len()),
            ));
        }
        Ok((v, shape, dtype))
    }

    fn float_scalar(&self, name: &str) -> Result<f64> {
        let (v, shape, _) = self.numbers(name)?;
        match v[..] {
            [x] => Ok(x),
            _ => Err(Error::format(
                self.path,
                name,
                "a scalar",
                format!("shape {shape:?}"),
            )),
        }
    }

    /// A one-element integer (or enum) dataset, with the enum member's name if it has one.
    fn enum_scalar(&self, name: &str) -> Result<(i64, Option<String>)> {
        let (v, shape, dtype) = self.numbers(name)?;
        let x = match v[..] {
            [x] if x.fract() == 0.0 && x.abs() < 1e15 => x as i64,
            _ => {
                return Err(Error::format(
                    self.path,
                    name,
                    "one integer",
                    format!("{v:?} of shape {shape:?}"),
                ));
            }
        };
        let member = match &dtype {
            Datatype::Enum { base, members } => members
                .iter()
                .find(|m| decode_numbers(&m.value, base).as_deref() == Some(&[x as f64][..]))
                .map(|m| m.name.clone()),
            _ => None,
        };
        Ok((x, member))
    }

    fn xyz(&self, name: &str) -> Result<[f64; 3]> {
        let (v, shape, _) = self.numbers(name)?;
        let p = <[f64; 3]>::try_from(v.as_slice()).map_err(|_| {
            Error::format(self.path, name, "3 coordinates", format!("shape {shape:?}"))
        })?;
        if !p.iter().all(|c| c.is_finite()) {
            return Err(Error::format(
                self.path,
                name,
                "finite coordinates",
                format!("{p:?}"),
            ));
        }
        Ok(p)
    }

    /// A grid `(X, Y, 3)` or `(N, 3)`, checked against its `*_grid_format` if present.
    fn grid(&self, name: &'static str, format_name: &str) -> Result<Grid> {
        let (v, shape, _) = self.numbers(name)?;
        let (xy, dims) = match shape[..] {
            [nx, ny, 3] => (true, [nx, ny]),
            [n, 3] => (false, [n, 1]),
            _ => {
                return Err(Error::format(
                    self.path,
                    name,
                    "shape (X, Y, 3) or (N, 3)",
                    format!("{shape:?}"),
                ));
            }
        };
        if self.has(format_name) {
            let (g, member) = self.enum_scalar(format_name)?;
            let (want, want_name) = if xy { (2, "X_Y_3") } else { (1, "N_3") };
            if g != want || member.is_some_and(|m| m != want_name) {
                return Err(Error::format(
                    self.path,
                    format_name,
                    format!("{want} = {want_name} (tal GridFormat) for {name} of shape {shape:?}"),
                    g,
                ));
            }
        }
        Ok(Grid {
            points: v
                .chunks_exact(3)
                .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32])
                .collect(),
            shape: dims,
            xy,
            field: name,
        })
    }
}

/// Decodes the raw element bytes of a float, integer or integer-enum datatype to f64.
fn decode_numbers(raw: &[u8], dtype: &Datatype) -> Option<Vec<f64>> {
    /// Little-endian words of `N` bytes.
    fn words<const N: usize>(raw: &[u8], order: ByteOrder) -> Option<Vec<[u8; N]>> {
        if !raw.len().is_multiple_of(N) {
            return None;
        }
        Some(
            raw.chunks_exact(N)
                .map(|c| {
                    let mut w = [0u8; N];
                    w.copy_from_slice(c);
                    if order == ByteOrder::BigEndian {
                        w.reverse();
                    }
                    w
                })
                .collect(),
        )
    }
    match dtype {
        &Datatype::FloatingPoint { size, byte_order } => match size {
            4 => words::<4>(raw, byte_order).map(|w| {
                w.into_iter()
                    .map(|b| f64::from(f32::from_le_bytes(b)))
                    .collect()
            }),
            8 => {
                words::<8>(raw, byte_order).map(|w| w.into_iter().map(f64::from_le_bytes).collect())
            }
            _ => None,
        },
        &Datatype::FixedPoint {
            size,
            signed,
            byte_order,
        } => {
            let size = usize::from(size);
            if !matches!(size, 1 | 2 | 4 | 8) || !raw.len().is_multiple_of(size) {
                return None;
            }
            Some(
                raw.chunks_exact(size)
                    .map(|c| {
                        let mut w = [0u8; 8];
                        w[..size].copy_from_slice(c);
                        if byte_order == ByteOrder::BigEndian {
                            w[..size].reverse();
                        }
                        if signed && w[size - 1] & 0x80 != 0 {
                            w[size..].fill(0xFF);
                        }
                        if signed {
                            i64::from_le_bytes(w) as f64
                        } else {
                            u64::from_le_bytes(w) as f64
                        }
                    })
                    .collect(),
            )
        }
        Datatype::Enum { base, .. } => decode_numbers(raw, base),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ltm::laser_falloff;

    /// A capture of `../shared/data` (beside the repository).
    fn shared(capture: &str) -> PathBuf {
        PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data"))
            .join(capture)
            .join(format!("{capture}.hdf5"))
    }

    /// A fresh scratch directory for one test.
    fn scratch(test: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("vltm-tal-{}-{test}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// The format error's field, or a failure message.
    fn format_field(r: Result<impl std::fmt::Debug>) -> String {
        match r {
            Err(Error::Format { field, .. }) => field,
            other => panic!("expected a format error, got {other:?}"),
        }
    }

    const ORIGIN: [f64; 3] = [-0.5, 0.0, 0.25];

    #[test]
    fn shared_captures_open_with_the_readme_geometry() {
        for name in ["two_patches", "two_patches_direct_only"] {
            let r = open(&shared(name)).unwrap();
            assert_eq!(r.h_shape(), [400, 8, 8, 8, 8]);
            assert_eq!(r.h_format(), HFormat::TLxLySxSy);
            assert_eq!(r.scan_type(), ScanType::Exhaustive);
            let g = r.geometry();
            assert_eq!((g.lasers.len(), g.laser_shape), (64, [8, 8]));
            assert_eq!((g.spads.len(), g.spad_shape), (64, [8, 8]));
            // Cell centres ±0.1 … ±0.7, first index along +x (`l = ix·8 + iy`).
            assert_eq!(g.lasers[0], [-0.7, -0.7, 0.0]);
            assert_eq!(g.lasers[1], [-0.7, -0.5, 0.0]);
            assert_eq!(g.lasers[8], [-0.5, -0.7, 0.0]);
            assert_eq!(g.spads[63], [0.7, 0.7, 0.0]);
            assert_eq!((g.nt, g.dt, g.t0), (400, 0.01, 1.0));
            assert_eq!((g.laser_origin, g.sensor_origin), (ORIGIN, ORIGIN));
            assert!(!g.legs_in_time && !g.confocal);
        }

        let r = open(&shared("line")).unwrap();
        assert_eq!(r.h_shape(), [400, 12, 12, 12, 1]);
        assert_eq!(r.scan_type(), ScanType::Exhaustive);
        let g = r.geometry();
        assert_eq!((g.lasers.len(), g.laser_shape), (144, [12, 12]));
        assert_eq!((g.spads.len(), g.spad_shape), (12, [12, 1]));
        assert!(g.spads.iter().all(|s| s[1] == 0.0 && s[2] == 0.0));
        assert!((g.spads[0][0] + 0.733_333_3).abs() < 1e-6);
        assert_eq!((g.nt, g.dt, g.t0), (400, 0.01, 0.9));
        assert_eq!(g.spads_per_row(), 12);

        // tal `single`: one laser spot, 16×16 SPADs → 16×16 lasers × 1 SPAD at the spot.
        let r = open(&shared("single")).unwrap();
        assert_eq!(r.h_shape(), [300, 16, 16]);
        assert_eq!(r.h_format(), HFormat::TSxSy);
        assert_eq!(r.scan_type(), ScanType::Single);
        let g = r.geometry();
        assert_eq!((g.lasers.len(), g.laser_shape), (256, [16, 16]));
        assert_eq!(
            (g.spads.clone(), g.spad_shape),
            (vec![[0.25, -0.15, 0.0]], [1, 1])
        );
        assert_eq!(g.lasers[0], [-0.75, -0.75, 0.0]);
        assert_eq!(g.lasers[10 * 16 + 6], [0.25, -0.15, 0.0]);
        assert_eq!((g.nt, g.dt, g.t0), (300, 0.01, 1.5));
        assert_eq!((g.laser_origin, g.sensor_origin), (ORIGIN, ORIGIN));
        assert!(!g.confocal && !g.legs_in_time);
    }

    #[test]
    fn streamed_rows_equal_read_all_in_any_order() {
        for name in ["two_patches", "line", "single"] {
            let c = read_all(&shared(name)).unwrap();
            let mut r = open(&shared(name)).unwrap();
            assert_eq!(r.geometry(), &c.geometry);
            let kl = c.geometry.lasers.len();
            let mut row = Vec::new();
            for l in (0..kl).rev().step_by(3).chain([0, kl / 2]) {
                let x = r.read_row(l, &mut row).unwrap();
                assert_eq!(x, c.geometry.lasers[l]);
                assert_eq!(row.as_slice(), c.row(l), "{name}: row {l}");
            }
        }
    }

    /// Values read with h5py (`f["H"][t, lx, ly, sx, sy]`, float32 bit patterns) and the f64
    /// sums of all of `H` (`H.astype(np.float64).sum()`).
    #[test]
    fn values_match_h5py() {
        let at = |c: &Capture, l: usize, s: usize, n: usize| c.row(l)[s * c.geometry.nt + n];
        let c = read_all(&shared("two_patches")).unwrap();
        // H[150, 3, 5, 2, 6] = 8.838952e-05, H[120, 4, 4, 4, 4] = 8.68398e-05, the maximum
        // H[167, 1, 4, 1, 4] = 0.0071075666, H[200, 0, 7, 7, 0] = 0.
        assert_eq!(at(&c, 3 * 8 + 5, 2 * 8 + 6, 150).to_bits(), 951_672_259);
        assert_eq!(at(&c, 4 * 8 + 4, 4 * 8 + 4, 120).to_bits(), 951_459_267);
        assert_eq!(at(&c, 8 + 4, 8 + 4, 167).to_bits(), 1_005_119_127);
        assert_eq!(at(&c, 7, 7 * 8, 200), 0.0);
        let max = c.data.iter().copied().fold(f32::MIN, f32::max);
        assert_eq!(max.to_bits(), 1_005_119_127);
        let sum: f64 = c.data.iter().map(|&h| f64::from(h)).sum();
        assert!((sum / 12.316_197_417_224_396 - 1.0).abs() < 1e-12, "{sum}");

        let c = read_all(&shared("line")).unwrap();
        // H[130, 2, 9, 5, 0] = 0.00010940093, H[250, 11, 0, 0, 0] = 4.121247e-09.
        assert_eq!(at(&c, 2 * 12 + 9, 5, 130).to_bits(), 954_560_045);
        assert_eq!(at(&c, 11 * 12, 0, 250).to_bits(), 831_363_807);
        let sum: f64 = c.data.iter().map(|&h| f64::from(h)).sum();
        assert!((sum / 32.913_522_176_732_46 - 1.0).abs() < 1e-12, "{sum}");

        // single: H[45, 3, 3] = 0.0002095045 times c'(S[3, 3]) / c(x0); c(x0) = 0.47982221114
        // (numpy, float64), c'(S[3, 3]) = 1.80698418831.
        let c = read_all(&shared("single")).unwrap();
        let g = &c.geometry;
        let raw = f64::from(f32::from_bits(962_309_744));
        let c0 = 0.479_822_211_140_720_4;
        let cs = laser_falloff(g, g.lasers[3 * 16 + 3]);
        assert!((cs - 1.806_984_188_306_343_8).abs() < 1e-9, "{cs}");
        assert_eq!(at(&c, 3 * 16 + 3, 0, 45), (raw * cs / c0) as f32);
        // Σ_l Σ_t H[t, l]·c'(S_l)/c(x0) = 1.4848346794 (numpy); after --compensate-laser every
        // row is H / c(x0): Σ = 0.8313117163, y-tal's compensate_laser_cos_dsqr.
        let kl = g.lasers.len();
        let sum: f64 = c.data.iter().map(|&h| f64::from(h)).sum();
        assert!((sum / 1.484_834_679_407_712_3 - 1.0).abs() < 1e-6, "{sum}");
        let comp: f64 = (0..kl)
            .map(|l| {
                c.row(l).iter().map(|&h| f64::from(h)).sum::<f64>() / laser_falloff(g, g.lasers[l])
            })
            .sum();
        assert!(
            (comp / 0.831_311_716_266_990_7 - 1.0).abs() < 1e-6,
            "{comp}"
        );
    }

    #[test]
    fn bin_centre_moves_t0_by_half_a_bin_only() {
        let a = read_all_with(&shared("line"), TalOptions::YTAL).unwrap();
        let b = read_all_with(&shared("line"), TalOptions::BIN_CENTRE).unwrap();
        assert_eq!(TalOptions::default(), TalOptions::YTAL);
        assert!((b.geometry.t0 - 0.905).abs() < 1e-12);
        assert_eq!(a.data, b.data);
        assert_eq!(
            Geometry {
                t0: a.geometry.t0,
                ..b.geometry
            },
            a.geometry
        );
    }

    #[test]
    fn capture_open_dispatches_hdf5_and_h5() {
        let a = crate::capture::open(&shared("single")).unwrap();
        let dir = scratch("h5");
        let p = dir.join("copy.H5");
        std::fs::copy(shared("single"), &p).unwrap();
        let b = crate::capture::open(&p).unwrap();
        assert_eq!(a, b);
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn bad_row_and_missing_file() {
        let mut r = open(&shared("single")).unwrap();
        let mut row = Vec::new();
        assert!(matches!(
            r.read_row(256, &mut row),
            Err(Error::Argument { .. })
        ));
        let e = open(Path::new("/nonexistent/x.hdf5")).unwrap_err();
        assert!(matches!(e, Error::Io { .. }), "{e}");
        assert!(e.to_string().contains("/nonexistent/x.hdf5"));
    }

    /// Truncated and byte-corrupted copies: every outcome is `Ok` or an `Error`, never a panic;
    /// every truncation and a broken signature are errors.
    #[test]
    fn corrupt_files_are_errors_not_panics() {
        let orig = std::fs::read(shared("single")).unwrap();
        let n = orig.len();
        let dir = scratch("corrupt");
        let p = dir.join("c.hdf5");
        let attempt = |bytes: &[u8]| -> Result<Capture> {
            std::fs::write(&p, bytes).unwrap();
            read_all(&p)
        };
        // H's data starts at byte 2048 (h5py), the other datasets and the metadata follow it.
        for cut in [
            0,
            1,
            7,
            8,
            100,
            512,
            1000,
            2047,
            2048,
            2049,
            4096,
            n / 2,
            309_248,
            n - 100,
            n - 1,
        ] {
            let r = attempt(&orig[..cut]);
            assert!(r.is_err(), "truncated at {cut} of {n}: read");
            assert!(!r.unwrap_err().to_string().is_empty());
        }
        let mut bad = orig.clone();
        bad[1] ^= 0xFF; // the "\x89HDF" signature
        let e = attempt(&bad).unwrap_err();
        assert!(
            matches!(e, Error::Format { ref field, .. } if field == "(file)"),
            "{e}"
        );
        let mut errors = 0;
        let positions = (0..2048).step_by(16).chain((309_248..n).step_by(64));
        for (k, i) in positions.enumerate() {
            let mut b = orig.clone();
            b[i] ^= [0xFF, 0x01, 0x80][k % 3];
            if let Err(e) = attempt(&b) {
                errors += 1;
                assert!(e.to_string().contains("c.hdf5"), "{e}");
            }
        }
        assert!(errors > 50, "only {errors} corrupt copies were refused");
        let _ = std::fs::remove_dir_all(dir);
    }

    /// What a synthetic tal file holds (written with `hdf5-pure`).
    struct Spec {
        h_shape: Vec<u64>,
        h_format: i32,
        /// Write `H_format` as tal's named enum (else a plain int32).
        enum_names: Option<Vec<(&'static str, i32)>>,
        h_f64: bool,
        h_int: bool,
        chunks: Option<Vec<u64>>,
        laser_grid: (Vec<f32>, Vec<u64>),
        sensor_grid: (Vec<f32>, Vec<u64>),
        laser_grid_format: Option<i32>,
        laser_xyz: [f32; 3],
        sensor_xyz: [f32; 3],
        delta_t: f64,
        t_start: f64,
        legs: u8,
        skip: &'static str,
    }

    /// Value of `H` at `(t, a, b, ...)` in C order: `t·10⁴ + (flat index of the rest)`.
    fn pattern(shape: &[u64]) -> Vec<f64> {
        let rest: u64 = shape[1..].iter().product();
        (0..shape[0] * rest)
            .map(|i| ((i / rest) * 10_000 + i % rest) as f64)
            .collect()
    }

    /// `n` grid points `(x_i, y_j, 0)` on a 0.1 m pitch, shape `(nx, ny, 3)` or `(n, 3)`.
    fn grid(nx: u64, ny: u64, n3: bool, dx: f32) -> (Vec<f32>, Vec<u64>) {
        let mut v = Vec::new();
        for i in 0..nx {
            for j in 0..ny {
                v.extend([0.1 * i as f32 - 0.2 + dx, 0.1 * j as f32 - 0.1, 0.0]);
            }
        }
        let shape = if n3 {
            vec![nx * ny, 3]
        } else {
            vec![nx, ny, 3]
        };
        (v, shape)
    }

    impl Spec {
        fn exhaustive() -> Self {
            Self {
                h_shape: vec![5, 3, 2, 4, 2],
                h_format: 2,
                enum_names: None,
                h_f64: false,
                h_int: false,
                chunks: None,
                laser_grid: grid(3, 2, false, 0.0),
                sensor_grid: grid(4, 2, false, 0.0),
                laser_grid_format: None,
                laser_xyz: [-0.5, 0.0, 0.25],
                sensor_xyz: [0.5, 0.125, 0.375],
                delta_t: 0.02,
                t_start: 0.5,
                legs: 1,
                skip: "",
            }
        }

        fn write(&self, path: &Path) {
            use hdf5_pure::{EnumTypeBuilder, FileBuilder};
            let mut b = FileBuilder::new();
            let h = pattern(&self.h_shape);
            if self.skip != "H" {
                let d = b.create_dataset("H");
                if self.h_int {
                    d.with_i32_data(&h.iter().map(|&x| x as i32).collect::<Vec<_>>());
                } else if self.h_f64 {
                    d.with_f64_data(&h);
                } else {
                    d.with_f32_data(&h.iter().map(|&x| x as f32).collect::<Vec<_>>());
                }
                d.with_shape(&self.h_shape);
                if let Some(c) = &self.chunks {
                    d.with_chunks(c).with_deflate(4);
                }
            }
            if self.skip != "H_format" {
                let d = b.create_dataset("H_format");
                match &self.enum_names {
                    Some(names) => {
                        let t = names
                            .iter()
                            .fold(EnumTypeBuilder::i32_based(), |t, &(n, v)| t.value(n, v))
                            .build()
                            .unwrap();
                        d.with_enum_i32_data(t, &[self.h_format]);
                    }
                    None => {
                        d.with_i32_data(&[self.h_format]);
                    }
                }
                d.with_shape(&[1]);
            }
            for (name, (v, shape)) in [
                ("laser_grid_xyz", &self.laser_grid),
                ("sensor_grid_xyz", &self.sensor_grid),
            ] {
                if self.skip != name {
                    b.create_dataset(name).with_f32_data(v).with_shape(shape);
                }
            }
            if let Some(g) = self.laser_grid_format {
                b.create_dataset("laser_grid_format")
                    .with_i32_data(&[g])
                    .with_shape(&[1]);
            }
            for (name, v) in [
                ("laser_xyz", self.laser_xyz),
                ("sensor_xyz", self.sensor_xyz),
            ] {
                if self.skip != name {
                    b.create_dataset(name).with_f32_data(&v).with_shape(&[3]);
                }
            }
            for (name, v) in [("delta_t", self.delta_t), ("t_start", self.t_start)] {
                if self.skip != name {
                    b.create_dataset(name).with_f64_data(&[v]).with_shape(&[]);
                }
            }
            if self.skip != "t_accounts_first_and_last_bounces" {
                b.create_dataset("t_accounts_first_and_last_bounces")
                    .with_u8_data(&[self.legs])
                    .with_shape(&[]);
            }
            b.write(path).unwrap();
        }

        fn open(&self, dir: &Path, name: &str) -> Result<TalReader> {
            let p = dir.join(format!("{name}.hdf5"));
            self.write(&p);
            open(&p)
        }
    }

    /// Checks every row of `r` against the pattern: row `l`, SPAD `s`, bin `n` holds
    /// `n·10⁴ + index(l, s)` times `scale(l)`.
    fn check_rows(r: &mut TalReader, index: impl Fn(usize, usize) -> usize) {
        let g = r.geometry().clone();
        let mut row = Vec::new();
        for l in 0..g.lasers.len() {
            assert_eq!(r.read_row(l, &mut row).unwrap(), g.lasers[l]);
            for s in 0..g.spads_per_row() {
                for n in 0..g.nt {
                    let want = (n * 10_000 + index(l, s)) as f32;
                    assert_eq!(row[s * g.nt + n], want, "row {l}, SPAD {s}, bin {n}");
                }
            }
        }
    }

    #[test]
    fn synthetic_formats_stream_the_right_values() {
        let dir = scratch("formats");
        // T_Lx_Ly_Sx_Sy, contiguous f32, and chunked + gzip f64, with the named tal enum.
        let mut spec = Spec::exhaustive();
        spec.enum_names = Some(vec![
            ("UNKNOWN", 0),
            ("T_Sx_Sy", 1),
            ("T_Lx_Ly_Sx_Sy", 2),
            ("T_Si", 3),
            ("T_Li_Si", 4),
        ]);
        for (k, chunks) in [None, Some(vec![2, 1, 2, 4, 2])].into_iter().enumerate() {
            spec.chunks = chunks;
            spec.h_f64 = k == 1;
            let mut r = spec.open(&dir, &format!("exhaustive{k}")).unwrap();
            let g = r.geometry().clone();
            assert_eq!((g.laser_shape, g.spad_shape, g.nt), ([3, 2], [4, 2], 5));
            assert_eq!((g.dt, g.t0, g.legs_in_time), (0.02, 0.5, true));
            assert_eq!(
                (g.laser_origin, g.sensor_origin),
                ([-0.5, 0.0, 0.25], [0.5, 0.125, 0.375])
            );
            check_rows(&mut r, |l, s| l * 8 + s);
        }

        // Rows of 120 kB: blocks of 2 rows (BLOCK_BYTES), lines of 5 end in a partial block;
        // rows read in a scrambled order.
        let mut spec = Spec::exhaustive();
        spec.h_shape = vec![30, 2, 5, 10, 100];
        spec.laser_grid = grid(2, 5, false, 0.0);
        spec.sensor_grid = grid(10, 100, false, 0.0);
        let mut r = spec.open(&dir, "blocks").unwrap();
        assert_eq!(r.block_len(), 2);
        let mut row = Vec::new();
        for l in [9, 0, 4, 5, 3, 8, 1, 2, 7, 6, 6, 9] {
            r.read_row(l, &mut row).unwrap();
            for s in [0, 1, 499, 999] {
                for n in [0, 17, 29] {
                    assert_eq!(row[s * 30 + n], (n * 10_000 + l * 1000 + s) as f32);
                }
            }
        }
        check_rows(&mut r, |l, s| l * 1000 + s);

        // T_Li_Si with N_3 grids.
        let mut spec = Spec::exhaustive();
        spec.h_shape = vec![4, 6, 3];
        spec.h_format = 4;
        spec.laser_grid = grid(3, 2, true, 0.0);
        spec.sensor_grid = grid(3, 1, true, 0.0);
        spec.laser_grid_format = Some(1);
        let mut r = spec.open(&dir, "lisi").unwrap();
        assert_eq!(r.scan_type(), ScanType::Exhaustive);
        assert_eq!(
            (r.geometry().laser_shape, r.geometry().spad_shape),
            ([6, 1], [3, 1])
        );
        check_rows(&mut r, |l, s| l * 3 + s);

        // T_Sx_Sy confocal (laser grid = sensor grid) and T_Si confocal.
        let mut spec = Spec::exhaustive();
        spec.h_shape = vec![6, 3, 2];
        spec.h_format = 1;
        spec.laser_grid = grid(3, 2, false, 0.0);
        spec.sensor_grid = grid(3, 2, false, 0.0);
        let mut r = spec.open(&dir, "confocal").unwrap();
        assert_eq!(r.scan_type(), ScanType::Confocal);
        assert!(r.geometry().confocal && r.geometry().spads_per_row() == 1);
        assert_eq!(r.geometry().laser_shape, [3, 2]);
        check_rows(&mut r, |l, _| l);
        spec.h_shape = vec![6, 6];
        spec.h_format = 3;
        spec.laser_grid = grid(3, 2, true, 0.0);
        spec.sensor_grid = grid(3, 2, true, 0.0);
        let mut r = spec.open(&dir, "confocal_si").unwrap();
        assert_eq!(r.scan_type(), ScanType::Confocal);
        assert_eq!(r.geometry().laser_shape, [6, 1]);
        check_rows(&mut r, |l, _| l);

        // T_Si single: one laser point → the sensor points become lasers, with the factor.
        spec.laser_grid = (vec![0.05, 0.02, 0.0], vec![1, 1, 3]);
        let mut r = spec.open(&dir, "single_si").unwrap();
        assert_eq!(r.scan_type(), ScanType::Single);
        let g = r.geometry().clone();
        assert_eq!(
            (g.spads.clone(), g.spad_shape),
            (vec![[0.05, 0.02, 0.0]], [1, 1])
        );
        assert_eq!(
            (g.laser_origin, g.sensor_origin),
            ([0.5, 0.125, 0.375], [-0.5, 0.0, 0.25])
        );
        let physical = Geometry {
            laser_origin: [-0.5, 0.0, 0.25],
            ..g.clone()
        };
        let c0 = laser_falloff(&physical, g.spads[0]);
        let mut row = Vec::new();
        for l in 0..6 {
            r.read_row(l, &mut row).unwrap();
            let k = laser_falloff(&g, g.lasers[l]) / c0;
            for (n, &h) in row.iter().enumerate() {
                assert_eq!(h, (((n * 10_000 + l) as f64) * k) as f32);
            }
        }
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn malformed_fields_name_the_field() {
        let dir = scratch("malformed");
        let case = |name: &str, edit: &dyn Fn(&mut Spec)| {
            let mut s = Spec::exhaustive();
            edit(&mut s);
            format_field(s.open(&dir, name))
        };
        for missing in [
            "H",
            "H_format",
            "laser_grid_xyz",
            "sensor_grid_xyz",
            "laser_xyz",
            "sensor_xyz",
            "delta_t",
            "t_start",
            "t_accounts_first_and_last_bounces",
        ] {
            assert_eq!(case(missing, &|s| s.skip = missing), missing);
        }
        assert_eq!(case("dt_nan", &|s| s.delta_t = f64::NAN), "delta_t");
        assert_eq!(case("dt_inf", &|s| s.delta_t = f64::INFINITY), "delta_t");
        assert_eq!(case("dt_zero", &|s| s.delta_t = 0.0), "delta_t");
        assert_eq!(case("t0_nan", &|s| s.t_start = f64::NAN), "t_start");
        assert_eq!(case("fmt_unknown", &|s| s.h_format = 0), "H_format");
        assert_eq!(case("fmt_7", &|s| s.h_format = 7), "H_format");
        // An enum whose names disagree with tal's numbering.
        assert_eq!(
            case("fmt_names", &|s| s.enum_names =
                Some(vec![("T_Si", 2), ("T_Lx_Ly_Sx_Sy", 3)])),
            "H_format"
        );
        assert_eq!(case("rank", &|s| s.h_format = 4), "H");
        assert_eq!(case("int_h", &|s| s.h_int = true), "H");
        assert_eq!(
            case("lgrid", &|s| s.laser_grid = grid(2, 3, false, 0.0)),
            "laser_grid_xyz"
        );
        assert_eq!(
            case("sgrid", &|s| s.sensor_grid = grid(4, 1, false, 0.0)),
            "sensor_grid_xyz"
        );
        assert_eq!(
            case("grid_rank", &|s| s.laser_grid =
                (vec![0.0; 18], vec![6, 3, 1])),
            "laser_grid_xyz"
        );
        assert_eq!(
            case("grid_fmt", &|s| s.laser_grid_format = Some(1)),
            "laser_grid_format"
        );
        // A paired, non-confocal T_Sx_Sy scan (each point its own shifted laser).
        assert_eq!(
            case("paired", &|s| {
                s.h_shape = vec![5, 3, 2];
                s.h_format = 1;
                s.sensor_grid = grid(3, 2, false, 0.0);
                s.laser_grid = grid(3, 2, false, 0.05);
            }),
            "laser_grid_xyz"
        );
        // The single-scan reciprocity factor needs both devices off the wall plane.
        let single = |s: &mut Spec| {
            s.h_shape = vec![5, 3, 2];
            s.h_format = 1;
            s.sensor_grid = grid(3, 2, false, 0.0);
            s.laser_grid = (vec![0.0, 0.0, 0.0], vec![1, 1, 3]);
        };
        let laser_in_wall = |s: &mut Spec| {
            single(s);
            s.laser_xyz = [-0.5, 0.0, 0.0];
        };
        let sensor_in_wall = |s: &mut Spec| {
            single(s);
            s.sensor_xyz = [0.5, 0.0, 0.0];
        };
        assert_eq!(case("laser_in_wall", &laser_in_wall), "laser_xyz");
        assert_eq!(case("sensor_in_wall", &sensor_in_wall), "sensor_xyz");
        let mut s = Spec::exhaustive();
        single(&mut s);
        assert_eq!(
            s.open(&dir, "single_ok").unwrap().scan_type(),
            ScanType::Single
        );
        let _ = std::fs::remove_dir_all(dir);
    }
}
