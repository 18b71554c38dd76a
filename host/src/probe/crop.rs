//! The automatic crop of the time axis to the window the probed voxels can reach, before the
//! band transform (so that the DFT period `N`, the band `J ∝ N` and every per-row cost shrink
//! with it).
//!
//! A bin `n` at path `t0 + n·Δt` can carry light to a probe only if some path of the probed
//! elements lies within the gate's support `c_g·σ` of it (the Gaussian gate is below
//! `e^{−c_g²/2}` = 3.7e-6 further out). The paths are bounded over the
//! **bounding boxes** of the voxels (and foci), so the bound is O(Kl + Ks) to compute and never
//! too tight:
//!
//! * diagonal (`x_l → v → x_s`): `[min_l (d1 + near(x_l)) + min_s (d4 + near(x_s)),
//!   max_l (d1 + far(x_l)) + max_s (d4 + far(x_s))]`, with `near`/`far` the shortest and
//!   longest distance from a wall point to the voxels' box;
//! * two-bounce columns (`x_l → a → b → x_s`): the foci's box for the laser leg, the voxels'
//!   box for the SPAD leg, plus the shortest and longest distance between the two boxes;
//! * the late (higher-order) gate counts all light after the path: only the start is cropped;
//! * the un-gated probes sum every bin: nothing is cropped.
//!
//! Kept: bins whose time lies in `[lo − c_g·σ − 2Δt, hi + c_g·σ + 2Δt]` (and in the capture's
//! axis). A result on the cropped axis differs from the uncropped one only by the gate's tail
//! beyond `c_g·σ` and the band truncation (both ≲ 4e-6 of the signal, `tests/proptest_fast.rs`).
//! Cost of the bound: O(Kl + Ks + voxels); of the crop: one copy per row (`Cropped`).
//!
//! **The DFT period** ([`cut`], the diagonal's): the kernel pads the period by `2·c_g·σ` so
//! that a path anywhere in its guard `[−c_g·σ, (Nt−1)Δt + c_g·σ]` is alias-free. The probed
//! paths lie in `[lo, hi]`, so a period of `max(hi − t0, (Nt−1)Δt − (lo − t0)) + c_g·σ`
//! suffices ([`tightened`]: a negative [`Params::margin`], which shrinks the kernel's guard to
//! the paths' span): on a cropped axis, whose edges lie `c_g·σ` beyond the paths, the padding
//! goes, and the band `J ∝ N` with every per-row cost shrinks by up to `2·c_g·σ/(NΔt)` (on the
//! uncropped 16×16 × 16×16 × 800-bin capture of `docs/performance.md`, 9.8 → 8.4 m, `J` 33 →
//! 29). Every path of `direct` but the band path takes it (the band path is what the firmware
//! runs, and its states, made at the kernel's period, must merge with the host's); not the
//! late gate (its paths are unbounded above), nor with the crop off. The sums equal those at
//! the kernel's period to `f32` rounding on the exact paths (planar, confocal, band) and to
//! their tables' tolerance on the interpolating ones (phasor, lookup, resampled); a part of a
//! split scan takes the same decision as a whole pass, so parts still merge to one pass bit
//! for bit.

use super::wave::{Wave, legs};
use crate::error::Result;
use crate::exec::{Exec, Progress};
use crate::io::capture::{Geometry, RowSource};
use crate::io::prep::Cropped;
use std::ops::Range;
use vltm_kernel::{Config, Params, Point};

/// The part of the capture's time axis a probe kept (bins `start..end` of `nt`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Crop {
    /// First kept bin.
    pub start: usize,
    /// One past the last kept bin.
    pub end: usize,
    /// Bins of the capture's axis.
    pub nt: usize,
}

impl std::fmt::Display for Crop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "time axis cropped to bins {}..{} of {} (the voxels' reach)",
            self.start, self.end, self.nt
        )
    }
}

/// What the probed paths are.
#[derive(Clone, Copy, Debug)]
pub(super) struct Reach<'a> {
    /// Foci of columns (`None`: the diagonal, `a = b`).
    pub(super) foci: Option<&'a [Point]>,
    /// Imaged voxels.
    pub(super) voxels: &'a [Point],
    /// The late gate: light after the path counts, only the start is cropped.
    pub(super) late: bool,
}

/// An axis-aligned box of points (m).
#[derive(Clone, Copy, Debug)]
struct Bbox {
    lo: [f64; 3],
    hi: [f64; 3],
}

impl Bbox {
    fn of(pts: &[Point]) -> Option<Self> {
        let first = pts.first()?.map(f64::from);
        let mut b = Self {
            lo: first,
            hi: first,
        };
        for p in pts {
            for (i, &c) in p.iter().enumerate() {
                b.lo[i] = b.lo[i].min(f64::from(c));
                b.hi[i] = b.hi[i].max(f64::from(c));
            }
        }
        Some(b)
    }

    /// Shortest and longest distance from `p` to the box.
    fn span(&self, p: Point) -> (f64, f64) {
        let (mut near, mut far) = (0.0, 0.0);
        for (i, &c) in p.iter().enumerate() {
            let x = f64::from(c);
            let d = (self.lo[i] - x).max(x - self.hi[i]).max(0.0);
            let f = (x - self.lo[i]).abs().max((self.hi[i] - x).abs());
            near += d * d;
            far += f * f;
        }
        (near.sqrt(), far.sqrt())
    }

    /// Shortest and longest distance between points of two boxes.
    fn between(&self, o: &Self) -> (f64, f64) {
        let (mut near, mut far) = (0.0, 0.0);
        for i in 0..3 {
            let d = (o.lo[i] - self.hi[i]).max(self.lo[i] - o.hi[i]).max(0.0);
            let f = (o.hi[i] - self.lo[i])
                .abs()
                .max((self.hi[i] - o.lo[i]).abs());
            near += d * d;
            far += f * f;
        }
        (near.sqrt(), far.sqrt())
    }
}

/// The span `(shortest, longest)` of `leg + distance to the box` over wall points.
fn leg_span(pts: &[Point], legs: &[f64], b: &Bbox) -> (f64, f64) {
    pts.iter()
        .zip(legs)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), (p, d)| {
            let (n, f) = b.span(*p);
            (lo.min(n + d), hi.max(f + d))
        })
}

/// The bins of `g`'s axis a probe of `reach` needs (module docs), `None` when that is all of
/// them (or the crop is off, [`Wave::crop`]).
///
/// # Errors
/// Configuration errors of [`Wave::config`].
pub(super) fn bins(g: &Geometry, wave: &Wave, reach: Reach<'_>) -> Result<Option<Range<usize>>> {
    if !wave.crop || Bbox::of(reach.voxels).is_none() {
        return Ok(None);
    }
    let cfg = wave.config(g)?;
    Ok(bins_of(g, &cfg, &legs(g, &cfg), reach))
}

/// The span `(lo, hi)` of path times (m, on the capture's clock, `t0` included) of every path
/// `reach` probes, bounded over the boxes of its voxels and foci (module docs); `None` for an
/// empty reach.
fn path_span(
    g: &Geometry,
    (d1, d4): &(Vec<f64>, Vec<f64>),
    reach: Reach<'_>,
) -> Option<(f64, f64)> {
    let vb = Bbox::of(reach.voxels)?;
    Some(match reach.foci {
        None => {
            let (l0, l1) = leg_span(&g.lasers, d1, &vb);
            let (s0, s1) = leg_span(&g.spads, d4, &vb);
            (l0 + s0, l1 + s1)
        }
        Some(foci) => {
            let fb = Bbox::of(foci)?;
            let (l0, l1) = leg_span(&g.lasers, d1, &fb);
            let (s0, s1) = leg_span(&g.spads, d4, &vb);
            let (m0, m1) = fb.between(&vb);
            (l0 + m0 + s0, l1 + m1 + s1)
        }
    })
}

/// [`bins`] with the crop on, from the capture's configuration `cfg` ([`Wave::config`]) and
/// device legs `(d1, d4)` ([`legs`]).
fn bins_of(
    g: &Geometry,
    cfg: &Config,
    legs: &(Vec<f64>, Vec<f64>),
    reach: Reach<'_>,
) -> Option<Range<usize>> {
    bins_for(g, cfg, path_span(g, legs, reach)?, reach.late)
}

/// [`bins_of`] from the reach's path span `(lo, hi)` ([`path_span`]); `late`: the late gate's
/// (only the start is cropped).
fn bins_for(g: &Geometry, cfg: &Config, (lo, hi): (f64, f64), late: bool) -> Option<Range<usize>> {
    let pad = cfg.params().gate_support * cfg.sigma() + 2.0 * g.dt;
    let first = ((lo - pad - g.t0) / g.dt).floor();
    let last = ((hi + pad - g.t0) / g.dt).ceil() + 1.0;
    let clamp = |x: f64| {
        if x.is_nan() || x <= 0.0 {
            0
        } else {
            (x.min(g.nt as f64)) as usize
        }
    };
    let start = clamp(first);
    let end = if late { g.nt } else { clamp(last) };
    if start == 0 && end == g.nt {
        return None;
    }
    Some(start..end.max(start))
}

/// `cfg` (margin 0) with the most negative [`Params::margin`] whose [`Config::guard`] still
/// holds every path time in `lo..=hi` (m, on the capture's clock) with `1e-4·σ` to spare (the
/// kernel's `f32` path lengths, as the diagonal's guard check): the DFT
/// period shrinks to `max(hi − t0, (Nt−1)Δt − (lo − t0)) + c_g·σ` instead of
/// `(Nt−1)Δt + 2·c_g·σ`, and the band `J ∝ N` with it, at most by `2·c_g·σ` (a cropped axis,
/// whose edges lie `c_g·σ` beyond the paths, reaches it). Paths outside `lo..=hi` are not
/// probed, so the sums are those at margin 0: to `f32` rounding on the exact paths (≲ 1e-6
/// of the peak) and to their tables' tolerance on the interpolating ones
/// (`tests/proptest_kernel.rs` checks the kernel under such a guard against the `f64`
/// reference). `cfg` itself when nothing shrinks (a span past the guard, an empty span, a
/// margin already set).
///
/// # Errors
/// Configuration errors of the tightened parameters.
pub(super) fn tightened(cfg: &Config, (lo, hi): (f64, f64)) -> Result<Config> {
    let p = cfg.params();
    if lo.partial_cmp(&hi).is_none_or(|o| o.is_gt()) {
        return Ok(*cfg);
    }
    let a = p.gate_support * cfg.sigma();
    let slack = 1e-4 * cfg.sigma();
    let (lo, hi) = (lo - p.t0 - slack, hi - p.t0 + slack);
    // Margin m < 0: guard ⊇ [−a − 2m, W + a + 2m] (N's ceiling only widens it).
    let m = (-a).max(-(lo + a) / 2.0).max((hi - cfg.window() - a) / 2.0);
    if p.margin != 0.0 || !m.is_finite() || m >= 0.0 {
        return Ok(*cfg);
    }
    Ok(Config::try_new(&Params { margin: m, ..*p })?)
}

/// Runs `f` on the bins `bins` of `src` (`None`: on `src` itself).
///
/// # Errors
/// [`Error::Argument`](crate::Error::Argument) (`--volume`) when `bins` is empty; `f`'s errors.
pub(super) fn on_bins<T>(
    src: &mut dyn RowSource,
    bins: Option<Range<usize>>,
    f: impl FnOnce(&mut dyn RowSource) -> Result<T>,
) -> Result<T> {
    match bins {
        None => f(src),
        Some(r) => f(&mut Cropped::new(src, r)?),
    }
}

/// The geometry of `g` with its time axis cut to `bins` (as [`Cropped`] presents it).
pub(super) fn cropped_geometry(g: &Geometry, bins: &Option<Range<usize>>) -> Geometry {
    match bins {
        None => g.clone(),
        Some(r) => Geometry {
            nt: r.len(),
            t0: g.t0 + r.start as f64 * g.dt,
            ..g.clone()
        },
    }
}

/// Progress labels with a note appended (`direct (time axis cropped to …)`, `direct (path
/// planar)`).
pub(super) struct Labelled<'p> {
    /// Where the labelled progress goes.
    pub(super) inner: &'p dyn Progress,
    /// The note.
    pub(super) note: String,
}

impl Progress for Labelled<'_> {
    fn start(&self, label: &str, total: u64) {
        self.inner.start(&format!("{label} ({})", self.note), total);
    }
    fn advance(&self, n: u64) {
        self.inner.advance(n);
    }
    fn finish(&self) {
        self.inner.finish();
    }
}

/// Runs `f` on `src` cropped to what `reach` needs ([`bins`]), or on `src` itself when nothing
/// is cropped; `f` gets the crop made and the execution options, whose progress labels then
/// name the crop.
///
/// # Errors
/// As [`bins`]; [`Error::Argument`](crate::Error::Argument) (`--volume`) when the crop leaves
/// no bins; `f`'s errors.
pub(super) fn with_crop<T>(
    src: &mut dyn RowSource,
    wave: &Wave,
    exec: Exec<'_>,
    reach: Reach<'_>,
    f: impl FnOnce(&mut dyn RowSource, Exec<'_>, Option<Crop>) -> Result<T>,
) -> Result<T> {
    let t = crate::timings::section("planning: crop", crate::timings::Kind::Serial);
    let bins = bins(src.geometry(), wave, reach)?;
    drop(t);
    match bins {
        None => f(src, exec, None),
        Some(r) => {
            let crop = Crop {
                start: r.start,
                end: r.end,
                nt: src.geometry().nt,
            };
            let mut c = Cropped::new(src, r)?;
            let labelled = exec.progress.map(|p| Labelled {
                inner: p,
                note: crop.to_string(),
            });
            let exec = Exec {
                progress: labelled.as_ref().map(|l| l as &dyn Progress),
                ..exec
            };
            f(&mut c, exec, Some(crop))
        }
    }
}

/// A probe's source cut to what its reach needs ([`bins`]), made by [`cut`]: the source
/// (cropped, or the source itself), the crop made, the configuration on the kept axis, and
/// execution options whose progress labels name the crop.
pub(super) struct Cut<'s, 'p> {
    src: Kept<'s>,
    exec: Exec<'p>,
    labelled: Option<Labelled<'p>>,
    /// The crop made (`None`: the whole axis).
    pub(super) crop: Option<Crop>,
    /// The configuration on the kept axis (the capture's own when nothing is cropped).
    pub(super) cfg: Config,
    /// `cfg` with its DFT period shrunk to the reach's path times ([`tightened`]), with the
    /// crop on, where that shortens it (the caller decides where to use it).
    pub(super) shrunk: Option<Config>,
}

/// The source a [`Cut`] hands on.
enum Kept<'s> {
    Whole(&'s mut dyn RowSource),
    Cropped(Box<Cropped<'s>>),
}

impl Cut<'_, '_> {
    /// The source to read and the execution options to run with.
    pub(super) fn parts(&mut self) -> (&mut dyn RowSource, Exec<'_>) {
        let exec = Exec {
            progress: match &self.labelled {
                Some(l) => Some(l as &dyn Progress),
                None => self.exec.progress,
            },
            ..self.exec
        };
        let src: &mut dyn RowSource = match &mut self.src {
            Kept::Whole(s) => &mut **s,
            Kept::Cropped(c) => &mut **c,
        };
        (src, exec)
    }
}

/// Cuts `src` to what `reach` needs (as [`bins`], with the crop on when `crop`), from the
/// capture's configuration `base` ([`Wave::config`]) and device legs `legs` ([`legs`]): the
/// configuration on the kept axis is `base` with the kept axis's `nt` and `t0` (what
/// [`Wave::config`] makes of the cropped capture) and, with the crop on, that configuration
/// with its DFT period shrunk to the reach's path times ([`tightened`]; not for the late
/// gate).
///
/// # Errors
/// [`Error::Argument`](crate::Error::Argument) (`--volume`) when the crop leaves no bins;
/// configuration errors of the kept axis.
pub(super) fn cut<'s, 'p>(
    src: &'s mut dyn RowSource,
    crop: bool,
    base: &Config,
    legs: &(Vec<f64>, Vec<f64>),
    exec: Exec<'p>,
    reach: Reach<'_>,
) -> Result<Cut<'s, 'p>> {
    let t = crate::timings::section("planning: crop", crate::timings::Kind::Serial);
    // The reach's path span, made once: for the crop and for the shorter period.
    let span = crop
        .then(|| path_span(src.geometry(), legs, reach))
        .flatten();
    let bins = span.and_then(|s| bins_for(src.geometry(), base, s, reach.late));
    drop(t);
    let span = span.filter(|_| !reach.late);
    let shrunk = |cfg: &Config| -> Result<Option<Config>> {
        let Some(span) = span else {
            return Ok(None);
        };
        let t = tightened(cfg, span)?;
        Ok((t.n_fft() < cfg.n_fft()).then_some(t))
    };
    let Some(r) = bins else {
        return Ok(Cut {
            src: Kept::Whole(src),
            exec,
            labelled: None,
            crop: None,
            cfg: *base,
            shrunk: shrunk(base)?,
        });
    };
    let crop = Crop {
        start: r.start,
        end: r.end,
        nt: src.geometry().nt,
    };
    let c = Cropped::new(src, r)?;
    let kept = c.geometry();
    let cfg = Config::try_new(&Params {
        nt: kept.nt,
        t0: kept.t0,
        ..*base.params()
    })?;
    let shrunk = shrunk(&cfg)?;
    let labelled = exec.progress.map(|p| Labelled {
        inner: p,
        note: crop.to_string(),
    });
    Ok(Cut {
        src: Kept::Cropped(Box::new(c)),
        exec,
        labelled,
        crop: Some(crop),
        cfg,
        shrunk,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn geometry(nt: usize) -> Geometry {
        Geometry {
            lasers: vec![[0.0, 0.0, 0.0], [0.2, 0.0, 0.0]],
            laser_shape: [2, 1],
            spads: vec![[0.1, 0.0, 0.0]],
            spad_shape: [1, 1],
            laser_origin: [0.0, 0.0, 0.5],
            sensor_origin: [0.0, 0.0, 0.5],
            legs_in_time: false,
            confocal: false,
            nt,
            dt: 0.001,
            t0: 0.0,
            normals: Default::default(),
        }
    }

    /// The kept bins hold every path through every voxel, with the gate's support, and are
    /// far fewer than the axis.
    #[test]
    fn crop_holds_every_path() {
        let g = geometry(100_000);
        let wave = Wave {
            wavelength: Some(0.05),
            ..Wave::default()
        };
        let vox: Vec<Point> = (0..27)
            .map(|i| {
                let f = |k: usize| (k as f32 - 1.0) * 0.05;
                [f(i % 3), f((i / 3) % 3), 1.0 + f(i / 9)]
            })
            .collect();
        let diag = Reach {
            foci: None,
            voxels: &vox,
            late: false,
        };
        let r = bins(&g, &wave, diag).unwrap().unwrap();
        let sig = wave.config(&g).unwrap().sigma();
        for v in &vox {
            for l in &g.lasers {
                let d = |a: &Point, b: &Point| {
                    (0..3)
                        .map(|i| f64::from(a[i] - b[i]).powi(2))
                        .sum::<f64>()
                        .sqrt()
                };
                let t = d(l, v) + d(v, &g.spads[0]);
                assert!(t - 5.0 * sig >= r.start as f64 * g.dt, "{t} {r:?}");
                assert!(t + 5.0 * sig <= (r.end - 1) as f64 * g.dt, "{t} {r:?}");
            }
        }
        assert!(r.len() < 2_000, "{r:?}");
        // The late gate keeps the end; columns reach further than the diagonal.
        let late = bins(&g, &wave, Reach { late: true, ..diag })
            .unwrap()
            .unwrap();
        assert_eq!((late.start, late.end), (r.start, g.nt));
        let col = Reach {
            foci: Some(&vox[..1]),
            voxels: &vox,
            late: false,
        };
        let c = bins(&g, &wave, col).unwrap().unwrap();
        assert!(c.end > r.end);
        // Off: nothing cropped.
        let off = Wave {
            crop: false,
            ..wave
        };
        assert_eq!(bins(&g, &off, diag).unwrap(), None);
    }

    /// A crop of the whole axis is none; a volume out of the window's reach leaves no bins, an
    /// error naming `--volume`.
    #[test]
    fn empty_crop_is_an_error() {
        let g = geometry(1000);
        let wave = Wave {
            wavelength: Some(0.05),
            ..Wave::default()
        };
        let near = [[0.0, 0.0, 0.2f32]];
        let whole = Reach {
            foci: None,
            voxels: &near,
            late: true,
        };
        assert!(bins(&g, &wave, whole).unwrap().is_some_and(|r| r.start > 0));
        let far = [[0.0, 0.0, 50.0f32]];
        let reach = Reach {
            foci: None,
            voxels: &far,
            late: false,
        };
        let r = bins(&g, &wave, reach).unwrap().unwrap();
        assert!(r.is_empty());
        let mut c =
            crate::io::Capture::new(g.clone(), vec![0.0; 2 * 1000], std::path::Path::new("c"))
                .unwrap();
        let e = with_crop(&mut c, &wave, Exec::default(), reach, |_, _, _| Ok(())).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("`volume`") && !msg.contains('\n'), "{msg}");
    }

    /// The shrunk period holds the span it was made for, and only shrinks: a span reaching
    /// past the guard, an empty span or a margin already set leave the configuration as it
    /// was.
    #[test]
    fn tightened_guard_holds_the_span() {
        let cfg = Wave {
            wavelength: Some(0.1),
            ..Wave::default()
        }
        .config(&geometry(1000))
        .unwrap();
        let (g0, g1) = cfg.guard();
        let span = (0.3, 0.6);
        let t = tightened(&cfg, span).unwrap();
        assert!(t.params().margin < 0.0 && t.n_fft() < cfg.n_fft() && t.bins() < cfg.bins());
        let (t0, t1) = t.guard();
        assert!(g0 < t0 && t0 <= span.0 - cfg.t0() && t1 >= span.1 - cfg.t0() && t1 < g1);
        assert_eq!(t.alias_free(), t.guard());
        let past = (0.3, g1 + cfg.t0() + 1.0);
        assert_eq!(tightened(&cfg, past).unwrap(), cfg);
        let empty = (f64::INFINITY, f64::NEG_INFINITY);
        assert_eq!(tightened(&cfg, empty).unwrap(), cfg);
        assert_eq!(tightened(&t, span).unwrap(), t);
        assert_eq!(tightened(&cfg, (f64::NAN, 0.5)).unwrap(), cfg);
    }
}
