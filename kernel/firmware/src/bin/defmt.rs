//! The defmt firmware: the same pipeline as `vltm-firmware`, logged through defmt over
//! semihosting (formatting happens on the host: decode with
//! `defmt-print -e ELF --log-format '{s}'`). Exit status as for `vltm-firmware`.
//! Build with `DEFMT_LOG=info` (or lower): without it only `error!` frames are kept.
#![no_std]
#![no_main]

use cortex_m::singleton;
use cortex_m_rt::entry;
use defmt_semihosting as _;
use panic_semihosting as _;
use semihosting::process;
use vltm_firmware::fixture::{COLUMN_LEN, DIAG_LEN, N_VOXELS, ROWBUF_LEN, TABLES_LEN, params};
use vltm_firmware::pipeline::{self, Buffers, Results};

#[entry]
fn main() -> ! {
    let (Some(tables), Some(row), Some(diag), Some(column), Some(diag_photons), Some(out)) = (
        singleton!(: [f32; TABLES_LEN] = [0.0; TABLES_LEN]),
        singleton!(: [f32; ROWBUF_LEN] = [0.0; ROWBUF_LEN]),
        singleton!(: [f64; DIAG_LEN] = [0.0; DIAG_LEN]),
        singleton!(: [f64; COLUMN_LEN] = [0.0; COLUMN_LEN]),
        singleton!(: [f64; DIAG_LEN] = [0.0; DIAG_LEN]),
        singleton!(: Results = Results::ZERO),
    ) else {
        defmt::error!("a static buffer was taken twice");
        process::exit(7)
    };
    let Some(scan) = vltm_firmware::scan_data() else {
        process::exit(2)
    };
    // The kernel's `defmt` feature derives Format for Params/Config/errors/Report.
    defmt::debug!("params {}", params());
    let bufs = Buffers {
        tables,
        row,
        diag,
        column,
        diag_photons,
    };
    if let Err(e) = pipeline::run(scan, bufs, out) {
        defmt::error!("ERROR {}", e);
        process::exit(2)
    }
    for i in 0..N_VOXELS {
        defmt::info!(
            "RESULT voxel={=usize} diag={=f64} col={=f64} diag_photons={=f64}",
            i,
            out.diag[i],
            out.col[i],
            out.diag_photons[i]
        );
    }
    for (name, r) in [
        ("diag", out.report_diag),
        ("col", out.report_col),
        ("diag_photons", out.report_photons),
    ] {
        // The derived `Format` of the kernel's Report, then the line run-qemu.sh compares.
        defmt::debug!("{=str}: {}", name, r);
        defmt::info!(
            "REPORT {=str} rows={=u64} non_finite={=u64} dropped={=u64} aliased={=usize}",
            name,
            r.rows,
            r.non_finite,
            r.dropped,
            r.aliased
        );
    }
    let verdict = pipeline::verdict(out);
    defmt::info!("VERDICT {=i32}", verdict);
    process::exit(verdict)
}
