//! The `.npz` readers: whole (`npz::read`, as `info` and compressed captures) and streamed
//! (`npz::open_stream` + every row, as the probes read a stored capture).
#![no_main]

mod common;
use libfuzzer_sys::fuzz_target;
use vltm::io::npz;

fuzz_target!(|data: &[u8]| {
    common::init();
    let p = common::scratch("npz", data);
    let _ = npz::read(&p);
    if let Ok(Some(mut s)) = npz::open_stream(&p) {
        common::drain(&mut s);
    }
});
