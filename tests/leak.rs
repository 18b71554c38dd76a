//! Leak-corrected in-focus indirect light (`vltm::probe::DirectModel`, `--leak-correct`)
//! against the direct-only control, as means over the lit object's voxels (its surface ± one
//! voxel), on two scenes with the same settings:
//!
//! * the shared path-traced `two_patches` / `two_patches_direct_only` (mitransient, tal HDF5,
//!   8×8 lasers × 8×8 SPADs): patch B, lit by patch A;
//! * a panel lighting a figure (the demo's scene at 16×16 lasers × 16×16 SPADs), rendered in
//!   the test by the simulator twice (all paths / direct only).
//!
//! Settings, the same on both: λ = twice the aperture pitch (the default), σ = 2λ/3 (default),
//! the paper's 1/d lens weights, Γ = {I_d > 0.1·max} from the full capture's diagonal, r0 =
//! 1.5σ (default), the fit's defaults ([`LeakOptions::default`]). The control gets the same
//! correction (its own fit over the same Γ). Measured values are printed (`--nocapture`).

use std::path::PathBuf;
use vltm::io::{self, Capture, RowSource};
use vltm::kernel::Point;
use vltm::probe::{self, Exec, IndirectOptions, LeakMethod, LeakOptions, Wave};
use vltm::sim::{Aperture, Bounces, Cuboid, Patch, Scene, Setup};
use vltm::volume::Volume;

const EXEC: Exec<'static> = Exec {
    progress: None,
    path: vltm::probe::Path::Auto,
};

fn shared(capture: &str, file: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(capture)
        .join(file)
}

/// Voxels of an object: the voxels its surface passes through (the nearest voxel of each
/// of a dense set of surface points), grown by one voxel in every grid direction.
pub fn object_voxels(vol: &Volume, surface: &[Point]) -> Vec<usize> {
    let [nx, ny, nz] = vol.shape;
    let mut on = vec![false; vol.len()];
    for p in surface {
        on[vol.nearest(*p)] = true;
    }
    let mut grown = on.clone();
    for i in (0..vol.len()).filter(|&i| on[i]) {
        let (ix, iy, iz) = (i / (ny * nz), (i / nz) % ny, i % nz);
        let r = |c: usize, n: usize| c.saturating_sub(1)..=(c + 1).min(n - 1);
        for jx in r(ix, nx) {
            for jy in r(iy, ny) {
                for jz in r(iz, nz) {
                    grown[(jx * ny + jy) * nz + jz] = true;
                }
            }
        }
    }
    (0..vol.len()).filter(|&i| grown[i]).collect()
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

/// Patch B of the shared two_patches scene (corners from its `scene.json`).
fn patch_b() -> Vec<Point> {
    let path = shared("two_patches", "scene.json");
    let text = std::fs::read_to_string(&path).unwrap();
    let j: serde_json::Value = serde_json::from_str(&text).unwrap();
    let corners = &j["objects"]["patch_B"]["corners"];
    let c: [[f64; 3]; 4] =
        core::array::from_fn(|i| core::array::from_fn(|k| corners[i][k].as_f64().unwrap()));
    quad(c, 40)
}

fn mean(v: &[f32], idx: &[usize]) -> f64 {
    idx.iter().map(|&i| f64::from(v[i])).sum::<f64>() / idx.len() as f64
}

/// Object-voxel means of I_i on the full capture and the control (same Γ, from the full
/// capture's diagonal), with `leak` correction or without.
struct Means {
    full: f64,
    control: f64,
    gamma: usize,
    explained: (f64, f64),
}

fn measure(
    full: &mut dyn RowSource,
    control: &mut dyn RowSource,
    vol: &Volume,
    wave: &Wave,
    object: &[usize],
    leak: Option<LeakOptions>,
) -> Means {
    let d = probe::direct(full, vol, wave, EXEC).expect("direct");
    let gamma = probe::gamma_mask(&d.values, 0.1);
    let opts = IndirectOptions {
        leak,
        ..IndirectOptions::default()
    };
    let f = probe::indirect_over(full, vol, &gamma, &opts, wave, EXEC).expect("indirect");
    let c = probe::indirect_over(control, vol, &gamma, &opts, wave, EXEC).expect("indirect");
    Means {
        full: mean(&f.values, object),
        control: mean(&c.values, object),
        gamma: gamma.iter().filter(|&&g| g).count(),
        explained: (f.explained.unwrap_or(0.0), c.explained.unwrap_or(0.0)),
    }
}

fn report(name: &str, m: &Means) -> f64 {
    let r = m.full / m.control;
    println!(
        "{name}: Γ {} voxels; I_i mean over the object's voxels {:.4e} vs control {:.4e}: {r:.2}x \
         (direct model explains {:.4} / {:.4})",
        m.gamma, m.full, m.control, m.explained.0, m.explained.1
    );
    r
}

fn tal_wave(g: &vltm::io::Geometry) -> Wave {
    let _ = g;
    Wave {
        compensate_laser: true,
        ..Wave::default()
    }
}

#[test]
fn two_patches_leak_corrected() {
    let vol = Volume::parse("-0.75:0.75:16,-0.75:0.75:16,0.4:1.35:20").unwrap();
    let b = object_voxels(&vol, &patch_b());
    let open = |n: &str| io::open(&shared(n, &format!("{n}.hdf5"))).unwrap();
    let (mut full, mut ctrl) = (open("two_patches"), open("two_patches_direct_only"));
    let wave = tal_wave(&full.geometry);
    let plain = measure(&mut full, &mut ctrl, &vol, &wave, &b, None);
    report("two_patches, Eq. 17", &plain);
    for lo in variants() {
        let m = measure(&mut full, &mut ctrl, &vol, &wave, &b, Some(lo));
        report(&format!("two_patches, leak-corrected {lo:?}"), &m);
    }
    // The indirect-only truth: H − H_control.
    let mut diff: Capture = full.clone();
    diff.data
        .iter_mut()
        .zip(&ctrl.data)
        .for_each(|(a, b)| *a -= b);
    let d = probe::direct(&mut full, &vol, &wave, EXEC).expect("direct");
    let gamma = probe::gamma_mask(&d.values, 0.1);
    let t = probe::indirect_over(
        &mut diff,
        &vol,
        &gamma,
        &IndirectOptions::default(),
        &wave,
        EXEC,
    )
    .unwrap();
    println!("indirect-only truth mean {:.4e}", mean(&t.values, &b));
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

#[test]
fn panel_figure_16_leak_corrected() {
    let vol = Volume::grid([-0.6, -0.3, 0.5], [0.6, 0.3, 1.22], [21, 11, 13]).unwrap();
    let fig = object_voxels(&vol, &figure_surface());
    let mut full = panel_scene(Bounces::All).render().unwrap();
    let mut ctrl = panel_scene(Bounces::Direct).render().unwrap();
    let wave = Wave::default();
    let plain = measure(&mut full, &mut ctrl, &vol, &wave, &fig, None);
    report("panel/figure 16, Eq. 17", &plain);
    let mut diff: Capture = full.clone();
    diff.data
        .iter_mut()
        .zip(&ctrl.data)
        .for_each(|(a, b)| *a -= b);
    let d = probe::direct(&mut full, &vol, &wave, EXEC).expect("direct");
    let gamma = probe::gamma_mask(&d.values, 0.1);
    let t = probe::indirect_over(
        &mut diff,
        &vol,
        &gamma,
        &IndirectOptions::default(),
        &wave,
        EXEC,
    )
    .unwrap();
    println!("indirect-only truth mean {:.4e}", mean(&t.values, &fig));
    for lo in variants() {
        let m = measure(&mut full, &mut ctrl, &vol, &wave, &fig, Some(lo));
        report(&format!("panel/figure 16, leak-corrected {lo:?}"), &m);
    }
}

fn variants() -> Vec<LeakOptions> {
    vec![
        LeakOptions::default(),
        LeakOptions {
            cells: 1.0,
            ..LeakOptions::default()
        },
    ]
}
