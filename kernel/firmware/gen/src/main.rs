//! Host side of the firmware fixture.
//!
//! * `vltm-firmware-gen fixture CAPTURE.npz [DIR]` takes the fixture scan that the host
//!   simulator rendered of `../fixture/scene.json` (two point scatterers, direct and
//!   P1 ↔ P2 indirect paths, Gaussian pulse, seeded Poisson counts:
//!   `vltm simulate ../fixture/scene.json --out CAPTURE.npz --uncompressed`), checks that its
//!   geometry is the firmware's, writes `DIR/scan.bin` and runs the firmware's own pipeline
//!   (`../src/pipeline.rs`, the same kernel calls in the same order) on x86 to write
//!   `DIR/expected.txt` (and the fixed-point `expected_fixed.txt`, the lookup path's
//!   `expected_lookup.txt`). DIR defaults to
//!   `../fixture` (run from `gen/`). `../fixture/regenerate.sh` does both steps.
//! * `vltm-firmware-gen budget` prints the kernel memory of the paper's real setup.

#[path = "../../src/fixed_pipeline.rs"]
mod fixed_pipeline;
#[path = "../../src/fixture.rs"]
mod fixture;
mod lookup;
#[path = "../../src/lookup_pipeline.rs"]
mod lookup_pipeline;
mod npz;
#[path = "../../src/pipeline.rs"]
mod pipeline;
mod state;

use fixture::*;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use vltm_kernel::{Config, Gate, Params, Point, Probe, RowBuffer, Scan, Target};

/// The fixture scan, `N_LASERS × N_SPADS × NT` counts (layout of scan.bin), from the capture
/// that the host simulator rendered of `fixture/scene.json` (`vltm simulate … --uncompressed`):
/// its geometry and time axis must be the firmware's (`src/fixture.rs`), its values whole
/// counts that fit a `u16`.
fn load_scan(capture: &Path) -> Vec<u16> {
    let fail = |what: String| -> ! {
        eprintln!("{}: {what}", capture.display());
        std::process::exit(1)
    };
    let bytes = std::fs::read(capture).unwrap_or_else(|e| fail(e.to_string()));
    let arrays = npz::read(&bytes).unwrap_or_else(|e| fail(e));
    let get = |name: &str| match arrays.get(name) {
        Some(Ok(a)) => a,
        Some(Err(e)) => fail(e.clone()),
        None => fail(format!("no array `{name}`")),
    };
    let points = |name: &str, want: &[Point]| {
        let a = get(name);
        let got: Vec<Point> = a
            .values
            .chunks_exact(3)
            .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32])
            .collect();
        if got != want {
            fail(format!("`{name}` {got:?} is not src/fixture.rs's {want:?}"));
        }
    };
    points("laser_grid_xyz", &LASERS);
    points("sensor_grid_xyz", &SPADS);
    let scalar = |name: &str| match get(name).values[..] {
        [x] => x,
        _ => fail(format!("`{name}` is not a scalar")),
    };
    if (scalar("delta_t"), scalar("t_start")) != (DT, T0) {
        fail(format!("time axis is not dt = {DT}, t0 = {T0}"));
    }
    let h = get("H");
    if h.shape != [N_LASERS, 1, N_SPADS, 1, NT] {
        fail(format!(
            "H has shape {:?}, expected [{N_LASERS}, 1, {N_SPADS}, 1, {NT}]",
            h.shape
        ));
    }
    h.values
        .iter()
        .map(|&v| {
            if v.fract() == 0.0 && (0.0..=f64::from(u16::MAX)).contains(&v) {
                v as u16
            } else {
                fail(format!("H holds {v}, not a u16 count (render with noise)"))
            }
        })
        .collect()
}

fn fixture(capture: &Path, dir: PathBuf) {
    let cfg = Config::try_new(&params()).expect("fixture params");
    assert_eq!(
        (cfg.bins(), cfg.n_fft()),
        (BINS, N_FFT),
        "update BINS / N_FFT in src/fixture.rs"
    );
    assert_eq!(Scan::tables_len(&cfg, N_SPADS), TABLES_LEN);
    assert_eq!(RowBuffer::len(&cfg, N_SPADS), ROWBUF_LEN);
    let diag_len = Probe::state_len(&cfg, Target::Diagonal, Gate::Gaussian, N_VOXELS, N_SPADS);
    let col_len = Probe::state_len(
        &cfg,
        Target::Column(FOCUS),
        Gate::Gaussian,
        N_VOXELS,
        N_SPADS,
    );
    let ho_len = Probe::state_len(&cfg, Target::Diagonal, Gate::HigherOrder, N_VOXELS, N_SPADS);
    assert_eq!((diag_len, col_len, ho_len), (DIAG_LEN, COLUMN_LEN, HO_LEN));
    assert_eq!(VOXELS[P1_VOXEL], P1);
    assert_eq!(VOXELS[P2_VOXEL], P2);

    let scan = load_scan(capture);
    let bytes: Vec<u8> = scan.iter().flat_map(|c| c.to_le_bytes()).collect();
    std::fs::create_dir_all(&dir).expect("mkdir");
    std::fs::write(dir.join("scan.bin"), &bytes).expect("write scan.bin");

    let (mut tables, mut row) = (vec![0.0f32; TABLES_LEN], vec![0.0f32; ROWBUF_LEN]);
    let (mut d, mut c, mut p) = (
        vec![0.0f64; DIAG_LEN],
        vec![0.0f64; COLUMN_LEN],
        vec![0.0f64; DIAG_LEN],
    );
    let mut r = pipeline::Results::ZERO;
    let bufs = pipeline::Buffers {
        tables: &mut tables,
        row: &mut row,
        diag: &mut d,
        column: &mut c,
        diag_photons: &mut p,
    };
    pipeline::run(&scan, bufs, &mut r).expect("pipeline");
    let verdict = pipeline::verdict(&r);
    assert_eq!(
        verdict, 0,
        "the fixture fails the firmware's own checks: {r:#?}"
    );

    let mut txt = String::new();
    let photons: u64 = scan.iter().map(|&c| u64::from(c)).sum();
    writeln!(
        txt,
        "# vltm-firmware fixture: T = |A|^2 from vltm-kernel on the host ({}), the firmware's pipeline.",
        std::env::consts::ARCH
    )
    .unwrap();
    writeln!(
        txt,
        "# scan.bin: {N_LASERS} lasers x {N_SPADS} SPADs x {NT} bins u16 LE, {} bytes, {photons} counts; \
         lambda={WAVELENGTH} dt={DT} t0={T0} J={BINS} N={N_FFT}",
        bytes.len()
    )
    .unwrap();
    writeln!(
        txt,
        "# diag: Gaussian diagonal; col: Gaussian column T(P1, v); diag_photons: diagonal from photon events"
    )
    .unwrap();
    for i in 0..N_VOXELS {
        writeln!(
            txt,
            "RESULT voxel={i} diag={:e} col={:e} diag_photons={:e}",
            r.diag[i], r.col[i], r.diag_photons[i]
        )
        .unwrap();
    }
    let rep = |name: &str, x: vltm_kernel::Report| {
        format!(
            "REPORT {name} rows={} non_finite={} dropped={} aliased={}",
            x.rows, x.non_finite, x.dropped, x.aliased
        )
    };
    writeln!(txt, "{}", rep("diag", r.report_diag)).unwrap();
    writeln!(txt, "{}", rep("col", r.report_col)).unwrap();
    writeln!(txt, "{}", rep("diag_photons", r.report_photons)).unwrap();
    std::fs::write(dir.join("expected.txt"), &txt).expect("write expected.txt");
    fixed_fixture(&dir, &scan, &r);
    lookup::lookup_fixture(&dir, &scan, &r);
    print!("{txt}");
    eprintln!(
        "wrote {} ({} bytes) and expected.txt; verdict {verdict}",
        dir.join("scan.bin").display(),
        bytes.len()
    );
}

/// The paper's real setup (ICCV 2021 §6): 24 × 24 lasers, a 28-pixel SPAD line,
/// Δt = 2.55 cm (85 ps), a 6.5 m window, λ = 0.13 m.
pub fn real_params() -> Params {
    let dt = 0.0255;
    Params::new(0.13, (6.5f64 / dt).round() as usize, dt)
}

fn budget() {
    let p = real_params();
    let cfg = Config::try_new(&p).expect("real params");
    let (ks, kv, kl) = (28usize, 64 * 64usize, 24 * 24usize);
    let tables = 4 * Scan::tables_len(&cfg, ks);
    let rowbuf = 4 * RowBuffer::len(&cfg, ks);
    let hist = 2 * ks * cfg.nt();
    let diag = Probe::state_bytes(&cfg, Target::Diagonal, Gate::Gaussian, kv, ks);
    let col = Probe::state_bytes(
        &cfg,
        Target::Column([0.0, 0.0, 1.0]),
        Gate::Gaussian,
        kv,
        ks,
    );
    let ho = Probe::state_bytes(
        &cfg,
        Target::Column([0.0, 0.0, 1.0]),
        Gate::HigherOrder,
        kv,
        ks,
    );
    println!(
        "real setup: {kl} lasers, Ks={ks}, Nt={}, dt={} m, lambda={} m, sigma={:.4} m: N={} J={} (k {}..={}), R={}",
        cfg.nt(),
        cfg.dt(),
        cfg.wavelength(),
        cfg.sigma(),
        cfg.n_fft(),
        cfg.bins(),
        cfg.k_lo(),
        cfg.k_hi(),
        cfg.ho_support()
    );
    println!("| buffer | formula | bytes |");
    println!("|---|---|---|");
    println!("| band tables `Scan::tables_len` (f32) | 4·(2N + J + Ks) | {tables} |");
    println!("| row buffer `RowBuffer::len` (f32) | 4·Ks·(2J + 3) | {rowbuf} |");
    println!(
        "| one row of u16 histograms (caller's, optional with photon events) | 2·Ks·Nt | {hist} |"
    );
    println!("| diagonal × Gaussian, 64×64 voxels `Probe::state_bytes` | 8·2Kv | {diag} |");
    println!("| column × Gaussian, factorised `Probe::state_bytes` | 8·2J(Ks + 1) | {col} |");
    println!("| (column × higher-order, 64×64 voxels) | 8·2(Kv + Nt + 1) | {ho} |");
    println!(
        "| total: tables + row buffer + histograms + diagonal + column | | {} |",
        tables + rowbuf + hist + diag + col
    );
    println!(
        "| voxel list (caller's, 12 B per voxel), 64×64 | 12·Kv | {} |",
        12 * kv
    );
    println!(
        "per row: band DFT Ks·J·Nt = {} MACs; diagonal Kv·Ks = {} (voxel, SPAD) pairs × J = {} band terms; column Ks·J = {} terms",
        ks * cfg.bins() * cfg.nt(),
        kv * ks,
        kv * ks * cfg.bins(),
        ks * cfg.bins()
    );
}

/// The `--volume` spec of [`VOXELS`] (a point list, `x,y,z;…`), and `--focus` of [`FOCUS`]:
/// what the host passes to run the firmware's probes.
fn volume_spec() -> String {
    let pts: Vec<String> = VOXELS
        .iter()
        .map(|p| format!("{},{},{}", p[0], p[1], p[2]))
        .collect();
    pts.join(";")
}

/// `fixture/state_direct.json` and `fixture/state_column.json`: the header templates of the
/// firmware's states (`src/bin/state.rs`), from the host's partial states of the same probes.
fn state_templates(direct: &Path, column: &Path, dir: &Path) {
    assert_eq!(
        STATE_ROWS.end, N_LASERS,
        "the firmware takes the scan's last rows"
    );
    let make = |part: &Path, n_spads: usize, n_acc: usize, name: &str| {
        let bytes = std::fs::read(part).unwrap_or_else(|e| {
            eprintln!("{}: {e}", part.display());
            std::process::exit(1)
        });
        let t = state::template(&bytes, n_spads, N_VOXELS, n_acc).unwrap_or_else(|e| {
            eprintln!("{}: {e}", part.display());
            std::process::exit(1)
        });
        std::fs::write(dir.join(name), t + "\n").expect("write template");
    };
    make(direct, 0, DIAG_LEN, "state_direct.json");
    make(column, N_SPADS, COLUMN_LEN, "state_column.json");
}

/// Exits 1 unless the `.npy` volumes `a` and `b` agree within `rtol` of `b`'s largest value.
fn compare(a: &str, b: &str, rtol: &str) {
    let read = |p: &str| {
        std::fs::read(p).unwrap_or_else(|e| {
            eprintln!("{p}: {e}");
            std::process::exit(1)
        })
    };
    let rtol: f64 = rtol.parse().unwrap_or_else(|_| {
        eprintln!("RTOL `{rtol}` is not a number");
        std::process::exit(2)
    });
    match state::compare(&read(a), &read(b)) {
        Ok(e) if e <= rtol => println!("{a} = {b} within {e:.2e} of the peak (rtol {rtol:e})"),
        Ok(e) => {
            eprintln!("{a} differs from {b} by {e:.2e} of the peak (rtol {rtol:e})");
            std::process::exit(1)
        }
        Err(e) => {
            eprintln!("{a} vs {b}: {e}");
            std::process::exit(1)
        }
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    match args.next().as_deref() {
        Some("fixture") => {
            let Some(capture) = args.next() else {
                eprintln!("usage: vltm-firmware-gen fixture CAPTURE.npz [DIR]");
                std::process::exit(2);
            };
            fixture(
                Path::new(&capture),
                args.next()
                    .map_or_else(|| PathBuf::from("../fixture"), PathBuf::from),
            );
        }
        Some("budget") => budget(),
        Some("volume") => println!("{}", volume_spec()),
        // The host's rows: those the firmware-to-host run leaves (`--rows A:B`).
        Some("host-rows") => println!("0:{}", STATE_ROWS.start),
        Some("focus") => println!("{},{},{}", FOCUS[0], FOCUS[1], FOCUS[2]),
        Some("wavelength") => println!("{WAVELENGTH}"),
        Some("state-template") => {
            let (Some(d), Some(c), Some(dir)) = (args.next(), args.next(), args.next()) else {
                eprintln!("usage: vltm-firmware-gen state-template DIRECT.part COLUMN.part DIR");
                std::process::exit(2);
            };
            state_templates(Path::new(&d), Path::new(&c), Path::new(&dir));
        }
        Some("compare") => {
            let (Some(a), Some(b), Some(rtol)) = (args.next(), args.next(), args.next()) else {
                eprintln!("usage: vltm-firmware-gen compare A.npy B.npy RTOL");
                std::process::exit(2);
            };
            compare(&a, &b, &rtol);
        }
        _ => {
            eprintln!(
                "usage: vltm-firmware-gen fixture CAPTURE.npz [DIR] | budget | volume | \
                 state-template DIRECT.part COLUMN.part DIR | compare A.npy B.npy RTOL"
            );
            std::process::exit(2);
        }
    }
}

/// `expected_fixed.txt`: the fixed-point pipeline on the host (the M0 firmware must print the
/// same numbers), checked against the float pipeline's `r` first.
fn fixed_fixture(dir: &std::path::Path, scan: &[u16], r: &pipeline::Results) {
    use fixed_pipeline::*;
    let mut tables = vec![vltm_kernel::I1F15::ZERO; FIXED_TABLES_LEN];
    let (mut row, mut d, mut c) = (
        vec![0i32; FIXED_ROW_LEN],
        vec![0i64; FIXED_DIAG_LEN],
        vec![0i64; FIXED_COLUMN_LEN],
    );
    let (mut ph, mut dp) = (vec![0i64; FIXED_PHOTONS_LEN], vec![0i64; FIXED_DIAG_LEN]);
    let mut lt = vec![vltm_kernel::I1F15::ZERO; FIXED_LOOKUP_TABLES_LEN];
    let mut ld = vec![0i64; FIXED_DIAG_LEN];
    let mut f = FixedResults::ZERO;
    let bufs = FixedBuffers {
        tables: &mut tables,
        row: &mut row,
        diag: &mut d,
        column: &mut c,
        photons: &mut ph,
        diag_photons: &mut dp,
        lookup_tables: &mut lt,
        lookup_state: &mut ld,
    };
    run_fixed(scan, bufs, &mut f).expect("fixed pipeline");
    assert_eq!(
        verdict_fixed(&f),
        0,
        "fixed pipeline fails its checks: {f:#?}"
    );
    // |√T_fixed − √T_float| relative to the largest amplitude: the quantisation of
    // tests/fixed_point.rs, well below 1e-3 here.
    let rel = |a: &[f64], b: &[f64]| {
        let big = b.iter().fold(0.0f64, |m, x| m.max(x.sqrt()));
        a.iter()
            .zip(b)
            .fold(0.0f64, |m, (x, y)| m.max((x.sqrt() - y.sqrt()).abs() / big))
    };
    let (ed, ec) = (rel(&f.diag, &r.diag), rel(&f.col, &r.col));
    // The fixed-point lookup diagonal against the float band diagonal.
    let (el, elc) = (rel(&f.lookup_diag, &r.diag), rel(&f.lookup_col, &r.col));
    assert!(
        ed < 1e-3 && ec < 1e-3 && el < 1e-3 && elc < 1e-3,
        "fixed vs float: diag {ed:e}, col {ec:e}, lookup diag {el:e}, lookup col {elc:e}"
    );
    eprintln!(
        "fixed-point vs float, max |√T_fixed − √T_float| / max √T_float: diag {ed:.2e}, col {ec:.2e}, lookup diag {el:.2e}, lookup col {elc:.2e}"
    );
    let mut txt = String::new();
    writeln!(
        txt,
        "# vltm-firmware fixed-point fixture: T = |A|^2 from the kernel's fixed-point path on the host ({}).",
        std::env::consts::ARCH
    )
    .unwrap();
    writeln!(
        txt,
        "# same scan.bin; max |sqrt(T_fixed) - sqrt(T_float)| / max sqrt(T_float): diag {ed:.2e}, col {ec:.2e}, lookup_diag, lookup_col (fixed-point lookup path, L = {FIXED_LOOKUP_GRID}) {el:.2e}, {elc:.2e}"
    )
    .unwrap();
    for i in 0..N_VOXELS {
        writeln!(
            txt,
            "RESULT voxel={i} diag={:e} col={:e} diag_photons={:e} lookup_diag={:e} lookup_col={:e}",
            f.diag[i], f.col[i], f.diag_photons[i], f.lookup_diag[i], f.lookup_col[i]
        )
        .unwrap();
    }
    std::fs::write(dir.join("expected_fixed.txt"), &txt).expect("write expected_fixed.txt");
    print!("{txt}");
}
