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
