//! The HDF5 readers, both layouts (y-tal `HDF5_TAL` and Zaragoza Z-NLOS, picked by
//! `tal::detect` as `vltm` does): open, then every row (as the probes stream it), then the
//! whole capture (as `info` and `--swap-roles`).
#![no_main]

mod common;
use libfuzzer_sys::fuzz_target;
use vltm::io::tal;

fuzz_target!(|data: &[u8]| {
    common::init();
    let p = common::scratch("hdf5", data);
    if let Ok(mut r) = tal::open_any(&p) {
        common::drain(r.as_mut());
        let _ = tal::read_any(&p);
    }
});
