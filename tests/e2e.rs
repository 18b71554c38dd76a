//! End-to-end tests of the probes on the committed fixtures (`fixtures/`, see
//! `fixtures/README.md`), through the library API: `vltm::io::open`, `vltm::volume::Volume`,
//! `vltm::probe` and the simulator.
//!
//! * the fixtures are what their scene files render to (guards stale `.npz` files);
//! * the diagonal images both patches (2D×2D scan, 1-D SPAD array, single SPAD);
//! * the A → B inter-reflection shows up in the gated, Γ-masked column at B against the
//!   direct-only control; the gate removes out-of-focus light (the paper's Fig. 6);
//! * the higher-order gate (Eq. 18) picks up a 5-vertex path and rejects a 4-vertex one;
//! * swapping lasers and SPADs transposes the matrix; a streamed scene equals its render.
//!
//! Measured values are printed in every assertion message (and by `--nocapture`).

mod support;

use std::path::PathBuf;
use support::{mean_over, scene_object_voxels};

use vltm::io::{self, Capture};
use vltm::kernel::Point;
use vltm::probe::{self, ColumnGate, Exec, IndirectOptions, LeakOptions, Shell, Wave};
use vltm::sim::{Bounces, Scene};
use vltm::volume::Volume;

const EXEC: Exec<'static> = Exec {
    progress: None,
    path: vltm::probe::EvalPath::Auto,
};

/// The imaged volume: 25 × 5 × 15 voxels, 5 cm pitch in x and z (10 cm in y), with voxels at
/// the patch centres (±0.45, 0, 0.8) and the point scatterers (±0.3, 0, 0.8).
const VOLUME: &str = "-0.6:0.6:25,-0.2:0.2:5,0.5:1.2:15";

/// Every committed scene (stem of `fixtures/scenes/*.json` and `fixtures/*.npz`).
const FIXTURES: [&str; 5] = [
    "two_patches",
    "two_patches_direct",
    "two_patches_line",
    "two_patches_single",
    "three_points",
];

fn scene_path(stem: &str) -> PathBuf {
    support::fixture(&format!("scenes/{stem}.json"))
}

fn capture_path(stem: &str) -> PathBuf {
    support::fixture(&format!("{stem}.npz"))
}

fn scene(stem: &str) -> Scene {
    let p = scene_path(stem);
    Scene::load(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

fn fixture(stem: &str) -> Capture {
    let p = capture_path(stem);
    io::open(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

fn volume() -> Volume {
    Volume::parse(VOLUME).expect("volume")
}

fn centre(s: &Scene, name: &str) -> Point {
    s.object_centre(name)
        .unwrap_or_else(|| panic!("no object {name}"))
}

/// The wave used for the indirect-light tests: default λ (twice the aperture pitch) and
/// σ = λ/2 instead of the default 2λ/3. With 2λ/3 the patches' own direct returns leak into
/// the 4-vertex gate at B even more strongly, the gate's known limitation; σ = λ/2 is
/// the remedy noted there (and leak correction, `vltm::probe::leak`, the one vltm uses).
fn indirect_wave(g: &vltm::io::Geometry) -> Wave {
    Wave {
        sigma: Some(probe::default_wavelength(g) / 2.0),
        ..Wave::default()
    }
}

fn dist(a: Point, b: Point) -> f32 {
    ((0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f32>()).sqrt()
}

fn max_of(v: &[f32]) -> f32 {
    v.iter().copied().fold(0.0, f32::max)
}

/// Grid indices (ix, iy, iz) of voxel `i` (C order over the volume's shape).
fn grid_index(vol: &Volume, i: usize) -> [usize; 3] {
    let [_, ny, nz] = vol.shape;
    [i / (ny * nz), (i / nz) % ny, i % nz]
}

/// Whether voxel `i` is ≥ each of its (up to 26) grid neighbours.
fn is_local_max(vol: &Volume, v: &[f32], i: usize) -> bool {
    let [nx, ny, nz] = vol.shape;
    let [ix, iy, iz] = grid_index(vol, i);
    let r = |c: usize, n: usize| c.saturating_sub(1)..=(c + 1).min(n - 1);
    for jx in r(ix, nx) {
        for jy in r(iy, ny) {
            for jz in r(iz, nz) {
                if v[(jx * ny + jy) * nz + jz] > v[i] {
                    return false;
                }
            }
        }
    }
    true
}

// ---------------------------------------------------------------------------------------------
// fixtures
// ---------------------------------------------------------------------------------------------

/// Every committed capture equals a fresh render of its scene file (the fixtures are not
/// stale), every scene file has its capture, and every capture stays small.
#[test]
fn fixtures_match_fresh_renders() {
    let mut scenes: Vec<String> = std::fs::read_dir(support::fixture("scenes"))
        .expect("fixtures/scenes")
        .filter_map(|e| {
            let p = e.ok()?.path();
            (p.extension()? == "json").then(|| p.file_stem()?.to_str().map(String::from))?
        })
        .collect();
    scenes.sort();
    let mut listed: Vec<String> = FIXTURES.iter().map(|s| s.to_string()).collect();
    listed.sort();
    assert_eq!(
        scenes, listed,
        "fixtures/scenes/*.json and the FIXTURES list of tests/e2e.rs differ"
    );
    for stem in FIXTURES {
        let t = std::time::Instant::now();
        let fresh = scene(stem).render().expect("render");
        let secs = t.elapsed().as_secs_f64();
        let committed = fixture(stem);
        let bytes = std::fs::metadata(capture_path(stem)).expect("size").len();
        assert_eq!(
            committed.geometry,
            fresh.geometry,
            "{stem}: geometry of the committed capture differs from a fresh render of {}; \
             re-run the command in fixtures/README.md, then `bash fixtures/sums.sh`",
            scene_path(stem).display()
        );
        assert_eq!(committed.data.len(), fresh.data.len(), "{stem}: H size");
        let peak = max_of(&fresh.data);
        let diff = committed
            .data
            .iter()
            .zip(&fresh.data)
            .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
        println!(
            "{stem}: {bytes} bytes, render {secs:.2} s, max |H_committed - H_fresh| = {diff:e} (peak {peak:e})"
        );
        assert!(peak > 0.0, "{stem}: the fresh render is empty");
        assert!(
            diff <= 1e-6 * peak,
            "{stem}: committed capture differs from a fresh render by {diff:e} (peak {peak:e}); \
             re-run `cargo run --release --bin vltm -- simulate fixtures/scenes/{stem}.json --out fixtures/{stem}.npz`, \
             then `bash fixtures/sums.sh`"
        );
        assert!(
            bytes <= 1 << 20,
            "{stem}: {bytes} bytes; keep fixtures below 1 MiB"
        );
    }
}

// ---------------------------------------------------------------------------------------------
// diagonal
// ---------------------------------------------------------------------------------------------

/// The diagonal T(x_v, x_v) peaks within one voxel of each patch centre, at a local maximum
/// holding at least 30 % of the image maximum, for the 2D×2D scan, the 1-D SPAD array and the
/// single SPAD.
#[test]
fn direct_light_peaks_at_both_patches() {
    let vol = volume();
    let s = scene("two_patches");
    for stem in ["two_patches", "two_patches_line", "two_patches_single"] {
        let mut c = fixture(stem);
        let d = probe::direct(&mut c, &vol, &Wave::default(), EXEC).expect("direct");
        let max = max_of(&d.values);
        assert!(
            max > 0.0 && d.values.iter().all(|v| v.is_finite()),
            "{stem}: max {max}"
        );
        for name in ["A", "B"] {
            let p = centre(&s, name);
            let at = vol.nearest(p);
            // The strongest voxel within 0.2 m of the centre.
            let peak = (0..vol.len())
                .filter(|&i| dist(vol.points[i], p) < 0.2)
                .max_by(|&a, &b| d.values[a].total_cmp(&d.values[b]))
                .expect("voxels near the patch");
            let (gi, gp) = (grid_index(&vol, at), grid_index(&vol, peak));
            let off = (0..3).map(|k| gi[k].abs_diff(gp[k])).max().unwrap_or(0);
            let rel = d.values[peak] / max;
            println!(
                "{stem}: patch {name} at {p:?}: peak {:?} ({off} voxel(s) off), {rel:.3} of the maximum, \
                 centre voxel {:.3} of the maximum",
                vol.points[peak],
                d.values[at] / max
            );
            assert!(
                off <= 1,
                "{stem}: direct-light peak near {name} is at {:?}, {off} voxels from the centre {p:?}",
                vol.points[peak]
            );
            assert!(
                is_local_max(&vol, &d.values, peak),
                "{stem}: the peak near {name} at {:?} is not a local maximum",
                vol.points[peak]
            );
            assert!(
                rel >= 0.3,
                "{stem}: the peak near {name} is only {rel:.3} of the image maximum"
            );
        }
    }
}

// ---------------------------------------------------------------------------------------------
// first-order indirect light
// ---------------------------------------------------------------------------------------------

/// The Γ-masked, 4-vertex-gated column focused at A, averaged over patch B's voxels (its
/// surface ± one voxel), is higher with the A → B inter-reflection than in the direct-only
/// control (same Γ, from the full scene's direct image). σ = λ/2. fixtures/README.md states
/// the measured means.
#[test]
fn inter_reflection_raises_the_gated_column_at_b() {
    let vol = volume();
    let s = scene("two_patches");
    let (mut full, mut control) = (fixture("two_patches"), fixture("two_patches_direct"));
    let wave = indirect_wave(&full.geometry);
    let d = probe::direct(&mut full, &vol, &wave, EXEC).expect("direct");
    let gamma = probe::gamma_mask(&d.values, 0.1);
    let (ia, ib) = (vol.nearest(centre(&s, "A")), vol.nearest(centre(&s, "B")));
    let n_gamma = gamma.iter().filter(|&&g| g).count();
    assert!(
        gamma[ia] && gamma[ib],
        "A's voxel (in Γ: {}) and B's voxel (in Γ: {}) must be in Γ ({n_gamma} voxels)",
        gamma[ia],
        gamma[ib]
    );
    let a = vol.points[ia];
    let object_b = scene_object_voxels(&s, "B", &vol);
    let col = |c: &mut Capture| {
        let o = probe::column(c, a, &vol, ColumnGate::TwoBounce, Shell::ALL, &wave, EXEC)
            .expect("column");
        let masked: Vec<f32> = o
            .values
            .iter()
            .zip(&gamma)
            .map(|(&v, &g)| if g { v } else { 0.0 })
            .collect();
        (o.values[ib], mean_over(&masked, &object_b))
    };
    let ((t_full, m_full), (t_ctrl, m_ctrl)) = (col(&mut full), col(&mut control));
    let ratio = m_full / m_ctrl;
    println!(
        "Γ: {n_gamma} voxels; T(A,·) gated, Γ-masked, mean over patch B's {} voxels: {m_full:.4e} \
         with the inter-reflection, {m_ctrl:.4e} direct-only control: {ratio:.2}x (σ = {:.4} m)",
        object_b.len(),
        d.config.sigma()
    );
    assert!(
        (1.04..=1.12).contains(&ratio),
        "T(A,·) over B is {ratio:.2}x the control ({m_full:.4e} vs {m_ctrl:.4e}); fixtures/README.md: 1.08x"
    );
    // The mechanism, at the one voxel of B's centre (a check, not a measure of the object):
    // the inter-reflection arrives there, where the leak is weakest.
    assert!(
        t_full >= 3.0 * t_ctrl,
        "T(A,B) at B's centre voxel: {t_full:.4e} vs control {t_ctrl:.4e}"
    );

    // Eq. 17 with the same Γ (default r0 = 1.5σ), without leak correction. On this scene the
    // sum over the Γ voxels around A is dominated by the patches' direct light leaking into
    // the gate at voxels off the patch centres: about as high as the
    // control over B's voxels (fixtures/README.md). Also: the sum over a ∈ Γ includes a = A's
    // voxel, so I_i(B) ≥ T(A, B) (the same factorised column, the other terms are ≥ 0).
    let opts = IndirectOptions::default();
    let i_full =
        probe::indirect_over(&mut full, &vol, &gamma, &opts, &wave, EXEC).expect("indirect");
    let i_ctrl =
        probe::indirect_over(&mut control, &vol, &gamma, &opts, &wave, EXEC).expect("indirect");
    let (f, c) = (i_full.values[ib], i_ctrl.values[ib]);
    let (mf, mc) = (
        mean_over(&i_full.values, &object_b),
        mean_over(&i_ctrl.values, &object_b),
    );
    println!(
        "in-focus indirect I_i (Eq. 17, Γ as above, r0 = {:.3} m), mean over B's voxels: \
         {mf:.4e} vs control {mc:.4e}: {:.2}x",
        i_full.shell.r0,
        mf / mc
    );
    assert!(
        (0.95..=1.05).contains(&(mf / mc)),
        "Eq. 17 over B: {:.2}x the control (fixtures/README.md: 1.00x)",
        mf / mc
    );
    assert!(
        f >= t_full && c >= t_ctrl,
        "I_i(B) must include the term T(A,B): {f:.4e} < {t_full:.4e} or {c:.4e} < {t_ctrl:.4e}"
    );
    assert!(
        i_full
            .values
            .iter()
            .zip(&gamma)
            .all(|(&v, &g)| g || v == 0.0),
        "I_i is not zero outside Γ"
    );
    // What `vltm indirect` does by default: vltm's default σ = 2λ/3, Γ at ε = 0.1 of its
    // diagonal, the capture's direct light removed first (the control: the same correction).
    let wave = Wave::default();
    let d = probe::direct(&mut full, &vol, &wave, EXEC).expect("direct");
    let gamma = probe::gamma_mask(&d.values, 0.1);
    let opts = IndirectOptions {
        leak: Some(LeakOptions::default()),
        ..IndirectOptions::default()
    };
    let lf = probe::indirect_over(&mut full, &vol, &gamma, &opts, &wave, EXEC).expect("indirect");
    let lc =
        probe::indirect_over(&mut control, &vol, &gamma, &opts, &wave, EXEC).expect("indirect");
    let (mf, mc) = (
        mean_over(&lf.values, &object_b),
        mean_over(&lc.values, &object_b),
    );
    println!(
        "leak-corrected I_i (defaults: σ = {:.4} m, ε = 0.1, r0 = {:.3} m), mean over B's voxels: \
         {mf:.4e} vs control {mc:.4e}: {:.2}x",
        d.config.sigma(),
        lf.shell.r0,
        mf / mc
    );
    assert!(
        mf > 0.0 && mf >= 2.0 * mc,
        "leak-corrected I_i over B: {mf:.4e} vs control {mc:.4e} (fixtures/README.md: ≥ 2x, control 0)"
    );
}

/// In-focus indirect light, Eqs. 15–17 end to end (`probe::indirect`: pass 1 the diagonal and
/// Γ = {I_d > 0.1·max}, pass 2 the Γ-masked sum over pairs ≥ r0 apart), on the test bench of
/// A bench rendered in-test: 12×12 lasers × 12×12 SPADs over 1 m, 500 bins of 1 cm,
/// λ = 0.2 m, σ = 2λ/3 (the defaults of the method), isotropic point patches A, B 0.7 m
/// apart, r0 = 0.3 m, no leak correction. The float64 prototype gave I_i = 7.5× its
/// direct-only control at B's single voxel; docs/reliability.md states the mean over B's voxels (its
/// voxel ± one voxel, 9 voxels of this 25 × 1 × 13 slice) and the same over A's, which this
/// test asserts within a band. Γ must hold both patches.
/// (The 8×8 fixtures are too coarse for the unweighted Eq. 17 sum at the default σ: see
/// fixtures/README.md.)
#[test]
fn in_focus_indirect_light_eq17_finds_the_inter_reflection() {
    use vltm::sim::{Aperture, PointScatterer, Setup};
    let wall = || Aperture::grid([12, 12], [1.0, 1.0], [0.0, 0.0]);
    let (a, b) = ([-0.35, 0.0, 0.8], [0.35, 0.0, 0.8]);
    let mut bench = Scene::new(Setup::new(wall(), wall(), 500, 0.01))
        .with(PointScatterer::new("A", a, 0.04))
        .with(PointScatterer::new("B", b, 0.04));
    bench.pulse_sigma = Some(0.01);
    bench.cosines = false;
    let mut control = bench.clone();
    control.bounces = Bounces::Direct;
    let vol = Volume::parse("-0.6:0.6:25,0:0:1,0.5:1.1:13").expect("volume");
    let wave = Wave {
        wavelength: Some(0.2),
        ..Wave::default()
    };
    let opts = IndirectOptions {
        shell: Some(Shell {
            r0: 0.3,
            r1: f32::INFINITY,
        }),
        ..IndirectOptions::default()
    };
    let run = |s: &Scene| {
        let mut c = s.render().expect("render");
        probe::indirect(&mut c, &vol, &opts, &wave, EXEC).expect("indirect")
    };
    let (full, ctrl) = (run(&bench), run(&control));
    let to_p = |p: [f64; 3]| p.map(|c| c as f32);
    let (ia, ib) = (vol.nearest(to_p(a)), vol.nearest(to_p(b)));
    let n_gamma = full.gamma.iter().filter(|&&g| g).count();
    assert!(
        full.gamma[ia] && full.gamma[ib],
        "Γ ({n_gamma} voxels) must hold A's and B's voxels"
    );
    let (ob, oa) = (
        scene_object_voxels(&bench, "B", &vol),
        scene_object_voxels(&bench, "A", &vol),
    );
    let (f, c) = (mean_over(&full.values, &ob), mean_over(&ctrl.values, &ob));
    let ratio = f / c;
    let ra = mean_over(&full.values, &oa) / mean_over(&ctrl.values, &oa);
    println!(
        "Eq. 17 on the 12x12 bench: |Γ| = {n_gamma}, I_i mean over B's {} voxels = {f:.4e} \
         with the inter-reflection, {c:.4e} direct-only: {ratio:.2}x; over A's: {ra:.2}x \
         (single voxel B: {:.2}x; prototype: 7.5x)",
        ob.len(),
        full.values[ib] / ctrl.values[ib]
    );
    assert!(
        (3.0..=3.5).contains(&ratio),
        "I_i over B is {ratio:.2}x the control ({f:.4e} vs {c:.4e}); documented: 3.24x"
    );
    // By symmetry the light from B lands on A as well.
    assert!(
        (3.0..=3.5).contains(&ra),
        "I_i over A is {ra:.2}x the control; documented: 3.24x"
    );
    // The default of `vltm indirect`: the capture's direct light removed first.
    let leak = IndirectOptions {
        leak: Some(LeakOptions::default()),
        ..opts
    };
    let run = |s: &Scene| {
        let mut c = s.render().expect("render");
        probe::indirect_over(&mut c, &vol, &full.gamma, &leak, &wave, EXEC).expect("indirect")
    };
    let (lf, lc) = (run(&bench), run(&control));
    let (mf, mc) = (mean_over(&lf.values, &ob), mean_over(&lc.values, &ob));
    println!(
        "leak-corrected, mean over B's voxels: {mf:.4e} vs control {mc:.4e}: {:.2}x",
        mf / mc
    );
    assert!(
        mf > 0.0 && mf >= 2.0 * mc,
        "leak-corrected I_i over B: {mf:.4e} vs control {mc:.4e} (documented: ≥ 2x, control 0)"
    );
    // Nothing outside Γ.
    assert!(
        full.values
            .iter()
            .zip(&full.gamma)
            .all(|(&v, &g)| g || v == 0.0)
    );
}

/// The paper's Fig. 6: without a time gate the virtual projector focused at A also lights the
/// rest of the scene (out-of-focus light); the 4-vertex gate confines it.
///
/// Measure (on the direct-only control, where no light travels from A to another surface, so
/// the ideal column T(A, ·) vanishes away from A): the **out-of-focus fraction**
/// `f = Σ_{v∈Γ, |v−A| ≥ r0} T(A,v) / Σ_{v∈Γ} T(A,v)`, Γ = {direct > 0.1·max} of the full
/// scene, r0 = 1.5σ. On the full scene the same fraction also counts the true A → B light, but
/// that is tiny next to A's own light, so it must drop too. (The variant "energy outside a 2σ
/// ball around B among Γ voxels ≥ r0 from A" is identically 0 here with and without the gate:
/// Γ holds only the two patch blobs, and A's lies within r0.)
///
/// Over patch B's voxels (its surface ± one voxel): without the gate the column is about the
/// direct-only control's value (it is B's direct light), with the gate it is above it.
#[test]
fn gate_removes_out_of_focus_light() {
    let vol = volume();
    let s = scene("two_patches");
    let (mut full, mut control) = (fixture("two_patches"), fixture("two_patches_direct"));
    let wave = indirect_wave(&full.geometry);
    let d = probe::direct(&mut full, &vol, &wave, EXEC).expect("direct");
    let gamma = probe::gamma_mask(&d.values, 0.1);
    let sigma = d.config.sigma() as f32;
    let r0 = 1.5 * sigma;
    let (pa, object_b) = (centre(&s, "A"), scene_object_voxels(&s, "B", &vol));
    let a = vol.points[vol.nearest(pa)];
    let fraction = |v: &[f32]| {
        let (mut far, mut all) = (0.0f64, 0.0f64);
        for (i, p) in vol.points.iter().enumerate() {
            if gamma[i] {
                all += f64::from(v[i]);
                if dist(*p, a) >= r0 {
                    far += f64::from(v[i]);
                }
            }
        }
        far / all
    };
    let mut at_b = Vec::new();
    for (label, c) in [("control", &mut control), ("full", &mut full)] {
        let mut f = Vec::new();
        for gate in [ColumnGate::TwoBounce, ColumnGate::None] {
            let o = probe::column(c, a, &vol, gate, Shell::ALL, &wave, EXEC).expect("column");
            f.push(fraction(&o.values));
            at_b.push(mean_over(&o.values, &object_b));
        }
        println!(
            "{label}: out-of-focus fraction (Γ energy ≥ {r0:.3} m from A) gated {:.3e}, no gate {:.3e}",
            f[0], f[1]
        );
        assert!(
            f[1] > 0.0 && f[0] < 0.1 * f[1],
            "{label}: the gate should cut the out-of-focus fraction at least 10x: gated {:.3e}, no gate {:.3e}",
            f[0],
            f[1]
        );
    }
    // at_b = [control gated, control none, full gated, full none]
    let (gated, ungated) = (at_b[2] / at_b[0], at_b[3] / at_b[1]);
    println!(
        "T(A,·) over patch B's voxels, full / control: gated {gated:.2}x ({:.3e} / {:.3e}), no gate {ungated:.2}x ({:.3e} / {:.3e})",
        at_b[2], at_b[0], at_b[3], at_b[1]
    );
    assert!(
        (0.93..=1.03).contains(&ungated) && (1.0..=1.07).contains(&gated) && gated > ungated,
        "T(A,·) over B, full/control, should be ~1 without the gate (measured {ungated:.2}x) and higher with it ({gated:.2}x; fixtures/README.md: 0.98x and 1.03x)"
    );
}

// ---------------------------------------------------------------------------------------------
// higher-order gate
// ---------------------------------------------------------------------------------------------

/// Eq. 18 (the late gate) at (A, B) on three point scatterers, averaged over B's voxels (B's
/// voxel of the tests' grid ± one voxel: 27 voxels at 5 cm × 10 cm × 5 cm): it picks up the 5-vertex path
/// A → C → B (fixture with up to 5 vertices vs the same scene rendered with up to 4), and it
/// rejects the 4-vertex A → B path (two-point scene A, B with and without indirect light),
/// which the 4-vertex gate (Eq. 14) picks up.
#[test]
fn higher_order_gate_picks_up_five_vertex_light() {
    let s5 = scene("three_points");
    let (pa, pb) = (centre(&s5, "A"), centre(&s5, "B"));
    // B's voxel of VOLUME's grid (pitch 0.05, 0.1, 0.05 m) ± one voxel.
    let vol = Volume::grid(
        [pb[0] - 0.05, pb[1] - 0.1, pb[2] - 0.05],
        [pb[0] + 0.05, pb[1] + 0.1, pb[2] + 0.05],
        [3, 3, 3],
    )
    .expect("B ± one voxel");
    let all: Vec<usize> = (0..vol.len()).collect();
    let centre_b = vol.nearest(pb);
    let mut s4 = s5.clone();
    s4.max_vertices = 4;
    let mut ab = s5.clone();
    ab.objects.retain(|o| o.name() != "C");
    ab.max_vertices = 4;
    let mut ab_direct = ab.clone();
    ab_direct.bounces = Bounces::Direct;
    let probe = |c: &mut Capture| {
        let w = Wave::default();
        let t = |c: &mut Capture, g| {
            let o = probe::column(c, pa, &vol, g, Shell::ALL, &w, EXEC).expect("column");
            (mean_over(&o.values, &all), o.values[centre_b])
        };
        (t(c, ColumnGate::HigherOrder), t(c, ColumnGate::TwoBounce))
    };
    let ((ho5, ho5c), _) = probe(&mut fixture("three_points"));
    let ((ho4, ho4c), _) = probe(&mut s4.render().expect("render"));
    let ((ho_ab, ho_abc), (t2_ab, _)) = probe(&mut ab.render().expect("render"));
    let ((ho_ab_d, ho_ab_dc), (t2_ab_d, _)) = probe(&mut ab_direct.render().expect("render"));
    println!(
        "T_ho(A,·) mean over B's voxels: A,B,C up to 5 vertices {ho5:.4e}, up to 4 {ho4:.4e} \
         ({:.2}x); A,B all paths {ho_ab:.4e}, direct only {ho_ab_d:.4e} ({:.3} of the 5-vertex \
         signal)\nT_2(A,·) mean over B's voxels: A,B all paths {t2_ab:.4e}, direct only \
         {t2_ab_d:.4e} ({:.2}x)",
        ho5 / ho4,
        (ho_ab - ho_ab_d).abs() / ho5,
        t2_ab / t2_ab_d
    );
    assert!(
        (5.0..=7.0).contains(&(ho5 / ho4)),
        "the 5-vertex path A→C→B should raise T_ho over B's voxels ~6x (fixtures/README.md 5.97x): \
         {ho5:.4e} vs {ho4:.4e}"
    );
    assert!(
        (ho_ab - ho_ab_d).abs() <= 0.2 * ho5,
        "the 4-vertex path A→B should stay well below the 5-vertex signal over B's voxels: \
         {ho_ab_d:.4e} → {ho_ab:.4e} (the 5-vertex signal is {ho5:.4e}; fixtures/README.md 0.16)"
    );
    assert!(
        (2.4..=2.9).contains(&(t2_ab / t2_ab_d)),
        "the 4-vertex gate should pick up the A→B path: T_2 over B {t2_ab_d:.4e} → {t2_ab:.4e} \
         (fixtures/README.md 2.67x)"
    );
    // The mechanism at B's centre voxel (a check, not a measure of the object): the late
    // gate there sees the 5-vertex light and not the 4-vertex path.
    assert!(
        ho5c >= 10.0 * ho4c && (ho_abc - ho_ab_dc).abs() <= 0.05 * ho5c,
        "T_ho at B's centre: {ho5c:.4e} vs {ho4c:.4e}; A,B {ho_ab_dc:.4e} → {ho_abc:.4e}"
    );
}

// ---------------------------------------------------------------------------------------------
// reciprocity, streaming
// ---------------------------------------------------------------------------------------------

/// `swap_roles` (the CLI's `--swap-roles`) transposes the matrix: T_swap(a, b) = T(b, a), for
/// the 2D×2D scan and the 1-D SPAD array (8×8 lasers × 8×1 SPADs, where T is not symmetric),
/// with the 4-vertex gate and without a gate.
#[test]
fn swap_roles_transposes_the_matrix() {
    let s = scene("two_patches");
    let (pa, pb) = (centre(&s, "A"), centre(&s, "B"));
    let p: Point = [0.05, 0.1, 1.0];
    for stem in ["two_patches", "two_patches_line"] {
        let mut c = fixture(stem);
        let mut sw = vltm::io::swap_roles(&c).expect("swap");
        assert_eq!(sw.geometry.lasers, c.geometry.spads);
        assert_eq!(sw.geometry.spads, c.geometry.lasers);
        for gate in [ColumnGate::TwoBounce, ColumnGate::None] {
            // The largest |T(a,b) − T(b,a)| / T(b,a) over the pairs: the matrix is not
            // symmetric, so the check below could tell a transpose from no swap at all.
            let mut asym = 0.0f32;
            for (a, b) in [(pa, pb), (pb, pa), (pa, p), (p, pb)] {
                let t = |c: &mut Capture, f: Point, x: Point| {
                    let v = Volume::points(vec![x]).expect("point");
                    // Default λ: twice the coarser pitch of both apertures, the same after a swap.
                    probe::column(c, f, &v, gate, Shell::ALL, &Wave::default(), EXEC)
                        .expect("column")
                        .values[0]
                };
                let (t_swap, t_ba) = (t(&mut sw, a, b), t(&mut c, b, a));
                asym = asym.max((t(&mut c, a, b) - t_ba).abs() / t_ba);
                let rel = (t_swap - t_ba).abs() / t_swap.abs().max(t_ba.abs());
                println!(
                    "{stem}, {gate:?}: T_swap({a:?}, {b:?}) = {t_swap:.6e}, T(b, a) = {t_ba:.6e}, rel. diff {rel:.1e}"
                );
                assert!(t_ba > 0.0, "{stem}: T(b,a) = {t_ba}");
                assert!(
                    rel <= 1e-4,
                    "{stem}, {gate:?}: T_swap(a,b) = {t_swap:e} but T(b,a) = {t_ba:e} (rel. diff {rel:e})"
                );
            }
            println!("{stem}, {gate:?}: largest |T(a,b) - T(b,a)| / T(b,a) = {asym:.2e}");
            if c.geometry.lasers == c.geometry.spads {
                // Identical laser and SPAD grids: H(l,s,t) = H(s,l,t) (the simulator is
                // reciprocal), so T itself is symmetric and the swap is a no-op.
                assert!(
                    asym <= 1e-4,
                    "{stem}, {gate:?}: T(a,b) should equal T(b,a) for identical grids ({asym:e})"
                );
            } else {
                // Different apertures: T is not symmetric, so the equalities above tell a
                // transpose from no swap at all.
                assert!(
                    asym > 0.01,
                    "{stem}, {gate:?}: T is symmetric on these pairs ({asym:e}): pick asymmetric ones"
                );
            }
        }
    }
}

/// The simulator streamed row by row (`Scene::source`) gives the same direct image as its
/// rendered capture.
#[test]
fn streamed_scene_equals_rendered_capture() {
    let vol = volume();
    let s = scene("two_patches");
    let mut rendered = s.render().expect("render");
    let mut streamed = s.source().expect("source");
    let w = Wave::default();
    let a = probe::direct(&mut rendered, &vol, &w, EXEC).expect("direct");
    let b = probe::direct(&mut streamed, &vol, &w, EXEC).expect("direct");
    let max = max_of(&a.values);
    let diff = a
        .values
        .iter()
        .zip(&b.values)
        .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
    println!(
        "direct image: max |streamed - rendered| = {diff:e} (peak {max:e}); rows {} / {}",
        b.report.rows, a.report.rows
    );
    assert!(max > 0.0, "empty direct image");
    assert_eq!(a.report.rows, b.report.rows, "rows streamed");
    assert!(
        diff <= 1e-6 * max,
        "streamed and rendered direct images differ by {diff:e} (peak {max:e})"
    );
}

/// `RowSource::iter_rows` yields every laser row in scan order, equal to `read_row`, from an
/// in-memory capture, a streamed `.npz` and a streamed y-tal HDF5 file.
#[test]
fn iter_rows_yields_the_scan_in_order() {
    use vltm::io::RowSource;
    fn check(src: &mut dyn FnMut() -> Box<dyn RowSource>, what: &str) {
        let a = src();
        let n = a.geometry().lasers.len();
        let mut b = src();
        let mut buf = Vec::new();
        let mut count = 0;
        // `iter_rows` needs a sized source: wrap the box.
        struct Boxed(Box<dyn RowSource>);
        impl RowSource for Boxed {
            fn geometry(&self) -> &vltm::io::Geometry {
                self.0.geometry()
            }
            fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> vltm::Result<Point> {
                self.0.read_row(l, out)
            }
        }
        let mut boxed = Boxed(a);
        let it = boxed.iter_rows();
        assert_eq!(it.size_hint(), (n, Some(n)), "{what}");
        for (l, row) in it.enumerate() {
            let (laser, h) = row.unwrap_or_else(|e| panic!("{what}: {e}"));
            let p = b.read_row(l, &mut buf).expect("read_row");
            assert_eq!((laser, &h), (p, &buf), "{what}: row {l}");
            count += 1;
        }
        assert_eq!(count, n, "{what}");
    }
    let npz = capture_path("two_patches_line");
    check(&mut || Box::new(io::open(&npz).expect("npz")), "in memory");
    let tmp = std::env::temp_dir().join(format!("vltm-rows-{}.npz", std::process::id()));
    io::npz::write_with(&io::open(&npz).expect("npz"), &tmp, false).expect("write");
    check(
        &mut || Box::new(io::npz::open_stream(&tmp).expect("stream").expect("stored")),
        "streamed .npz",
    );
    let _ = std::fs::remove_file(&tmp);
    let h5 = support::fixture("ytal/line/line.hdf5");
    check(
        &mut || Box::new(vltm::io::tal::open(&h5).expect("tal")),
        "y-tal HDF5",
    );
}

/// The factorised column cannot zero single paths the way the diagonal's guard does; with
/// `Wave::auto_margin` (the default) the DFT period is widened until every path time of the
/// column is alias-free, so voxels whose paths all lie far beyond the capture's window get
/// (almost) nothing instead of wrapped-around light, and in-window voxels keep their values.
#[test]
fn auto_margin_keeps_columns_alias_free() {
    let s = scene("two_patches");
    let a = centre(&s, "A");
    // B's voxel, and voxels 3.2–4 m deep whose 4-vertex paths (≈ 7.5 m) end ~1 DFT period
    // after the 4.48 m window: without a margin they wrap onto the patches' returns.
    let b = centre(&s, "B");
    let mut pts = vec![b];
    for i in 0..5 {
        for j in 0..3 {
            for k in 0..5 {
                pts.push([
                    -0.4 + 0.2 * i as f32,
                    -0.2 + 0.2 * j as f32,
                    3.2 + 0.2 * k as f32,
                ]);
            }
        }
    }
    let vol = Volume::points(pts).expect("volume");
    let run = |auto_margin: bool| {
        let wave = Wave {
            auto_margin,
            ..indirect_wave(&fixture("two_patches").geometry)
        };
        probe::column(
            &mut fixture("two_patches"),
            a,
            &vol,
            ColumnGate::TwoBounce,
            Shell::ALL,
            &wave,
            EXEC,
        )
        .expect("column")
    };
    let (plain, auto) = (run(false), run(true));
    let far = |o: &probe::Output| max_of(&o.values[1..]);
    println!(
        "far voxels: max {:.3e} without margin ({} aliased, N = {}), {:.3e} with the automatic \
         margin ({} aliased, N = {}); at B {:.4e} vs {:.4e}",
        far(&plain),
        plain.report.aliased,
        plain.config.n_fft(),
        far(&auto),
        auto.report.aliased,
        auto.config.n_fft(),
        plain.values[0],
        auto.values[0]
    );
    assert!(
        plain.report.aliased > 0,
        "the far voxels should alias without a margin"
    );
    assert_eq!(
        auto.report.aliased, 0,
        "aliased voxels with the automatic margin"
    );
    assert!(auto.config.n_fft() > plain.config.n_fft());
    assert!(
        far(&auto) <= 1e-3 * far(&plain),
        "far voxels: {:.3e} with the margin vs {:.3e} wrapped",
        far(&auto),
        far(&plain)
    );
    let rel = (auto.values[0] - plain.values[0]).abs() / plain.values[0];
    assert!(rel < 1e-3, "T(A, B) moved by {rel:.2e} with the margin");
}

/// Every reader refuses a laser row past the scan with the one message of
/// `io::check_row`: the capture in memory (it panicked), a streamed uncompressed `.npz` and
/// the simulator's row source.
#[test]
fn every_reader_refuses_an_out_of_range_row_alike() {
    use vltm::io::RowSource;
    let c = fixture("two_patches");
    let kl = c.geometry.lasers.len();
    let want = io::check_row(kl, kl).unwrap_err().to_string();
    let dir = std::env::temp_dir().join(format!("vltm-e2e-rows-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let npz = dir.join("plain.npz");
    io::npz::write_with(&c, &npz, false).expect("write npz");
    let mut sources: Vec<(&str, Box<dyn RowSource>)> = vec![
        ("in memory", Box::new(c.clone())),
        ("npz stream", io::open_source(&npz).expect("open npz")),
        (
            "simulator",
            Box::new(scene("two_patches").source().expect("source")),
        ),
    ];
    let mut row = Vec::new();
    for (name, src) in &mut sources {
        assert_eq!(src.geometry().lasers.len(), kl, "{name}");
        src.read_row(kl - 1, &mut row)
            .unwrap_or_else(|e| panic!("{name}: last row: {e}"));
        let e = src.read_row(kl, &mut row).expect_err(name);
        assert_eq!(e.to_string(), want, "{name}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The in-focus indirect sum's counters hold the aliased pairs of every focus of Γ, as the
/// single columns count them (it kept only the last focus's count).
#[test]
fn indirect_counts_the_aliased_pairs_of_every_focus() {
    let band = Exec {
        progress: None,
        path: vltm::probe::EvalPath::Band,
    };
    let s = scene("two_patches");
    // Uncropped: a time axis cropped to the voxels' reach keeps every pair in the window.
    let wave = Wave {
        auto_margin: false,
        crop: false,
        ..indirect_wave(&fixture("two_patches").geometry)
    };
    // Foci: the patches and deeper voxels whose 4-vertex paths to the far foci leave the
    // capture's window (no margin: those pairs alias). A focus none of whose paths the
    // capture saw is refused by the column; it is left out until every column runs.
    let mut pts = vec![centre(&s, "A"), centre(&s, "B")];
    // Depths in fine steps: a focus none of whose paths meets the window is refused (the
    // window rule), so the aliasing foci are those just short of that.
    for k in 0..16 {
        pts.push([0.1 * (k % 3) as f32 - 0.1, 0.0, 1.6 + 0.075 * k as f32]);
    }
    let column = |a, vol: &Volume| {
        let c = &mut fixture("two_patches");
        probe::column(c, a, vol, ColumnGate::TwoBounce, Shell::ALL, &wave, band)
    };
    let (vol, per) = loop {
        let vol = Volume::points(pts.clone()).expect("volume");
        let runs: Vec<_> = vol.points.iter().map(|&a| column(a, &vol)).collect();
        match runs.iter().position(Result::is_err) {
            Some(i) => {
                pts.remove(i);
            }
            None => {
                let per: Vec<usize> = runs
                    .into_iter()
                    .map(|r| r.expect("column").report.aliased)
                    .collect();
                break (vol, per);
            }
        }
    };
    let gamma = vec![true; vol.len()];
    let opts = IndirectOptions {
        shell: Some(Shell::ALL),
        ..IndirectOptions::default()
    };
    let out = probe::indirect_over(
        &mut fixture("two_patches"),
        &vol,
        &gamma,
        &opts,
        &wave,
        band,
    )
    .expect("indirect");
    println!(
        "foci {:?}: aliased voxels per focus {per:?}, indirect {}",
        vol.points, out.report.aliased
    );
    assert!(
        per.iter().filter(|&&n| n > 0).count() >= 2,
        "the test needs several foci with aliased pairs: {per:?}"
    );
    assert_eq!(out.report.aliased, per.iter().sum::<usize>());
    assert_eq!(
        out.report.rows,
        fixture("two_patches").geometry.lasers.len() as u64
    );
}
