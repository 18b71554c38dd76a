//! The lookup-path firmware: the fixture through the kernel's lookup diagonal and column and
//! the factorised `f32` column's lookup finish, then the structured slice's diagonal and column
//! (`src/lookup_pipeline.rs`), `RESULT voxel=i lookup_diag=… lookup_col=… lookup_col32=…`,
//! `RESULT voxel=i slice_diag=… slice_col=…` (`i` the slice lattice's voxel) and `REPORT`
//! lines compared by `run-qemu.sh` with `fixture/expected_lookup.txt` (the host's numbers,
//! bit for bit), exit status = `verdict_lookup` (1 = panic, 2 = rejected, 7 = a static
//! buffer taken twice). Runs on the M4F and, linked for the mps2-an386 memory map, as M0 code
//! (about 33 KB of `.bss`, most of it the slice's scratch: more than the microbit's 16 KB).
#![no_std]
#![no_main]

use cortex_m::singleton;
use cortex_m_rt::entry;
use panic_semihosting as _;
use semihosting::{println, process};
use vltm_firmware::fixture::{N_VOXELS, ROWBUF_LEN, TABLES_LEN};
use vltm_firmware::lookup_pipeline::{
    self, COLUMN32_STATE_LEN, LOOKUP_STATE_LEN, LOOKUP_TABLES_LEN, LookupBuffers, LookupResults,
    N_SLICE, SCRATCH_LEN, SLICE_STATE_LEN, SLICE_TABLES_LEN,
};

#[entry]
fn main() -> ! {
    let (Some(tables), Some(row), Some(lookup), Some(diag), Some(column), Some(out)) = (
        singleton!(: [f32; TABLES_LEN] = [0.0; TABLES_LEN]),
        singleton!(: [f32; ROWBUF_LEN] = [0.0; ROWBUF_LEN]),
        singleton!(: [f32; LOOKUP_TABLES_LEN] = [0.0; LOOKUP_TABLES_LEN]),
        singleton!(: [f32; LOOKUP_STATE_LEN] = [0.0; LOOKUP_STATE_LEN]),
        singleton!(: [f32; LOOKUP_STATE_LEN] = [0.0; LOOKUP_STATE_LEN]),
        singleton!(: LookupResults = LookupResults::ZERO),
    ) else {
        process::exit(7)
    };
    let (Some(scratch), Some(column32), Some(slice_tables), Some(slice_state)) = (
        singleton!(: [f32; SCRATCH_LEN] = [0.0; SCRATCH_LEN]),
        singleton!(: [f32; COLUMN32_STATE_LEN] = [0.0; COLUMN32_STATE_LEN]),
        singleton!(: [f32; SLICE_TABLES_LEN] = [0.0; SLICE_TABLES_LEN]),
        singleton!(: [f32; SLICE_STATE_LEN] = [0.0; SLICE_STATE_LEN]),
    ) else {
        process::exit(7)
    };
    let Some(scan) = vltm_firmware::scan_data() else {
        process::exit(2)
    };
    let bufs = LookupBuffers {
        tables,
        row,
        lookup,
        diag,
        column,
        scratch,
        column32,
        slice_tables,
        slice_state,
    };
    if let Err(e) = lookup_pipeline::run_lookup(scan, bufs, out) {
        println!("ERROR {e:?}");
        process::exit(2)
    }
    for i in 0..N_VOXELS {
        println!(
            "RESULT voxel={i} lookup_diag={:e} lookup_col={:e} lookup_col32={:e}",
            out.diag[i], out.col[i], out.col32[i]
        );
    }
    for i in 0..N_SLICE {
        println!(
            "RESULT voxel={i} slice_diag={:e} slice_col={:e} slice_diag_h={:e} slice_col_h={:e}",
            out.slice_diag[i], out.slice_col[i], out.slice_diag_h[i], out.slice_col_h[i]
        );
    }
    for (name, r) in [
        ("lookup_diag", out.report_diag),
        ("lookup_col", out.report_col),
        ("lookup_col32", out.report_col32),
        ("slice_diag", out.report_slice_diag),
        ("slice_col", out.report_slice_col),
        ("slice_diag_h", out.report_slice_diag_h),
        ("slice_col_h", out.report_slice_col_h),
    ] {
        println!(
            "REPORT {name} rows={} non_finite={} dropped={} aliased={}",
            r.rows, r.non_finite, r.dropped, r.aliased
        );
    }
    let verdict = lookup_pipeline::verdict_lookup(out);
    println!("VERDICT {verdict}");
    process::exit(verdict)
}
