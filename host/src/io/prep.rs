//! Preprocessing of raw photon counts, as a [`RowSource`] wrapper ([`Prepared`]) that any
//! reader's rows go through: a time window, rebinning and background subtraction. The CLI
//! applies it to `direct`, `column`, `indirect`, `relight` and `row` on every format
//! (`--t-min`, `--t-max`, `--rebin`, `--background`).
//!
//! Order, per histogram: **window**, then **rebin**, then **background**.
//!
//! * **Window** ([`Prep::t_min`], [`Prep::t_max`]): keeps bins `n` with `t-min ≤ n < t-max`
//!   when given in bins (`600b`), or `t-min ≤ t0 + n·Δt < t-max` when given in metres of path
//!   (`0.72`, `0.72m`). The kept bins are cropped, not zeroed: the new `t0` is the path of the
//!   first kept bin. `--t-min 600b` is the Stanford authors' `rect_data(:,:,1:600) = 0`
//!   (MATLAB's bins 1..600 are bins 0..599 here).
//! * **Rebin** ([`Prep::rebin`] = K): sums K consecutive kept bins; a last group of fewer than
//!   K bins is dropped. The sum is a point sample at the mean of its K sample times:
//!   `t0' = t0 + (K−1)·Δt/2`, `Δt' = K·Δt`.
//! * **Background** ([`Background`]): subtracts a floor from each histogram and clamps at 0
//!   (counts are not negative; a constant floor also has no energy in the gate's band, so
//!   the subtraction matters most near the window's edges and for the no-gate probes).
//!   `Value(b)` subtracts `b` counts per original bin (`K·b` after rebinning). `Auto`
//!   estimates each histogram's floor as the **mean** of its bins where no hidden return
//!   from the imaged volume can arrive ([`Reach`]): paths shorter than the shortest or longer
//!   than the longest `x_l → voxel → x_s` path over the volume's bounding box (device legs
//!   added when the time axis includes them), widened by a margin (the CLI uses 3σ + Δt').
//!   Without a volume (`vltm info`) it uses the last tenth of the window. Fewer than
//!   [`MIN_QUIET_BINS`] such bins is an error, never a guess.
//!
//! Nothing here produces NaN: a non-finite sample is left for the probes (which count it
//! and read it as 0), and floors are means of finite samples only. [`Stats`] counts what was
//! removed and how many histograms were left empty, so that a background larger than the
//! signal is reported (every front end warns above half, and refuses an all-empty capture:
//! [`check`]) instead of imaging zeros. [`with_prep`] runs a pass through the preprocessing
//! as every front end does (the imaged volume's [`Reach`], the checks). Cost: O(Nt) per
//! histogram; memory: one source row.

use crate::error::{Error, Result};
use crate::io::capture::{Geometry, RowSource};
use vltm_kernel::Point;
use vltm_kernel::geometry::dist64;

/// Fewest bins `--background auto` averages over per histogram.
pub const MIN_QUIET_BINS: usize = 4;

/// One end of the time window.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Bound {
    /// Metres of optical path.
    Metres(f64),
    /// A bin index of the source capture.
    Bins(usize),
}

impl Bound {
    /// Parses `600b` / `600bins` (bins) or `0.72` / `0.72m` (metres of path).
    ///
    /// # Errors
    /// [`Error::Argument`] naming `arg`.
    pub fn parse(arg: &str, s: &str) -> Result<Self> {
        let t = s.trim();
        let bad = || {
            Error::arg(
                arg,
                format!("expected metres of path (0.72 or 0.72m) or bins (600b), found `{s}`"),
            )
        };
        if let Some(b) = t.strip_suffix("bins").or_else(|| t.strip_suffix('b')) {
            return b.trim().parse().map(Self::Bins).map_err(|_| bad());
        }
        let m: f64 = t
            .strip_suffix('m')
            .unwrap_or(t)
            .trim()
            .parse()
            .map_err(|_| bad())?;
        if !m.is_finite() {
            return Err(bad());
        }
        Ok(Self::Metres(m))
    }

    /// The first bin `n` of the axis `(t0, dt, nt)` at or after this bound.
    fn bin(self, g: &Geometry) -> usize {
        match self {
            Self::Bins(b) => b.min(g.nt),
            Self::Metres(m) => {
                let n = ((m - g.t0) / g.dt - 1e-9).ceil();
                if n <= 0.0 { 0 } else { (n as usize).min(g.nt) }
            }
        }
    }
}

/// Background subtraction.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Background {
    /// None (the default).
    #[default]
    None,
    /// Each histogram's floor from its return-free bins (module docs).
    Auto,
    /// A fixed floor in counts per source bin.
    Value(f64),
}

impl Background {
    /// Parses `auto`, `none` or a number of counts per bin (finite, ≥ 0).
    ///
    /// # Errors
    /// [`Error::Argument`] (`background`).
    pub fn parse(s: &str) -> Result<Self> {
        match s.trim() {
            "auto" => Ok(Self::Auto),
            "none" => Ok(Self::None),
            v => match v.parse::<f64>() {
                Ok(b) if b.is_finite() && b >= 0.0 => Ok(Self::Value(b)),
                _ => Err(Error::arg(
                    "background",
                    format!("expected auto, none or counts per bin >= 0, found `{s}`"),
                )),
            },
        }
    }
}

/// The preprocessing steps.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Prep {
    /// Start of the window (inclusive).
    pub t_min: Option<Bound>,
    /// End of the window (exclusive).
    pub t_max: Option<Bound>,
    /// Bins summed into one (1 = none; 0 is refused).
    pub rebin: usize,
    /// Background subtraction.
    pub background: Background,
}

impl Prep {
    /// Whether nothing is to be done.
    pub fn is_identity(&self) -> bool {
        self.t_min.is_none()
            && self.t_max.is_none()
            && self.rebin <= 1
            && self.background == Background::None
    }

    /// The preprocessing a front end's options ask for (`t_min`, `t_max`: [`Bound::parse`];
    /// `background`: [`Background::parse`], none by default), `None` when they ask for
    /// nothing. `rebin = 0` is kept, for [`Prepared::new`] to refuse.
    ///
    /// # Errors
    /// [`Error::Argument`] (`t_min`, `t_max`, `background`) for a value that does not parse.
    pub fn parse(
        t_min: Option<&str>,
        t_max: Option<&str>,
        rebin: usize,
        background: Option<&str>,
    ) -> Result<Option<Self>> {
        let p = Self {
            t_min: t_min.map(|s| Bound::parse("t_min", s)).transpose()?,
            t_max: t_max.map(|s| Bound::parse("t_max", s)).transpose()?,
            rebin,
            background: background
                .map(Background::parse)
                .transpose()?
                .unwrap_or_default(),
        };
        Ok((!p.is_identity() || rebin == 0).then_some(p))
    }
}

/// Where hidden returns from the imaged volume can arrive: its bounding box and a margin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reach {
    /// Lowest corner of the volume's bounding box (m).
    pub lo: [f64; 3],
    /// Highest corner (m).
    pub hi: [f64; 3],
    /// Extra path on both sides (m), e.g. 3σ + Δt.
    pub margin: f64,
}

impl Reach {
    /// The bounding box of `points` with a margin.
    pub fn of(points: &[Point], margin: f64) -> Option<Self> {
        let first = points.first()?;
        let mut lo = first.map(f64::from);
        let mut hi = lo;
        for p in points {
            for i in 0..3 {
                lo[i] = lo[i].min(f64::from(p[i]));
                hi[i] = hi[i].max(f64::from(p[i]));
            }
        }
        Some(Self { lo, hi, margin })
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
        (f64::sqrt(near), f64::sqrt(far))
    }
}

/// What the preprocessing did, over the rows read (each row counted once).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Stats {
    /// Histograms processed.
    pub histograms: usize,
    /// Histograms with no count left after the background.
    pub empty: usize,
    /// Counts in the window (after rebinning, before the background).
    pub counts_in: f64,
    /// Counts left after the background.
    pub counts_out: f64,
    /// Sum of the floors subtracted (per new bin) over histograms.
    pub floor_sum: f64,
    /// Sum over histograms of the bins the floor was estimated from (`auto`).
    pub quiet_bins: usize,
}

/// A [`RowSource`] with [`Prep`] applied to every row.
pub struct Prepared<'a> {
    inner: &'a mut dyn RowSource,
    prep: Prep,
    reach: Option<Reach>,
    geometry: Geometry,
    /// First source bin of the window.
    n0: usize,
    k: usize,
    buf: Vec<f32>,
    seen: Vec<bool>,
    /// What was done so far.
    pub stats: Stats,
}

impl std::fmt::Debug for Prepared<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Prepared")
            .field("prep", &self.prep)
            .field("n0", &self.n0)
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl<'a> Prepared<'a> {
    /// Wraps `inner`. `reach` (the imaged volume) is what `--background auto` needs to find
    /// return-free bins; without it the last tenth of the window is used.
    ///
    /// # Errors
    /// [`Error::Argument`] for a rebin of 0, or a window/rebin that leaves no bins (naming
    /// the window in bins and metres).
    pub fn new(inner: &'a mut dyn RowSource, prep: Prep, reach: Option<Reach>) -> Result<Self> {
        let g = inner.geometry().clone();
        let k = prep.rebin.max(1);
        if prep.rebin == 0 {
            return Err(Error::arg("rebin", "expected K >= 1 bins"));
        }
        let n0 = prep.t_min.map_or(0, |b| b.bin(&g));
        let n1 = prep.t_max.map_or(g.nt, |b| b.bin(&g));
        let nt = n1.saturating_sub(n0) / k;
        if nt == 0 {
            // The window is empty (`t_min` at or past `t_max`) or narrower than one rebinned
            // bin (`rebin`).
            let arg = if n1 > n0 { "rebin" } else { "t_min" };
            return Err(Error::arg(
                arg,
                format!(
                    "the window keeps bins {n0}..{n1} (path {:.4}..{:.4} m) of the capture's {} (path {:.4}..{:.4} m){}: no bins left",
                    g.t0 + n0 as f64 * g.dt,
                    g.t0 + n1 as f64 * g.dt,
                    g.nt,
                    g.t0,
                    g.t0 + g.nt as f64 * g.dt,
                    if k > 1 {
                        format!(", fewer than $rebin {k}")
                    } else if n1 <= n0 {
                        " ($t_min must lie before $t_max)".to_string()
                    } else {
                        String::new()
                    }
                ),
            ));
        }
        let geometry = Geometry {
            nt,
            dt: g.dt * k as f64,
            t0: g.t0 + n0 as f64 * g.dt + (k as f64 - 1.0) * g.dt / 2.0,
            ..g
        };
        let rows = geometry.lasers.len();
        Ok(Self {
            inner,
            prep,
            reach,
            geometry,
            n0,
            k,
            buf: Vec::new(),
            seen: vec![false; rows],
            stats: Stats::default(),
        })
    }

    /// A one-line account of what was done, for the CLI.
    pub fn summary(&self) -> String {
        let g = &self.geometry;
        let s = &self.stats;
        let mut parts = vec![format!(
            "window bins {}..{} of the source (path {:.4}..{:.4} m), rebin {} -> {} bins of {:.6} m",
            self.n0,
            self.n0 + g.nt * self.k,
            g.t0 - (self.k as f64 - 1.0) * g.dt / self.k as f64 / 2.0,
            g.t0 + (g.nt as f64 - 0.5) * g.dt,
            self.k,
            g.nt,
            g.dt
        )];
        let h = s.histograms.max(1) as f64;
        let removed = if s.counts_in > 0.0 {
            100.0 * (1.0 - s.counts_out / s.counts_in)
        } else {
            0.0
        };
        match self.prep.background {
            Background::None => parts.push("no background subtracted".into()),
            Background::Value(b) => parts.push(format!(
                "background {b} counts per source bin ({} per bin) subtracted: {removed:.1} % of the window's counts removed, {} of {} histograms left empty",
                b * self.k as f64,
                s.empty,
                s.histograms,
            )),
            Background::Auto => parts.push(format!(
                "background auto: mean floor {:.4} counts per bin from {:.0} bins per histogram {}; {removed:.1} % of the window's counts removed, {} of {} histograms left empty",
                s.floor_sum / h,
                s.quiet_bins as f64 / h,
                if self.reach.is_some() {
                    "where no return from the volume can arrive"
                } else {
                    "in the last tenth of the window"
                },
                s.empty,
                s.histograms,
            )),
        }
        parts.join("; ")
    }

    /// The shortest and longest hidden path from the volume for laser `x_l` and SPAD `x_s`.
    fn window_of(&self, r: &Reach, x_l: Point, x_s: Point) -> (f64, f64) {
        let g = &self.geometry;
        let (a0, a1) = r.span(x_l);
        let (b0, b1) = r.span(x_s);
        let legs = if g.legs_in_time {
            dist64(&x_l, &g.laser_origin) + dist64(&x_s, &g.sensor_origin)
        } else {
            0.0
        };
        (a0 + b0 + legs - r.margin, a1 + b1 + legs + r.margin)
    }

    /// The floor of one histogram `h` (new bins), with the number of bins used.
    fn floor(&self, h: &[f32], x_l: Point, x_s: Point) -> Result<(f64, usize)> {
        let g = &self.geometry;
        let quiet: Box<dyn Fn(usize) -> bool> = match &self.reach {
            Some(r) => {
                let (p0, p1) = self.window_of(r, x_l, x_s);
                Box::new(move |n| {
                    let t = g.t0 + n as f64 * g.dt;
                    t < p0 || t > p1
                })
            }
            None => {
                let from = g.nt - (g.nt / 10).max(1);
                Box::new(move |n| n >= from)
            }
        };
        let (mut sum, mut n) = (0.0f64, 0usize);
        for (i, &x) in h.iter().enumerate() {
            if x.is_finite() && quiet(i) {
                sum += f64::from(x);
                n += 1;
            }
        }
        if n < MIN_QUIET_BINS {
            let where_ = match &self.reach {
                Some(r) => {
                    let (p0, p1) = self.window_of(r, x_l, x_s);
                    format!("outside the volume's reach (path {p0:.3}..{p1:.3} m, margin included)")
                }
                None => "in the last tenth of the window".into(),
            };
            return Err(Error::arg(
                "background",
                format!(
                    "auto: only {n} bins of the window (path {:.3}..{:.3} m) lie {where_} for the histogram at {x_l:?}; widen $t_min/$t_max or give $background VALUE",
                    g.t0,
                    g.t0 + (g.nt as f64 - 1.0) * g.dt
                ),
            ));
        }
        Ok((sum / n as f64, n))
    }
}

impl RowSource for Prepared<'_> {
    fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    fn rows(&self) -> std::ops::Range<usize> {
        self.inner.rows()
    }

    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        let mut buf = std::mem::take(&mut self.buf);
        let x_l = self.inner.read_row(l, &mut buf)?;
        let src_nt = self.inner.geometry().nt;
        let (nt, k, n0) = (self.geometry.nt, self.k, self.n0);
        let ks = self.geometry.spads_per_row();
        out.clear();
        out.resize(ks * nt, 0.0);
        let first = !self.seen.get(l).copied().unwrap_or(true);
        if let Some(s) = self.seen.get_mut(l) {
            *s = true;
        }
        for s in 0..ks {
            let src = &buf[s * src_nt..(s + 1) * src_nt];
            let h = &mut out[s * nt..(s + 1) * nt];
            for (m, y) in h.iter_mut().enumerate() {
                let a = n0 + m * k;
                *y = src[a..a + k].iter().sum();
            }
            let x_s = if self.geometry.confocal {
                self.geometry.spads.get(l).copied().unwrap_or(x_l)
            } else {
                self.geometry.spads[s]
            };
            let counts_in: f64 = h
                .iter()
                .filter(|x| x.is_finite())
                .map(|&x| f64::from(x))
                .sum();
            let (floor, quiet) = match self.prep.background {
                Background::None => (0.0, 0),
                Background::Value(b) => (b * k as f64, 0),
                Background::Auto => self.floor(h, x_l, x_s)?,
            };
            if floor > 0.0 {
                for y in h.iter_mut() {
                    if y.is_finite() {
                        *y = (f64::from(*y) - floor).max(0.0) as f32;
                    }
                }
            }
            if first {
                let out_sum: f64 = h
                    .iter()
                    .filter(|x| x.is_finite())
                    .map(|&x| f64::from(x))
                    .sum();
                let st = &mut self.stats;
                st.histograms += 1;
                st.empty += usize::from(out_sum <= 0.0);
                st.counts_in += counts_in;
                st.counts_out += out_sum;
                st.floor_sum += floor;
                st.quiet_bins += quiet;
            }
        }
        self.buf = buf;
        Ok(x_l)
    }
}

/// The bins `start..end` of another source's time axis, and nothing else done: the probes'
/// automatic crop to the window the probed voxels can reach (`crate::probe`'s module docs).
/// The new `t0` is the path of bin `start`; Δt is unchanged. Cost O(Nt) per row (one copy);
/// memory one source row.
pub struct Cropped<'a> {
    inner: &'a mut dyn RowSource,
    geometry: Geometry,
    start: usize,
    buf: Vec<f32>,
}

impl std::fmt::Debug for Cropped<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Cropped")
            .field("start", &self.start)
            .field("nt", &self.geometry.nt)
            .finish_non_exhaustive()
    }
}

impl<'a> Cropped<'a> {
    /// Keeps the bins `bins` of `inner`'s time axis.
    ///
    /// # Errors
    /// [`Error::Argument`] (`volume`: the crop follows from the probed voxels) when `bins`
    /// is empty or does not lie in the axis.
    pub fn new(inner: &'a mut dyn RowSource, bins: std::ops::Range<usize>) -> Result<Self> {
        let g = inner.geometry().clone();
        if bins.is_empty() || bins.end > g.nt {
            return Err(Error::arg(
                "volume",
                format!(
                    "the time axis cropped to the voxels' reach keeps bins {}..{} of the capture's {}: no bins left (choose voxels the capture saw, or check its t_start and delta_t)",
                    bins.start, bins.end, g.nt
                ),
            ));
        }
        let geometry = Geometry {
            nt: bins.len(),
            t0: g.t0 + bins.start as f64 * g.dt,
            ..g
        };
        Ok(Self {
            inner,
            geometry,
            start: bins.start,
            buf: Vec::new(),
        })
    }
}

impl RowSource for Cropped<'_> {
    fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    fn rows(&self) -> std::ops::Range<usize> {
        self.inner.rows()
    }

    fn read_rows(&mut self, first: usize, out: &mut [(Point, Vec<f32>)]) -> Result<()> {
        use rayon::prelude::*;
        self.inner.read_rows(first, out)?;
        let src_nt = self.inner.geometry().nt;
        let (nt, n0) = (self.geometry.nt, self.start);
        out.par_iter_mut().for_each(|(_, h)| {
            let ks = h.len() / src_nt.max(1);
            // In place, SPAD by SPAD: the destination never passes the source (nt <= src_nt).
            for s in 0..ks {
                h.copy_within(s * src_nt + n0..s * src_nt + n0 + nt, s * nt);
            }
            h.truncate(ks * nt);
        });
        Ok(())
    }

    fn reads_in_parallel(&self) -> bool {
        self.inner.reads_in_parallel()
    }

    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        let x_l = self.inner.read_row(l, &mut self.buf)?;
        let src_nt = self.inner.geometry().nt;
        let (nt, n0) = (self.geometry.nt, self.start);
        out.clear();
        for h in self.buf.chunks_exact(src_nt) {
            out.extend_from_slice(&h[n0..n0 + nt]);
        }
        Ok(x_l)
    }
}

// A pass run through the preprocessing, as every front end (the command line, the Python
// package) runs it: the imaged volume's reach for `background auto`, and the checks on what
// the preprocessing removed. Errors name the parameter (`background`).

/// What the preprocessing of a run did.
#[derive(Clone, Debug, PartialEq)]
pub struct PrepReport {
    /// A one-line account ([`Prepared::summary`]).
    pub summary: String,
    /// A warning when the background left more than half of the histograms empty.
    pub warning: Option<String>,
    /// The counters.
    pub stats: Stats,
}

impl PrepReport {
    /// What `p` did so far, not yet checked ([`PrepReport::check`]).
    pub fn of(p: &Prepared<'_>) -> Self {
        let s = &p.stats;
        let warning = (2 * s.empty > s.histograms).then(|| {
            format!(
                "the background left {} of {} histograms empty: it is larger than most of the signal",
                s.empty, s.histograms
            )
        });
        Self {
            summary: p.summary(),
            warning,
            stats: s.clone(),
        }
    }

    /// Refuses a preprocessing that left every histogram it read empty.
    ///
    /// # Errors
    /// [`Error::Argument`] (`background`) when every histogram read was left empty.
    pub fn check(&self) -> Result<()> {
        let s = &self.stats;
        if s.histograms > 0 && s.empty == s.histograms {
            return Err(Error::arg(
                "background",
                format!(
                    "the background removed every count of all {} histograms: nothing left to image (lower it or use auto)",
                    s.histograms
                ),
            ));
        }
        Ok(())
    }
}

/// The checks on what a preprocessing removed: every histogram empty is an error, more than
/// half of them a warning ([`PrepReport::warning`]).
///
/// # Errors
/// As [`PrepReport::check`].
pub fn check(p: &Prepared<'_>) -> Result<PrepReport> {
    let report = PrepReport::of(p);
    report.check()?;
    Ok(report)
}

/// Runs `f` on `src`, through the preprocessing `prep` when there is one: the background's
/// return-free bins are those no path through `points` (widened by `3·sigma` plus one
/// rebinned bin) can reach. `shown` sees what the preprocessing did once `f` has run, before
/// it is checked (a front end that prints it prints it even when the check fails). Returns
/// `f`'s result and the checked report.
///
/// # Errors
/// `f`'s errors; [`Error::Argument`] for a window that keeps no bins, and as [`check`].
pub fn with_prep<T, E: From<Error>>(
    prep: Option<Prep>,
    src: &mut dyn RowSource,
    points: &[Point],
    sigma: f64,
    f: impl FnOnce(&mut dyn RowSource) -> std::result::Result<T, E>,
    shown: impl FnOnce(&PrepReport),
) -> std::result::Result<(T, Option<PrepReport>), E> {
    let Some(prep) = prep else {
        return Ok((f(src)?, None));
    };
    let src_dt = src.geometry().dt;
    let margin = 3.0 * sigma + src_dt * prep.rebin.max(1) as f64;
    let mut p = Prepared::new(src, prep, Reach::of(points, margin))?;
    let out = f(&mut p)?;
    let report = PrepReport::of(&p);
    shown(&report);
    report.check()?;
    Ok((out, Some(report)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::capture::Capture;

    fn capture(nt: usize, f: impl Fn(usize, usize) -> f32) -> Capture {
        let lasers = vec![[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]];
        let g = Geometry {
            spads: lasers.clone(),
            lasers,
            laser_shape: [2, 1],
            spad_shape: [2, 1],
            laser_origin: [0.0; 3],
            sensor_origin: [0.0; 3],
            legs_in_time: false,
            confocal: true,
            nt,
            dt: 0.01,
            t0: 0.0,
            normals: Default::default(),
        };
        let data = (0..2)
            .flat_map(|l| (0..nt).map(move |n| (l, n)))
            .map(|(l, n)| f(l, n))
            .collect();
        Capture::new(g, data, std::path::Path::new("t")).unwrap()
    }

    /// A batch of cropped rows (the in-place, parallel crop) equals the rows cropped one by
    /// one, and both are the kept bins of the source.
    #[test]
    fn cropped_batches_equal_cropped_rows() {
        let mut c = capture(50, |l, n| (100 * l + n) as f32);
        let mut one = Vec::new();
        let mut singles = Vec::new();
        {
            let mut cr = Cropped::new(&mut c, 7..31).unwrap();
            for l in 0..2 {
                cr.read_row(l, &mut one).unwrap();
                singles.push(one.clone());
            }
        }
        let mut cr = Cropped::new(&mut c, 7..31).unwrap();
        let mut batch = vec![([9.0; 3], vec![1.0; 3]); 2];
        cr.read_rows(0, &mut batch).unwrap();
        for (l, (x, h)) in batch.iter().enumerate() {
            assert_eq!(h, &singles[l]);
            assert_eq!(*x, cr.geometry().lasers[l]);
            let src_nt = 50;
            let ks = h.len() / 24;
            assert_eq!(ks, cr.geometry().spads_per_row());
            for s in 0..ks {
                for n in 0..24 {
                    let want = (100 * l + s * src_nt + 7 + n) as f32;
                    assert_eq!(h[s * 24 + n], want, "row {l} SPAD {s} bin {n}");
                }
            }
        }
    }

    #[test]
    fn window_and_rebin_sum_and_shift_the_axis() {
        let mut c = capture(100, |l, n| (l * 1000 + n) as f32);
        let prep = Prep {
            t_min: Some(Bound::Bins(10)),
            t_max: Some(Bound::Metres(0.505)),
            rebin: 4,
            background: Background::None,
        };
        let mut p = Prepared::new(&mut c, prep, None).unwrap();
        let g = p.geometry().clone();
        // Bins 10..51 (t < 0.505 m keeps n <= 50): 41 bins, 10 groups of 4.
        assert_eq!(g.nt, 10);
        assert!((g.dt - 0.04).abs() < 1e-12);
        assert!((g.t0 - (0.10 + 0.015)).abs() < 1e-12, "{}", g.t0);
        let mut row = Vec::new();
        p.read_row(1, &mut row).unwrap();
        assert_eq!(row[0], (1010 + 1011 + 1012 + 1013) as f32);
        assert_eq!(row[9], (1046 + 1047 + 1048 + 1049) as f32);
    }

    #[test]
    fn empty_windows_are_errors() {
        let mut c = capture(100, |_, _| 1.0);
        for (prep, arg) in [
            (
                Prep {
                    t_min: Some(Bound::Bins(100)),
                    rebin: 1,
                    ..Prep::default()
                },
                "t_min",
            ),
            (
                Prep {
                    t_min: Some(Bound::Metres(0.5)),
                    t_max: Some(Bound::Metres(0.4)),
                    rebin: 1,
                    ..Prep::default()
                },
                "t_min",
            ),
            (
                Prep {
                    t_min: Some(Bound::Bins(98)),
                    rebin: 4,
                    ..Prep::default()
                },
                "rebin",
            ),
        ] {
            let e = Prepared::new(&mut c, prep, None).unwrap_err().to_string();
            assert!(e.contains(arg) && e.contains("no bins left"), "{e}");
        }
    }

    #[test]
    fn auto_background_uses_return_free_bins_and_never_nan() {
        // Floor 3 everywhere, a return of 100 at path 0.8 m (a point at z = 0.4 m).
        let mut c = capture(200, |_, n| if n == 80 { 103.0 } else { 3.0 });
        let reach = Reach::of(&[[0.0, 0.0, 0.3], [0.1, 0.0, 0.5]], 0.053);
        let prep = Prep {
            rebin: 1,
            background: Background::Auto,
            ..Prep::default()
        };
        let mut p = Prepared::new(&mut c, prep, reach).unwrap();
        let mut row = Vec::new();
        p.read_row(0, &mut row).unwrap();
        assert!(row.iter().all(|x| x.is_finite()));
        assert!((row[80] - 100.0).abs() < 1e-4, "{}", row[80]);
        assert_eq!(row.iter().filter(|&&x| x > 0.0).count(), 1);
        // Return-free: path < 2·0.3 − 0.053 or > 2·|(0.1, 0, 0.5)| + 0.053.
        let (lo, hi) = (0.547, 2.0 * (0.01f64 + 0.25).sqrt() + 0.053);
        let want = (0..200)
            .filter(|&n| {
                let t = n as f64 * 0.01;
                t < lo || t > hi
            })
            .count();
        assert_eq!(p.stats.quiet_bins, want);
        assert!(
            p.summary()
                .contains("where no return from the volume can arrive")
        );
        // A floor above every count leaves the histogram empty, and says so.
        let mut c = capture(200, |_, _| 2.0);
        let prep = Prep {
            rebin: 1,
            background: Background::Value(5.0),
            ..Prep::default()
        };
        let mut p = Prepared::new(&mut c, prep, None).unwrap();
        p.read_row(0, &mut row).unwrap();
        p.read_row(0, &mut row).unwrap();
        assert_eq!((p.stats.histograms, p.stats.empty), (1, 1));
        assert!(row.iter().all(|&x| x == 0.0));
    }

    #[test]
    fn bounds_parse() {
        assert_eq!(Bound::parse("t_min", "600b").unwrap(), Bound::Bins(600));
        assert_eq!(Bound::parse("t_min", "600bins").unwrap(), Bound::Bins(600));
        assert_eq!(Bound::parse("t_min", "0.72m").unwrap(), Bound::Metres(0.72));
        assert_eq!(Bound::parse("t_min", "0.72").unwrap(), Bound::Metres(0.72));
        assert!(Bound::parse("t_min", "x").is_err());
        assert!(Background::parse("-1").is_err());
        assert_eq!(Background::parse("auto").unwrap(), Background::Auto);
    }

    fn flat(value: f32) -> Capture {
        capture(16, |_, _| value)
    }

    fn read_rows(s: &mut dyn RowSource) -> Result<usize> {
        let mut row = Vec::new();
        for l in 0..s.geometry().lasers.len() {
            s.read_row(l, &mut row)?;
        }
        Ok(row.len())
    }

    fn background(b: f64) -> Option<Prep> {
        Some(Prep {
            t_min: None,
            t_max: None,
            rebin: 1,
            background: Background::Value(b),
        })
    }

    #[test]
    fn without_preprocessing_the_pass_runs_on_the_source() {
        let mut c = flat(1.0);
        let pts = [[0.0, 0.0, 0.5]];
        let (n, r) = with_prep(None, &mut c, &pts, 0.01, read_rows, |_| panic!()).unwrap();
        assert_eq!((n, r), (16, None));
    }

    #[test]
    fn an_all_empty_result_is_shown_then_refused() {
        let pts = [[0.0, 0.0, 0.5]];
        let mut shown = None;
        let e = with_prep(
            background(2.0),
            &mut flat(1.0),
            &pts,
            0.01,
            read_rows,
            |r| shown = Some(r.clone()),
        )
        .unwrap_err();
        assert!(e.to_string().starts_with("argument `background`"), "{e}");
        let shown = shown.expect("the report is shown before the check");
        assert_eq!((shown.stats.empty, shown.stats.histograms), (2, 2));
        assert!(shown.warning.is_some());
        // A smaller floor leaves the counts: checked, no warning.
        let (_, r) = with_prep(
            background(0.5),
            &mut flat(1.0),
            &pts,
            0.01,
            read_rows,
            |_| {},
        )
        .unwrap();
        let r = r.expect("a report");
        assert_eq!((r.stats.empty, r.warning), (0, None));
        assert!(r.summary.contains("background"), "{}", r.summary);
    }

    #[test]
    fn options_parse_to_nothing_or_a_preprocessing() {
        assert_eq!(Prep::parse(None, None, 1, None).unwrap(), None);
        let p = Prep::parse(Some("600b"), Some("2.4"), 4, Some("auto"))
            .unwrap()
            .unwrap();
        assert_eq!(
            (p.t_min, p.t_max, p.rebin, p.background),
            (
                Some(Bound::Bins(600)),
                Some(Bound::Metres(2.4)),
                4,
                Background::Auto
            )
        );
        assert!(Prep::parse(None, None, 0, None).unwrap().is_some());
        let e = Prep::parse(None, Some("x"), 1, None).unwrap_err();
        assert!(e.to_string().starts_with("argument `t_max`"), "{e}");
    }
}
