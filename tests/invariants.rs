//! Invariants of the streaming kernel: row order, split + merge, finish / continue / reset,
//! and scene semantics on simulated data (a point scatterer is imaged at its voxel; an
//! inter-reflection A → B shows up in the column T(A, ·) at B).

mod reference;
mod support;

use reference::{P3, dist, p64};
use support::{Data, all_probes, all_rows, max_rel_diff, run};
use vltm_kernel::{
    Config, Gate, Legs, Params, Point, Probe, Report, RowBuffer, Scan, Target, Weights,
};

/// A regular grid on the wall (z = 0), `n × n` points over `[−half, half]²` (C order).
fn wall_grid(n: usize, half: f32) -> Vec<Point> {
    let c = |i: usize| -half + 2.0 * half * i as f32 / (n - 1) as f32;
    (0..n)
        .flat_map(|i| (0..n).map(move |j| [c(i), c(j), 0.0]))
        .collect()
}

/// Tiny transient simulator (`fixtures/sim/sim.py`, reduced): a Gaussian pulse of std Δt in
/// every `H[l][s][·]` at the path time of `x_l → vertices → x_s` (legs included when
/// configured), with amplitude `k/(d_0² d_1² …)` over the path's segments (`k` = product of
/// the vertices' reflectances).
struct Sim<'a> {
    p: &'a Params,
    lasers: &'a [Point],
    spads: &'a [Point],
}

impl Sim<'_> {
    fn legs(&self, l: usize, s: usize) -> (f64, f64) {
        match self.p.legs {
            Legs::WallToWall => (0.0, 0.0),
            Legs::FirstAndLast {
                laser_origin,
                sensor_origin,
            } => (
                dist(&p64(self.lasers[l]), &laser_origin),
                dist(&p64(self.spads[s]), &sensor_origin),
            ),
        }
    }

    /// Adds the paths `x_l → vertices[0] → … → x_s` with total reflectance `k`.
    fn add(&self, h: &mut [f32], vertices: &[P3], k: f64) {
        let (ks, nt, dt) = (self.spads.len(), self.p.nt, self.p.dt);
        for (l, xl) in self.lasers.iter().enumerate() {
            for (s, xs) in self.spads.iter().enumerate() {
                let mut pts = vec![p64(*xl)];
                pts.extend_from_slice(vertices);
                pts.push(p64(*xs));
                let segs: Vec<f64> = pts.windows(2).map(|w| dist(&w[0], &w[1])).collect();
                let (d1, d4) = self.legs(l, s);
                let t = d1 + segs.iter().sum::<f64>() + d4;
                let amp = k / segs.iter().map(|d| d * d).product::<f64>();
                let hist = &mut h[(l * ks + s) * nt..(l * ks + s + 1) * nt];
                for (n, x) in hist.iter_mut().enumerate() {
                    let u = self.p.t0 + n as f64 * dt - t;
                    *x += (amp * (-u * u / (2.0 * dt * dt)).exp()) as f32;
                }
            }
        }
    }
}

fn argmax(x: &[f64]) -> usize {
    (0..x.len()).fold(0, |best, i| if x[i] > x[best] { i } else { best })
}

fn median(x: &[f64]) -> f64 {
    let mut v = x.to_vec();
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// A small scan with structure (two scatterers, an inter-reflection) plus deterministic
/// signed noise, used by the bookkeeping invariants.
struct Bench {
    params: Params,
    lasers: Vec<Point>,
    spads: Vec<Point>,
    voxels: Vec<Point>,
    focus: Point,
    h: Vec<f32>,
}

fn bench() -> Bench {
    let params = Params {
        t0: 0.4,
        legs: Legs::FirstAndLast {
            laser_origin: [0.3, -0.2, 0.6],
            sensor_origin: [-0.2, 0.3, 0.5],
        },
        ..Params::new(0.08, 500, 0.01)
    };
    let lasers = wall_grid(3, 0.5);
    let spads = wall_grid(3, 0.4);
    let voxels = vec![
        [-0.25, 0.0, 0.8],
        [0.25, 0.0, 0.8],
        [0.0, 0.1, 0.6],
        [0.1, -0.2, 1.0],
        [0.3, 0.3, 0.9],
    ];
    let (a, b) = (p64(voxels[0]), p64(voxels[1]));
    let mut h = vec![0.0f32; lasers.len() * spads.len() * params.nt];
    let sim = Sim {
        p: &params,
        lasers: &lasers,
        spads: &spads,
    };
    sim.add(&mut h, &[a], 1.0);
    sim.add(&mut h, &[b], 1.0);
    sim.add(&mut h, &[a, b], 0.1);
    let mut state = 12345u32;
    for x in &mut h {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        *x += (f64::from(state >> 8) / f64::from(1u32 << 24) - 0.5) as f32 * 0.02;
    }
    Bench {
        params,
        lasers,
        spads,
        voxels,
        focus: [-0.25, 0.0, 0.8],
        h,
    }
}

impl Bench {
    fn cfg(&self) -> Config {
        Config::try_new(&self.params).expect("valid")
    }
    fn data(&self) -> Data<'_, f32> {
        Data {
            lasers: &self.lasers,
            spads: &self.spads,
            hists: &self.h,
        }
    }
}

/// Rows pushed in any order give the same intensities (to f64 rounding of the accumulators).
#[test]
fn row_order_does_not_matter() {
    let b = bench();
    let cfg = b.cfg();
    let kl = b.lasers.len();
    let forward = all_rows(kl);
    let reversed: Vec<usize> = (0..kl).rev().collect();
    let shuffled: Vec<usize> = (0..kl).map(|i| (i * 5 + 3) % kl).collect(); // 5 ⟂ 9
    assert_ne!(shuffled, forward);
    for (t, g) in all_probes(b.focus) {
        let (one, r1) = run(&cfg, b.data(), t, g, &b.voxels, &forward);
        assert!(one.iter().any(|&x| x > 0.0), "{t:?}/{g:?}: empty result");
        for order in [&reversed, &shuffled] {
            let (other, r2) = run(&cfg, b.data(), t, g, &b.voxels, order);
            let d = max_rel_diff(&other, &one);
            assert!(d < 1e-12, "{t:?}/{g:?}: order changed the result by {d:e}");
            assert_eq!(r1, r2);
        }
    }
}

/// Splitting the rows over two probes and merging equals one pass, counters included.
#[test]
fn split_and_merge_equals_one_pass() {
    let mut b = bench();
    b.h[7] = f32::NAN; // row 0
    let last = b.h.len() - 3;
    b.h[last] = f32::INFINITY; // last row
    let cfg = b.cfg();
    let (ks, kv) = (b.spads.len(), b.voxels.len());
    let mut tables = vec![0.0f32; Scan::tables_len(&cfg, ks)];
    let scan = Scan::new(&cfg, &b.spads, &mut tables).unwrap();
    let mut buf = vec![0.0f32; RowBuffer::len(&cfg, ks)];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    let data = b.data();
    for (t, g) in all_probes(b.focus) {
        let (one, r_one) = run(&cfg, data, t, g, &b.voxels, &all_rows(b.lasers.len()));
        assert_eq!(r_one.aliased, 0, "the bench keeps columns alias-free");
        for split in [0, 1, 4, b.lasers.len() - 1, b.lasers.len()] {
            let len = Probe::state_len(&cfg, t, g, kv, ks);
            let (mut s1, mut s2) = (vec![0.0; len], vec![0.0; len]);
            let mut p1 = Probe::new(&scan, t, g, &b.voxels, &mut s1).unwrap();
            let mut p2 = Probe::new(&scan, t, g, &b.voxels, &mut s2).unwrap();
            for l in 0..b.lasers.len() {
                let row = rows
                    .load(&scan, b.lasers[l], data.row(cfg.nt(), l))
                    .unwrap();
                if l < split {
                    p1.push_row(&scan, &row)
                } else {
                    p2.push_row(&scan, &row)
                }
                .unwrap();
            }
            p1.merge(&p2).unwrap();
            let mut out = vec![0.0; kv];
            let rep = p1.finish(&scan, &mut out).unwrap();
            let d = max_rel_diff(&out, &one);
            assert!(
                d < 1e-12,
                "{t:?}/{g:?} split at {split}: merge differs by {d:e}"
            );
            assert_eq!(rep, r_one, "{t:?}/{g:?} split at {split}: counters");
            assert_eq!(rep.non_finite, 2);
            assert_eq!(rep.rows, b.lasers.len() as u64);
        }
    }
}

/// `finish` does not consume: calling it twice gives the same bits, and a scan can be
/// finished half-way, continued and finished again with the one-pass result.
#[test]
fn finish_twice_and_continue() {
    let b = bench();
    let cfg = b.cfg();
    let (ks, kv, kl) = (b.spads.len(), b.voxels.len(), b.lasers.len());
    let mut tables = vec![0.0f32; Scan::tables_len(&cfg, ks)];
    let scan = Scan::new(&cfg, &b.spads, &mut tables).unwrap();
    let mut buf = vec![0.0f32; RowBuffer::len(&cfg, ks)];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    let data = b.data();
    for (t, g) in all_probes(b.focus) {
        let (one, r_one) = run(&cfg, data, t, g, &b.voxels, &all_rows(kl));
        let (half, r_half) = run(&cfg, data, t, g, &b.voxels, &all_rows(kl / 2));
        let mut state = vec![0.0; Probe::state_len(&cfg, t, g, kv, ks)];
        let mut probe = Probe::new(&scan, t, g, &b.voxels, &mut state).unwrap();
        let (mut o1, mut o2) = (vec![0.0; kv], vec![0.0; kv]);
        for l in 0..kl {
            if l == kl / 2 {
                let rep1 = probe.finish(&scan, &mut o1).unwrap();
                let rep2 = probe.finish(&scan, &mut o2).unwrap();
                assert_eq!(o1, o2, "{t:?}/{g:?}: second finish differs");
                assert_eq!((rep1, rep2), (r_half, r_half));
                assert_eq!(o1, half, "{t:?}/{g:?}: half-way finish");
                assert_ne!(
                    o1, one,
                    "{t:?}/{g:?}: half a scan should differ from the whole"
                );
            }
            let row = rows
                .load(&scan, b.lasers[l], data.row(cfg.nt(), l))
                .unwrap();
            probe.push_row(&scan, &row).unwrap();
        }
        let rep = probe.finish(&scan, &mut o1).unwrap();
        assert_eq!(o1, one, "{t:?}/{g:?}: continued scan");
        assert_eq!(rep, r_one);
    }
}

/// `reset` zeroes accumulators and counters; the probe is then as good as new.
#[test]
fn reset_gives_a_fresh_probe() {
    let b = bench();
    let cfg = b.cfg();
    let (ks, kv, kl) = (b.spads.len(), b.voxels.len(), b.lasers.len());
    let mut tables = vec![0.0f32; Scan::tables_len(&cfg, ks)];
    let scan = Scan::new(&cfg, &b.spads, &mut tables).unwrap();
    let mut buf = vec![0.0f32; RowBuffer::len(&cfg, ks)];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    let data = b.data();
    for (t, g) in all_probes(b.focus) {
        let (one, r_one) = run(&cfg, data, t, g, &b.voxels, &all_rows(kl));
        let mut state = vec![0.0; Probe::state_len(&cfg, t, g, kv, ks)];
        let mut probe = Probe::new(&scan, t, g, &b.voxels, &mut state).unwrap();
        // Junk rows (a different laser order and scaled data) before the reset.
        let junk: Vec<f32> = b.h.iter().map(|x| 3.0 * x + 1.0).collect();
        for l in (0..kl).rev().take(4) {
            let row = rows
                .load(
                    &scan,
                    b.lasers[(l + 2) % kl],
                    &junk[l * ks * cfg.nt()..(l + 1) * ks * cfg.nt()],
                )
                .unwrap();
            probe.push_row(&scan, &row).unwrap();
        }
        let mut out = vec![0.0; kv];
        probe.finish(&scan, &mut out).unwrap();
        assert!(out.iter().any(|&x| x > 0.0));
        probe.reset();
        assert_eq!(probe.report(), Report::default());
        let rep = probe.finish(&scan, &mut out).unwrap();
        assert_eq!(rep, Report::default(), "{t:?}/{g:?}");
        assert!(
            out.iter().all(|&x| x == 0.0),
            "{t:?}/{g:?}: reset left {out:?}"
        );
        for l in 0..kl {
            let row = rows
                .load(&scan, b.lasers[l], data.row(cfg.nt(), l))
                .unwrap();
            probe.push_row(&scan, &row).unwrap();
        }
        let rep = probe.finish(&scan, &mut out).unwrap();
        assert_eq!(out, one, "{t:?}/{g:?}: after reset");
        assert_eq!(rep, r_one);
    }
}

/// A single point scatterer: the Gaussian diagonal over a 5 × 3 × 5 voxel grid peaks at the
/// scatterer's voxel, well above the rest, for several time axes, legs and weights.
#[test]
fn point_scatterer_is_imaged_at_its_voxel() {
    let lasers = wall_grid(5, 0.5);
    let spads = wall_grid(4, 0.4);
    let grid: Vec<Point> = (0..5)
        .flat_map(|i| {
            (0..3).flat_map(move |j| {
                (0..5).map(move |k| {
                    [
                        0.1 * i as f32 - 0.2,
                        0.1 * j as f32 - 0.1,
                        0.5 + 0.1 * k as f32,
                    ]
                })
            })
        })
        .collect();
    let p: Point = [0.1, 0.0, 0.7];
    let at = grid
        .iter()
        .position(|v| v.iter().zip(&p).all(|(a, b)| (a - b).abs() < 1e-6))
        .unwrap();
    let legs = Legs::FirstAndLast {
        laser_origin: [0.4, 0.1, 0.8],
        sensor_origin: [-0.3, -0.2, 0.7],
    };
    let setups = [
        Params {
            t0: 0.5,
            ..Params::new(0.06, 256, 0.01)
        },
        Params {
            t0: -0.3,
            weights: Weights::One,
            ..Params::new(0.06, 300, 0.01)
        },
        Params {
            t0: 1.2,
            legs,
            sigma: Some(0.05),
            ..Params::new(0.08, 300, 0.01)
        },
        Params {
            t0: 1.2,
            legs,
            weights: Weights::One,
            ..Params::new(0.05, 400, 0.0075)
        },
    ];
    for params in setups {
        let mut h = vec![0.0f32; lasers.len() * spads.len() * params.nt];
        Sim {
            p: &params,
            lasers: &lasers,
            spads: &spads,
        }
        .add(&mut h, &[p64(p)], 1.0);
        let cfg = Config::try_new(&params).unwrap();
        let data = Data {
            lasers: &lasers,
            spads: &spads,
            hists: &h,
        };
        let (t, rep) = run(
            &cfg,
            data,
            Target::Diagonal,
            Gate::Gaussian,
            &grid,
            &all_rows(lasers.len()),
        );
        assert_eq!(argmax(&t), at, "{params:?}: peak at {:?}", grid[argmax(&t)]);
        let runner_up = (0..t.len())
            .filter(|&i| i != at)
            .map(|i| t[i])
            .fold(0.0, f64::max);
        assert!(
            t[at] > 5.0 * runner_up,
            "{params:?}: peak {} vs runner-up {runner_up}",
            t[at]
        );
        assert!(
            t[at] > 1e4 * median(&t),
            "{params:?}: peak {} vs median {}",
            t[at],
            median(&t)
        );
        assert_eq!(rep.rows, lasers.len() as u64);
    }
}

/// Two patches A, B with an A → B inter-reflection: the gated column T(A, ·) at B is much
/// larger than on the same scene without the 4-vertex path (direct light only), while the
/// higher-order gate (Eq. 18) rejects the 4-vertex path and picks up a 5-vertex A → C → B.
#[test]
fn inter_reflection_shows_in_the_column() {
    let lasers = wall_grid(6, 0.5);
    let spads = wall_grid(5, 0.5);
    let (a, b, c): (Point, Point, Point) = ([-0.25, 0.0, 0.8], [0.25, 0.0, 0.8], [0.0, 0.35, 1.1]);
    let voxels: Vec<Point> = vec![
        b,
        [0.0, 0.0, 0.8],
        [0.25, 0.0, 0.6],
        [0.25, 0.2, 0.8],
        [0.4, -0.1, 1.0],
    ];
    let params = Params {
        t0: 0.5,
        ..Params::new(0.06, 400, 0.01)
    };
    let cfg = Config::try_new(&params).unwrap();
    let k = 0.04 / std::f64::consts::PI; // albedo 1, area 0.04 m²
    let scene = |four: bool, five: bool| {
        let mut h = vec![0.0f32; lasers.len() * spads.len() * params.nt];
        let sim = Sim {
            p: &params,
            lasers: &lasers,
            spads: &spads,
        };
        for x in [a, b, c] {
            sim.add(&mut h, &[p64(x)], k);
        }
        if four {
            sim.add(&mut h, &[p64(a), p64(b)], k * k);
        }
        if five {
            sim.add(&mut h, &[p64(a), p64(c), p64(b)], k * k); // C bright: k_C = 1
        }
        h
    };
    let column = |h: &[f32], gate| {
        let data = Data {
            lasers: &lasers,
            spads: &spads,
            hists: h,
        };
        let (t, rep) = run(
            &cfg,
            data,
            Target::Column(a),
            gate,
            &voxels,
            &all_rows(lasers.len()),
        );
        assert_eq!(rep.aliased, 0);
        t
    };
    let (direct, with_ab, with_acb) = (scene(false, false), scene(true, false), scene(false, true));
    let (t_direct, t_ab) = (
        column(&direct, Gate::Gaussian),
        column(&with_ab, Gate::Gaussian),
    );
    assert!(
        t_ab[0] > 10.0 * t_direct[0],
        "T(A,B): {} with A→B vs {} without",
        t_ab[0],
        t_direct[0]
    );
    assert_eq!(argmax(&t_ab), 0, "column with A→B peaks at B: {t_ab:?}");
    // Eq. 18: blind to the 4-vertex path, sees the 5-vertex one.
    let (ho_direct, ho_ab, ho_acb) = (
        column(&direct, Gate::HigherOrder),
        column(&with_ab, Gate::HigherOrder),
        column(&with_acb, Gate::HigherOrder),
    );
    assert!(
        ho_acb[0] > 3.0 * ho_direct[0],
        "T_ho(A,B): {} with A→C→B vs {}",
        ho_acb[0],
        ho_direct[0]
    );
    assert!(
        ho_ab[0] < 1.5 * ho_direct[0],
        "T_ho(A,B) {} should ignore A→B ({})",
        ho_ab[0],
        ho_direct[0]
    );
}

/// Integer counts give bit-identical results whether passed as `u16`, `u32` or `f32`.
#[test]
fn sample_types_agree() {
    let b = bench();
    let cfg = b.cfg();
    let counts: Vec<u16> =
        b.h.iter()
            .map(|x| (x * 300.0).round().clamp(0.0, 65535.0) as u16)
            .collect();
    let wide: Vec<u32> = counts.iter().map(|&c| u32::from(c)).collect();
    let float: Vec<f32> = counts.iter().map(|&c| f32::from(c)).collect();
    assert!(counts.iter().any(|&c| c > 100));
    let order = all_rows(b.lasers.len());
    for (t, g) in all_probes(b.focus) {
        let d16 = Data {
            lasers: &b.lasers,
            spads: &b.spads,
            hists: &counts[..],
        };
        let d32 = Data {
            lasers: &b.lasers,
            spads: &b.spads,
            hists: &wide[..],
        };
        let df = Data {
            lasers: &b.lasers,
            spads: &b.spads,
            hists: &float[..],
        };
        let (x16, r16) = run(&cfg, d16, t, g, &b.voxels, &order);
        let (x32, r32) = run(&cfg, d32, t, g, &b.voxels, &order);
        let (xf, rf) = run(&cfg, df, t, g, &b.voxels, &order);
        assert!(x16.iter().any(|&x| x > 0.0));
        assert_eq!(x16, x32, "{t:?}/{g:?}");
        assert_eq!(x16, xf, "{t:?}/{g:?}");
        assert_eq!((r16, r32), (rf, rf));
    }
}

/// `Probe::image` of a factorised column on voxels other than its own equals finishing a
/// probe built over those voxels (its state does not depend on them); the other probes
/// refuse to image.
#[test]
fn image_equals_finish_on_other_voxels() {
    let b = bench();
    let cfg = b.cfg();
    let (ks, kv, kl) = (b.spads.len(), b.voxels.len(), b.lasers.len());
    let mut tables = vec![0.0f32; Scan::tables_len(&cfg, ks)];
    let scan = Scan::new(&cfg, &b.spads, &mut tables).unwrap();
    let mut buf = vec![0.0f32; RowBuffer::len(&cfg, ks)];
    let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    let data = b.data();
    let other: Vec<Point> = (0..7)
        .map(|i| [0.1 * i as f32 - 0.3, 0.05, 0.7 + 0.03 * i as f32])
        .collect();
    for (t, g) in all_probes(b.focus) {
        let mut state = vec![0.0; Probe::state_len(&cfg, t, g, kv, ks)];
        let mut probe = Probe::new(&scan, t, g, &b.voxels, &mut state).unwrap();
        for l in 0..kl {
            let row = rows
                .load(&scan, b.lasers[l], data.row(cfg.nt(), l))
                .unwrap();
            probe.push_row(&scan, &row).unwrap();
        }
        let factorised = matches!((t, g), (Target::Column(_), Gate::Gaussian | Gate::None));
        assert_eq!(probe.is_factorised(), factorised, "{t:?}/{g:?}");
        let mut out = vec![0.0; other.len()];
        let imaged = probe.image(&scan, &other, &mut out);
        if factorised {
            let (expect, r_expect) = run(&cfg, data, t, g, &other, &all_rows(kl));
            assert!(expect.iter().any(|&x| x > 0.0));
            assert_eq!(out, expect, "{t:?}/{g:?}");
            assert_eq!(imaged.unwrap(), r_expect);
            // Its own voxels through `image` are `finish`.
            let (mut o1, mut o2) = (vec![0.0; kv], vec![0.0; kv]);
            assert_eq!(
                probe.image(&scan, &b.voxels, &mut o1).unwrap(),
                probe.finish(&scan, &mut o2).unwrap()
            );
            assert_eq!(o1, o2);
        } else {
            assert!(
                matches!(imaged, Err(vltm_kernel::ArgumentError::Incompatible(_))),
                "{t:?}/{g:?}: {imaged:?}"
            );
        }
    }
}
