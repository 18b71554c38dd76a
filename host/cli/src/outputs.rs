//! Writing a probe's outputs: one volume and its figure, or several parts of one run (the
//! near, middle and far shells; Γ and `I_d` beside `I_i`) named `F.<part>.npy` /
//! `F.<part>.png` after `--out F.npy` / `--png F.png`, all in one transaction (all or
//! nothing); a matrix and its summary as HDF5.

use std::path::{Path, PathBuf};

use anyhow::Context;
use vltm::atomic::Transaction;
use vltm::export::figure::Figure;
use vltm::export::h5::{MatrixData, Provenance};
use vltm::io;
use vltm::probe;
use vltm::volume::Volume;
use vltm_kernel::Point;

use crate::console::{Failure, say, tell};

/// One output volume of a run: its name part (`None` for the main output), values, title.
pub(crate) struct Part<'a> {
    /// Inserted before the extension: `F.npy` → `F.<tag>.npy`.
    pub(crate) tag: Option<&'a str>,
    /// One value per voxel.
    pub(crate) values: &'a [f32],
    /// The figure's title.
    pub(crate) title: String,
}

/// `F.npy` → `F.<tag>.npy` (the tag before the last extension).
pub(crate) fn tagged(p: &Path, tag: Option<&str>) -> PathBuf {
    let Some(tag) = tag else {
        return p.to_path_buf();
    };
    match (p.file_stem(), p.extension()) {
        (Some(stem), Some(ext)) => p.with_file_name(format!(
            "{}.{tag}.{}",
            stem.to_string_lossy(),
            ext.to_string_lossy()
        )),
        _ => p.with_file_name(format!(
            "{}.{tag}",
            p.file_name().unwrap_or_default().to_string_lossy()
        )),
    }
}

/// Writes the volume (`c`: `--out` and `--png`; `--out`: `.npy`, or HDF5 for `.h5`/`.hdf5`) and the figure (`--png`);
/// with neither, `<probe>.npy` and `<probe>.png`.
pub(crate) fn write_outputs(
    c: (&Option<PathBuf>, &Option<PathBuf>),
    meta: &Provenance<'_>,
    v: &[f32],
    volume: &Volume,
    title: &str,
    marks: &[(Point, String)],
) -> Result<(), Failure> {
    let part = Part {
        tag: None,
        values: v,
        title: title.to_string(),
    };
    write_parts(c, meta, &[part], volume, marks)
}

/// Writes every part (see [`Part`]) in one transaction.
pub(crate) fn write_parts(
    (c_out, c_png): (&Option<PathBuf>, &Option<PathBuf>),
    meta: &Provenance<'_>,
    parts: &[Part<'_>],
    volume: &Volume,
    marks: &[(Point, String)],
) -> Result<(), Failure> {
    let _t = vltm::timings::section("writing outputs (and fsync)", vltm::timings::Kind::Serial);
    let stem = meta.probe;
    let (out, png) = match (c_out, c_png) {
        (None, None) => (
            Some(PathBuf::from(format!("{stem}.npy"))),
            Some(PathBuf::from(format!("{stem}.png"))),
        ),
        (a, b) => (a.clone(), b.clone()),
    };
    // The volumes and their figures: all or nothing.
    let mut t = Transaction::new();
    let mut wrote = Vec::new();
    for part in parts {
        let v = part.values;
        if let Some(p) = out.as_deref().map(|p| tagged(p, part.tag)) {
            if io::is_hdf5(&p) {
                vltm::export::h5::stage_volume(&mut t, &p, v, volume, meta)
            } else {
                vltm::export::npy::stage_f32(&mut t, &p, v, &volume.shape)
            }
            .with_context(|| format!("writing {}", p.display()))?;
            wrote.push(p);
        }
        if let Some(p) = png.as_deref().map(|p| tagged(p, part.tag)) {
            match volume.axes {
                Some([x, y, z]) => {
                    let fig = Figure {
                        data: v,
                        shape: volume.shape,
                        x,
                        y,
                        z,
                        title: part.title.clone(),
                        marks: marks.to_vec(),
                    };
                    fig.stage_png(&mut t, &p)
                        .with_context(|| format!("writing {}", p.display()))?;
                    wrote.push(p);
                }
                None if part.tag.is_none() => {
                    tell!("vltm: note: no figure for a point list (only for grid volumes)");
                }
                None => {}
            }
        }
    }
    t.commit()?;
    for p in &wrote {
        say!("wrote {}", p.display());
    }
    Ok(())
}

/// Refuses a matrix output that is not HDF5.
pub(crate) fn check_matrix_out(out: &Path) -> vltm::Result<()> {
    prepare_output(out, Out::Matrix)
}

/// What an output file holds, which its extension must say.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Out {
    /// A volume (`--out`): float32 `.npy`, or HDF5 (`.h5`, `.hdf5`).
    Volume,
    /// A figure (`--png`): `.png`.
    Figure,
    /// A matrix: HDF5 (`.h5`, `.hdf5`).
    Matrix,
    /// A capture (`simulate --out`): `.npz`.
    Capture,
    /// A PicoQuant T3 stream: `.ptu`.
    Ptu,
    /// A depth map (`surface --depth`): float32 `.npy`.
    Depth,
    /// A partial state: any name.
    State,
}

impl Out {
    /// The parameter the output comes from, the extensions it may have, and what it is.
    fn spec(self) -> (&'static str, &'static [&'static str], &'static str) {
        match self {
            Self::Volume => (
                "out",
                &["npy", "h5", "hdf5"],
                "a volume is written as float32 .npy, or HDF5 for .h5/.hdf5",
            ),
            Self::Figure => ("png", &["png"], "a figure is written as .png"),
            Self::Matrix => (
                "out",
                &["h5", "hdf5"],
                "the matrix is written as HDF5 (.h5 or .hdf5)",
            ),
            Self::Capture => ("out", &["npz"], "a capture is written as .npz"),
            Self::Ptu => ("ptu", &["ptu"], "a photon stream is written as .ptu"),
            Self::Depth => (
                "depth",
                &["npy"],
                "the depth map is written as float32 .npy",
            ),
            Self::State => ("partial", &[], ""),
        }
    }
}

/// Checks an output path before any work: its extension says what it holds (`--out r.png`
/// is refused, not written as a NumPy array; an existing device such as `/dev/null` is
/// exempt), and its folder exists (it is created here, or refused in one line when it cannot
/// be).
pub(crate) fn prepare_output(p: &Path, kind: Out) -> vltm::Result<()> {
    let (param, exts, what) = kind.spec();
    // An existing device or pipe (`/dev/null`) is written as it is named: no extension.
    let special = std::fs::metadata(p).is_ok_and(|m| !m.is_file() && !m.is_dir());
    if !exts.is_empty() && !special {
        let ext = io::extension(p);
        if !ext.as_deref().is_some_and(|e| exts.contains(&e)) {
            let found = ext.map_or_else(|| "no extension".to_string(), |e| format!(".{e}"));
            return Err(vltm::Error::arg(
                param,
                format!("{}: {what} (found {found})", p.display()),
            ));
        }
    }
    match p.parent() {
        Some(d) if !d.as_os_str().is_empty() && !d.is_dir() => {
            std::fs::create_dir_all(d).map_err(|e| {
                vltm::Error::arg(
                    param,
                    format!(
                        "{}: cannot create its folder {}: {e}",
                        p.display(),
                        d.display()
                    ),
                )
            })
        }
        _ => Ok(()),
    }
}

/// The summary of a matrix and its HDF5 file (all or nothing): `numbers` and `texts` are
/// attributes beside the configuration's.
pub(crate) fn write_matrix(
    m: &probe::Matrix,
    from: &[Point],
    to: &[Point],
    capture: &Path,
    out: &Path,
    numbers: &[(&str, f64)],
    texts: [(&str, String); 3],
) -> Result<(), Failure> {
    let int = m.intensities();
    let (imax, max) =
        int.iter().enumerate().fold(
            (0, f32::NEG_INFINITY),
            |b, (i, &x)| if x > b.1 { (i, x) } else { b },
        );
    let (fa, tb) = (from[imax / m.n_to], to[imax % m.n_to]);
    say!(
        "matrix: {} x {} elements, {} rows x {} pass(es) in {:.2} s (λ = {:.4} m, σ = {:.4} m, J = {}); largest {max:.4e} at x_a = ({:.3}, {:.3}, {:.3}), x_b = ({:.3}, {:.3}, {:.3}) m",
        m.n_from,
        m.n_to,
        m.report.rows,
        m.passes,
        m.seconds,
        m.config.wavelength(),
        m.config.sigma(),
        m.config.bins(),
        fa[0],
        fa[1],
        fa[2],
        tb[0],
        tb[1],
        tb[2]
    );
    if let Some(c) = m.crop {
        say!("matrix: {c}");
    }
    if m.report.aliased > 0 {
        tell!(
            "vltm: warning: {} elements have path lengths outside the capture's alias-free window",
            m.report.aliased
        );
    }
    let meta = Provenance {
        probe: "matrix",
        config: &m.config,
        focus: None,
        capture,
    };
    let cfg = &m.config;
    let mut all = vec![
        ("n_fft", cfg.n_fft() as f64),
        ("band_bins", cfg.bins() as f64),
        ("margin", cfg.params().margin),
    ];
    all.extend_from_slice(numbers);
    let numbers = all;
    let [t0, t1, t2] = texts;
    let texts = [
        t0,
        t1,
        t2,
        ("gate", "two-bounce".to_string()),
        (
            "layout",
            "re, im, intensity: f32 (n_from, n_to), element [i, k] = T(from_xyz[i], to_xyz[k]), intensity = re^2 + im^2".to_string(),
        ),
    ];
    let data = MatrixData {
        amplitudes: &m.amplitudes,
        from,
        to,
        numbers: &numbers,
        texts: &texts,
    };
    let mut t = Transaction::new();
    vltm::export::h5::stage_matrix(&mut t, out, &data, &meta)?;
    t.commit()?;
    say!("wrote {}", out.display());
    Ok(())
}

/// Refuses an output path that names one of the command's input files (the capture, its PTU
/// sidecar, a scene): writing it would destroy the input.
pub(crate) fn refuse_overwriting_inputs(inputs: &[PathBuf], outputs: &[&Path]) -> vltm::Result<()> {
    for o in outputs {
        if let Some(i) = inputs.iter().find(|i| same_file(i, o)) {
            return Err(vltm::Error::arg(
                "out",
                format!(
                    "{} is an input of this command ({}): choose another output path",
                    o.display(),
                    i.display()
                ),
            ));
        }
    }
    Ok(())
}

/// Whether two paths name the same file (after resolving links; for a path that does not
/// exist yet, its directory is resolved).
pub(crate) fn same_file(a: &Path, b: &Path) -> bool {
    let resolve = |p: &Path| {
        p.canonicalize().ok().or_else(|| {
            let dir = match p.parent() {
                Some(d) if !d.as_os_str().is_empty() => d,
                _ => Path::new("."),
            };
            Some(dir.canonicalize().ok()?.join(p.file_name()?))
        })
    };
    match (resolve(a), resolve(b)) {
        (Some(x), Some(y)) => x == y,
        _ => a == b,
    }
}
