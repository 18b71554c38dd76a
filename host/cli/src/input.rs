//! Reading a capture for a command: conventions a file does not record (`--delta-t`,
//! `--t-start`, `--grid-width`, for `.mat` captures), the preprocessing of raw counts
//! (`--t-min`, `--t-max`, `--rebin`, `--background`, [`vltm::io::prep`]), and `vltm info`.

use crate::console::tell;
use crate::console::{Failure, flag, say};
use crate::outputs::{Out, prepare_output, refuse_overwriting_inputs};
use clap::Args;
use std::path::Path;
use vltm::atomic::Transaction;
use vltm::export::figure::plot::Transient;
use vltm::io::prep::{Background, Bound, Prep, Prepared, Reach};
use vltm::io::{self, RowSource};
use vltm_kernel::Point;

/// How to read a capture and preprocess its counts.
#[derive(Args, Debug, Default)]
pub struct Input {
    /// Bin width in metres of path (.mat: overrides the layout's convention; Stanford: 4 ps).
    #[arg(long, value_name = "M")]
    pub delta_t: Option<f64>,
    /// Path length of bin 0 in metres (.mat: overrides the layout's convention; Stanford: 0).
    #[arg(long, value_name = "M", allow_hyphen_values = true)]
    pub t_start: Option<f64>,
    /// Half-width W of a confocal .mat grid [-W, W]^2 in metres (Stanford: the file's width).
    #[arg(long, value_name = "M")]
    pub grid_width: Option<f64>,
    /// Start of the time window (inclusive): metres of path (0.72, 0.72m) or a bin (600b).
    #[arg(long, value_name = "T")]
    pub t_min: Option<String>,
    /// End of the time window (exclusive): metres of path or a bin (2048b).
    #[arg(long, value_name = "T")]
    pub t_max: Option<String>,
    /// Sum K consecutive bins (after the window).
    #[arg(long, value_name = "K", default_value_t = 1)]
    pub rebin: usize,
    /// Subtract a floor per histogram: auto (from bins no return from the volume can reach),
    /// none, or counts per source bin.
    #[arg(long, value_name = "auto|VALUE")]
    pub background: Option<String>,
}

impl Input {
    /// The `.mat` overrides.
    pub fn mat_options(&self) -> io::mat::MatOptions {
        io::mat::MatOptions {
            delta_t: self.delta_t,
            t_start: self.t_start,
            grid_width: self.grid_width,
        }
    }

    /// The preprocessing asked for, if any.
    pub fn prep(&self) -> vltm::Result<Option<Prep>> {
        let p = Prep {
            t_min: self
                .t_min
                .as_deref()
                .map(|s| Bound::parse("t_min", s))
                .transpose()?,
            t_max: self
                .t_max
                .as_deref()
                .map(|s| Bound::parse("t_max", s))
                .transpose()?,
            rebin: self.rebin,
            background: self
                .background
                .as_deref()
                .map(Background::parse)
                .transpose()?
                .unwrap_or_default(),
        };
        Ok((!p.is_identity() || self.rebin == 0).then_some(p))
    }

    /// Opens the capture as a row source: `.mat` through [`io::mat::read`] with the
    /// overrides, other formats through [`io::open_source`] (the overrides are refused there:
    /// those files record their conventions).
    pub fn open(&self, path: &Path) -> vltm::Result<Box<dyn RowSource>> {
        let src: Box<dyn RowSource> = if io::extension(path).as_deref() == Some("mat") {
            vltm::budget::regular_file(path)?;
            Box::new(io::mat::read(path, &self.mat_options())?.capture)
        } else {
            self.refuse_overrides()?;
            require_sidecar(path)?;
            io::open_source(path)?
        };
        Ok(watched(path, src))
    }

    fn refuse_overrides(&self) -> vltm::Result<()> {
        for (set, arg) in [
            (self.delta_t.is_some(), "delta_t"),
            (self.t_start.is_some(), "t_start"),
            (self.grid_width.is_some(), "grid_width"),
        ] {
            if set {
                return Err(vltm::Error::arg(
                    arg,
                    "only for .mat captures (other formats record their time axis and grid)",
                ));
            }
        }
        Ok(())
    }
}

/// Runs `f` on `src`, through the preprocessing when one is asked for: prints what it did,
/// warns when the background removed most histograms, and refuses a result made of empty
/// histograms only.
pub fn with_prep<T, E: Into<Failure>>(
    input: &Input,
    src: &mut dyn RowSource,
    points: &[Point],
    sigma: f64,
    f: impl FnOnce(&mut dyn RowSource) -> Result<T, E>,
) -> Result<T, Failure> {
    let Some(prep) = input.prep()? else {
        return f(src).map_err(Into::into);
    };
    let src_dt = src.geometry().dt;
    let margin = 3.0 * sigma + src_dt * prep.rebin.max(1) as f64;
    let mut p = Prepared::new(src, prep, Reach::of(points, margin))?;
    let out = f(&mut p).map_err(Into::into)?;
    say!("preprocessing: {}", p.summary());
    check_stats(&p)?;
    Ok(out)
}

fn check_stats(p: &Prepared<'_>) -> Result<(), Failure> {
    let s = &p.stats;
    if s.histograms > 0 && s.empty == s.histograms {
        return Err(vltm::Error::arg(
            "background",
            format!(
                "the background removed every count of all {} histograms: nothing left to image (lower it or use auto)",
                s.histograms
            ),
        )
        .into());
    }
    if 2 * s.empty > s.histograms {
        tell!(
            "vltm: warning: the background left {} of {} histograms empty: it is larger than most of the signal",
            s.empty,
            s.histograms
        );
    }
    Ok(())
}

/// A `.ptu` capture whose sidecar is missing: the error names the sidecar, says what it is
/// and how to make one (`vltm info F.ptu --sidecar F.json`).
pub fn require_sidecar(path: &Path) -> vltm::Result<()> {
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
    require_sidecar(path)?;
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

/// `src` (the capture file `path`) with its implausible values (a flipped byte in a file
/// without checksums, negative counts) named in one warning once every row has been read
/// ([`io::plausible`]).
pub(crate) fn watched(path: &Path, src: Box<dyn RowSource>) -> Box<dyn RowSource> {
    Box::new(io::plausible::Watched::new(
        src,
        io::plausible::nonnegative_format(path),
        Box::new(|w: &str| vltm::exec::Progress::warn(&crate::progress::BARS, w)),
    ))
}
