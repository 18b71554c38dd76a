//! The command line's partial runs: `--rows A:B --partial F` on `direct`, `column`,
//! `indirect` and `matrix` (the accumulator state of a part of the scan), `vltm merge` (add
//! the parts and finish them: a volume, or the matrix's HDF5 file), and reading a
//! direct-light `.npy` for Γ.

use crate::args::Common;
use crate::console::{Failure, say};
use crate::open;
use crate::outputs::{
    Out, check_matrix_out, prepare_output, refuse_overwriting_inputs, write_matrix, write_outputs,
};
use crate::summary::summarize;
use std::ops::Range;
use std::path::{Path, PathBuf};
use vltm::export::h5::Provenance;
use vltm::io::RowSource;
use vltm::probe::{Exec, Partial, Task, Wave, partial};
use vltm::volume::Volume;

/// Whether the probe's run is a partial one (`--partial`); `--rows` without it is refused.
pub(crate) fn wanted(c: &Common) -> vltm::Result<bool> {
    match (&c.rows, &c.partial) {
        (Some(_), None) => Err(vltm::Error::arg(
            "rows",
            "a part of a scan is written as a partial state: add $partial F (then `vltm merge` the parts)",
        )),
        (_, Some(_)) if c.input.prep()?.is_some() => Err(vltm::Error::arg(
            "partial",
            "partial states do not record preprocessing yet: run without $t_min/$t_max/$rebin/$background",
        )),
        (_, p) => Ok(p.is_some()),
    }
}

/// Parses `A:B` (`A <= B`; either side may be left out: `:B`, `A:`, `:`) against `n` rows.
pub(crate) fn parse_rows(s: &str, n: usize) -> vltm::Result<Range<usize>> {
    let bad = || {
        vltm::Error::arg(
            "rows",
            format!("expected A:B with 0 <= A <= B <= {n} (laser rows, B exclusive), found `{s}`"),
        )
    };
    let (a, b) = s.split_once(':').ok_or_else(bad)?;
    let num = |t: &str, d: usize| {
        let t = t.trim();
        if t.is_empty() {
            Ok(d)
        } else {
            t.parse::<usize>().map_err(|_| bad())
        }
    };
    let (a, b) = (num(a, 0)?, num(b, n)?);
    if a > b || b > n {
        return Err(bad());
    }
    Ok(a..b)
}

/// Runs `task` over `--rows` of the capture and writes its state to `--partial`.
pub(crate) fn run(c: &Common, capture: &Path, task: Task) -> Result<(), Failure> {
    let volume = Volume::parse(&c.volume)?;
    let mut src = open::capture(c, capture)?;
    let Some(out) = &c.partial else {
        return Ok(());
    };
    let wave = c.wave();
    run_task(
        capture,
        &mut *src,
        &volume,
        &task,
        (&wave, c.exec()),
        c.rows.as_deref(),
        out,
    )
}

/// Runs `task` over the rows `rows` (`A:B`, default all) of `src` (the capture file
/// `capture`) and writes its state to `out`.
pub(crate) fn run_task(
    capture: &Path,
    src: &mut dyn RowSource,
    volume: &Volume,
    task: &Task,
    (wave, exec): (&Wave, Exec<'_>),
    rows: Option<&str>,
    out: &Path,
) -> Result<(), Failure> {
    let n = src.geometry().lasers.len();
    let rows = match rows {
        Some(r) => parse_rows(r, n)?,
        None => 0..n,
    };
    let bytes = std::fs::metadata(capture)
        .map_err(|e| vltm::Error::io(capture, e))?
        .len();
    let name = capture
        .file_name()
        .map_or_else(String::new, |f| f.to_string_lossy().into_owned());
    let t = std::time::Instant::now();
    let p = partial::accumulate(src, bytes, &name, volume, task, wave, exec, rows.clone())?;
    p.write(out)?;
    say!(
        "{}: rows {}:{} of {n} in {:.2} s; wrote {} ({} bytes)",
        p.kind(),
        rows.start,
        rows.end,
        t.elapsed().as_secs_f64(),
        out.display(),
        p.byte_len()
    );
    Ok(())
}

/// `vltm merge`: reads the parts, adds them, and writes the merged state (`--partial`) or
/// the finished volume and figure.
pub(crate) fn merge(
    parts: &[PathBuf],
    out: Option<PathBuf>,
    png: Option<PathBuf>,
    state: Option<PathBuf>,
) -> Result<(), Failure> {
    let outputs: Vec<&Path> = out
        .iter()
        .chain(&png)
        .chain(&state)
        .map(PathBuf::as_path)
        .collect();
    refuse_overwriting_inputs(parts, &outputs)?;
    for (p, kind) in [
        (&out, Out::Volume),
        (&png, Out::Figure),
        (&state, Out::State),
    ] {
        if let Some(p) = p {
            prepare_output(p, kind)?;
        }
    }
    let names: Vec<String> = parts.iter().map(|p| p.display().to_string()).collect();
    let read = parts
        .iter()
        .map(|p| Partial::read(p))
        .collect::<vltm::Result<Vec<_>>>()?;
    let merged = Partial::merge(read, &names)?;
    if let Some(s) = &state {
        merged.write(s)?;
        say!("wrote {} ({} bytes)", s.display(), merged.byte_len());
        if out.is_none() && png.is_none() {
            return Ok(());
        }
    }
    let f = merged.finish()?;
    let o = &f.output;
    let kind = merged.kind().to_string();
    if let Some(m) = &f.matrix {
        let Some(out) = &out else {
            return Err(vltm::Error::arg(
                "out",
                "merged matrix parts are written as HDF5: add $out F.h5",
            )
            .into());
        };
        if png.is_some() {
            return Err(vltm::Error::arg("png", "a matrix has no figure: leave out $png").into());
        }
        check_matrix_out(out)?;
        let texts = [
            ("from", format!("{} points (partial states)", m.n_from)),
            ("to", format!("{} points (partial states)", m.n_to)),
            ("volume", String::new()),
        ];
        let capture = PathBuf::from(merged.capture_name());
        let to = &f.volume.points;
        return write_matrix(m, merged.from_points(), to, &capture, out, &[], texts);
    }
    if let Some(e) = f.explained {
        say!(
            "leak correction: {e:.4} of the capture's energy was in the 3-vertex windows of Γ and removed"
        );
    }
    summarize(
        &kind,
        &o.values,
        &f.volume,
        o.seconds,
        &o.report,
        &o.config,
        Some(o.path),
    );
    let probe: &'static str = match kind.as_str() {
        "direct" => "direct",
        "column" => "column",
        _ => "indirect",
    };
    let capture = PathBuf::from(merged.capture_name());
    let meta = Provenance {
        probe,
        config: &o.config,
        focus: merged.focus(),
        capture: &capture,
    };
    let marks: Vec<_> = merged
        .focus()
        .map(|a| (a, "x_a".to_string()))
        .into_iter()
        .collect();
    let title = match (probe, merged.focus()) {
        ("direct", _) => crate::title::direct("gaussian", &o.config),
        ("column", Some(a)) => crate::title::merged_column(a, &o.config),
        _ => "in-focus indirect light".to_string(),
    };
    write_outputs((&out, &png), &meta, &o.values, &f.volume, &title, &marks)
}

/// A direct-light volume (float32 `.npy` of `volume`'s shape or length) for Γ.
pub(crate) fn read_direct(path: &Path, volume: &Volume) -> vltm::Result<Vec<f32>> {
    use ndarray_npy::ReadNpyExt as _;
    let f = std::fs::File::open(path).map_err(|e| vltm::Error::io(path, e))?;
    let a = ndarray::ArrayD::<f32>::read_npy(f)
        .map_err(|e| vltm::Error::format(path, "array", "a float32 .npy volume", e.to_string()))?;
    if a.len() != volume.len() {
        return Err(vltm::Error::format(
            path,
            "shape",
            format!("{} values, the voxels of $volume", volume.len()),
            format!("{:?}", a.shape()),
        ));
    }
    Ok(a.iter().copied().collect())
}
