//! The y-tal `HDF5_TAL` reader: open, then every row (as the probes stream it), then the
//! whole capture (as `info` and `--swap-roles`).
#![no_main]

mod common;
use libfuzzer_sys::fuzz_target;
use vltm::io::tal;

fuzz_target!(|data: &[u8]| {
    common::init();
    let p = common::scratch("hdf5", data);
    if let Ok(mut r) = tal::open(&p) {
        common::drain(&mut r);
        let _ = r.into_capture();
    }
});
