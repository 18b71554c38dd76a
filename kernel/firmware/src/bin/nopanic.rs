//! Link-time proof that the kernel's per-row paths cannot panic: the panic handler is
//! `panic-never`, whose `rust_begin_unwind` is an undefined symbol, so this ELF links only
//! if the optimiser removed every panicking branch of everything called here. Release
//! profile only (a debug build keeps the branches). No `core::fmt`: the result is the exit
//! status (0 = every call succeeded and the counters and the diagonal's peak are right).
//!
//! Inputs are passed through `black_box` (parameters, SPAD count, voxels, lasers, the
//! target × gate list), so the proof holds for any configuration, not just the fixture's
//! constants. Exercised: `Config::try_new`, `Scan::new`, `RowBuffer::new`, `RowBuffer::load`
//! for `u16` and `f32` samples, `begin_photons`/`push_photon` (in and out of range)/
//! `end_photons`, `Probe::new`/`push_row`/`merge`/`finish`/`reset` for every target × gate,
//! and `Probe::image` for the factorised columns.
//!
//! Uses the first two SPADs of the fixture (the rows are SPAD-major, so their histograms
//! are the first `2·Nt` counts of each row) to keep the statics within the microbit's
//! 16 KB of RAM.
#![no_std]
#![no_main]

use core::hint::black_box;
use cortex_m::singleton;
use cortex_m_rt::entry;
#[cfg(not(feature = "find-panics"))]
use panic_never as _;

/// `--features find-panics`: a plain panic handler instead of panic-never, so the ELF links
/// and its calls into `core::panicking` can be listed (see README, "No panic").
#[cfg(feature = "find-panics")]
#[panic_handler]
fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
    process::exit(1)
}
use semihosting::process;
use vltm_firmware::fixture::{
    BINS, FOCUS, LASERS, N_FFT, N_LASERS, N_VOXELS, NT, P1_VOXEL, ROW, SPADS, VOXELS, params,
};
use vltm_firmware::pipeline::argmax;
use vltm_kernel::{ColumnF32, Config, Gate, Probe, RowBuffer, Scan, Target};

/// SPADs used here.
const KS: usize = 2;
const TABLES: usize = 2 * N_FFT + BINS + KS;
const ROWBUF: usize = KS * (2 * BINS + 3);
/// The largest probe state: column × Gaussian `2J(Ks+1)` or higher-order `2(Kv+Nt+1)`.
const COLUMN32: usize = (4 * KS + 2) * BINS;
const STATE: usize = {
    let col = 2 * BINS * (KS + 1);
    let ho = 2 * (N_VOXELS + NT + 1);
    if col > ho { col } else { ho }
};

#[entry]
fn main() -> ! {
    process::exit(run())
}

fn run() -> i32 {
    let (Some(tables), Some(rowbuf), Some(s1), Some(s2), Some(hf), Some(out)) = (
        singleton!(: [f32; TABLES] = [0.0; TABLES]),
        singleton!(: [f32; ROWBUF] = [0.0; ROWBUF]),
        singleton!(: [f64; STATE] = [0.0; STATE]),
        singleton!(: [f64; STATE] = [0.0; STATE]),
        singleton!(: [f32; KS * NT] = [0.0; KS * NT]),
        singleton!(: [f64; N_VOXELS] = [0.0; N_VOXELS]),
    ) else {
        return 7;
    };
    let Some(data) = vltm_firmware::scan_data() else {
        return 2;
    };
    // `--features panic-canary`: one indexing that can panic, to show that the check bites
    // (this build must FAIL to link; ci.sh checks it).
    #[cfg(feature = "panic-canary")]
    if data[black_box(usize::MAX)] == 1 {
        return 9;
    }
    let Ok(cfg) = Config::try_new(&black_box(params())) else {
        return 2;
    };
    let ks = black_box(KS);
    let Some(spads) = black_box(&SPADS[..]).get(..ks) else {
        return 2;
    };
    let Some(tables) = tables.get_mut(..Scan::tables_len(&cfg, ks)) else {
        return 2;
    };
    let Ok(scan) = Scan::new(&cfg, spads, tables) else {
        return 2;
    };
    let Some(rowbuf) = rowbuf.get_mut(..RowBuffer::len(&cfg, ks)) else {
        return 2;
    };
    let Ok(mut rows) = RowBuffer::new(&scan, rowbuf) else {
        return 2;
    };
    let voxels = black_box(&VOXELS[..]);
    let lasers = black_box(&LASERS[..]);
    let nt = cfg.nt();
    let focus = Target::Column(FOCUS);
    let combos = black_box([
        (Target::Diagonal, Gate::Gaussian),
        (Target::Diagonal, Gate::None),
        (Target::Diagonal, Gate::HigherOrder),
        (focus, Gate::Gaussian),
        (focus, Gate::None),
        (focus, Gate::HigherOrder),
    ]);
    let mut photon_rows = 0u64;
    for (k, (target, gate)) in combos.into_iter().enumerate() {
        let len = Probe::state_len(&cfg, target, gate, voxels.len(), ks);
        let (Some(a), Some(b)) = (s1.get_mut(..len), s2.get_mut(..len)) else {
            return 2;
        };
        let (Ok(mut even), Ok(mut odd)) = (
            Probe::new(&scan, target, gate, voxels, a),
            Probe::new(&scan, target, gate, voxels, b),
        ) else {
            return 2;
        };
        let mut dropped = 0u64;
        for (l, &laser) in lasers.iter().enumerate() {
            let Some(h) = data.get(l * ROW..l * ROW + ks * nt) else {
                return 2;
            };
            let probe = if l % 2 == 0 { &mut even } else { &mut odd };
            let ok = match l % 3 {
                // u16 histograms.
                0 => rows
                    .load(&scan, laser, h)
                    .and_then(|row| probe.push_row(&scan, &row)),
                // f32 histograms.
                1 => {
                    let Some(hf) = hf.get_mut(..h.len()) else {
                        return 2;
                    };
                    for (f, c) in hf.iter_mut().zip(h) {
                        *f = f32::from(*c);
                    }
                    rows.load(&scan, laser, &*hf)
                        .and_then(|row| probe.push_row(&scan, &row))
                }
                // Photon events (the higher-order gate needs histograms: rejected, then
                // pushed as a histogram row), plus two out-of-range photons.
                _ => {
                    rows.begin_photons();
                    for (spad, hist) in h.chunks_exact(nt.max(1)).enumerate() {
                        for (bin, &count) in hist.iter().enumerate() {
                            for _ in 0..count {
                                rows.push_photon(&scan, spad, bin);
                            }
                        }
                    }
                    rows.push_photon(&scan, ks, 0);
                    rows.push_photon(&scan, 0, nt);
                    photon_rows += 1;
                    let pushed = rows
                        .end_photons(&scan, laser)
                        .and_then(|row| probe.push_row(&scan, &row));
                    if gate == Gate::HigherOrder {
                        if pushed.is_ok() {
                            return 5;
                        }
                        rows.load(&scan, laser, h)
                            .and_then(|row| probe.push_row(&scan, &row))
                    } else {
                        dropped += 2;
                        pushed
                    }
                }
            };
            if ok.is_err() {
                return 3;
            }
        }
        if even.merge(&odd).is_err() {
            return 4;
        }
        let Some(out) = out.get_mut(..voxels.len()) else {
            return 2;
        };
        let Ok(report) = even.finish(&scan, out) else {
            return 4;
        };
        if report.rows != N_LASERS as u64 || report.dropped != dropped || report.non_finite != 0 {
            return 6;
        }
        if !out.iter().all(|x| x.is_finite() && *x >= 0.0) {
            return 6;
        }
        if k == 0 && argmax(out) != P1_VOXEL {
            return 8;
        }
        if even.is_factorised() && even.image(&scan, voxels, out).is_err() {
            return 4;
        }
        even.reset();
        if even.report().rows != 0 {
            return 6;
        }
    }
    if photon_rows == 0 {
        return 6;
    }
    // The f32 column (Kahan state, no f64): every row, histogram and photon rows, then finish.
    let (Some(c32), Some(out32)) = (
        singleton!(: [f32; COLUMN32] = [0.0; COLUMN32]),
        singleton!(: [f32; N_VOXELS] = [0.0; N_VOXELS]),
    ) else {
        return 7;
    };
    let Some(c32) = c32.get_mut(..ColumnF32::state_len(&cfg, ks)) else {
        return 2;
    };
    let Ok(mut col) = ColumnF32::new(&scan, black_box(FOCUS), c32) else {
        return 2;
    };
    for (l, &laser) in lasers.iter().enumerate() {
        let Some(h) = data.get(l * ROW..l * ROW + ks * nt) else {
            return 2;
        };
        let ok = if l % 2 == 0 {
            rows.load(&scan, laser, h)
                .and_then(|row| col.push_row(&scan, &row))
        } else {
            rows.begin_photons();
            for (spad, hist) in h.chunks_exact(nt.max(1)).enumerate() {
                for (bin, &count) in hist.iter().enumerate() {
                    for _ in 0..count {
                        rows.push_photon(&scan, spad, bin);
                    }
                }
            }
            rows.end_photons(&scan, laser)
                .and_then(|row| col.push_row(&scan, &row))
        };
        if ok.is_err() {
            return 3;
        }
    }
    let Some(out32) = out32.get_mut(..voxels.len()) else {
        return 2;
    };
    match col.finish(&scan, voxels, out32) {
        Ok(r) if r.rows == N_LASERS as u64 && out32.iter().all(|x| x.is_finite()) => 0,
        _ => 6,
    }
}
