//! PicoQuant PTU T3 streams with their JSON sidecar: the input is `n` (2 bytes, little
//! endian), `n` bytes of sidecar JSON, then the PTU file. Every row is binned.
#![no_main]

mod common;
use libfuzzer_sys::fuzz_target;
use std::io::Cursor;
use std::path::Path;
use vltm::io::ptu::{PtuSource, Sidecar};

fuzz_target!(|data: &[u8]| {
    common::init();
    if data.len() < 2 {
        return;
    }
    let n = usize::from(u16::from_le_bytes([data[0], data[1]])).min(data.len() - 2);
    let (json, ptu) = data[2..].split_at(n);
    let Ok(json) = std::str::from_utf8(json) else {
        return;
    };
    let side = Path::new("fuzz.json");
    let Ok(sidecar) = Sidecar::from_json_str(json, side) else {
        return;
    };
    if let Ok(mut s) = PtuSource::from_reader(Cursor::new(ptu), "fuzz.ptu", sidecar, side) {
        common::drain(&mut s);
    }
});
