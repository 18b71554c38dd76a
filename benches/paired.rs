//! The paired benchmark of issue 36: `probe::direct` on a synthetic paired capture of
//! 64 × 64 = 4,096 pairs × 512 bins of 32 ps (pairs 0.27 m apart on a 2 × 2 m wall, patches at
//! 0.7–1.6 m; the scene of `benches/paired_scene.py`), rendered at bench time (nothing large
//! is committed), over 32³ and 64³ voxels on the phasor path (`EvalPath::Phasor`, the one `Auto`
//! takes), whole scan, the global thread pool; 128³ too with `VLTM_BENCH_LARGE=1` (≈ 20 s a
//! run on 2 cores). Run: `cargo bench --bench paired`.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use vltm::probe::{self, EvalPath, Exec, Wave};
use vltm::sim::Scene;
use vltm::volume::Volume;

/// The scene of `benches/paired_scene.py` with `n × n` pairs.
fn scene(n: usize) -> String {
    let gap = 0.27;
    let mut lasers = Vec::new();
    let mut spads = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let x = -1.0 + (2.0 - gap) * i as f64 / (n - 1) as f64;
            let y = -1.0 + 2.0 * j as f64 / (n - 1) as f64;
            lasers.push(format!("[{x},{y},0.0]"));
            spads.push(format!("[{},{y},0.0]", x + gap));
        }
    }
    format!(
        r#"{{"setup": {{"lasers": {{"points": [{}], "shape": [{n}, {n}]}},
        "spads": {{"points": [{}], "shape": [{n}, {n}]}}, "scan": "paired",
        "nt": 512, "dt": 0.0095938, "t0": 1.0}},
        "bounces": "direct", "max_vertices": 3,
        "objects": [
          {{"type": "patch", "name": "near", "center": [-0.3, 0.2, 0.7], "normal": [0, 0, -1], "size": [0.3, 0.2]}},
          {{"type": "patch", "name": "mid", "center": [0.3, -0.2, 1.1], "normal": [0, 0, -1], "size": 0.3}},
          {{"type": "patch", "name": "far", "center": [0.0, 0.4, 1.6], "normal": [0, 0, -1], "size": [0.5, 0.3]}}]}}"#,
        lasers.join(","),
        spads.join(",")
    )
}

fn paired(c: &mut Criterion) {
    let capture = Scene::from_json_str(&scene(64), "paired.json")
        .expect("scene")
        .render()
        .expect("render");
    let wave = Wave::default();
    let mut g = c.benchmark_group("paired_4096x512");
    g.sample_size(10);
    let mut sizes = vec![32, 64];
    if std::env::var_os("VLTM_BENCH_LARGE").is_some() {
        sizes.push(128);
    }
    for n in sizes {
        let volume = Volume::parse(&format!("-1:1:{n},-1:1:{n},0.5:1.8:{n}")).expect("volume");
        g.bench_with_input(BenchmarkId::new("phasor", format!("{n}^3")), &n, |b, _| {
            b.iter(|| {
                let out = probe::direct(
                    &mut capture.clone(),
                    black_box(&volume),
                    &wave,
                    Exec {
                        progress: None,
                        path: EvalPath::Phasor,
                    },
                )
                .expect("direct");
                black_box(out.values.len())
            });
        });
    }
    g.finish();
}

criterion_group!(benches, paired);
criterion_main!(benches);
