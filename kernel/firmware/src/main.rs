//! The text firmware: streams the fixture scan through vltm-kernel with all state in
//! `static` memory, prints `RESULT` / `REPORT` lines through semihosting and exits with the
//! verdict of its own checks (0 = passed; see `pipeline::verdict`; 1 = panic, 2 = a kernel
//! call or the fixture was rejected, 7 = a static buffer was taken twice).
#![no_std]
#![no_main]

use cortex_m::singleton;
use cortex_m_rt::entry;
use panic_semihosting as _;
use semihosting::{println, process};
use vltm_firmware::fixture::{COLUMN_LEN, DIAG_LEN, N_VOXELS, ROWBUF_LEN, TABLES_LEN};
use vltm_firmware::pipeline::{self, Buffers, Results};

#[entry]
fn main() -> ! {
    // Every buffer is a `static` handed out once (`singleton!` returns `None` the second
    // time): zero-initialised, so in `.bss`; the scan itself stays in flash.
    let (Some(tables), Some(row), Some(diag), Some(column), Some(diag_photons), Some(out)) = (
        singleton!(: [f32; TABLES_LEN] = [0.0; TABLES_LEN]),
        singleton!(: [f32; ROWBUF_LEN] = [0.0; ROWBUF_LEN]),
        singleton!(: [f64; DIAG_LEN] = [0.0; DIAG_LEN]),
        singleton!(: [f64; COLUMN_LEN] = [0.0; COLUMN_LEN]),
        singleton!(: [f64; DIAG_LEN] = [0.0; DIAG_LEN]),
        singleton!(: Results = Results::ZERO),
    ) else {
        process::exit(7)
    };
    let Some(scan) = vltm_firmware::scan_data() else {
        process::exit(2)
    };
    let bufs = Buffers {
        tables,
        row,
        diag,
        column,
        diag_photons,
    };
    if let Err(e) = pipeline::run(scan, bufs, out) {
        println!("ERROR {e:?}");
        process::exit(2)
    }
    for i in 0..N_VOXELS {
        println!(
            "RESULT voxel={i} diag={:e} col={:e} diag_photons={:e}",
            out.diag[i], out.col[i], out.diag_photons[i]
        );
    }
    for (name, r) in [
        ("diag", out.report_diag),
        ("col", out.report_col),
        ("diag_photons", out.report_photons),
    ] {
        println!(
            "REPORT {name} rows={} non_finite={} dropped={} aliased={}",
            r.rows, r.non_finite, r.dropped, r.aliased
        );
    }
    let verdict = pipeline::verdict(out);
    println!("VERDICT {verdict}");
    process::exit(verdict)
}
