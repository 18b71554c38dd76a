//! Instruction counts per laser row for the paper's real setup (24 × 24 lasers, a 28-pixel
//! SPAD line, Δt = 2.55 cm, Nt = 255 (6.5 m), λ = 0.13 m → N = 289, J = 137), a Gaussian
//! diagonal over a 64 × 64 slice and one factorised Gaussian column, on the Cortex-M4F build.
//!
//! QEMU is not cycle-accurate, but with `-icount shift=0` its virtual clock advances exactly
//! 1 ns per executed guest instruction, and SysTick (core clock, 25 MHz on mps2-an386) runs
//! on that clock: SysTick ticks × (instructions per tick, calibrated here with a loop of a
//! known instruction count) = instructions executed. Cycles = instructions × a CPI (see the
//! README). Run: `run-qemu.sh cycles ELF` (mps2-an386 only: ~210 KB of RAM).
#![no_std]
#![no_main]

use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m::peripheral::{SYST, syst::SystClkSource};
use cortex_m::singleton;
use cortex_m_rt::{entry, exception};
use panic_semihosting as _;
use semihosting::{println, process};
use vltm_kernel::{Config, Gate, Params, Point, Probe, RowBuffer, Scan, Target};

const KS: usize = 28;
const NT: usize = 255;
const N_FFT: usize = 289;
const J: usize = 137;
const KV: usize = 64 * 64;
const TABLES: usize = 2 * N_FFT + J + KS;
const ROWBUF: usize = KS * (2 * J + 3);
const DIAG: usize = 2 * KV;
const COLUMN: usize = 2 * J * (KS + 1);

fn params() -> Params {
    Params::new(0.13, NT, 0.0255)
}

/// 28 SPADs on a line along x, 2.5 cm pitch (the paper's line sensor).
static SPADS: [Point; KS] = {
    let mut s = [[0.0f32; 3]; KS];
    let mut i = 0;
    while i < KS {
        s[i] = [-0.3375 + 0.025 * i as f32, 0.0, 0.0];
        i += 1;
    }
    s
};
/// A 64 × 64 slice, 2 m × 2 m at z = 1 m.
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

static WRAPS: AtomicU32 = AtomicU32::new(0);

#[exception]
fn SysTick() {
    WRAPS.fetch_add(1, Ordering::Relaxed);
}

/// SysTick ticks since start (24-bit counter + wraps counted by the exception).
fn ticks() -> u64 {
    loop {
        let w = WRAPS.load(Ordering::Relaxed);
        let v = SYST::get_current();
        if WRAPS.load(Ordering::Relaxed) == w {
            return u64::from(w) * (1 << 24) + u64::from(0xFF_FFFF - v);
        }
    }
}

/// Ticks taken by `f`.
fn measure<R>(f: impl FnOnce() -> R) -> (u64, R) {
    let t0 = ticks();
    let r = f();
    (ticks() - t0, r)
}

#[entry]
fn main() -> ! {
    let Some(mut p) = cortex_m::Peripherals::take() else {
        process::exit(7)
    };
    p.SYST.set_clock_source(SystClkSource::Core);
    p.SYST.set_reload(0xFF_FFFF);
    p.SYST.clear_current();
    p.SYST.enable_interrupt();
    p.SYST.enable_counter();

    // VAL reads 0 until the first tick reloads it.
    while SYST::get_current() == 0 {}
    // Calibration: a loop of exactly 2 instructions per iteration (subs + bne).
    let n_loop = 5_000_000u32;
    let (t_cal, ()) = measure(|| unsafe {
        core::arch::asm!("2:", "subs {0}, #1", "bne 2b", inout(reg) n_loop => _, options(nomem, nostack));
    });
    let per_tick = 2.0 * n_loop as f64 / t_cal as f64;
    println!(
        "CYCLES calibration: {} instructions in {t_cal} ticks: {per_tick:.3} instructions/tick",
        2 * n_loop
    );

    let (Some(tables), Some(rowbuf), Some(hist), Some(diag_s), Some(col_s), Some(out)) = (
        singleton!(: [f32; TABLES] = [0.0; TABLES]),
        singleton!(: [f32; ROWBUF] = [0.0; ROWBUF]),
        singleton!(: [u16; KS * NT] = [0; KS * NT]),
        singleton!(: [f64; DIAG] = [0.0; DIAG]),
        singleton!(: [f64; COLUMN] = [0.0; COLUMN]),
        singleton!(: [f64; KV] = [0.0; KV]),
    ) else {
        process::exit(7)
    };
    let Ok(cfg) = Config::try_new(&params()) else {
        process::exit(2)
    };
    if cfg.n_fft() != N_FFT || cfg.bins() != J {
        println!("ERROR N = {}, J = {}", cfg.n_fft(), cfg.bins());
        process::exit(2)
    }
    // Synthetic counts: background 0–3 and a pulse (the counts do not change the cost).
    let mut rng = 0x2545_f491u32;
    for (i, h) in hist.iter_mut().enumerate() {
        rng = rng.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        let n = i % NT;
        *h = (rng >> 30) as u16 + if (100..104).contains(&n) { 40 } else { 0 };
    }
    let photons: u64 = hist.iter().map(|&c| u64::from(c)).sum();
    let (Ok(scan), focus) = (
        Scan::new(&cfg, &SPADS, tables),
        Target::Column([0.1, 0.2, 1.0]),
    ) else {
        process::exit(2)
    };
    let (Ok(mut rows), Ok(mut diag), Ok(mut col)) = (
        RowBuffer::new(&scan, rowbuf),
        Probe::new(&scan, Target::Diagonal, Gate::Gaussian, &VOXELS, diag_s),
        Probe::new(&scan, focus, Gate::Gaussian, &VOXELS, col_s),
    ) else {
        process::exit(2)
    };
    let i = |t: u64| t as f64 * per_tick;
    let lasers = [[-0.5f32, -0.5, 0.0], [-0.45, -0.5, 0.0]];
    let mut last = (0, 0, 0);
    for laser in lasers {
        let (t_load, row) = measure(|| rows.load(&scan, laser, &hist[..]));
        let Ok(row) = row else { process::exit(3) };
        let (t_diag, d) = measure(|| diag.push_row(&scan, &row));
        let (t_col, c) = measure(|| col.push_row(&scan, &row));
        if d.is_err() || c.is_err() {
            process::exit(3)
        }
        last = (t_load, t_diag, t_col);
    }
    let (t_load, t_diag, t_col) = last;
    // `finish` images all 4096 voxels (once per scan); time 64 of them with `image` (the same
    // per-voxel loop) and scale, to keep the QEMU run short.
    let (t_fin, f) = measure(|| col.image(&scan, &VOXELS[..64], &mut out[..64]));
    if f.is_err() {
        process::exit(3)
    }
    let (t_ph, ()) = measure(|| {
        rows.begin_photons();
        for (s, h) in hist.chunks_exact(NT).enumerate() {
            for (n, &c) in h.iter().enumerate() {
                for _ in 0..c {
                    rows.push_photon(&scan, s, n);
                }
            }
        }
    });
    let macs = (KS * J * NT) as f64;
    let pairs = (KV * KS) as f64;
    println!("CYCLES setup Ks={KS} Nt={NT} N={N_FFT} J={J} Kv={KV}");
    println!(
        "CYCLES load instructions={:.0} per_mac={:.2}",
        i(t_load),
        i(t_load) / macs
    );
    println!(
        "CYCLES diag64x64 instructions={:.0} per_pair={:.1} per_band_term={:.2}",
        i(t_diag),
        i(t_diag) / pairs,
        i(t_diag) / (pairs * J as f64)
    );
    println!(
        "CYCLES column instructions={:.0} per_spad_bin={:.1}",
        i(t_col),
        i(t_col) / (KS * J) as f64
    );
    println!(
        "CYCLES column_finish64x64 instructions={:.0} per_pair={:.1} (64 voxels timed, x64)",
        64.0 * i(t_fin),
        i(t_fin) / (64 * KS) as f64
    );
    println!(
        "CYCLES photons={photons} instructions={:.0} per_photon={:.1}",
        i(t_ph),
        i(t_ph) / photons as f64
    );
    // The lookup path (src/lookup_cycles.rs).
    let mut m = |f: &mut dyn FnMut()| measure(f).0;
    if !vltm_firmware::lookup_cycles::run(&scan, &mut rows, &hist[..], &VOXELS, &mut m, per_tick) {
        process::exit(3)
    }
    process::exit(0)
}
