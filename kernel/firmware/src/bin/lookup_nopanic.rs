//! Link-time proof (as `nopanic.rs`, panic-never) that the kernel's **lookup path** cannot
//! panic: `LookupGrid::try_new`, `Lookup::new`, `LookupProbe::new`/`push_row`/`merge`/
//! `finish`/`reset` for the diagonal and a column, `ColumnF32::new`/`push_row`/
//! `finish_lookup` (the factorised column's lookup finish, and its refusal of a short
//! scratch), `u16` and `f32` rows, and a refused
//! grid that is not a power of two or too coarse, with the inputs through `black_box` (any configuration, grid and
//! voxel list). Two SPADs of the fixture keep the statics within the microbit's 16 KB.
//! Exit status 0 = every call succeeded and the diagonal peaks at P1.
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
use vltm_firmware::fixture::{
    BINS, FOCUS, LASERS, N_FFT, N_VOXELS, NT, P1_VOXEL, ROW, SPADS, VOXELS, params,
};
use vltm_firmware::lookup_pipeline::{
    LOOKUP_SCRATCH_LEN, LOOKUP_STATE_LEN, LOOKUP_TABLES_LEN, lookup_params,
};
use vltm_firmware::pipeline::argmax;
use vltm_kernel::{
    ColumnF32, Config, Lookup, LookupGrid, LookupParams, LookupProbe, RowBuffer, Scan, Target,
};

/// SPADs used here.
const KS: usize = 2;
const TABLES: usize = 2 * N_FFT + BINS + KS;
const ROWBUF: usize = KS * (2 * BINS + 3);
/// `ColumnF32::state_len` for [`KS`] SPADs.
const COLUMN32: usize = (4 * KS + 2) * BINS;

#[entry]
fn main() -> ! {
    process::exit(run())
}

fn run() -> i32 {
    let (Some(tables), Some(rowbuf), Some(lt), Some(s1), Some(s2), Some(out)) = (
        singleton!(: [f32; TABLES] = [0.0; TABLES]),
        singleton!(: [f32; ROWBUF] = [0.0; ROWBUF]),
        singleton!(: [f32; LOOKUP_TABLES_LEN] = [0.0; LOOKUP_TABLES_LEN]),
        singleton!(: [f64; LOOKUP_STATE_LEN] = [0.0; LOOKUP_STATE_LEN]),
        singleton!(: [f64; LOOKUP_STATE_LEN] = [0.0; LOOKUP_STATE_LEN]),
        singleton!(: [f64; N_VOXELS] = [0.0; N_VOXELS]),
    ) else {
        return 7;
    };
    let (Some(sc1), Some(sc2), Some(hf), Some(c32), Some(out32)) = (
        singleton!(: [f32; LOOKUP_SCRATCH_LEN] = [0.0; LOOKUP_SCRATCH_LEN]),
        singleton!(: [f32; LOOKUP_SCRATCH_LEN] = [0.0; LOOKUP_SCRATCH_LEN]),
        singleton!(: [f32; KS * NT] = [0.0; KS * NT]),
        singleton!(: [f32; COLUMN32] = [0.0; COLUMN32]),
        singleton!(: [f32; N_VOXELS] = [0.0; N_VOXELS]),
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
    let ks = black_box(KS);
    let Some(spads) = black_box(&SPADS[..]).get(..ks) else {
        return 2;
    };
    let voxels = black_box(&VOXELS[..]);
    let Ok(scan) = Scan::new(&cfg, spads, black_box(&mut tables[..])) else {
        return 2;
    };
    let Ok(lookup) = Lookup::new(&grid, black_box(&mut lt[..])) else {
        return 2;
    };
    let Ok(mut rows) = RowBuffer::new(&scan, black_box(&mut rowbuf[..])) else {
        return 2;
    };
    let target = black_box(Target::Column(FOCUS));
    let (Ok(mut diag), Ok(mut col)) = (
        LookupProbe::new(
            &scan,
            &lookup,
            Target::Diagonal,
            voxels,
            black_box(&mut s1[..]),
            black_box(&mut sc1[..]),
        ),
        LookupProbe::new(
            &scan,
            &lookup,
            target,
            voxels,
            black_box(&mut s2[..]),
            black_box(&mut sc2[..]),
        ),
    ) else {
        return 2;
    };
    let Some(c32) = black_box(&mut c32[..]).get_mut(..ColumnF32::state_len(&cfg, ks)) else {
        return 2;
    };
    let Ok(mut col32) = ColumnF32::new(&scan, black_box(FOCUS), c32) else {
        return 2;
    };
    let nt = black_box(cfg.nt());
    let row_len = black_box(ROW);
    for (hists, laser) in data
        .chunks_exact(row_len.max(1))
        .zip(black_box(&LASERS[..]))
    {
        // The first Ks SPADs' histograms (SPAD-major rows).
        let Some(h) = hists.get(..ks * nt) else {
            return 2;
        };
        let Ok(row) = rows.load(&scan, *laser, h) else {
            return 2;
        };
        if diag.push_row(&scan, &lookup, &row).is_err()
            || col.push_row(&scan, &lookup, &row).is_err()
            || col32.push_row(&scan, &row).is_err()
        {
            return 2;
        }
    }
    // An f32 row (the first row's counts) into the column.
    for (f, c) in hf.iter_mut().zip(data) {
        *f = f32::from(*c);
    }
    let Ok(row) = rows.load(&scan, LASERS[0], &hf[..]) else {
        return 2;
    };
    if col.push_row(&scan, &lookup, &row).is_err() || col32.push_row(&scan, &row).is_err() {
        return 2;
    }
    // A grid that is not a power of two, or too coarse, is refused.
    for l in [black_box(100usize), black_box(8)] {
        let p = LookupParams {
            grid_len: Some(l),
            ..lookup_params()
        };
        if LookupGrid::try_new(&cfg, &p).is_ok() {
            return 6;
        }
    }
    if diag.finish(&mut out[..]).is_err() {
        return 2;
    }
    if argmax(&out[..]) != P1_VOXEL {
        return 3;
    }
    if diag.merge(&col).is_ok() {
        return 6;
    }
    col.reset();
    if col.finish(&mut out[..]).is_err() || out.iter().any(|x| *x != 0.0) {
        return 4;
    }
    // The factorised column's lookup finish, in the lookup column's scratch (free now); a
    // scratch one element short is refused.
    drop(col);
    let need = black_box(ColumnF32::lookup_scratch_len(&grid, voxels.len()));
    let (Some(short), Some(scratch)) = (
        black_box(&mut sc1[..]).get_mut(..need.saturating_sub(1)),
        black_box(&mut sc2[..]).get_mut(..need),
    ) else {
        return 2;
    };
    let out32 = black_box(&mut out32[..]);
    if col32
        .finish_lookup(&scan, &lookup, voxels, short, out32)
        .is_ok()
    {
        return 6;
    }
    match col32.finish_lookup(&scan, &lookup, voxels, scratch, out32) {
        Ok(r) if r.rows == black_box(LASERS.len() as u64 + 1) => {}
        _ => return 2,
    }
    if out32.iter().any(|x| !x.is_finite()) {
        return 5;
    }
    0
}
