//! `expected_lookup.txt`: the lookup pipeline (`../../src/lookup_pipeline.rs`) on the host;
//! the lookup firmware must print the same numbers, bit for bit.

use crate::fixture::{
    FOCUS, LASERS, N_SPADS, N_VOXELS, ROW, ROWBUF_LEN, SPADS, TABLES_LEN, params,
};
use crate::lookup_pipeline::*;
use crate::pipeline;
use std::fmt::Write as _;
use vltm_kernel::{
    Config, Gate, Lookup, LookupGrid, LookupProbe, Point, Probe, RowBuffer, Scan, Target,
};

/// The slice's voxels as a list ([`vltm_kernel::Lattice::point`]) through the general lookup
/// path ([`LookupProbe`]) and the band path ([`Probe`], Gaussian gate): `(lookup, band)` of
/// `target`, the host references of the firmware's [`vltm_kernel::LookupSlice`].
fn slice_references(scan_data: &[u16], target: Target) -> (Vec<f64>, Vec<f64>) {
    let cfg = Config::try_new(&params()).expect("fixture params");
    let grid = LookupGrid::try_new(&cfg, &lookup_params()).expect("grid");
    let voxels: Vec<Point> = (0..N_SLICE).map(|i| SLICE_LATTICE.point(i)).collect();
    let mut tables = vec![0.0f32; TABLES_LEN];
    let scan = Scan::new(&cfg, &SPADS, &mut tables).expect("scan");
    let mut lt = vec![0.0f32; Lookup::tables_len(&grid)];
    let lookup = Lookup::new(&grid, &mut lt).expect("lookup");
    let mut buf = vec![0.0f32; RowBuffer::len(&cfg, N_SPADS)];
    let mut rows = RowBuffer::new(&scan, &mut buf).expect("rows");
    let mut st = vec![0.0f32; LookupProbe::state_len(N_SLICE)];
    let mut sc = vec![0.0f32; LookupProbe::scratch_len(&grid, N_SLICE)];
    let mut lp = LookupProbe::new(&scan, &lookup, target, &voxels, &mut st, &mut sc).expect("lp");
    let mut bst = vec![0.0f64; Probe::state_len(&cfg, target, Gate::Gaussian, N_SLICE, N_SPADS)];
    let mut band = Probe::new(&scan, target, Gate::Gaussian, &voxels, &mut bst).expect("band");
    for (hists, laser) in scan_data.chunks_exact(ROW).zip(LASERS) {
        let row = rows.load(&scan, laser, hists).expect("row");
        lp.push_row(&scan, &lookup, &row).expect("lookup row");
        band.push_row(&scan, &row).expect("band row");
    }
    let (mut a, mut b) = (vec![0.0; N_SLICE], vec![0.0; N_SLICE]);
    lp.finish(&mut a).expect("lookup finish");
    band.finish(&scan, &mut b).expect("band finish");
    (a, b)
}

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
        vec![0.0f32; LOOKUP_STATE_LEN],
        vec![0.0f32; LOOKUP_STATE_LEN],
    );
    let (mut sc, mut c32) = (vec![0.0f32; SCRATCH_LEN], vec![0.0f32; COLUMN32_STATE_LEN]);
    let (mut stab, mut sst) = (
        vec![0.0f32; SLICE_TABLES_LEN],
        vec![0.0f32; SLICE_STATE_LEN],
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
        slice_tables: &mut stab,
        slice_state: &mut sst,
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
    // The slice against the same voxels as a list: the general lookup path (same grid, same
    // interpolation; only f32 rounding differs) and the band path.
    let (lp_diag, band_diag) = slice_references(scan, Target::Diagonal);
    let (lp_col, band_col) = slice_references(scan, Target::Column(FOCUS));
    let (sd_lp, sc_lp, sd_band, sc_band) = (
        rel(&f.slice_diag, &lp_diag),
        rel(&f.slice_col, &lp_col),
        rel(&f.slice_diag, &band_diag),
        rel(&f.slice_col, &band_col),
    );
    assert!(
        sd_lp < 1e-5 && sc_lp < 1e-5 && sd_band < 1e-3 && sc_band < 1e-2,
        "slice vs LookupProbe: diag {sd_lp:e}, col {sc_lp:e}; vs band: diag {sd_band:e}, col {sc_band:e}"
    );
    eprintln!(
        "slice vs LookupProbe: diag {sd_lp:.2e}, col {sc_lp:.2e}; vs band: diag {sd_band:.2e}, col {sc_band:.2e}"
    );
    // The Hermite slice (its own grid; no LookupProbe reads it): against the band path.
    let (hd_band, hc_band) = (
        rel(&f.slice_diag_h, &band_diag),
        rel(&f.slice_col_h, &band_col),
    );
    assert!(
        hd_band < 1e-3 && hc_band < 1e-2,
        "Hermite slice vs band: diag {hd_band:e}, col {hc_band:e}"
    );
    eprintln!("Hermite slice vs band: diag {hd_band:.2e}, col {hc_band:.2e}");
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
    writeln!(
        txt,
        "# slice_*: LookupSlice over a 10 x 4 lattice at z = 0.5 m (5 cm along the SPAD line, 15 cm across; voxel = iy*10 + ix, P1 = 13, P2 = 29); \
         same max relative amplitude difference vs LookupProbe over the same voxels: diag {sd_lp:.2e}, col {sc_lp:.2e}; vs the band path: diag {sd_band:.2e}, col {sc_band:.2e}"
    )
    .unwrap();
    writeln!(
        txt,
        "# slice_*_h: the same slice with Hermite cells (L = {}); vs the band path: diag {hd_band:.2e}, col {hc_band:.2e}",
        hermite_len()
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
    for i in 0..N_SLICE {
        writeln!(
            txt,
            "RESULT voxel={i} slice_diag={:e} slice_col={:e} slice_diag_h={:e} slice_col_h={:e}",
            f.slice_diag[i], f.slice_col[i], f.slice_diag_h[i], f.slice_col_h[i]
        )
        .unwrap();
    }
    for (name, x) in [
        ("lookup_diag", f.report_diag),
        ("lookup_col", f.report_col),
        ("lookup_col32", f.report_col32),
        ("slice_diag", f.report_slice_diag),
        ("slice_col", f.report_slice_col),
        ("slice_diag_h", f.report_slice_diag_h),
        ("slice_col_h", f.report_slice_col_h),
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

/// `L` of the Hermite slice's grid at the fixture's tolerance.
fn hermite_len() -> usize {
    let cfg = Config::try_new(&params()).expect("config");
    let p = vltm_kernel::LookupParams {
        interpolant: vltm_kernel::Interpolant::Hermite,
        ..lookup_params()
    };
    LookupGrid::try_new(&cfg, &p).expect("grid").len()
}
