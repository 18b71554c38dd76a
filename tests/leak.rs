//! Leak-corrected in-focus indirect light (`vltm::probe::DirectModel`, `--leak-correct`)
//! against the direct-only control, as means over the lit object's voxels (its surface ± one
//! voxel), on two scenes with the same settings:
//!
//! * the path-traced `two_patches` / `two_patches_direct_only` (mitransient, tal HDF5,
//!   8×8 lasers × 8×8 SPADs): patch B, lit by patch A;
//! * a panel lighting a figure (the demo's scene at 16×16 lasers × 16×16 SPADs), rendered in
//!   the test by the simulator twice (all paths / direct only);
//! * the path-traced scenes of `fixtures/pathtraced` (mitransient: all paths, direct only and
//!   the indirect-only truth, same seed), every object against its control and the truth
//!   (`kept`, Pearson), at vltm indirect's defaults (`support/pathtraced.rs`).
//! * the simulator's two patches (`fixtures/two_patches*.npz`, 16 point samples each), where
//!   the surface model (`--leak-correct model`) leaves direct light the windows do not.
//!
//! Settings, the same on both: λ = twice the aperture pitch (the default), σ = 2λ/3 (default),
//! the paper's 1/d lens weights, Γ = {I_d > 0.1·max} from the full capture's diagonal, r0 =
//! 1.5σ (default), the fit's defaults ([`LeakOptions::default`]). The control gets the same
//! correction (its own fit over the same Γ). Measured values are printed (`--nocapture`).

mod support;

use std::path::PathBuf;
use support::mean_over as mean;
use vltm::io::{self, Capture};
use vltm::kernel::Point;
use vltm::probe::{self, Exec, IndirectOptions, LeakMethod, LeakOptions, Shell, Wave};
use vltm::sim::{Aperture, Bounces, Cuboid, Patch, Scene, Setup};
use vltm::volume::Volume;

const EXEC: Exec<'static> = Exec {
    progress: None,
    path: vltm::probe::EvalPath::Auto,
};

/// `fixtures/ytal/<capture>/<file>`, checked (`support::fixture`).
fn ytal(capture: &str, file: &str) -> PathBuf {
    support::fixture(&format!("ytal/{capture}/{file}"))
}

/// Points on the quadrilateral with corners `c` (in order), `n × n` cell centres.
fn quad(c: [[f64; 3]; 4], n: usize) -> Vec<Point> {
    let mut out = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (u, v) = ((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
            let p: [f64; 3] = core::array::from_fn(|k| {
                (1.0 - u) * (1.0 - v) * c[0][k]
                    + u * (1.0 - v) * c[1][k]
                    + u * v * c[2][k]
                    + (1.0 - u) * v * c[3][k]
            });
            out.push(p.map(|x| x as f32));
        }
    }
    out
}

/// Patch B of the path-traced two_patches scene (`fixtures/ytal`) (corners from its `scene.json`).
fn patch_b() -> Vec<Point> {
    let path = ytal("two_patches", "scene.json");
    let text = std::fs::read_to_string(&path).unwrap();
    let j: serde_json::Value = serde_json::from_str(&text).unwrap();
    let corners = &j["objects"]["patch_B"]["corners"];
    let c: [[f64; 3]; 4] =
        core::array::from_fn(|i| core::array::from_fn(|k| corners[i][k].as_f64().unwrap()));
    quad(c, 40)
}

/// Probe settings of one measurement: σ (None = 2λ/3), ε, r0 (None = 1.5σ).
#[derive(Clone, Copy, Debug)]
struct Settings {
    sigma: Option<f64>,
    epsilon: f32,
    r0: Option<f32>,
}

/// vltm's defaults: σ = 2λ/3, ε = 0.1, r0 = 1.5σ.
const DEFAULTS: Settings = Settings {
    sigma: None,
    epsilon: 0.1,
    r0: None,
};

/// The paper's: σ such that 99 % of the Gaussian envelope lies within 4λ (±2.576σ = ±2λ),
/// a small threshold ε = 0.01, no minimum separation (only a ≠ b).
fn paper(lambda: f64) -> Settings {
    Settings {
        sigma: Some(2.0 * lambda / 2.5758),
        epsilon: 0.01,
        r0: Some(0.0),
    }
}

/// Object-voxel means of I_i on the full capture, the control (same Γ, from the full
/// capture's diagonal, the same correction) and the indirect-only truth `H − H_control`
/// (uncorrected).
struct Means {
    full: f64,
    control: f64,
    truth: f64,
    gamma: usize,
}

impl Means {
    fn ratio(&self) -> f64 {
        self.full / self.control
    }
    /// The corrected full capture's I_i as a fraction of the indirect-only truth.
    fn kept(&self) -> f64 {
        self.full / self.truth
    }
}

fn measure(
    full: &mut Capture,
    control: &mut Capture,
    vol: &Volume,
    wave: &Wave,
    set: Settings,
    object: &[usize],
    leak: Option<LeakOptions>,
) -> Means {
    let wave = Wave {
        sigma: set.sigma,
        ..*wave
    };
    let d = probe::direct(full, vol, &wave, EXEC).expect("direct");
    let gamma = probe::gamma_mask(&d.values, set.epsilon);
    let opts = IndirectOptions {
        epsilon: set.epsilon,
        shell: set.r0.map(|r0| Shell {
            r0,
            r1: f32::INFINITY,
        }),
        leak,
        ..IndirectOptions::default()
    };
    let f = probe::indirect_over(full, vol, &gamma, &opts, &wave, EXEC).expect("indirect");
    let c = probe::indirect_over(control, vol, &gamma, &opts, &wave, EXEC).expect("indirect");
    let mut diff = full.clone();
    diff.data
        .iter_mut()
        .zip(&control.data)
        .for_each(|(a, b)| *a -= b);
    let plain = IndirectOptions { leak: None, ..opts };
    let t = probe::indirect_over(&mut diff, vol, &gamma, &plain, &wave, EXEC).expect("indirect");
    let m = Means {
        full: mean(&f.values, object),
        control: mean(&c.values, object),
        truth: mean(&t.values, object),
        gamma: gamma.iter().filter(|&&g| g).count(),
    };
    println!(
        "{set:?}, leak {leak:?}: Γ {} voxels, r0 {:.3} m; I_i mean over the object's {} voxels \
         {:.4e} vs control {:.4e}: {:.2}x; indirect-only truth {:.4e} (kept {:.2})",
        m.gamma,
        f.shell.r0,
        object.len(),
        m.full,
        m.control,
        m.ratio(),
        m.truth,
        m.kept()
    );
    m
}

/// `x` within `tol` (relative) of the documented value `want` (docs/indirect-light.md).
fn near(what: &str, x: f64, want: f64, tol: f64) {
    assert!(
        (x - want).abs() <= tol * want.abs(),
        "{what}: measured {x:.3}, documented {want} (±{:.0} %)",
        100.0 * tol
    );
}

fn check_corrected(name: &str, m: &Means) {
    assert!(
        m.full > 0.0 && m.full >= 2.0 * m.control,
        "{name}: leak-corrected I_i {:.4e} is not 2x the control {:.4e}",
        m.full,
        m.control
    );
    assert!(
        (0.4..=1.2).contains(&m.kept()),
        "{name}: leak-corrected I_i keeps {:.2} of the indirect-only truth (want 0.4–1.2)",
        m.kept()
    );
}

fn two_patches() -> (Capture, Capture, Volume, Vec<usize>) {
    let vol = Volume::parse("-0.75:0.75:16,-0.75:0.75:16,0.4:1.35:20").unwrap();
    let b = vol.surface_voxels(&patch_b());
    let open = |n: &str| io::open(&ytal(n, &format!("{n}.hdf5"))).unwrap();
    (open("two_patches"), open("two_patches_direct_only"), vol, b)
}

/// The path-traced two_patches of `fixtures/ytal` (the capture holds the physical laser's falloff, so
/// `--compensate-laser`): patch B's voxels. docs/indirect-light.md.
#[test]
fn two_patches_leak_corrected_beats_the_control() {
    let (mut full, mut ctrl, vol, b) = two_patches();
    let wave = Wave {
        compensate_laser: true,
        ..Wave::default()
    };
    let plain = measure(&mut full, &mut ctrl, &vol, &wave, DEFAULTS, &b, None);
    near("two_patches, Eq. 17 vs control", plain.ratio(), 0.92, 0.05);
    // Uncorrected, I_i is direct light: ~100x the indirect-only truth (docs/indirect-light.md).
    near("two_patches, Eq. 17 / truth", plain.kept(), 103.0, 0.1);
    let gated = measure(
        &mut full,
        &mut ctrl,
        &vol,
        &wave,
        DEFAULTS,
        &b,
        Some(LeakOptions::default()),
    );
    check_corrected("two_patches, gate", &gated);
    near("two_patches, gate, kept", gated.kept(), 0.56, 0.1);
    // The model fit works here (voxel pitch ≤ λ/4): documented 3.79x.
    let fit = LeakOptions {
        method: LeakMethod::Fit,
        ..LeakOptions::default()
    };
    let fitted = measure(&mut full, &mut ctrl, &vol, &wave, DEFAULTS, &b, Some(fit));
    near("two_patches, fit vs control", fitted.ratio(), 3.79, 0.15);
    near("two_patches, fit, kept", fitted.kept(), 1.18, 0.15);
    // The paper's settings.
    let lambda = probe::default_wavelength(&full.geometry);
    let pp = measure(&mut full, &mut ctrl, &vol, &wave, paper(lambda), &b, None);
    let pc = measure(
        &mut full,
        &mut ctrl,
        &vol,
        &wave,
        paper(lambda),
        &b,
        Some(LeakOptions::default()),
    );
    near(
        "two_patches, paper's, Eq. 17 vs control",
        pp.ratio(),
        0.99,
        0.05,
    );
    near(
        "two_patches, paper's, Eq. 17 / truth",
        pp.kept(),
        2564.0,
        0.1,
    );
    assert!(
        pc.full >= 2.0 * pc.control,
        "paper's settings, corrected: {:.2}x",
        pc.ratio()
    );
    // The paper's settings keep less of the indirect light than vltm's defaults (docs/indirect-light.md).
    near("two_patches, paper's, kept", pc.kept(), 0.10, 0.3);
    assert!(pc.kept() < gated.kept());
}

/// The panel/figure scene of `vltm demo` at 16×16 lasers × 16×16 SPADs.
fn panel_scene(bounces: Bounces) -> Scene {
    let grid = || Aperture::grid([16, 16], [1.0, 1.0], [0.0, 0.0]);
    let mut setup = Setup::new(grid(), grid(), 300, 0.01);
    setup.t0 = 1.0;
    let mut panel = Patch::new("panel", [-0.35, 0.0, 0.8], [1.0, 0.0, -1.0], [0.3, 0.3]);
    panel.samples = 6;
    let mut figure = Patch::new("figure", [0.35, 0.0, 0.8], [-1.0, 0.0, -1.0], [0.14, 0.34]);
    figure.samples = 5;
    let mut distractor = Cuboid::new("box", [0.0, -0.3, 1.1], [0.15, 0.15, 0.15]);
    distractor.samples = 2;
    let mut s = Scene::new(setup).with(panel).with(figure).with(distractor);
    s.bounces = bounces;
    s.pulse_sigma = Some(0.01);
    s
}

fn figure_surface() -> Vec<Point> {
    let mut f = Patch::new("figure", [0.35, 0.0, 0.8], [-1.0, 0.0, -1.0], [0.14, 0.34]);
    f.samples = 40;
    let s = Scene::new(Setup::new(
        Aperture::grid([1, 1], [0.0, 0.0], [0.0, 0.0]),
        Aperture::grid([1, 1], [0.0, 0.0], [0.0, 0.0]),
        1,
        0.01,
    ))
    .with(f);
    s.sample_points()
        .iter()
        .map(|p| p.position.map(|x| x as f32))
        .collect()
}

/// The demo's panel/figure scene at 16×16 lasers × 16×16 SPADs (65 536 histograms), rendered
/// twice: the figure's voxels. docs/indirect-light.md.
#[test]
fn panel_figure_16_leak_corrected_beats_the_control() {
    let vol = Volume::grid([-0.6, -0.3, 0.5], [0.6, 0.3, 1.22], [21, 11, 13]).unwrap();
    let fig = vol.surface_voxels(&figure_surface());
    let mut full = panel_scene(Bounces::All).render().unwrap();
    let mut ctrl = panel_scene(Bounces::Direct).render().unwrap();
    let wave = Wave::default();
    let plain = measure(&mut full, &mut ctrl, &vol, &wave, DEFAULTS, &fig, None);
    near("panel/figure, Eq. 17 vs control", plain.ratio(), 1.01, 0.05);
    near("panel/figure, Eq. 17 / truth", plain.kept(), 127.5, 0.1);
    let gated = measure(
        &mut full,
        &mut ctrl,
        &vol,
        &wave,
        DEFAULTS,
        &fig,
        Some(LeakOptions::default()),
    );
    check_corrected("panel/figure, gate", &gated);
    near("panel/figure, gate vs control", gated.ratio(), 313.0, 0.2);
    near("panel/figure, gate, kept", gated.kept(), 0.53, 0.1);
    // The model fit does not separate here: the 6 cm voxels are 0.45λ (documented 1.01x).
    let fit = LeakOptions {
        method: LeakMethod::Fit,
        ..LeakOptions::default()
    };
    let fitted = measure(&mut full, &mut ctrl, &vol, &wave, DEFAULTS, &fig, Some(fit));
    near("panel/figure, fit vs control", fitted.ratio(), 1.01, 0.05);
    let lambda = probe::default_wavelength(&full.geometry);
    let pp = measure(&mut full, &mut ctrl, &vol, &wave, paper(lambda), &fig, None);
    let pc = measure(
        &mut full,
        &mut ctrl,
        &vol,
        &wave,
        paper(lambda),
        &fig,
        Some(LeakOptions::default()),
    );
    near(
        "panel/figure, paper's, Eq. 17 vs control",
        pp.ratio(),
        1.00,
        0.05,
    );
    near(
        "panel/figure, paper's, Eq. 17 / truth",
        pp.kept(),
        1101.0,
        0.1,
    );
    assert!(
        pc.full >= 2.0 * pc.control,
        "paper's settings, corrected: {:.2}x",
        pc.ratio()
    );
    near("panel/figure, paper's, kept", pc.kept(), 0.19, 0.2);
    assert!(pc.kept() < gated.kept());
}

/// `--leak-correct` with nothing to correct: an empty Γ, or voxels whose direct returns all
/// fall outside the capture's window, is an error naming the option, never an all-zero result.
#[test]
fn leak_correct_without_direct_returns_is_an_error() {
    let (mut full, _, vol, _) = two_patches();
    let wave = Wave {
        compensate_laser: true,
        ..Wave::default()
    };
    let opts = IndirectOptions {
        leak: Some(LeakOptions::default()),
        ..IndirectOptions::default()
    };
    let none = vec![false; vol.len()];
    let e = probe::indirect_over(&mut full, &vol, &none, &opts, &wave, EXEC).unwrap_err();
    assert!(e.to_string().contains("argument `leak_correct`"), "{e}");
    // 3-vertex paths of a voxel 4 m deep are longer than the 5 m window.
    for method in [LeakMethod::Gate, LeakMethod::Fit] {
        let lo = LeakOptions {
            method,
            ..LeakOptions::default()
        };
        let e = probe::DirectModel::fit(&mut full, &[[0.0, 0.0, 4.0]], 0.05, &wave, &lo, EXEC)
            .unwrap_err();
        assert!(
            e.to_string().contains("argument `leak_correct`") && e.to_string().contains("window"),
            "{e}"
        );
    }
    // A capture with no light at the direct returns of patch B's voxel (all zero): refused,
    // never an all-zero correction.
    let mut dark = full.clone();
    dark.data.iter_mut().for_each(|x| *x = 0.0);
    for method in [LeakMethod::Gate, LeakMethod::Fit] {
        let lo = LeakOptions {
            method,
            ..LeakOptions::default()
        };
        let e = probe::DirectModel::fit(&mut dark, &[[0.45, 0.0, 0.8]], 0.05, &wave, &lo, EXEC)
            .unwrap_err();
        assert!(
            e.to_string().contains("argument `leak_correct`") && e.to_string().contains("no light"),
            "{method:?}: {e}"
        );
    }
}

#[path = "support/pathtraced.rs"]
mod pathtraced;

/// `vltm column` at its defaults on the path-traced panel + figure
/// (`fixtures/pathtraced/panel_figure_all`), focused in front of the panel (the projector's
/// own surface): the leak correction is on by default and the column peaks on the lit figure
/// (its surface ± one voxel, from `scene.json`), not beside x_a. With `--no-leak-correct` the
/// panel's own direct light passes the gate and the column peaks beside x_a, between it and
/// the wall, on the panel's side (the test's teeth). Measured: peaks at (0.15, −0.05, 0.85) m
/// and (0.15, −0.05, 0.90) m corrected; (−0.45, −0.05, 0.55) m and (−0.35, −0.05, 0.50) m
/// (0.21 and 0.36 m from x_a) as they are.
#[test]
fn pathtraced_column_at_the_defaults_peaks_on_the_lit_figure() {
    let c = pathtraced::load("panel_figure");
    let voxels = |name: &str| {
        c.objects
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.clone())
            .unwrap_or_else(|| panic!("no {name} in scene.json"))
    };
    let figure = voxels("figure");
    let capture = pathtraced::dir().join("panel_figure_all/panel_figure_all.hdf5");
    let dir = std::env::temp_dir().join(format!("vltm-leak-column-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let column = |focus: &str, extra: &[&str]| -> (usize, String) {
        let out = dir.join("c.npy");
        let o = std::process::Command::new(support::vltm_bin())
            .arg("column")
            .arg(&capture)
            .args(["--focus", focus, "--volume", pathtraced::VOLUME])
            .args(extra)
            .arg("--out")
            .arg(&out)
            .output()
            .expect("run vltm");
        let text = String::from_utf8_lossy(&o.stdout).into_owned();
        assert!(
            o.status.success(),
            "{text}{}",
            String::from_utf8_lossy(&o.stderr)
        );
        let (v, _) = vltm::export::npy::read_f32(&out).expect("column.npy");
        let peak = (0..v.len()).fold(0, |b, i| if v[i] > v[b] { i } else { b });
        (peak, text)
    };
    for focus in ["-0.5,0,0.75", "-0.29,0,0.85"] {
        let a = vltm::volume::parse_point("focus", focus).expect("focus");
        let (peak, text) = column(focus, &[]);
        let p = c.vol.points[peak];
        println!("column --focus {focus}: peak at {p:?}");
        assert!(text.contains("leak correction"), "{text}");
        assert!(
            figure.contains(&peak),
            "column --focus {focus} at the defaults peaks at {p:?}, not on the lit figure:\n{text}"
        );
        let (raw, _) = column(focus, &["--no-leak-correct"]);
        let q = c.vol.points[raw];
        let d = (0..3).map(|k| (q[k] - a[k]).powi(2)).sum::<f32>().sqrt();
        println!("column --focus {focus} --no-leak-correct: peak at {q:?}, {d:.2} m from x_a");
        assert!(
            !figure.contains(&raw) && d < 0.4 && q[0] < 0.0,
            "uncorrected column --focus {focus} peaks at {q:?}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// One object's documented figures at vltm's defaults on a path-traced scene
/// (docs/indirect-light.md, `cargo bench --bench pathtraced`): ratio to the direct-only
/// control, kept (fraction of the indirect-only truth), Pearson with the truth over the
/// object's Γ voxels, and the ceilings of a window-based correction: the truth put through the
/// same windows, its kept and its Pearson with the truth.
struct Documented {
    object: &'static str,
    ratio: f64,
    kept: f64,
    pearson: f64,
    kept_ceiling: f64,
    pearson_ceiling: f64,
}

fn check_pathtraced(scene: &str, want: &[Documented], pearson_gamma: f64) {
    let mut c = pathtraced::load(scene);
    let r = pathtraced::measure(&mut c, &pathtraced::defaults());
    pathtraced::print(scene, "defaults", &r);
    for w in want {
        let o = r.rows.iter().find(|o| o.name == w.object).unwrap();
        let what = format!("{scene}/{}", w.object);
        assert!(
            o.full > 0.0 && o.control > 0.0 && o.truth > 0.0,
            "{what}: {o:?}"
        );
        near(
            &format!("{what}, corrected vs control"),
            o.ratio(),
            w.ratio,
            0.25,
        );
        near(&format!("{what}, kept"), o.kept(), w.kept, 0.15);
        assert!(
            (o.pearson - w.pearson).abs() <= 0.05,
            "{what}: Pearson with the truth {:.3}, documented {}",
            o.pearson,
            w.pearson
        );
        // What survives of the truth through the windows (the ceilings of any window-based
        // correction): a fraction of it, and a pattern that correlates only so well with it.
        assert!(o.truth_gated <= o.truth, "{what}: {o:?}");
        near(
            &format!("{what}, kept ceiling (the truth through the windows)"),
            o.kept_ceiling(),
            w.kept_ceiling,
            0.15,
        );
        assert!(
            (o.pearson_ceiling - w.pearson_ceiling).abs() <= 0.05,
            "{what}: Pearson ceiling (windowed truth vs truth) {:.3}, documented {}",
            o.pearson_ceiling,
            w.pearson_ceiling
        );
        // The correction reproduces what the windows let through of the truth: the gap to
        // the truth is the windows', not a residual of direct light.
        assert!(
            o.pearson_windowed >= 0.9,
            "{what}: Pearson of the corrected I_i with the windowed truth {:.3}",
            o.pearson_windowed
        );
        // The oracle subtraction H_all − H_control with no windows validates the measuring
        // chain: it is the truth plus the light of three or more bounces (a few %).
        assert!(
            (0.95..=1.15).contains(&o.kept_oracle()) && o.pearson_oracle >= 0.98,
            "{what}: oracle subtraction keeps {:.3} of the truth, Pearson {:.3}",
            o.kept_oracle(),
            o.pearson_oracle
        );
    }
    assert!(
        (r.pearson - pearson_gamma).abs() <= 0.05,
        "{scene}: Pearson over Γ {:.3}, documented {pearson_gamma}",
        r.pearson
    );
    assert!(r.pearson_oracle >= 0.98, "{scene}: {:.3}", r.pearson_oracle);
}

/// The path-traced panel/figure scene (fixtures/pathtraced, like the paper's Fig. 5): at vltm's
/// defaults the figure is ≥ 20× and the projector's own panel ≥ 3× its direct-only control,
/// but only a quarter to a third of the indirect-only truth survives the windows.
#[test]
fn pathtraced_panel_figure_at_the_defaults() {
    check_pathtraced(
        "panel_figure",
        &[
            Documented {
                object: "figure",
                ratio: 21.6,
                kept: 0.249,
                pearson: 0.803,
                kept_ceiling: 0.179,
                pearson_ceiling: 0.893,
            },
            Documented {
                object: "panel",
                ratio: 8.09,
                kept: 0.338,
                pearson: 0.858,
                kept_ceiling: 0.198,
                pearson_ceiling: 0.954,
            },
        ],
        0.831,
    );
}

/// The path-traced corner (fixtures/pathtraced: two panels at 90°, each lighting the other,
/// the projector's foci on the left one): ≥ 19× the control on both, but kept ≤ 0.25 and the
/// Pearson correlation with the truth only 0.4–0.6 (docs/indirect-light.md). The truth itself
/// through the same windows correlates with the truth at only 0.67: no window-based
/// correction reaches Pearson 0.8 on this scene.
#[test]
fn pathtraced_corner_at_the_defaults() {
    check_pathtraced(
        "corner",
        &[
            Documented {
                object: "left",
                ratio: 19.15,
                kept: 0.182,
                pearson: 0.408,
                kept_ceiling: 0.139,
                pearson_ceiling: 0.678,
            },
            Documented {
                object: "right",
                ratio: 28.13,
                kept: 0.246,
                pearson: 0.629,
                kept_ceiling: 0.131,
                pearson_ceiling: 0.674,
            },
        ],
        0.480,
    );
}

/// `--leak-correct auto` on the path-traced scenes (docs/indirect-light.md): the energy the
/// windows leave lies mostly next to them (measured 0.75 on panel/figure, 0.77 on the corner;
/// 0.07 on the simulator's two patches, `tests/cli.rs`), so auto tries the surface model. On
/// panel/figure it is used, and the run writes what `--leak-correct model` writes; on the
/// corner it explains 95.4 % of the capture, below the 99 % rule, so auto falls back with one
/// warning line and writes what `--leak-correct gate` writes.
#[test]
fn leak_correct_auto_tries_the_model_on_extended_surfaces() {
    let dir = std::env::temp_dir().join(format!("vltm-leak-auto-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let run = |scene: &str, method: &str| -> (String, String, Vec<f32>) {
        let capture = pathtraced::dir().join(format!("{scene}_all/{scene}_all.hdf5"));
        let out = dir.join(format!("{scene}-{method}.npy"));
        let o = std::process::Command::new(support::vltm_bin())
            .arg("indirect")
            .arg(&capture)
            .args(["--volume", pathtraced::VOLUME, "--leak-correct", method])
            .args(["--progress", "none", "--out"])
            .arg(&out)
            .output()
            .expect("run vltm");
        let (text, err) = (
            String::from_utf8_lossy(&o.stdout).into_owned(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        );
        assert!(o.status.success(), "{scene} {method}: {text}{err}");
        let (v, _) = vltm::export::npy::read_f32(&out).expect("indirect.npy");
        (text, err, v)
    };
    let (out, err, auto) = run("panel_figure", "auto");
    println!("{out}");
    assert!(
        (0.6..=0.9).contains(&support::cmd::auto_adjacency(&out)),
        "{out}"
    );
    assert!(out.contains("trying the surface model"), "{out}");
    assert!(
        out.contains("the surface model (") && err.is_empty(),
        "{out}{err}"
    );
    let (_, _, model) = run("panel_figure", "model");
    assert_eq!(auto, model, "auto is the model on panel/figure");
    let (out, err, auto) = run("corner", "auto");
    println!("{out}{err}");
    assert!(
        (0.6..=0.9).contains(&support::cmd::auto_adjacency(&out)),
        "{out}"
    );
    assert!(
        err.lines().count() == 1 && err.contains("(< 99 %); using the time windows"),
        "{err}"
    );
    let (_, _, gate) = run("corner", "gate");
    assert_eq!(auto, gate, "the corner's model falls back to the windows");
    std::fs::remove_dir_all(&dir).ok();
}

/// Analysis by synthesis, **Stage 1: the oracle** (geometry from `scene.json`, labelled so; it
/// validates the renderer, the fit and the subtraction, not the method): on both path-traced
/// scenes with the same settings, the direct light of every box face rendered from surfels
/// every centimetre (`vltm::probe::synth`), fitted to each capture (reflectance per object,
/// delay, response width, per-histogram gains and delays) and subtracted; the control fitted
/// with its own model. Every object keeps ≥ 100× its control and correlates at ≥ 0.98 with the
/// indirect-only truth. `kept` may exceed 1: the capture of all paths also holds the light of
/// three and more hidden vertices, which the truth (two hidden vertices) does not (2.8 % of the
/// corner's energy); measured 0.99–1.07 on panel/figure, 1.18–1.23 on the corner.
#[test]
fn synthesis_with_the_oracle_geometry_keeps_the_indirect_light() {
    use pathtraced::{SCENES, Surf, defaults, load, measure_synth};
    for scene in SCENES {
        let mut c = load(scene);
        let (r, e) = measure_synth(
            &mut c,
            &defaults(),
            Surf::Oracle,
            &probe::synth::SynthOptions::default(),
        );
        assert!(
            e[1].0 > 0.99,
            "{scene}: the control's model explains {}",
            e[1].0
        );
        for o in &r.rows {
            let what = format!(
                "{scene}/{}: {:.1}× the control, kept {:.3}, Pearson {:.3}",
                o.name,
                o.ratio(),
                o.kept(),
                o.pearson
            );
            assert!(o.ratio() >= 100.0, "{what}");
            assert!((0.95..=1.3).contains(&o.kept()), "{what}");
            assert!(o.pearson >= 0.98, "{what}");
        }
        assert!(r.pearson >= 0.98, "{scene}: Pearson over Γ {}", r.pearson);
    }
}

/// Stage 2 of the analysis by synthesis on `panel_figure`, geometry from the capture alone
/// (`vltm::probe::synth`: planes read from a direct-light image at half the wall's pitch,
/// rectangles refined and grown against the capture, then the model fitted and subtracted;
/// the control with its own model, Γ from the full capture's diagonal), on the seed-0 capture
/// and on its seed-1 re-render (`fixtures/pathtraced/seed1`, whose Monte Carlo noise the
/// truth does not share; the control, its model and the truth stay seed 0), with the noise
/// share: the `I_i` of `((H0 − M0) − (H1 − M1))/√2` as a share of the corrected `I_i`.
/// Every model explains ≥ 0.99 of its capture's energy; the measured figures are beside the
/// bands. The corner, whose direct-light image does not show the two panels' planes, is not asserted
/// (docs/indirect-light.md, Stage 2).
#[test]
fn synthesis_with_the_capture_geometry_keeps_the_indirect_light_on_panel_figure() {
    use pathtraced::{
        Surf, defaults, load, measure_models, seed1_path, surface_models, synth_seed_one,
    };
    let t0 = std::time::Instant::now();
    let (s, opts) = (defaults(), probe::synth::SynthOptions::default());
    let mut c = load("panel_figure");
    let boxes = c.boxes.clone();
    // The three models (seed 0, its control, seed 1) fitted at once, in threads of their own;
    // the control's serves both seeds.
    let mut other = io::open(&seed1_path("panel_figure")).expect("seed-1 capture");
    let models = surface_models(
        vec![&mut c.all, &mut c.direct, &mut other],
        &boxes,
        &s,
        Surf::Capture,
        &opts,
    );
    let [ma, mk, m1]: [_; 3] = models.try_into().unwrap_or_else(|_| unreachable!());
    eprintln!("models fitted after {:.0} s", t0.elapsed().as_secs_f64());
    let r = measure_models(&mut c, &s, &ma, &mk);
    assert!(
        ma.explained >= 0.99 && mk.explained >= 0.99,
        "the models explain {} (full) and {} (control)",
        ma.explained,
        mk.explained
    );
    for o in &r.rows {
        let what = format!(
            "seed 0, {}: {:.1}× the control, kept {:.3}, Pearson {:.3}",
            o.name,
            o.ratio(),
            o.kept(),
            o.pearson
        );
        eprintln!("{what}");
        // Measured (2026-12-05, the library's image grid on the phasor path from every second
        // laser row and column, the refinement on a subset of 16 × 16 laser rows × SPADs, its
        // Levenberg–Marquardt step on the moves' renders): figure 83.6×, kept 0.886, Pearson
        // 0.989; panel 89.4×, kept 0.940, Pearson 0.994 (the image from every laser spot:
        // 78.1×, 0.866, 0.987; 88.6×, 0.922, 0.993; on all 64 × 64 histograms and a fixed grid:
        // figure 89.6×, 0.892, 0.991; panel 68.6×, 0.952, 0.993).
        assert!(o.ratio() >= 60.0, "{what}");
        assert!((0.85..=1.1).contains(&o.kept()), "{what}");
        assert!(o.pearson >= 0.98, "{what}");
    }
    eprintln!(
        "seed 0: all of Γ: Pearson {:.3}; explained {:.4} / {:.4}",
        r.pearson, ma.explained, mk.explained
    );
    // Measured 0.992.
    assert!(r.pearson >= 0.98, "Pearson over Γ {}", r.pearson);
    eprintln!("seed 0 done after {:.0} s", t0.elapsed().as_secs_f64());
    let (r1, noise) = synth_seed_one(&mut c, &s, other, &ma, &m1, &mk);
    assert!(
        m1.explained >= 0.99,
        "the seed-1 model explains {}",
        m1.explained
    );
    for ((o, n), o0) in r1.rows.iter().zip(&noise).zip(&r.rows) {
        let what = format!(
            "seed 1, {}: {:.1}× the control, kept {:.3}, Pearson {:.3}; noise share {:.4} (seed 0's corrected I_i), {:.4} without the model",
            o.name,
            o.ratio(),
            o.kept(),
            o.pearson,
            n.corrected / o0.full,
            n.plain / o0.full
        );
        eprintln!("{what}");
        // Measured (2026-12-05, the refinement on a 16 × 16 subset, the image on the phasor
        // path from every second laser row and column): figure 85.8×, kept 0.910, Pearson
        // 0.990, noise share 0.0064; panel 90.0×, kept 0.947, Pearson 0.987, noise share
        // 0.0076 (issue 34: lit object ≥ 20×, projector's surface ≥ 10×, kept 0.8–1.25,
        // Pearson ≥ 0.95).
        assert!(o.ratio() >= 60.0, "{what}");
        assert!((0.85..=1.1).contains(&o.kept()), "{what}");
        assert!(o.pearson >= 0.96, "{what}");
        assert!(n.corrected / o0.full <= 0.03, "{what}");
    }
    eprintln!(
        "seed 1: all of Γ: Pearson {:.3}; explained {:.4}; {:.0} s in all",
        r1.pearson,
        m1.explained,
        t0.elapsed().as_secs_f64()
    );
    // Measured 0.991.
    assert!(r1.pearson >= 0.97, "seed 1: Pearson over Γ {}", r1.pearson);
}

/// Stage 2 on `panel_figure` with every capture (full, control, truth) convolved with a
/// Gaussian response of 40 ps FWHM (σ ≈ 0.51 bin of 33.4 ps) and delayed by 6 ps (0.18 bin),
/// each bin the Gaussian integrated over it (`pathtraced::blurred`); the model is told
/// neither: it fits its response width (≤ 1 bin) and global delay (± 1 bin) itself (it found
/// 0.5 bin and 0). Issue 34 asks ≥ 10× and Pearson ≥ 0.9 here.
#[test]
fn synthesis_with_the_capture_geometry_survives_an_unknown_response_and_delay() {
    use pathtraced::{Surf, blur_all, defaults, load, measure_models, surface_models};
    let t0 = std::time::Instant::now();
    let (s, opts) = (defaults(), probe::synth::SynthOptions::default());
    let mut c = load("panel_figure");
    blur_all(&mut c, 40.0, 6.0);
    let boxes = c.boxes.clone();
    let models = surface_models(
        vec![&mut c.all, &mut c.direct],
        &boxes,
        &s,
        Surf::Capture,
        &opts,
    );
    let [ma, mk]: [_; 2] = models.try_into().unwrap_or_else(|_| unreachable!());
    let r = measure_models(&mut c, &s, &ma, &mk);
    eprintln!(
        "blurred: models' width {:.3} / {:.3} bin, delay {:.3} / {:.3} bin, explained {:.4} / {:.4}",
        ma.width, mk.width, ma.shift, mk.shift, ma.explained, mk.explained
    );
    for o in &r.rows {
        let what = format!(
            "blurred, {}: {:.1}× the control, kept {:.3}, Pearson {:.3}",
            o.name,
            o.ratio(),
            o.kept(),
            o.pearson
        );
        eprintln!("{what}");
        // Measured (2026-12-05, the refinement on a 16 × 16 subset, the image on the phasor
        // path from every second laser row and column): figure 36.3×, kept 0.843, Pearson
        // 0.970; panel 41.5×, kept 0.903, Pearson 0.993 (the image from every spot: 30.0×,
        // 0.855, 0.956; 36.2×, 0.929, 0.990; on all 64 × 64: figure 44.0×, 0.863, 0.948; panel
        // 42.8×, 0.941, 0.991).
        assert!(o.ratio() >= 20.0, "{what}");
        assert!((0.8..=1.1).contains(&o.kept()), "{what}");
        assert!(o.pearson >= 0.93, "{what}");
    }
    eprintln!(
        "blurred: all of Γ: Pearson {:.3}; {:.0} s",
        r.pearson,
        t0.elapsed().as_secs_f64()
    );
    // Measured 0.984 (0.977 on all 64 × 64).
    assert!(r.pearson >= 0.95, "blurred: Pearson over Γ {}", r.pearson);
}

/// The robustness case's response (`pathtraced::blur_kernel`): 40 ps FWHM and 6 ps on bins of
/// 0.01 m (33.36 ps) is a Gaussian of σ = 0.509 bin centred 0.180 bin late; integrated over
/// each bin, its weights sum to 1, their mean is the delay and their variance σ² + 1/12 (the
/// bin's own width), both up to the aliasing of so narrow a Gaussian on the bins (measured
/// mean 0.1782 bin for 0.1799, variance 0.3398 for 0.3427, as erf gives them).
#[test]
fn the_robustness_response_has_its_width_and_delay() {
    let (first, w) = pathtraced::blur_kernel(0.01, 40.0, 6.0);
    let sum: f64 = w.iter().sum();
    let m: f64 = w
        .iter()
        .enumerate()
        .map(|(j, x)| (first + j as isize) as f64 * x)
        .sum();
    let v: f64 = w
        .iter()
        .enumerate()
        .map(|(j, x)| ((first + j as isize) as f64 - m).powi(2) * x)
        .sum();
    let c = 299_792_458.0e-12;
    let sigma = 40.0 * c / (8.0 * 2f64.ln()).sqrt() / 0.01;
    near("weights' sum", sum, 1.0, 1e-12);
    near("delay (bins)", m, 6.0 * c / 0.01, 0.02);
    near("variance (bins²)", v, sigma * sigma + 1.0 / 12.0, 0.02);
    near("delay (bins), as erf gives it", m, 0.178_153, 1e-4);
    near("variance (bins²), as erf gives it", v, 0.339_751, 1e-4);
    assert!(
        (sigma - 0.509).abs() < 1e-3 && (6.0 * c / 0.01 - 0.180).abs() < 1e-3,
        "σ {sigma} bin"
    );
}

/// A capture of photon counts (the two patches with Poisson noise of 100 counts at the peak
/// and a background of 0.05 counts per bin, as `examples/live_scan.json` simulates them): no
/// model explains its noise, so the surface model is used when it explains 99 % less the
/// noise's share `Σ H / Σ H²`. The same light scaled by 1.5 (no longer counts) is held to the
/// plain 99 % and falls back: the share is what lets the model through.
#[test]
fn photon_counts_are_held_to_the_rule_less_their_noise() {
    let mut cap = io::open(&support::fixture("two_patches.npz")).expect("two_patches");
    let row = cap.geometry.spads.len() * cap.geometry.nt;
    vltm::sim::Noise {
        peak_counts: 100.0,
        background: 0.05,
        seed: 7,
    }
    .apply(&mut cap.data, row)
    .expect("noise");
    let opts = probe::ModelOptions::default();
    let m = match probe::model_of_capture(&mut cap, &Wave::default(), &opts, EXEC).unwrap() {
        probe::ModelOutcome::Fitted(m) => m,
        probe::ModelOutcome::Unexplained { reason, .. } => panic!("{reason}"),
    };
    let noise = m.photon_noise.expect("counts");
    eprintln!(
        "photon counts: explained {:.4}, photon noise {noise:.4}",
        m.explained
    );
    assert!(
        m.explained < opts.min_explained && m.explained >= opts.min_explained - noise,
        "{} {noise}",
        m.explained
    );
    cap.data.iter_mut().for_each(|x| *x *= 1.5);
    match probe::model_of_capture(&mut cap, &Wave::default(), &opts, EXEC).unwrap() {
        probe::ModelOutcome::Unexplained {
            reason,
            model: Some(m),
        } => {
            assert!(m.photon_noise.is_none());
            assert!(reason.ends_with("(< 99 %)"), "{reason}");
        }
        probe::ModelOutcome::Fitted(_) => panic!("scaled counts were held to less than 99 %"),
        probe::ModelOutcome::Unexplained { reason, .. } => panic!("no model: {reason}"),
    }
}

/// Per patch of the two-patches scene (A left, B right): the mean in-focus indirect light over
/// its Γ voxels of the full capture with the model and with the windows, of the direct-only
/// control with each, and of the indirect-only truth (the full capture minus the control,
/// uncorrected); Γ from the full capture's diagonal for every run (`--direct`), over the
/// volume `spec`. Also what the model said on the full capture.
struct PatchRow {
    name: &'static str,
    voxels: usize,
    model: f64,
    model_control: f64,
    gate: f64,
    gate_control: f64,
    truth: f64,
}

impl std::fmt::Display for PatchRow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "patch {} ({} Γ voxels): model {:.4e} vs control {:.4e} ({:.2}×, kept {:.2}); windows {:.4e} vs control {:.1e} (kept {:.2}); truth {:.4e}",
            self.name,
            self.voxels,
            self.model,
            self.model_control,
            self.model / self.model_control,
            self.model / self.truth,
            self.gate,
            self.gate_control,
            self.gate / self.truth,
            self.truth
        )
    }
}

fn two_patch_rows(
    t: &support::cmd::TempDir,
    full: &std::path::Path,
    direct: &std::path::Path,
    spec: &str,
) -> (Vec<PatchRow>, String) {
    use support::cmd::{read_npy, text, vltm};
    let truth = t.path("truth.npz");
    {
        let mut c = io::open(full).expect("full");
        let d = io::open(direct).expect("direct");
        c.data.iter_mut().zip(&d.data).for_each(|(x, y)| *x -= y);
        io::npz::write(&c, &truth).expect("truth.npz");
    }
    let run = |cap: &std::path::Path, name: &str, extra: &[&str]| -> (Vec<f32>, String) {
        let out = t.path(&format!("{name}.npy"));
        let (c, o) = (cap.to_string_lossy(), out.to_string_lossy().into_owned());
        let mut args = vec!["indirect", &c, "--volume", spec, "--out", &o];
        args.extend_from_slice(extra);
        let r = vltm(&args);
        let said = text(&r.stdout) + &text(&r.stderr);
        assert!(r.status.success(), "{name}: {said}");
        (read_npy(&out).0, said)
    };
    let (model, said) = run(full, "full", &["--leak-correct", "model"]);
    let gamma_of = t.path("full.direct.npy").to_string_lossy().into_owned();
    let given = ["--direct", gamma_of.as_str()];
    let with = |c: &'static str| [given[0], given[1], "--leak-correct", c];
    let (gate, _) = run(full, "full_gate", &with("gate"));
    let (model_control, ctl) = run(direct, "control", &with("model"));
    assert!(ctl.contains("the surface model ("), "{ctl}");
    let (gate_control, _) = run(direct, "control_gate", &with("gate"));
    let (truth_i, _) = run(&truth, "truth", &[given[0], given[1], "--no-leak-correct"]);
    let (gamma, _) = read_npy(&t.path("full.gamma.npy"));
    let vol = Volume::parse(spec).expect("spec");
    let rows = [("A", true), ("B", false)]
        .into_iter()
        .map(|(name, left)| {
            let idx: Vec<usize> = (0..vol.len())
                .filter(|&i| gamma[i] > 0.0 && (vol.points[i][0] < 0.0) == left)
                .collect();
            assert!(!idx.is_empty(), "no Γ voxel on patch {name}");
            PatchRow {
                name,
                voxels: idx.len(),
                model: mean(&model, &idx),
                model_control: mean(&model_control, &idx),
                gate: mean(&gate, &idx),
                gate_control: mean(&gate_control, &idx),
                truth: mean(&truth_i, &idx),
            }
        })
        .collect();
    (rows, said)
}

/// The volume of the two-patch comparisons (10 cm voxels).
const TWO_PATCH_SPEC: &str = "-0.6:0.6:13,-0.1:0.1:3,0.5:1.2:8";

/// `--leak-correct auto` on the two patches by voxel size (docs/indirect-light.md's table):
/// on 5 and 10 cm voxels what the windows leave stands apart from them (adjacency measured
/// 0.07, 0.29), auto keeps the windows, and they keep the whole indirect-only truth with the
/// control at 0 where the model stays 2–3.4× its control. On 20 cm voxels the windows are
/// 0.46 m of path wide and cut through the inter-reflection (kept 0.31): the adjacency says
/// so (0.68) and auto picks the model — which is worse still on these point-sampled patches
/// (1.2× its control, keeping 4.1–4.5× the truth). The rule says when the windows lose
/// indirect light, not when the model keeps more: one reason auto is not the default. Means
/// over each patch's Γ voxels, Γ from the full capture ([`two_patch_rows`]).
#[test]
fn auto_follows_the_windows_not_the_model() {
    use support::cmd::{TempDir, npz_fixture, read_npy, text, vltm};
    let t = TempDir::new("leak", "auto-voxels");
    let full = npz_fixture("two_patches");
    // (volume, adjacency band, auto picks the model, windows' kept band, model's ratio and
    // kept bands)
    type Band = std::ops::RangeInclusive<f64>;
    let cases: [(&str, Band, bool, Band, Band, Band); 3] = [
        (
            "-0.6:0.6:25,-0.2:0.2:5,0.5:1.2:15",
            0.0..=0.15,
            false,
            0.99..=1.01,
            2.5..=4.5,
            0.9..=1.15,
        ),
        (
            "-0.6:0.6:13,-0.2:0.2:3,0.5:1.2:8",
            0.2..=0.35,
            false,
            0.99..=1.01,
            1.6..=2.6,
            1.3..=1.65,
        ),
        (
            "-0.6:0.6:7,-0.2:0.2:2,0.5:1.2:5",
            0.5..=0.9,
            true,
            0.2..=0.45,
            1.0..=2.0,
            3.0..=6.0,
        ),
    ];
    for (spec, adjacency, model, kept, ratio, model_kept) in cases {
        let (rows, _) = two_patch_rows(&t, &full, &npz_fixture("two_patches_direct"), spec);
        let auto = t.path("auto.npy");
        let (c, o) = (full.to_string_lossy(), auto.to_string_lossy().into_owned());
        let r = vltm(&[
            "indirect",
            &c,
            "--volume",
            spec,
            "--leak-correct",
            "auto",
            "--out",
            &o,
        ]);
        let said = text(&r.stdout);
        assert!(r.status.success(), "{said}{}", text(&r.stderr));
        let a = support::cmd::auto_adjacency(&said);
        println!("{spec}: adjacency {a:.2}");
        assert!(adjacency.contains(&a), "{spec}: {said}");
        // auto wrote the model's output (the helper's `full.npy`: the same volume and Γ) or
        // the windows'.
        assert_eq!(
            said.contains("the surface model ("),
            model,
            "{spec}: {said}"
        );
        assert_eq!(
            model,
            read_npy(&auto).0 == read_npy(&t.path("full.npy")).0,
            "{spec}"
        );
        for r in &rows {
            println!("{spec}: {r}");
            assert!(r.gate_control == 0.0, "{r}");
            assert!(kept.contains(&(r.gate / r.truth)), "{spec}: {r}");
            assert!(ratio.contains(&(r.model / r.model_control)), "{spec}: {r}");
            assert!(model_kept.contains(&(r.model / r.truth)), "{spec}: {r}");
        }
    }
}

/// Why `gate` stays the default (docs/indirect-light.md): on the simulator's two patches,
/// each 16 point samples, the surface model explains ≥ 99 % of the capture and is used, yet
/// it misses the point sampling, and the mean in-focus indirect light over each patch's Γ
/// voxels stays within a few times its direct-only control's (measured 2.2×), where the
/// windows leave the control at exactly 0 and keep the whole of the indirect-only truth
/// (0.99–1.01: the inter-reflection of two small patches arrives outside their direct light's
/// windows). When a rule learns to refuse such a model, this test fails and the docs' reason
/// changes with it.
#[test]
fn the_model_on_point_sampled_patches_leaves_their_direct_light() {
    use support::cmd::{TempDir, npz_fixture};
    let t = TempDir::new("leak", "point-sampled");
    let (rows, said) = two_patch_rows(
        &t,
        &npz_fixture("two_patches"),
        &npz_fixture("two_patches_direct"),
        TWO_PATCH_SPEC,
    );
    assert!(said.contains("the surface model (2 facets"), "{said}");
    for r in &rows {
        println!("{r}");
        assert!(r.model / r.model_control < 5.0, "{r}");
        assert!(r.gate_control == 0.0, "{r}");
        assert!((0.99..=1.01).contains(&(r.gate / r.truth)), "{r}");
    }
}

/// The same scene with each patch sampled at 16 × 16 points (0.75 cm apart, smooth
/// transients, rendered here by `vltm simulate`): the model explains more (≥ 99.7 %) and its
/// control falls, but the windows still do better on this scene: exactly 0 on the control and
/// the whole truth kept, where the model's in-focus indirect light stays within 15× its
/// control (measured 4.0× on A, 10.6× on B; kept 1.24 / 1.03). Its 0.2 % of direct light
/// left over is still 200 times the energy of the two patches' inter-reflection (1·10⁻⁵ of
/// `Σ H²`). So the windows are the better correction where indirect light arrives apart from
/// the direct light of small objects, the model where it overlaps the direct light of extended
/// surfaces (the path-traced panel and figure).
#[test]
fn on_finely_sampled_patches_the_windows_still_beat_the_model() {
    use support::cmd::{TempDir, text, vltm};
    let t = TempDir::new("leak", "finely-sampled");
    let render = |stem: &str| {
        let src = support::fixture(&format!("scenes/{stem}.json"));
        let mut scene: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&src).expect("scene")).expect("json");
        for o in scene["objects"].as_array_mut().expect("objects") {
            o["samples"] = 16.into();
        }
        let (json, out) = (
            t.path(&format!("{stem}.json")),
            t.path(&format!("{stem}.npz")),
        );
        std::fs::write(&json, scene.to_string()).expect("write scene");
        let r = vltm(&[
            "simulate",
            &json.to_string_lossy(),
            "--out",
            &out.to_string_lossy(),
        ]);
        assert!(r.status.success(), "{}", text(&r.stderr));
        out
    };
    let (full, direct) = (render("two_patches"), render("two_patches_direct"));
    let (rows, said) = two_patch_rows(&t, &full, &direct, TWO_PATCH_SPEC);
    let explained: f64 = said
        .split("explains ")
        .nth(1)
        .and_then(|x| x.split_whitespace().next())
        .and_then(|x| x.parse().ok())
        .unwrap_or_else(|| panic!("{said}"));
    assert!(explained >= 0.997, "{said}");
    for r in &rows {
        println!("{r}");
        let ratio = r.model / r.model_control;
        assert!(ratio > 2.0 && ratio < 15.0, "{r}");
        assert!((0.9..=1.4).contains(&(r.model / r.truth)), "{r}");
        assert!(r.gate_control == 0.0, "{r}");
        assert!((0.99..=1.01).contains(&(r.gate / r.truth)), "{r}");
    }
}

/// The surface model does not depend on the number of threads: on the two patches and on the
/// path-traced panel and figure (where facets are grown), fitted in pools of 1, 2 and 3
/// threads, the energy explained and every subtracted row are the same bits. (Its parallel
/// sums run in fixed chunks added in order; a rayon fold/reduce rounded as its splits fell,
/// 1e-8 of the peak apart between 1 and 2 threads.)
#[test]
fn the_surface_model_is_the_same_on_any_number_of_threads() {
    let captures = [
        (support::fixture("two_patches.npz"), false),
        (
            support::fixture("pathtraced/panel_figure_all/panel_figure_all.hdf5"),
            true,
        ),
    ];
    for (path, falloff) in captures {
        let fit = |threads: usize| -> (f64, Vec<u32>) {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("pool");
            pool.install(|| {
                let mut cap = io::open(&path).expect("capture");
                let opts = probe::ModelOptions::with_laser_falloff(falloff);
                let m = match probe::model_of_capture(&mut cap, &Wave::default(), &opts, EXEC)
                    .expect("model")
                {
                    probe::ModelOutcome::Fitted(m) => m,
                    probe::ModelOutcome::Unexplained { reason, .. } => panic!("{reason}"),
                };
                let row = cap.geometry.spads_per_row() * cap.geometry.nt;
                let mut data = cap.data.clone();
                for (l, r) in data.chunks_mut(row).enumerate() {
                    m.model.subtract_row(l, r);
                }
                (m.explained, data.iter().map(|x| x.to_bits()).collect())
            })
        };
        let (e1, d1) = fit(1);
        for threads in [2, 3] {
            let (e, d) = fit(threads);
            assert_eq!(
                e.to_bits(),
                e1.to_bits(),
                "{path:?}: explained on {threads} threads"
            );
            let differ = d.iter().zip(&d1).filter(|(a, b)| a != b).count();
            assert_eq!(
                differ, 0,
                "{path:?}: {differ} samples differ on {threads} threads"
            );
        }
    }
}

/// The surface model's memory plan counts the refinement's surfel legs at the facets' cap
/// before the first pass: on one thread (three sets of legs of 65,536 surfels over the 8 × 8
/// fixture's 16 + 16 spots of the subset, 107 MB), a budget of 60 MB refuses the model, names
/// the buffer, and the run goes on with the windows, equal to `--leak-correct gate`.
#[test]
fn the_model_plans_its_refinement_s_legs() {
    use support::cmd::{TempDir, npz_fixture, read_npy, text, vltm};
    let t = TempDir::new("leak", "legs-plan");
    let cap = npz_fixture("two_patches");
    let run = |global: &[&str], correct: &str| {
        let out = t.s(&format!("{correct}.npy"));
        let c = cap.to_string_lossy();
        let mut args = vec!["--threads", "1"];
        args.extend_from_slice(global);
        args.extend_from_slice(&[
            "indirect",
            &c,
            "--volume",
            "-0.6:0.6:13,-0.1:0.1:3,0.5:1.2:8",
        ]);
        args.extend_from_slice(&["--leak-correct", correct, "--out", &out]);
        let r = vltm(&args);
        let said = text(&r.stderr);
        assert!(r.status.success(), "{said}");
        (read_npy(std::path::Path::new(&out)).0, said)
    };
    let (tight, said) = run(&["--max-memory", "60M"], "model");
    assert!(
        said.contains("the refinement's surfel legs, 107 MB")
            && said.contains("using the time windows"),
        "{said}"
    );
    let (gate, _) = run(&[], "gate");
    assert_eq!(tight, gate);
}

/// The two-bounce render of [`a_two_bounce_render_of_the_oracle_facets_explains_the_indirect_truth`]
/// (test code, not a product path): every histogram of `c`'s geometry (laser-major), and the
/// surfels and pairs it used.
fn two_bounce_of_the_oracle(c: &pathtraced::Captures) -> (Vec<f64>, usize, usize) {
    let s = pathtraced::oracle_surfels(c, 25.0);
    let g = &c.indirect.geometry;
    let k = s.points.len();
    let sub = |a: [f64; 3], b: [f64; 3]| -> [f64; 3] { core::array::from_fn(|i| a[i] - b[i]) };
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let spot = |p: [f32; 3]| p.map(f64::from);
    // (distance, cos_wall·cos_surfel/d²) from a wall spot to surfel i.
    let leg = |w: [f64; 3], nw: [f64; 3], i: usize| -> (f64, f64) {
        let v = sub(w, s.points[i]);
        let d = dot(v, v).sqrt();
        let cw = (-dot(v, nw)).max(0.0) / d;
        let cs = dot(v, s.normals[i]).max(0.0) / d;
        (d, cw * cs / (d * d))
    };
    let mut pairs = Vec::new();
    for a in 0..k {
        for b in 0..k {
            if s.cluster[a] == s.cluster[b] {
                continue;
            }
            let v = sub(s.points[b], s.points[a]);
            let d = dot(v, v).sqrt();
            let ca = dot(v, s.normals[a]) / d;
            let cb = -dot(v, s.normals[b]) / d;
            if ca > 0.0 && cb > 0.0 {
                pairs.push((a, b, d, ca * cb / (d * d) * s.areas[a] * s.areas[b]));
            }
        }
    }
    let (nl, ns, nt) = (g.lasers.len(), g.spads.len(), g.nt);
    // Per wall spot: its legs to every surfel, and its device leg (0 without legs in time).
    let per_spot = |pts: &[[f32; 3]], normal: &dyn Fn(usize) -> [f64; 3], origin: &[f64; 3]| {
        let legs: Vec<Vec<(f64, f64)>> = (0..pts.len())
            .map(|i| (0..k).map(|q| leg(spot(pts[i]), normal(i), q)).collect())
            .collect();
        let device: Vec<f64> = pts
            .iter()
            .map(|p| {
                if g.legs_in_time {
                    vltm::kernel::geometry::dist64(p, origin)
                } else {
                    0.0
                }
            })
            .collect();
        (legs, device)
    };
    let (legs_l, d1) = per_spot(&g.lasers, &|l| g.laser_normal(l), &g.laser_origin);
    let (legs_s, d4) = per_spot(&g.spads, &|j| g.spad_normal(j), &g.sensor_origin);
    use rayon::prelude::*;
    let r: Vec<f64> = (0..nl * ns)
        .into_par_iter()
        .flat_map_iter(|ls| {
            let (l, j) = (ls / ns, ls % ns);
            let mut h = vec![0.0f64; nt];
            let sc = g.laser_falloff_at(l);
            for &(a, b, dab, gab) in &pairs {
                let (dl, fl) = legs_l[l][a];
                let (ds, fs) = legs_s[j][b];
                let w = fl * fs * gab;
                if w == 0.0 {
                    continue;
                }
                let t = ((d1[l] + dl + dab + ds + d4[j] - g.t0) / g.dt).floor();
                if t >= 0.0 && t < nt as f64 {
                    h[t as usize] += sc * w;
                }
            }
            h.into_iter()
        })
        .collect();
    (r, k, pairs.len())
}

/// The least-squares scale `k` of `r` against `t` (`min ‖t − k·r‖²`).
fn ls_scale(t: &[f64], r: &[f64]) -> f64 {
    let tr: f64 = t.iter().zip(r).map(|(a, b)| a * b).sum();
    tr / r.iter().map(|x| x * x).sum::<f64>()
}

/// The measured basis of the corner's next step (docs/indirect-light.md): a two-bounce render
/// of the oracle facets (every box face of `scene.json` at 4 cm surfels, each pair of surfels
/// on different objects facing each other, no occlusion, no pulse, times binned as the direct
/// render bins them, the laser's falloff applied) with one least-squares scale explains most
/// of the indirect-only truth: measured 0.814 of its energy on the corner (Pearson 0.900;
/// 0.921 and 0.958 over 3-bin sums) and 0.942 on panel/figure (Pearson 0.970; 0.980 and
/// 0.990). The corner's inter-reflections are 4.6 % of its capture's energy, which least
/// squares on direct light alone absorbs with a wrong pose; a term this cheap (76,500 pairs,
/// 3 s for both scenes here) could give them a place in the fit. Not a product path: the
/// renderer lives in this test.
#[test]
fn a_two_bounce_render_of_the_oracle_facets_explains_the_indirect_truth() {
    for scene in ["corner", "panel_figure"] {
        let c = pathtraced::load(scene);
        let (r, k, n_pairs) = two_bounce_of_the_oracle(&c);
        let nt = c.indirect.geometry.nt;
        let t: Vec<f64> = c.indirect.data.iter().map(|&x| f64::from(x)).collect();
        let smooth = |x: &[f64]| -> Vec<f64> {
            x.chunks(nt)
                .flat_map(|h| {
                    (0..nt).map(move |i| {
                        let lo = i.saturating_sub(1);
                        let hi = (i + 2).min(nt);
                        h[lo..hi].iter().sum::<f64>()
                    })
                })
                .collect()
        };
        let stats = |t: &[f64], r: &[f64]| {
            let tt: f64 = t.iter().map(|x| x * x).sum();
            let kk = ls_scale(t, r);
            let res: f64 = t.iter().zip(r).map(|(a, b)| (a - kk * b).powi(2)).sum();
            let n = t.len() as f64;
            let (mt, mr) = (t.iter().sum::<f64>() / n, r.iter().sum::<f64>() / n);
            let cov: f64 = t.iter().zip(r).map(|(a, b)| (a - mt) * (b - mr)).sum();
            let vt: f64 = t.iter().map(|a| (a - mt).powi(2)).sum();
            let vr: f64 = r.iter().map(|b| (b - mr).powi(2)).sum();
            (kk, 1.0 - res / tt, cov / (vt * vr).sqrt())
        };
        let all: f64 = c.all.data.iter().map(|&x| f64::from(x).powi(2)).sum();
        let tt: f64 = t.iter().map(|x| x * x).sum();
        let (kk, expl, p) = stats(&t, &r);
        let (_, expl3, p3) = stats(&smooth(&t), &smooth(&r));
        let what = format!(
            "{scene}: {k} surfels, {} pairs; truth holds {:.4} of the full capture's energy; scale {kk:.4e}; two-bounce render explains {expl:.3} of the truth (Pearson {p:.3}); 3-bin sums: {expl3:.3} (Pearson {p3:.3})",
            n_pairs,
            tt / all
        );
        println!("{what}");
        let (least, pearson) = if scene == "corner" {
            (0.78, 0.88)
        } else {
            (0.92, 0.96)
        };
        assert!(expl >= least && p >= pearson && expl3 >= expl, "{what}");
    }
}

/// The corner's Stage 2 with most of its two-bounce light taken out before the fit (an oracle
/// experiment: [`two_bounce_of_the_oracle`] scaled to the indirect-only truth, 0.81 of it,
/// subtracted from the full capture; the model fitted to what is left, from the capture's own
/// image, then subtracted from the full capture as in Stage 2): the in-focus indirect light
/// keeps more of the truth (measured kept 0.91 / 0.85 against 0.57 / 0.49) but reaches only
/// 5.5× / 7.0× its control (3.5× / 4.0× without), because the left panel still stretches past
/// the apex (11.4°, 96 mm off, 1.08 m wide) and the model explains 95.5 %: the three-bounce
/// light (2.8 % of the energy) and the noise (1.4 %) are left for a wrong pose to absorb, and
/// the control's own left panel lands 6.5° off. So a two-bounce term alone does not make the
/// corner work (docs/indirect-light.md).
#[test]
fn the_corner_without_its_two_bounce_light_still_misses_its_pose() {
    use pathtraced::{Surf, defaults, load, measure_models, surface_models};
    let (s, opts) = (defaults(), probe::synth::SynthOptions::default());
    let mut c = load("corner");
    let boxes = c.boxes.clone();
    let (r, _, _) = two_bounce_of_the_oracle(&c);
    let t: Vec<f64> = c.indirect.data.iter().map(|&x| f64::from(x)).collect();
    let k = ls_scale(&t, &r);
    let mut h = c.all.clone();
    h.data
        .iter_mut()
        .zip(&r)
        .for_each(|(x, y)| *x -= (k * y) as f32);
    let models = surface_models(
        vec![&mut h, &mut c.direct],
        &boxes,
        &s,
        Surf::Capture,
        &opts,
    );
    let [ma, mk]: [_; 2] = models.try_into().unwrap_or_else(|_| unreachable!());
    let res = measure_models(&mut c, &s, &ma, &mk);
    assert!(ma.explained < 0.97, "explained {}", ma.explained);
    for o in &res.rows {
        let what = format!(
            "{}: {:.1}× the control, kept {:.3}, Pearson {:.3} (explained {:.4} / {:.4})",
            o.name,
            o.ratio(),
            o.kept(),
            o.pearson,
            ma.explained,
            mk.explained
        );
        println!("{what}");
        assert!(o.ratio() > 4.0 && o.ratio() < 10.0, "{what}");
        assert!((0.75..=1.0).contains(&o.kept()), "{what}");
    }
    println!("all of Γ: Pearson {:.3}", res.pearson);
}
