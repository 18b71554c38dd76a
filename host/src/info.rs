//! The layout text of `vltm info`: what a capture file holds (format, scan, spots, device
//! positions, time axis, counts), the conventions assumed for it, the memory budget, and the
//! summed transient after an optional preprocessing — one function for every front end, so
//! that the command line and the Python package print the same lines.
//!
//! Units: metres (positions and paths). Cost: one pass over the capture's rows (the summed
//! transient, O(Kl·Ks·Nt)); memory: the capture as [`crate::io::open`] reads it (the whole
//! `H`) plus `Nt` f64.

use std::path::Path;

use crate::error::Result;
use crate::io::prep::{Prep, Prepared};
use crate::io::{self, Capture, RowSource};
use crate::probe;
use vltm_kernel::Point;

/// Where a line of [`info`] goes: the report (stdout) or a warning (stderr).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stream {
    /// A line of the layout text.
    Out,
    /// A warning (without the `vltm: warning: ` prefix).
    Warning,
}

/// The summed transient [`info`] measured: every histogram summed bin by bin (non-finite
/// samples skipped) after the preprocessing, over the path axis `t0 + n·dt` metres.
#[derive(Clone, Debug, PartialEq)]
pub struct Summed {
    /// Counts per bin.
    pub counts: Vec<f64>,
    /// Path length of bin 0 (m).
    pub t0: f64,
    /// Bin width (m of path).
    pub dt: f64,
}

/// Writes `vltm info`'s layout text of the capture file `path` line by line to `say`, and
/// returns the summed transient. `.mat` files are read with `mat`'s overrides (other formats
/// refuse them: they record their time axis and grid); `prep` preprocesses the counts first
/// (the time window, rebinning and background of [`crate::io::prep`]); `volume`, when given,
/// is named in the `fast paths` line (the path it takes, or the aligned grid that is fast). Lines may name
/// parameters as `$name` (a `.mat` file's conventions): front ends spell them as their own
/// flags or arguments ([`crate::error::respell`]).
///
/// # Errors
/// Read errors of the file; [`crate::error::Error::Argument`] for `mat` overrides on other formats
/// and for a preprocessing that leaves nothing.
pub fn info(
    path: &Path,
    mat: &io::mat::MatOptions,
    prep: Option<Prep>,
    volume: Option<&crate::volume::Volume>,
    say: &mut dyn FnMut(Stream, &str),
) -> Result<Summed> {
    let mut out = |s: String| say(Stream::Out, &s);
    let mut c = if io::extension(path).as_deref() == Some("mat") {
        crate::budget::regular_file(path)?;
        let m = io::mat::read(path, mat)?;
        out(format!("capture      {}", path.display()));
        out(format!("format       MATLAB {}", m.version));
        out(format!("variables    {}", m.variables.join(", ")));
        out("conventions:".to_string());
        for line in &m.conventions {
            out(format!("  {line}"));
        }
        m.capture
    } else {
        mat.refuse()?;
        let c = io::open(path)?;
        out(format!("capture      {}", path.display()));
        c
    };
    if io::is_hdf5(path) {
        describe_hdf5(path, &mut out)?;
    }
    describe(&c, &mut out);
    let mut plausible =
        io::plausible::Plausibility::new(&c.geometry, io::plausible::nonnegative_format(path));
    for l in 0..c.geometry.lasers.len() {
        plausible.observe(l, c.row(l));
    }
    out(laser_line(io::laser_falloff_in_data(path)?));
    out(format!("memory       budget {}", crate::budget::describe()));
    let (g, counts) = match prep {
        Some(p) => {
            let mut pr = Prepared::new(&mut c, p, None)?;
            let sum = summed(&mut pr)?;
            let g = pr.geometry().clone();
            out(format!(
                "time window  {} bins x {} m from t0 = {} m (after preprocessing)",
                g.nt, g.dt, g.t0
            ));
            let r = crate::io::prep::check(&pr)?;
            out(format!("preprocessing: {}", r.summary));
            if let Some(w) = &r.warning {
                say(Stream::Warning, w);
            }
            (g, sum)
        }
        None => (c.geometry.clone(), summed(&mut c)?),
    };
    if let Some(w) = plausible.verdict() {
        say(Stream::Warning, &w);
    }
    say(
        Stream::Out,
        &format!("fast paths   {}", crate::probe::fft_note(&g, volume)),
    );
    say(Stream::Out, &volume_line(&g));
    let total: f64 = counts.iter().sum();
    let (peak, _) =
        counts.iter().enumerate().fold(
            (0, f64::NEG_INFINITY),
            |a, (i, &x)| if x > a.1 { (i, x) } else { a },
        );
    say(
        Stream::Out,
        &format!(
            "transient    summed over {} histograms: {total:.4e} counts; peak bin {peak} (path {:.4} m); first 10 % of the bins hold {:.1} % of the counts",
            g.lasers.len() * g.spads_per_row(),
            g.t0 + peak as f64 * g.dt,
            100.0 * counts[..g.nt.div_ceil(10)].iter().sum::<f64>() / total.max(f64::MIN_POSITIVE)
        ),
    );
    Ok(Summed {
        counts,
        t0: g.t0,
        dt: g.dt,
    })
}

/// The histograms of every row summed bin by bin (non-finite samples skipped): the summed
/// transient, `Nt` values over the path axis `t0 + n·Δt`.
///
/// # Errors
/// Read errors.
pub fn summed(src: &mut dyn RowSource) -> Result<Vec<f64>> {
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

/// The `volume` line: the `$volume` [`crate::probe::suggested_volume`] suggests, whose z range
/// is the depths the time window reaches ([`crate::probe::window_depths`]).
fn volume_line(g: &crate::io::capture::Geometry) -> String {
    let end = g.t0 + (g.nt.max(1) - 1) as f64 * g.dt;
    let legs = if g.legs_in_time {
        " + the device legs"
    } else {
        ""
    };
    match crate::probe::suggested_volume(g) {
        Some(spec) => format!(
            "volume       suggested $volume {spec} (x-y: the relay wall's extent and pitch; z: the depths whose nearest 3-bounce path |x_l-x_v|+|x_v-x_s|{legs}, 2z in front of a spot, lies in the time window {:.4}..{end:.4} m)",
            g.t0
        ),
        None => format!(
            "volume       the time window {:.4}..{end:.4} m reaches no depth in front of the wall (the nearest 3-bounce path |x_l-x_v|+|x_v-x_s|{legs} is 2z in front of a spot): check the time axis",
            g.t0
        ),
    }
}

/// The `laser` line: whether the data hold the laser's falloff, and what `$compensate_laser`
/// (off by default) does with it.
fn laser_line((held, why): (bool, &str)) -> String {
    if held {
        format!(
            "laser        falloff cos θ / d² in the data ({why}); $compensate_laser (off by default) divides it out: use it to compare with y-tal and for `indirect`'s in-focus light; leak-corrected columns peak on the lit surface without it (docs/indirect-light.md)"
        )
    } else {
        format!("laser        no falloff in the data ({why}): leave $compensate_laser off")
    }
}

/// The HDF5 layout of a capture: `H_format` and scan type of an `HDF5_TAL` file; axis order,
/// scan type and the conventions applied to a Z-NLOS file.
fn describe_hdf5(path: &Path, out: &mut dyn FnMut(String)) -> Result<()> {
    use io::tal::{Hdf5Layout, ScanType};
    let scan = |s: ScanType| match s {
        ScanType::Exhaustive => "exhaustive (every laser spot x every SPAD spot)",
        ScanType::Confocal => "confocal (the SPAD looks at the laser spot)",
        ScanType::Paired => {
            "paired (one laser spot and one SPAD spot per histogram, apart: a non-confocal \
             galvo or arbitrary scan)"
        }
        ScanType::Single => {
            "single (one laser spot, the SPAD grid scanned): shown below by reciprocity \
             as the SPAD grid's spots as lasers x one SPAD at the laser spot"
        }
    };
    match io::tal::detect(path)? {
        Hdf5Layout::Tal => {
            let r = io::tal::open(path)?;
            out(format!(
                "format       y-tal HDF5_TAL, H_format {} (tal value {}), H shape {:?} (time first)",
                r.h_format().tal_name(),
                r.h_format().tal_value(),
                r.h_shape()
            ));
            out(format!("tal scan     {}", scan(r.scan_type())));
        }
        Hdf5Layout::Znlos => {
            let r = io::tal::znlos::open(path)?;
            out(format!(
                "format       Zaragoza Z-NLOS HDF5 (y-tal HDF5_ZNLOS), data shape {:?}, layout {:?}",
                r.data_shape(),
                r.layout()
            ));
            out(format!("tal scan     {}", scan(r.scan_type())));
            out("conventions (y-tal's Z-NLOS converter, tal/io/format.py):".to_string());
            for line in r.conventions() {
                out(format!("  {line}"));
            }
        }
    }
    Ok(())
}

/// The capture's scan, geometry, time axis and counts.
fn describe(c: &Capture, out: &mut dyn FnMut(String)) {
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
    out(format!(
        "scan         {}",
        if g.coincident() {
            "confocal"
        } else if g.confocal {
            "paired (one laser spot and one SPAD spot per histogram)"
        } else {
            "non-confocal"
        }
    ));
    out(format!(
        "lasers       {} = {}x{} ({})",
        kl,
        g.laser_shape[0],
        g.laser_shape[1],
        span(&g.lasers)
    ));
    out(format!(
        "SPADs        {} = {}x{} ({})",
        g.spads.len(),
        g.spad_shape[0],
        g.spad_shape[1],
        span(&g.spads)
    ));
    let zspan = |p: &[Point]| {
        p.iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), q| {
                (a.min(q[2]), b.max(q[2]))
            })
    };
    // The FFT paths need a flat set of the points they convolve over: the SPAD grid of a
    // grid scan (its laser legs are exact per row), every spot of a confocal scan.
    let conv = if g.confocal { &g.lasers } else { &g.spads };
    let (z0, z1) = zspan(conv);
    let (a0, a1) = zspan(&g.lasers);
    let (b0, b1) = zspan(&g.spads);
    let all = (a0.min(b0), a1.max(b1));
    let flat_conv = z1 - z0 <= 1e-6 * (1.0 + z0.abs().max(z1.abs()));
    let surface = if all.1 - all.0 <= 1e-6 * (1.0 + all.0.abs().max(all.1.abs())) {
        format!("planar (every spot at z = {:.4} m)", all.0)
    } else if !g.confocal && flat_conv {
        format!(
            "not planar (z spans {:.4} m; the SPADs at one z, {:.4} m)",
            all.1 - all.0,
            z0
        )
    } else {
        format!(
            "not planar (z spans {:.4} m): the FFT paths need a flat wall",
            all.1 - all.0
        )
    };
    out(format!("relay        {surface}"));
    let tilt = |ns: &[Point]| {
        ns.iter()
            .filter_map(io::unit)
            .map(|u| u[2].abs().clamp(0.0, 1.0).acos().to_degrees())
            .fold(0.0f64, f64::max)
    };
    out(format!(
        "normals      {}",
        if g.normals.flat() {
            "+z at every spot (none in the file, or all +z)".to_string()
        } else {
            format!(
                "per point from the file ({}; tilted up to {:.1}° from +z): used by $compensate_laser and $weights cos",
                match (g.normals.lasers.is_empty(), g.normals.spads.is_empty()) {
                    (false, false) => "at the laser and SPAD spots",
                    (false, true) => "at the laser spots; +z at the SPAD spots",
                    _ => "at the SPAD spots; +z at the laser spots",
                },
                tilt(&g.normals.lasers).max(tilt(&g.normals.spads))
            )
        }
    ));
    if g.paired_apart() {
        out(
            "paths        direct: phasor, lookup or band (each row imaged with its own laser \
             and SPAD spot; $weights cos on lookup and band); no FFT path (the planar one needs a SPAD grid, the \
             confocal one coincident points); columns, rows and the matrix need a SPAD grid"
                .to_string(),
        );
    } else if !flat_conv {
        out(format!(
            "paths        band or lookup: no FFT path ({}){}",
            if g.confocal {
                "the wall is not flat"
            } else {
                "the SPADs are not in one plane"
            },
            if g.confocal { "; $weights cos too" } else { "" }
        ));
    }
    out(format!(
        "laser_xyz    {:?} m, sensor_xyz {:?} m",
        g.laser_origin, g.sensor_origin
    ));
    out(format!(
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
    ));
    let (mut sum, mut max, mut nonzero, mut bad) = (0.0f64, f32::NEG_INFINITY, 0usize, 0usize);
    for &h in &c.data {
        if h.is_finite() {
            sum += f64::from(h);
            max = max.max(h);
            nonzero += usize::from(h != 0.0);
        } else {
            bad += 1;
        }
    }
    out(format!(
        "histograms   {} = {kl} x {ks} x {} values; sum {sum:.4e}, max {max:.4e}, non-zero {nonzero}, non-finite {bad}",
        c.data.len(),
        g.nt
    ));
    out(format!(
        "default λ    {:.4} m (twice the aperture pitch)",
        probe::default_wavelength(g)
    ));
}
