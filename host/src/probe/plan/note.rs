//! The notes of the path chosen: the progress label a pass carries (`path lookup; the FFT path
//! would take …`), the aligned grid a probe reports, and `vltm info`'s line on the FFT paths.

use crate::exec::EvalPath;
use crate::io::capture::Geometry;
use crate::probe::fast::aligned::{aligned_volume, suggested_volume};
use crate::probe::fast::lattice;
use crate::probe::wave::default_wavelength;
use crate::volume::Volume;

/// The progress note of a diagonal pass on `path` (`path lookup; the FFT path would take
/// $volume …`) and the aligned grid the probe reports ([`crate::probe::Output::aligned`]): for
/// a volume resampled from a support grid (`support`: its SPEC) that grid; under `cos` weights
/// (`cosine`) a note naming them.
pub(crate) fn diagonal_notes(
    g: &Geometry,
    volume: &Volume,
    wavelength: f64,
    path: EvalPath,
    support: Option<String>,
    cosine: bool,
) -> (String, Option<String>) {
    if let Some(s) = support {
        return (format!("path planar, resampled from $volume {s}"), Some(s));
    }
    let hint = aligned_hint(g, volume, wavelength, path);
    let note = match (&hint, cosine) {
        (_, true) => "cos weights (the wall's cosine per leg)".to_string(),
        (Some(v), false) => format!("path {}; the FFT path would take $volume {v}", path.name()),
        (None, false) => format!("path {}", path.name()),
    };
    (note, hint)
}

/// The aligned `$volume` SPEC the FFT path would take, for a grid that ran on another `path`:
/// [`aligned_volume`] when the wall is a regular lattice
/// and the aligned grid lays out on it (lattice tolerance `1e-5·λ`, as the paths check).
fn aligned_hint(g: &Geometry, volume: &Volume, wavelength: f64, path: EvalPath) -> Option<String> {
    // No FFT path takes a paired scan with laser and SPAD apart: no grid would be fast.
    if path == EvalPath::Planar || volume.axes.is_none() || g.paired_apart() {
        return None;
    }
    let spec = aligned_volume(g, volume)?;
    let v = Volume::parse(&spec).ok()?;
    let wall = if g.confocal { &g.lasers } else { &g.spads };
    lattice::layout(wall, &v.points, v.shape, 1e-5 * wavelength).ok()?;
    Some(spec)
}

/// What the FFT paths take on this capture, for `vltm info`: the wall lattice's pitch and a
/// `--volume` SPEC on it, or why the wall is not a lattice; with `volume`, which path that
/// grid gets (exact FFT, resampled FFT or lookup, the aligned SPEC). The lattice tolerance is
/// `1e-5·λ` at the default wavelength.
pub fn fft_note(g: &Geometry, volume: Option<&Volume>) -> String {
    let wall = if g.confocal { &g.lasers } else { &g.spads };
    let tol = 1e-5 * default_wavelength(g);
    let (origin, pitch, n, _) = match lattice::wall_lattice(wall, tol) {
        Ok(l) => l,
        Err(e) => {
            return format!(
                "no FFT path: the wall points are not a regular lattice in one plane ({e}); direct light takes the phasor, the lookup or the band path"
            );
        }
    };
    let f = |x: f64| {
        let t = format!("{:.7}", if x.abs() < 5e-8 { 0.0 } else { x });
        t.trim_end_matches('0').trim_end_matches('.').to_string()
    };
    let axis = |i: usize| {
        let end = origin[i] + (n[i] - 1) as f64 * pitch[i];
        format!("{}:{}:{}", f(origin[i]), f(end), n[i])
    };
    let mut s = format!(
        "FFT path for wall-parallel grids of x-y pitch {} x {} m (the wall's) or an integer divisor, any offset and extent, e.g. $volume {}; other regular grids are resampled from such a grid where λ and σ allow it (the probe says so), else they take the phasor, lookup or band path (the cheapest)",
        f(pitch[0]),
        f(pitch[1]),
        suggested_volume(g).unwrap_or_else(|| format!("{},{},Z0:Z1:NZ", axis(0), axis(1)))
    );
    if let Some(v) = volume {
        let what = if v.axes.is_none() {
            "a point list: the phasor, lookup or band path".to_string()
        } else if lattice::layout(wall, &v.points, v.shape, tol).is_ok() {
            "on the wall's lattice: the FFT path".to_string()
        } else {
            match aligned_volume(g, v) {
                Some(a) => format!(
                    "off the wall's lattice: resampled from a finer aligned grid where λ and σ allow it, else the phasor or lookup path; the nearest aligned grid is $volume {a}"
                ),
                None => {
                    "off the wall's lattice: resampled where λ and σ allow it, else the phasor or lookup path"
                        .to_string()
                }
            }
        };
        s.push_str(&format!("\nthe volume   {what}"));
    }
    s
}
