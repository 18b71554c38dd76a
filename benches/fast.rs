//! Per-row cost of the host fast paths against the kernel's portable paths, and how they
//! scale (criterion, **one thread**: the host runs one row per core on top of this).
//!
//! * `stage1`: band spectra of one laser row, kernel `RowBuffer::load` (integer-phase DFT)
//!   vs `fast::BandDft` (one sgemm), for Nt = 200 / 400 / 800 (exh16 geometry, 16×16 SPADs);
//!   on a CPU with AVX-512 also the portable product beside the AVX-512 one (`fast::sgemm`).
//! * `planar_diagonal`: one row of the planar-FFT diagonal for the exh16 setup (16×16 SPADs,
//!   800 bins of 6 mm, λ = σ = 0.5 m, J = 33) over 16×16×24 voxels (pitch = SPAD pitch) and
//!   32×32×24 (half pitch, 4 polyphase sub-grids), and for 8×8 / 32×32 SPAD grids (voxels
//!   on the SPAD grid, 24 slices); plus 6 vs 24 slices.
//! * `column_image`: imaging a factorised column over 16×16×24 voxels once, kernel vs planar.
//! * `lookup_diagonal`: one row of the baseband-lookup diagonal on the paper's 1-D setup, and
//!   on the exh16 case of `planar_diagonal` (the two paths on the same row).
//! * `confocal_diagonal`: the confocal FFT convolution at the issue-12 size (64×64 confocal
//!   wall points, 2048 bins, λ = σ = 0.04 m): the forward transforms of the wall spectra and
//!   imaging 64×64×11 and 64×64×41 voxels (whole scan, the global thread pool).
//! * `indirect_gamma`: in-focus indirect light (Eq. 17) as `probe::indirect` runs it: per row
//!   the `push_row` of 64 factorised columns (one per voxel of Γ), once their imaging over Γ.
//!
//! The kernel's band diagonal over the same 16×16×24 voxels is `benches/kernel.rs`
//! (`exh16/diagonal_gaussian`, ≈ 150 ms per row). Memory of every path is printed first; none
//! depends on the number of laser rows. Run: `cargo bench --bench fast` (≈ 2 min).

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use num_complex::{Complex32, Complex64};
use std::hint::black_box;
use vltm::probe::fast::{BandDft, Confocal, Planar};
use vltm_kernel::{Config, Gate, Params, Point, Probe, RowBuffer, Scan, Target};

fn axis(n: usize, lo: f32, pitch: f32) -> impl Iterator<Item = f32> + Clone {
    (0..n).map(move |i| lo + pitch * i as f32)
}

/// An n×n SPAD grid of pitch 0.125 m centred on the origin.
fn spads(n: usize) -> Vec<Point> {
    let lo = -0.0625 * (n as f32 - 1.0);
    axis(n, lo, 0.125)
        .flat_map(|x| axis(n, lo, 0.125).map(move |y| [x, y, 0.0]))
        .collect()
}

/// Voxels over the SPAD grid's extent at pitch 0.125/r, `nz` slices from 0.4 m.
fn voxels(n: usize, r: usize, nz: usize) -> (Vec<Point>, [usize; 3]) {
    let lo = -0.0625 * (n as f32 - 1.0);
    let m = n * r;
    let p = 0.125 / r as f32;
    let pts = axis(m, lo, p)
        .flat_map(|x| {
            axis(m, lo, p).flat_map(move |y| (0..nz).map(move |k| [x, y, 0.4 + 0.04 * k as f32]))
        })
        .collect();
    (pts, [m, m, nz])
}

fn config(nt: usize) -> Config {
    Config::try_new(&Params {
        sigma: Some(0.5),
        ..Params::new(0.5, nt, 0.006)
    })
    .unwrap()
}

/// The exh16 setup (16×16 SPADs, 800 bins of 6 mm, λ = σ = 0.5 m) and one row of counts.
fn exh16() -> (Config, Vec<Point>, Vec<f32>) {
    let sp = spads(16);
    let h = hists(sp.len() * 800, 800);
    (config(800), sp, h)
}

/// Deterministic counts: background + returns.
fn hists(len: usize, nt: usize) -> Vec<f32> {
    let mut x = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let mut h: Vec<f32> = (0..len).map(|_| (next() % 3) as f32).collect();
    for chunk in h.chunks_mut(nt) {
        for _ in 0..4 {
            let i = (next() as usize) % nt;
            chunk[i] += 200.0;
        }
    }
    h
}

fn stage1(c: &mut Criterion) {
    let mut g = c.benchmark_group("stage1");
    g.sample_size(10);
    let sp = spads(16);
    for nt in [200, 400, 800] {
        let cfg = config(nt);
        let h = hists(sp.len() * nt, nt);
        let mut tables = vec![0.0f32; Scan::tables_len(&cfg, sp.len())];
        let scan = Scan::new(&cfg, &sp, &mut tables).unwrap();
        let mut buf = vec![0.0f32; RowBuffer::len(&cfg, sp.len())];
        let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
        let dft = BandDft::new(&cfg);
        g.throughput(Throughput::Elements((sp.len() * nt) as u64));
        g.bench_function(BenchmarkId::new("kernel_load", nt), |b| {
            b.iter(|| {
                black_box(
                    rows.load(&scan, [0.1, 0.0, 0.0], black_box(&h))
                        .unwrap()
                        .band()[0],
                )
            });
        });
        g.bench_function(BenchmarkId::new("sgemm_load_with", nt), |b| {
            b.iter(|| {
                let row = rows
                    .load_with(&scan, [0.1, 0.0, 0.0], black_box(&h), |band, m| {
                        dft.apply(&h, band, m);
                    })
                    .unwrap();
                black_box(row.band()[0])
            });
        });
        // The portable product (`matrixmultiply`), where `BandDft::new` took AVX-512 lanes.
        if dft.uses_avx512() {
            let portable = BandDft::portable_table(&cfg);
            g.bench_function(BenchmarkId::new("sgemm_portable_load_with", nt), |b| {
                b.iter(|| {
                    let row = rows
                        .load_with(&scan, [0.1, 0.0, 0.0], black_box(&h), |band, m| {
                            portable.apply(&h, band, m);
                        })
                        .unwrap();
                    black_box(row.band()[0])
                });
            });
        }
    }
    g.finish();
}

struct Case {
    name: String,
    ns: usize,
    r: usize,
    nz: usize,
}

fn planar_diagonal(c: &mut Criterion) {
    let cfg = config(800);
    let mut g = c.benchmark_group("planar_diagonal");
    g.sample_size(10);
    let cases = [
        Case {
            name: "exh16_16x16x24".into(),
            ns: 16,
            r: 1,
            nz: 24,
        },
        Case {
            name: "exh16_32x32x24".into(),
            ns: 16,
            r: 2,
            nz: 24,
        },
        Case {
            name: "exh16_16x16x6".into(),
            ns: 16,
            r: 1,
            nz: 6,
        },
        Case {
            name: "spads8_8x8x24".into(),
            ns: 8,
            r: 1,
            nz: 24,
        },
        Case {
            name: "spads32_32x32x24".into(),
            ns: 32,
            r: 1,
            nz: 24,
        },
    ];
    for case in cases {
        let sp = spads(case.ns);
        let (vox, shape) = voxels(case.ns, case.r, case.nz);
        let planar = Planar::new(&cfg, &sp, &vox, shape).unwrap();
        let mut scratch = vltm::probe::fast::planar::Scratch::default();
        let (mx, my, slices) = planar.shape();
        eprintln!(
            "planar {}: Ks = {}, Kv = {}, FFT {mx}×{my}, {slices} slices, κ̂ {:.1} MB shared, \
             scratch {:.2} MB + {} B accumulators per worker",
            case.name,
            sp.len(),
            vox.len(),
            planar.table_bytes() as f64 / 1e6,
            (3 * cfg.bins() * mx * my * 8) as f64 / 1e6,
            16 * vox.len(),
        );
        let spectra: Vec<Complex32> = (0..sp.len() * cfg.bins())
            .map(|i| Complex32::new((i % 7) as f32 - 3.0, (i % 5) as f32 - 2.0))
            .collect();
        let skip = vec![false; vox.len()];
        let mut acc = vec![Complex64::new(0.0, 0.0); vox.len()];
        let laser: Point = [0.1, -0.2, 0.0];
        g.throughput(Throughput::Elements((vox.len() * sp.len()) as u64));
        g.bench_function(BenchmarkId::from_parameter(&case.name), |b| {
            b.iter(|| {
                planar.apply(
                    black_box(&spectra),
                    &vox,
                    |v| {
                        let d = ((0..3).map(|i| (v[i] - laser[i]).powi(2)).sum::<f32>()).sqrt();
                        (d, cfg.weight(d))
                    },
                    &skip,
                    &mut scratch,
                    &mut acc,
                );
            });
        });
    }
    g.finish();
}

fn column_image(c: &mut Criterion) {
    let (cfg, sp, h) = exh16();
    let (vox, shape) = voxels(16, 1, 24);
    let mut tables = vec![0.0f32; Scan::tables_len(&cfg, sp.len())];
    let scan = Scan::new(&cfg, &sp, &mut tables).unwrap();
    let mut buf = vec![0.0f32; RowBuffer::len(&cfg, sp.len())];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    let row = rows.load(&scan, [0.1, 0.0, 0.0], &h).unwrap();
    let focus: Point = [0.0, 0.1, 0.8];
    let target = Target::Column(focus);
    let mut state = vec![0.0f64; Probe::state_len(&cfg, target, Gate::Gaussian, 0, sp.len())];
    let mut probe = Probe::new(&scan, target, Gate::Gaussian, &[], &mut state).unwrap();
    probe.push_row(&scan, &row).unwrap();
    let mut g = c.benchmark_group("column_image");
    g.sample_size(10);
    g.throughput(Throughput::Elements((vox.len() * sp.len()) as u64));
    let mut out = vec![0.0f64; vox.len()];
    g.bench_function("kernel_16x16x24", |b| {
        b.iter(|| probe.image(&scan, black_box(&vox), &mut out).unwrap());
    });
    g.bench_function("planar_16x16x24_incl_table", |b| {
        b.iter(|| {
            let planar = Planar::new(&cfg, &sp, &vox, shape).unwrap();
            let (u, _) = probe.column_spectra().unwrap();
            let u: Vec<Complex32> = u
                .iter()
                .map(|z| Complex32::new(z.re as f32, z.im as f32))
                .collect();
            let mut acc = vec![Complex64::new(0.0, 0.0); vox.len()];
            let skip = vec![false; vox.len()];
            planar.apply(
                &u,
                &vox,
                |b| {
                    let d = ((0..3).map(|i| (b[i] - focus[i]).powi(2)).sum::<f32>()).sqrt();
                    (d, 1.0)
                },
                &skip,
                &mut vltm::probe::fast::planar::Scratch::default(),
                &mut acc,
            );
            black_box(acc[0])
        });
    });
    g.finish();
}

/// The baseband lookup on the paper's real setup (a 28-pixel SPAD line, 64×64 voxels whose
/// pitch is not a divisor of the SPAD pitch: no planar path), one row; the kernel's band sum
/// on the same row is `benches/kernel.rs` `paper1d/diagonal_gaussian`.
fn lookup_diagonal(c: &mut Criterion) {
    let (dt, window) = (0.0255, 6.5);
    let nt = (window / dt) as usize;
    let cfg = Config::try_new(&Params::new(0.13, nt, dt)).unwrap();
    let line =
        |n: usize, half: f32| (0..n).map(move |i| -half + 2.0 * half * i as f32 / (n - 1) as f32);
    let sp: Vec<Point> = line(28, 0.9).map(|x| [x, 0.0, 0.0]).collect();
    let vox: Vec<Point> = line(64, 1.0)
        .flat_map(|x| line(64, 1.0).map(move |y| [x, y, 1.2]))
        .collect();
    let h = hists(sp.len() * nt, nt);
    let mut tables = vec![0.0f32; Scan::tables_len(&cfg, sp.len())];
    let scan = Scan::new(&cfg, &sp, &mut tables).unwrap();
    let mut buf = vec![0.0f32; RowBuffer::len(&cfg, sp.len())];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    let row = rows.load(&scan, [0.1, -0.2, 0.0], &h).unwrap();
    let lookup = vltm::probe::fast::LookupDiagonal::new(&cfg);
    let mut scratch = lookup.scratch(sp.len());
    let mut acc = vec![Complex64::new(0.0, 0.0); vox.len()];
    eprintln!(
        "lookup paper1d: Ks = {}, Kv = {}, grid L = {} ({:.2}× N), scratch {:.2} MB per worker",
        sp.len(),
        vox.len(),
        lookup.grid_len(),
        lookup.oversampling(),
        lookup.scratch_bytes(sp.len()) as f64 / 1e6
    );
    let mut g = c.benchmark_group("lookup_diagonal");
    g.sample_size(10);
    g.throughput(Throughput::Elements((vox.len() * sp.len()) as u64));
    g.bench_function("paper1d_64x64", |b| {
        b.iter(|| lookup.apply(&scan, black_box(&row), &vox, &mut scratch, &mut acc));
    });
    // The exh16 case of `planar_diagonal` (16×16 SPADs, 16×16×24 voxels at the SPAD pitch):
    // the lookup and the planar path measured on the same row.
    let (cfg, sp, h) = exh16();
    let (vox, _) = voxels(16, 1, 24);
    let mut tables = vec![0.0f32; Scan::tables_len(&cfg, sp.len())];
    let scan = Scan::new(&cfg, &sp, &mut tables).unwrap();
    let mut buf = vec![0.0f32; RowBuffer::len(&cfg, sp.len())];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    let row = rows.load(&scan, [0.1, 0.0, 0.0], &h).unwrap();
    let lookup = vltm::probe::fast::LookupDiagonal::new(&cfg);
    let mut scratch = lookup.scratch(sp.len());
    let mut acc = vec![Complex64::new(0.0, 0.0); vox.len()];
    g.throughput(Throughput::Elements((vox.len() * sp.len()) as u64));
    g.bench_function("exh16_16x16x24", |b| {
        b.iter(|| lookup.apply(&scan, black_box(&row), &vox, &mut scratch, &mut acc));
    });
    g.finish();
}

/// In-focus indirect light (Eq. 17) as `probe::indirect` evaluates it: one factorised
/// column per voxel of Γ, so per row `G·Ks·J` (`push_row` of G column probes), then once the
/// G columns imaged over Γ (`G²·Ks` band sums). exh16 setup, G = 64 voxels of a 8×8 patch of
/// the 16×16 grid at z = 0.8 m.
fn indirect_gamma(c: &mut Criterion) {
    let (cfg, sp, h) = exh16();
    let mut tables = vec![0.0f32; Scan::tables_len(&cfg, sp.len())];
    let scan = Scan::new(&cfg, &sp, &mut tables).unwrap();
    let mut buf = vec![0.0f32; RowBuffer::len(&cfg, sp.len())];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    let row = rows.load(&scan, [0.1, 0.0, 0.0], &h).unwrap();
    let gamma: Vec<Point> = axis(8, -0.4375, 0.125)
        .flat_map(|x| axis(8, -0.4375, 0.125).map(move |y| [x, y, 0.8]))
        .collect();
    let n_state = Probe::state_len(&cfg, Target::Column(gamma[0]), Gate::Gaussian, 0, sp.len());
    let mut states = vec![vec![0.0f64; n_state]; gamma.len()];
    let mut probes: Vec<Probe<'_>> = gamma
        .iter()
        .zip(states.iter_mut())
        .map(|(a, s)| Probe::new(&scan, Target::Column(*a), Gate::Gaussian, &[], s).unwrap())
        .collect();
    eprintln!(
        "indirect exh16: G = {} columns, {:.2} MB of column state",
        gamma.len(),
        (gamma.len() * n_state * 8) as f64 / 1e6
    );
    let mut g = c.benchmark_group("indirect_gamma");
    g.sample_size(10);
    g.throughput(Throughput::Elements((gamma.len() * sp.len()) as u64));
    g.bench_function("push_row_64_columns", |b| {
        b.iter(|| {
            for p in probes.iter_mut() {
                p.push_row(&scan, black_box(&row)).unwrap();
            }
        });
    });
    let mut out = vec![0.0f64; gamma.len()];
    g.throughput(Throughput::Elements(
        (gamma.len() * gamma.len() * sp.len()) as u64,
    ));
    g.bench_function("image_64_columns_over_gamma_once", |b| {
        b.iter(|| {
            for p in &probes {
                p.image(&scan, black_box(&gamma), &mut out).unwrap();
            }
        });
    });
    g.finish();
}

/// The confocal FFT convolution (`fast::confocal`) at the issue-12 target size: a 64×64
/// confocal wall grid over 0.8 m (the Stanford captures' layout), 2048 bins of 1.2 mm,
/// λ = σ = 0.04 m (J = 116), no lens weights, voxels at the wall pitch over z 0.55–0.75 m:
/// the forward transforms of the wall spectra, then imaging 11 and 41 slices (threads: the
/// global pool, as `probe::direct` runs it). Stage 1 of the 4096 rows is `stage1`'s sgemm.
fn confocal_diagonal(c: &mut Criterion) {
    let n = 64;
    let p = 0.8 / (n - 1) as f32;
    let wall: Vec<Point> = axis(n, -0.4, p)
        .flat_map(|x| axis(n, -0.4, p).map(move |y| [x, y, 0.0]))
        .collect();
    let cfg = Config::try_new(&Params {
        sigma: Some(0.04),
        weights: vltm_kernel::Weights::One,
        ..Params::new(0.04, 2048, 0.0012)
    })
    .unwrap();
    let j = cfg.bins();
    let spectra_of = |conv: &Confocal| {
        let mut s = conv.spectra();
        let h: Vec<Complex32> = (0..j)
            .map(|k| Complex32::new((k % 7) as f32 - 3.0, (k % 5) as f32 - 2.0))
            .collect();
        for l in 0..wall.len() {
            conv.place(&mut s, l, &h);
        }
        s
    };
    let mut g = c.benchmark_group("confocal_diagonal");
    g.sample_size(10);
    for nz in [11usize, 41] {
        let vox: Vec<Point> = axis(n, -0.4, p)
            .flat_map(|x| {
                axis(n, -0.4, p).flat_map(move |y| {
                    (0..nz).map(move |k| [x, y, 0.55 + 0.2 * k as f32 / (nz - 1) as f32])
                })
            })
            .collect();
        let conv = Confocal::new(&cfg, &wall, &vox, [n, n, nz]).unwrap();
        let (mx, my, slices) = conv.shape();
        println!(
            "confocal 64x64 wall, {nz} slices: J = {j}, FFT {mx}×{my}, {slices} slices, \
             wall spectra {:.1} MB",
            conv.spectra_bytes() as f64 / 1e6,
        );
        let mut spectra = spectra_of(&conv);
        if nz == 11 {
            g.bench_function("forward_64x64_J116", |b| {
                b.iter(|| {
                    let mut s = spectra.clone();
                    conv.forward(black_box(&mut s));
                    black_box(s[0])
                });
            });
        }
        conv.forward(&mut spectra);
        let skip = vec![false; vox.len()];
        let mut acc = vec![Complex64::new(0.0, 0.0); vox.len()];
        g.throughput(Throughput::Elements(vox.len() as u64));
        g.bench_function(BenchmarkId::new("image_64x64", nz), |b| {
            b.iter(|| conv.image(Some(0.0), black_box(&spectra), &skip, &mut acc));
        });
    }
    g.finish();
}

criterion_group! {
    name = fast;
    config = Criterion::default().warm_up_time(std::time::Duration::from_millis(500));
    targets = stage1, planar_diagonal, column_image, lookup_diagonal, indirect_gamma,
        confocal_diagonal
}
criterion_main!(fast);
