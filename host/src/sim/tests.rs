//! Unit tests of the simulator.

use super::noise::*;
use super::objects::*;
use super::render::*;
use super::scene::*;
use super::*;
use crate::io::capture::RowSource;

fn scene(pulse_bins: f64, max_vertices: usize) -> Scene {
    let mut scene = Scene::new(Setup::new(
        Aperture::grid([4, 3], [1.0, 0.8], [0.0, 0.0]),
        Aperture::grid([6, 6], [1.0, 1.0], [0.05, 0.0]),
        400,
        0.01,
    ))
    .with(Patch {
        samples: 3,
        ..Patch::new("A", [-0.3, 0.0, 0.6], [0.4, 0.0, -1.0], [0.2, 0.15])
    })
    .with(Patch {
        samples: 3,
        albedo: 0.5,
        ..Patch::new("B", [0.3, 0.1, 0.7], [-0.3, 0.0, -1.0], [0.2, 0.2])
    })
    .with(Cuboid {
        samples: 2,
        ..Cuboid::new("C", [0.0, -0.3, 0.9], [0.1, 0.1, 0.2])
    })
    .with(PointScatterer::new("P", [0.05, 0.3, 0.5], 0.01));
    scene.pulse_sigma = Some(pulse_bins * 0.01);
    scene.max_vertices = max_vertices;
    scene.setup.t0 = 0.3;
    scene
}

fn render_with(scene: &Scene, mode: Mode) -> Vec<f32> {
    let mut src = scene.source().unwrap();
    src.tables.mode = mode;
    let mut all = Vec::new();
    let mut row = Vec::new();
    for l in 0..src.geometry.lasers.len() {
        src.read_row(l, &mut row).unwrap();
        all.extend_from_slice(&row);
    }
    all
}

#[test]
fn presummed_paths_match_direct_deposits() {
    for (pulse, max_vertices) in [(1.0, 4), (1.0, 5), (1.7, 5), (4.2, 4)] {
        let scene = scene(pulse, max_vertices);
        let direct = render_with(&scene, Mode::Direct);
        let fine = render_with(&scene, Mode::Fine);
        let auto = render_with(&scene, Mode::Auto);
        assert_eq!(auto, scene.render().unwrap().data);
        let peak = direct.iter().fold(0.0f32, |m, &v| m.max(v));
        for (name, other) in [("fine", &fine), ("auto", &auto)] {
            let worst = direct
                .iter()
                .zip(other)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            println!(
                "σ = {pulse} bins, {max_vertices} vertices, {name}: {:.2e}",
                worst / peak
            );
            assert!(
                worst <= 2e-7 * peak,
                "σ = {pulse} bins, {max_vertices} vertices, {name}: {:.2e}",
                worst / peak
            );
        }
        // The indirect part alone, relative to its own peak.
        let mut indirect = scene.clone();
        indirect.bounces = Bounces::Indirect;
        let (d, f) = (
            render_with(&indirect, Mode::Direct),
            render_with(&indirect, Mode::Fine),
        );
        let peak = d.iter().fold(0.0f32, |m, &v| m.max(v));
        assert!(peak > 0.0);
        let worst = d
            .iter()
            .zip(&f)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        println!(
            "σ = {pulse} bins, {max_vertices} vertices, indirect only, fine: {:.2e}",
            worst / peak
        );
        assert!(
            worst <= 1e-6 * peak,
            "indirect, σ = {pulse} bins: {:.2e}",
            worst / peak
        );
    }
}

#[test]
fn pulse_recurrence_matches_the_formula() {
    for s in [0.3, 0.5, 0.9, 1.0, 1.5, 7.3, 40.0] {
        let norm = 1.0 / (s * (2.0 * std::f64::consts::PI).sqrt());
        let p = Pulse::new(s, norm);
        for x in [150.0, 150.5, 150.49, 151.37, 3.2, 296.8, -2.0] {
            let mut h = vec![0.0; 300];
            p.deposit(&mut h, x, 2.0);
            let n0 = f64::round_ties_even(x);
            for (n, &v) in h.iter().enumerate() {
                let inside = (n as f64 - n0).abs() <= p.r as f64;
                let want = if inside {
                    2.0 * norm * (-0.5 * ((n as f64 - x) / s).powi(2)).exp()
                } else {
                    0.0
                };
                assert!(
                    (v - want).abs() <= 1e-12 * 2.0 * norm,
                    "s {s} x {x} n {n}: {v} vs {want}"
                );
            }
            if s >= 1.0 && (20.0..280.0).contains(&x) && s < 10.0 {
                // Unit sum up to the aliasing term 2·exp(−2π²s²) (1e-8 at s = 1).
                assert!(
                    (h.iter().sum::<f64>() - 2.0).abs() < 2e-7,
                    "unit sum, s {s}"
                );
            }
        }
    }
}

#[test]
fn scenes_round_trip_through_json() {
    let mut scene = scene(1.3, 5);
    scene.noise = Some(Noise {
        peak_counts: 300.0,
        background: 0.1,
        seed: 3,
    });
    scene.pulse_sigma = Some(0.013); // (serde_json's float parsing may be 1 ulp off)
    scene.setup.spads = Some(Aperture::points(vec![[0.1, 0.0, 0.0], [0.2, 0.1, 0.0]]));
    scene.description = "round trip".into();
    let json = serde_json::to_string_pretty(&scene).unwrap();
    assert_eq!(Scene::from_json_str(&json, "rt.json").unwrap(), scene);
}
