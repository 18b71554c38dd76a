//! Opening a command's capture: its outputs refused where they would overwrite it and
//! prepared ([`capture`]), the file opened by its format (`.mat` with the conventions a file
//! does not record, `--delta-t`, `--t-start`, `--grid-width`; a `.ptu` only with its
//! sidecar), watched for implausible values, and read into memory with its roles swapped
//! for `--swap-roles` ([`vltm::io::capture::swapped`], as the Python package does).

use std::path::{Path, PathBuf};
use vltm::io::{self, RowSource};

use crate::args::Common;
use crate::outputs::{Out, prepare_output, refuse_overwriting_inputs};

/// The capture of a probe as a row source, once its outputs (`--out`, `--png`, `--partial`)
/// are checked ([`outputs`]): y-tal HDF5 files, PicoQuant PTU photon streams and
/// uncompressed `.npz` captures are streamed row by row (memory O(Ks·Nt)); compressed
/// `.npz`, `.mat`, and `--swap-roles` (a transpose), are read into memory.
pub(crate) fn capture(c: &Common, path: &Path) -> vltm::Result<Box<dyn RowSource>> {
    let _t = vltm::timings::section("opening the capture", vltm::timings::Kind::Serial);
    outputs(c, path)?;
    let mut src = source(path, &c.input.mat_options())?;
    if c.swap_roles {
        Ok(Box::new(io::capture::swapped(&mut *src, path)?))
    } else {
        Ok(src)
    }
}

/// Refuses a probe's output that names its capture (or a `.ptu` capture's sidecar), and
/// prepares each output ([`prepare_output`]).
pub(crate) fn outputs(c: &Common, path: &Path) -> vltm::Result<()> {
    let mut inputs = vec![path.to_path_buf()];
    if io::extension(path).as_deref() == Some("ptu") {
        inputs.push(path.with_extension("json"));
    }
    let outputs: Vec<&Path> = c
        .out
        .iter()
        .chain(&c.png)
        .chain(&c.partial)
        .map(PathBuf::as_path)
        .collect();
    refuse_overwriting_inputs(&inputs, &outputs)?;
    for (p, kind) in [
        (&c.out, Out::Volume),
        (&c.png, Out::Figure),
        (&c.partial, Out::State),
    ] {
        if let Some(p) = p {
            prepare_output(p, kind)?;
        }
    }
    Ok(())
}

/// Opens the capture as a row source: `.mat` through [`io::mat::read`] with the overrides
/// `mat`, other formats through [`io::open_source`] (the overrides are refused there: those
/// files record their conventions); watched for implausible values ([`watched`]).
pub(crate) fn source(path: &Path, mat: &io::mat::MatOptions) -> vltm::Result<Box<dyn RowSource>> {
    let src: Box<dyn RowSource> = if io::extension(path).as_deref() == Some("mat") {
        vltm::budget::regular_file(path)?;
        Box::new(io::mat::read(path, mat)?.capture)
    } else {
        mat.refuse()?;
        require_sidecar(path)?;
        io::open_source(path)?
    };
    Ok(watched(path, src))
}

/// Opens the capture streamed by its format ([`io::open_source`], the `.mat` conventions as
/// the layout has them), watched for implausible values: `vltm matrix`'s capture.
pub(crate) fn streamed(path: &Path) -> vltm::Result<Box<dyn RowSource>> {
    require_sidecar(path)?;
    Ok(watched(path, io::open_source(path)?))
}

/// A `.ptu` capture whose sidecar is missing: the error names the sidecar, says what it is
/// and how to make one (`vltm info F.ptu --sidecar F.json`).
pub(crate) fn require_sidecar(path: &Path) -> vltm::Result<()> {
    if io::extension(path).as_deref() != Some("ptu") || !path.is_file() {
        return Ok(());
    }
    let json = path.with_extension("json");
    if std::fs::symlink_metadata(&json).is_ok() {
        return Ok(());
    }
    let msg = format!(
        "No such file or directory: {} needs a JSON sidecar {} describing the scan (rows, \
         SPADs, time axis; its fields: docs/formats.md, PTU sidecar); `vltm info {} --sidecar {}` \
         writes a template to fill in",
        path.display(),
        json.display(),
        path.display(),
        json.display()
    );
    Err(vltm::Error::io(
        &json,
        std::io::Error::new(std::io::ErrorKind::NotFound, msg),
    ))
}

/// `src` (the capture file `path`) with its implausible values (a flipped byte in a file
/// without checksums, negative counts) named in one warning once every row has been read
/// ([`io::plausible`]).
fn watched(path: &Path, src: Box<dyn RowSource>) -> Box<dyn RowSource> {
    Box::new(io::plausible::Watched::new(
        src,
        io::plausible::nonnegative_format(path),
        Box::new(|w: &str| vltm::exec::Progress::warn(&crate::progress::BARS, w)),
    ))
}
