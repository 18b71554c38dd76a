//! Leak-corrected in-focus indirect light measured on the path-traced scenes of
//! `fixtures/pathtraced` (mitransient 1.3.1, three captures per scene with the same seed: all
//! paths, direct only, two hidden vertices only = the indirect-only truth).
//!
//! Shared by `tests/leak.rs` (which asserts the numbers in bands) and `benches/pathtraced.rs`
//! (which prints the table of docs/indirect-light.md). Every figure is a mean over an
//! object's voxels (its box surface sampled densely, ± one voxel: `Volume::surface_voxels`),
//! and the same Γ (from the full capture's diagonal) serves the full capture, the control and
//! the truth.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use vltm::io::{self, Capture};
use vltm::kernel::Point;
use vltm::probe::{self, Exec, IndirectOptions, LeakOptions, Shell, Wave};
use vltm::volume::Volume;

#[path = "pathtraced_stage2.rs"]
mod stage2;
pub use stage2::*;

const EXEC: Exec<'static> = Exec {
    progress: None,
    path: vltm::probe::EvalPath::Auto,
};

/// The volume every path-traced scene is probed over (pitch 0.1 × 0.1 × 0.05 m).
pub const VOLUME: &str = "-0.75:0.75:16,-0.75:0.75:16,0.5:1.4:19";

/// The scenes of `fixtures/pathtraced`.
pub const SCENES: [&str; 2] = ["panel_figure", "corner"];

/// `fixtures/pathtraced`.
pub fn dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("fixtures/pathtraced")
}

/// One scene's three captures, its volume and its objects' voxels.
pub struct Captures {
    /// Scene name.
    pub scene: String,
    /// All paths.
    pub all: Capture,
    /// Direct only (one hidden vertex): the control.
    pub direct: Capture,
    /// Two hidden vertices only: the indirect-only truth.
    pub indirect: Capture,
    /// The probed volume.
    pub vol: Volume,
    /// (object name, its voxels), in `scene.json` order.
    pub objects: Vec<(String, Vec<usize>)>,
    /// The object the virtual projector focuses on (the "projector's own surface").
    pub projector: String,
    /// Points on each object's box surface (50 per metre), in `objects` order.
    pub surfaces: Vec<Vec<Point>>,
    /// `scene.json`'s objects (centre, size, frame), in `objects` order.
    pub boxes: Vec<serde_json::Value>,
}

/// Points on the surface of a box (`scene.json`: centre, size along (r, u, −f), frame), `n`
/// samples per unit length (at least 2 per edge).
fn box_surface(o: &serde_json::Value, n: f64) -> Vec<Point> {
    let v3 = |k: &str| -> [f64; 3] { core::array::from_fn(|i| o[k][i].as_f64().unwrap()) };
    let (c, s) = (v3("centre"), v3("size_m"));
    let (r, u, f) = (v3("right_r"), v3("up_u"), v3("front_normal_f"));
    let axes = [r, u, f.map(|x| -x)];
    let mut out = Vec::new();
    for k in 0..3 {
        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
        let (ni, nj) = (
            ((s[i] * n).ceil() as usize).max(2),
            ((s[j] * n).ceil() as usize).max(2),
        );
        for side in [-0.5, 0.5] {
            for a in 0..ni {
                for b in 0..nj {
                    let ca = (a as f64 + 0.5) / ni as f64 - 0.5;
                    let cb = (b as f64 + 0.5) / nj as f64 - 0.5;
                    let p: [f64; 3] = core::array::from_fn(|x| {
                        c[x] + side * s[k] * axes[k][x]
                            + ca * s[i] * axes[i][x]
                            + cb * s[j] * axes[j][x]
                    });
                    out.push(p.map(|x| x as f32));
                }
            }
        }
    }
    out
}

/// Load `scene` from `fixtures/pathtraced` (`<scene>_{all,direct,indirect}/`).
pub fn load(scene: &str) -> Captures {
    load_from(&dir(), scene)
}

/// Load `scene` from `root`.
pub fn load_from(root: &Path, scene: &str) -> Captures {
    let open = |v: &str| {
        let p = root
            .join(format!("{scene}_{v}"))
            .join(format!("{scene}_{v}.hdf5"));
        if !p.is_file() {
            panic!(
                "{} is missing: restore it with `git checkout -- fixtures/pathtraced` \
                 (fixtures/pathtraced/README.md says how it is rendered)",
                p.display()
            );
        }
        io::open(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
    };
    let text = std::fs::read_to_string(root.join(format!("{scene}_all/scene.json"))).unwrap();
    let j: serde_json::Value = serde_json::from_str(&text).unwrap();
    let vol = Volume::parse(VOLUME).unwrap();
    let objects = j["objects"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(name, o)| (name.clone(), vol.surface_voxels(&box_surface(o, 200.0))))
        .collect();
    let surfaces = j["objects"]
        .as_object()
        .unwrap()
        .values()
        .map(|o| box_surface(o, 50.0))
        .collect();
    Captures {
        scene: scene.to_string(),
        all: open("all"),
        direct: open("direct"),
        indirect: open("indirect"),
        vol,
        objects,
        projector: j["projector_surface"].as_str().unwrap().to_string(),
        surfaces,
        boxes: j["objects"]
            .as_object()
            .unwrap()
            .values()
            .cloned()
            .collect(),
    }
}

/// The oracle surfels of the scene (Stage 1 of the analysis by synthesis: geometry from
/// `scene.json`, never from the capture): every face of every box sampled `n` per metre, with
/// its outward normal and area, one cluster per object.
pub fn oracle_surfels(c: &Captures, n: f64) -> probe::synth::Surfels {
    c_boxes_surfels(&c.boxes, n)
}

fn c_boxes_surfels(boxes: &[serde_json::Value], n: f64) -> probe::synth::Surfels {
    let (mut pts, mut nrm, mut area, mut cl) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (ci, o) in boxes.iter().enumerate() {
        let v3 = |k: &str| -> [f64; 3] { core::array::from_fn(|i| o[k][i].as_f64().unwrap()) };
        let (ctr, s) = (v3("centre"), v3("size_m"));
        let (r, u, f) = (v3("right_r"), v3("up_u"), v3("front_normal_f"));
        let axes = [r, u, f.map(|x| -x)];
        for k in 0..3 {
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            let (ni, nj) = (
                ((s[i] * n).ceil() as usize).max(2),
                ((s[j] * n).ceil() as usize).max(2),
            );
            for side in [-0.5f64, 0.5] {
                for a in 0..ni {
                    for b in 0..nj {
                        let ca = (a as f64 + 0.5) / ni as f64 - 0.5;
                        let cb = (b as f64 + 0.5) / nj as f64 - 0.5;
                        pts.push(core::array::from_fn(|x| {
                            ctr[x]
                                + side * s[k] * axes[k][x]
                                + ca * s[i] * axes[i][x]
                                + cb * s[j] * axes[j][x]
                        }));
                        nrm.push(axes[k].map(|x| x * side.signum()));
                        area.push(s[i] * s[j] / (ni * nj) as f64);
                        cl.push(ci);
                    }
                }
            }
        }
    }
    probe::synth::Surfels::new(pts, nrm, area, cl).expect("oracle surfels")
}

/// A facet's error against `scene.json` (a diagnostic only, never an input): the angle
/// (degrees) between its normal and that of the box face it stands for (of the faces that look
/// at the wall, the nearest with 1° weighed as 1 cm), and the distance (m) of its centre from
/// that face's plane.
pub fn facet_error(boxes: &[serde_json::Value], f: &probe::synth::Facet) -> (f64, f64) {
    let mut best = (f64::INFINITY, f64::INFINITY);
    for o in boxes {
        let v3 = |k: &str| -> [f64; 3] { core::array::from_fn(|i| o[k][i].as_f64().unwrap()) };
        let (ctr, s) = (v3("centre"), v3("size_m"));
        let (r, u, fr) = (v3("right_r"), v3("up_u"), v3("front_normal_f"));
        let axes = [r, u, fr.map(|x| -x)];
        for k in 0..3 {
            for side in [-0.5f64, 0.5] {
                let n = axes[k].map(|x| x * side.signum());
                let c: [f64; 3] = core::array::from_fn(|i| ctr[i] + side * s[k] * axes[k][i]);
                if n[2] >= 0.0 {
                    continue;
                }
                let cos = (0..3)
                    .map(|i| n[i] * f.normal[i])
                    .sum::<f64>()
                    .clamp(-1.0, 1.0);
                let ang = cos.acos().to_degrees();
                let off = (0..3)
                    .map(|i| (f.centre[i] - c[i]) * n[i])
                    .sum::<f64>()
                    .abs();
                // The face the facet stands for: the nearest in angle and distance together
                // (1° weighs as 1 cm).
                if ang + off * 100.0 < best.0 + best.1 * 100.0 {
                    best = (ang, off);
                }
            }
        }
    }
    best
}

/// Probe settings of one measurement.
#[derive(Clone, Copy, Debug)]
pub struct Setup {
    /// λ, σ, weights, `compensate_laser`.
    pub wave: Wave,
    /// Γ threshold ε.
    pub epsilon: f32,
    /// Minimum pair separation r0 (None = 1.5σ, the default).
    pub r0: Option<f32>,
    /// Leak correction (None = the paper's Eq. 17).
    pub leak: Option<LeakOptions>,
}

impl Setup {
    /// The in-focus indirect light's options with no leak correction (ε, r0): for a capture
    /// whose direct light is removed another way (a model subtracted) or not at all.
    pub fn uncorrected(&self) -> IndirectOptions {
        IndirectOptions {
            epsilon: self.epsilon,
            shell: self.r0.map(|r0| Shell {
                r0,
                r1: f32::INFINITY,
            }),
            leak: None,
            ..IndirectOptions::default()
        }
    }
}

/// vltm indirect's defaults on a tal capture (λ = 2 × pitch, σ = 2λ/3, ε = 0.1, r0 = 1.5σ,
/// leak correction by gating) plus `--compensate-laser`, stated explicitly: it is off by
/// default, and the renders hold the laser's falloff (docs/indirect-light.md).
pub fn defaults() -> Setup {
    Setup {
        wave: Wave {
            compensate_laser: true,
            ..Wave::default()
        },
        epsilon: 0.1,
        r0: None,
        leak: Some(LeakOptions::default()),
    }
}

/// One object's figures.
#[derive(Clone, Debug)]
pub struct ObjectRow {
    /// Object name.
    pub name: String,
    /// Its voxels, and how many of them are in Γ.
    pub voxels: usize,
    /// Of which in Γ.
    pub in_gamma: usize,
    /// Mean I_i of the full capture (with the setup's correction).
    pub full: f64,
    /// Mean I_i of the direct-only control (the same correction, same Γ).
    pub control: f64,
    /// Mean I_i of the indirect-only truth (no correction).
    pub truth: f64,
    /// Mean I_i of the truth with the same correction as the full capture: the part of the
    /// indirect light that arrives outside the zeroed windows.
    pub truth_gated: f64,
    /// Pearson correlation of the full capture's I_i with the truth's over the object's Γ
    /// voxels.
    pub pearson: f64,
    /// Pearson ceiling: the correlation of the truth put through the same windows with the
    /// truth itself over the object's Γ voxels. A window-based correction of the full capture
    /// can at best reproduce the windowed truth, so its Pearson cannot be expected above this.
    pub pearson_ceiling: f64,
    /// Pearson correlation of the full capture's corrected I_i with the windowed truth over
    /// the object's Γ voxels: how close the correction comes to what the windows let through.
    pub pearson_windowed: f64,
    /// Mean I_i of the oracle subtraction `H_all − H_control` with no windows (same Γ): it
    /// validates the measuring chain (≈ the truth when the renders add up).
    pub oracle: f64,
    /// Pearson correlation of the oracle's I_i with the truth's over the object's Γ voxels.
    pub pearson_oracle: f64,
}

impl ObjectRow {
    /// Full / control.
    pub fn ratio(&self) -> f64 {
        self.full / self.control
    }
    /// Full / truth.
    pub fn kept(&self) -> f64 {
        self.full / self.truth
    }
    /// Kept ceiling: the windowed truth / the truth (what a window-based correction can keep
    /// at best).
    pub fn kept_ceiling(&self) -> f64 {
        self.truth_gated / self.truth
    }
    /// Oracle / truth.
    pub fn kept_oracle(&self) -> f64 {
        self.oracle / self.truth
    }
}

/// One scene's figures under one setup.
#[derive(Clone, Debug)]
pub struct SceneResult {
    /// Γ's voxel count.
    pub gamma: usize,
    /// r0 used (m).
    pub r0: f32,
    /// Pearson correlation of the full capture's I_i with the truth's over Γ.
    pub pearson: f64,
    /// Pearson of the windowed truth with the truth over Γ (the ceiling).
    pub pearson_ceiling: f64,
    /// Pearson of the oracle subtraction's I_i with the truth's over Γ.
    pub pearson_oracle: f64,
    /// Fraction of the full capture's energy removed by the correction.
    pub explained: Option<f64>,
    /// Per object, in `scene.json` order.
    pub rows: Vec<ObjectRow>,
    /// I_i of the full capture, the control, the truth, the windowed truth and the oracle
    /// subtraction (per voxel).
    pub maps: [Vec<f32>; 5],
    /// Γ.
    pub mask: Vec<bool>,
}

/// Pearson correlation of `x` and `y` over the indices `idx`.
pub fn pearson(x: &[f32], y: &[f32], idx: &[usize]) -> f64 {
    let n = idx.len() as f64;
    if idx.len() < 2 {
        return f64::NAN;
    }
    let mx = idx.iter().map(|&i| f64::from(x[i])).sum::<f64>() / n;
    let my = idx.iter().map(|&i| f64::from(y[i])).sum::<f64>() / n;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for &i in idx {
        let (a, b) = (f64::from(x[i]) - mx, f64::from(y[i]) - my);
        sxy += a * b;
        sxx += a * a;
        syy += b * b;
    }
    sxy / (sxx * syy).sqrt()
}

fn mean(v: &[f32], idx: &[usize]) -> f64 {
    idx.iter().map(|&i| f64::from(v[i])).sum::<f64>() / idx.len() as f64
}

/// Measure one scene under `s`: Γ from the full capture's diagonal; the full capture and the
/// control with the setup's correction; the truth with none.
pub fn measure(c: &mut Captures, s: &Setup) -> SceneResult {
    let d = probe::direct(&mut c.all, &c.vol, &s.wave, EXEC).expect("direct");
    let mask = probe::gamma_mask(&d.values, s.epsilon);
    let opts = IndirectOptions {
        epsilon: s.epsilon,
        shell: s.r0.map(|r0| Shell {
            r0,
            r1: f32::INFINITY,
        }),
        leak: s.leak,
        ..IndirectOptions::default()
    };
    let f = probe::indirect_over(&mut c.all, &c.vol, &mask, &opts, &s.wave, EXEC).expect("full");
    let k =
        probe::indirect_over(&mut c.direct, &c.vol, &mask, &opts, &s.wave, EXEC).expect("control");
    let plain = IndirectOptions { leak: None, ..opts };
    let t =
        probe::indirect_over(&mut c.indirect, &c.vol, &mask, &plain, &s.wave, EXEC).expect("truth");
    let tg = probe::indirect_over(&mut c.indirect, &c.vol, &mask, &opts, &s.wave, EXEC)
        .expect("truth, corrected");
    let mut diff = subtract(&c.all, &c.direct, 1.0);
    let o = probe::indirect_over(&mut diff, &c.vol, &mask, &plain, &s.wave, EXEC)
        .expect("oracle subtraction");
    let g: Vec<usize> = (0..mask.len()).filter(|&i| mask[i]).collect();
    let rows = c
        .objects
        .iter()
        .map(|(name, idx)| {
            let ig: Vec<usize> = idx.iter().copied().filter(|&i| mask[i]).collect();
            ObjectRow {
                name: name.clone(),
                voxels: idx.len(),
                in_gamma: ig.len(),
                full: mean(&f.values, idx),
                control: mean(&k.values, idx),
                truth: mean(&t.values, idx),
                truth_gated: mean(&tg.values, idx),
                pearson: pearson(&f.values, &t.values, &ig),
                pearson_ceiling: pearson(&tg.values, &t.values, &ig),
                pearson_windowed: pearson(&f.values, &tg.values, &ig),
                oracle: mean(&o.values, idx),
                pearson_oracle: pearson(&o.values, &t.values, &ig),
            }
        })
        .collect();
    SceneResult {
        gamma: g.len(),
        r0: f.shell.r0,
        pearson: pearson(&f.values, &t.values, &g),
        pearson_ceiling: pearson(&tg.values, &t.values, &g),
        pearson_oracle: pearson(&o.values, &t.values, &g),
        explained: f.explained,
        rows,
        maps: [f.values, k.values, t.values, tg.values, o.values],
        mask,
    }
}

/// `(a − b)·scale`, bin by bin, with `a`'s geometry (the two must share it).
pub fn subtract(a: &Capture, b: &Capture, scale: f32) -> Capture {
    assert_eq!(a.geometry, b.geometry, "captures of different geometry");
    let data = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(x, y)| (x - y) * scale)
        .collect();
    Capture::new(a.geometry.clone(), data, Path::new("difference")).unwrap()
}

/// Distance (m) from each voxel of `idx` to the nearest surface point of the objects other
/// than object `k`.
pub fn distance_to_others(c: &Captures, k: usize, idx: &[usize]) -> Vec<f64> {
    idx.iter()
        .map(|&i| {
            let v = c.vol.points[i];
            c.surfaces
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != k)
                .flat_map(|(_, s)| s.iter())
                .map(|p| {
                    (0..3)
                        .map(|x| f64::from(p[x] - v[x]).powi(2))
                        .sum::<f64>()
                        .sqrt()
                })
                .fold(f64::INFINITY, f64::min)
        })
        .collect()
}

/// Monte Carlo noise of the full capture, measured from a second render with another seed.
#[derive(Clone, Debug)]
pub struct NoiseRow {
    /// Object name.
    pub name: String,
    /// Mean I_i of the noise-only capture `(H_all,seed0 − H_all,seed1)/√2` with the setup's
    /// correction (the windows of the seed-0 Γ).
    pub corrected: f64,
    /// The same without windows (the paper's Eq. 17 on the noise).
    pub plain: f64,
}

/// I_i of the noise-only capture `(c.all − other)/√2` per object: with `s`'s correction over
/// the Γ of `c.all`, and without correction. `(a − b)/√2` of two independent renders has the
/// variance of one render's noise and none of its signal.
pub fn noise(c: &mut Captures, other: &Capture, s: &Setup) -> Vec<NoiseRow> {
    let d = probe::direct(&mut c.all, &c.vol, &s.wave, EXEC).expect("direct");
    let mask = probe::gamma_mask(&d.values, s.epsilon);
    let opts = IndirectOptions {
        epsilon: s.epsilon,
        shell: s.r0.map(|r0| Shell {
            r0,
            r1: f32::INFINITY,
        }),
        leak: s.leak,
        ..IndirectOptions::default()
    };
    let mut n = subtract(&c.all, other, core::f32::consts::FRAC_1_SQRT_2);
    let f = probe::indirect_over(&mut n, &c.vol, &mask, &opts, &s.wave, EXEC).expect("noise");
    let plain = IndirectOptions { leak: None, ..opts };
    let p = probe::indirect_over(&mut n, &c.vol, &mask, &plain, &s.wave, EXEC).expect("noise");
    c.objects
        .iter()
        .map(|(name, idx)| NoiseRow {
            name: name.clone(),
            corrected: mean(&f.values, idx),
            plain: mean(&p.values, idx),
        })
        .collect()
}

/// Print one scene's result as table rows (markdown).
pub fn print(scene: &str, label: &str, r: &SceneResult) {
    for o in &r.rows {
        println!(
            "| {scene} | {label} | {} ({} voxels, {} in Γ) | {} | {:.4e} vs {:.4e}: {:.2}× | {:.3} (truth {:.4e}; the truth corrected keeps {:.3}) | {:.3} (object) / {:.3} (Γ) |",
            o.name,
            o.voxels,
            o.in_gamma,
            r.gamma,
            o.full,
            o.control,
            o.ratio(),
            o.kept(),
            o.truth,
            o.truth_gated / o.truth,
            o.pearson,
            r.pearson
        );
    }
}

/// Print one scene's ceilings and oracle (markdown rows): per object the kept ceiling (the
/// truth through the same windows / the truth), the Pearson ceiling (the windowed truth with
/// the truth), the corrected I_i's Pearson with the windowed truth, and the oracle subtraction `H_all − H_control` with no windows (kept, Pearson).
pub fn print_ceilings(scene: &str, r: &SceneResult) {
    for o in &r.rows {
        println!(
            "| {scene} | {} | {:.3} | {:.3} (Γ {:.3}) | {:.3} | {:.3} | {:.3} (Γ {:.3}) |",
            o.name,
            o.kept_ceiling(),
            o.pearson_ceiling,
            r.pearson_ceiling,
            o.pearson_windowed,
            o.kept_oracle(),
            o.pearson_oracle,
            r.pearson_oracle
        );
    }
}

/// Where the surfels of the analysis by synthesis come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Surf {
    /// Stage 1, the oracle: `scene.json`'s boxes (validates the renderer and the subtraction).
    Oracle,
    /// Stage 2, the method: the library's pipeline on each capture alone
    /// (`vltm::probe::model_of_capture`) on the image grid the library derives from the
    /// capture, as `vltm --leak-correct model` runs it (the environment's `SURFEL_VOLUME`, a
    /// volume spec or `fixed` for [`SURFEL_VOLUME`], to change it).
    Capture,
}

/// The threshold of the columns that get surfels (× the brightest; `SURFEL_EPSILON` to
/// change it).
pub fn surfel_epsilon() -> f32 {
    std::env::var("SURFEL_EPSILON")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0.1)
}

/// Sweeps of the geometry refinement.
pub const SWEEPS: usize = 4;

/// A fixed grid for the surfels of Stage 2 (`SURFEL_VOLUME=fixed`; pitch 0.05 × 0.05 × 0.01
/// m, the grid of the measurements before 2026-12-05). The library's default grid for these
/// captures spans the same x–y at the same pitch and z 0.5–2.0 m every 0.02 m.
pub const SURFEL_VOLUME: &str = "-0.75:0.75:31,-0.75:0.75:31,0.5:1.4:91";

/// One scene measured with the direct light removed by the fitted surfel model (module
/// `vltm::probe::synth`) instead of the windows: the full capture and the control each with
/// its own model, the truth uncorrected, Γ from the full capture's diagonal. Returns the
/// result and, for the full capture and the control, the energy explained and the fit's
/// seconds.
pub fn measure_synth(
    c: &mut Captures,
    s: &Setup,
    surf: Surf,
    opts: &probe::synth::SynthOptions,
) -> (SceneResult, [(f64, f64); 2]) {
    let boxes = c.boxes.clone();
    let [ma, mk]: [_; 2] = surface_models(vec![&mut c.all, &mut c.direct], &boxes, s, surf, opts)
        .try_into()
        .unwrap_or_else(|_| unreachable!());
    let r = measure_models(c, s, &ma, &mk);
    (r, [(ma.explained, ma.seconds), (mk.explained, mk.seconds)])
}

/// The surfel model of `cap`'s direct light (`surf`: the oracle geometry of `boxes`, or the
/// library's pipeline on the capture alone; `boxes` then serve only the printed diagnostics).
pub fn surface_model(
    cap: &mut Capture,
    boxes: &[serde_json::Value],
    s: &Setup,
    surf: Surf,
    opts: &probe::synth::SynthOptions,
) -> probe::synth::SynthModel {
    use probe::synth::{Surfels, SynthModel};
    let spec = std::env::var("SURFEL_VOLUME").unwrap_or_else(|_| "default".to_string());
    let fine = if spec == "default" || spec == "fixed" {
        Volume::parse(SURFEL_VOLUME).expect("SURFEL_VOLUME")
    } else {
        Volume::parse(&spec).expect("SURFEL_VOLUME")
    };
    let sub: usize = std::env::var("SURFEL_SUB")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(5);
    let fit = |cap: &mut Capture, surfels: Surfels| {
        SynthModel::fit(cap, surfels, opts, EXEC).expect("fit")
    };
    match surf {
        Surf::Oracle => fit(cap, c_boxes_surfels(boxes, 100.0)),
        Surf::Capture => {
            let wave = Wave {
                wavelength: std::env::var("SURFEL_LAMBDA")
                    .ok()
                    .and_then(|v| v.parse().ok())
                    .or_else(|| probe::synth::geometry_wavelength(&cap.geometry)),
                sigma: None,
                ..s.wave
            };
            if std::env::var("SURFEL_METHOD").is_ok_and(|m| m == "patches") {
                let d = probe::direct(cap, &fine, &wave, EXEC).expect("direct, fine");
                let raw = Surfels::from_direct(&fine, &d.values, surfel_epsilon(), sub, 0.0)
                    .expect("surfels");
                let g = &cap.geometry;
                let scale: Vec<f64> = (0..g.lasers.len()).map(|l| g.laser_falloff_at(l)).collect();
                let r =
                    probe::synth::refine(cap, &raw, &scale, SWEEPS, 0.02, EXEC).expect("refine");
                eprintln!(
                    "refined {} patches ({} kept): explained {:.4} -> {:.4}",
                    raw.patches.len(),
                    r.surfels.patches.len(),
                    r.before,
                    r.after
                );
                return fit(cap, r.surfels);
            }
            // The library's pipeline (`probe::model_of_capture`) on the grid it derives from
            // the capture (what `vltm --leak-correct model` runs), or the environment's
            // (`SURFEL_VOLUME=fixed`: [`SURFEL_VOLUME`]).
            let mopts = probe::ModelOptions {
                volume: (spec != "default").then(|| fine.clone()),
                wavelength: wave.wavelength,
                epsilon: surfel_epsilon(),
                sub,
                per_facet: !std::env::var("FACET_CLUSTERS").is_ok_and(|m| m == "source"),
                fit: *opts,
                min_explained: 0.0,
                ..probe::ModelOptions::default()
            };
            let m =
                match probe::model_of_capture(cap, &s.wave, &mopts, EXEC).expect("surface model") {
                    probe::ModelOutcome::Fitted(m) => m,
                    probe::ModelOutcome::Unexplained { reason, .. } => {
                        panic!("surface model: {reason}")
                    }
                };
            for f in &m.initial {
                let (ang, off) = facet_error(boxes, f);
                eprintln!(
                    "  initial facet of cluster {}: normal {:.3?} extent {:.3?}: {ang:.1}°, {:.1} mm off the nearest face",
                    f.cluster,
                    f.normal,
                    f.extent,
                    off * 1e3
                );
            }
            let r = &m.facets;
            eprintln!(
                "refined {} facets (+{} grown) in {} sweeps; the pipeline took {:.1} s: explained {:.4} -> {:.4} (subset), {:.4} (fit); image grid {:?} {:?}",
                m.initial.len(),
                r.grown,
                r.sweeps,
                m.seconds,
                r.before,
                r.after,
                m.explained,
                m.volume.shape,
                m.volume.axes
            );
            for (f, a) in r.facets.iter().zip(&r.amplitudes) {
                eprintln!(
                    "  facet of cluster {}: centre {:.3?} normal {:.3?} extent {:.3?} area {:.3} amp {:.2}: {:.1}°, {:.1} mm",
                    f.cluster,
                    f.centre,
                    f.normal,
                    f.extent,
                    f.area(),
                    a,
                    facet_error(boxes, f).0,
                    facet_error(boxes, f).1 * 1e3
                );
            }
            m.model
        }
    }
}

/// [`measure_synth`] with the models given: `ma` fitted to `c.all`, `mk` to `c.direct` (Γ
/// from `c.all`'s diagonal, the truth uncorrected).
pub fn measure_models(
    c: &mut Captures,
    s: &Setup,
    ma: &probe::synth::SynthModel,
    mk: &probe::synth::SynthModel,
) -> SceneResult {
    use probe::synth::Synthesized;
    let d = probe::direct(&mut c.all, &c.vol, &s.wave, EXEC).expect("direct");
    let mask = probe::gamma_mask(&d.values, s.epsilon);
    let opts_i = s.uncorrected();
    let f = probe::indirect_over(
        &mut Synthesized::new(&mut c.all, ma),
        &c.vol,
        &mask,
        &opts_i,
        &s.wave,
        EXEC,
    )
    .expect("full");
    let k = probe::indirect_over(
        &mut Synthesized::new(&mut c.direct, mk),
        &c.vol,
        &mask,
        &opts_i,
        &s.wave,
        EXEC,
    )
    .expect("control");
    let t = probe::indirect_over(&mut c.indirect, &c.vol, &mask, &opts_i, &s.wave, EXEC)
        .expect("truth");
    let g: Vec<usize> = (0..mask.len()).filter(|&i| mask[i]).collect();
    let nan = vec![f32::NAN; mask.len()];
    let rows = c
        .objects
        .iter()
        .map(|(name, idx)| {
            let ig: Vec<usize> = idx.iter().copied().filter(|&i| mask[i]).collect();
            ObjectRow {
                name: name.clone(),
                voxels: idx.len(),
                in_gamma: ig.len(),
                full: mean(&f.values, idx),
                control: mean(&k.values, idx),
                truth: mean(&t.values, idx),
                truth_gated: f64::NAN,
                pearson: pearson(&f.values, &t.values, &ig),
                pearson_ceiling: f64::NAN,
                pearson_windowed: f64::NAN,
                oracle: f64::NAN,
                pearson_oracle: f64::NAN,
            }
        })
        .collect();
    SceneResult {
        gamma: g.len(),
        r0: f.shell.r0,
        pearson: pearson(&f.values, &t.values, &g),
        pearson_ceiling: f64::NAN,
        pearson_oracle: f64::NAN,
        explained: Some(ma.explained),
        rows,
        maps: [f.values, k.values, t.values, nan.clone(), nan],
        mask,
    }
}
