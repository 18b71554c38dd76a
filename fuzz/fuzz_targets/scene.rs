//! Scene JSON: parse and validate; for scenes small enough to render quickly (at most 4096
//! histogram values and 64 surface samples), the first laser row is rendered too.
#![no_main]

mod common;
use libfuzzer_sys::fuzz_target;
use vltm::io::RowSource;
use vltm::sim::Scene;

fuzz_target!(|data: &[u8]| {
    common::init();
    let Ok(json) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(scene) = Scene::from_json_str(json, "fuzz.json") else {
        return;
    };
    let g = scene.geometry();
    let values = g.lasers.len() * g.spads_per_row() * g.nt;
    let points = scene.sample_points().len();
    if values <= 4096 && points <= 64 {
        if let Ok(mut src) = scene.source() {
            let mut row = Vec::new();
            let _ = src.read_row(0, &mut row);
        }
    }
});
