//! Reading a capture for a command: conventions a file does not record (`--delta-t`,
//! `--t-start`, `--grid-width`, for `.mat` captures), the preprocessing of raw counts
//! (`--t-min`, `--t-max`, `--rebin`, `--background`, [`vltm::io::prep`]), and `vltm info`.

use crate::console::tell;
use crate::console::{Failure, flag, say};
use crate::outputs::refuse_overwriting_inputs;
use clap::Args;
use std::path::Path;
use vltm::atomic::Transaction;
use vltm::export::figure::plot::Transient;
use vltm::io::prep::{Background, Bound, Prep, Prepared, Reach};
use vltm::io::{self, RowSource};
use vltm::probe;
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
        if io::extension(path).as_deref() == Some("mat") {
            return Ok(Box::new(io::mat::read(path, &self.mat_options())?.capture));
        }
        self.refuse_overrides()?;
        io::open_source(path)
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

/// `vltm info`: what the file holds, the conventions assumed, counts after preprocessing,
/// and with `--png` the summed transient.
pub fn info(
    path: &Path,
    input: &Input,
    png: Option<&Path>,
    volume: Option<&str>,
) -> Result<(), Failure> {
    if let Some(p) = png {
        refuse_overwriting_inputs(&[path.to_path_buf()], &[p])?;
    }
    let volume = volume.map(vltm::volume::Volume::parse).transpose()?;
    let mut c = if io::extension(path).as_deref() == Some("mat") {
        let m = io::mat::read(path, &input.mat_options())?;
        say!("capture      {}", path.display());
        say!("format       MATLAB {}", m.version);
        say!("variables    {}", m.variables.join(", "));
        say!("conventions:");
        for line in &m.conventions {
            // The library names the options that set a convention by parameter.
            say!("  {}", vltm::error::respell(line, flag));
        }
        m.capture
    } else {
        input.refuse_overrides()?;
        say!("capture      {}", path.display());
        io::open(path)?
    };
    describe(path, &c)?;
    say!("memory       budget {}", vltm::budget::describe());
    let prep = input.prep()?;
    let (g, sum) = match prep {
        Some(p) => {
            let mut pr = Prepared::new(&mut c, p, None)?;
            let sum = summed(&mut pr)?;
            let g = pr.geometry().clone();
            say!(
                "time window  {} bins x {} m from t0 = {} m (after preprocessing)",
                g.nt,
                g.dt,
                g.t0
            );
            say!("preprocessing: {}", pr.summary());
            check_stats(&pr)?;
            (g, sum)
        }
        None => (c.geometry.clone(), summed(&mut c)?),
    };
    say!("fast paths   {}", probe::fft_note(&g, volume.as_ref()));
    let total: f64 = sum.iter().sum();
    let (peak, _) =
        sum.iter().enumerate().fold(
            (0, f64::NEG_INFINITY),
            |a, (i, &x)| if x > a.1 { (i, x) } else { a },
        );
    say!(
        "transient    summed over {} histograms: {total:.4e} counts; peak bin {peak} (path {:.4} m); first 10 % of the bins hold {:.1} % of the counts",
        g.lasers.len() * g.spads_per_row(),
        g.t0 + peak as f64 * g.dt,
        100.0 * sum[..g.nt.div_ceil(10)].iter().sum::<f64>() / total.max(f64::MIN_POSITIVE)
    );
    if let Some(p) = png {
        let name = path
            .file_name()
            .map_or(String::new(), |n| n.to_string_lossy().into_owned());
        let t = Transient {
            counts: &sum,
            t0: g.t0,
            dt: g.dt,
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

/// The histograms of every row summed bin by bin (non-finite samples skipped).
fn summed(src: &mut dyn RowSource) -> vltm::Result<Vec<f64>> {
    let g = src.geometry().clone();
    let mut sum = vec![0.0f64; g.nt];
    let mut row = Vec::new();
    for l in 0..g.lasers.len() {
        src.read_row(l, &mut row)?;
        for h in row.chunks_exact(g.nt) {
            for (s, &x) in sum.iter_mut().zip(h) {
                if x.is_finite() {
                    *s += f64::from(x);
                }
            }
        }
    }
    Ok(sum)
}

/// The HDF5 layout of a capture for `vltm info`: `H_format` and scan type of an `HDF5_TAL`
/// file; axis order, scan type and the conventions applied to a Z-NLOS file.
pub fn describe_hdf5(path: &Path) -> vltm::Result<()> {
    use io::tal::{Hdf5Layout, ScanType};
    let scan = |s: ScanType| match s {
        ScanType::Exhaustive => "exhaustive (every laser spot x every SPAD spot)",
        ScanType::Confocal => "confocal (the SPAD looks at the laser spot)",
        ScanType::Single => {
            "single (one laser spot, the SPAD grid scanned): shown below by reciprocity \
             as the SPAD grid's spots as lasers x one SPAD at the laser spot"
        }
    };
    match io::tal::detect(path)? {
        Hdf5Layout::Tal => {
            let r = io::tal::open(path)?;
            say!(
                "format       y-tal HDF5_TAL, H_format {} (tal value {}), H shape {:?} (time first)",
                r.h_format().tal_name(),
                r.h_format().tal_value(),
                r.h_shape()
            );
            say!("tal scan     {}", scan(r.scan_type()));
        }
        Hdf5Layout::Znlos => {
            let r = io::tal::znlos::open(path)?;
            say!(
                "format       Zaragoza Z-NLOS HDF5 (y-tal HDF5_ZNLOS), data shape {:?}, layout {:?}",
                r.data_shape(),
                r.layout()
            );
            say!("tal scan     {}", scan(r.scan_type()));
            say!("conventions (y-tal's Z-NLOS converter, tal/io/format.py):");
            for line in r.conventions() {
                say!("  {}", vltm::error::respell(line, flag));
            }
        }
    }
    Ok(())
}

/// The capture's format (HDF5), geometry, time axis and counts, for `vltm info`.
fn describe(path: &Path, c: &io::Capture) -> Result<(), Failure> {
    let g = &c.geometry;
    let (kl, ks) = (g.lasers.len(), g.spads_per_row());
    let span = |p: &[Point]| {
        let lo: Vec<f32> = (0..3)
            .map(|i| p.iter().map(|q| q[i]).fold(f32::INFINITY, f32::min))
            .collect();
        let hi: Vec<f32> = (0..3)
            .map(|i| p.iter().map(|q| q[i]).fold(f32::NEG_INFINITY, f32::max))
            .collect();
        format!(
            "x {:.3}..{:.3}, y {:.3}..{:.3}, z {:.3}..{:.3} m",
            lo[0], hi[0], lo[1], hi[1], lo[2], hi[2]
        )
    };
    if io::is_hdf5(path) {
        describe_hdf5(path)?;
    }
    say!(
        "scan         {}",
        if g.confocal {
            "confocal"
        } else {
            "non-confocal"
        }
    );
    say!(
        "lasers       {} = {}x{} ({})",
        kl,
        g.laser_shape[0],
        g.laser_shape[1],
        span(&g.lasers)
    );
    say!(
        "SPADs        {} = {}x{} ({})",
        g.spads.len(),
        g.spad_shape[0],
        g.spad_shape[1],
        span(&g.spads)
    );
    say!(
        "laser_xyz    {:?} m, sensor_xyz {:?} m",
        g.laser_origin,
        g.sensor_origin
    );
    say!(
        "time axis    {} bins x {} m from t0 = {} m to {:.4} m; device legs {}",
        g.nt,
        g.dt,
        g.t0,
        g.t0 + (g.nt as f64 - 1.0) * g.dt,
        if g.legs_in_time {
            "included"
        } else {
            "not included (wall to wall)"
        }
    );
    let (mut sum, mut max, mut nonzero, mut bad) = (0.0f64, f32::NEG_INFINITY, 0usize, 0usize);
    for &h in &c.data {
        if h.is_finite() {
            sum += h as f64;
            max = max.max(h);
            nonzero += usize::from(h != 0.0);
        } else {
            bad += 1;
        }
    }
    say!(
        "histograms   {} = {kl} x {ks} x {} values; sum {sum:.4e}, max {max:.4e}, non-zero {nonzero}, non-finite {bad}",
        c.data.len(),
        g.nt
    );
    say!(
        "default λ    {:.4} m (twice the aperture pitch)",
        probe::default_wavelength(g)
    );
    Ok(())
}
