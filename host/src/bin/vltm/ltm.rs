//! The LTM beyond sums on the command line: `matrix` (T between two voxel sets, HDF5),
//! `relight` (the image under a weighted sum of projector foci) and `row` (`T(·, x_b)`,
//! streamed by laser rows).

use std::path::{Path, PathBuf};

use clap::Args;
use vltm::atomic::Transaction;
use vltm::io;
use vltm::out::h5::{MatrixData, Provenance};
use vltm::probe::{self, Pattern, Wave};
use vltm::volume::{Volume, parse_point};
use vltm_kernel::{Point, Weights};

use crate::{
    Common, Failure, WeightsArg, progress, refuse_overwriting_inputs, summarize, write_outputs,
};

/// `vltm matrix`.
#[derive(Args, Debug)]
pub(crate) struct MatrixArgs {
    /// Capture file.
    capture: PathBuf,
    /// Projector foci x_a (the matrix's rows): a SPEC ("x0:x1:nx,y0:y1:ny,z0:z1:nz" or
    /// "x,y,z;x,y,z") or `gamma` (Γ of --volume).
    #[arg(long, value_name = "SPEC|gamma", allow_hyphen_values = true)]
    from: String,
    /// Imaged voxels x_b (the matrix's columns): a SPEC or `gamma`.
    #[arg(long, value_name = "SPEC|gamma", allow_hyphen_values = true)]
    to: String,
    /// The volume whose Γ = {x : direct(x) > ε·max} `gamma` stands for (as `vltm indirect`).
    #[arg(long, value_name = "SPEC", allow_hyphen_values = true)]
    volume: Option<String>,
    /// Relative threshold ε of Γ (0 <= ε < 1).
    #[arg(long, default_value_t = 0.1)]
    epsilon: f32,
    /// Output: HDF5 file (datasets re, im, intensity of shape (n_from, n_to), from_xyz,
    /// to_xyz; the parameters as attributes).
    #[arg(long, value_name = "F.h5", required_unless_present = "partial")]
    out: Option<PathBuf>,
    /// Only the laser rows A..B (B exclusive, 0-based) of the scan: one part of a scan split
    /// over processes. Needs --partial.
    #[arg(long, value_name = "A:B")]
    rows: Option<String>,
    /// Write the accumulator state (one factorised column per --from focus) to F instead of
    /// the matrix; `vltm merge --out F.h5` adds the parts and images the matrix.
    #[arg(long, value_name = "F", conflicts_with = "out")]
    partial: Option<PathBuf>,
    #[command(flatten)]
    wave: WaveArgs,
}

/// The virtual wave options (as for every probe).
#[derive(Args, Debug)]
pub(crate) struct WaveArgs {
    /// Virtual wavelength λ in metres (default: twice the aperture pitch).
    #[arg(long, value_name = "M")]
    wavelength: Option<f64>,
    /// Std of the Gaussian time gate in metres of path (default 2λ/3).
    #[arg(long, value_name = "M")]
    sigma: Option<f64>,
    /// Lens weights per leg: inv = the paper's 1/d, one = none (y-tal).
    #[arg(long, value_enum, default_value_t = WeightsArg::Inv)]
    weights: WeightsArg,
    /// Frequency band half-width in units of 1/σ (truncation error ≈ erfc(m/√2)).
    #[arg(long, default_value_t = 5.0, value_name = "M")]
    band: f64,
    /// Divide each laser row by the physical laser's cos θ / d² falloff to its spot.
    #[arg(long)]
    compensate_laser: bool,
    /// Keep the whole time axis (by default it is cropped to the bins the probed voxels can
    /// reach, with the gate's support, before the band transform).
    #[arg(long)]
    no_crop: bool,
}

impl WaveArgs {
    /// The probes' wave options.
    pub(crate) fn wave(&self) -> Wave {
        Wave {
            wavelength: self.wavelength,
            sigma: self.sigma,
            weights: match self.weights {
                WeightsArg::Inv => Weights::Inv,
                WeightsArg::One => Weights::One,
            },
            band_half_width: self.band,
            compensate_laser: self.compensate_laser,
            auto_margin: true,
            crop: !self.no_crop,
        }
    }
}

fn exec() -> probe::Exec<'static> {
    probe::Exec {
        progress: Some(&progress::BARS),
        ..probe::Exec::default()
    }
}

/// Refuses a matrix output that is not HDF5.
pub(crate) fn check_matrix_out(out: &Path) -> vltm::Result<()> {
    if io::is_hdf5(out) {
        return Ok(());
    }
    Err(vltm::Error::arg(
        "--out",
        format!(
            "{}: the matrix is written as HDF5 (.h5 or .hdf5)",
            out.display()
        ),
    ))
}

/// `vltm matrix`: Γ if asked for, the matrix (or a part's state), the HDF5 file.
pub(crate) fn matrix(a: MatrixArgs) -> Result<(), Failure> {
    let outputs: Vec<&Path> = a
        .out
        .iter()
        .chain(&a.partial)
        .map(PathBuf::as_path)
        .collect();
    refuse_overwriting_inputs(std::slice::from_ref(&a.capture), &outputs)?;
    if let Some(out) = &a.out {
        check_matrix_out(out)?;
    }
    if a.rows.is_some() && a.partial.is_none() {
        return Err(vltm::Error::arg(
            "--rows",
            "a part of a scan is written as a partial state: add --partial F (then `vltm merge` the parts)",
        )
        .into());
    }
    if !(0.0..1.0).contains(&a.epsilon) {
        return Err(vltm::Error::arg(
            "--epsilon",
            format!("expected 0 <= E < 1, found {}", a.epsilon),
        )
        .into());
    }
    let wave = a.wave.wave();
    let wants_gamma = [&a.from, &a.to].iter().any(|s| s.trim() == "gamma");
    if wants_gamma && a.partial.is_some() {
        return Err(vltm::Error::arg(
            "--partial",
            "`gamma` needs the direct light of the whole capture: give --from/--to as SPECs or point lists (Γ's points of a merged direct run)",
        )
        .into());
    }
    let mut src = io::open_source(&a.capture)?;
    let gamma: Option<Vec<Point>> = if wants_gamma {
        let spec = a.volume.as_deref().ok_or_else(|| {
            vltm::Error::arg("--volume", "`gamma` in --from/--to needs the volume of Γ")
        })?;
        let volume = Volume::parse(spec)?;
        let d = probe::direct(&mut *src, &volume, &wave, exec())?;
        let g = probe::gamma_mask(&d.values, a.epsilon);
        let pts: Vec<Point> = volume
            .points
            .iter()
            .zip(&g)
            .filter_map(|(p, &k)| k.then_some(*p))
            .collect();
        if pts.is_empty() {
            return Err(vltm::Error::arg(
                "--epsilon",
                "Γ is empty: no voxel of --volume has direct light above ε·max (all zero)",
            )
            .into());
        }
        say!(
            "Γ: {} of {} voxels above ε = {} of the direct maximum",
            pts.len(),
            volume.len(),
            a.epsilon
        );
        Some(pts)
    } else {
        None
    };
    let set = |arg: &str, s: &str| -> vltm::Result<Vec<Point>> {
        match (s.trim(), &gamma) {
            ("gamma", Some(g)) => Ok(g.clone()),
            _ => Volume::parse(s).map(|v| v.points).map_err(|e| match e {
                vltm::Error::Argument { msg, .. } => vltm::Error::arg(arg, msg),
                e => e,
            }),
        }
    };
    let from = set("--from", &a.from)?;
    let to = set("--to", &a.to)?;
    if let Some(part) = &a.partial {
        let volume = Volume::points(to)?;
        let task = probe::Task::Matrix { from };
        return crate::partial::run_task(
            &a.capture,
            &mut *src,
            &volume,
            &task,
            (&wave, exec()),
            a.rows.as_deref(),
            part,
        );
    }
    let m = probe::matrix(&mut *src, &from, &to, &wave, exec())?;
    let texts = [
        ("from", a.from.trim().to_string()),
        ("to", a.to.trim().to_string()),
        ("volume", a.volume.clone().unwrap_or_default()),
    ];
    let numbers = [
        ("epsilon", f64::from(a.epsilon)),
        (
            "compensate_laser",
            f64::from(u8::from(wave.compensate_laser)),
        ),
    ];
    let out = a.out.as_deref().unwrap_or(Path::new("matrix.h5"));
    write_matrix(&m, &from, &to, &a.capture, out, &numbers, texts)
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
    if m.report.aliased > 0 {
        eprintln!(
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
    vltm::out::h5::stage_matrix(&mut t, out, &data, &meta)?;
    t.commit()?;
    say!("wrote {}", out.display());
    Ok(())
}

/// `vltm relight`.
#[derive(Args, Debug)]
pub(crate) struct RelightArgs {
    /// Capture file.
    capture: PathBuf,
    /// The illumination: weighted foci "x,y,z,w;x,y,z,w" (metres; w = 1 if left out), or a
    /// float32 .npy voxel image of the volume's shape (its voxels are the foci).
    #[arg(long, value_name = "x,y,z,w;...|F.npy", allow_hyphen_values = true)]
    pattern: String,
    #[command(flatten)]
    common: Common,
}

/// `vltm relight`: the pattern, one factorised pass, the outputs.
pub(crate) fn relight(a: RelightArgs) -> Result<(), Failure> {
    let c = &a.common;
    let volume = Volume::parse(&c.volume)?;
    let pattern = if a.pattern.trim().ends_with(".npy") {
        let p = Path::new(a.pattern.trim());
        let (img, shape) = vltm::out::npy::read_f32(p)?;
        if shape.iter().product::<usize>() != volume.len() || shape.len() != 3 {
            return Err(vltm::Error::arg(
                "--pattern",
                format!(
                    "{}: shape {shape:?}, expected the volume's {:?}",
                    p.display(),
                    volume.shape
                ),
            )
            .into());
        }
        Pattern::from_image(&volume, &img)?
    } else {
        Pattern::parse(&a.pattern)?
    };
    let mut src = c.load(&a.capture)?;
    let r = probe::relight(&mut *src, &pattern, &volume, &c.wave(), c.exec())?;
    say!(
        "pattern: {} foci with non-zero weight, {} pass(es) over the capture",
        pattern.foci.len(),
        r.passes
    );
    let title = format!("relit image, {} foci", pattern.foci.len());
    let marks: Vec<(Point, String)> = pattern
        .foci
        .iter()
        .take(8)
        .map(|p| (*p, "p".to_string()))
        .collect();
    finish(c, &a.capture, "relight", &r.output, &volume, &title, &marks)
}

/// `vltm row`.
#[derive(Args, Debug)]
pub(crate) struct RowArgs {
    /// Capture file.
    capture: PathBuf,
    /// Focus x_b of the virtual camera, "X,Y,Z" in metres (z > 0).
    #[arg(long, value_name = "X,Y,Z", allow_hyphen_values = true)]
    focus: String,
    #[command(flatten)]
    common: Common,
}

/// `vltm row`: `T(x_a, x_b)` over the volume's `x_a`, streamed by laser rows.
pub(crate) fn row(a: RowArgs) -> Result<(), Failure> {
    let b = parse_point("--focus", &a.focus)?;
    probe::check_focus(b)?;
    let c = &a.common;
    if c.swap_roles {
        return Err(vltm::Error::arg(
            "--swap-roles",
            "`row` is the transposed column already (use `column --swap-roles` for the in-memory transpose)",
        )
        .into());
    }
    let volume = Volume::parse(&c.volume)?;
    let mut src = c.load(&a.capture)?;
    let o = probe::row(&mut *src, b, &volume, &c.wave(), c.exec())?;
    let marks = [(b, "x_b".to_string())];
    finish(
        c,
        &a.capture,
        "row",
        &o,
        &volume,
        "row T(., x_b), two-bounce gate",
        &marks,
    )
}

/// The summary line and the outputs (`--out`, `--png`) of a probe over a volume.
fn finish(
    c: &Common,
    capture: &Path,
    probe: &str,
    o: &probe::Output,
    volume: &Volume,
    title: &str,
    marks: &[(Point, String)],
) -> Result<(), Failure> {
    summarize(
        probe,
        &o.values,
        volume,
        o.seconds,
        &o.report,
        &o.config,
        Some(o.path),
    );
    if let Some(cr) = o.crop {
        say!("{probe}: {cr}");
    }
    if let Some(v) = &o.aligned {
        say!(
            "{probe}: path {} (the FFT path needs an x-y pitch dividing the wall's; it would take --volume {v})",
            o.path.name()
        );
    }
    let meta = Provenance {
        probe,
        config: &o.config,
        focus: None,
        capture,
    };
    write_outputs((&c.out, &c.png), &meta, &o.values, volume, title, marks)
}
