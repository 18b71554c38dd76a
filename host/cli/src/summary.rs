//! The summary line of a probe (`summarize`) and [`finish`]: the summary and the outputs of
//! a probe over a volume.

use std::path::Path;
use vltm::exec::EvalPath;
use vltm::export::h5::Provenance;
use vltm::probe;
use vltm::volume::Volume;
use vltm_kernel::Point;

use crate::args::Common;
use crate::console::{Failure, say, tell};
use crate::outputs::write_outputs;

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
        tell!(
            "vltm: warning: {} non-finite histogram samples were read as 0",
            report.non_finite
        );
    }
    if report.aliased > 0 {
        tell!(
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
    if let Some(c) = o.crop {
        say!("{}: {c}", label.probe);
    }
    match (&o.aligned, o.path) {
        (Some(v), EvalPath::Planar) => say!(
            "{}: path planar, resampled (the volume's x-y pitch does not divide the wall's: computed on --volume {v}, then interpolated within {:.0e} of the scale)",
            label.probe,
            probe::resample::MAX_ERROR
        ),
        (Some(v), p) => say!(
            "{}: path {} (the FFT path needs an x-y pitch dividing the wall's; it would take --volume {v})",
            label.probe,
            p.name()
        ),
        (None, _) => {}
    }
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
