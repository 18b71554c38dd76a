//! The MATLAB `.mat` reader (MAT v5 with zlib elements, MAT v7.3 through HDF5): the variable
//! listing (as `info`), then the capture with default conventions (Stanford confocal or
//! phasor-field layout) and every row.
#![no_main]

mod common;
use libfuzzer_sys::fuzz_target;
use vltm::io::mat::{self, MatOptions};

fuzz_target!(|data: &[u8]| {
    common::init();
    let p = common::scratch("mat", data);
    let _ = mat::variables(&p);
    if let Ok(mut m) = mat::read(&p, &MatOptions::default()) {
        common::drain(&mut m.capture);
    }
});
