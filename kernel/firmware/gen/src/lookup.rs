//! `expected_lookup.txt`: the lookup pipeline (`../../src/lookup_pipeline.rs`) on the host;
//! the lookup firmware must print the same numbers, bit for bit.

use crate::fixture::{N_VOXELS, ROWBUF_LEN, TABLES_LEN};
use crate::lookup_pipeline::*;
use crate::pipeline;
use std::fmt::Write as _;

/// Runs the lookup pipeline, checks it against the band path's results `r` (within the grid's
/// interpolation tolerance, relative to the largest amplitude) and writes
/// `dir/expected_lookup.txt`.
pub fn lookup_fixture(dir: &std::path::Path, scan: &[u16], r: &pipeline::Results) {
    let (mut tables, mut row, mut lt) = (
        vec![0.0f32; TABLES_LEN],
        vec![0.0f32; ROWBUF_LEN],
        vec![0.0f32; LOOKUP_TABLES_LEN],
    );
    let (mut d, mut c) = (
        vec![0.0f64; LOOKUP_STATE_LEN],
        vec![0.0f64; LOOKUP_STATE_LEN],
    );
    let (mut sc, mut c32) = (
        vec![0.0f32; LOOKUP_SCRATCH_LEN],
        vec![0.0f32; COLUMN32_STATE_LEN],
    );
    let mut f = LookupResults::ZERO;
    let bufs = LookupBuffers {
        tables: &mut tables,
        row: &mut row,
        lookup: &mut lt,
        diag: &mut d,
        column: &mut c,
        scratch: &mut sc,
        column32: &mut c32,
    };
    run_lookup(scan, bufs, &mut f).expect("lookup pipeline");
    assert_eq!(
        verdict_lookup(&f),
        0,
        "lookup pipeline fails its checks: {f:#?}"
    );
    // |√T_lookup − √T_band| relative to the largest amplitude: the grid's interpolation
    // error (η = 1e-4 of the histograms' L1 norm, far less of the peak: 8.8e-6 measured).
    let rel = |a: &[f64], b: &[f64]| {
        let big = b.iter().fold(0.0f64, |m, x| m.max(x.sqrt()));
        a.iter()
            .zip(b)
            .fold(0.0f64, |m, (x, y)| m.max((x.sqrt() - y.sqrt()).abs() / big))
    };
    let col32: Vec<f64> = f.col32.iter().map(|&x| f64::from(x)).collect();
    let (ed, ec, e32) = (
        rel(&f.diag, &r.diag),
        rel(&f.col, &r.col),
        rel(&col32, &r.col),
    );
    assert!(
        ed < 1e-3 && ec < 1e-2 && e32 < 1e-3,
        "lookup vs band: diag {ed:e}, col {ec:e}, factorised col (lookup finish) {e32:e}"
    );
    assert_eq!(
        f.report_col32.aliased, r.report_col.aliased,
        "the lookup finish reports the band finish's aliased voxels"
    );
    eprintln!(
        "lookup vs band, max |√T_lookup − √T_band| / max √T_band: diag {ed:.2e}, col {ec:.2e}, col32 {e32:.2e}"
    );
    let mut txt = String::new();
    writeln!(
        txt,
        "# vltm-firmware lookup fixture: T = |A|^2 from the kernel's lookup path on the host ({}), tolerance {LOOKUP_TOLERANCE:e}, L = {LOOKUP_GRID}.",
        std::env::consts::ARCH
    )
    .unwrap();
    writeln!(
        txt,
        "# same scan.bin; max |sqrt(T_lookup) - sqrt(T_band)| / max sqrt(T_band): diag {ed:.2e}, col {ec:.2e}, col32 (ColumnF32::finish_lookup vs the band column) {e32:.2e}"
    )
    .unwrap();
    for i in 0..N_VOXELS {
        writeln!(
            txt,
            "RESULT voxel={i} lookup_diag={:e} lookup_col={:e} lookup_col32={:e}",
            f.diag[i], f.col[i], f.col32[i]
        )
        .unwrap();
    }
    for (name, x) in [
        ("lookup_diag", f.report_diag),
        ("lookup_col", f.report_col),
        ("lookup_col32", f.report_col32),
    ] {
        writeln!(
            txt,
            "REPORT {name} rows={} non_finite={} dropped={} aliased={}",
            x.rows, x.non_finite, x.dropped, x.aliased
        )
        .unwrap();
    }
    std::fs::write(dir.join("expected_lookup.txt"), &txt).expect("write expected_lookup.txt");
}
