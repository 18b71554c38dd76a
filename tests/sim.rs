//! The transient simulator (`vltm::sim`) against the numpy prototype `reference/sim.py`
//! (`fixtures/sim/reference.json`, made by `python3 fixtures/sim/make_reference.py`), and its own
//! invariants: bounce filters, Poisson noise, scene validation, boxes, 5-vertex paths, confocal
//! rows, row streaming.
//!
//! `cargo test --release -p vltm-suite --test sim`; the render-time measurement of a 16×16 ×
//! 16×16 × 800-bin scene is `-- --ignored --nocapture`.

use std::path::PathBuf;

use vltm::Error;
use vltm::io::RowSource;
use vltm::sim::{Aperture, Bounces, Cuboid, Noise, Object, Patch, PointScatterer, Scene, Setup};

mod support;

/// `fixtures/sim/<name>`, checked (`support::fixture`).
fn fixture(name: &str) -> PathBuf {
    support::fixture(&format!("sim/{name}"))
}

/// Accessors for the reference file (panicking with the key: a test helper).
trait Json {
    fn key(&self, key: &str) -> &Self;
    fn num(&self) -> f64;
    fn nums(&self) -> Vec<f64>;
    fn vec3s(&self) -> Vec<[f64; 3]>;
}

impl Json for serde_json::Value {
    fn key(&self, key: &str) -> &Self {
        self.as_object()
            .and_then(|o| o.get(key))
            .unwrap_or_else(|| panic!("no key {key}"))
    }
    fn num(&self) -> f64 {
        self.as_f64()
            .unwrap_or_else(|| panic!("not a number: {self}"))
    }
    fn nums(&self) -> Vec<f64> {
        self.as_array()
            .expect("an array")
            .iter()
            .map(Json::num)
            .collect()
    }
    fn vec3s(&self) -> Vec<[f64; 3]> {
        let arr = self.as_array().expect("an array");
        arr.iter()
            .map(|v| <[f64; 3]>::try_from(v.nums()).expect("3-vector"))
            .collect()
    }
}

fn reference() -> serde_json::Value {
    let path = fixture("reference.json");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e} (run python3 fixtures/sim/make_reference.py)",
            path.display()
        )
    });
    serde_json::from_str(&text).expect("valid JSON")
}

fn small_scene() -> Scene {
    Scene::load(fixture("small_scene.json")).expect("fixtures/sim/small_scene.json")
}

/// `max |x − y| / max |y|`.
fn rel_diff(x: &[f32], y: &[f64]) -> f64 {
    assert_eq!(x.len(), y.len());
    let scale = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(scale > 0.0);
    x.iter()
        .zip(y)
        .fold(0.0f64, |m, (&a, &b)| m.max((f64::from(a) - b).abs()))
        / scale
}

fn render(scene: &Scene) -> Vec<f32> {
    scene.render().expect("render").data
}

// ---------------------------------------------------------------------------------------------
// against sim.py
// ---------------------------------------------------------------------------------------------

#[test]
fn geometry_and_samples_match_the_prototype() {
    let r = reference();
    let scene = small_scene();
    let geo = scene.geometry();
    let setup = r.key("setup");
    for (ours, theirs) in [
        (&geo.lasers, setup.key("lasers")),
        (&geo.spads, setup.key("spads")),
    ] {
        let theirs = theirs.vec3s();
        assert_eq!(ours.len(), theirs.len());
        for (a, b) in ours.iter().zip(&theirs) {
            for k in 0..3 {
                assert!((f64::from(a[k]) - b[k]).abs() < 1e-7, "spot {a:?} vs {b:?}");
            }
        }
    }
    assert_eq!(geo.laser_shape, [3, 3]);
    assert_eq!(geo.spad_shape, [2, 2]);
    assert!(geo.legs_in_time);
    assert_eq!((geo.nt, geo.dt, geo.t0), (260, 0.01, 1.5));

    let sc = r.key("scene");
    let (points, normals) = (sc.key("points").vec3s(), sc.key("normals").vec3s());
    let (areas, albedo, group) = (
        sc.key("areas").nums(),
        sc.key("albedo").nums(),
        sc.key("group").nums(),
    );
    let ours = scene.sample_points();
    assert_eq!(ours.len(), points.len());
    for (i, p) in ours.iter().enumerate() {
        let n = p.normal.expect("patch normal");
        for k in 0..3 {
            assert!((p.position[k] - points[i][k]).abs() < 1e-12, "point {i}");
            assert!((n[k] - normals[i][k]).abs() < 1e-12, "normal {i}");
        }
        assert!((p.area - areas[i]).abs() < 1e-15 && (p.albedo - albedo[i]).abs() < 1e-15);
        assert_eq!(p.group as f64, group[i]);
    }
}

#[test]
fn renders_match_the_prototype() {
    let r = reference();
    let cases = r.key("cases");
    let base = small_scene();
    let shape = r.key("shape").nums();
    assert_eq!(shape, [9.0, 4.0, 260.0]);

    let mut scene = base.clone();
    for (case, bounces) in [
        ("all", Bounces::All),
        ("direct", Bounces::Direct),
        ("indirect", Bounces::Indirect),
    ] {
        scene.bounces = bounces;
        let d = rel_diff(&render(&scene), &cases.key(case).nums());
        println!("{case:>16}: max |diff| / max |H| = {d:.2e}");
        assert!(d <= 1e-5, "{case}: {d:.2e}");
    }

    // 5-vertex paths (sim.py's are isotropic: compare with cosines off).
    let mut scene = base;
    scene.cosines = false;
    scene.max_vertices = 5;
    let five = render(&scene);
    let d = rel_diff(&five, &cases.key("five_nocos").nums());
    println!("{:>16}: max |diff| / max |H| = {d:.2e}", "five_nocos");
    assert!(d <= 1e-5, "five_nocos: {d:.2e}");

    scene.bounces = Bounces::Indirect;
    let upto5 = render(&scene);
    scene.max_vertices = 4;
    let upto4 = render(&scene);
    let only5: Vec<f32> = upto5.iter().zip(&upto4).map(|(a, b)| a - b).collect();
    let d = rel_diff(&only5, &cases.key("five_only_nocos").nums());
    println!("{:>16}: max |diff| / max |H| = {d:.2e}", "five_only_nocos");
    assert!(d <= 1e-4, "five_only_nocos: {d:.2e}"); // a difference of two f32 renders
}

// ---------------------------------------------------------------------------------------------
// invariants
// ---------------------------------------------------------------------------------------------

#[test]
fn direct_plus_indirect_is_all() {
    for max_vertices in [4, 5] {
        let mut scene = small_scene();
        scene.max_vertices = max_vertices;
        let all = render(&scene);
        scene.bounces = Bounces::Direct;
        let direct = render(&scene);
        scene.bounces = Bounces::Indirect;
        let indirect = render(&scene);
        let peak = all.iter().fold(0.0f32, |m, &v| m.max(v));
        let worst = (0..all.len())
            .map(|i| (direct[i] + indirect[i] - all[i]).abs())
            .fold(0.0f32, f32::max);
        assert!(
            worst <= 1e-6 * peak,
            "max_vertices {max_vertices}: {worst} vs peak {peak}"
        );
        assert!(indirect.iter().any(|&v| v > 0.0) && direct.iter().any(|&v| v > 0.0));
    }
}

#[test]
fn render_row_and_source_match_render() {
    let scene = small_scene();
    let capture = scene.render().unwrap();
    let mut source = scene.source().unwrap();
    let mut row = Vec::new();
    for l in [0, 4, 8] {
        let spot = scene.render_row(l, &mut row).unwrap();
        assert_eq!(row.as_slice(), capture.row(l));
        assert_eq!(spot, capture.geometry.lasers[l]);
        source.read_row(l, &mut row).unwrap();
        assert_eq!(row.as_slice(), capture.row(l));
    }
    assert_eq!(source.geometry(), &capture.geometry);
    assert!(matches!(
        source.read_row(9, &mut row),
        Err(Error::Argument { .. })
    ));
    assert!(scene.render_row(9, &mut row).is_err());
}

#[test]
fn confocal_rows_are_the_diagonal_of_the_full_capture() {
    let grid = Aperture::grid([3, 2], [0.6, 0.4], [0.05, 0.0]);
    let mut full = small_scene();
    full.setup.lasers = grid.clone();
    full.setup.spads = Some(grid.clone());
    full.max_vertices = 5;
    let mut confocal = full.clone();
    confocal.setup.confocal = true;
    confocal.setup.spads = None;
    let (a, b) = (full.render().unwrap(), confocal.render().unwrap());
    assert_eq!(b.geometry.spads_per_row(), 1);
    assert_eq!(b.geometry.spads, b.geometry.lasers);
    let nt = a.geometry.nt;
    for l in 0..6 {
        assert_eq!(&a.row(l)[l * nt..(l + 1) * nt], b.row(l));
    }
    assert!(b.data.iter().any(|&v| v > 0.0));
}

#[test]
fn poisson_noise_is_seeded_and_has_the_expected_mean() {
    let clean = small_scene();
    let h = render(&clean);
    let max = h.iter().fold(0.0f32, |m, &v| m.max(v));
    let noise = Noise {
        peak_counts: 200.0,
        background: 0.5,
        seed: 7,
    };
    let mut scene = clean.clone();
    scene.noise = Some(noise);
    let a = render(&scene);
    let b = render(&scene);
    assert_eq!(a, b, "same seed, same counts");
    scene.noise = Some(Noise { seed: 8, ..noise });
    assert_ne!(a, render(&scene), "another seed, other counts");
    assert!(
        a.iter().all(|&v| v >= 0.0 && v.fract() == 0.0),
        "counts are whole numbers, not scaled back"
    );

    let lambda: Vec<f64> = h
        .iter()
        .map(|&v| f64::from(v) * 200.0 / f64::from(max) + 0.5)
        .collect();
    let total: f64 = lambda.iter().sum();
    let counts: f64 = a.iter().map(|&v| f64::from(v)).sum();
    assert!(
        (counts - total).abs() < 5.0 * total.sqrt(),
        "Σ counts {counts} vs expected {total}"
    );
    // Background-only bins: mean 0.5.
    let bg: Vec<f64> = (0..h.len())
        .filter(|&i| h[i] == 0.0)
        .map(|i| f64::from(a[i]))
        .collect();
    assert!(bg.len() > 1000);
    let mean = bg.iter().sum::<f64>() / bg.len() as f64;
    assert!(
        (mean - 0.5).abs() < 5.0 * (0.5 / bg.len() as f64).sqrt(),
        "background mean {mean}"
    );
    // The brightest bin: expected 200.5 counts.
    let peak_bin = (0..h.len()).max_by(|&i, &j| h[i].total_cmp(&h[j])).unwrap();
    assert!((f64::from(a[peak_bin]) - 200.5).abs() < 6.0 * 200.5f64.sqrt());

    // Noise::apply on a buffer with the same seed gives the same counts as render.
    let mut buf = h.clone();
    noise.apply(&mut buf, 4 * 260).unwrap();
    assert_eq!(buf, a);
}

#[test]
fn a_box_is_six_outward_faces() {
    let (c, size, n) = ([0.1, -0.05, 0.7], [0.2, 0.3, 0.4], 3);
    let cube = Cuboid {
        samples: n,
        albedo: 0.8,
        ..Cuboid::new("C", c, size)
    };
    let mut scene = Scene::new(Setup::new(
        Aperture::grid([4, 4], [1.0, 1.0], [0.0, 0.0]),
        Aperture::grid([3, 3], [0.8, 0.8], [0.0, 0.0]),
        300,
        0.01,
    ))
    .with(cube.clone());
    let pts = scene.sample_points();
    assert_eq!(pts.len(), 6 * n * n);
    assert!(pts.iter().all(|p| p.group == 0 && p.albedo == 0.8));
    let area: f64 = pts.iter().map(|p| p.area).sum();
    let want = 2.0 * (size[0] * size[1] + size[1] * size[2] + size[0] * size[2]);
    assert!((area - want).abs() < 1e-12, "area {area} vs {want}");
    let mut per_normal = std::collections::HashMap::new();
    for p in &pts {
        let nrm = p.normal.unwrap();
        let axis = (0..3).find(|&k| nrm[k] != 0.0).unwrap();
        assert_eq!(
            nrm.iter().filter(|v| **v != 0.0).count(),
            1,
            "axis-aligned unit normal"
        );
        // On the face plane, on the outward side, inside the face.
        assert!((p.position[axis] - c[axis] - nrm[axis] * size[axis] / 2.0).abs() < 1e-12);
        for k in 0..3 {
            assert!((p.position[k] - c[k]).abs() <= size[k] / 2.0 + 1e-12);
        }
        *per_normal.entry(nrm.map(|v| v as i32)).or_insert(0) += 1;
    }
    assert_eq!(per_normal.len(), 6);
    assert!(per_normal.values().all(|&k| k == n * n));
    assert_eq!(scene.object_centre("C"), Some(c.map(|v| v as f32)));

    // Direct light: the box equals its five faces that can see the wall; the back face
    // (+z, facing away) receives nothing.
    scene.bounces = Bounces::Direct;
    let boxed = render(&scene);
    let face = |axis: usize, sign: f64, sides: [f64; 2]| {
        let mut fc = c;
        fc[axis] += sign * size[axis] / 2.0;
        let mut nrm = [0.0; 3];
        nrm[axis] = sign;
        Patch {
            samples: n,
            albedo: 0.8,
            ..Patch::new("", fc, nrm, sides)
        }
    };
    let faces = [
        face(0, 1.0, [size[2], size[1]]),
        face(0, -1.0, [size[2], size[1]]),
        face(1, 1.0, [size[2], size[0]]),
        face(1, -1.0, [size[2], size[0]]),
        face(2, -1.0, [size[0], size[1]]),
    ];
    let mut open = Scene {
        objects: Vec::new(),
        ..scene.clone()
    };
    for f in faces {
        open = open.with(f);
    }
    let five_faces = render(&open);
    let peak = boxed.iter().fold(0.0f32, |m, &v| m.max(v));
    assert!(peak > 0.0);
    let worst = boxed
        .iter()
        .zip(&five_faces)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(
        worst <= 1e-6 * peak,
        "box vs five faces: {worst} (peak {peak})"
    );
    // ... and a convex box does not light itself.
    scene.bounces = Bounces::Indirect;
    assert!(render(&scene).iter().all(|&v| v == 0.0));
}

/// A box turned by `normal`: its samples lie on its six faces in its own frame, with outward
/// normals along its axes and the full surface area; `[0, 0, −1]` is the axis-aligned box
/// (the same sample points); turning the box changes what the wall sees; and the turned box
/// is still closed (no light from itself).
#[test]
fn a_turned_box_has_its_faces_along_its_axes() {
    let (c, size, n) = ([0.1, -0.05, 0.7], [0.2, 0.3, 0.4], 3);
    let setup = Setup::new(
        Aperture::grid([4, 4], [1.0, 1.0], [0.0, 0.0]),
        Aperture::grid([3, 3], [0.8, 0.8], [0.0, 0.0]),
        300,
        0.01,
    );
    let turned = |normal: Option<[f64; 3]>| Cuboid {
        samples: n,
        normal,
        ..Cuboid::new("C", c, size)
    };
    let sorted = |b: Cuboid| {
        let mut v: Vec<[f64; 7]> = Scene::new(setup.clone())
            .with(b)
            .sample_points()
            .iter()
            .map(|p| {
                let q = p.normal.unwrap();
                [
                    p.position[0],
                    p.position[1],
                    p.position[2],
                    q[0],
                    q[1],
                    q[2],
                    p.area,
                ]
            })
            .map(|v| v.map(|x| (x * 1e9).round() / 1e9 + 0.0))
            .collect();
        v.sort_by(|a, b| a.partial_cmp(b).unwrap());
        v
    };
    assert_eq!(sorted(turned(None)), sorted(turned(Some([0.0, 0.0, -2.0]))));

    let b = turned(Some([1.0, 0.3, -1.0]));
    let u = b.axes();
    for i in 0..3 {
        for j in 0..3 {
            let d: f64 = (0..3).map(|k| u[i][k] * u[j][k]).sum();
            assert!(
                (d - f64::from(u8::from(i == j))).abs() < 1e-12,
                "axes not orthonormal"
            );
        }
    }
    let front = [1.0, 0.3, -1.0].map(|x: f64| x / (2.09f64).sqrt());
    assert!(
        (0..3).all(|k| (u[2][k] + front[k]).abs() < 1e-12),
        "front face normal"
    );
    let pts = Scene::new(setup.clone()).with(b.clone()).sample_points();
    assert_eq!(pts.len(), 6 * n * n);
    let area: f64 = pts.iter().map(|p| p.area).sum();
    let want = 2.0 * (size[0] * size[1] + size[1] * size[2] + size[0] * size[2]);
    assert!((area - want).abs() < 1e-12, "area {area} vs {want}");
    for p in &pts {
        let local: [f64; 3] =
            std::array::from_fn(|i| (0..3).map(|k| (p.position[k] - c[k]) * u[i][k]).sum());
        let nrm = p.normal.unwrap();
        let along: [f64; 3] = std::array::from_fn(|i| (0..3).map(|k| nrm[k] * u[i][k]).sum());
        let axis = (0..3)
            .max_by(|&i, &j| along[i].abs().total_cmp(&along[j].abs()))
            .unwrap();
        assert!(
            (along[axis].abs() - 1.0).abs() < 1e-12,
            "normal along an axis: {along:?}"
        );
        // On that face (outward side), inside it.
        assert!(
            (local[axis] - along[axis] * size[axis] / 2.0).abs() < 1e-12,
            "{local:?}"
        );
        assert!(
            (0..3).all(|k| local[k].abs() <= size[k] / 2.0 + 1e-12),
            "{local:?}"
        );
    }
    let mut scene = Scene::new(setup).with(b);
    scene.bounces = Bounces::Direct;
    let h_turned = render(&scene);
    let mut straight = scene.clone();
    straight.objects = vec![turned(None).into()];
    let h_straight = render(&straight);
    assert!(h_turned.iter().any(|&v| v > 0.0));
    assert!(h_turned != h_straight, "turning the box changed nothing");
    scene.bounces = Bounces::Indirect;
    assert!(
        render(&scene).iter().all(|&v| v == 0.0),
        "a closed box lights itself"
    );
}

#[test]
fn five_vertex_paths_appear_only_with_max_vertices_5_at_their_time() {
    let (la, sp) = ([-0.1, 0.0, 0.0], [0.15, 0.05, 0.0]);
    let (a, b) = ([-0.2, 0.0, 0.5], [0.25, 0.1, 0.6]);
    let (area_a, area_b) = (0.02, 0.03);
    let mut setup = Setup::new(
        Aperture::points(vec![la]),
        Aperture::points(vec![sp]),
        800,
        0.005,
    );
    setup.t0 = 0.5;
    let mut scene = Scene::new(setup)
        .with(PointScatterer::new("A", a, area_a))
        .with(PointScatterer {
            albedo: 0.9,
            ..PointScatterer::new("B", b, area_b)
        });
    scene.pulse_sigma = Some(0.01);
    scene.bounces = Bounces::Indirect;
    let d = |p: [f64; 3], q: [f64; 3]| {
        ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
    };
    let pi = std::f64::consts::PI;
    let (ka, kb) = (area_a / pi, 0.9 * area_b / pi);
    let dab = d(a, b);
    // wall cosines (emission at the laser spot, reception at the SPAD)
    let wl = |p: [f64; 3]| p[2] / d(la, p) / d(la, p).powi(2);
    let ws = |p: [f64; 3]| p[2] / d(sp, p) / d(sp, p).powi(2);
    // The 5-vertex paths of two objects: A→B→A and B→A→B.
    let paths5 = [
        (
            d(la, a) + 2.0 * dab + d(a, sp) - 0.5,
            ka * kb * ka / dab.powi(4) * wl(a) * ws(a),
        ),
        (
            d(la, b) + 2.0 * dab + d(b, sp) - 0.5,
            kb * ka * kb / dab.powi(4) * wl(b) * ws(b),
        ),
    ];
    let paths4 = [
        (
            d(la, a) + dab + d(b, sp) - 0.5,
            ka * kb / dab.powi(2) * wl(a) * ws(b),
        ),
        (
            d(la, b) + dab + d(a, sp) - 0.5,
            kb * ka / dab.powi(2) * wl(b) * ws(a),
        ),
    ];
    let moments = |h: &[f64]| {
        let sum: f64 = h.iter().sum();
        let mean = h
            .iter()
            .enumerate()
            .map(|(n, v)| n as f64 * 0.005 * v)
            .sum::<f64>()
            / sum;
        (sum, mean)
    };
    let expect = |paths: &[(f64, f64)]| {
        let sum: f64 = paths.iter().map(|p| p.1).sum();
        (sum, paths.iter().map(|p| p.0 * p.1).sum::<f64>() / sum)
    };

    let h4: Vec<f64> = render(&scene).iter().map(|&v| f64::from(v)).collect();
    scene.max_vertices = 5;
    let h5: Vec<f64> = render(&scene).iter().map(|&v| f64::from(v)).collect();
    let only5: Vec<f64> = h5.iter().zip(&h4).map(|(x, y)| x - y).collect();

    let ((s4, t4), (e4, et4)) = (moments(&h4), expect(&paths4));
    assert!(
        (s4 / e4 - 1.0).abs() < 1e-5 && (t4 - et4).abs() < 1e-5,
        "4-vertex: {s4} at {t4} vs {e4} at {et4}"
    );
    let ((s5, t5), (e5, et5)) = (moments(&only5), expect(&paths5));
    assert!(
        (s5 / e5 - 1.0).abs() < 1e-3 && (t5 - et5).abs() < 1e-4,
        "5-vertex: {s5} at {t5} vs {e5} at {et5}"
    );
    // No 5-vertex light before the first 5-vertex path's pulse, none with max_vertices 4 after
    // the last 4-vertex pulse.
    let bin = |t: f64| (t / 0.005).round() as usize;
    let first5 = paths5.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let last4 = paths4.iter().map(|p| p.0).fold(0.0, f64::max);
    assert!(first5 > last4 + 0.1, "test geometry separates the orders");
    let peak5 = only5.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(
        only5[..bin(first5 - 0.08)]
            .iter()
            .all(|v| v.abs() <= 1e-4 * peak5)
    );
    assert!(h4[bin(last4 + 0.08)..].iter().all(|&v| v == 0.0));
    // The 5-vertex pulse peaks at one of its path times.
    let argmax = (0..only5.len())
        .max_by(|&i, &j| only5[i].total_cmp(&only5[j]))
        .unwrap();
    assert!(
        paths5
            .iter()
            .any(|p| (argmax as f64 - p.0 / 0.005).abs() <= 1.0),
        "peak at bin {argmax}"
    );
}

// ---------------------------------------------------------------------------------------------
// scene files
// ---------------------------------------------------------------------------------------------

const GOOD: &str = r#"{
  "setup": {"lasers": {"grid": [4, 4], "size": 1.0}, "spads": {"grid": 2, "size": [0.5, 0.4], "center": [0.1, 0]},
            "nt": 200, "dt": 0.01},
  "objects": [
    {"type": "patch", "name": "A", "center": [-0.2, 0, 0.8], "normal": [0, 0, -1], "size": 0.2},
    {"type": "box", "name": "C", "center": [0.3, 0, 0.9], "size": [0.2, 0.3, 0.2]},
    {"type": "point", "name": "P", "center": [0, 0.3, 0.7], "area": 0.01, "normal": [0, 0, -1]}
  ]
}"#;

#[test]
fn scene_file_defaults() {
    let scene = Scene::from_json_str(GOOD, "good.json").unwrap();
    assert_eq!(scene.pulse_sigma(), 0.01);
    assert_eq!(
        (
            scene.bounces,
            scene.max_vertices,
            scene.cosines,
            scene.noise
        ),
        (Bounces::All, 4, true, None)
    );
    let s = &scene.setup;
    assert_eq!((s.t0, s.legs_in_time, s.confocal), (0.0, false, false));
    assert_eq!(s.laser_origin, vltm::sim::DEFAULT_LASER_ORIGIN);
    assert_eq!(
        s.spads,
        Some(Aperture::grid([2, 2], [0.5, 0.4], [0.1, 0.0]))
    );
    let Object::Patch(p) = &scene.objects[0] else {
        panic!("patch")
    };
    assert_eq!(
        (p.size, p.albedo, p.samples),
        ([0.2, 0.2], 1.0, vltm::sim::DEFAULT_SAMPLES)
    );
    let geo = scene.geometry();
    assert_eq!(geo.lasers.len(), 16);
    // Inclusive end points, C order over (x, y).
    let close = |a: &[[f32; 3]], b: &[[f32; 3]]| {
        a.len() == b.len()
            && a.iter()
                .zip(b)
                .all(|(p, q)| (0..3).all(|k| (p[k] - q[k]).abs() < 1e-6))
    };
    let third = 1.0 / 3.0;
    assert!(close(
        &geo.lasers[..2],
        &[[-0.5, -0.5, 0.0], [-0.5, -0.5 + third, 0.0]]
    ));
    assert_eq!(geo.lasers[15], [0.5, 0.5, 0.0]);
    assert!(close(
        &geo.spads,
        &[
            [-0.15, -0.2, 0.0],
            [-0.15, 0.2, 0.0],
            [0.35, -0.2, 0.0],
            [0.35, 0.2, 0.0]
        ]
    ));
    assert_eq!(scene.object_centre("P"), Some([0.0, 0.3, 0.7]));
    assert_eq!(scene.object_centre("nope"), None);
    assert_eq!(scene.sample_points().len(), 16 + 6 * 16 + 1);
    // A 1-D SPAD array and a single SPAD.
    let one_d = GOOD.replace(
        r#""grid": 2, "size": [0.5, 0.4]"#,
        r#""grid": [5, 1], "size": [0.5, 0]"#,
    );
    let scene = Scene::from_json_str(&one_d, "1d.json").unwrap();
    assert_eq!(scene.geometry().spad_shape, [5, 1]);
    assert_eq!(scene.geometry().spads[2], [0.1, 0.0, 0.0]);
    let single = GOOD.replace(
        r#""grid": 2, "size": [0.5, 0.4], "center": [0.1, 0]"#,
        r#""points": [[0.1, 0.2, 0]]"#,
    );
    let scene = Scene::from_json_str(&single, "1.json").unwrap();
    assert_eq!(
        (scene.geometry().spad_shape, scene.geometry().spads.len()),
        ([1, 1], 1)
    );
    assert_eq!(scene.render().unwrap().data.len(), 16 * 200);
}

#[test]
fn bad_scenes_are_rejected_naming_the_field() {
    let cases: &[(&str, &str, &str)] = &[
        (
            r#""type": "patch", "name": "A""#,
            r#""type": "sphere", "name": "A""#,
            "sphere",
        ),
        (
            r#""normal": [0, 0, -1], "size": 0.2"#,
            r#""normal": [0, 0, -1], "size": 0"#,
            "objects[0].size",
        ),
        (
            r#""size": [0.2, 0.3, 0.2]"#,
            r#""size": [0.2, -0.3, 0.2]"#,
            "objects[1].size",
        ),
        (r#""dt": 0.01"#, r#""dt": 0"#, "setup.dt"),
        (r#""dt": 0.01"#, r#""dt": -0.01"#, "setup.dt"),
        (r#""nt": 200"#, r#""nt": 0"#, "setup.nt"),
        (r#""nt": 200"#, r#""nt": -3"#, "scene"),
        (
            r#""center": [-0.2, 0, 0.8]"#,
            r#""center": [-0.2, 0, 0.0]"#,
            "objects[0].center",
        ),
        (
            r#""center": [-0.2, 0, 0.8]"#,
            r#""center": [-0.2, 0, -1]"#,
            "objects[0].center",
        ),
        (
            r#""center": [0.3, 0, 0.9]"#,
            r#""center": [0.3, 0, 0.05]"#,
            "objects[1].center",
        ),
        (
            r#""normal": [0, 0, -1], "size": 0.2"#,
            r#""normal": [1, 0, 0], "size": 2.0"#,
            "objects[0].center",
        ), // reaches through the wall
        (
            r#""normal": [0, 0, -1], "size""#,
            r#""normal": [0, 0, 0], "size""#,
            "objects[0].normal",
        ),
        (
            r#""area": 0.01, "normal": [0, 0, -1]"#,
            r#""area": 0.01, "normal": [0, 0, 0]"#,
            "objects[2].normal",
        ),
        (
            r#""size": [0.2, 0.3, 0.2]"#,
            r#""size": [0.2, 0.3, 0.2], "normal": [0, 0, 0]"#,
            "objects[1].normal",
        ),
        (
            r#""size": [0.2, 0.3, 0.2]"#,
            r#""size": [2.4, 0.3, 0.2], "normal": [1, 0, -1]"#,
            "objects[1].center",
        ), // turned 45°, its long side reaches through the wall (axis-aligned it would not)
        (r#""area": 0.01"#, r#""area": 0"#, "objects[2].area"),
        (
            r#""size": 0.2}"#,
            r#""size": 0.2, "samples": 0}"#,
            "objects[0].samples",
        ),
        (
            r#""size": 0.2}"#,
            r#""size": 0.2, "albedo": 1.5}"#,
            "objects[0].albedo",
        ),
        (r#""name": "C""#, r#""name": "A""#, "objects[1].name"),
        (
            r#""nt": 200"#,
            r#""nt": 200, "pulse_sigmaa": 1"#,
            "pulse_sigmaa",
        ),
        (
            r#""grid": [4, 4]"#,
            r#""grid": [0, 4]"#,
            "setup.lasers.grid",
        ),
        (r#""grid": [4, 4]"#, r#""grid": [2.5, 4]"#, "whole numbers"),
        (
            r#""grid": [4, 4], "size": 1.0"#,
            r#""grid": [4, 4], "size": 0"#,
            "setup.lasers.size",
        ),
        (
            r#""grid": [4, 4], "size": 1.0"#,
            r#""grid": [4, 4], "points": [[0, 0, 0]]"#,
            "exactly one of",
        ),
        (
            r#""dt": 0.01}"#,
            r#""dt": 0.01}, "max_vertices": 6"#,
            "max_vertices",
        ),
        (
            r#""dt": 0.01}"#,
            r#""dt": 0.01}, "bounces": "indirect", "max_vertices": 3"#,
            "max_vertices",
        ),
        (
            r#""dt": 0.01}"#,
            r#""dt": 0.01}, "bounces": "twice""#,
            "twice",
        ),
        (
            r#""dt": 0.01}"#,
            r#""dt": 0.01}, "pulse_sigma": -1"#,
            "pulse_sigma",
        ),
        (
            r#""dt": 0.01}"#,
            r#""dt": 0.01}, "noise": {"peak_counts": 0}"#,
            "noise.peak_counts",
        ),
        (
            r#""dt": 0.01}"#,
            r#""dt": 0.01}, "noise": {"peak_counts": 10, "background": -1}"#,
            "noise.background",
        ),
        (
            r#""spads": {"grid": 2, "size": [0.5, 0.4], "center": [0.1, 0]},"#,
            "",
            "setup.spads",
        ),
        (
            r#""dt": 0.01"#,
            r#""dt": 0.01, "confocal": true"#,
            "setup.spads",
        ),
        (r#""objects": ["#, r#""objects": {"#, "scene"),
    ];
    for (from, to, field) in cases {
        assert!(
            GOOD.contains(from),
            "case {from} -> {to}: pattern not in the scene"
        );
        let json = GOOD.replacen(from, to, 1);
        let err =
            Scene::from_json_str(&json, "bad.json").expect_err(&format!("{from} -> {to} accepted"));
        let msg = err.to_string();
        assert!(matches!(err, Error::Format { .. }), "{msg}");
        assert!(msg.starts_with("bad.json: "), "{msg}");
        assert!(
            msg.contains(field),
            "{from} -> {to}: `{field}` not in: {msg}"
        );
    }
    // A confocal setup without `spads` is fine.
    let confocal = GOOD
        .replace(
            r#""spads": {"grid": 2, "size": [0.5, 0.4], "center": [0.1, 0]},"#,
            "",
        )
        .replace(r#""dt": 0.01"#, r#""dt": 0.01, "confocal": true"#);
    assert!(
        Scene::from_json_str(&confocal, "confocal.json")
            .unwrap()
            .geometry()
            .confocal
    );
    // Files.
    let err = Scene::load("/nonexistent/scene.json").unwrap_err();
    assert!(matches!(err, Error::Io { .. }) && err.to_string().contains("/nonexistent/scene.json"));
    // Scenes built in code are checked when rendered.
    let mut scene = small_scene();
    scene.setup.dt = f64::NAN;
    let err = scene.render().unwrap_err().to_string();
    assert!(err.contains("<scene>") && err.contains("setup.dt"), "{err}");
    let mut scene = small_scene();
    scene.objects.push(Object::Patch(Patch::new(
        "D",
        [0.0, 0.0, 0.5],
        [0.0, 0.0, -1.0],
        [0.1, f64::INFINITY],
    )));
    assert!(
        scene
            .render()
            .unwrap_err()
            .to_string()
            .contains("objects[2].size")
    );
}
