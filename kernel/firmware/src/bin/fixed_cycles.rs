//! Instruction counts per laser row of the kernel's **fixed-point** path (the Cortex-M0's,
//! `thumbv6m-none-eabi`) for the paper's real setup (24 × 24 lasers, 28 SPADs, Nt = 255,
//! λ = 0.13 m → N = 289, J = 137): `FixedRowBuffer::load`, one `FixedColumn::push_row`, and
//! the fixed-point lookup diagonal (`FixedLookupProbe::push_row`, L = 1024) over a 64 × 64
//! slice (2 m × 2 m at z = 1 m, as `cycles.rs`).
//!
//! The microbit's 16 KB of RAM cannot hold this setup (the row buffer alone is 30 KB), so the
//! M0 build runs on the mps2-an386 machine, whose Cortex-M4 executes the ARMv6-M instruction
//! stream unchanged: the counts are the M0 code's instructions (`-icount shift=0`, SysTick
//! calibrated as in `cycles.rs`). Build with `VLTM_FW_BOARD=mps2-an386` (memory map) for
//! `thumbv6m-none-eabi`; run with `run-qemu.sh m4f cycles ELF`. Reported, not budgeted.
#![no_std]
#![no_main]

use cortex_m::singleton;
use cortex_m_rt::{entry, exception};
use panic_semihosting as _;
use semihosting::{println, process};
use vltm_firmware::icount::{self, measure};
use vltm_kernel::{
    Config, FixedColumn, FixedConfig, FixedDiagonal, FixedLimits, FixedLookup, FixedLookupGrid,
    FixedLookupProbe, FixedRowBuffer, FixedScan, I1F15, LookupParams, Params, Point, Target,
};

const KS: usize = 28;
const NT: usize = 255;
const N_FFT: usize = 289;
const J: usize = 137;
const TABLES: usize = 2 * N_FFT + J;
const ROWBUF: usize = KS * (2 * J + 1);
const COLUMN: usize = 2 * KS * J;
/// The lookup grid at the default tolerance 1e-5.
const L: usize = 1024;
const KV: usize = 64 * 64;
const LOOKUP_SCRATCH: usize = 2 * (L + 3) + 2 * KV;

/// A 64 × 64 slice, 2 m × 2 m at z = 1 m (as `cycles.rs`).
static VOXELS: [Point; KV] = {
    let mut v = [[0.0f32; 3]; KV];
    let mut i = 0;
    while i < KV {
        v[i] = [
            -1.0 + 2.0 * (i % 64) as f32 / 63.0,
            -1.0 + 2.0 * (i / 64) as f32 / 63.0,
            1.0,
        ];
        i += 1;
    }
    v
};

/// 28 SPADs on a line along x, 2.5 cm pitch (as `cycles.rs`).
static SPADS: [Point; KS] = {
    let mut s = [[0.0f32; 3]; KS];
    let mut i = 0;
    while i < KS {
        s[i] = [-0.3375 + 0.025 * i as f32, 0.0, 0.0];
        i += 1;
    }
    s
};

#[exception]
fn SysTick() {
    icount::on_systick();
}

#[entry]
fn main() -> ! {
    let Some(p) = cortex_m::Peripherals::take() else {
        process::exit(7)
    };
    let (per_tick, n_cal, t_cal) = icount::start(p.SYST);
    println!(
        "CYCLES calibration: {n_cal} instructions in {t_cal} ticks: {per_tick:.3} instructions/tick"
    );

    let (Some(tables), Some(rowbuf), Some(hist), Some(col_s)) = (
        singleton!(: [I1F15; TABLES] = [I1F15::ZERO; TABLES]),
        singleton!(: [i32; ROWBUF] = [0; ROWBUF]),
        singleton!(: [u16; KS * NT] = [0; KS * NT]),
        singleton!(: [i64; COLUMN] = [0; COLUMN]),
    ) else {
        process::exit(7)
    };
    let Ok(cfg) = Config::try_new(&Params::new(0.13, NT, 0.0255)) else {
        process::exit(2)
    };
    if cfg.n_fft() != N_FFT || cfg.bins() != J {
        process::exit(2)
    }
    // 576 rows of 28 SPADs, legs ≥ 0.5 m (the slice at z = 1 m).
    let Ok(fc) = FixedConfig::try_new(&cfg, &FixedLimits::new(576, KS as u32, 0.5)) else {
        process::exit(2)
    };
    let mut rng = 0x2545_f491u32;
    for (i, h) in hist.iter_mut().enumerate() {
        rng = rng.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        let n = i % NT;
        *h = (rng >> 30) as u16 + if (100..104).contains(&n) { 40 } else { 0 };
    }
    let Ok(scan) = FixedScan::new(&fc, &SPADS, tables) else {
        process::exit(2)
    };
    let (Ok(mut rows), Ok(mut col)) = (
        FixedRowBuffer::new(&scan, rowbuf),
        FixedColumn::new(&scan, [0.1, 0.2, 1.0], col_s),
    ) else {
        process::exit(2)
    };
    let i = |t: u64| t as f64 * per_tick;
    let (t_load, row) = measure(|| rows.load(&scan, [-0.5, -0.5, 0.0], &hist[..]));
    let Ok(row) = row else { process::exit(3) };
    let (t_col, c) = measure(|| col.push_row(&scan, &row));
    if c.is_err() {
        process::exit(3)
    }
    println!("CYCLES m0_fixed setup Ks={KS} Nt={NT} N={N_FFT} J={J}");
    println!(
        "CYCLES m0_fixed load instructions={:.0} per_mac={:.2}",
        i(t_load),
        i(t_load) / (KS * J * NT) as f64
    );
    println!(
        "CYCLES m0_fixed column instructions={:.0} per_spad_bin={:.1}",
        i(t_col),
        i(t_col) / (KS * J) as f64
    );
    println!(
        "CYCLES m0_fixed row_to_column instructions={:.0}",
        i(t_load + t_col)
    );
    let (Some(lt), Some(ld), Some(ls)) = (
        singleton!(: [I1F15; L] = [I1F15::ZERO; L]),
        singleton!(: [i64; 2 * KV] = [0; 2 * KV]),
        singleton!(: [i32; LOOKUP_SCRATCH] = [0; LOOKUP_SCRATCH]),
    ) else {
        process::exit(7)
    };
    let Ok(grid) = FixedLookupGrid::try_new(&fc, &LookupParams::new()) else {
        process::exit(2)
    };
    if grid.grid().len() != L {
        process::exit(2)
    }
    let Ok(lookup) = FixedLookup::new(&grid, lt) else {
        process::exit(2)
    };
    let Ok(mut diag) =
        FixedLookupProbe::new(&lookup, Target::Diagonal, &VOXELS, &mut ld[..], &mut ls[..])
    else {
        process::exit(2)
    };
    let (t_diag, d) = measure(|| diag.push_row(&scan, &lookup, &row));
    if d.is_err() {
        process::exit(3)
    }
    // The same row over the slice's first 64 voxels: the `Ks` grid syntheses and 64·Ks pairs,
    // which separates the per-row synthesis from the per-pair cost.
    let (Some(ld64), Some(ls64), Some(bd64)) = (
        singleton!(: [i64; 128] = [0; 128]),
        singleton!(: [i32; 2 * (L + 3) + 128] = [0; 2 * (L + 3) + 128]),
        singleton!(: [i64; 128] = [0; 128]),
    ) else {
        process::exit(7)
    };
    let Ok(mut d64) = FixedLookupProbe::new(&lookup, Target::Diagonal, &VOXELS[..64], ld64, ls64)
    else {
        process::exit(2)
    };
    let (t_64, d) = measure(|| d64.push_row(&scan, &lookup, &row));
    if d.is_err() {
        process::exit(3)
    }
    // The fixed band diagonal (`J` MACs per pair) over the same 64 voxels, for comparison.
    let Ok(mut b64) = FixedDiagonal::new(&VOXELS[..64], bd64) else {
        process::exit(2)
    };
    let (t_b64, d) = measure(|| b64.push_row(&scan, &row));
    if d.is_err() {
        process::exit(3)
    }
    let per_pair = (i(t_diag) - i(t_64)) / (KS * (KV - 64)) as f64;
    println!(
        "CYCLES m0_fixed lookup_synthesis L={L} instructions={:.0} per_spad={:.0}",
        i(t_64) - per_pair * (KS * 64) as f64,
        (i(t_64) - per_pair * (KS * 64) as f64) / KS as f64
    );
    println!(
        "CYCLES m0_fixed band_diag per_pair={:.1}",
        i(t_b64) / (KS * 64) as f64
    );
    println!(
        "CYCLES m0_fixed lookup_diag64x64 L={L} instructions={:.0} per_pair={per_pair:.1}",
        i(t_diag),
    );
    // The column T(a, ·) over the same slice on the same buffers (its lead d_la + d_av per
    // voxel and row; the same per-pair work).
    let Ok(mut col) =
        FixedLookupProbe::new(&lookup, Target::Column([0.1, 0.2, 1.0]), &VOXELS, ld, ls)
    else {
        process::exit(2)
    };
    let (t_lcol, c) = measure(|| col.push_row(&scan, &lookup, &row));
    if c.is_err() {
        process::exit(3)
    }
    println!(
        "CYCLES m0_fixed lookup_col64x64 L={L} instructions={:.0}",
        i(t_lcol)
    );
    process::exit(0)
}
