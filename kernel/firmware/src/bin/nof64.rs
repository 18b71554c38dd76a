//! The **no soft `f64`** check of the M4F's per-row and per-scan paths (bin
//! `vltm-firmware-nof64`, feature `nopanic`, so it is also a panic-never link of them): the
//! set-up (configuration, tables — `f64` `libm` by design) runs in `main`; the per-row path
//! (`RowBuffer::load`, `ColumnF32::push_row`, the photon row `begin_photons` /
//! `push_photon` / `end_photons`, the structured slice's `LookupSlice::push_row` and the
//! general lookup path's `LookupProbe::push_row`, their targets through `black_box` so both
//! the diagonal's and the column's code are reachable) and the per-scan path
//! (`ColumnF32::finish`, `ColumnF32::finish_lookup`, `LookupProbe::finish_f32`) run in two
//! `#[inline(never)]` functions, [`per_row`] and
//! [`per_scan`]. `no-f64.sh` disassembles the ELF, follows every call and branch from those
//! two functions, and fails if a soft-double routine (`__aeabi_d*`, `__*df*`) or an `f64`
//! `libm` function is reachable. Exit status 0 = every call succeeded.
#![no_std]
#![no_main]

use core::hint::black_box;
use cortex_m::singleton;
use cortex_m_rt::entry;
use panic_never as _;
use semihosting::process;
use vltm_firmware::fixture::{
    BINS, FOCUS, LASERS, N_FFT, N_VOXELS, NT, ROW, SPADS, VOXELS, params,
};
use vltm_firmware::lookup_pipeline::{
    LOOKUP_GRID, LOOKUP_SCRATCH_LEN, LOOKUP_STATE_LEN, LOOKUP_TABLES_LEN, SLICE_LATTICE,
    SLICE_SCRATCH_LEN, SLICE_STATE_LEN, SLICE_TABLES_LEN, lookup_params,
};
use vltm_kernel::{
    ColumnF32, Config, Lookup, LookupGrid, LookupProbe, LookupSlice, Point, Report, RowBuffer,
    Scan, SliceLayout, Target,
};

/// SPADs used here (the fixture's four).
const KS: usize = 4;
const TABLES: usize = 2 * N_FFT + BINS + KS;
const ROWBUF: usize = KS * (2 * BINS + 3);
const COLUMN32: usize = (4 * KS + 2) * BINS;
/// `ColumnF32::lookup_scratch_len`.
const SCRATCH: usize = 2 * (LOOKUP_GRID + 3) + 2 * N_VOXELS;

/// One laser row into the column, from histograms and again from photon events, and into
/// the structured slice and the general lookup probe (histogram row).
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn per_row(
    scan: &Scan<'_>,
    lookup: &Lookup<'_>,
    rows: &mut RowBuffer<'_>,
    col: &mut ColumnF32<'_>,
    slice: &mut LookupSlice<'_>,
    probe: &mut LookupProbe<'_>,
    hists: &[u16],
    laser: Point,
) -> bool {
    let Ok(row) = rows.load(scan, laser, hists) else {
        return false;
    };
    if col.push_row(scan, &row).is_err()
        || slice.push_row(scan, lookup, &row).is_err()
        || probe.push_row(scan, lookup, &row).is_err()
    {
        return false;
    }
    rows.begin_photons();
    for (s, h) in hists.chunks_exact(NT).enumerate() {
        for (n, &c) in h.iter().enumerate() {
            for _ in 0..c {
                rows.push_photon(scan, s, n);
            }
        }
    }
    let Ok(row) = rows.end_photons(scan, laser) else {
        return false;
    };
    col.push_row(scan, &row).is_ok()
}

/// The column's two finishes over the voxels, and the general lookup probe's `f32` finish.
#[inline(never)]
fn per_scan(
    scan: &Scan<'_>,
    lookup: &Lookup<'_>,
    col: &ColumnF32<'_>,
    probe: &LookupProbe<'_>,
    voxels: &[Point],
    scratch: &mut [f32],
    out: &mut [f32],
) -> Option<(Report, Report, Report)> {
    let band = col.finish(scan, voxels, out).ok()?;
    let fast = col.finish_lookup(scan, lookup, voxels, scratch, out).ok()?;
    let general = probe.finish_f32(out).ok()?;
    Some((band, fast, general))
}

#[entry]
fn main() -> ! {
    process::exit(run())
}

fn run() -> i32 {
    let (Some(tables), Some(rowbuf), Some(lt), Some(c32), Some(scratch), Some(out)) = (
        singleton!(: [f32; TABLES] = [0.0; TABLES]),
        singleton!(: [f32; ROWBUF] = [0.0; ROWBUF]),
        singleton!(: [f32; LOOKUP_TABLES_LEN] = [0.0; LOOKUP_TABLES_LEN]),
        singleton!(: [f32; COLUMN32] = [0.0; COLUMN32]),
        singleton!(: [f32; SCRATCH] = [0.0; SCRATCH]),
        singleton!(: [f32; N_VOXELS] = [0.0; N_VOXELS]),
    ) else {
        return 7;
    };
    let (Some(st), Some(ss), Some(sc)) = (
        singleton!(: [f32; SLICE_TABLES_LEN] = [0.0; SLICE_TABLES_LEN]),
        singleton!(: [f32; SLICE_STATE_LEN] = [0.0; SLICE_STATE_LEN]),
        singleton!(: [f32; SLICE_SCRATCH_LEN] = [0.0; SLICE_SCRATCH_LEN]),
    ) else {
        return 7;
    };
    let (Some(ps), Some(pc)) = (
        singleton!(: [f32; LOOKUP_STATE_LEN] = [0.0; LOOKUP_STATE_LEN]),
        singleton!(: [f32; LOOKUP_SCRATCH_LEN] = [0.0; LOOKUP_SCRATCH_LEN]),
    ) else {
        return 7;
    };
    let Some(data) = vltm_firmware::scan_data() else {
        return 2;
    };
    let Ok(cfg) = Config::try_new(&black_box(params())) else {
        return 2;
    };
    let Ok(grid) = LookupGrid::try_new(&cfg, &black_box(lookup_params())) else {
        return 2;
    };
    let Ok(scan) = Scan::new(&cfg, black_box(&SPADS[..]), &mut tables[..]) else {
        return 2;
    };
    let Ok(lookup) = Lookup::new(&grid, &mut lt[..]) else {
        return 2;
    };
    let (Ok(mut rows), Ok(mut col)) = (
        RowBuffer::new(&scan, &mut rowbuf[..]),
        ColumnF32::new(&scan, black_box(FOCUS), &mut c32[..]),
    ) else {
        return 2;
    };
    let Ok(layout) = SliceLayout::try_new(&scan, &grid, &black_box(SLICE_LATTICE), usize::MAX)
    else {
        return 2;
    };
    let target = black_box(Target::Column(FOCUS));
    let Ok(mut slice) = LookupSlice::new(
        &scan,
        &lookup,
        &layout,
        target,
        &mut st[..],
        &mut ss[..],
        &mut sc[..],
    ) else {
        return 2;
    };
    let voxels = black_box(&VOXELS[..]);
    let target = black_box(Target::Diagonal);
    let Ok(mut probe) = LookupProbe::new(&scan, &lookup, target, voxels, &mut ps[..], &mut pc[..])
    else {
        return 2;
    };
    for (hists, laser) in data.chunks_exact(ROW).zip(black_box(&LASERS[..])) {
        if !per_row(
            &scan, &lookup, &mut rows, &mut col, &mut slice, &mut probe, hists, *laser,
        ) {
            return 2;
        }
    }
    if slice.report().rows != LASERS.len() as u64 {
        return 3;
    }
    match per_scan(
        &scan,
        &lookup,
        &col,
        &probe,
        voxels,
        &mut scratch[..],
        &mut out[..],
    ) {
        Some((a, b, c))
            if a == b && a.rows == 2 * LASERS.len() as u64 && c.rows == LASERS.len() as u64 =>
        {
            0
        }
        _ => 3,
    }
}
