//! The fixed-point firmware (for the Cortex-M0 without FPU): the fixture through the kernel's
//! fixed-point path (histograms, and photon events for the diagonal; the diagonal again on the
//! fixed-point lookup path, and the column on it),
//! `RESULT voxel=i diag=… col=… diag_photons=… lookup_diag=… lookup_col=…` lines compared by `run-qemu.sh` with
//! `fixture/expected_fixed.txt` (the host's numbers), exit status = `verdict_fixed`.
#![no_std]
#![no_main]

use cortex_m::singleton;
use cortex_m_rt::entry;
use panic_semihosting as _;
use semihosting::{println, process};
use vltm_firmware::fixed_pipeline::{
    self, FIXED_COLUMN_LEN, FIXED_DIAG_LEN, FIXED_LOOKUP_TABLES_LEN, FIXED_PHOTONS_LEN,
    FIXED_ROW_LEN, FIXED_TABLES_LEN, FixedBuffers, FixedResults,
};
use vltm_firmware::fixture::N_VOXELS;
use vltm_kernel::I1F15;

#[entry]
fn main() -> ! {
    let (Some(tables), Some(row), Some(diag), Some(column), Some(out)) = (
        singleton!(: [I1F15; FIXED_TABLES_LEN] = [I1F15::ZERO; FIXED_TABLES_LEN]),
        singleton!(: [i32; FIXED_ROW_LEN] = [0; FIXED_ROW_LEN]),
        singleton!(: [i64; FIXED_DIAG_LEN] = [0; FIXED_DIAG_LEN]),
        singleton!(: [i64; FIXED_COLUMN_LEN] = [0; FIXED_COLUMN_LEN]),
        singleton!(: FixedResults = FixedResults::ZERO),
    ) else {
        process::exit(7)
    };
    let (Some(photons), Some(diag_photons)) = (
        singleton!(: [i64; FIXED_PHOTONS_LEN] = [0; FIXED_PHOTONS_LEN]),
        singleton!(: [i64; FIXED_DIAG_LEN] = [0; FIXED_DIAG_LEN]),
    ) else {
        process::exit(7)
    };
    let (Some(lookup_tables), Some(lookup_state)) = (
        singleton!(: [I1F15; FIXED_LOOKUP_TABLES_LEN] = [I1F15::ZERO; FIXED_LOOKUP_TABLES_LEN]),
        singleton!(: [i64; FIXED_DIAG_LEN] = [0; FIXED_DIAG_LEN]),
    ) else {
        process::exit(7)
    };
    let Some(scan) = vltm_firmware::scan_data() else {
        process::exit(2)
    };
    let bufs = FixedBuffers {
        tables,
        row,
        diag,
        column,
        photons,
        diag_photons,
        lookup_tables,
        lookup_state,
    };
    if let Err(e) = fixed_pipeline::run_fixed(scan, bufs, out) {
        println!("ERROR {e:?}");
        process::exit(2)
    }
    for i in 0..N_VOXELS {
        println!(
            "RESULT voxel={i} diag={:e} col={:e} diag_photons={:e} lookup_diag={:e} lookup_col={:e}",
            out.diag[i], out.col[i], out.diag_photons[i], out.lookup_diag[i], out.lookup_col[i]
        );
    }
    let verdict = fixed_pipeline::verdict_fixed(out);
    println!("VERDICT {verdict}");
    process::exit(verdict)
}
