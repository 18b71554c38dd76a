//! Link-time proof (as `nopanic.rs`, panic-never) that the kernel's **fixed-point** path cannot
//! panic: `FixedConfig::try_new`, `FixedScan::new`, `FixedRowBuffer::new`/`load`,
//! `FixedDiagonal`/`FixedColumn` `new`/`push_row` (including a refused row past the budget)/
//! `finish`, `FixedPhotons` `new`/`reset`/`push` (with out-of-range events)/`load_photons`,
//! the fixed-point lookup path (`FixedLookupGrid::try_new`, `FixedLookup::new`,
//! `FixedLookupProbe` `new`/`push_row` (with the refused row)/`finish`, diagonal and column),
//! with inputs through `black_box`. Exit status 0 = every call succeeded, the
//! diagonals (band and lookup) peak at P1 and the extra row was refused.
#![no_std]
#![no_main]

use core::hint::black_box;
use cortex_m::singleton;
use cortex_m_rt::entry;
#[cfg(not(feature = "find-panics"))]
use panic_never as _;

#[cfg(feature = "find-panics")]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
    process::exit(1)
}
use semihosting::process;
use vltm_firmware::fixed_pipeline::{
    FIXED_COLUMN_LEN, FIXED_DIAG_LEN, FIXED_LOOKUP_SCRATCH_LEN, FIXED_LOOKUP_TABLES_LEN,
    FIXED_PHOTONS_LEN, FIXED_ROW_LEN, FIXED_TABLES_LEN, LIMITS, fixed_lookup_params,
};
use vltm_firmware::fixture::{FOCUS, LASERS, N_VOXELS, P1_VOXEL, ROW, SPADS, VOXELS, params};
use vltm_firmware::pipeline::argmax;
use vltm_kernel::{
    Config, FixedColumn, FixedConfig, FixedDiagonal, FixedLookup, FixedLookupGrid,
    FixedLookupProbe, FixedPhotons, FixedRowBuffer, FixedScan, I1F15, Target,
};

#[entry]
fn main() -> ! {
    process::exit(run())
}

fn run() -> i32 {
    let (Some(tables), Some(rowbuf), Some(sd), Some(sc), Some(out)) = (
        singleton!(: [I1F15; FIXED_TABLES_LEN] = [I1F15::ZERO; FIXED_TABLES_LEN]),
        singleton!(: [i32; FIXED_ROW_LEN] = [0; FIXED_ROW_LEN]),
        singleton!(: [i64; FIXED_DIAG_LEN] = [0; FIXED_DIAG_LEN]),
        singleton!(: [i64; FIXED_COLUMN_LEN] = [0; FIXED_COLUMN_LEN]),
        singleton!(: [f64; N_VOXELS] = [0.0; N_VOXELS]),
    ) else {
        return 7;
    };
    let Some(data) = vltm_firmware::scan_data() else {
        return 2;
    };
    let Some(pbuf) = singleton!(: [i64; FIXED_PHOTONS_LEN] = [0; FIXED_PHOTONS_LEN]) else {
        return 7;
    };
    let (Some(lt), Some(ld), Some(ls)) = (
        singleton!(: [I1F15; FIXED_LOOKUP_TABLES_LEN] = [I1F15::ZERO; FIXED_LOOKUP_TABLES_LEN]),
        singleton!(: [i64; FIXED_DIAG_LEN] = [0; FIXED_DIAG_LEN]),
        singleton!(: [i32; FIXED_LOOKUP_SCRATCH_LEN] = [0; FIXED_LOOKUP_SCRATCH_LEN]),
    ) else {
        return 7;
    };
    let Ok(cfg) = Config::try_new(&black_box(params())) else {
        return 2;
    };
    let Ok(fc) = FixedConfig::try_new(&cfg, &black_box(LIMITS)) else {
        return 2;
    };
    let spads = black_box(&SPADS[..]);
    let voxels = black_box(&VOXELS[..]);
    let Ok(scan) = FixedScan::new(&fc, spads, black_box(&mut tables[..])) else {
        return 2;
    };
    let Ok(mut rows) = FixedRowBuffer::new(&scan, black_box(&mut rowbuf[..])) else {
        return 2;
    };
    let Ok(mut diag) = FixedDiagonal::new(voxels, black_box(&mut sd[..])) else {
        return 2;
    };
    let Ok(mut col) = FixedColumn::new(&scan, black_box(FOCUS), black_box(&mut sc[..])) else {
        return 2;
    };
    let Ok(grid) = FixedLookupGrid::try_new(&fc, &black_box(fixed_lookup_params())) else {
        return 2;
    };
    let Ok(lookup) = FixedLookup::new(&grid, black_box(&mut lt[..])) else {
        return 2;
    };
    let Ok(mut ldiag) = FixedLookupProbe::new(
        &lookup,
        black_box(Target::Diagonal),
        voxels,
        black_box(&mut ld[..]),
        black_box(&mut ls[..]),
    ) else {
        return 2;
    };
    let row_len = black_box(ROW);
    for (hists, laser) in data
        .chunks_exact(row_len.max(1))
        .zip(black_box(&LASERS[..]))
    {
        let Ok(row) = rows.load(&scan, *laser, hists) else {
            return 2;
        };
        if diag.push_row(&scan, &row).is_err()
            || col.push_row(&scan, &row).is_err()
            || ldiag.push_row(&scan, &lookup, &row).is_err()
        {
            return 2;
        }
    }
    // Photon events (the first row's counts, plus events that must be dropped), through
    // `load_photons`: the band spectra equal the histogram row's.
    let Some(first) = data.get(..row_len) else {
        return 2;
    };
    let Ok(mut photons) = FixedPhotons::new(&scan, black_box(&mut pbuf[..])) else {
        return 2;
    };
    photons.reset();
    let nt = black_box(cfg.nt()).max(1);
    for (i, &c) in first.iter().enumerate() {
        for _ in 0..c {
            photons.push(&scan, black_box(i / nt), black_box(i % nt));
        }
    }
    photons.push(&scan, black_box(usize::MAX), black_box(0));
    photons.push(&scan, black_box(0), black_box(usize::MAX));
    if photons.dropped() != 2 {
        return 5;
    }
    let mut band = [0i32; 8];
    {
        let Ok(prow) = rows.load_photons(&scan, LASERS[0], &photons) else {
            return 2;
        };
        for (b, x) in band.iter_mut().zip(prow.band()) {
            *b = *x;
        }
    }
    // One row past the budget is refused.
    let Ok(row) = rows.load(&scan, LASERS[0], first) else {
        return 2;
    };
    if row.band().iter().zip(band).any(|(a, b)| *a != b) {
        return 5;
    }
    if diag.push_row(&scan, &row).is_ok() || ldiag.push_row(&scan, &lookup, &row).is_ok() {
        return 6;
    }
    if ldiag.finish(&mut out[..]).is_err() {
        return 2;
    }
    if argmax(&out[..]) != P1_VOXEL {
        return 3;
    }
    // The lookup column on the same buffers (one row): covers its per-row path.
    let Ok(mut lcol) = FixedLookupProbe::new(
        &lookup,
        black_box(Target::Column(FOCUS)),
        voxels,
        black_box(&mut ld[..]),
        black_box(&mut ls[..]),
    ) else {
        return 2;
    };
    if lcol.push_row(&scan, &lookup, &row).is_err() || lcol.finish(&mut out[..]).is_err() {
        return 2;
    }
    if diag.finish(&fc, &mut out[..]).is_err() {
        return 2;
    }
    if argmax(&out[..]) != P1_VOXEL {
        return 3;
    }
    match col.finish(&scan, voxels, &mut out[..]) {
        Ok(0) => 0,
        _ => 4,
    }
}
