//! The kernel's photon-event path (`begin_photons` / `push_photon` / `end_photons`) equals the
//! histogram path on the same counts, for every probe that can use it; out-of-range events are
//! dropped and counted; the higher-order gate refuses photon rows.

use proptest::prelude::*;
use vltm_kernel::{
    ArgumentError, Config, Gate, Params, Point, Probe, RowBuffer, Scan, Target, Weights,
};

/// A small scan: apertures, voxels and u16 counts `[Kl][Ks][Nt]`.
#[derive(Clone, Debug)]
struct Case {
    lasers: Vec<Point>,
    spads: Vec<Point>,
    voxels: Vec<Point>,
    nt: usize,
    lambda: f64,
    t0: f64,
    counts: Vec<u16>,
    shuffle: u64,
}

fn wall() -> impl Strategy<Value = Point> {
    (-1.0f32..1.0, -1.0f32..1.0).prop_map(|(x, y)| [x, y, 0.0])
}

fn case() -> impl Strategy<Value = Case> {
    (
        1usize..5,
        1usize..6,
        1usize..5,
        16usize..200,
        0.05f64..0.3,
        -0.5f64..1.0,
        any::<u64>(),
    )
        .prop_flat_map(|(kl, ks, kv, nt, lambda, t0, shuffle)| {
            (
                prop::collection::vec(wall(), kl),
                prop::collection::vec(wall(), ks),
                prop::collection::vec(
                    (-0.8f32..0.8, -0.8f32..0.8, 0.3f32..1.5).prop_map(|(x, y, z)| [x, y, z]),
                    kv,
                ),
                prop::collection::vec(
                    prop_oneof![6 => Just(0u16), 3 => 1u16..4, 1 => 4u16..20],
                    kl * ks * nt,
                ),
            )
                .prop_map(move |(lasers, spads, voxels, counts)| Case {
                    lasers,
                    spads,
                    voxels,
                    nt,
                    lambda,
                    t0,
                    counts,
                    shuffle,
                })
        })
}

/// Runs one probe over all rows, feeding histograms or photon events.
fn run(c: &Case, cfg: &Config, target: Target, gate: Gate, photons: bool) -> (Vec<f64>, u64) {
    let ks = c.spads.len();
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, ks)];
    let scan = Scan::new(cfg, &c.spads, &mut tables).unwrap();
    let mut buf = vec![0.0f32; RowBuffer::len(cfg, ks)];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    let mut state = vec![0.0f64; Probe::state_len(cfg, target, gate, c.voxels.len(), ks)];
    let mut probe = Probe::new(&scan, target, gate, &c.voxels, &mut state).unwrap();
    for (l, laser) in c.lasers.iter().enumerate() {
        let h = &c.counts[l * ks * c.nt..(l + 1) * ks * c.nt];
        if photons {
            // Every count becomes that many events, in a scrambled order, plus junk events.
            let mut events: Vec<(usize, usize)> = Vec::new();
            for (i, &n) in h.iter().enumerate() {
                events.extend(std::iter::repeat_n((i / c.nt, i % c.nt), n as usize));
            }
            let mut x = c.shuffle | 1;
            for i in (1..events.len()).rev() {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                events.swap(i, (x % (i as u64 + 1)) as usize);
            }
            rows.begin_photons();
            for (s, n) in events {
                rows.push_photon(&scan, s, n);
            }
            rows.push_photon(&scan, ks, 0); // no such SPAD
            rows.push_photon(&scan, 0, c.nt); // past the time axis
            let row = rows.end_photons(&scan, *laser).unwrap();
            assert_eq!(row.dropped(), 2);
            probe.push_row(&scan, &row).unwrap();
        } else {
            let row = rows.load(&scan, *laser, h).unwrap();
            probe.push_row(&scan, &row).unwrap();
        }
    }
    let mut out = vec![0.0; c.voxels.len()];
    let rep = probe.finish(&scan, &mut out).unwrap();
    (out, rep.dropped)
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 96,
        rng_algorithm: proptest::test_runner::RngAlgorithm::ChaCha,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x5eed_f070),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// Photon events and histograms give the same intensities. Both paths sum the same
    /// twiddles (the photon path adds `e^{−2πik n/N}` once per event, the histogram path
    /// multiplies it by the count), so they differ only by `f32` rounding in a different
    /// order. With unit weights `|A| ≤ S = Σ counts` (the gate is ≤ 1), and each of the
    /// `J ≲ 300` band terms carries a relative rounding ≲ 1e-7·√events, so amplitudes are
    /// compared with `|√T_h − √T_p| ≤ 1e-5·S` (a bin shifted by one would fail by ≫ 1e-3·S).
    #[test]
    fn photon_events_equal_histograms(c in case()) {
        let p = Params { t0: c.t0, weights: Weights::One, ..Params::new(c.lambda, c.nt, 0.01) };
        let Ok(cfg) = Config::try_new(&p) else { return Ok(()) };
        let focus = c.voxels[0];
        for (target, gate) in [
            (Target::Diagonal, Gate::Gaussian),
            (Target::Diagonal, Gate::None),
            (Target::Column(focus), Gate::Gaussian),
            (Target::Column(focus), Gate::None),
        ] {
            let (h, _) = run(&c, &cfg, target, gate, false);
            let (ph, dropped) = run(&c, &cfg, target, gate, true);
            prop_assert_eq!(dropped, 2 * c.lasers.len() as u64);
            let scale: f64 = c.counts.iter().map(|&n| f64::from(n)).sum();
            for (a, b) in h.iter().zip(&ph) {
                let err = (a.sqrt() - b.sqrt()).abs();
                prop_assert!(err <= 1e-5 * scale, "{target:?} {gate:?}: {a} vs {b} (Σ counts {scale})");
            }
        }
    }
}

#[test]
fn higher_order_gate_refuses_photon_rows() {
    let cfg = Config::try_new(&Params::new(0.2, 64, 0.01)).unwrap();
    let spads = [[0.0f32, 0.0, 0.0]];
    let voxels = [[0.0f32, 0.0, 0.3]];
    let mut tables = vec![0.0f32; Scan::tables_len(&cfg, 1)];
    let scan = Scan::new(&cfg, &spads, &mut tables).unwrap();
    let mut buf = vec![0.0f32; RowBuffer::len(&cfg, 1)];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    let target = Target::Column([0.1, 0.0, 0.4]);
    let mut state = vec![0.0f64; Probe::state_len(&cfg, target, Gate::HigherOrder, 1, 1)];
    let mut probe = Probe::new(&scan, target, Gate::HigherOrder, &voxels, &mut state).unwrap();
    rows.begin_photons();
    rows.push_photon(&scan, 0, 60);
    let row = rows.end_photons(&scan, [0.0, 0.0, 0.0]).unwrap();
    assert_eq!(
        probe.push_row(&scan, &row),
        Err(ArgumentError::Length {
            what: "row histograms",
            expected: 64,
            found: 0
        })
    );
    assert_eq!(probe.report().rows, 0);
    assert!(matches!(
        rows.end_photons(&scan, [f32::NAN, 0.0, 0.0]),
        Err(ArgumentError::NonFinite { .. })
    ));
}
