//! The exhaustive benchmark of issue 36 (item 4): `probe::direct` on the exh16 capture
//! (`benches/scenes/exh16.json`: 16×16 lasers × 16×16 SPADs × 800 bins, rendered at bench time,
//! nothing large is committed) over 16×16×24 voxels at the SPAD pitch (z 0.5–1.25 m), λ = σ =
//! 0.5 m, no lens weights: the planar path `auto` takes, whole scan from memory (reading a
//! file not included: `docs/performance.md` has the command-line figures), the global thread
//! pool. Run: `cargo bench --bench exh16`.

use criterion::{Criterion, criterion_group, criterion_main};
use std::hint::black_box;
use vltm::probe::{self, Exec, Wave};
use vltm::sim::Scene;
use vltm::volume::Volume;
use vltm_kernel::Weights;

fn exh16(c: &mut Criterion) {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/scenes/exh16.json");
    let json = std::fs::read_to_string(&path).expect("benches/scenes/exh16.json");
    let capture = Scene::from_json_str(&json, "exh16.json")
        .expect("scene")
        .render()
        .expect("render");
    let wave = Wave {
        wavelength: Some(0.5),
        sigma: Some(0.5),
        weights: Weights::One,
        ..Wave::default()
    };
    let volume = Volume::parse("-0.9375:0.9375:16,-0.9375:0.9375:16,0.5:1.25:24").expect("volume");
    let mut g = c.benchmark_group("exh16");
    g.sample_size(10);
    g.bench_function("direct_16x16x24", |b| {
        b.iter(|| {
            let out = probe::direct(
                &mut capture.clone(),
                black_box(&volume),
                &wave,
                Exec::default(),
            )
            .expect("direct");
            black_box(out.values.len())
        });
    });
    g.finish();
}

criterion_group!(benches, exh16);
criterion_main!(benches);
