//! Dirty caller buffers (issue 35 item 7, after RustFFT's tests): every kernel type that
//! takes caller-provided tables, scratch or state — [`Scan`] (tables, and the sensor legs of
//! [`Scan::with_spads`]), [`RowBuffer`] (histogram and photon rows), [`Probe`] (all six
//! target × gate pairs; the higher-order gate keeps its suffix sums in the state),
//! [`ColumnF32`] (state; `finish_lookup`'s scratch and `out`), [`Lookup`] (tables and the
//! grid buffer of [`Lookup::baseband`]), [`LookupProbe`] and [`LookupSlice`] (tables, state
//! and scratch, Lagrange and Hermite cells), and the fixed-point path's [`FixedScan`],
//! [`FixedRowBuffer`], [`FixedPhotons`], [`FixedDiagonal`], [`FixedColumn`], [`FixedLookup`]
//! and [`FixedLookupProbe`] — gives **bit for bit** the result it gives with zeroed buffers
//! when those buffers start full of garbage (NaN, ±∞, ±3e38 and 1e30 in the float buffers,
//! `i64::MAX`/`MIN`-like patterns in the integer ones, the extremes of Q1.15), output
//! buffers included. Each case runs a small scene end to end twice, clean and dirty, and
//! compares every output's bits; the clean outputs are checked to be finite and not all 0,
//! so that an equality of two empty results cannot pass for one.
//!
//! Not covered, on purpose: [`Probe::resume`] takes its state as it is (a saved probe); the
//! test uses it as its teeth: the same dirty state through `resume` must change the result.

use vltm_kernel::num_complex::Complex32;
use vltm_kernel::{
    ColumnF32, Config, FixedColumn, FixedConfig, FixedDiagonal, FixedLimits, FixedLookup,
    FixedLookupGrid, FixedLookupProbe, FixedPhotons, FixedRowBuffer, FixedScan, Gate, I1F15,
    Lattice, Legs, Lookup, LookupGrid, LookupParams, LookupProbe, LookupSlice, Params, Point,
    Probe, Report, RowBuffer, Scan, SliceLayout, Target,
};

/// Named outputs of one run, each as the bits of its values.
type Outputs = Vec<(String, Vec<u64>)>;

const NT: usize = 128;
const DT: f64 = 0.01;

/// SPADs on a line at the lattice's x pitch (the structured slice needs it).
const SPADS: [Point; 3] = [[-0.1, 0.0, 0.0], [0.0, 0.0, 0.0], [0.1, 0.0, 0.0]];
const LASERS: [Point; 4] = [
    [-0.05, -0.05, 0.0],
    [0.05, -0.05, 0.0],
    [-0.05, 0.05, 0.0],
    [0.07, 0.04, 0.0],
];
const FOCUS: Point = [0.05, 0.0, 0.4];
/// A point scatterer (lattice voxel (2, 1)).
const TARGET: Point = [0.0, 0.0, 0.5];

fn lattice() -> Lattice {
    Lattice {
        origin: [-0.2, -0.1, 0.5],
        step_x: [0.1, 0.0, 0.0],
        step_y: [0.0, 0.1, 0.0],
        nx: 5,
        ny: 3,
    }
}

fn voxels() -> Vec<Point> {
    let lat = lattice();
    (0..lat.len()).map(|i| lat.point(i)).collect()
}

/// The time axis includes the legs from the laser and to the sensor device (so that the
/// rows' leg offsets and the scans' sensor legs are not trivial).
const LASER_ORIGIN: [f64; 3] = [0.02, -0.03, -0.1];
const SENSOR_ORIGIN: [f64; 3] = [-0.04, 0.01, -0.12];
const T0: f64 = 0.2;

fn config() -> Config {
    let mut p = Params::new(0.2, NT, DT);
    p.t0 = T0;
    p.legs = Legs::FirstAndLast {
        laser_origin: LASER_ORIGIN,
        sensor_origin: SENSOR_ORIGIN,
    };
    Config::try_new(&p).unwrap()
}

fn dist(a: &Point, b: &Point) -> f64 {
    (0..3)
        .map(|k| (f64::from(a[k]) - f64::from(b[k])).powi(2))
        .sum::<f64>()
        .sqrt()
}

fn origin(o: [f64; 3]) -> Point {
    o.map(|c| c as f32)
}

/// Laser `l`'s histograms (SPAD-major): a return from the target on a low background.
fn histograms(l: usize) -> Vec<u16> {
    let mut h = vec![0u16; SPADS.len() * NT];
    let x_l = &LASERS[l];
    for (s, sp) in SPADS.iter().enumerate() {
        for n in 0..NT {
            h[s * NT + n] = ((n * 7 + s * 3 + l) % 3) as u16;
        }
        let t = dist(&origin(LASER_ORIGIN), x_l)
            + dist(x_l, &TARGET)
            + dist(&TARGET, sp)
            + dist(sp, &origin(SENSOR_ORIGIN));
        let bin = ((t - T0) / DT).round() as usize;
        assert!(bin < NT, "return outside the time axis");
        h[s * NT + bin] += 40;
    }
    h
}

// ---------------------------------------------------------------------------------------
// Buffers: zeroed, or full of garbage.

fn f32s(n: usize, dirty: bool) -> Vec<f32> {
    const G: [f32; 5] = [f32::NAN, f32::INFINITY, -3.0e38, 1.0e30, f32::NEG_INFINITY];
    (0..n)
        .map(|i| if dirty { G[i % G.len()] } else { 0.0 })
        .collect()
}

fn f64s(n: usize, dirty: bool) -> Vec<f64> {
    const G: [f64; 5] = [f64::NAN, f64::INFINITY, -1.0e300, 3.0e38, f64::NEG_INFINITY];
    (0..n)
        .map(|i| if dirty { G[i % G.len()] } else { 0.0 })
        .collect()
}

fn i64s(n: usize, dirty: bool) -> Vec<i64> {
    const G: [i64; 4] = [i64::MAX, i64::MIN, 0x5555_5555_5555_5555, -1];
    (0..n)
        .map(|i| if dirty { G[i % G.len()] } else { 0 })
        .collect()
}

fn i32s(n: usize, dirty: bool) -> Vec<i32> {
    const G: [i32; 4] = [i32::MAX, i32::MIN, 0x7f80_0001, -1]; // 0x7f80_0001: an f32 NaN's bits
    (0..n)
        .map(|i| if dirty { G[i % G.len()] } else { 0 })
        .collect()
}

fn q15s(n: usize, dirty: bool) -> Vec<I1F15> {
    const G: [I1F15; 3] = [I1F15::MAX, I1F15::MIN, I1F15::from_bits(0x5a5a)];
    (0..n)
        .map(|i| if dirty { G[i % G.len()] } else { I1F15::ZERO })
        .collect()
}

fn bits32(x: &[f32]) -> Vec<u64> {
    x.iter().map(|v| u64::from(v.to_bits())).collect()
}

fn bits64(x: &[f64]) -> Vec<u64> {
    x.iter().map(|v| v.to_bits()).collect()
}

fn complex_bits(x: &[Complex32]) -> Vec<u64> {
    x.iter()
        .map(|z| u64::from(z.re.to_bits()) << 32 | u64::from(z.im.to_bits()))
        .collect()
}

fn report_bits(r: Report) -> Vec<u64> {
    vec![r.rows, r.non_finite, r.dropped, r.aliased as u64]
}

fn push(out: &mut Outputs, name: &str, bits: Vec<u64>) {
    out.push((name.to_string(), bits));
}

// ---------------------------------------------------------------------------------------
// The float path.

fn float_outputs(dirty: bool) -> Outputs {
    let cfg = config();
    let vox = voxels();
    let kv = vox.len();
    let ks = SPADS.len();
    let mut out = Outputs::new();

    let mut tables = f32s(Scan::tables_len(&cfg, ks), dirty);
    let scan = Scan::new(&cfg, &SPADS, &mut tables).unwrap();
    // The same scan re-pointed at the same spots: its sensor legs in a caller buffer.
    let mut d4 = f32s(ks, dirty);
    let moved = scan.with_spads(&SPADS, &mut d4).unwrap();
    push(
        &mut out,
        "Scan::with_spads legs",
        bits32(moved.sensor_legs()),
    );

    let mut buf = f32s(RowBuffer::len(&cfg, ks), dirty);
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();

    // Band probes: every target × gate.
    let pairs = [
        (Target::Diagonal, Gate::Gaussian),
        (Target::Diagonal, Gate::None),
        (Target::Diagonal, Gate::HigherOrder),
        (Target::Column(FOCUS), Gate::Gaussian),
        (Target::Column(FOCUS), Gate::None),
        (Target::Column(FOCUS), Gate::HigherOrder),
    ];
    let mut states: Vec<Vec<f64>> = pairs
        .iter()
        .map(|&(t, g)| f64s(Probe::state_len(&cfg, t, g, kv, ks), dirty))
        .collect();
    let mut probes: Vec<Probe<'_>> = pairs
        .iter()
        .zip(states.iter_mut())
        .map(|(&(t, g), st)| Probe::new(&scan, t, g, &vox, st).unwrap())
        .collect();

    let mut col_state = f32s(ColumnF32::state_len(&cfg, ks), dirty);
    let mut col = ColumnF32::new(&scan, FOCUS, &mut col_state).unwrap();

    // The lookup path: a Lagrange grid (voxel list and slice) and a Hermite grid (slice).
    let grid = LookupGrid::try_new(&cfg, &LookupParams::new()).unwrap();
    let hgrid = LookupGrid::try_new(&cfg, &LookupParams::hermite()).unwrap();
    let mut lt = f32s(Lookup::tables_len(&grid), dirty);
    let lookup = Lookup::new(&grid, &mut lt).unwrap();
    let mut hlt = f32s(Lookup::tables_len(&hgrid), dirty);
    let hlookup = Lookup::new(&hgrid, &mut hlt).unwrap();

    let targets = [Target::Diagonal, Target::Column(FOCUS)];
    let mut lp_bufs: Vec<(Vec<f32>, Vec<f32>)> = targets
        .iter()
        .map(|_| {
            (
                f32s(LookupProbe::state_len(kv), dirty),
                f32s(LookupProbe::scratch_len(&grid, kv), dirty),
            )
        })
        .collect();
    let mut lprobes: Vec<LookupProbe<'_>> = targets
        .iter()
        .zip(lp_bufs.iter_mut())
        .map(|(&t, (st, sc))| LookupProbe::new(&scan, &lookup, t, &vox, st, sc).unwrap())
        .collect();

    let lat = lattice();
    let layouts = [
        SliceLayout::try_new(&scan, &grid, &lat, usize::MAX).unwrap(),
        SliceLayout::try_new(&scan, &hgrid, &lat, usize::MAX).unwrap(),
    ];
    // (layout index, target): Lagrange and Hermite cells, diagonal and column.
    let slices_of = [
        (0, Target::Diagonal),
        (0, Target::Column(FOCUS)),
        (1, Target::Diagonal),
        (1, Target::Column(FOCUS)),
    ];
    let mut sl_bufs: Vec<(Vec<f32>, Vec<f32>, Vec<f32>)> = slices_of
        .iter()
        .map(|&(k, _)| {
            let g = if k == 0 { &grid } else { &hgrid };
            (
                f32s(layouts[k].tables_len(), dirty),
                f32s(LookupSlice::state_len(kv), dirty),
                f32s(LookupSlice::scratch_len(g, kv), dirty),
            )
        })
        .collect();
    let mut slices: Vec<LookupSlice<'_>> = slices_of
        .iter()
        .zip(sl_bufs.iter_mut())
        .map(|(&(k, t), (tb, st, sc))| {
            let lk = if k == 0 { &lookup } else { &hlookup };
            LookupSlice::new(&scan, lk, &layouts[k], t, tb, st, sc).unwrap()
        })
        .collect();

    for (l, x_l) in LASERS.iter().enumerate() {
        let h = histograms(l);
        let row = rows.load(&scan, *x_l, &h).unwrap();
        push(&mut out, &format!("row {l} band"), complex_bits(row.band()));
        push(
            &mut out,
            &format!("row {l} ungated"),
            complex_bits(row.ungated()),
        );
        push(&mut out, &format!("row {l} offsets"), bits32(row.offsets()));
        for p in probes.iter_mut() {
            p.push_row(&scan, &row).unwrap();
        }
        col.push_row(&scan, &row).unwrap();
        for p in lprobes.iter_mut() {
            p.push_row(&scan, &lookup, &row).unwrap();
        }
        for ((k, _), s) in slices_of.iter().zip(slices.iter_mut()) {
            let lk = if *k == 0 { &lookup } else { &hlookup };
            s.push_row(&scan, lk, &row).unwrap();
        }
    }
    // A photon-event row in its own dirty buffer (the same counts as laser 0's histograms).
    {
        let mut pbuf = f32s(RowBuffer::len(&cfg, ks), dirty);
        let mut prow = RowBuffer::new(&scan, &mut pbuf).unwrap();
        prow.begin_photons();
        for (s, hs) in histograms(0).chunks_exact(NT).enumerate() {
            for (n, &c) in hs.iter().enumerate() {
                for _ in 0..c {
                    prow.push_photon(&scan, s, n);
                }
            }
        }
        let row = prow.end_photons(&scan, LASERS[0]).unwrap();
        push(&mut out, "photon row band", complex_bits(row.band()));
        push(&mut out, "photon row ungated", complex_bits(row.ungated()));
        push(&mut out, "photon row offsets", bits32(row.offsets()));
    }

    for ((t, g), p) in pairs.iter().zip(&probes) {
        let mut img = f64s(kv, dirty);
        let r = p.finish(&scan, &mut img).unwrap();
        push(&mut out, &format!("Probe {t:?} {g:?}"), bits64(&img));
        push(
            &mut out,
            &format!("Probe {t:?} {g:?} report"),
            report_bits(r),
        );
    }

    let mut img = f32s(kv, dirty);
    let r = col.finish(&scan, &vox, &mut img).unwrap();
    push(&mut out, "ColumnF32::finish", bits32(&img));
    push(&mut out, "ColumnF32::finish report", report_bits(r));
    let mut scratch = f32s(ColumnF32::lookup_scratch_len(&grid, kv), dirty);
    let mut img = f32s(kv, dirty);
    let r = col
        .finish_lookup(&scan, &lookup, &vox, &mut scratch, &mut img)
        .unwrap();
    push(&mut out, "ColumnF32::finish_lookup", bits32(&img));
    push(&mut out, "ColumnF32::finish_lookup report", report_bits(r));

    for (t, p) in targets.iter().zip(&lprobes) {
        let mut img = f64s(kv, dirty);
        p.finish(&mut img).unwrap();
        push(&mut out, &format!("LookupProbe {t:?}"), bits64(&img));
        let mut img = f32s(kv, dirty);
        p.finish_f32(&mut img).unwrap();
        push(&mut out, &format!("LookupProbe {t:?} f32"), bits32(&img));
    }
    for ((k, t), s) in slices_of.iter().zip(&slices) {
        let mut img = f64s(kv, dirty);
        s.finish(&mut img).unwrap();
        push(&mut out, &format!("LookupSlice {k} {t:?}"), bits64(&img));
    }

    // Lookup::baseband into a dirty grid buffer, read back through the reader.
    let spectrum = col.spectra().get(..cfg.bins()).unwrap().to_vec();
    let mut y: Vec<Complex32> = f32s(2 * Lookup::grid_buf_len(&grid), dirty)
        .chunks_exact(2)
        .map(|c| Complex32::new(c[0], c[1]))
        .collect();
    lookup.baseband(&spectrum, &mut y).unwrap();
    push(&mut out, "Lookup::baseband", complex_bits(&y));
    let reader = lookup.reader();
    let reads: Vec<Complex32> = (0..50).map(|i| reader.read(&y, 0.03 * i as f32)).collect();
    push(&mut out, "GridReader::read", complex_bits(&reads));
    out
}

// ---------------------------------------------------------------------------------------
// The fixed-point path.

fn fixed_outputs(dirty: bool) -> Outputs {
    let cfg = config();
    let fc = FixedConfig::try_new(&cfg, &FixedLimits::new(64, 8, 0.1)).unwrap();
    let vox = voxels();
    let kv = vox.len();
    let ks = SPADS.len();
    let mut out = Outputs::new();

    let mut tables = q15s(FixedScan::tables_len(&fc), dirty);
    let scan = FixedScan::new(&fc, &SPADS, &mut tables).unwrap();
    let mut buf = i32s(FixedRowBuffer::len(&fc, ks), dirty);
    let mut rows = FixedRowBuffer::new(&scan, &mut buf).unwrap();
    let mut pbuf = i32s(FixedRowBuffer::len(&fc, ks), dirty);
    let mut prows = FixedRowBuffer::new(&scan, &mut pbuf).unwrap();
    let mut photon_sums = i64s(FixedPhotons::len(&fc, ks), dirty);
    let mut photons = FixedPhotons::new(&scan, &mut photon_sums).unwrap();

    let mut ds = i64s(FixedDiagonal::state_len(kv), dirty);
    let mut diag = FixedDiagonal::new(&vox, &mut ds).unwrap();
    let mut cs = i64s(FixedColumn::state_len(&fc, ks), dirty);
    let mut col = FixedColumn::new(&scan, FOCUS, &mut cs).unwrap();
    // The photon rows go to a second diagonal.
    let mut pds = i64s(FixedDiagonal::state_len(kv), dirty);
    let mut pdiag = FixedDiagonal::new(&vox, &mut pds).unwrap();

    let g = FixedLookupGrid::try_new(&fc, &LookupParams::new()).unwrap();
    let mut lt = q15s(FixedLookup::tables_len(&g), dirty);
    let lookup = FixedLookup::new(&g, &mut lt).unwrap();
    let targets = [Target::Diagonal, Target::Column(FOCUS)];
    let mut lp_bufs: Vec<(Vec<i64>, Vec<i32>)> = targets
        .iter()
        .map(|_| {
            (
                i64s(FixedLookupProbe::state_len(kv), dirty),
                i32s(FixedLookupProbe::scratch_len(&g, kv), dirty),
            )
        })
        .collect();
    let mut lprobes: Vec<FixedLookupProbe<'_>> = targets
        .iter()
        .zip(lp_bufs.iter_mut())
        .map(|(&t, (st, sc))| FixedLookupProbe::new(&lookup, t, &vox, st, sc).unwrap())
        .collect();

    for (l, x_l) in LASERS.iter().enumerate() {
        let h = histograms(l);
        let row = rows.load(&scan, *x_l, &h).unwrap();
        diag.push_row(&scan, &row).unwrap();
        col.push_row(&scan, &row).unwrap();
        for p in lprobes.iter_mut() {
            p.push_row(&scan, &lookup, &row).unwrap();
        }
        // `new` made an empty row of the dirty sums; later rows start from `reset`.
        if l > 0 {
            photons.reset();
        }
        for (s, hs) in h.chunks_exact(NT).enumerate() {
            for (n, &c) in hs.iter().enumerate() {
                for _ in 0..c {
                    photons.push(&scan, s, n);
                }
            }
        }
        let prow = prows.load_photons(&scan, *x_l, &photons).unwrap();
        pdiag.push_row(&scan, &prow).unwrap();
    }

    let mut img = f64s(kv, dirty);
    diag.finish(&fc, &mut img).unwrap();
    push(&mut out, "FixedDiagonal", bits64(&img));
    push(&mut out, "FixedDiagonal raw", raw_bits(diag.raw()));
    let mut img = f64s(kv, dirty);
    pdiag.finish(&fc, &mut img).unwrap();
    push(&mut out, "FixedDiagonal (photon rows)", bits64(&img));
    let mut img = f64s(kv, dirty);
    let aliased = col.finish(&scan, &vox, &mut img).unwrap();
    push(&mut out, "FixedColumn", bits64(&img));
    // (Checked with the image, not on its own: 0 is its value here.)
    push(&mut out, "FixedColumn aliased + raw", {
        let mut v = vec![aliased as u64];
        v.extend(raw_bits(col.raw()));
        v
    });
    for (t, p) in targets.iter().zip(&lprobes) {
        let mut img = f64s(kv, dirty);
        p.finish(&mut img).unwrap();
        push(&mut out, &format!("FixedLookupProbe {t:?}"), bits64(&img));
        push(
            &mut out,
            &format!("FixedLookupProbe {t:?} raw"),
            raw_bits(p.raw()),
        );
    }
    out
}

fn raw_bits(x: &[i64]) -> Vec<u64> {
    x.iter().map(|&v| v as u64).collect()
}

// ---------------------------------------------------------------------------------------

/// The clean run's outputs are worth comparing: every value finite (as bits of the type
/// they came from: `f32`s are the low 32 bits) and some not 0.
fn assert_meaningful(outputs: &Outputs) {
    for (name, bits) in outputs {
        assert!(!bits.is_empty(), "{name}: empty");
        assert!(bits.iter().any(|&b| b != 0), "{name}: all zero");
    }
}

fn assert_same(clean: &Outputs, dirty: &Outputs) {
    assert_eq!(clean.len(), dirty.len());
    let mut differ = Vec::new();
    for ((name, a), (name_b, b)) in clean.iter().zip(dirty) {
        assert_eq!(name, name_b);
        if a != b {
            let first = a.iter().zip(b).position(|(x, y)| x != y);
            differ.push(format!("{name} (first difference at {first:?})"));
        }
    }
    assert!(
        differ.is_empty(),
        "results differ with dirty caller buffers:\n{}",
        differ.join("\n")
    );
}

#[test]
fn float_path_ignores_dirty_buffers() {
    let clean = float_outputs(false);
    assert_meaningful(&clean);
    // Finite: the f64 images and the f32 ones (by their bits' exponent).
    for (name, bits) in &clean {
        if name.starts_with("Probe") && !name.ends_with("report") {
            assert!(
                bits.iter().all(|&b| f64::from_bits(b).is_finite()),
                "{name}: not finite"
            );
        }
        if name.starts_with("ColumnF32::finish") && !name.ends_with("report") {
            assert!(
                bits.iter().all(|&b| f32::from_bits(b as u32).is_finite()),
                "{name}: not finite"
            );
        }
    }
    assert_same(&clean, &float_outputs(true));
}

#[test]
fn fixed_path_ignores_dirty_buffers() {
    let clean = fixed_outputs(false);
    assert_meaningful(&clean);
    for (name, bits) in &clean {
        if !name.ends_with("raw") {
            assert!(
                bits.iter().all(|&b| f64::from_bits(b).is_finite()),
                "{name}: not finite"
            );
        }
    }
    assert_same(&clean, &fixed_outputs(true));
}

/// Teeth: the comparison sees state that a probe does read. [`Probe::resume`] takes its
/// state as it is (the accumulators of a saved probe), so the same garbage given to
/// `resume` instead of `new` must change the image.
#[test]
fn dirty_state_that_is_read_is_caught() {
    let cfg = config();
    let vox = voxels();
    let (kv, ks) = (vox.len(), SPADS.len());
    let mut tables = f32s(Scan::tables_len(&cfg, ks), false);
    let scan = Scan::new(&cfg, &SPADS, &mut tables).unwrap();
    let mut buf = f32s(RowBuffer::len(&cfg, ks), false);
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    let image = |resume: bool, rows: &mut RowBuffer<'_>| {
        let n = Probe::state_len(&cfg, Target::Diagonal, Gate::Gaussian, kv, ks);
        let mut st = f64s(n, true);
        let mut p = if resume {
            Probe::resume(
                &scan,
                Target::Diagonal,
                Gate::Gaussian,
                &vox,
                &mut st,
                Report::default(),
                (f64::INFINITY, f64::NEG_INFINITY),
            )
            .unwrap()
        } else {
            Probe::new(&scan, Target::Diagonal, Gate::Gaussian, &vox, &mut st).unwrap()
        };
        let h = histograms(0);
        let row = rows.load(&scan, LASERS[0], &h).unwrap();
        p.push_row(&scan, &row).unwrap();
        let mut img = vec![0.0f64; kv];
        p.finish(&scan, &mut img).unwrap();
        vec![("diagonal".to_string(), bits64(&img))]
    };
    let fresh = image(false, &mut rows);
    let resumed = image(true, &mut rows);
    assert_meaningful(&fresh);
    assert_ne!(
        fresh, resumed,
        "resume read the garbage state, yet nothing changed"
    );
    let caught = std::panic::catch_unwind(|| assert_same(&fresh, &resumed));
    assert!(caught.is_err(), "assert_same accepted different results");
}
