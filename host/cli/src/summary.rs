//! The summary lines of a run (`describe` for `vltm info`, `summarize` for a probe) and
//! [`finish`]: the summary and the outputs of a probe over a volume.

use std::path::Path;
use vltm::exec::Path as EvalPath;
use vltm::export::h5::Provenance;
use vltm::io;
use vltm::probe;
use vltm::volume::Volume;
use vltm_kernel::Point;

use crate::args::Common;
use crate::console::{Failure, say};
use crate::input;
use crate::outputs::write_outputs;

/// The capture's format (HDF5), geometry, time axis and counts, for `vltm info`.
pub(crate) fn describe(path: &Path, c: &io::Capture) -> Result<(), Failure> {
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
        input::describe_hdf5(path)?;
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

/// The summary line of a probe: voxels, rows, time, the configuration and the peak; warnings
/// for non-finite samples and aliased voxels.
pub(crate) fn summarize(
    what: &str,
    v: &[f32],
    volume: &Volume,
    seconds: f64,
    report: &vltm_kernel::Report,
    cfg: &vltm_kernel::Config,
    path: Option<EvalPath>,
) {
    let (i, m) =
        v.iter().enumerate().fold(
            (0, f32::NEG_INFINITY),
            |a, (i, &x)| if x > a.1 { (i, x) } else { a },
        );
    let p = volume.points.get(i).copied().unwrap_or_default();
    let path = path.map_or(String::new(), |p| format!(", path {}", p.name()));
    say!(
        "{what}: {} voxels, {} rows in {seconds:.2} s (λ = {:.4} m, σ = {:.4} m, J = {}{path}); peak {m:.4e} at ({:.3}, {:.3}, {:.3}) m",
        v.len(),
        report.rows,
        cfg.wavelength(),
        cfg.sigma(),
        cfg.bins(),
        p[0],
        p[1],
        p[2]
    );
    if report.non_finite > 0 {
        eprintln!(
            "vltm: warning: {} non-finite histogram samples were read as 0",
            report.non_finite
        );
    }
    if report.aliased > 0 {
        eprintln!(
            "vltm: warning: {} voxels have path lengths outside the capture's alias-free window",
            report.aliased
        );
    }
}

/// What a probe's outputs are labelled with.
pub(crate) struct Label<'a> {
    /// The probe's name (`direct`, `column`, …): the summary line and the HDF5 provenance.
    pub(crate) probe: &'a str,
    /// The figure's title.
    pub(crate) title: String,
    /// A column's focus x_a: recorded in an HDF5 volume and marked in the figure.
    pub(crate) focus: Option<Point>,
    /// Further points marked in the figure (a row's x_b, a pattern's foci).
    pub(crate) marks: Vec<(Point, String)>,
}

/// The summary line and the outputs (`--out`, `--png`) of a probe over a volume: the one
/// ending of `direct`, `column`, `relight` and `row`.
pub(crate) fn finish(
    common: &Common,
    capture: &Path,
    o: &probe::Output,
    volume: &Volume,
    label: Label<'_>,
) -> Result<(), Failure> {
    summarize(
        label.probe,
        &o.values,
        volume,
        o.seconds,
        &o.report,
        &o.config,
        Some(o.path),
    );
    let meta = Provenance {
        probe: label.probe,
        config: &o.config,
        focus: label.focus,
        capture,
    };
    let mut marks: Vec<(Point, String)> = label
        .focus
        .map(|a| (a, "x_a".to_string()))
        .into_iter()
        .collect();
    marks.extend(label.marks);
    write_outputs(
        (&common.out, &common.png),
        &meta,
        &o.values,
        volume,
        &label.title,
        &marks,
    )
}
