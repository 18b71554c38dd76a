//! Unit tests of the baseband lookup diagonal (`super`).

use super::*;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::f64::consts::TAU;
use vltm_kernel::{Gate, Legs, Params, Probe, RowBuffer, Target};

/// A test geometry: SPADs on a line (x axis, z = 0), one laser spot, voxels in a box.
struct Case {
    cfg: Config,
    spads: Vec<Point>,
    laser: Point,
    voxels: Vec<Point>,
    hists: Vec<f32>,
}

/// Random row with peaks at random path lengths and a noise floor.
fn case(p: &Params, ks: usize, kv: usize, seed: u64) -> Case {
    let cfg = Config::try_new(p).unwrap();
    let mut rng = StdRng::seed_from_u64(seed);
    let spads: Vec<Point> = (0..ks)
        .map(|i| [-0.7 + 1.4 * i as f32 / ks as f32 + 0.013, 0.05, 0.0])
        .collect();
    let laser = [0.2, -0.3, 0.0];
    let voxels: Vec<Point> = (0..kv)
        .map(|_| {
            [
                rng.random_range(-0.8..0.8),
                rng.random_range(-0.8..0.8),
                rng.random_range(0.1..1.6),
            ]
        })
        .collect();
    let nt = cfg.nt();
    let mut hists = vec![0.0f32; ks * nt];
    for h in hists.chunks_exact_mut(nt) {
        for x in h.iter_mut() {
            *x = rng.random::<f32>();
        }
        for _ in 0..4 {
            h[rng.random_range(0..nt)] += rng.random_range(20.0..100.0);
        }
    }
    Case {
        cfg,
        spads,
        laser,
        voxels,
        hists,
    }
}

struct Outcome {
    /// Kernel band diagonal intensities.
    band: Vec<f64>,
    /// Lookup amplitudes.
    lookup: Vec<Complex64>,
    /// f64 band sum (same f32 τ and guard decisions) amplitudes.
    exact: Vec<Complex64>,
    /// Fraction of voxels with at least one guarded-out path.
    cut: f64,
}

/// Runs one row through the kernel's band diagonal, the lookup (voxels shifted by
/// `shift` m in z) and an f64 band sum.
fn run(c: &Case, shift: f32) -> Outcome {
    let cfg = &c.cfg;
    let ks = c.spads.len();
    let kv = c.voxels.len();
    let mut tables = vec![0.0; Scan::tables_len(cfg, ks)];
    let scan = Scan::new(cfg, &c.spads, &mut tables).unwrap();
    let mut buf = vec![0.0; RowBuffer::len(cfg, ks)];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    let row = rows.load(&scan, c.laser, &c.hists).unwrap();
    let mut state = vec![0.0; Probe::state_len(cfg, Target::Diagonal, Gate::Gaussian, kv, ks)];
    let mut probe = Probe::new(
        &scan,
        Target::Diagonal,
        Gate::Gaussian,
        &c.voxels,
        &mut state,
    )
    .unwrap();
    probe.push_row(&scan, &row).unwrap();
    let mut band = vec![0.0; kv];
    probe.finish(&scan, &mut band).unwrap();

    let lk = LookupDiagonal::new(cfg);
    let mut s = lk.scratch(ks);
    let moved: Vec<Point> = c
        .voxels
        .iter()
        .map(|v| [v[0], v[1], v[2] + shift])
        .collect();
    let mut lookup = vec![Complex64::new(0.0, 0.0); kv];
    lk.apply(&scan, &row, &moved, &mut s, &mut lookup);

    let (g_lo, g_hi) = cfg.guard();
    let (g_lo, g_hi) = (g_lo as f32, g_hi as f32);
    let j = cfg.bins();
    let mut cuts = 0;
    let exact = c
        .voxels
        .iter()
        .map(|v| {
            let d_lv = dist(&c.laser, v);
            let mut sum = Complex64::new(0.0, 0.0);
            let mut cut = false;
            for ((sp, hg), off) in c
                .spads
                .iter()
                .zip(row.band().chunks_exact(j))
                .zip(row.offsets())
            {
                let d_vs = dist(v, sp);
                let tau = d_lv + d_vs;
                let rel = tau + off;
                if !(rel >= g_lo && rel <= g_hi) {
                    cut = true;
                    continue;
                }
                let z: Complex64 = hg
                    .iter()
                    .enumerate()
                    .map(|(j, h)| {
                        let k = (cfg.k_lo() + j as i64) as f64;
                        let ph = Complex64::from_polar(1.0, TAU * k * tau as f64 / cfg.span());
                        Complex64::new(h.re as f64, h.im as f64) * ph
                    })
                    .sum();
                sum += z * cfg.weight(d_vs) as f64;
            }
            cuts += usize::from(cut);
            sum * cfg.weight(d_lv) as f64
        })
        .collect();
    Outcome {
        band,
        lookup,
        exact,
        cut: cuts as f64 / kv as f64,
    }
}

/// max | |A_f64|² − I_band | / max I_band: the kernel's own `f32` error, for scale.
fn kernel_error(o: &Outcome) -> f64 {
    let i_max = o.band.iter().copied().fold(0.0, f64::max);
    o.band
        .iter()
        .zip(&o.exact)
        .map(|(b, e)| (e.norm_sqr() - b).abs())
        .fold(0.0, f64::max)
        / i_max
}

/// (max |I_lookup − I_band| / max I_band, max |A_lookup − A_f64| / max |A_f64|).
fn errors(o: &Outcome) -> (f64, f64) {
    let i_max = o.band.iter().copied().fold(0.0, f64::max);
    let a_max = o.exact.iter().map(|a| a.norm()).fold(0.0, f64::max);
    let di = o
        .band
        .iter()
        .zip(&o.lookup)
        .map(|(b, l)| (l.norm_sqr() - b).abs())
        .fold(0.0, f64::max);
    let da = o
        .exact
        .iter()
        .zip(&o.lookup)
        .map(|(e, l)| (e - l).norm())
        .fold(0.0, f64::max);
    (di / i_max, da / a_max)
}

/// Parameters: λ = 0.13 m, Δt = λ/ratio, a window from t0 = 0.9 m to ~2.6 m so that
/// a good part of the voxels have paths outside the guard on either side.
fn params(ratio: f64) -> Params {
    let lam = 0.13;
    let dt = lam / ratio;
    Params {
        t0: 0.9,
        ..Params::new(lam, (1.7 / dt) as usize, dt)
    }
}

const TOL: f64 = 1e-4;

fn check(p: &Params, seed: u64) -> (f64, f64) {
    let c = case(p, 16, 200, seed);
    let o = run(&c, 0.0);
    let (di, da) = errors(&o);
    let lk = LookupDiagonal::new(&c.cfg);
    println!(
        "λ/Δt {:5.1}  σ/Δt {:5.2}  N {:5}  L {:5} (×{:.2})  J {:4}  cut {:3.0}%  \
         intensity err {di:.2e}  amplitude err {da:.2e}  (kernel vs f64: {:.2e})",
        p.wavelength / p.dt,
        c.cfg.sigma() / p.dt,
        c.cfg.n_fft(),
        lk.grid_len(),
        lk.oversampling(),
        c.cfg.bins(),
        100.0 * o.cut,
        kernel_error(&o)
    );
    assert!(o.cut > 0.1 && o.cut < 0.9, "guard cut {:.2}", o.cut);
    assert!(di <= TOL, "intensity error {di:.3e}");
    assert!(da <= TOL / 2.0, "amplitude error {da:.3e}");
    (di, da)
}

#[test]
fn matches_band_diagonal_ratios() {
    let mut worst = (0.0f64, 0.0f64);
    for (k, ratio) in [6.0, 8.0, 13.0, 20.0, 40.0].into_iter().enumerate() {
        let (di, da) = check(&params(ratio), 10 + k as u64);
        worst = (worst.0.max(di), worst.1.max(da));
    }
    println!(
        "worst: intensity {:.2e}, amplitude {:.2e}",
        worst.0, worst.1
    );
}

#[test]
fn matches_band_diagonal_weights_and_legs() {
    let legs = Legs::FirstAndLast {
        laser_origin: [0.3, -1.0, -0.4],
        sensor_origin: [-0.2, 0.5, -0.3],
    };
    for (k, (ratio, weights, legs, t0)) in [
        (6.0, Weights::One, Legs::WallToWall, 0.9),
        (10.0, Weights::Inv, legs, 2.1),
        (25.0, Weights::One, legs, 2.1),
        (40.0, Weights::Inv, legs, 2.1),
    ]
    .into_iter()
    .enumerate()
    {
        let p = Params {
            weights,
            legs,
            t0,
            ..params(ratio)
        };
        check(&p, 20 + k as u64);
    }
}

#[test]
fn catches_a_one_centimetre_shift() {
    let c = case(&params(8.0), 16, 200, 3);
    let (di, da) = errors(&run(&c, 0.01));
    println!("1 cm shift: intensity err {di:.2e}, amplitude err {da:.2e}");
    assert!(di > 10.0 * TOL && da > 10.0 * TOL, "{di:.2e} {da:.2e}");
}

#[test]
fn fast_lengths() {
    assert_eq!(fast_len(1), 1);
    assert_eq!(fast_len(7), 8);
    assert_eq!(fast_len(847), 864);
    assert_eq!(fast_len(1001), 1024);
    for n in 1..3000 {
        let l = fast_len(n);
        let mut r = l;
        for p in [2, 3, 5] {
            while r.is_multiple_of(p) {
                r /= p;
            }
        }
        assert!(l >= n && r == 1 && l < n + n / 8 + 2, "{n} → {l}");
    }
}

/// The cold wrapping path equals the contiguous fast path, also one period away.
#[test]
fn wrapped_path_agrees() {
    let c = case(&params(8.0), 3, 1, 5);
    let cfg = &c.cfg;
    let mut tables = vec![0.0; Scan::tables_len(cfg, 3)];
    let scan = Scan::new(cfg, &c.spads, &mut tables).unwrap();
    let mut buf = vec![0.0; RowBuffer::len(cfg, 3)];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    let row = rows.load(&scan, c.laser, &c.hists).unwrap();
    let lk = LookupDiagonal::new(cfg);
    let mut s = lk.scratch(3);
    lk.tables(scan.spads(), row.band(), row.offsets(), &mut s);
    let (g_lo, g_hi) = cfg.guard();
    let stride = lk.len + EXTRA;
    let period = lk.len as f64;
    let mut worst: f32 = 0.0;
    for (si, off) in row.offsets().iter().enumerate() {
        let tab = &s.tables[si * stride..(si + 1) * stride];
        for i in 0..500 {
            let rel = g_lo + (g_hi - g_lo) * (i as f64 + 0.5) / 500.0;
            let tau = (rel - *off as f64) as f32;
            let fast = lk.gated(tab, s.base[si], tau);
            let x = tau as f64 * lk.per_m - s.base[si].0;
            for shift in [0.0, period, -period, -3.0 * period] {
                let z = lk.gated_wrapped(tab, s.base[si].1, x + shift);
                worst = worst.max((z - fast).norm() / fast.norm().max(1e-30));
                assert!((z - fast).norm() <= 1e-4 * fast.norm() + 1e-9, "{z} {fast}");
            }
        }
    }
    println!("wrapped vs fast path: worst relative difference {worst:.2e}");
}

/// Worst amplitude error of one SPAD's interpolated `Z(τ)` against the f64 band sum,
/// relative to `max |Z|`, over dense τ in the guard, for a density of `r` samples per σ.
fn interp_error(p: &Params, r: f64, seed: u64) -> f64 {
    let c = case(p, 4, 1, seed);
    let cfg = &c.cfg;
    let mut tables = vec![0.0; Scan::tables_len(cfg, 4)];
    let scan = Scan::new(cfg, &c.spads, &mut tables).unwrap();
    let mut buf = vec![0.0; RowBuffer::len(cfg, 4)];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    let row = rows.load(&scan, c.laser, &c.hists).unwrap();
    let lk = LookupDiagonal::with_density(cfg, r);
    let mut s = lk.scratch(4);
    lk.tables(scan.spads(), row.band(), row.offsets(), &mut s);
    let (g_lo, g_hi) = cfg.guard();
    let j = cfg.bins();
    let mut worst: f64 = 0.0;
    for (si, off) in row.offsets().iter().enumerate() {
        let hg = &row.band()[si * j..(si + 1) * j];
        let tab = &s.tables[si * (lk.len + EXTRA)..(si + 1) * (lk.len + EXTRA)];
        let n = 4000;
        let (mut zmax, mut emax) = (0.0f64, 0.0f64);
        for i in 0..=n {
            let rel = g_lo + (g_hi - g_lo) * (i as f64 + 0.37) / (n + 1) as f64;
            let tau = (rel - *off as f64) as f32;
            let exact: Complex64 = hg
                .iter()
                .enumerate()
                .map(|(j, h)| {
                    let k = (cfg.k_lo() + j as i64) as f64;
                    Complex64::new(h.re as f64, h.im as f64)
                        * Complex64::from_polar(1.0, TAU * k * tau as f64 / cfg.span())
                })
                .sum();
            let z = lk.gated(tab, s.base[si], tau);
            zmax = zmax.max(exact.norm());
            emax = emax.max((Complex64::new(z.re as f64, z.im as f64) - exact).norm());
        }
        worst = worst.max(emax / zmax);
    }
    worst
}

#[test]
fn interpolation_error() {
    let ratios = [6.0, 13.0, 40.0];
    for r in [4.0, 6.0, 8.0, 10.0, 12.0, 14.0, 16.0] {
        let e = ratios
            .iter()
            .enumerate()
            .map(|(k, &q)| interp_error(&params(q), r, 40 + k as u64))
            .fold(0.0, f64::max);
        println!("{r:4} samples/σ: worst relative amplitude error {e:.2e}");
        if r == SAMPLES_PER_SIGMA {
            assert!(e < 1e-5, "{e:.2e}");
        }
    }
}

/// `cargo test --release -p vltm --lib fast::lookup::tests::timing -- --ignored --nocapture`
#[test]
#[ignore = "timing, prints numbers only"]
fn timing() {
    use std::time::Instant;
    let p = Params::new(0.13, 254, 0.0255);
    let cfg = Config::try_new(&p).unwrap();
    let ks = 28;
    let spads: Vec<Point> = (0..ks)
        .map(|i| [-0.7 + 1.4 * i as f32 / (ks - 1) as f32, 0.0, 0.0])
        .collect();
    let voxels: Vec<Point> = (0..4096)
        .map(|i| {
            let (x, y, z) = (i / 256, (i / 16) % 16, i % 16);
            [
                -0.8 + 0.1 * x as f32,
                -0.8 + 0.1 * y as f32,
                0.3 + 0.1 * z as f32,
            ]
        })
        .collect();
    let mut rng = StdRng::seed_from_u64(7);
    let hists: Vec<f32> = (0..ks * 254).map(|_| rng.random::<f32>()).collect();
    let mut tables = vec![0.0; Scan::tables_len(&cfg, ks)];
    let scan = Scan::new(&cfg, &spads, &mut tables).unwrap();
    let mut buf = vec![0.0; RowBuffer::len(&cfg, ks)];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    let row = rows.load(&scan, [0.1, 0.2, 0.0], &hists).unwrap();
    let kv = voxels.len();
    let mut state = vec![0.0; Probe::state_len(&cfg, Target::Diagonal, Gate::Gaussian, kv, ks)];
    let mut probe =
        Probe::new(&scan, Target::Diagonal, Gate::Gaussian, &voxels, &mut state).unwrap();
    let lk = LookupDiagonal::new(&cfg);
    let mut s = lk.scratch(ks);
    let mut acc = vec![Complex64::new(0.0, 0.0); kv];
    let reps = 20;
    let t = Instant::now();
    for _ in 0..reps {
        probe.push_row(&scan, &row).unwrap();
    }
    let band = t.elapsed().as_secs_f64() / reps as f64;
    let t = Instant::now();
    for _ in 0..reps * 10 {
        lk.apply(&scan, &row, &voxels, &mut s, &mut acc);
    }
    let look = t.elapsed().as_secs_f64() / (reps * 10) as f64;
    let t = Instant::now();
    for _ in 0..reps * 10 {
        lk.tables(scan.spads(), row.band(), row.offsets(), &mut s);
    }
    let ffts = t.elapsed().as_secs_f64() / (reps * 10) as f64;
    let pairs = (kv * ks) as f64;
    println!(
        "{ks} SPADs × {kv} voxels, Nt 254, N {}, J {}, L {} (×{:.2}): band diagonal \
         {:.2} ms/row ({:.1} ns/pair), lookup {:.3} ms/row ({:.2} ns/pair, of which \
         FFT tables {:.3} ms), speed-up {:.1}×",
        cfg.n_fft(),
        cfg.bins(),
        lk.grid_len(),
        lk.oversampling(),
        band * 1e3,
        band / pairs * 1e9,
        look * 1e3,
        look / pairs * 1e9,
        ffts * 1e3,
        band / look
    );
}
