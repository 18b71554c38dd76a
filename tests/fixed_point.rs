//! The fixed-point path (`vltm_kernel::Fixed*`, kernel/src/fixed.rs) against the `f64`
//! time-domain reference (`reference/mod.rs`) and against the float kernel, on random small
//! scans of `u16` counts: the Gaussian diagonal and the factorised Gaussian column.
//!
//! # Tolerance (amplitudes; `|√T_k − |A_r|| ≤ |A_k − A_r|` is compared)
//!
//! With `S = Σ_l Σ_s w_l w_s Σ_n |H_ls[n]|` (the element's scale, `Reference::scale`) and
//! `W = Σ_l Σ_s w_l w_s`, the fixed path computes, per (l, s),
//! `Z = Σ_j ĝ_j·p_j·c_j·D_j` where `D_j = Σ_n h_n·W_{k_j n}` (Q15 twiddles), `ĝ_j` the Q15 gate
//! weight (× Ĝ_max), `p_j` the leg phase and `c_j` the path phase (NCO, Q15). First-order
//! error terms, each a worst case with all errors aligned:
//!
//! 1. twiddles, ≤ 2⁻¹⁵ per component: `|ΔD_j| ≤ √2·2⁻¹⁵·Σ|h|`, through `Σ_j Ĝ_j = G`:
//!    `√2·2⁻¹⁵·G·Σ|h|`;
//! 2. gate weights, `|Δĝ_j| ≤ 2⁻¹⁵` (× Ĝ_max): `J·Ĝ_max·2⁻¹⁵·Σ|h|`;
//! 3. NCO cos/sin, ≤ `CIS_ERR` = 1.2·2⁻¹⁵ per component, two factors (p and c; three for
//!    the column, whose projector leg has its own phase): `3·√2·CIS_ERR·G·Σ|h|`;
//! 4. phase steps rounded to 2⁻³² turns, `|k| ≤ k_max` steps from the exact `k·step`:
//!    `3·2π·k_max·2⁻³³·G·Σ|h|` rad;
//! 5. `HG` rounded to ½ LSB per component (`hg_lsb` counts), `J` of them, and the band sum
//!    rounded once more: `(J + 1)·(√2/2)·hg_lsb` — an absolute term per (l, s), × `w_l w_s`;
//! 6. the weighted term rounded into the accumulator: diagonal `(√2/2)·diag_lsb` per (l, s);
//!    column `(√2/2)·column_lsb` per (l, s, j), × `w_s` at the finish.
//!
//! Summed over (l, s) with the weights: `ε_q·S + W·(J + 1)·(√2/2)·hg_lsb + (last term)`,
//! `ε_q = √2·2⁻¹⁵·G + J·Ĝ_max·2⁻¹⁵ + 3√2·CIS_ERR·G + 3π·k_max·2⁻³²·G`. The distances, the
//! `1/d` weights and the phase-step seeds are `f32`/`f64` as in the float path, whose own
//! terms are added unchanged (tests/proptest_kernel.rs): `ε_f32 = u·(2πΦ + J + Nt + 64)`,
//! band truncation `erfc(m/√2)`, guard and periodisation `2e^{−c_g²/2}`.
//! So `tol = (ε_q + ε_f32 + erfc(m/√2) + 2e^{−c_g²/2})·S + atol`. With G ≈ 1 and J·Ĝ_max ≈ 3,
//! ε_q ≈ 1.9e-4: the fixed path is ~2⁻¹² of the element's scale, against ~1e-6 for `f32`.
//!
//! The statistical test (STYLE §8.24) compares fixed with float on the same band algorithm,
//! which isolates the quantisation: independent roundings uniform in ±e add in quadrature,
//! so the RMS of `M` of them is `e·√(M/3)` against the worst case `M·e`: the RMS of
//! `|A_fixed − A_float| / bound` must be ≤ 1/√3, and is in fact far smaller.

mod reference;
mod support;

use num_complex::Complex64;
use proptest::prelude::*;
use reference::{Reference, p64};
// `hidden()`: z ≥ 0.3, every leg longer than MIN_DISTANCE, so the weights equal the float path's.
use support::prop::{Rng, hidden, wall};
use support::{Data, all_rows, run};
use vltm_kernel::{
    CIS_ERR, Config, FixedColumn, FixedConfig, FixedDiagonal, FixedLimits, FixedLookup,
    FixedLookupGrid, FixedLookupProbe, FixedPhotons, FixedRowBuffer, FixedScan, Gate, I1F15,
    LAGRANGE_Q15_ERR, LookupParams, Params, Point, Target, Weights,
};

const SEED: u64 = 0xf1ed_0015_c0de_0005;
const U32: f64 = f32::EPSILON as f64 / 2.0;
const MIN_DISTANCE: f64 = 0.25;

#[derive(Clone, Debug)]
struct Case {
    lasers: Vec<Point>,
    spads: Vec<Point>,
    voxels: Vec<Point>,
    focus: Point,
    nt: usize,
    dt: f64,
    lambda_over_dt: f64,
    m: f64,
    cg: f64,
    inv: bool,
    /// 0: noise + returns; 1: every bin 65535 (the budget's edge).
    saturated: bool,
    seed: u64,
    pos: f64,
}

prop_compose! {
    fn case()(
        lasers in prop::collection::vec(wall(), 1..=5),
        spads in prop::collection::vec(wall(), 1..=5),
        voxels in prop::collection::vec(hidden(), 1..=4),
        focus in hidden(),
        nt in 16usize..=300,
        dt in 0.005f64..=0.04,
        lambda_over_dt in 8.0f64..=20.0,
        m in 4.0f64..=6.5,
        cg in 4.5f64..=6.5,
        inv in any::<bool>(),
        saturated in prop::bool::weighted(0.1),
        seed in any::<u64>(),
        pos in 0.0f64..=1.0,
    ) -> Case {
        Case { lasers, spads, voxels, focus, nt, dt, lambda_over_dt, m, cg, inv, saturated, seed, pos }
    }
}

impl Case {
    fn params(&self, t0: f64) -> Params {
        Params {
            band_half_width: self.m,
            gate_support: self.cg,
            t0,
            weights: if self.inv { Weights::Inv } else { Weights::One },
            ..Params::new(self.lambda_over_dt * self.dt, self.nt, self.dt)
        }
    }

    /// Parameters (window over the diagonal paths) and histograms `[(l·Ks + s)·Nt + n]`.
    fn prepare(&self) -> (Params, Vec<u16>) {
        let (kl, ks, nt) = (self.lasers.len(), self.spads.len(), self.nt);
        let geo = Reference::new(
            &self.params(0.0),
            &self.lasers,
            &self.spads,
            vec![0.0; kl * ks * nt],
        );
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for v in &self.voxels {
            let (a, b) = geo.tau_range(&p64(*v), &p64(*v));
            (lo, hi) = (lo.min(a), hi.max(b));
        }
        let window = (nt - 1) as f64 * self.dt;
        let t0 = lo + 0.5 * (hi - lo) - self.pos * window;
        if self.saturated {
            return (self.params(t0), vec![u16::MAX; kl * ks * nt]);
        }
        let mut rng = Rng(self.seed);
        let mut h: Vec<f64> = (0..kl * ks * nt).map(|_| (3.0 * rng.f()).floor()).collect();
        let geo = Reference { t0, ..geo };
        let (v, b, a) = (
            p64(self.voxels[0]),
            p64(*self.voxels.last().unwrap()),
            p64(self.focus),
        );
        for l in 0..kl {
            for s in 0..ks {
                for (tau, amp) in [
                    (geo.tau(l, s, &v, &v), 2000.0),
                    (geo.tau(l, s, &a, &b), 600.0),
                ] {
                    let bin = ((tau - t0) / self.dt).round();
                    if bin >= 0.0 && bin < nt as f64 {
                        h[(l * ks + s) * nt + bin as usize] += amp;
                    }
                }
            }
        }
        (self.params(t0), h.iter().map(|&x| x as u16).collect())
    }
}

/// `p` with the margin widened until every column path time is alias-free.
fn alias_free(p: Params, r: &Reference, focus: Point, voxels: &[Point]) -> Params {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in voxels {
        let (a, b) = r.tau_range(&p64(focus), &p64(*v));
        (lo, hi) = (lo.min(a), hi.max(b));
    }
    support::prop::widen_margin(p, (lo, hi))
}

/// Fixed-point amplitudes `|A|` (diagonal if `focus` is None, else the column).
fn run_fixed(
    fc: &FixedConfig,
    lasers: &[Point],
    spads: &[Point],
    hists: &[u16],
    voxels: &[Point],
    focus: Option<Point>,
) -> (Vec<f64>, Vec<Complex64>) {
    let nt = fc.config().nt();
    let mut tables = vec![I1F15::ZERO; FixedScan::tables_len(fc)];
    let scan = FixedScan::new(fc, spads, &mut tables).unwrap();
    let mut buf = vec![0i32; FixedRowBuffer::len(fc, spads.len())];
    let mut rows = FixedRowBuffer::new(&scan, &mut buf).unwrap();
    let mut out = vec![0.0; voxels.len()];
    let len = spads.len() * nt;
    match focus {
        None => {
            let mut st = vec![0i64; FixedDiagonal::state_len(voxels.len())];
            let mut d = FixedDiagonal::new(voxels, &mut st).unwrap();
            for (l, x_l) in lasers.iter().enumerate() {
                let row = rows
                    .load(&scan, *x_l, &hists[l * len..(l + 1) * len])
                    .unwrap();
                d.push_row(&scan, &row).unwrap();
            }
            // The budget is exhausted: one more row is refused.
            let row = rows.load(&scan, lasers[0], &hists[..len]).unwrap();
            assert!(d.push_row(&scan, &row).is_err());
            d.finish(fc, &mut out).unwrap();
            let lsb = fc.diag_lsb();
            let z = d
                .raw()
                .chunks_exact(2)
                .map(|a| Complex64::new(a[0] as f64 * lsb, a[1] as f64 * lsb))
                .collect();
            return (out.iter().map(|t| t.sqrt()).collect(), z);
        }
        Some(a) => {
            let mut st = vec![0i64; FixedColumn::state_len(fc, spads.len())];
            let mut c = FixedColumn::new(&scan, a, &mut st).unwrap();
            for (l, x_l) in lasers.iter().enumerate() {
                let row = rows
                    .load(&scan, *x_l, &hists[l * len..(l + 1) * len])
                    .unwrap();
                c.push_row(&scan, &row).unwrap();
            }
            let aliased = c.finish(&scan, voxels, &mut out).unwrap();
            assert_eq!(aliased, 0);
        }
    }
    (out.iter().map(|t| t.sqrt()).collect(), Vec::new())
}

/// One element's comparison.
#[derive(Debug, Clone, Copy)]
struct Cmp {
    /// `|A_fixed − A_ref|`, `|A_fixed − A_float|`.
    err_ref: f64,
    err_float: f64,
    /// Full tolerance vs the reference; quantisation-only bound vs the float path.
    tol: f64,
    tol_q: f64,
    scale: f64,
    /// Diagonal only: `arg(A_fixed / A_ref)` (rad) and `|A_ref| / S`.
    phase: Option<(f64, f64)>,
}

fn compare(case: &Case) -> Vec<Cmp> {
    compare_shifted(case, 0.0)
}

/// As [`compare`], with the kernels' (fixed and float) `t0` moved by `dt0` — a mistake the
/// tolerance must detect — while the reference keeps the true `t0`.
fn compare_shifted(case: &Case, dt0: f64) -> Vec<Cmp> {
    let (p, hists) = case.prepare();
    let h64: Vec<f64> = hists.iter().map(|&x| f64::from(x)).collect();
    let truth = Reference::new(&p, &case.lasers, &case.spads, h64);
    let mut out = Vec::new();
    for column in [false, true] {
        let p = if column {
            alias_free(p, &truth, case.focus, &case.voxels)
        } else {
            p
        };
        let truth_p = p;
        let p = Params {
            t0: p.t0 + dt0,
            ..p
        };
        let cfg = Config::try_new(&p).unwrap();
        let limits = FixedLimits::new(
            case.lasers.len() as u32,
            case.spads.len() as u32,
            MIN_DISTANCE,
        );
        let fc = FixedConfig::try_new(&cfg, &limits).unwrap();
        let (target, focus) = if column {
            (Target::Column(case.focus), Some(case.focus))
        } else {
            (Target::Diagonal, None)
        };
        let (fixed, z_fixed) =
            run_fixed(&fc, &case.lasers, &case.spads, &hists, &case.voxels, focus);
        let data = Data {
            lasers: &case.lasers,
            spads: &case.spads,
            hists: &hists,
        };
        let (t_float, _) = run(
            &cfg,
            data,
            target,
            Gate::Gaussian,
            &case.voxels,
            &all_rows(case.lasers.len()),
        );
        let amps = match focus {
            None => truth.diagonal(reference::Gate::Gaussian, &case.voxels),
            Some(a) => truth.column(reference::Gate::Gaussian, a, &case.voxels),
        };
        // Error model of the module docs.
        let j = cfg.bins() as f64;
        let g: f64 = (0..cfg.bins()).map(|j| cfg.gate_weight(j)).sum();
        let k_max = cfg.k_lo().abs().max(cfg.k_hi().abs()) as f64;
        let eps_q = std::f64::consts::SQRT_2 * 2f64.powi(-15) * g
            + j * fc.gate_max() * 2f64.powi(-15)
            + 3.0 * std::f64::consts::SQRT_2 * CIS_ERR * g
            + 3.0 * std::f64::consts::PI * k_max * 2f64.powi(-32) * g;
        let nu_max = (0..cfg.bins())
            .map(|j| cfg.nu(j).abs())
            .fold(cfg.omega(), f64::max);
        let h_half = std::f64::consts::FRAC_1_SQRT_2;
        let (kl, ks) = (case.lasers.len() as f64, case.spads.len() as f64);
        for (i, v) in case.voxels.iter().enumerate() {
            let a = focus.unwrap_or(*v);
            let (pa, pb) = (p64(a), p64(*v));
            let s_ab = truth.scale(&pa, &pb);
            let w_sum: f64 = truth
                .lasers
                .iter()
                .flat_map(|xl| truth.spads.iter().map(move |xs| (xl, xs)))
                .map(|(xl, xs)| {
                    truth.w(reference::dist(xl, &pa)) * truth.w(reference::dist(&pb, xs))
                })
                .sum();
            let ws_sum: f64 = truth
                .spads
                .iter()
                .map(|xs| truth.w(reference::dist(&pb, xs)))
                .sum();
            let (_, tau_max) = truth.tau_range(&pa, &pb);
            let turns = nu_max * (tau_max.abs() + truth_p.t0.abs()) / (2.0 * std::f64::consts::PI);
            let eps_f32 = U32 * (2.0 * std::f64::consts::PI * turns + j + cfg.nt() as f64 + 64.0);
            let tail = reference::erfc(p.band_half_width / 2f64.sqrt())
                + 2.0 * (-p.gate_support.powi(2) / 2.0).exp();
            let atol = w_sum * (j + 1.0) * h_half * fc.hg_lsb()
                + if column {
                    ws_sum * kl * j * h_half * fc.column_lsb()
                } else {
                    kl * ks * h_half * fc.diag_lsb()
                };
            out.push(Cmp {
                err_ref: support::nan_is_inf((fixed[i] - amps[i].norm()).abs()),
                err_float: support::nan_is_inf((fixed[i] - t_float[i].sqrt()).abs()),
                tol: (eps_q + eps_f32 + tail) * s_ab + atol,
                tol_q: (eps_q + 2.0 * eps_f32) * s_ab + atol,
                scale: s_ab,
                phase: z_fixed
                    .get(i)
                    .map(|z| ((z / amps[i]).arg(), amps[i].norm() / s_ab)),
            });
        }
    }
    out
}

proptest! {
    #![proptest_config(support::prop::config(SEED, 256))]

    /// Diagonal and column within the derived tolerance of the reference and of the float path.
    #[test]
    fn fixed_matches_reference(case in case()) {
        for c in compare(&case) {
            prop_assert!(c.err_ref <= c.tol, "vs reference: {c:?}");
            prop_assert!(c.err_float <= c.tol_q, "vs float: {c:?}");
        }
    }
}

/// STYLE §8.24: a sweep over wavelength × gate half-width × data, RMS and max of the error
/// relative to the bound, fixed vs float (quantisation only) and fixed vs reference.
#[test]
fn fixed_error_statistics() {
    use proptest::strategy::ValueTree;
    let mut runner = support::prop::sweep_runner(SEED);
    let (mut n, mut sq_q, mut max_q, mut sq_r, mut max_r, mut max_rel) =
        (0usize, 0.0, 0.0f64, 0.0, 0.0f64, 0.0f64);
    let (mut n_ph, mut sum_ph, mut max_ph) = (0usize, 0.0f64, 0.0f64);
    for _ in 0..300 {
        let case = case().new_tree(&mut runner).unwrap().current();
        for c in compare(&case) {
            let (rq, rr) = (c.err_float / c.tol_q, c.err_ref / c.tol);
            sq_q += rq * rq;
            sq_r += rr * rr;
            max_q = max_q.max(rq);
            max_r = max_r.max(rr);
            max_rel = max_rel.max(c.err_float / c.scale);
            n += 1;
            // Phase of strong elements (|A| ≥ 5 % of S): error ≤ tol/|A| rad.
            if let Some((ph, sig)) = c.phase.filter(|&(_, sig)| sig >= 0.05) {
                assert!(ph.abs() <= c.tol / (sig * c.scale), "phase {ph} rad, {c:?}");
                sum_ph += ph;
                max_ph = max_ph.max(ph.abs());
                n_ph += 1;
            }
        }
    }
    let (rms_q, rms_r) = ((sq_q / n as f64).sqrt(), (sq_r / n as f64).sqrt());
    let bias = sum_ph / n_ph.max(1) as f64;
    println!(
        "{n_ph} strong diagonal elements: phase bias {bias:.3e} rad, max |phase error| {max_ph:.3e} rad"
    );
    // No systematic rotation: the rounding is to nearest everywhere (the NCO, the tables,
    // the shifts), so the mean phase error must be far below its max.
    assert!(n_ph >= 50, "too few strong elements: {n_ph}");
    assert!(
        bias.abs() <= max_ph / 3.0 + 1e-9,
        "phase bias {bias} vs max {max_ph}"
    );
    println!(
        "{n} elements: fixed−float / bound: RMS {rms_q:.3e} max {max_q:.3e}; \
         fixed−reference / tol: RMS {rms_r:.3e} max {max_r:.3e}; max |fixed−float|/S {max_rel:.3e}"
    );
    assert!(max_q <= 1.0 && max_r <= 1.0);
    assert!(rms_q <= 1.0 / 3f64.sqrt(), "RMS {rms_q}");
    assert!(rms_r <= 1.0 / 3f64.sqrt(), "RMS {rms_r}");
}

/// The comparison has teeth: the kernels' t0 off by half a bin fails the tolerance by > 3×.
#[test]
fn tolerance_detects_half_bin_shift() {
    let grid = |n: usize, half: f32, z: f32| -> Vec<Point> {
        let c = |i: usize| -half + 2.0 * half * i as f32 / (n - 1) as f32;
        (0..n)
            .flat_map(|i| (0..n).map(move |j| [c(i), c(j), z]))
            .collect()
    };
    let case = Case {
        lasers: grid(3, 0.4, 0.0),
        spads: grid(2, 0.3, 0.0),
        voxels: vec![[0.1, 0.0, 0.8], [-0.2, 0.1, 0.6], [0.3, -0.3, 1.0]],
        focus: [0.0, 0.0, 0.7],
        nt: 300,
        dt: 0.01,
        lambda_over_dt: 10.0,
        m: 5.0,
        cg: 5.0,
        inv: true,
        saturated: false,
        seed: 7,
        pos: 0.5,
    };
    let worst = |c: &[Cmp]| c.iter().fold(0.0f64, |m, c| m.max(c.err_ref / c.tol));
    assert!(worst(&compare(&case)) <= 1.0);
    let shifted = compare_shifted(&case, case.dt / 2.0);
    let (diag, col) = shifted.split_at(case.voxels.len());
    assert!(worst(diag) > 3.0, "diagonal: {diag:?}");
    assert!(worst(col) > 3.0, "column: {col:?}");
}

/// Photon events in the fixed-point path: the photons of every histogram, pushed one by one in
/// a random order (with events of unknown SPADs and out-of-window bins mixed in, which are
/// dropped and counted), give **bit-identical** band spectra, diagonal and column accumulators
/// to the histograms themselves (integer sums are exact in any order).
#[test]
fn fixed_photons_equal_histograms_bit_for_bit() {
    use proptest::strategy::ValueTree;
    let mut runner = support::prop::sweep_runner(SEED);
    let mut photons_total = 0u64;
    for _ in 0..48 {
        let case = case().new_tree(&mut runner).unwrap().current();
        if case.saturated {
            continue; // 65535 photons per bin: too many events for a test
        }
        let (p, hists) = case.prepare();
        let cfg = Config::try_new(&p).unwrap();
        let limits = FixedLimits::new(
            case.lasers.len() as u32,
            case.spads.len() as u32,
            MIN_DISTANCE,
        );
        let fc = FixedConfig::try_new(&cfg, &limits).unwrap();
        let (ks, nt) = (case.spads.len(), cfg.nt());
        let mut tables = vec![I1F15::ZERO; FixedScan::tables_len(&fc)];
        let scan = FixedScan::new(&fc, &case.spads, &mut tables).unwrap();
        let (mut b1, mut b2) = (
            vec![0i32; FixedRowBuffer::len(&fc, ks)],
            vec![0i32; FixedRowBuffer::len(&fc, ks)],
        );
        let mut rows = FixedRowBuffer::new(&scan, &mut b1).unwrap();
        let mut prow = FixedRowBuffer::new(&scan, &mut b2).unwrap();
        let mut pbuf = vec![0i64; FixedPhotons::len(&fc, ks)];
        let mut ph = FixedPhotons::new(&scan, &mut pbuf).unwrap();
        let (mut sd1, mut sd2) = (
            vec![0i64; FixedDiagonal::state_len(case.voxels.len())],
            vec![0i64; FixedDiagonal::state_len(case.voxels.len())],
        );
        let mut d1 = FixedDiagonal::new(&case.voxels, &mut sd1).unwrap();
        let mut d2 = FixedDiagonal::new(&case.voxels, &mut sd2).unwrap();
        let (mut sc1, mut sc2) = (
            vec![0i64; FixedColumn::state_len(&fc, ks)],
            vec![0i64; FixedColumn::state_len(&fc, ks)],
        );
        let mut c1 = FixedColumn::new(&scan, case.focus, &mut sc1).unwrap();
        let mut c2 = FixedColumn::new(&scan, case.focus, &mut sc2).unwrap();
        let mut rng = Rng(case.seed ^ 0x5eed);
        let len = ks * nt;
        for (l, x_l) in case.lasers.iter().enumerate() {
            let h = &hists[l * len..(l + 1) * len];
            let mut events: Vec<(usize, usize)> = Vec::new();
            for (i, &c) in h.iter().enumerate() {
                events.extend(std::iter::repeat_n((i / nt, i % nt), c as usize));
            }
            // Fisher–Yates, then junk that must be dropped.
            for i in (1..events.len()).rev() {
                events.swap(i, (rng.next_u64() % (i as u64 + 1)) as usize);
            }
            let junk = [(ks, 0), (usize::MAX, 1), (0, nt), (0, usize::MAX)];
            ph.reset();
            for (k, &(s, n)) in events.iter().enumerate() {
                ph.push(&scan, s, n);
                if k % 997 == 0 {
                    let (js, jn) = junk[k / 997 % junk.len()];
                    ph.push(&scan, js, jn);
                }
            }
            photons_total += events.len() as u64;
            assert_eq!(ph.dropped(), events.len().div_ceil(997) as u64);
            let a = rows.load(&scan, *x_l, h).unwrap();
            let b = prow.load_photons(&scan, *x_l, &ph).unwrap();
            assert_eq!(a.band(), b.band(), "row {l}: band spectra differ");
            d1.push_row(&scan, &a).unwrap();
            d2.push_row(&scan, &b).unwrap();
            c1.push_row(&scan, &a).unwrap();
            c2.push_row(&scan, &b).unwrap();
        }
        assert_eq!(d1.raw(), d2.raw(), "diagonal accumulators differ");
        assert_eq!(c1.raw(), c2.raw(), "column state differs");
        assert!(d1.raw().iter().any(|&x| x != 0), "empty diagonal");
    }
    assert!(photons_total > 100_000, "only {photons_total} photons");
    println!("{photons_total} photons, every row bit-identical to its histogram");
}

// ---------------------------------------------------------------------------------------
// The fixed-point lookup diagonal (`FixedLookupProbe`, kernel/src/fixed/lookup.rs).
//
// Tolerance (module docs of `FixedLookupProbe`): per (l, s), the band path's relative
// terms `ε_q` × 1.25 (the interpolant's `Σ|ℓ_q|`), plus the grid's interpolation bound `η`,
// plus the block-floating terms
// `ε_blk = √2·G·(1.25(m−1)·2⁻¹⁵ + 4.002·LAGRANGE_Q15_ERR + 1.77·CIS_ERR + 2⁻²⁸(1.25(J + L/2)·0.71 + 1.42))`,
// all × `S`; the `f32` terms of the band path plus `2u·2π·turns` (the phase product
// `τ·2³²/NΔt` in `f32`); absolute terms `W·(1.25(J + 1)·0.71 + 2⁻¹⁶(1.25(J + L/2)·0.71 + 1.42)
// + √2·J·ε_blk)·hg_lsb + Kl·Ks·0.71·diag_lsb`.
// ---------------------------------------------------------------------------------------

/// How the fixed lookup run is perturbed (teeth).
#[derive(Clone, Copy, PartialEq)]
enum Mistake {
    None,
    /// The kernel's `t0` off by half a grid step.
    HalfStep,
    /// The accumulators read one bit off (`diag_lsb·2`).
    Shift,
}

/// Amplitudes `|A|` of the fixed lookup probe for `target`.
#[allow(clippy::too_many_arguments)]
fn run_fixed_lookup(
    fc: &FixedConfig,
    g: &FixedLookupGrid,
    target: Target,
    lasers: &[Point],
    spads: &[Point],
    hists: &[u16],
    voxels: &[Point],
    lsb_factor: f64,
) -> Vec<f64> {
    let nt = fc.config().nt();
    let mut tables = vec![I1F15::ZERO; FixedScan::tables_len(fc)];
    let scan = FixedScan::new(fc, spads, &mut tables).unwrap();
    let mut lt = vec![I1F15::ZERO; FixedLookup::tables_len(g)];
    let lookup = FixedLookup::new(g, &mut lt).unwrap();
    let mut buf = vec![0i32; FixedRowBuffer::len(fc, spads.len())];
    let mut rows = FixedRowBuffer::new(&scan, &mut buf).unwrap();
    let mut st = vec![0i64; FixedLookupProbe::state_len(voxels.len())];
    let mut sc = vec![0i32; FixedLookupProbe::scratch_len(g, voxels.len())];
    let mut d = FixedLookupProbe::new(&lookup, target, voxels, &mut st, &mut sc).unwrap();
    let len = spads.len() * nt;
    for (l, x_l) in lasers.iter().enumerate() {
        let row = rows
            .load(&scan, *x_l, &hists[l * len..(l + 1) * len])
            .unwrap();
        d.push_row(&scan, &lookup, &row).unwrap();
    }
    // The budget is exhausted: one more row is refused, and nothing changes.
    let before = d.raw().to_vec();
    let row = rows.load(&scan, lasers[0], &hists[..len]).unwrap();
    assert!(d.push_row(&scan, &lookup, &row).is_err());
    assert_eq!(d.raw(), &before[..]);
    assert_eq!(d.rows(), lasers.len() as u32);
    let mut out = vec![0.0; voxels.len()];
    d.finish(&mut out).unwrap();
    out.iter().map(|t| t.sqrt() * lsb_factor).collect()
}

/// The fixed lookup diagonal, then the column `T(focus, ·)`, against the reference;
/// `(err, tol, S)` per voxel (diagonal first).
fn compare_lookup(case: &Case, tolerance: f64, mistake: Mistake) -> Vec<(f64, f64, f64)> {
    let (p, hists) = case.prepare();
    let h64: Vec<f64> = hists.iter().map(|&x| f64::from(x)).collect();
    let truth = Reference::new(&p, &case.lasers, &case.spads, h64);
    let mut out = compare_lookup_target(case, &truth, p, &hists, None, tolerance, mistake);
    // The column with the band test's alias-free window (the reference sums every path).
    let pc = alias_free(p, &truth, case.focus, &case.voxels);
    out.extend(compare_lookup_target(
        case,
        &truth,
        pc,
        &hists,
        Some(case.focus),
        tolerance,
        mistake,
    ));
    out
}

/// [`compare_lookup`] for one target (`focus`: None = the diagonal) under `p`.
fn compare_lookup_target(
    case: &Case,
    truth: &Reference,
    p: Params,
    hists: &[u16],
    focus: Option<Point>,
    tolerance: f64,
    mistake: Mistake,
) -> Vec<(f64, f64, f64)> {
    let target = focus.map_or(Target::Diagonal, Target::Column);
    let lp = LookupParams {
        tolerance,
        grid_len: None,
        ..LookupParams::new()
    };
    let limits = FixedLimits::new(
        case.lasers.len() as u32,
        case.spads.len() as u32,
        MIN_DISTANCE,
    );
    let cfg0 = Config::try_new(&p).unwrap();
    let step = FixedLookupGrid::try_new(&FixedConfig::try_new(&cfg0, &limits).unwrap(), &lp)
        .unwrap()
        .grid()
        .step();
    let p_k = Params {
        t0: p.t0
            + if mistake == Mistake::HalfStep {
                step / 2.0
            } else {
                0.0
            },
        ..p
    };
    let cfg = Config::try_new(&p_k).unwrap();
    let fc = FixedConfig::try_new(&cfg, &limits).unwrap();
    let g = FixedLookupGrid::try_new(&fc, &lp).unwrap();
    let factor = if mistake == Mistake::Shift { 2.0 } else { 1.0 };
    let fixed = run_fixed_lookup(
        &fc,
        &g,
        target,
        &case.lasers,
        &case.spads,
        hists,
        &case.voxels,
        factor,
    );
    let amps = match focus {
        None => truth.diagonal(reference::Gate::Gaussian, &case.voxels),
        Some(a) => truth.column(reference::Gate::Gaussian, a, &case.voxels),
    };
    let j = cfg.bins() as f64;
    let len = g.grid().len() as f64;
    let m_bits = len.log2();
    let gsum: f64 = (0..cfg.bins()).map(|j| cfg.gate_weight(j)).sum();
    let k_max = cfg.k_lo().abs().max(cfg.k_hi().abs()) as f64;
    let sq2 = std::f64::consts::SQRT_2;
    // The band path's terms that reach HG (twiddles, gate weights, one NCO factor: the leg
    // phase) and the phase steps (leg phase and carrier).
    let eps_q = sq2 * 2f64.powi(-15) * gsum
        + j * fc.gate_max() * 2f64.powi(-15)
        + sq2 * CIS_ERR * gsum
        + 3.0 * std::f64::consts::PI * k_max * 2f64.powi(-32) * gsum;
    let h_half = std::f64::consts::FRAC_1_SQRT_2;
    let blk_abs = 1.25 * (j + len / 2.0) * h_half + 1.42;
    let eps_blk = gsum
        * (1.25 * (m_bits - 1.0) * sq2 * 2f64.powi(-16)
            + 4.002 * LAGRANGE_Q15_ERR
            + 1.251 * sq2 * CIS_ERR)
        + sq2 * gsum * 2f64.powi(-28) * blk_abs;
    let eps = 1.25 * eps_q + eps_blk + g.grid().bound();
    let nu_max = (0..cfg.bins())
        .map(|j| cfg.nu(j).abs())
        .fold(cfg.omega(), f64::max);
    let (kl, ks) = (case.lasers.len() as f64, case.spads.len() as f64);
    let mut out = Vec::new();
    for (i, v) in case.voxels.iter().enumerate() {
        let (pa, pv) = (p64(focus.unwrap_or(*v)), p64(*v));
        let s_ab = truth.scale(&pa, &pv);
        let w_sum: f64 = truth
            .lasers
            .iter()
            .flat_map(|xl| truth.spads.iter().map(move |xs| (xl, xs)))
            .map(|(xl, xs)| truth.w(reference::dist(xl, &pa)) * truth.w(reference::dist(&pv, xs)))
            .sum();
        let (_, tau_max) = truth.tau_range(&pa, &pv);
        let turns = nu_max * (tau_max.abs() + p.t0.abs()) / (2.0 * std::f64::consts::PI);
        let eps_f32 = U32
            * (2.0 * std::f64::consts::PI * turns * (1.0 + 2.0 * gsum.max(1.0))
                + j
                + cfg.nt() as f64
                + 64.0);
        let tail = reference::erfc(p.band_half_width / 2f64.sqrt())
            + 2.0 * (-p.gate_support.powi(2) / 2.0).exp();
        let atol = w_sum
            * (1.25 * (j + 1.0) * h_half + 2f64.powi(-16) * blk_abs + sq2 * j * eps_blk)
            * fc.hg_lsb()
            + kl * ks * h_half * fc.diag_lsb();
        out.push((
            support::nan_is_inf((fixed[i] - amps[i].norm()).abs()),
            (eps + eps_f32 + tail) * s_ab + atol,
            s_ab,
        ));
    }
    out
}

proptest! {
    #![proptest_config(support::prop::config(SEED ^ 0x100c, 128))]

    /// The fixed-point lookup diagonal within its derived tolerance of the reference (grids
    /// for tolerances 1e-5 and 1e-3; 10 % of the cases at the budget's edge, every bin 65535).
    #[test]
    fn fixed_lookup_matches_reference(case in case()) {
        for tol in [1e-5, 1e-3] {
            for (err, t, s) in compare_lookup(&case, tol, Mistake::None) {
                prop_assert!(err <= t, "tolerance {tol}: err {err:e} > tol {t:e} (S {s:e})");
            }
        }
    }
}

/// Error statistics of the fixed lookup diagonal (printed; `cargo test -- --nocapture`): the
/// worst and RMS `err/tol` over a sweep, with the worst error relative to `S`.
#[test]
fn fixed_lookup_error_statistics() {
    use proptest::strategy::ValueTree;
    let mut runner = support::prop::sweep_runner(SEED ^ 7);
    let (mut n, mut sq, mut worst, mut rel) = (0usize, 0.0, 0.0f64, 0.0f64);
    for _ in 0..100 {
        let case = case().new_tree(&mut runner).unwrap().current();
        for (err, tol, s) in compare_lookup(&case, 1e-5, Mistake::None) {
            let r = err / tol;
            sq += r * r;
            worst = worst.max(r);
            rel = rel.max(err / s);
            n += 1;
        }
    }
    let rms = (sq / n as f64).sqrt();
    println!(
        "fixed lookup, {n} elements: err/tol RMS {rms:.3e} max {worst:.3e}; max err/S {rel:.3e}"
    );
    assert!(worst <= 1.0);
    assert!(rms <= 1.0 / 3f64.sqrt(), "RMS {rms}");
}

/// The fixed lookup tolerance has teeth: half a grid step off in path time, or the
/// accumulators read one bit off, fail it by > 3×.
#[test]
fn fixed_lookup_tolerance_detects_half_step_and_wrong_shift() {
    let grid = |n: usize, half: f32, z: f32| -> Vec<Point> {
        let c = |i: usize| -half + 2.0 * half * i as f32 / (n - 1) as f32;
        (0..n)
            .flat_map(|i| (0..n).map(move |j| [c(i), c(j), z]))
            .collect()
    };
    let case = Case {
        lasers: grid(3, 0.4, 0.0),
        spads: grid(2, 0.3, 0.0),
        // The second voxel lies on the flank of the first one's return (its path ≈ σ/2
        // longer), where a shift of the path time changes |A| to first order.
        voxels: vec![
            [0.1, 0.0, 0.8],
            [0.1, 0.0, 0.815],
            [-0.2, 0.1, 0.6],
            [0.3, -0.3, 1.0],
        ],
        focus: [0.0, 0.0, 0.7],
        nt: 300,
        dt: 0.01,
        lambda_over_dt: 10.0,
        m: 5.0,
        cg: 5.0,
        inv: true,
        saturated: false,
        seed: 7,
        pos: 0.5,
    };
    let worst = |c: &[(f64, f64, f64)]| c.iter().fold(0.0f64, |m, c| m.max(c.0 / c.1));
    // (Here both tolerances get the same grid: L = 8·k_d rounded up to a power of two.)
    for tol in [1e-5, 1e-3] {
        let kv = case.voxels.len();
        let ok = compare_lookup(&case, tol, Mistake::None);
        let half = compare_lookup(&case, tol, Mistake::HalfStep);
        let shift = compare_lookup(&case, tol, Mistake::Shift);
        for (what, lo, hi) in [("diagonal", 0, kv), ("column", kv, 2 * kv)] {
            let (ok, half, shift) = (
                worst(&ok[lo..hi]),
                worst(&half[lo..hi]),
                worst(&shift[lo..hi]),
            );
            println!(
                "{what}, grid tolerance {tol}: err/tol correct {ok:.3}, half step {half:.3}, shift {shift:.3}"
            );
            assert!(ok <= 1.0, "{what}: {ok}");
            assert!(half > 3.0, "{what}: half a grid step not detected: {half}");
            assert!(shift > 3.0, "{what}: a wrong shift not detected: {shift}");
        }
    }
}

/// The fixed-point reader is the Lagrange cubic: a grid sized for the Hermite interpolant's
/// (smaller) bound is refused by name rather than read with the wrong weights.
#[test]
fn fixed_lookup_refuses_a_hermite_grid() {
    let cfg = Config::try_new(&Params::new(0.13, 255, 0.0255)).unwrap();
    let fc = FixedConfig::try_new(&cfg, &FixedLimits::new(576, 28, 0.5)).unwrap();
    assert!(FixedLookupGrid::try_new(&fc, &LookupParams::new()).is_ok());
    assert_eq!(
        FixedLookupGrid::try_new(&fc, &LookupParams::hermite()).err(),
        Some(vltm_kernel::ConfigError::OutOfRange("interpolant"))
    );
}
