//! `vltm info`: what a capture file holds (the library's layout text, [`vltm::info`], the
//! lines every front end prints), with `--png` its summed transient, and the template
//! sidecar of a `.ptu` capture that has none (`--sidecar`).

use crate::console::{Failure, flag, say, tell};
use crate::input::Input;
use crate::open;
use crate::outputs::{Out, prepare_output, refuse_overwriting_inputs};
use std::path::Path;
use vltm::atomic::Transaction;
use vltm::export::figure::plot::Transient;
use vltm::io;

/// `vltm info F.ptu --sidecar F.json`: a template sidecar to fill in (written all or nothing,
/// never over an existing file).
pub fn sidecar_template(ptu: &Path, out: &Path) -> Result<(), Failure> {
    if io::extension(ptu).as_deref() != Some("ptu") {
        return Err(vltm::Error::arg(
            "sidecar",
            format!(
                "{}: a template sidecar is for a PicoQuant .ptu capture",
                ptu.display()
            ),
        )
        .into());
    }
    if io::extension(out).as_deref() != Some("json") {
        return Err(vltm::Error::arg(
            "sidecar",
            format!("{}: a sidecar is a .json file", out.display()),
        )
        .into());
    }
    if out.exists() {
        return Err(vltm::Error::arg(
            "sidecar",
            format!("{} exists: remove it or choose another name", out.display()),
        )
        .into());
    }
    refuse_overwriting_inputs(&[ptu.to_path_buf()], &[out])?;
    vltm::budget::regular_file(ptu)?;
    let text = io::ptu::template(ptu)?;
    vltm::atomic::write_bytes(out, text.as_bytes())?;
    say!(
        "wrote {}: fill in the fields marked FILL IN (docs/formats.md, PTU sidecar); name it {} to read {} with it",
        out.display(),
        ptu.with_extension("json").display(),
        ptu.display()
    );
    Ok(())
}

/// `vltm info`: what the file holds, the conventions assumed, counts after preprocessing
/// (the library's [`vltm::info::info`], the text every front end prints), and with
/// `--png` the summed transient.
pub fn info(
    path: &Path,
    input: &Input,
    png: Option<&Path>,
    volume: Option<&str>,
) -> Result<(), Failure> {
    use vltm::info::Stream;
    if let Some(p) = png {
        refuse_overwriting_inputs(&[path.to_path_buf()], &[p])?;
        prepare_output(p, Out::Figure)?;
    }
    let volume = volume.map(vltm::volume::Volume::parse).transpose()?;
    open::require_sidecar(path)?;
    // The description is printed once it is whole: nothing on stdout before a failure.
    let mut lines = Vec::new();
    let sum = vltm::info::info(
        path,
        &input.mat_options(),
        input.prep()?,
        volume.as_ref(),
        &mut |stream, line| {
            // The library names the options that set a convention by parameter.
            let line = vltm::error::respell(line, flag);
            match stream {
                Stream::Out => lines.push(line),
                Stream::Warning => tell!("vltm: warning: {line}"),
            }
        },
    )?;
    for line in &lines {
        say!("{line}");
    }
    if let Some(p) = png {
        let name = path
            .file_name()
            .map_or(String::new(), |n| n.to_string_lossy().into_owned());
        let t = Transient {
            counts: &sum.counts,
            t0: sum.t0,
            dt: sum.dt,
            title: format!("{name}: summed transient"),
            shade: None,
        };
        let mut tr = Transaction::new();
        t.stage_png(&mut tr, p)?;
        tr.commit()?;
        say!("wrote {}", p.display());
    }
    Ok(())
}
