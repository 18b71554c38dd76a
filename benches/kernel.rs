//! Per-row throughput of the kernel's stages and probes (criterion).
//!
//! Setups (issue 2):
//! * `paper1d`: the paper's real capture: 24×24 laser rows, a 28-pixel SPAD line, Δt = 2.55 cm
//!   (85 ps), a 6.5 m window, λ = 0.13 m; diagonal over a 64×64 slice.
//! * `exh16`: an exhaustive 16×16-by-16×16 scan with 800 bins of 6 mm, λ = σ = 0.5 m;
//!   diagonal over 16×16×24 voxels, one column over the same voxels.
//!
//! Each benchmark times one laser row (`push_row` of one probe, or stage 1 `load`).
//! Throughput is reported in (voxel·SPAD) pairs for the diagonal, bins for stage 1.
//! Run: `cargo bench --bench kernel` (≈ 3 min). The budget table is printed first.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use std::hint::black_box;
use vltm_kernel::{Config, Gate, Params, Point, Probe, RowBuffer, Scan, Target};

struct Setup {
    name: &'static str,
    cfg: Config,
    spads: Vec<Point>,
    voxels: Vec<Point>,
    column_voxels: Vec<Point>,
    hists: Vec<u16>,
    laser: Point,
}

fn grid(n: usize, half: f32) -> impl Iterator<Item = f32> {
    (0..n).map(move |i| {
        if n == 1 {
            0.0
        } else {
            -half + 2.0 * half * i as f32 / (n - 1) as f32
        }
    })
}

/// Deterministic Poisson-like counts (xorshift): background + a few returns per histogram.
fn counts(len: usize, nt: usize) -> Vec<u16> {
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let mut h: Vec<u16> = (0..len).map(|_| (next() % 3) as u16).collect();
    for chunk in h.chunks_mut(nt) {
        for _ in 0..4 {
            let i = (next() as usize) % nt;
            chunk[i] += 200;
        }
    }
    h
}

fn paper1d() -> Setup {
    let (dt, window) = (0.0255, 6.5);
    let nt = (window / dt) as usize;
    let cfg = Config::try_new(&Params::new(0.13, nt, dt)).unwrap();
    let spads: Vec<Point> = grid(28, 0.9).map(|x| [x, 0.0, 0.0]).collect();
    let voxels: Vec<Point> = grid(64, 1.0)
        .flat_map(|x| grid(64, 1.0).map(move |y| [x, y, 1.2]))
        .collect();
    Setup {
        name: "paper1d",
        cfg,
        hists: counts(spads.len() * nt, nt),
        column_voxels: voxels.clone(),
        spads,
        voxels,
        laser: [0.1, -0.2, 0.0],
    }
}

fn exh16() -> Setup {
    let nt = 800;
    let p = Params {
        sigma: Some(0.5),
        ..Params::new(0.5, nt, 0.006)
    };
    let cfg = Config::try_new(&p).unwrap();
    let spads: Vec<Point> = grid(16, 0.75)
        .flat_map(|x| grid(16, 0.75).map(move |y| [x, y, 0.0]))
        .collect();
    let voxels: Vec<Point> = grid(16, 0.75)
        .flat_map(|x| {
            grid(16, 0.75).flat_map(move |y| (0..24).map(move |k| [x, y, 0.4 + 0.05 * k as f32]))
        })
        .collect();
    Setup {
        name: "exh16",
        cfg,
        hists: counts(spads.len() * nt, nt),
        column_voxels: voxels.clone(),
        spads,
        voxels,
        laser: [0.1, -0.2, 0.0],
    }
}

fn budget(s: &Setup) {
    let (kv, ks) = (s.voxels.len(), s.spads.len());
    let c = &s.cfg;
    let b = |t, g| Probe::state_bytes(c, t, g, kv, ks);
    let col = Target::Column([0.0, 0.0, 1.0]);
    eprintln!(
        "{}: Nt={} N={} J={} Ks={} Kv={} | tables {} B, row buffer {} B | state: diag {} B, column(factorised) {} B, \
         higher-order column {} B, un-gated column {} B",
        s.name,
        c.nt(),
        c.n_fft(),
        c.bins(),
        ks,
        kv,
        4 * Scan::tables_len(c, ks),
        4 * RowBuffer::len(c, ks),
        b(Target::Diagonal, Gate::Gaussian),
        b(col, Gate::Gaussian),
        b(col, Gate::HigherOrder),
        b(col, Gate::None),
    );
}

fn bench_setup(c: &mut Criterion, s: &Setup) {
    budget(s);
    let cfg = &s.cfg;
    let ks = s.spads.len();
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, ks)];
    let scan = Scan::new(cfg, &s.spads, &mut tables).unwrap();
    let mut buf = vec![0.0f32; RowBuffer::len(cfg, ks)];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();

    let mut g = c.benchmark_group(s.name);
    g.sample_size(10);
    g.throughput(Throughput::Elements((ks * cfg.nt()) as u64));
    g.bench_function("stage1_band_spectra_row", |b| {
        b.iter(|| {
            let row = rows
                .load(&scan, black_box(s.laser), black_box(&s.hists))
                .unwrap();
            black_box(row.band()[0]);
        });
    });
    let row = rows.load(&scan, s.laser, &s.hists).unwrap();

    let focus = [0.0f32, 0.1, 1.0];
    let cases: [(&str, Target, Gate, &[Point]); 5] = [
        (
            "diagonal_gaussian",
            Target::Diagonal,
            Gate::Gaussian,
            &s.voxels,
        ),
        ("diagonal_ungated", Target::Diagonal, Gate::None, &s.voxels),
        (
            "column_gaussian_push",
            Target::Column(focus),
            Gate::Gaussian,
            &s.column_voxels,
        ),
        (
            "column_ungated_push",
            Target::Column(focus),
            Gate::None,
            &s.column_voxels,
        ),
        (
            "column_higher_order",
            Target::Column(focus),
            Gate::HigherOrder,
            &s.column_voxels[..256],
        ),
    ];
    for (name, target, gate, voxels) in cases {
        let mut state = vec![0.0f64; Probe::state_len(cfg, target, gate, voxels.len(), ks)];
        let mut probe = Probe::new(&scan, target, gate, voxels, &mut state).unwrap();
        g.throughput(Throughput::Elements((voxels.len() * ks) as u64));
        g.bench_function(BenchmarkId::new(name, voxels.len()), |b| {
            b.iter(|| probe.push_row(&scan, black_box(&row)).unwrap());
        });
        if matches!(target, Target::Column(_)) && gate == Gate::Gaussian {
            let mut out = vec![0.0f64; voxels.len()];
            g.bench_function(
                BenchmarkId::new("column_gaussian_finish", voxels.len()),
                |b| {
                    b.iter(|| probe.finish(&scan, black_box(&mut out)).unwrap());
                },
            );
        }
    }
    g.finish();
}

fn benches(c: &mut Criterion) {
    bench_setup(c, &paper1d());
    bench_setup(c, &exh16());
}

criterion_group! {
    name = kernel;
    config = Criterion::default().warm_up_time(std::time::Duration::from_millis(500))
        .measurement_time(std::time::Duration::from_secs(3));
    targets = benches
}
criterion_main!(kernel);
