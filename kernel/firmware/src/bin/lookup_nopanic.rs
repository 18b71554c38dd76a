//! Link-time proof (as `nopanic.rs`, panic-never) that the kernel's **lookup path** cannot
//! panic: `LookupGrid::try_new`, `Lookup::new`, `LookupProbe::new`/`push_row`/`merge`/
//! `finish`/`reset` for the diagonal and a column, `ColumnF32::new`/`push_row`/
//! `finish_lookup` (the factorised column's lookup finish, and its refusal of a short
//! scratch), `u16` and `f32` rows, and a refused
//! grid that is not a power of two or too coarse, with the inputs through `black_box` (any configuration, grid and
//! voxel list); then the structured slice (`SliceLayout::try_new`, `LookupSlice::new`/
//! `push_row`/`finish`/`reset`/`amplitude`, a refused off-lattice SPAD line and a table that does
//! not fit) on a small configuration of its own (`L` = 32). Two SPADs of the fixture keep the
//! statics within the microbit's 16 KB.
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
    ColumnF32, Config, Interpolant, Lattice, Lookup, LookupGrid, LookupParams, LookupProbe,
    LookupSlice, Params, RowBuffer, Scan, SliceLayout, Target,
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

/// The structured slice's small configuration: Nt = 10, Δt = 5 cm, λ = 0.5 m, σ = λ/2,
/// m = c_g = 3 (N = 40, J = 9, `L` = 32 at tolerance 1e-2).
const S_NT: usize = 10;
/// Its largest grid and table sizes (checked at run time).
const S_L: usize = 32;
/// A 3 × 2 slice at the SPAD pitch (10 cm).
const S_LATTICE: Lattice = Lattice {
    origin: [-0.2, -0.1, 0.4],
    step_x: [0.1, 0.0, 0.0],
    step_y: [0.0, 0.1, 0.05],
    nx: 3,
    ny: 2,
};
const S_KV: usize = 6;
const S_SLICE_TABLES: usize = 4 * (KS + 2 * (3 + 1));
const S_STATE: usize = 4 * S_KV;
const S_SCRATCH: usize = 2 * (S_L + 8) + 16 * S_L + 4 * S_KV;
const _: () = assert!(4 * S_L + S_SLICE_TABLES + S_STATE + S_SCRATCH <= LOOKUP_TABLES_LEN);

/// The structured slice on the buffers of [`run`] (its probes are done with them): the
/// fixture's scan tables and row buffer, and its lookup tables split into the small grid's
/// tables, the slice tables, the state and the scratch.
fn run_slice(
    tables: &mut [f32],
    rowbuf: &mut [f32],
    lt: &mut [f32],
    out: &mut [f64],
    interpolant: Interpolant,
) -> i32 {
    let Some((lt, rest)) = lt.split_at_mut_checked(4 * S_L) else {
        return 20;
    };
    let Some((st, rest)) = rest.split_at_mut_checked(S_SLICE_TABLES) else {
        return 20;
    };
    let Some((s1, sc)) = rest.split_at_mut_checked(S_STATE) else {
        return 20;
    };
    let mut hb = [0u16; KS * S_NT];
    let h = &mut hb[..];
    let p = Params {
        sigma: Some(0.25),
        gate_support: 3.0,
        band_half_width: 3.0,
        ..Params::new(0.5, S_NT, 0.05)
    };
    let Ok(cfg) = Config::try_new(&black_box(p)) else {
        return 21;
    };
    let p = LookupParams {
        tolerance: 1e-2,
        grid_len: None,
        interpolant,
    };
    let Ok(grid) = LookupGrid::try_new(&cfg, &black_box(p)) else {
        return 22;
    };
    let ks = black_box(KS);
    let Some(spads) = black_box(&SPADS[..]).get(..ks) else {
        return 23;
    };
    let (Some(tables), Some(lt)) = (
        tables.get_mut(..Scan::tables_len(&cfg, ks)),
        lt.get_mut(..Lookup::tables_len(&grid)),
    ) else {
        return 24;
    };
    let Ok(scan) = Scan::new(&cfg, spads, black_box(tables)) else {
        return 25;
    };
    let Ok(lookup) = Lookup::new(&grid, black_box(lt)) else {
        return 26;
    };
    let Some(rowbuf) = rowbuf.get_mut(..RowBuffer::len(&cfg, ks)) else {
        return 27;
    };
    let Ok(mut rows) = RowBuffer::new(&scan, black_box(rowbuf)) else {
        return 28;
    };
    let lattice = black_box(S_LATTICE);
    // Off the lattice, and a table that does not fit: refused.
    let off = Lattice {
        step_x: [0.03, 0.0, 0.0],
        ..lattice
    };
    if SliceLayout::try_new(&scan, &grid, &black_box(off), usize::MAX).is_ok()
        || SliceLayout::try_new(&scan, &grid, &lattice, black_box(4)).is_ok()
    {
        return 16;
    }
    let Ok(layout) = SliceLayout::try_new(&scan, &grid, &lattice, st.len()) else {
        return 29;
    };
    let kv = lattice.len();
    let (Some(st), Some(s1), Some(sc)) = (
        st.get_mut(..layout.tables_len()),
        s1.get_mut(..LookupSlice::state_len(kv)),
        sc.get_mut(..LookupSlice::scratch_len(&grid, kv)),
    ) else {
        return 30;
    };
    let target = black_box(Target::Diagonal);
    let Ok(mut diag) = LookupSlice::new(&scan, &lookup, &layout, target, st, s1, sc) else {
        return 31;
    };
    for (i, c) in h.iter_mut().enumerate() {
        *c = black_box(u16::from(i % S_NT == 6) * 30 + 1);
    }
    for laser in black_box(&LASERS[..4]) {
        let Ok(row) = rows.load(&scan, *laser, &h[..]) else {
            return 32;
        };
        if diag.push_row(&scan, &lookup, &row).is_err() {
            return 33;
        }
    }
    let Some(out) = out.get_mut(..kv) else {
        return 34;
    };
    if diag.finish(out).is_err() || out.iter().all(|x| *x == 0.0) {
        return 13;
    }
    diag.reset();
    if diag.finish(out).is_err() || out.iter().any(|x| *x != 0.0) || diag.amplitude(kv).re != 0.0 {
        return 14;
    }
    0
}

fn run() -> i32 {
    let (Some(tables), Some(rowbuf), Some(lt), Some(s1), Some(s2), Some(out)) = (
        singleton!(: [f32; TABLES] = [0.0; TABLES]),
        singleton!(: [f32; ROWBUF] = [0.0; ROWBUF]),
        singleton!(: [f32; LOOKUP_TABLES_LEN] = [0.0; LOOKUP_TABLES_LEN]),
        singleton!(: [f32; LOOKUP_STATE_LEN] = [0.0; LOOKUP_STATE_LEN]),
        singleton!(: [f32; LOOKUP_STATE_LEN] = [0.0; LOOKUP_STATE_LEN]),
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
    // The slice with both interpolants (the Hermite cells are a path of their own).
    for i in [Interpolant::Lagrange, Interpolant::Hermite] {
        let r = run_slice(
            &mut tables[..],
            &mut rowbuf[..],
            &mut lt[..],
            &mut out[..],
            i,
        );
        if r != 0 {
            return r;
        }
    }
    0
}
