//! Paired scans (one laser spot and one SPAD spot per histogram, both moving, on a relay
//! surface that need not be flat) through the public API (`probe::direct`), against the `f64`
//! time-domain reference (`reference/mod.rs`): the reference of a paired scan is the sum over
//! its rows of one-pair references (laser `lasers[l]`, SPAD `spads[l]`), the diagonal
//! `A(v) = Σ_l w(|x_l − v|)·w(|v − s_l|)·Z_l(d1_l + |x_l − v| + |v − s_l| + d4_l)`.
//!
//! Cases (fixed seeds, 48 of them): a flat wall (z = 0) and a bumpy one (z within ±5 cm),
//! 3–7 × 2–5 pairs with the SPAD spot 2–9 cm from its laser spot, jittered; voxel grids of
//! 1–5 per axis and 1–3 slices at z 0.3–1.1 m; Nt 48–220, λ 0.05–0.3 m, λ/Δt 7–14, σ = λ or
//! 2λ/3, band half-width m 3–6, weights `1/d` or 1, device legs in the time axis or not;
//! signed histograms (noise, 3-vertex returns of random voxels, spikes). The window either
//! covers every path or only part of them (paths outside the guard).
//!
//! Tolerances as `tests/proptest_fast.rs` (module docs there): `|√I − |A|| ≤ ε·S(v)` with the
//! scale `S(v) = Σ_l w w Σ_n |H_l[n]|`, `ε = u·(2πΦ + J + Nt + 64) + 8u·log₂L + erfc(m/√2) +
//! 2e^{−c_g²/2}` vs the reference, plus `ε_interp = 2e-5` on the lookup path; band vs lookup
//! within `u·(2πΦ_h + 2J + 16) + 8u·log₂L + ε_interp`. Measured: worst error/tolerance 0.20
//! vs the reference (band, lookup, `Auto`), 0.04 lookup vs band. Teeth
//! (`paired_is_not_confocal`): the same histograms with the SPAD spots moved onto the laser
//! spots (a confocal reading of a paired file) fail the reference by 52–1200×, every SPAD
//! spot moved by 1 cm by 1.7–147× (1.7× at λ = 0.26 m).

mod reference;
mod support;

use reference::{Reference, p64};
use std::process::Command;
use vltm::io::{Capture, Geometry};
use vltm::kernel::{Config, Legs, Params, Point, Weights};
use vltm::probe::fast::LookupDiagonal;
use vltm::probe::{self, EvalPath, Exec, Output, Wave};
use vltm::volume::Volume;

const U32: f64 = f32::EPSILON as f64 / 2.0;
const INTERP: f64 = 2e-5;
/// The phasor path's table bound (relative to one return's peak, `Σ_j Ĝ_j ≤ 1.01`), on top
/// of the band path's `ε` (`vltm::probe::fast::phasor` module docs).
const PHASOR: f64 = 1.01 * vltm::probe::fast::phasor::TOLERANCE + INTERP;

/// The interpolation allowance of a path.
fn interp(path: EvalPath) -> f64 {
    match path {
        EvalPath::Phasor => PHASOR,
        EvalPath::Band => 0.0,
        _ => INTERP,
    }
}

/// A small deterministic generator (xorshift*).
struct Rng(u64);
impl Rng {
    fn f(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.f()
    }
    fn below(&mut self, n: usize) -> usize {
        ((self.f() * n as f64) as usize).min(n - 1)
    }
}

/// One paired case: the capture, its volume, the wave, the kernel parameters and one
/// reference per row.
struct Case {
    capture: Capture,
    volume: Volume,
    wave: Wave,
    params: Params,
    rows: Vec<Reference>,
}

/// The bump of the relay surface at (x, y): within ±`amp` m.
fn bump(amp: f64, x: f64, y: f64) -> f32 {
    (amp * (7.0 * x).sin() * (5.0 * y + 0.3).cos()) as f32
}

fn build(seed: u64, bumpy: bool) -> Case {
    let mut rng = Rng(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1);
    let amp = if bumpy { 0.05 } else { 0.0 };
    let (nx, ny) = (3 + rng.below(5), 2 + rng.below(4));
    let pitch = rng.range(0.06, 0.15);
    let (ox, oy) = (rng.range(0.02, 0.09), rng.range(-0.05, 0.05));
    let mut lasers = Vec::new();
    let mut spads = Vec::new();
    for i in 0..nx {
        for j in 0..ny {
            let x = (i as f64 - (nx - 1) as f64 / 2.0) * pitch + rng.range(-0.01, 0.01);
            let y = (j as f64 - (ny - 1) as f64 / 2.0) * pitch + rng.range(-0.01, 0.01);
            lasers.push([x as f32, y as f32, bump(amp, x, y)]);
            let (sx, sy) = (x + ox, y + oy);
            spads.push([sx as f32, sy as f32, bump(amp, sx, sy)]);
        }
    }
    let k = lasers.len();
    let vn = [1 + rng.below(5), 1 + rng.below(5), 1 + rng.below(3)];
    let z0 = rng.range(0.3, 0.7) as f32;
    let vh = rng.range(0.1, 0.4) as f32;
    let volume = Volume::grid([-vh, -vh, z0], [vh, vh, z0 + 0.4], vn).expect("z > 0");
    let lambda = rng.range(0.05, 0.3);
    let nt = 48 + rng.below(173);
    let dt = lambda / rng.range(7.0, 14.0);
    let legs = (rng.f() < 0.5).then_some(([0.3, -0.2, 1.2], [-0.4, 0.1, 1.5]));
    let params_at = |t0: f64| Params {
        sigma: Some(if rng_sigma(seed) {
            lambda
        } else {
            2.0 * lambda / 3.0
        }),
        band_half_width: 3.0 + (seed % 4) as f64,
        t0,
        legs: match legs {
            None => Legs::WallToWall,
            Some((laser_origin, sensor_origin)) => Legs::FirstAndLast {
                laser_origin,
                sensor_origin,
            },
        },
        weights: if seed.is_multiple_of(3) {
            Weights::One
        } else {
            Weights::Inv
        },
        ..Params::new(lambda, nt, dt)
    };
    let one =
        |p: &Params, l: usize, h: Vec<f64>| Reference::new(p, &lasers[l..=l], &spads[l..=l], h);
    // Place the window over the diagonal's path times (fully, or partly for a third).
    let zero = vec![0.0; nt];
    let p0 = params_at(0.0);
    let (lo, hi) = (0..k)
        .flat_map(|l| {
            let r = one(&p0, l, zero.clone());
            volume
                .points
                .iter()
                .map(|v| r.tau_range(&p64(*v), &p64(*v)))
                .collect::<Vec<_>>()
        })
        .fold((f64::INFINITY, f64::NEG_INFINITY), |a, b| {
            (a.0.min(b.0), a.1.max(b.1))
        });
    let window = (nt - 1) as f64 * dt;
    let t0 = if seed % 3 != 1 && window >= hi - lo {
        lo - rng.f() * (window - (hi - lo))
    } else {
        lo + rng.range(0.2, 0.6) * (hi - lo) - rng.f() * window
    };
    let params = params_at(t0);
    let mut h: Vec<f64> = (0..k * nt).map(|_| 0.02 * (2.0 * rng.f() - 1.0)).collect();
    for _ in 0..3 {
        let v = p64(volume.points[rng.below(volume.points.len())]);
        let amp = 0.3 + rng.f();
        for l in 0..k {
            let tau = one(&params, l, zero.clone()).tau(0, 0, &v, &v);
            let bin = ((tau - t0) / dt).round();
            if bin >= 0.0 && bin < nt as f64 {
                h[l * nt + bin as usize] += amp;
            }
        }
    }
    for _ in 0..4 {
        let i = rng.below(k * nt);
        h[i] += rng.range(-1.0, 1.0);
    }
    let h: Vec<f64> = h.iter().map(|&x| f64::from(x as f32)).collect();
    let rows = (0..k)
        .map(|l| one(&params, l, h[l * nt..(l + 1) * nt].to_vec()))
        .collect();
    let (laser_origin, sensor_origin) = legs.unwrap_or(([0.0, 0.0, 1.0], [0.0; 3]));
    let geometry = Geometry {
        lasers: lasers.clone(),
        laser_shape: [nx, ny],
        spads: spads.clone(),
        spad_shape: [nx, ny],
        laser_origin,
        sensor_origin,
        legs_in_time: legs.is_some(),
        confocal: true,
        nt,
        dt,
        t0,
        normals: Default::default(),
    };
    let data = h.iter().map(|&x| x as f32).collect();
    let capture = Capture::new(geometry, data, std::path::Path::new("case")).expect("valid");
    let wave = Wave {
        wavelength: Some(lambda),
        sigma: params.sigma,
        weights: params.weights,
        band_half_width: params.band_half_width,
        compensate_laser: false,
        auto_margin: false,
        crop: false,
        cosine: false,
    };
    Case {
        capture,
        volume,
        wave,
        params,
        rows,
    }
}

fn rng_sigma(seed: u64) -> bool {
    seed.is_multiple_of(2)
}

impl Case {
    fn direct(&self, path: EvalPath) -> vltm::Result<Output> {
        probe::direct(
            &mut self.capture.clone(),
            &self.volume,
            &self.wave,
            Exec {
                progress: None,
                path,
            },
        )
    }

    fn truth(&self) -> Vec<f64> {
        let g = reference::Gate::Gaussian;
        let mut a = vec![num_complex::Complex64::new(0.0, 0.0); self.volume.len()];
        for r in &self.rows {
            for (x, y) in a.iter_mut().zip(r.diagonal(g, &self.volume.points)) {
                *x += y;
            }
        }
        a.iter().map(|a| a.norm()).collect()
    }

    fn scales(&self) -> Vec<f64> {
        self.volume
            .points
            .iter()
            .map(|v| self.rows.iter().map(|r| r.scale(&p64(*v), &p64(*v))).sum())
            .collect()
    }

    /// (vs the reference, band vs lookup) tolerances relative to `S`.
    fn tol(&self) -> (f64, f64) {
        let cfg = Config::try_new(&self.params).expect("valid");
        let nu_max = (0..cfg.bins())
            .map(|j| cfg.nu(j).abs())
            .fold(cfg.omega(), f64::max);
        let span = |legs: bool| {
            self.rows
                .iter()
                .flat_map(|r| {
                    let r = if legs {
                        r.clone()
                    } else {
                        Reference {
                            legs: None,
                            ..r.clone()
                        }
                    };
                    self.volume
                        .points
                        .iter()
                        .map(|v| r.tau_range(&p64(*v), &p64(*v)).1)
                        .collect::<Vec<_>>()
                })
                .fold(0.0f64, f64::max)
        };
        let j = cfg.bins() as f64;
        let t0 = self.capture.geometry.t0;
        let eps32 = U32 * (nu_max * (span(true).abs() + t0.abs()) + j + cfg.nt() as f64 + 64.0);
        let fft = U32 * 8.0 * (LookupDiagonal::new(&cfg).grid_len() as f64).log2();
        let tail = (-cfg.params().gate_support.powi(2) / 2.0).exp();
        let band = reference::erfc(cfg.params().band_half_width / 2f64.sqrt());
        (
            eps32 + fft + band + 2.0 * tail,
            U32 * (nu_max * span(false) + 2.0 * j + 16.0) + fft + INTERP,
        )
    }
}

/// The worst `|√I − a| / (eps·S)` over the voxels.
fn worst(values: &[f32], truth: &[f64], scale: &[f64], eps: f64) -> f64 {
    values
        .iter()
        .zip(truth)
        .zip(scale)
        .map(|((&i, &a), &s)| {
            let e = (f64::from(i).sqrt() - a).abs();
            if e.is_nan() {
                f64::INFINITY
            } else if s > 0.0 {
                e / (eps * s)
            } else if e > 0.0 {
                f64::INFINITY
            } else {
                0.0
            }
        })
        .fold(0.0, f64::max)
}

/// Band, lookup and `Auto` diagonals of paired scans on a flat and on a bumpy (±5 cm) wall
/// against the sum of one-pair references; band against lookup; the forced FFT path is a
/// one-line error naming `--path` and the reason.
#[test]
fn paired_diagonal_matches_reference_flat_and_bumpy() {
    let mut worst_ref: f64 = 0.0;
    let mut worst_pair: f64 = 0.0;
    let mut worst_phasor: f64 = 0.0;
    let mut bumpy_cases = 0;
    for seed in 1..=48u64 {
        let bumpy = seed.is_multiple_of(2);
        let c = build(seed, bumpy);
        let g = &c.capture.geometry;
        assert!(g.paired_apart(), "seed {seed}");
        if bumpy {
            let z = g.spads.iter().map(|p| p[2].abs()).fold(0.0f32, f32::max);
            assert!(z > 0.005 && z <= 0.05, "seed {seed}: bumps {z}");
            bumpy_cases += 1;
        }
        let (eps, eps_pb) = c.tol();
        let truth = c.truth();
        let scale = c.scales();
        let band = c.direct(EvalPath::Band).expect("band");
        let lookup = c.direct(EvalPath::Lookup).expect("lookup");
        let auto = c.direct(EvalPath::Auto).expect("auto");
        let phasor = c.direct(EvalPath::Phasor).expect("phasor");
        assert_eq!(band.path, EvalPath::Band);
        assert_eq!(lookup.path, EvalPath::Lookup);
        assert_eq!(phasor.path, EvalPath::Phasor);
        assert_eq!(phasor.report.rows, g.lasers.len() as u64);
        let wp = worst(&phasor.values, &truth, &scale, eps + PHASOR);
        assert!(
            wp <= 1.0,
            "seed {seed} (bumpy {bumpy}): phasor vs reference {wp}"
        );
        worst_phasor = worst_phasor.max(wp);
        assert_ne!(auto.path, EvalPath::Planar, "seed {seed}");
        assert_eq!(band.report.rows, g.lasers.len() as u64);
        let wb = worst(&band.values, &truth, &scale, eps);
        let wl = worst(&lookup.values, &truth, &scale, eps + INTERP);
        let wa = worst(&auto.values, &truth, &scale, eps + interp(auto.path));
        let b: Vec<f64> = band.values.iter().map(|&i| f64::from(i).sqrt()).collect();
        let wlb = worst(&lookup.values, &b, &scale, eps_pb);
        worst_ref = worst_ref.max(wb).max(wl).max(wa);
        worst_pair = worst_pair.max(wlb);
        assert!(
            wb <= 1.0,
            "seed {seed} (bumpy {bumpy}): band vs reference {wb}"
        );
        assert!(
            wl <= 1.0,
            "seed {seed} (bumpy {bumpy}): lookup vs reference {wl}"
        );
        assert!(
            wa <= 1.0,
            "seed {seed} (bumpy {bumpy}): auto vs reference {wa}"
        );
        assert!(
            wlb <= 1.0,
            "seed {seed} (bumpy {bumpy}): lookup vs band {wlb}"
        );
        let e = c
            .direct(EvalPath::Planar)
            .expect_err("no FFT path for a paired scan");
        let msg = e.to_string();
        assert!(
            msg.contains("path") && msg.contains("paired") && !msg.contains('\n'),
            "{msg}"
        );
    }
    assert!(bumpy_cases >= 20);
    println!(
        "paired: worst error/tolerance vs reference {worst_ref:.3}, lookup vs band {worst_pair:.3}, phasor {worst_phasor:.3}"
    );
}

/// The phasor path gives bit-identical volumes on 1 and 2 threads (voxel tiles, the rows of
/// a batch summed in order), and `Auto` takes it on a paired scan with enough voxels.
#[test]
fn phasor_is_identical_on_1_and_2_threads() {
    for seed in [3u64, 4, 11] {
        let c = build(seed, seed.is_multiple_of(2));
        let on = |threads: usize, path: EvalPath| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool")
                .install(|| c.direct(path).expect("phasor"))
        };
        let (one, two) = (on(1, EvalPath::Phasor), on(2, EvalPath::Phasor));
        assert_eq!(one.path, EvalPath::Phasor);
        assert_eq!(one.values, two.values, "seed {seed}");
        assert_eq!(one.report.rows, two.report.rows);
    }
    // Auto: many voxels on a paired scan, the phasor path.
    let mut c = build(5, false);
    c.volume = Volume::parse("-0.3:0.3:24,-0.3:0.3:24,0.4:1.0:16").expect("volume");
    let auto = c.direct(EvalPath::Auto).expect("auto");
    assert_eq!(auto.path, EvalPath::Phasor);
}

/// Teeth: reading the same histograms as a confocal scan (SPADs on the laser spots) moves
/// the result far outside the tolerance, and so does moving every SPAD spot by 1 cm.
#[test]
fn paired_is_not_confocal() {
    for seed in [2u64, 5, 8] {
        let c = build(seed, true);
        let (eps, _) = c.tol();
        let truth = c.truth();
        let scale = c.scales();
        for (what, shift) in [("confocal", None), ("1 cm", Some(0.01f32))] {
            let mut moved = c.capture.clone();
            let g = &mut moved.geometry;
            match shift {
                None => g.spads = g.lasers.clone(),
                Some(d) => g.spads.iter_mut().for_each(|p| p[0] += d),
            }
            let out = probe::direct(
                &mut moved,
                &c.volume,
                &c.wave,
                Exec {
                    progress: None,
                    path: EvalPath::Band,
                },
            )
            .expect("band");
            let w = worst(&out.values, &truth, &scale, eps);
            println!("teeth seed {seed} {what}: error/tolerance {w:.2}");
            assert!(w > 1.0, "seed {seed}: {what} passes ({w})");
        }
    }
}

/// Columns, rows and the matrix need a SPAD grid: one line that says why; a confocal
/// capture keeps its own message.
#[test]
fn paired_columns_are_refused_with_one_line() {
    let c = build(3, false);
    let focus: Point = [0.0, 0.0, 0.6];
    let e = probe::column(
        &mut c.capture.clone(),
        focus,
        &c.volume,
        probe::ColumnGate::TwoBounce,
        probe::Shell::ALL,
        &c.wave,
        Exec {
            progress: None,
            path: EvalPath::Auto,
        },
    )
    .expect_err("columns need a SPAD grid");
    let msg = e.to_string();
    assert!(
        msg.contains("paired scan") && msg.contains("SPAD grid") && !msg.contains('\n'),
        "{msg}"
    );
}

/// A paired scene on a flat or bumpy (±5 cm) wall: 10 × 10 laser spots over ±0.45 m, each
/// SPAD spot 5 cm right of its laser spot; one patch facing the wall at (0.1, −0.05, 0.7).
fn paired_scene(bumpy: bool) -> vltm::sim::Scene {
    use vltm::sim::{Aperture, Patch, Scene, Setup};
    let amp = if bumpy { 0.05 } else { 0.0 };
    let mut lasers = Vec::new();
    let mut spads = Vec::new();
    for i in 0..10 {
        for j in 0..10 {
            let (x, y) = (-0.45 + 0.1 * i as f64, -0.45 + 0.1 * j as f64);
            lasers.push([x, y, f64::from(bump(amp, x, y))]);
            spads.push([x + 0.05, y, f64::from(bump(amp, x + 0.05, y))]);
        }
    }
    let setup = Setup {
        t0: 0.8,
        ..Setup::paired_with(
            Aperture::Points {
                points: lasers,
                shape: [10, 10],
            },
            Aperture::Points {
                points: spads,
                shape: [10, 10],
            },
            160,
            0.01,
        )
    };
    Scene::new(setup).with(Patch::new(
        "P",
        [0.1, -0.05, 0.7],
        [0.0, 0.0, -1.0],
        [0.1, 0.1],
    ))
}

/// `vltm::sim` renders paired scenes (flat and bumpy wall): one histogram per pair; the
/// direct light of the rendered capture (band and lookup) matches the `f64` reference on the
/// same histograms, and peaks at the patch.
#[test]
fn simulated_paired_captures_match_reference() {
    for bumpy in [false, true] {
        let scene = paired_scene(bumpy);
        let capture = scene.render().expect("render");
        let g = capture.geometry.clone();
        assert!(g.paired_apart() && g.spads_per_row() == 1);
        assert_eq!(capture.data.len(), 100 * 160);
        let volume = Volume::parse("-0.2:0.4:7,-0.35:0.25:7,0.5:0.9:5").unwrap();
        let params = Params {
            sigma: Some(0.1),
            band_half_width: 5.0,
            t0: g.t0,
            weights: Weights::Inv,
            ..Params::new(0.1, g.nt, g.dt)
        };
        let rows: Vec<Reference> = (0..g.lasers.len())
            .map(|l| {
                Reference::new(
                    &params,
                    &g.lasers[l..=l],
                    &g.spads[l..=l],
                    capture.row(l).iter().map(|&x| f64::from(x)).collect(),
                )
            })
            .collect();
        let case = Case {
            capture,
            volume,
            wave: Wave {
                wavelength: Some(0.1),
                sigma: Some(0.1),
                weights: Weights::Inv,
                band_half_width: 5.0,
                compensate_laser: false,
                auto_margin: false,
                crop: false,
                cosine: false,
            },
            params,
            rows,
        };
        let (eps, _) = case.tol();
        let truth = case.truth();
        let scale = case.scales();
        for path in [EvalPath::Band, EvalPath::Lookup] {
            let o = case.direct(path).expect("direct");
            let tol = if path == EvalPath::Lookup {
                eps + INTERP
            } else {
                eps
            };
            let w = worst(&o.values, &truth, &scale, tol);
            assert!(w <= 1.0, "bumpy {bumpy} {path:?}: {w}");
            let peak = (0..o.values.len())
                .max_by(|&a, &b| o.values[a].total_cmp(&o.values[b]))
                .unwrap();
            let v = case.volume.points[peak];
            let d = ((v[0] - 0.1).powi(2) + (v[1] + 0.05).powi(2) + (v[2] - 0.7).powi(2)).sqrt();
            assert!(d < 0.11, "bumpy {bumpy} {path:?}: peak at {v:?}");
        }
    }
}

fn vltm_cmd(args: &[&str]) -> std::process::Output {
    Command::new(support::vltm_bin())
        .args(args)
        .output()
        .expect("run vltm")
}

/// The command line: `vltm simulate` writes a paired capture from a scene file with
/// `"scan": "paired"`; `vltm info` names the scan, the relay surface and the paths that
/// apply; `vltm direct` images it; `vltm column` refuses it in one line; a scene whose lists
/// differ in length and a capture with NaN points are one-line errors naming the field, and
/// nothing is written (an existing output is kept).
#[test]
fn cli_simulate_info_direct_paired() {
    let dir = std::env::temp_dir().join(format!("vltm-paired-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut json = serde_json::to_value(paired_scene(true)).unwrap();
    let scene = dir.join("paired.json");
    std::fs::write(&scene, serde_json::to_string_pretty(&json).unwrap()).unwrap();
    assert!(
        std::fs::read_to_string(&scene)
            .unwrap()
            .contains("\"scan\": \"paired\"")
    );
    let cap = dir.join("paired.npz");
    let o = vltm_cmd(&[
        "simulate",
        scene.to_str().unwrap(),
        "--out",
        cap.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        said.contains("100 pairs (laser spot, SPAD spot) x "),
        "{said}"
    );
    let o = vltm_cmd(&["info", cap.to_str().unwrap()]);
    let info = String::from_utf8_lossy(&o.stdout);
    assert!(info.contains("normals      +z at every spot"), "{info}");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        info.contains("paired (one laser spot and one SPAD spot per histogram)"),
        "{info}"
    );
    assert!(info.contains("relay        not planar"), "{info}");
    assert!(
        info.contains("paths        direct: phasor, lookup or band"),
        "{info}"
    );
    let out = dir.join("direct.npy");
    let o = vltm_cmd(&[
        "direct",
        cap.to_str().unwrap(),
        "--volume",
        "-0.2:0.4:7,-0.35:0.25:7,0.5:0.9:5",
        "--wavelength",
        "0.1",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.is_file());
    // `--swap-roles` exchanges the pairs' spots: the same direct light (summary without the
    // time); `--weights cos` runs on a paired scan.
    let summary = |o: &std::process::Output| {
        let s = String::from_utf8_lossy(&o.stdout).into_owned();
        let line = s
            .lines()
            .find(|l| l.starts_with("direct:"))
            .unwrap_or("")
            .to_string();
        let (a, b) = line.split_once(" in ").unwrap_or((&line, ""));
        let b = b.split_once(" s (").map_or("", |x| x.1);
        format!("{a} {b}")
    };
    let flags = |extra: &'static str| {
        let mut v = vec![
            "direct".to_string(),
            cap.to_str().unwrap().to_string(),
            "--volume".into(),
            "-0.2:0.4:7,-0.35:0.25:7,0.5:0.9:5".into(),
            "--wavelength".into(),
            "0.1".into(),
            "--path".into(),
            "band".into(),
            "--out".into(),
            dir.join("swapped.npy").to_str().unwrap().to_string(),
        ];
        if !extra.is_empty() {
            v.extend(extra.split(' ').map(String::from));
        }
        v
    };
    let run = |extra| {
        let o = Command::new(support::vltm_bin())
            .args(flags(extra))
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "{extra}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        o
    };
    let (plain, swapped) = (run(""), run("--swap-roles"));
    assert!(summary(&plain).contains("peak"), "{}", summary(&plain));
    assert_eq!(summary(&plain), summary(&swapped));
    let cos = run("--weights cos");
    assert!(summary(&cos).contains("peak"));
    assert_ne!(summary(&plain), summary(&cos));
    let o = vltm_cmd(&[
        "column",
        cap.to_str().unwrap(),
        "--focus",
        "0.1,-0.05,0.7",
        "--volume",
        "-0.2:0.4:7,-0.35:0.25:7,0.5:0.9:5",
        "--wavelength",
        "0.1",
        "--out",
        dir.join("column.npy").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("paired scan") && err.trim().lines().count() == 1,
        "{err}"
    );
    assert!(!dir.join("column.npy").exists());

    // Lists of different lengths in the scene: nothing written, the old capture kept.
    let before = std::fs::read(&cap).unwrap();
    let spads = json["setup"]["spads"]["points"].as_array_mut().unwrap();
    spads.pop();
    json["setup"]["spads"]["shape"] = serde_json::json!([99, 1]);
    std::fs::write(&scene, serde_json::to_string(&json).unwrap()).unwrap();
    let o = vltm_cmd(&[
        "simulate",
        scene.to_str().unwrap(),
        "--out",
        cap.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("setup.spads") && err.trim().lines().count() == 1,
        "{err}"
    );
    assert_eq!(std::fs::read(&cap).unwrap(), before);

    // A paired capture with a NaN laser point: `direct` fails naming the field; the old
    // output is kept.
    let mut c = vltm::io::open(&cap).unwrap();
    c.geometry.lasers[7][1] = f32::NAN;
    let bad = dir.join("nan.npz");
    vltm::io::npz::write(&c, &bad).unwrap();
    let old = std::fs::read(&out).unwrap();
    let o = vltm_cmd(&[
        "direct",
        bad.to_str().unwrap(),
        "--volume",
        "-0.2:0.4:7,-0.35:0.25:7,0.5:0.9:5",
        "--out",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("laser_grid") && err.trim().lines().count() == 1,
        "{err}"
    );
    assert_eq!(std::fs::read(&out).unwrap(), old);
    let _ = std::fs::remove_dir_all(dir);
}

// ---- Per-point normals: `--weights cos` and `--compensate-laser` --------------------------

/// The unit normal of the bump surface `z = bump(amp, x, y)` at (x, y), `(−∂z/∂x, −∂z/∂y, 1)`
/// normalised (tilted up to ~23° at ±5 cm).
fn bump_normal(amp: f64, p: [f32; 3]) -> [f32; 3] {
    let (x, y) = (f64::from(p[0]), f64::from(p[1]));
    let zx = amp * 7.0 * (7.0 * x).cos() * (5.0 * y + 0.3).cos();
    let zy = -amp * 5.0 * (7.0 * x).sin() * (5.0 * y + 0.3).sin();
    let n = [-zx, -zy, 1.0];
    let len = (n[0] * n[0] + n[1] * n[1] + 1.0f64).sqrt();
    n.map(|c| (c / len) as f32)
}

/// A case whose geometry carries the bump's normals at every laser and SPAD spot (bumpy
/// walls; a flat wall keeps +z, the default) and whose wave asks for `cos` weights.
fn build_cos(seed: u64) -> (Case, bool) {
    let bumpy = seed.is_multiple_of(2);
    let mut c = build(seed, bumpy);
    if bumpy {
        let g = &mut c.capture.geometry;
        g.normals = vltm::io::Normals {
            lasers: g.lasers.iter().map(|&p| bump_normal(0.05, p)).collect(),
            spads: g.spads.iter().map(|&p| bump_normal(0.05, p)).collect(),
        };
    }
    c.wave.cosine = true;
    (c, bumpy)
}

/// `|n̂·(v − x)| / |v − x|` in `f64`, written here from the definition (not vltm's helper).
fn cos_at(x: [f32; 3], n: [f32; 3], v: [f32; 3]) -> f64 {
    let (x, n, v) = (p64(x), p64(n), p64(v));
    let d = [v[0] - x[0], v[1] - x[1], v[2] - x[2]];
    let nn = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let dd = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    (d[0] * n[0] + d[1] * n[1] + d[2] * n[2]).abs() / (nn * dd)
}

/// Normals per row, `(laser spots, SPAD spots)`.
type RowNormals<'a> = (&'a [[f32; 3]], &'a [[f32; 3]]);

impl Case {
    /// The reference under `cos` weights with the normals `(laser, SPAD)` per row (`None`:
    /// +z): `A(v) = Σ_l cos_l(v)·cos_s(v)·A_l(v)`, each one-pair `A_l` the time-domain
    /// reference with its distance weights.
    fn truth_cos(&self, normals: Option<RowNormals<'_>>) -> Vec<f64> {
        let g = &self.capture.geometry;
        let up = [0.0f32, 0.0, 1.0];
        let mut a = vec![num_complex::Complex64::new(0.0, 0.0); self.volume.len()];
        for (l, r) in self.rows.iter().enumerate() {
            let (nl, ns) = normals.map_or((up, up), |(nl, ns)| (nl[l], ns[l]));
            let d = r.diagonal(reference::Gate::Gaussian, &self.volume.points);
            for ((x, y), v) in a.iter_mut().zip(d).zip(&self.volume.points) {
                *x += y * (cos_at(g.lasers[l], nl, *v) * cos_at(g.spads[l], ns, *v));
            }
        }
        a.iter().map(|a| a.norm()).collect()
    }
}

/// `cos` weights (the wall's cosine per leg, from the per-point normals) on paired scans on a
/// flat and a ±5 cm bumpy wall: band, lookup and `auto` against the `f64` reference within the
/// tolerance of the distance-only weights (the cosines are ≤ 1, so `S` still bounds the
/// error). Teeth: the reference with the normals ignored (+z everywhere) fails every bumpy
/// case, and distance-only weights fail every case; the FFT path is refused in one line.
#[test]
fn cos_weights_match_reference_flat_and_bumpy() {
    let (mut worst_ok, mut least_teeth, mut least_inv) = (0.0f64, f64::INFINITY, f64::INFINITY);
    for seed in 1..=24u64 {
        let (c, bumpy) = build_cos(seed);
        let g = &c.capture.geometry;
        let (eps, _) = c.tol();
        let scale = c.scales();
        let normals = (!g.normals.flat()).then(|| (&g.normals.lasers[..], &g.normals.spads[..]));
        assert_eq!(normals.is_some(), bumpy);
        let truth = c.truth_cos(normals);
        for path in [EvalPath::Band, EvalPath::Lookup, EvalPath::Auto] {
            let out = c.direct(path).expect("cos weights");
            assert_ne!(out.path, EvalPath::Planar);
            let tol = if path == EvalPath::Band {
                eps
            } else {
                eps + INTERP
            };
            let w = worst(&out.values, &truth, &scale, tol);
            assert!(w <= 1.0, "seed {seed} (bumpy {bumpy}) {path:?}: {w}");
            worst_ok = worst_ok.max(w);
            if path == EvalPath::Band {
                if bumpy {
                    let flat = c.truth_cos(None);
                    let t = worst(&out.values, &flat, &scale, eps);
                    assert!(t > 1.0, "seed {seed}: normals ignored passes ({t})");
                    least_teeth = least_teeth.min(t);
                }
                let inv = c.truth();
                let t = worst(&out.values, &inv, &scale, eps);
                assert!(t > 1.0, "seed {seed}: distance-only weights pass ({t})");
                least_inv = least_inv.min(t);
            }
        }
        let e = c.direct(EvalPath::Planar).expect_err("no FFT path");
        let msg = e.to_string();
        assert!(msg.contains("path") && !msg.contains('\n'), "{msg}");
    }
    println!(
        "cos weights: worst error/tolerance {worst_ok:.3}; teeth: normals ignored ≥ {least_teeth:.1}×, distance-only ≥ {least_inv:.1}×"
    );
}

/// `cos` weights are refused in one line by the probes and scans that do not compute them
/// (a SPAD grid, columns), before any pass.
#[test]
fn cos_weights_refused_where_they_do_not_apply() {
    let (c, _) = build_cos(2);
    let e = probe::column(
        &mut c.capture.clone(),
        c.volume.points[0],
        &c.volume,
        probe::ColumnGate::TwoBounce,
        probe::Shell::ALL,
        &c.wave,
        Exec {
            progress: None,
            path: EvalPath::Auto,
        },
    )
    .expect_err("columns do not take cos weights");
    let msg = e.to_string();
    assert!(msg.contains("weights") && !msg.contains('\n'), "{msg}");
    // The same histograms read as a grid scan of one SPAD: refused (a SPAD grid).
    let mut grid = c.capture.clone();
    let g = &mut grid.geometry;
    g.confocal = false;
    g.spads.truncate(1);
    g.spad_shape = [1, 1];
    g.normals.spads.truncate(1);
    let e = probe::direct(
        &mut grid,
        &c.volume,
        &c.wave,
        Exec {
            progress: None,
            path: EvalPath::Auto,
        },
    )
    .expect_err("a SPAD grid does not take cos weights");
    let msg = e.to_string();
    assert!(
        msg.contains("weights") && msg.contains("one SPAD per row") && !msg.contains('\n'),
        "{msg}"
    );
}

/// `--compensate-laser` divides each row by the falloff to its spot with the spot's own
/// normal, `|v·n̂|/d³` (y-tal's `compensate_laser_cos_dsqr`): on a bumpy wall the result
/// equals the distance-only image of rows divided by that falloff computed here in `f64`,
/// and differs from the rows divided by the flat wall's `|v_z|/d³` (what it did before
/// normals). Flat wall: the two agree.
#[test]
fn compensate_laser_uses_each_spots_normal() {
    for (seed, bumpy) in [(2u64, true), (4, true), (3, false)] {
        let (mut c, b) = build_cos(seed);
        assert_eq!(b, bumpy);
        c.wave.cosine = false;
        c.capture.geometry.laser_origin = [0.3, -0.4, 1.1];
        let g = c.capture.geometry.clone();
        let falloff = |l: usize, n: [f32; 3]| {
            let (x, n) = (p64(g.lasers[l]), p64(n));
            let v = [0.3 - x[0], -0.4 - x[1], 1.1 - x[2]];
            let d = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            let nn = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            (v[0] * n[0] + v[1] * n[1] + v[2] * n[2]).abs() / nn / d.powi(3)
        };
        let divided = |f: &dyn Fn(usize) -> f64| {
            let mut cap = c.capture.clone();
            let nt = g.nt;
            for (l, row) in cap.data.chunks_exact_mut(nt).enumerate() {
                let k = (1.0 / f(l)) as f32;
                row.iter_mut().for_each(|h| *h *= k);
            }
            cap
        };
        let run = |cap: &mut Capture, compensate: bool| {
            let wave = Wave {
                compensate_laser: compensate,
                ..c.wave
            };
            let ex = Exec {
                progress: None,
                path: EvalPath::Band,
            };
            probe::direct(cap, &c.volume, &wave, ex)
                .expect("direct")
                .values
        };
        let own = run(&mut c.capture.clone(), true);
        let normals = if bumpy {
            g.normals.lasers.clone()
        } else {
            vec![[0.0, 0.0, 1.0]; g.lasers.len()]
        };
        let want = run(&mut divided(&|l| falloff(l, normals[l])), false);
        let flat = run(&mut divided(&|l| falloff(l, [0.0, 0.0, 1.0])), false);
        let max = want.iter().fold(0.0f32, |a, &b| a.max(b));
        let err = |a: &[f32], b: &[f32]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max)
                / max
        };
        let (e_own, e_flat) = (err(&own, &want), err(&own, &flat));
        println!(
            "compensate-laser seed {seed} bumpy {bumpy}: vs own normals {e_own:.2e}, vs +z {e_flat:.2e}"
        );
        assert!(e_own < 1e-4, "seed {seed}: {e_own}");
        if bumpy {
            assert!(
                e_flat > 1e-2,
                "seed {seed}: +z falloff is as good ({e_flat})"
            );
        } else {
            assert!(e_flat < 1e-4, "seed {seed}: {e_flat}");
        }
    }
}

/// Reciprocity on a paired scan: `swap_roles` exchanges the laser and SPAD lists (with their
/// normals and devices), keeps the histograms, and the direct light is unchanged (the
/// diagonal's path `d1 + |x_l − v| + |v − x_s| + d4` and weights are symmetric); swapping twice
/// is the identity. A confocal capture still has nothing to swap.
#[test]
fn swap_roles_on_paired_scans() {
    let (c, _) = build_cos(4);
    let s = vltm::io::swap_roles(&c.capture).expect("paired scans swap");
    let (g, h) = (&c.capture.geometry, &s.geometry);
    assert_eq!((&h.lasers, &h.spads), (&g.spads, &g.lasers));
    assert_eq!(h.normals.lasers, g.normals.spads);
    assert_eq!(
        (h.laser_origin, h.sensor_origin),
        (g.sensor_origin, g.laser_origin)
    );
    assert_eq!(s.data, c.capture.data);
    assert_eq!(vltm::io::swap_roles(&s).unwrap(), c.capture);
    let ex = || Exec {
        progress: None,
        path: EvalPath::Band,
    };
    let a = probe::direct(&mut c.capture.clone(), &c.volume, &c.wave, ex()).unwrap();
    let b = probe::direct(&mut s.clone(), &c.volume, &c.wave, ex()).unwrap();
    let max = a.values.iter().fold(0.0f32, |x, &y| x.max(y));
    for (x, y) in a.values.iter().zip(&b.values) {
        assert!((x - y).abs() <= 1e-5 * max, "{x} vs {y}");
    }
    let mut conf = c.capture.clone();
    conf.geometry.spads = conf.geometry.lasers.clone();
    conf.geometry.normals = Default::default();
    let e = vltm::io::swap_roles(&conf).expect_err("confocal: nothing to swap");
    assert!(e.to_string().contains("nothing to swap"), "{e}");
}
