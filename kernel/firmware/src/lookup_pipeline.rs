//! The fixture through the kernel's **lookup path** ([`LookupProbe`]: a per-SPAD baseband grid
//! and cubic interpolation instead of the band sum), shared word for word by the firmware
//! (bin `vltm-firmware-lookup`) and the host generator (which writes
//! `fixture/expected_lookup.txt` from it), so both run the same kernel calls in the same order.
//!
//! Two passes over the scan (it is in flash), so that the three probes share one scratch:
//! per laser row [`RowBuffer::load`] → push to the lookup diagonal and the factorised `f32`
//! column [`ColumnF32`], then [`LookupProbe::finish`]; per laser row again → push to the
//! lookup column `T(FOCUS, ·)`, then its finish; last [`ColumnF32::finish_lookup`] (the
//! factorised column's lookup finish). Each probe sees the same rows in the same order as in
//! one pass, so the results are the same bits. The grid is made for the tolerance
//! [`LOOKUP_TOLERANCE`] (1e-4 here: `L` = 256).
//!
//! Then the **structured slice** ([`LookupSlice`]) on the same grid: a lattice of voxels
//! ([`SLICE_LATTICE`], 10 × 4 at z = 0.5 m, 5 cm along the SPAD line so that the fixture's SPADs
//! (10 cm apart) lie on it, 15 cm across; P1 and P2 are lattice voxels) as a diagonal and the
//! column `T(FOCUS, ·)`, one more pass over the scan each, in the same shared scratch
//! ([`SCRATCH_LEN`], the slice's: 18.7 KB).

use crate::fixture::{
    BINS, FOCUS, LASERS, N_FFT, N_LASERS, N_VOXELS, P1_VOXEL, P2_VOXEL, ROW, ROWBUF_LEN, SLICE,
    SPADS, TABLES_LEN, VOXELS, params,
};
use crate::pipeline::{Failure, argmax};
use vltm_kernel::{
    ColumnF32, Config, Interpolant, Lattice, Lookup, LookupGrid, LookupParams, LookupProbe,
    LookupSlice, Report, RowBuffer, Scan, SliceLayout, Target,
};

/// Interpolation tolerance `η` of the fixture's grid.
pub const LOOKUP_TOLERANCE: f64 = 1e-4;
/// Grid length `L` for [`params`] at [`LOOKUP_TOLERANCE`] (checked at run time).
pub const LOOKUP_GRID: usize = 256;
/// `Lookup::tables_len`: `4L` `f32`.
pub const LOOKUP_TABLES_LEN: usize = 4 * LOOKUP_GRID;
/// `LookupProbe::state_len`: `4Kv` `f32`.
pub const LOOKUP_STATE_LEN: usize = 4 * N_VOXELS;
/// `LookupProbe::scratch_len`: `2(L + 3) + 3Kv` `f32`.
pub const LOOKUP_SCRATCH_LEN: usize = 2 * (LOOKUP_GRID + 3) + 3 * N_VOXELS;

/// `ColumnF32::state_len`: `(4Ks + 2)·J` `f32`.
pub const COLUMN32_STATE_LEN: usize = (4 * SPADS.len() + 2) * BINS;
/// `ColumnF32::lookup_scratch_len`: `2(L + 3) + 2Kv` `f32` (a prefix of the column's
/// [`LOOKUP_SCRATCH_LEN`]).
pub const COLUMN32_SCRATCH_LEN: usize = 2 * (LOOKUP_GRID + 3) + 2 * N_VOXELS;

/// The structured slice: 10 × 4 voxels at z = 0.5 m, `x` from −0.225 m in 5 cm steps (the
/// SPADs, at x = −0.15 … 0.15 m every 10 cm, are lattice offsets 0, 2, 4, 6), `y` from
/// −0.225 m in 15 cm steps. Voxel `iy·10 + ix`; P1 is voxel [`SLICE_P1`], P2 [`SLICE_P2`].
pub const SLICE_LATTICE: Lattice = Lattice {
    origin: [-0.225, -0.225, 0.5],
    step_x: [0.05, 0.0, 0.0],
    step_y: [0.0, 0.15, 0.0],
    nx: 10,
    ny: 4,
};
/// Voxels of [`SLICE_LATTICE`].
pub const N_SLICE: usize = 40;
/// P1 in the slice: `(ix, iy) = (3, 1)`.
pub const SLICE_P1: usize = 13;
/// P2 in the slice: `(ix, iy) = (9, 2)`.
pub const SLICE_P2: usize = 29;
/// `SliceLayout::tables_len`: `4Ks + 4·ny·width` `f32`, `width = nx + 6` (checked at run
/// time).
pub const SLICE_TABLES_LEN: usize = 4 * SPADS.len() + 4 * 4 * (10 + 6);
/// `LookupSlice::state_len`: `4Kv` `f32`.
pub const SLICE_STATE_LEN: usize = 4 * N_SLICE;
/// `LookupSlice::scratch_len`: `2(L + 8) + 16L + 4Kv` `f32`.
pub const SLICE_SCRATCH_LEN: usize = 2 * (LOOKUP_GRID + 8) + 16 * LOOKUP_GRID + 4 * N_SLICE;
/// The shared scratch: the larger of [`LOOKUP_SCRATCH_LEN`] and [`SLICE_SCRATCH_LEN`].
pub const SCRATCH_LEN: usize = if SLICE_SCRATCH_LEN > LOOKUP_SCRATCH_LEN {
    SLICE_SCRATCH_LEN
} else {
    LOOKUP_SCRATCH_LEN
};

/// The lookup parameters of the fixture.
pub const fn lookup_params() -> LookupParams {
    LookupParams {
        tolerance: LOOKUP_TOLERANCE,
        grid_len: None,
        ..LookupParams::new()
    }
}

/// Caller-owned buffers of the lookup pipeline.
pub struct LookupBuffers<'a> {
    /// `Scan::tables_len` `f32`.
    pub tables: &'a mut [f32],
    /// `RowBuffer::len` `f32`.
    pub row: &'a mut [f32],
    /// `Lookup::tables_len` `f32`.
    pub lookup: &'a mut [f32],
    /// Diagonal state.
    pub diag: &'a mut [f32],
    /// Column state.
    pub column: &'a mut [f32],
    /// Scratch of the diagonal, then of the column, then of the factorised column's
    /// `finish_lookup`, then of the slice's diagonal and column ([`SCRATCH_LEN`]).
    pub scratch: &'a mut [f32],
    /// Factorised `f32` column state ([`COLUMN32_STATE_LEN`]).
    pub column32: &'a mut [f32],
    /// The slice tables ([`SLICE_TABLES_LEN`]), filled by each slice probe.
    pub slice_tables: &'a mut [f32],
    /// The slice state ([`SLICE_STATE_LEN`]), the diagonal's then the column's.
    pub slice_state: &'a mut [f32],
}

/// Intensities `T = |A|²` per voxel from the lookup path, and the reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LookupResults {
    /// Lookup diagonal `T(v, v)`.
    pub diag: [f64; N_VOXELS],
    /// Lookup column `T(FOCUS, v)`.
    pub col: [f64; N_VOXELS],
    /// Report of the diagonal.
    pub report_diag: Report,
    /// Report of the column.
    pub report_col: Report,
    /// Factorised `f32` column `T(FOCUS, v)` by [`ColumnF32::finish_lookup`].
    pub col32: [f32; N_VOXELS],
    /// Its report.
    pub report_col32: Report,
    /// Slice diagonal `T(v, v)` over [`SLICE_LATTICE`] ([`LookupSlice`]).
    pub slice_diag: [f64; N_SLICE],
    /// Slice column `T(FOCUS, v)` over [`SLICE_LATTICE`].
    pub slice_col: [f64; N_SLICE],
    /// Report of the slice diagonal.
    pub report_slice_diag: Report,
    /// Report of the slice column.
    pub report_slice_col: Report,
    /// Slice diagonal with Hermite cells (`Interpolant::Hermite`, its own grid for the same
    /// tolerance).
    pub slice_diag_h: [f64; N_SLICE],
    /// Slice column with Hermite cells.
    pub slice_col_h: [f64; N_SLICE],
    /// Report of the Hermite slice diagonal.
    pub report_slice_diag_h: Report,
    /// Report of the Hermite slice column.
    pub report_slice_col_h: Report,
}

const ZERO_REPORT: Report = Report {
    rows: 0,
    non_finite: 0,
    dropped: 0,
    aliased: 0,
};

impl LookupResults {
    /// All zeros (a `const`, so a `static` of it lives in `.bss`).
    pub const ZERO: Self = Self {
        diag: [0.0; N_VOXELS],
        col: [0.0; N_VOXELS],
        report_diag: ZERO_REPORT,
        report_col: ZERO_REPORT,
        col32: [0.0; N_VOXELS],
        report_col32: ZERO_REPORT,
        slice_diag: [0.0; N_SLICE],
        slice_col: [0.0; N_SLICE],
        report_slice_diag: ZERO_REPORT,
        report_slice_col: ZERO_REPORT,
        slice_diag_h: [0.0; N_SLICE],
        slice_col_h: [0.0; N_SLICE],
        report_slice_diag_h: ZERO_REPORT,
        report_slice_col_h: ZERO_REPORT,
    };
}

/// The structured slice's buffers for one pass: its tables, state and scratch.
struct SliceBuffers<'a> {
    tables: &'a mut [f32],
    state: &'a mut [f32],
    scratch: &'a mut [f32],
}

/// The structured slice over the scan, one pass per target (the diagonal, then the column
/// `T(FOCUS, ·)`), each with fresh tables, state and scratch in `buf`: the values and report
/// of each into `outs` (diagonal first).
fn slice_passes(
    scan: &Scan<'_>,
    lookup: &Lookup<'_>,
    layout: &SliceLayout,
    rows: &mut RowBuffer<'_>,
    scan_data: &[u16],
    buf: SliceBuffers<'_>,
    outs: [(&mut [f64; N_SLICE], &mut Report); 2],
) -> Result<(), Failure> {
    for (target, (values, report)) in [Target::Diagonal, Target::Column(FOCUS)]
        .into_iter()
        .zip(outs)
    {
        let mut slice = LookupSlice::new(
            scan,
            lookup,
            layout,
            target,
            &mut *buf.tables,
            &mut *buf.state,
            &mut *buf.scratch,
        )?;
        for (hists, laser) in scan_data.chunks_exact(ROW).zip(LASERS) {
            let row = rows.load(scan, laser, hists)?;
            slice.push_row(scan, lookup, &row)?;
        }
        *report = slice.finish(values)?;
    }
    Ok(())
}

/// Runs the fixture scan through the lookup diagonal and column into `out`.
///
/// # Errors
/// [`Failure`] if a buffer, the grid or the scan data does not fit the configuration.
pub fn run_lookup(
    scan_data: &[u16],
    b: LookupBuffers<'_>,
    out: &mut LookupResults,
) -> Result<(), Failure> {
    let cfg = Config::try_new(&params()).map_err(Failure::Config)?;
    if cfg.bins() != BINS || cfg.n_fft() != N_FFT {
        return Err(Failure::Sizes);
    }
    let grid = LookupGrid::try_new(&cfg, &lookup_params()).map_err(Failure::Config)?;
    if grid.len() != LOOKUP_GRID || b.tables.len() != TABLES_LEN || b.row.len() != ROWBUF_LEN {
        return Err(Failure::Sizes);
    }
    if scan_data.len() != N_LASERS * ROW {
        return Err(Failure::ScanData);
    }
    let scan = Scan::new(&cfg, &SPADS, b.tables)?;
    let layout =
        SliceLayout::try_new(&scan, &grid, &SLICE_LATTICE, usize::MAX).map_err(Failure::Config)?;
    if layout.tables_len() != SLICE_TABLES_LEN || SLICE_LATTICE.len() != N_SLICE {
        return Err(Failure::Sizes);
    }
    let lookup = Lookup::new(&grid, &mut *b.lookup)?;
    let mut rows = RowBuffer::new(&scan, b.row)?;
    let mut col32 = ColumnF32::new(&scan, FOCUS, b.column32)?;
    let scratch = b
        .scratch
        .get_mut(..LOOKUP_SCRATCH_LEN)
        .ok_or(Failure::Sizes)?;
    let mut diag = LookupProbe::new(
        &scan,
        &lookup,
        Target::Diagonal,
        &VOXELS,
        b.diag,
        &mut *scratch,
    )?;
    for (hists, laser) in scan_data.chunks_exact(ROW).zip(LASERS) {
        let row = rows.load(&scan, laser, hists)?;
        diag.push_row(&scan, &lookup, &row)?;
        col32.push_row(&scan, &row)?;
    }
    out.report_diag = diag.finish(&mut out.diag)?;
    drop(diag);
    let mut col = LookupProbe::new(
        &scan,
        &lookup,
        Target::Column(FOCUS),
        &VOXELS,
        b.column,
        &mut *scratch,
    )?;
    for (hists, laser) in scan_data.chunks_exact(ROW).zip(LASERS) {
        let row = rows.load(&scan, laser, hists)?;
        col.push_row(&scan, &lookup, &row)?;
    }
    out.report_col = col.finish(&mut out.col)?;
    drop(col);
    let scratch32 = scratch
        .get_mut(..COLUMN32_SCRATCH_LEN)
        .ok_or(Failure::Sizes)?;
    out.report_col32 = col32.finish_lookup(&scan, &lookup, &VOXELS, scratch32, &mut out.col32)?;
    // The structured slice: one pass per target, each with fresh tables, state and scratch.
    let scratch = b
        .scratch
        .get_mut(..SLICE_SCRATCH_LEN)
        .ok_or(Failure::Sizes)?;
    slice_passes(
        &scan,
        &lookup,
        &layout,
        &mut rows,
        scan_data,
        SliceBuffers {
            tables: &mut *b.slice_tables,
            state: &mut *b.slice_state,
            scratch: &mut *scratch,
        },
        [
            (&mut out.slice_diag, &mut out.report_slice_diag),
            (&mut out.slice_col, &mut out.report_slice_col),
        ],
    )?;
    // The slice again with Hermite cells, on the grid they need for the same tolerance (the
    // lookup tables rebuilt in the same buffer).
    drop(lookup);
    let p = LookupParams {
        interpolant: Interpolant::Hermite,
        ..lookup_params()
    };
    let grid = LookupGrid::try_new(&cfg, &p).map_err(Failure::Config)?;
    let tables = b
        .lookup
        .get_mut(..Lookup::tables_len(&grid))
        .ok_or(Failure::Sizes)?;
    let lookup = Lookup::new(&grid, tables)?;
    let layout = SliceLayout::try_new(&scan, &grid, &SLICE_LATTICE, SLICE_TABLES_LEN)
        .map_err(Failure::Config)?;
    let scratch = scratch
        .get_mut(..LookupSlice::scratch_len(&grid, N_SLICE))
        .ok_or(Failure::Sizes)?;
    slice_passes(
        &scan,
        &lookup,
        &layout,
        &mut rows,
        scan_data,
        SliceBuffers {
            tables: b.slice_tables,
            state: b.slice_state,
            scratch,
        },
        [
            (&mut out.slice_diag_h, &mut out.report_slice_diag_h),
            (&mut out.slice_col_h, &mut out.report_slice_col_h),
        ],
    )?;
    Ok(())
}

/// The lookup firmware's own checks (the exit status); 0 = passed. 3: a diagonal (the voxel
/// list's or the slice's) does not peak at P1; 4: in the z = 0.5 m plane without P1 (and, on
/// the slice, its neighbours within 10 cm) a column does not peak at P2; 6: a report is off.
pub fn verdict_lookup(r: &LookupResults) -> i32 {
    if argmax(&r.diag) != P1_VOXEL {
        return 3;
    }
    let mut slice = [0.0f64; SLICE];
    for ((s, c), i) in slice.iter_mut().zip(r.col).zip(0..) {
        *s = if i == P1_VOXEL { 0.0 } else { c };
    }
    if argmax(&slice) != P2_VOXEL {
        return 4;
    }
    let mut slice32 = [0.0f64; SLICE];
    for ((s, c), i) in slice32.iter_mut().zip(r.col32).zip(0..) {
        *s = if i == P1_VOXEL { 0.0 } else { f64::from(c) };
    }
    if argmax(&slice32) != P2_VOXEL {
        return 4;
    }
    for (diag, col) in [
        (&r.slice_diag, &r.slice_col),
        (&r.slice_diag_h, &r.slice_col_h),
    ] {
        if argmax(diag) != SLICE_P1 {
            return 3;
        }
        // On the slice's 5 cm pitch the voxels within 10 cm of P1 along x (lattice row 1,
        // ix 1..=5) see P1's direct light through the column's gate (σ = 2λ/3 ≈ 6.7 cm):
        // left out.
        let mut plane = *col;
        for (i, p) in plane.iter_mut().enumerate() {
            let (ix, iy) = (i % SLICE_LATTICE.nx, i / SLICE_LATTICE.nx);
            if iy == SLICE_P1 / SLICE_LATTICE.nx && ix.abs_diff(SLICE_P1 % SLICE_LATTICE.nx) <= 2 {
                *p = 0.0;
            }
        }
        if argmax(&plane) != SLICE_P2 {
            return 4;
        }
    }
    for rep in [
        r.report_diag,
        r.report_col,
        r.report_col32,
        r.report_slice_diag,
        r.report_slice_col,
        r.report_slice_diag_h,
        r.report_slice_col_h,
    ] {
        if rep.rows != N_LASERS as u64 || rep.non_finite != 0 || rep.dropped != 0 {
            return 6;
        }
    }
    0
}
