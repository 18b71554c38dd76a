//! Reader of the Zaragoza **Z-NLOS** HDF5 layout (Galindo et al. 2019, the public synthetic
//! NLOS dataset; y-tal `FileFormat.HDF5_ZNLOS`), mapped onto vltm's [`Geometry`] exactly as
//! y-tal's converter `__convert_dict_znlos_to_tal` (`tal/io/format.py`, y-tal 0.20.0) maps it
//! onto tal's fields, which the `HDF5_TAL` reader's geometry code (`tal/scan.rs`) then reads.
//!
//! # Datasets
//!
//! | dataset | used as (tal field) |
//! |---|---|
//! | `data` (f32 or f64), 7 or 5 axes, see *Axis order* | `H`: summed over colours and bounces |
//! | `cameraGridPositions` `(Sx, Sy, 3)`, or `(3, Sy, Sx)` transposed | `sensor_grid_xyz` (X_Y_3) |
//! | `laserGridPositions` `(Lx, Ly, 3)`, or `(3, Ly, Lx)` transposed | `laser_grid_xyz` (X_Y_3) |
//! | `cameraPosition`, `laserPosition` (3 values, any shape) | `sensor_xyz`, `laser_xyz` |
//! | `deltaT` (1 value, m of optical path) | `delta_t` |
//! | `t0` (1 value, m of optical path) | `t_start` |
//! | (none) | `t_accounts_first_and_last_bounces` = **true** |
//! | `cameraGridNormals`, `laserGridNormals` (optional) | `sensor_grid_normals`, `laser_grid_normals`, laid out as the positions (absent or null: +z); checked and used as tal's ([`super`]) |
//! | `hiddenVolume*`, `t`, `isConfocal`, `*GridSize`, `*GridPoints`, `engine` | not used (the grids and `data` decide the scan) |
//!
//! A grid whose first axis has 3 elements is transposed (all axes reversed), as y-tal's
//! `conv_to_xy3` does; after that it must be `(X, Y, 3)`. One deviation: a grid stored
//! `(X, Y, 3)` with X = 3 that matches `data`'s axes only as stored is kept (y-tal transposes
//! it into a wrong grid); when both readings match (`(3, Y, 3)` for X = 3, Y = Y) y-tal's
//! transpose is followed. (For a 5-axis capture the laser grid is compared with the camera
//! grid's axes.)
//!
//! # Axis order
//!
//! y-tal tells the layouts apart by the shape of `data` (`np.moveaxis` in the converter; the
//! names below are where each axis lands in tal's `(t, lx, ly, sx, sy)`, taken from the
//! `moveaxis` destinations, which are not always the converter's comments):
//!
//! | [`ZnlosLayout`] | `data` rank, test | file axes | reading |
//! |---|---|---|---|
//! | `Rows7` | 7, `shape[4] == 6` | `(ly, lx, sy, sx, bounces, t, colours)` | streamed by block of rows |
//! | `Time7` | 7, else `shape[2] == 6` | `(colours, t, bounces, sy, sx, ly, lx)` | read whole, then by block |
//! | `Rows5` | 5, `shape[0] == shape[1]` | `(sx, sy, bounces, t, colours)` | streamed by block of rows |
//! | `Time5` | 5, else `shape[3] == shape[4]` | `(colours, t, bounces, sy, sx)` | read whole, then by block |
//!
//! (The 6 is the bounce axis of the Z-NLOS renderer, which stores bounces 2–7 separately.)
//! Colours and bounces are summed. A 7-axis capture with one laser point (1×1) is y-tal's
//! `T_Sx_Sy` after its `np.squeeze`: a tal **single** scan, presented by reciprocity as in
//! [`super`] (*Scan types*). A 5-axis capture is `T_Sx_Sy`: **confocal** when the two grids
//! are `allclose`, single when the laser grid is one point. Every other 7-axis capture is
//! **exhaustive** `T_Lx_Ly_Sx_Sy`; unlike y-tal, vltm does not squeeze other size-1 axes
//! (y-tal's squeeze turns a 1×1 camera grid into a mislabelled `T_Sx_Sy`; vltm reads it as
//! Kl lasers × one SPAD).
//!
//! # Time axis and legs
//!
//! Z-NLOS times are total optical path lengths: they include the first leg (laser device →
//! laser spot) and the last (SPAD spot → camera device). vltm keeps them as y-tal does
//! (`t_accounts_first_and_last_bounces = true`: [`Geometry::legs_in_time`]), so the probes
//! subtract `|laserPosition − x_l| + |x_s − cameraPosition|` from every path time
//! (`vltm_kernel::Legs::FirstAndLast`), exactly what y-tal's reconstructions do with such a
//! capture. Bin `k` is at `t0 + k·deltaT` ([`TalOptions::YTAL`], the default) or its centre
//! ([`TalOptions::BIN_CENTRE`]).
//!
//! # Memory and cost
//!
//! Rows are read by the `HDF5_TAL` reader's background thread ([`super`], *Reading*): blocks
//! of consecutive rows are read, summed over colours and bounces and reordered into vltm's
//! SPAD-major rows ahead of the probes, and handed over through a bounded queue of one block
//! with recycled row buffers, so that reading and summing overlap the probes' work
//! (`stream`). A contiguous little-endian `data` is read with positional reads of the file;
//! anything else (chunked or compressed, big-endian, compact) through the crate's hyperslabs.
//!
//! * `Rows7` and `Rows5` hold each histogram as one run of `bounces × Nt × colours` values
//!   and a row's histograms one after the other: a block is as many rows as fit in
//!   [`super::BLOCK_BYTES`] of `data` as stored (at least one), read in runs of adjacent
//!   histograms of at most [`super::BLOCK_BYTES`] (one `Ks·bounces·Nt·colours` hyperslab per
//!   row through the crate). Memory: three blocks of rows and a staging buffer of at most
//!   [`super::BLOCK_BYTES`] (one histogram as stored when larger), whatever the capture's size.
//! * `Time7` and `Time5` put the row axes last: a row would be `Nt·bounces·colours·Ks` reads
//!   of one value, and no row is complete before the last colour is read. On the first row
//!   the whole of `data` is read in file order (runs of whole `(sy, sx, ly, lx)` planes of at
//!   most [`super::BLOCK_BYTES`]; one `(colour, bin)` hyperslab through the crate) and summed
//!   into a time-major f32 copy of the capture (memory: `4·Kl·Ks·Nt` bytes, an index table
//!   of `Kl·Ks` entries, the staging buffer and three blocks); the blocks are then cut from
//!   it in the background.
//!
//! Sums are taken in the file's order from 0 on every path, so the rows do not depend on how
//! they were read. The memory is checked against [`crate::budget`] when the file is opened
//! and stated by [`ZnlosReader::conventions`]. Measured cost: docs/performance.md, *Reading Z-NLOS HDF5*.
//!
//! # Errors
//!
//! As the `HDF5_TAL` reader: one [`Error::Format`] naming the file and the dataset (a missing
//! dataset, a shape y-tal's converter does not recognise, grids that do not match `data`,
//! non-numeric or non-finite values, data outside the file).

use super::fields::{Fields, Grid, usize_of};
use super::{
    BLOCK_BYTES, Cursor, Elem, HFormat, ScanType, TalOptions, check_layout, open_file, scan,
};
use crate::budget;
use crate::error::{Error, Result};
use crate::io::capture::{Capture, Geometry, RowSource, check_row};
use hdf5_reader::{ByteOrder, Dataset, Datatype};
use std::path::{Path, PathBuf};
use stream::{Blocks, Source};
use vltm_kernel::Point;

/// Which of y-tal's four Z-NLOS axis orders `data` has (module docs, *Axis order*).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ZnlosLayout {
    /// `(ly, lx, sy, sx, bounces, t, colours)`.
    Rows7,
    /// `(colours, t, bounces, sy, sx, ly, lx)`.
    Time7,
    /// `(sx, sy, bounces, t, colours)`.
    Rows5,
    /// `(colours, t, bounces, sy, sx)`.
    Time5,
}

impl ZnlosLayout {
    /// The axis order, as text.
    pub fn axes(self) -> &'static str {
        match self {
            Self::Rows7 => "(ly, lx, sy, sx, bounces, t, colours)",
            Self::Time7 => "(colours, t, bounces, sy, sx, ly, lx)",
            Self::Rows5 => "(sx, sy, bounces, t, colours)",
            Self::Time5 => "(colours, t, bounces, sy, sx)",
        }
    }

    fn roles(self) -> &'static [Axis] {
        use Axis::*;
        match self {
            Self::Rows7 => &[Ly, Lx, Sy, Sx, B, T, C],
            Self::Time7 => &[C, T, B, Sy, Sx, Ly, Lx],
            Self::Rows5 => &[Sx, Sy, B, T, C],
            Self::Time5 => &[C, T, B, Sy, Sx],
        }
    }

    /// Whether each row is contiguous in the file (streamed), rather than spread over it.
    pub fn streams(self) -> bool {
        matches!(self, Self::Rows7 | Self::Rows5)
    }

    /// y-tal's test on the shape of `data`.
    fn detect(dims: &[usize]) -> Option<Self> {
        match dims.len() {
            7 if dims[4] == 6 => Some(Self::Rows7),
            7 if dims[2] == 6 => Some(Self::Time7),
            5 if dims[0] == dims[1] => Some(Self::Rows5),
            5 if dims[3] == dims[4] => Some(Self::Time5),
            _ => None,
        }
    }
}

/// What an axis of `data` holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Axis {
    C,
    T,
    B,
    Lx,
    Ly,
    Sx,
    Sy,
}

/// An open Z-NLOS capture that reads laser rows on demand ([`RowSource`]).
pub struct ZnlosReader {
    path: PathBuf,
    h: Dataset,
    elem: Elem,
    dims: Vec<usize>,
    layout: ZnlosLayout,
    scan: ScanType,
    geometry: Geometry,
    single_falloff: Option<f64>,
    /// For each axis of `data`: the row axis it is (0 x, 1 y), if any.
    row_axis: Vec<Option<usize>>,
    /// For each axis of `data`: its stride in the capture `[l][s][n]` without the row part
    /// (0 for colours and bounces, which are summed).
    strides: Vec<usize>,
    /// Rows per row-x index (the row grid's second size).
    row_ny: usize,
    /// File address of a contiguous little-endian `data` (positional reads), else `None`.
    raw: Option<u64>,
    /// The rows read last and the background reader.
    rows: Cursor,
    /// Bytes of `data` read at once ([`super::BLOCK_BYTES`]; smaller in tests).
    block_bytes: usize,
    conventions: Vec<String>,
}

impl std::fmt::Debug for ZnlosReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZnlosReader")
            .field("path", &self.path)
            .field("dims", &self.dims)
            .field("layout", &self.layout)
            .field("scan", &self.scan)
            .finish_non_exhaustive()
    }
}

/// Opens a Z-NLOS capture, with the default [`TalOptions`].
///
/// # Errors
/// [`Error::Io`] if the file cannot be opened, [`Error::Format`] naming the dataset for
/// anything malformed, [`Error::Memory`](crate::Error) over the budget.
pub fn open(path: &Path) -> Result<ZnlosReader> {
    open_with(path, TalOptions::default())
}

/// Opens a Z-NLOS capture.
///
/// # Errors
/// As [`open`].
pub fn open_with(path: &Path, options: TalOptions) -> Result<ZnlosReader> {
    ZnlosReader::new(path, options)
}

/// Reads a whole Z-NLOS capture into memory, with the default [`TalOptions`].
///
/// # Errors
/// As [`open`], plus read errors.
pub fn read_all(path: &Path) -> Result<Capture> {
    open(path)?.into_capture()
}

/// [`grid_xy3`] of a dataset the file may lack (the grid normals): `None` when absent or
/// a null dataset.
fn optional_grid_xy3(f: &Fields<'_>, name: &'static str, want: [usize; 2]) -> Result<Option<Grid>> {
    if f.has(name) && !f.is_null(name) {
        grid_xy3(f, name, want).map(Some)
    } else {
        Ok(None)
    }
}

/// A grid as y-tal's `conv_to_xy3` leaves it: transposed when its first axis has 3 elements,
/// then `(X, Y, 3)`; except that a grid already `(X, Y, 3)` for `data`'s axes `want` and not
/// `(3, Y, X)` is kept (y-tal would garble it: module docs, *Datasets*).
fn grid_xy3(f: &Fields<'_>, name: &'static str, want: [usize; 2]) -> Result<Grid> {
    let (v, shape, _) = f.numbers(name)?;
    let as_is = shape[..] == [want[0], want[1], 3];
    let transposed = shape[..] == [3, want[1], want[0]];
    let (v, shape) = if shape.first() == Some(&3) && shape.len() > 1 && (transposed || !as_is) {
        // Reverse all axes: new[i₀..i_{k−1}] = old[i_{k−1}..i₀].
        let rev: Vec<usize> = shape.iter().rev().copied().collect();
        let old_strides = c_strides(&shape);
        let mut out = Vec::with_capacity(v.len());
        let mut idx = vec![0usize; rev.len()];
        for _ in 0..v.len() {
            let off: usize = idx
                .iter()
                .zip(old_strides.iter().rev())
                .map(|(i, s)| i * s)
                .sum();
            out.push(v[off]);
            for k in (0..idx.len()).rev() {
                idx[k] += 1;
                if idx[k] < rev[k] {
                    break;
                }
                idx[k] = 0;
            }
        }
        (out, rev)
    } else {
        (v, shape)
    };
    let [nx, ny, 3] = shape[..] else {
        return Err(Error::format(
            f.path,
            name,
            "a grid of shape (X, Y, 3) or (3, Y, X)",
            format!("shape {shape:?}"),
        ));
    };
    Ok(Grid {
        points: v
            .chunks_exact(3)
            .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32])
            .collect(),
        shape: [nx, ny],
        xy: true,
        field: name,
    })
}

fn c_strides(dims: &[usize]) -> Vec<usize> {
    let mut s = vec![1usize; dims.len()];
    for k in (0..dims.len().saturating_sub(1)).rev() {
        s[k] = s[k + 1].saturating_mul(dims[k + 1]);
    }
    s
}

impl ZnlosReader {
    fn new(path: &Path, options: TalOptions) -> Result<Self> {
        let (file, names) = open_file(path)?;
        let f = Fields {
            path,
            file: &file,
            names: &names,
            kind: "Z-NLOS",
        };
        let h = f.dataset("data")?;
        let dims: Vec<usize> = h.shape().iter().map(|&d| usize_of(d)).collect();
        let layout = ZnlosLayout::detect(&dims).ok_or_else(|| {
            Error::format(
                path,
                "data",
                "a Z-NLOS shape y-tal recognises: 7 axes with 6 bounces at axis 4 or 2, or 5 axes with two equal grid axes first or last",
                format!("shape {dims:?}"),
            )
        })?;
        let elem = Elem::of(&h, path, "data")?;
        let elem_bytes: usize = if elem == Elem::F32 { 4 } else { 8 };
        let h_bytes = dims.iter().try_fold(elem_bytes, |a, &d| a.checked_mul(d));
        let file_len = std::fs::metadata(path)
            .map_err(|e| Error::io(path, e))?
            .len();
        if h.chunks().is_none() && h_bytes.is_none_or(|b| b as u64 > file_len) {
            return Err(Error::format(
                path,
                "data",
                format!("at most {file_len} bytes of data (the file's size)"),
                format!("shape {dims:?} of {elem_bytes}-byte values"),
            ));
        }
        let contiguous =
            check_layout(path, &file, &h, h_bytes, file_len).map_err(|e| rename(e, "data"))?;
        // Positional reads of a contiguous little-endian `data`; anything else goes through
        // the crate.
        let raw = match h.dtype() {
            Datatype::FloatingPoint {
                byte_order: ByteOrder::LittleEndian,
                ..
            } => contiguous,
            _ => None,
        };
        let roles = layout.roles();
        let size = |a: Axis| roles.iter().position(|&r| r == a).map_or(1, |k| dims[k]);
        let (nt, lx, ly, sx, sy) = (
            size(Axis::T),
            size(Axis::Lx),
            size(Axis::Ly),
            size(Axis::Sx),
            size(Axis::Sy),
        );
        let seven = dims.len() == 7;
        let (format, lead) = if seven && lx * ly != 1 {
            (HFormat::TLxLySxSy, vec![lx, ly, sx, sy])
        } else {
            (HFormat::TSxSy, vec![sx, sy])
        };
        let meta = scan::Meta {
            format,
            lead,
            nt,
            lgrid: grid_xy3(&f, "laserGridPositions", [lx, ly])?,
            sgrid: grid_xy3(&f, "cameraGridPositions", [sx, sy])?,
            laser_xyz: f.xyz("laserPosition")?,
            sensor_xyz: f.xyz("cameraPosition")?,
            dt: f.float_scalar("deltaT")?,
            t_start: f.float_scalar("t0")?,
            legs_in_time: true,
            xyz_names: ["laserPosition", "cameraPosition"],
            // As y-tal's converter: `laserGridNormals`/`cameraGridNormals` become the tal
            // grids' normals, laid out as the positions (absent or null: +z).
            normals: [
                optional_grid_xy3(&f, "laserGridNormals", [lx, ly])?,
                optional_grid_xy3(&f, "cameraGridNormals", [sx, sy])?,
            ],
        };
        let (dt, t_start) = (meta.dt, meta.t_start);
        let scan::Scan {
            scan,
            geometry,
            single_falloff,
        } = scan::build(path, meta, options).map_err(znlos_names)?;

        // Rows run over the laser grid (exhaustive) or the camera grid (confocal, single);
        // each row holds the camera grid (exhaustive) or one histogram.
        let exhaustive = scan == ScanType::Exhaustive;
        let (rx, ry) = if exhaustive {
            (Axis::Lx, Axis::Ly)
        } else {
            (Axis::Sx, Axis::Sy)
        };
        let row_ny = size(ry);
        let row_axis: Vec<Option<usize>> = roles
            .iter()
            .map(|&a| {
                if a == rx {
                    Some(0)
                } else if a == ry {
                    Some(1)
                } else {
                    None
                }
            })
            .collect();
        let strides: Vec<usize> = roles
            .iter()
            .map(|&a| match a {
                Axis::T => 1,
                Axis::Sx if exhaustive => sy * nt,
                Axis::Sy if exhaustive => nt,
                _ => 0,
            })
            .collect();

        let mut reader = Self {
            path: path.to_path_buf(),
            h,
            elem,
            dims,
            layout,
            scan,
            geometry,
            single_falloff,
            row_axis,
            strides,
            row_ny,
            raw,
            rows: Cursor::default(),
            block_bytes: BLOCK_BYTES,
            conventions: Vec::new(),
        };
        let (dims, src) = (&reader.dims, reader.source());
        let memory = src.memory();
        let how = if raw.is_some() {
            "positional reads"
        } else {
            "hyperslabs through the crate"
        };
        let what = if layout.streams() {
            format!(
                "streamed by row, in blocks of {} rows read ({how}) and summed by a background reader; at most {} MB",
                src.block_rows().min(src.kl),
                fmt_mb(memory)
            )
        } else {
            format!(
                "read whole on the first row (the row axes come last in the file; {how}) and summed into the capture as f32 ({} MB), then handed out by blocks of {} rows by a background reader; at most {} MB",
                fmt_mb((src.kl * src.ks * src.nt * 4) as u128),
                src.block_rows().min(src.kl),
                fmt_mb(memory)
            )
        };
        budget::check(
            || {
                format!(
                    "Z-NLOS data of shape {dims:?} read from {} ({what})",
                    path.display()
                )
            },
            memory,
        )?;
        let conventions = vec![
            format!("axis order   {} {} (y-tal's moveaxis)", layout.axes(), {
                let d: Vec<String> = dims.iter().map(usize::to_string).collect();
                format!("= {}", d.join(" x "))
            }),
            format!(
                "summed       colours and bounces; tal H_format {} as y-tal converts it",
                format.tal_name()
            ),
            format!(
                "time axis    deltaT = {dt} m and t0 = {t_start} m of optical path (y-tal delta_t, t_start); bin k at t0 + k deltaT{}",
                if options.bin_centre {
                    " + deltaT/2 (bin centre)"
                } else {
                    ""
                }
            ),
            "device legs  included in the times (t_accounts_first_and_last_bounces = true): |laserPosition - x_l| + |x_s - cameraPosition| is subtracted from each path by the probes".to_string(),
            "grids        cameraGridPositions, laserGridPositions and their *GridNormals as (X, Y, 3) (transposed when stored (3, Y, X)); hiddenVolume* not used".to_string(),
            format!("memory       {what}"),
        ];
        reader.conventions = conventions;
        Ok(reader)
    }

    /// What the background reader needs.
    fn source(&self) -> Source {
        Source {
            path: self.path.clone(),
            h: self.h.clone(),
            elem: self.elem,
            dims: self.dims.clone(),
            raw: self.raw,
            streams: self.layout.streams(),
            kl: self.geometry.lasers.len(),
            ks: self.geometry.spads_per_row(),
            nt: self.geometry.nt,
            row_axis: self.row_axis.clone(),
            strides: self.strides.clone(),
            row_ny: self.row_ny,
            block_bytes: self.block_bytes,
        }
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The axis order found.
    pub fn layout(&self) -> ZnlosLayout {
        self.layout
    }

    /// The scan type (as y-tal's converted capture has it).
    pub fn scan_type(&self) -> ScanType {
        self.scan
    }

    /// The shape of `data` as stored.
    pub fn data_shape(&self) -> &[usize] {
        &self.dims
    }

    /// One line per convention applied (axis order, sums, time axis, legs, grids, memory).
    pub fn conventions(&self) -> &[String] {
        &self.conventions
    }

    /// Reads every row into a [`Capture`].
    ///
    /// # Errors
    /// Read errors; [`Error::Format`] if the capture does not fit in memory.
    pub fn into_capture(mut self) -> Result<Capture> {
        let (path, dims) = (self.path.clone(), self.dims.clone());
        super::read_whole(&mut self, &path, "data", &dims, 4)
    }
}

fn fmt_mb(bytes: u128) -> String {
    format!("{:.1}", bytes as f64 / 1e6)
}

/// An error of the shared checks, with `H` named as this layout names it.
fn rename(e: Error, to: &str) -> Error {
    match e {
        Error::Format {
            path,
            field,
            expected,
            found,
        } if field == "H" => Error::Format {
            path,
            field: to.to_string(),
            expected,
            found,
        },
        other => other,
    }
}

/// The geometry's errors name tal's fields: name the Z-NLOS datasets instead.
fn znlos_names(e: Error) -> Error {
    match e {
        Error::Format {
            path,
            field,
            expected,
            found,
        } => {
            let field = match field.as_str() {
                "laser_grid" | "laser_grid_xyz" => "laserGridPositions",
                "sensor_grid" | "sensor_grid_xyz" => "cameraGridPositions",
                "delta_t" => "deltaT",
                "t_start" => "t0",
                "H" => "data",
                other => other,
            }
            .to_string();
            Error::Format {
                path,
                field,
                expected,
                found,
            }
        }
        other => other,
    }
}

impl RowSource for ZnlosReader {
    fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        check_row(l, self.geometry.lasers.len())?;
        // The background reader summed the block's colours and bounces into rows of
        // SPAD-major histograms: the row is swapped into `out`, whose old buffer goes back.
        let src = self.source();
        let b = src.block_rows();
        let reader = || Blocks::new(src);
        self.rows
            .take(l, l / b * b, out, reader, &self.path, "data")?;
        let x_l = self.geometry.lasers[l];
        if let Some(c0) = self.single_falloff {
            let k = self.geometry.laser_falloff_at(l) / c0;
            out.iter_mut().for_each(|h| *h = (f64::from(*h) * k) as f32);
        }
        Ok(x_l)
    }
}

mod stream;

#[cfg(test)]
mod tests;
