//! One rule for a capture's time window, shared by every probe (`direct`, `column`,
//! `indirect`, `matrix`, `row`, `relight`, and any front end that streams probes).
//!
//! A probe images paths `x_l → x_a → x_b → x_s` (on the diagonal `x_a = x_b`) whose length
//! `τ = d1 + |x_l − x_a| + |x_a − x_b| + |x_b − x_s| + d4` (metres of optical path; `d1`, `d4`
//! the device legs when the capture's times include them) must fall where the capture
//! recorded light. The **window** of this rule is the recorded time axis widened by one gate
//! σ on each side, `[t0 − σ, t0 + (Nt − 1)Δt + σ]`: a path within σ of the axis still sees
//! the Gaussian gate's central lobe (weight ≥ e^{−1/2}); a path further out sees only its
//! tail, and an image made of such paths alone is numerical noise (a peak of 10⁻¹⁴ where the
//! window holds the scene).
//!
//! - When **no** path meets the window, every probe refuses the run with the same one-line
//!   error ([`window_coverage`]; [`Error::Argument`] on `volume`), before any work.
//! - When fewer than [`WARN_FRACTION`] of the paths do, the probes warn (through
//!   [`Progress::warn`](crate::Progress::warn)) and run.
//! - The higher-order gate images light arriving **after** a path's time: a path meets the
//!   window when it is no later than the window's end. The ungated (monochromatic) probes do
//!   not depend on path times: the rule does not apply to them.
//!
//! Cost: the existence test takes the span of path lengths per (focus, voxel) pair from the
//! per-point spans over lasers and SPADs, `O(F·Kl + V·Ks + F·V)`, and stops at the first pair
//! that meets the window. The fraction is counted exactly on a strided sample of at most 32
//! lasers × 32 SPADs × 32 foci × 1024 voxels (sorted legs, `O(n log n)` per pair).

use super::wave::{ColumnGate, dist, legs};
use crate::error::{Error, Result};
use crate::exec::Exec;
use crate::io::capture::Geometry;
use rayon::prelude::*;
use vltm_kernel::{Config, Point};

/// The probes warn when fewer than this fraction of the sampled paths lie in the window.
pub const WARN_FRACTION: f64 = 0.25;

/// How the probed paths meet a capture's window ([`window_coverage`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coverage {
    /// Fraction of the (sampled) paths whose length lies in the window, in `[0, 1]`.
    pub fraction: f64,
    /// The window `[t0 − σ, t0 + (Nt − 1)Δt + σ]` (m of path).
    pub window: (f64, f64),
    /// The span of the paths' lengths (m), over every laser, SPAD, focus and voxel.
    pub span: (f64, f64),
}

impl Coverage {
    /// The warning for a fraction under [`WARN_FRACTION`] (`None` above it).
    pub fn warning(&self) -> Option<String> {
        (self.fraction < WARN_FRACTION).then(|| {
            format!(
                "only {:.1} % of the paths through the probed points lie in the capture's time window ({:.4} to {:.4} m of path; the paths span {:.4} to {:.4} m): the rest contribute nothing",
                100.0 * self.fraction,
                self.window.0,
                self.window.1,
                self.span.0,
                self.span.1
            )
        })
    }
}

/// Sample caps of the fraction (lasers, SPADs, foci, voxels).
const SAMPLE: (usize, usize, usize, usize) = (32, 32, 32, 1024);

/// Every `len / cap`-th index (at most `cap` of them, first and spread over the range).
fn strided(len: usize, cap: usize) -> impl Iterator<Item = usize> {
    let step = len.div_ceil(cap).max(1);
    (0..len).step_by(step)
}

/// How the paths from `foci` to `voxels` (the diagonal through `voxels` for `foci = None`)
/// meet the capture's window under `gate` (see the module docs). `cfg` is the capture's
/// configuration ([`Wave::config`](super::Wave::config)): its σ widens the window and its legs
/// give `d1`, `d4`.
///
/// # Errors
/// [`Error::Argument`] on `volume` when no path meets the window: the same one line for
/// every probe, naming the window (the paths' span is in [`Coverage::span`] otherwise).
pub fn window_coverage(
    g: &Geometry,
    cfg: &Config,
    foci: Option<&[Point]>,
    voxels: &[Point],
    gate: ColumnGate,
) -> Result<Coverage> {
    let sigma = cfg.sigma();
    let window = (g.t0 - sigma, g.t0 + cfg.window() + sigma);
    let full = Coverage {
        fraction: 1.0,
        window,
        span: (f64::NAN, f64::NAN),
    };
    if voxels.is_empty() || foci.is_some_and(<[Point]>::is_empty) || gate == ColumnGate::None {
        return Ok(full);
    }
    let after_only = gate == ColumnGate::HigherOrder;
    let (lo, hi) = window;
    let meets = |(a, b): (f64, f64)| a <= hi && (after_only || b >= lo);
    let (d1, d4) = legs(g, cfg);
    let span = |pts: &[Point], legs: &[f64], v: &Point| {
        pts.iter()
            .zip(legs)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (p, d)| {
                let x = f64::from(dist(*p, *v)) + d;
                (a.min(x), b.max(x))
            })
    };
    let join = |x: (f64, f64), y: (f64, f64)| (x.0.min(y.0), x.1.max(y.1));
    let empty = (f64::INFINITY, f64::NEG_INFINITY);
    // Spans of the camera legs per voxel, of the projector legs per focus.
    let cam: Vec<(f64, f64)> = voxels.par_iter().map(|b| span(&g.spads, &d4, b)).collect();
    let pair = |a: &Point, p: (f64, f64), b: &Point, c: (f64, f64)| {
        let d = f64::from(dist(*a, *b));
        (p.0 + d + c.0, p.1 + d + c.1)
    };
    let (found, all) = match foci {
        None => {
            let proj: Vec<(f64, f64)> =
                voxels.par_iter().map(|v| span(&g.lasers, &d1, v)).collect();
            let spans: Vec<(f64, f64)> = proj
                .iter()
                .zip(&cam)
                .map(|(p, c)| (p.0 + c.0, p.1 + c.1))
                .collect();
            let found = spans.par_iter().any(|&s| meets(s));
            (found, spans.iter().fold(empty, |a, &s| join(a, s)))
        }
        Some(foci) => {
            let proj: Vec<(f64, f64)> = foci.par_iter().map(|a| span(&g.lasers, &d1, a)).collect();
            let found = foci.par_iter().zip(&proj).any(|(a, &p)| {
                voxels
                    .iter()
                    .zip(&cam)
                    .any(|(b, &c)| meets(pair(a, p, b, c)))
            });
            let all = foci
                .par_iter()
                .zip(&proj)
                .map(|(a, &p)| {
                    voxels
                        .iter()
                        .zip(&cam)
                        .fold(empty, |acc, (b, &c)| join(acc, pair(a, p, b, c)))
                })
                .reduce(|| empty, join);
            (found, all)
        }
    };
    if !found {
        return Err(Error::arg(
            "volume",
            format!(
                "no path through the probed points lies in the capture's time window ({:.4} to {:.4} m of path: its time axis widened by σ = {:.4} m): choose points the capture saw, or check its t_start and delta_t",
                lo, hi, sigma
            ),
        ));
    }
    Ok(Coverage {
        fraction: sampled_fraction(g, (&d1, &d4), foci, voxels, window, after_only),
        window,
        span: all,
    })
}

/// The fraction of sampled paths in the window (module docs).
fn sampled_fraction(
    g: &Geometry,
    (d1, d4): (&[f64], &[f64]),
    foci: Option<&[Point]>,
    voxels: &[Point],
    (lo, hi): (f64, f64),
    after_only: bool,
) -> f64 {
    let (nl, ns, nf, nv) = SAMPLE;
    let lasers: Vec<usize> = strided(g.lasers.len(), nl).collect();
    let spads: Vec<usize> = strided(g.spads.len(), ns).collect();
    let vox: Vec<usize> = strided(voxels.len(), nv).collect();
    let sorted_legs = |pts: &[Point], legs: &[f64], idx: &[usize], x: &Point| {
        let mut v: Vec<f64> = idx
            .iter()
            .map(|&i| f64::from(dist(pts[i], *x)) + legs[i])
            .collect();
        v.sort_by(f64::total_cmp);
        v
    };
    // Pairs (p_i, c_j) with p_i + d + c_j in [lo, hi]: two binary searches per p_i.
    let count = |p: &[f64], d: f64, c: &[f64]| -> usize {
        p.iter()
            .map(|&x| {
                let base = x + d;
                let first = if after_only {
                    0
                } else {
                    c.partition_point(|&y| base + y < lo)
                };
                let last = c.partition_point(|&y| base + y <= hi);
                last.saturating_sub(first)
            })
            .sum()
    };
    let (inside, total) = match foci {
        None => vox
            .par_iter()
            .map(|&v| {
                let x = &voxels[v];
                let p = sorted_legs(&g.lasers, d1, &lasers, x);
                let c = sorted_legs(&g.spads, d4, &spads, x);
                (count(&p, 0.0, &c), p.len() * c.len())
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1)),
        Some(foci) => {
            let cams: Vec<Vec<f64>> = vox
                .par_iter()
                .map(|&v| sorted_legs(&g.spads, d4, &spads, &voxels[v]))
                .collect();
            strided(foci.len(), nf)
                .collect::<Vec<_>>()
                .par_iter()
                .map(|&f| {
                    let a = &foci[f];
                    let p = sorted_legs(&g.lasers, d1, &lasers, a);
                    vox.iter().zip(&cams).fold((0, 0), |acc, (&v, c)| {
                        let d = f64::from(dist(*a, voxels[v]));
                        (acc.0 + count(&p, d, c), acc.1 + p.len() * c.len())
                    })
                })
                .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
        }
    };
    if total == 0 {
        1.0
    } else {
        inside as f64 / total as f64
    }
}

/// [`window_coverage`] with the probes' warning sent to `exec`'s progress sink.
///
/// # Errors
/// As [`window_coverage`].
pub(super) fn window_rule(
    g: &Geometry,
    cfg: &Config,
    foci: Option<&[Point]>,
    voxels: &[Point],
    gate: ColumnGate,
    exec: Exec<'_>,
) -> Result<Coverage> {
    let c = window_coverage(g, cfg, foci, voxels, gate)?;
    if let (Some(w), Some(p)) = (c.warning(), exec.progress) {
        p.warn(&w);
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::probe::Wave;

    fn geometry(t0: f64) -> Geometry {
        Geometry {
            lasers: vec![[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0]],
            laser_shape: [2, 1],
            spads: vec![[0.0, 0.0, 0.0]],
            spad_shape: [1, 1],
            laser_origin: [0.0, 0.0, 0.5],
            sensor_origin: [0.0, 0.0, 0.5],
            legs_in_time: false,
            confocal: false,
            nt: 100,
            dt: 0.02,
            t0,
            normals: Default::default(),
        }
    }

    /// The window misses every path: one error for the diagonal, a column, and the
    /// higher-order gate only when every path is later than the window's end; a window over
    /// all paths covers them all, and one over some of them reports the fraction.
    #[test]
    fn empty_partial_and_full_windows() {
        let vox = [[0.0, 0.0, 1.0f32], [0.0, 0.0, 1.2]];
        let wave = Wave {
            wavelength: Some(0.1),
            ..Wave::default()
        };
        // Paths through (0, 0, 1): 1 + √1.25 ≈ 2.12 m; through (0, 0, 1.2): 1.2 + 1.3 = 2.5 m.
        let g = geometry(-3.0);
        let cfg = wave.config(&g).unwrap();
        for foci in [None, Some(&vox[..1])] {
            let e = window_coverage(&g, &cfg, foci, &vox, ColumnGate::TwoBounce)
                .unwrap_err()
                .to_string();
            assert!(e.contains("no path through the probed points"), "{e}");
            assert!(e.starts_with("argument `volume`"), "{e}");
        }
        // Later light: paths before the window's end exist only for a later window.
        assert!(window_coverage(&g, &cfg, None, &vox, ColumnGate::HigherOrder).is_err());
        assert!(window_coverage(&g, &cfg, None, &vox, ColumnGate::None).is_ok());
        let g = geometry(1.5);
        let cfg = wave.config(&g).unwrap();
        let c = window_coverage(&g, &cfg, None, &vox, ColumnGate::TwoBounce).unwrap();
        assert_eq!(c.fraction, 1.0);
        assert!(c.warning().is_none());
        // A window [2.3 − σ, 4.28 + σ] holds the paths of the far voxel only.
        let g = geometry(2.3);
        let cfg = wave.config(&g).unwrap();
        let c = window_coverage(&g, &cfg, None, &vox, ColumnGate::TwoBounce).unwrap();
        assert_eq!(c.fraction, 0.5, "{c:?}");
        let far = [[0.0, 0.0, 1.2f32]; 3];
        let near = [[0.0, 0.0, 1.0f32]; 9];
        let mixed: Vec<Point> = far.iter().chain(&near).copied().collect();
        let c = window_coverage(&g, &cfg, None, &mixed, ColumnGate::TwoBounce).unwrap();
        assert_eq!(c.fraction, 0.25, "{c:?}");
        let c = window_coverage(&g, &cfg, None, &mixed[2..], ColumnGate::TwoBounce).unwrap();
        assert!(c.fraction < WARN_FRACTION && c.warning().is_some(), "{c:?}");
    }
}
