//! Captures in: the capture model and every reader, opened by file extension.
//!
//! | module | owns |
//! |---|---|
//! | [`capture`] | [`Geometry`] (spots, time axis, device positions), [`RowSource`] (laser rows on demand), [`Capture`] (H in memory), reciprocity ([`swap_roles`]) |
//! | [`npz`] | vltm's `.npz` captures: write, read whole, stream a stored archive by row |
//! | [`tal`] | y-tal / mitransient `HDF5_TAL` captures, streamed by laser row; the Zaragoza Z-NLOS layout ([`tal::znlos`]) |
//! | [`mat`] | MATLAB `.mat` captures (v5 with zlib elements, v7.3 through HDF5): the Stanford confocal and phasor-field layouts |
//! | [`prep`] | preprocessing of raw counts as a row wrapper: time window, rebinning, background |
//! | [`ptu`] | PicoQuant PTU T3 photon streams with a JSON sidecar, binned row by row; the T3 writer |
//! | [`state`] | the file format of partial states (`probe::partial`): container, sections, CRC-32 |
//!
//! Readers only yield rows: nothing here imports the probes, the simulator or the outputs.

pub mod capture;
pub mod mat;
pub mod npz;
pub mod plausible;
pub mod prep;
pub mod ptu;
pub mod state;
pub mod tal;

pub use capture::{
    Capture, Geometry, Normals, RowRange, RowSource, Rows, WALL_NORMAL, check_row, swap_roles,
    unit, wall_cosine,
};

use crate::error::{Error, Result};
use std::path::Path;

/// The file name's extension, lower case.
pub fn extension(path: &Path) -> Option<String> {
    path.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
}

/// Opens a capture file by its extension and reads it whole: `.npz` (vltm), `.ptu`
/// (PicoQuant T3, with its sidecar `<same name>.json` describing rows, SPADs and time axis;
/// see [`ptu`]), `.hdf5` / `.h5` (y-tal `HDF5_TAL` or Z-NLOS, [`tal::read_any`]), `.mat` ([`mat::read`]
/// with the layout's default conventions).
///
/// # Errors
/// [`Error::Io`] for a missing file (whatever its extension), [`Error::Format`] for
/// anything but a regular file (a named pipe, a device: refused before it is opened),
/// [`Error::Argument`] for an unknown extension; read errors of the format.
pub fn open(path: &Path) -> Result<Capture> {
    crate::budget::regular_file(path)?;
    match extension(path).as_deref() {
        Some("npz") => npz::read(path),
        Some("ptu") => ptu::read_all(path, path.with_extension("json")),
        Some("hdf5" | "h5") => tal::read_any(path),
        Some("mat") => Ok(mat::read(path, &mat::MatOptions::default())?.capture),
        _ => Err(unknown_format(path)),
    }
}

/// Opens a capture file by its extension as a row source, streamed where the format allows:
/// y-tal HDF5 and Z-NLOS files (a Z-NLOS file whose row axes come last is read whole on the
/// first row, [`tal::znlos`]), PicoQuant PTU photon streams (binned row by row in one pass over the
/// records) and stored (uncompressed) `.npz` captures are read row by row (memory O(Ks·Nt));
/// a compressed `.npz` and a `.mat` capture ([`mat`], default conventions) are read into
/// memory.
///
/// # Errors
/// As [`open`].
pub fn open_source(path: &Path) -> Result<Box<dyn RowSource>> {
    crate::budget::regular_file(path)?;
    match extension(path).as_deref() {
        Some("hdf5" | "h5") => tal::open_any(path),
        Some("ptu") => Ok(Box::new(ptu::PtuSource::open(
            path,
            path.with_extension("json"),
        )?)),
        Some("npz") => match npz::open_stream(path)? {
            Some(s) => Ok(Box::new(s)),
            None => Ok(Box::new(npz::read(path)?)),
        },
        Some("mat") => Ok(Box::new(
            mat::read(path, &mat::MatOptions::default())?.capture,
        )),
        _ => Err(unknown_format(path)),
    }
}

/// Whether the histograms of the capture file `path` hold the physical laser's falloff
/// `cos θ / d²` at each laser spot (what `compensate_laser` divides out), and why, in words
/// for `vltm info`: y-tal/mitransient renders (`HDF5_TAL`) multiply every path by it
/// (`fixtures/ytal/README.md`, *Radiometry*); vltm's simulator renders none; a measured
/// capture's collimated laser puts the same power on every spot; a Z-NLOS file records none.
///
/// # Errors
/// An `.hdf5` file whose layout cannot be read ([`tal::detect`]).
pub fn laser_falloff_in_data(path: &Path) -> Result<(bool, &'static str)> {
    Ok(match extension(path).as_deref() {
        Some("hdf5" | "h5") => match tal::detect(path)? {
            tal::Hdf5Layout::Tal => (
                true,
                "a y-tal/mitransient render: tal multiplies every path by it at the laser spot",
            ),
            tal::Hdf5Layout::Znlos => (false, "a Z-NLOS capture records no laser falloff"),
        },
        Some("npz") => (
            false,
            "an .npz records none: `vltm simulate` renders none, one converted from a tal render still holds it",
        ),
        _ => (
            false,
            "a PicoQuant or MATLAB capture: a measured laser is collimated and puts the same power on every spot",
        ),
    })
}

/// Whether `path` names a y-tal HDF5 capture (`.hdf5` / `.h5`).
pub fn is_hdf5(path: &Path) -> bool {
    matches!(extension(path).as_deref(), Some("hdf5" | "h5"))
}

fn unknown_format(path: &Path) -> Error {
    Error::arg(
        "capture",
        format!(
            "{}: unknown capture format (expected .npz, .ptu, .hdf5, .h5 or .mat)",
            path.display()
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// tal renders hold the laser's falloff; vltm's own `.npz` and the measured Stanford
    /// capture do not; a file that is no capture is an error naming it.
    #[test]
    fn laser_falloff_follows_the_format() {
        let f = |p: &str| laser_falloff_in_data(&Path::new("..").join(p));
        let (held, why) = f("fixtures/ytal/two_patches/two_patches.hdf5").expect("tal");
        assert!(held && why.contains("render"), "{why}");
        for p in [
            "fixtures/two_patches.npz",
            "fixtures/real/data_exit_sign.mat",
        ] {
            assert!(!f(p).expect("capture").0, "{p}");
        }
        let e = f("fixtures/pathtraced/README.md.h5").expect_err("no file");
        assert!(e.to_string().contains("README.md.h5"), "{e}");
    }
}
