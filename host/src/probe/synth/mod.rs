//! Analysis by synthesis (beyond the paper): the hidden surfaces' **direct** light rendered
//! from surfels fitted to the capture, and subtracted, so that the off-diagonal probes see the
//! multi-bounce light and keep all of it.
//!
//! # Why
//!
//! Zeroing the time windows of Γ's direct returns ([`super::LeakMethod::Gate`]) removes the
//! two-bounce light that arrives in those same bins: direct light from extended surfaces fills
//! about 30 % of a capture's bins, and even an ideal window keeps only 4–13 % of the
//! indirect-only truth on the path-traced scenes (docs/indirect-light.md). A model of the
//! direct light, subtracted, keeps the rest.
//!
//! # Model
//!
//! Surfels `k` (centre `p_k`, unit normal `n_k`, area `A_k`, cluster `c_k`: [`Surfels`]) are
//! Lambertian patches. The direct return of surfel `k` for laser spot `x_l` and SPAD spot `x_s`
//! arrives at path length `τ = d1_l + |x_l − p_k| + |p_k − x_s| + d4_s` (device legs when the
//! capture's time axis holds them) with amplitude
//! `c_l · A_k · cos_wall,l cos_k,l / |x_l − p_k|² · cos_wall,s cos_k,s / |p_k − x_s|²`
//! (cosines clamped at 0: a surfel facing away returns nothing; `c_l` the physical laser's
//! falloff `cos/d²` when the capture has a laser position). No occlusion, no inter-reflection
//! (that is the light the probes are after). A return is binned as the renderer bins it: the
//! whole amplitude in bin `floor((τ − t0)/Δt)`, resolved to `Δt/8` so that delays below a bin
//! shift it; the capture's time response is a Gaussian of standard deviation `w` (bins).
//!
//! # Fit ([`SynthModel::fit`], two passes over the capture)
//!
//! 1. **Global**: one reflectance per cluster (non-negative least squares), with the response
//!    width `w ∈ {0, ¼, …, max_width}` bins and a global delay (time zero) in `±max_shift`
//!    bins at `Δt/8` chosen by the energy explained, on up to [`GLOBAL_HISTOGRAMS`] histograms
//!    spread over the scan (one render per histogram, blurred by each width).
//! 2. **Per histogram** ([`SynthOptions::per_histogram`], default): a gain per cluster
//!    (non-negative) and a delay within `±local_shift` bins of the global one, per (laser,
//!    SPAD) histogram. This absorbs the small errors of the geometry (a few mm of depth, a
//!    fraction of a degree of tilt), of the wall's and the laser's falloff and of the surfels'
//!    shading that a global fit leaves, at the cost of some indirect light that shares the
//!    direct light's shape within one histogram.
//!
//! [`SynthModel::explained`] is the fraction of the capture's energy `Σ H²` the model
//! explains over every histogram. On a capture of all paths it cannot reach 1: the
//! multi-bounce light is what it must not explain (0.1–7 % of the energy on the path-traced
//! scenes).
//!
//! # Cost and memory
//!
//! Rendering one row costs `K·S` returns (`K` surfels, `S` SPADs; the SPAD tables hold a
//! SPAD's surfels contiguously), then per histogram and cluster a blur and a binning of
//! `8·Nt` samples. Pass 1 renders each of its histograms once and adds `W` blurs and
//! `W·(2·8·max_shift + 1)` binnings; pass 2 `2·8·local_shift + 1` binnings per histogram.
//! Pass 2 keeps the model's histograms (`4·L·S·Nt` bytes, the size of the capture in `f32`)
//! when they fit [`SynthOptions::max_bytes`] together with the tables: subtracting a row is
//! then a difference; otherwise it renders the row again (the same values). Memory: `8·K·S`
//! bytes of SPAD tables (checked against [`SynthOptions::max_bytes`]), `S·(C + 1)` values per
//! row of gains and delays, the kept histograms, one row and one fine histogram per thread,
//! and pass 1's normal equations, `W·(2·8·max_shift + 1)·C·(C + 1)` f64 per row of a batch
//! (two rows per thread; 20 kB at the defaults and 5 clusters, 1.3 MB at 44), added in row
//! order so that the fit is the same on any number of threads.

mod facet;
mod facets;
mod linalg;
mod planes;
mod refine;
mod render;
mod subset;
mod surfels;
mod vec3;

pub use facet::Facet;
pub use facets::{
    FacetFit, FacetOptions, MAX_FACET_SURFELS, REFINE_WORK, facet_legs_bytes, refine_facets,
};
pub use planes::{facets_from_surfels, geometry_wavelength};
pub use refine::{Refined, refine};
pub use surfels::Surfels;

use crate::error::{Error, Result};
use crate::exec::{Exec, Pass, row_batch};
use crate::io::capture::{Geometry, RowSource};
use crate::timings::{self, Kind};
use linalg::nnls;
use rayon::prelude::*;
use render::{Renderer, SUB, bin, bin_range, bin_span, blurred_prefix, kernel};
use std::time::Instant;
use vltm_kernel::Point;

/// Histograms at most of the global fit (pass 1 of [`SynthModel::fit`]): its few parameters
/// (a width, a delay, a reflectance per cluster) are pinned by far fewer, and each costs
/// `W·(2·8·max_shift + 1)` binnings.
pub const GLOBAL_HISTOGRAMS: usize = 1024;

/// How [`SynthModel::fit`] fits the surfels' render to the capture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SynthOptions {
    /// A gain per cluster and a delay per histogram after the global fit (default true).
    pub per_histogram: bool,
    /// Global delay searched within ± this many bins (default 1).
    pub max_shift: f64,
    /// Per-histogram delay within ± this many bins of the global one (default 0.5).
    pub local_shift: f64,
    /// Largest response width searched, in bins (standard deviation; default 1, step ¼).
    pub max_width: f64,
    /// Whether the model includes the physical laser's falloff (true when the capture holds
    /// it, as renders and raw captures do; default true).
    pub laser_falloff: bool,
    /// Memory budget of the SPAD tables and the kept model histograms (bytes, default 2 GB;
    /// the histograms are rendered again per row when they do not fit).
    pub max_bytes: usize,
}

impl Default for SynthOptions {
    fn default() -> Self {
        Self {
            per_histogram: true,
            max_shift: 1.0,
            local_shift: 0.5,
            max_width: 1.0,
            laser_falloff: true,
            max_bytes: 2_000_000_000,
        }
    }
}

impl SynthOptions {
    /// Checks the options.
    ///
    /// # Errors
    /// [`Error::Argument`] naming `max_shift`, `local_shift` or `max_width` out of range.
    pub fn check(&self) -> Result<()> {
        let ok = |x: f64, hi: f64| x.is_finite() && (0.0..=hi).contains(&x);
        if !ok(self.max_shift, 50.0) {
            return Err(Error::arg("max_shift", "must lie in [0, 50] bins"));
        }
        if !ok(self.local_shift, 10.0) {
            return Err(Error::arg("local_shift", "must lie in [0, 10] bins"));
        }
        if !ok(self.max_width, 20.0) {
            return Err(Error::arg("max_width", "must lie in [0, 20] bins"));
        }
        Ok(())
    }
}

/// The surfels' direct light fitted to a capture (see the module docs).
#[derive(Clone, Debug)]
pub struct SynthModel {
    geometry: Geometry,
    renderer: Renderer,
    kern: Vec<f64>,
    /// Response width (bins, standard deviation).
    pub width: f64,
    /// Global delay (bins; positive: the capture arrives later than the geometry says).
    pub shift: f64,
    /// Reflectance per cluster of the global fit (in the capture's units per m² of surfel).
    pub albedo: Vec<f64>,
    /// Per histogram (`(l·S + s)·C + c`): the gain of each cluster (per-histogram fit).
    gains: Vec<f32>,
    /// Per histogram `l·S + s`: the delay in fine samples.
    shifts: Vec<i16>,
    /// The model's histograms (`(l·S + s)·Nt + t`), kept by the fit when they fit the memory
    /// budget with the SPAD tables; empty: [`SynthModel::subtract_row`] renders them again.
    kept: Vec<f32>,
    /// Fraction of the capture's energy `Σ H²` the model explains (0..1).
    pub explained: f64,
    /// When every sample of the capture is a non-negative integer (photon counts): the
    /// fraction of its energy that their Poisson noise holds, `Σ H / Σ H²` (the expected
    /// `Σ (H − E[H])²` is `Σ E[H]`), which no model explains. `None` for other data (a
    /// render, a preprocessed capture).
    pub photon_noise: Option<f64>,
    /// Wall-clock seconds of the fit.
    pub seconds: f64,
}

/// `aᵀGa − 2aᵀb`: the change of `‖y‖²` to the residual's.
fn drop_of(g: &[f64], b: &[f64], a: &[f64]) -> f64 {
    let c = b.len();
    let mut q = 0.0;
    for i in 0..c {
        for j in 0..c {
            q += a[i] * g[i * c + j] * a[j];
        }
        q -= 2.0 * a[i] * b[i];
    }
    q
}

/// Per-thread work of a histogram: fine render, prefix sums and binned templates.
#[derive(Default)]
struct Scratch {
    fine: Vec<f64>,
    prefix: Vec<Vec<f64>>,
    bins: Vec<Vec<f64>>,
    /// Per cluster, the fine samples `[lo, hi)` outside which its blurred render is zero (its
    /// prefix constant): the bins and sums of [`Scratch::normal`] skip the rest.
    support: Vec<(usize, usize)>,
    /// Per cluster, the bins `[n0, n1)` of the last [`Scratch::normal`] that can be nonzero.
    spans: Vec<(usize, usize)>,
}

impl Scratch {
    /// Renders SPAD `s` of `row` and prefixes it blurred by `kern`, per cluster.
    fn render(&mut self, r: &Renderer, g: &Geometry, row: &[(f64, f64)], s: usize, kern: &[f64]) {
        r.spad(g, row, s, &mut self.fine);
        self.blur(r, kern);
    }

    /// Prefixes the fine render of the last [`Scratch::render`] blurred by `kern`, per
    /// cluster (the render is kept: one render serves every width of the global fit).
    fn blur(&mut self, r: &Renderer, kern: &[f64]) {
        let c_n = r.surfels.clusters;
        self.prefix.resize_with(c_n, Vec::new);
        self.bins.resize_with(c_n, Vec::new);
        self.support.resize(c_n, (0, 0));
        for c in 0..c_n {
            let p = &mut self.prefix[c];
            blurred_prefix(&self.fine[c * r.nf..(c + 1) * r.nf], kern, p);
            let steps = |i: &usize| p[i + 1] != p[*i];
            let n = p.len() - 1;
            self.support[c] = match (0..n).find(steps) {
                Some(lo) => (lo, (lo..n).rfind(steps).map_or(lo, |i| i + 1)),
                None => (0, 0),
            };
        }
    }

    /// The model's histogram `Σ_c a_c·bin_c` with a delay of `shift` fine samples into `out`
    /// (overwritten), the gains `a` (per cluster) as the model stores them (`f32`).
    fn model(&mut self, pad: usize, shift: isize, a: &[f32], out: &mut [f64]) {
        out.fill(0.0);
        for (c, &a) in a.iter().enumerate() {
            if a == 0.0 {
                continue;
            }
            let m = &mut self.bins[c];
            m.resize(out.len(), 0.0);
            bin(&self.prefix[c], pad, shift, m);
            let a = f64::from(a);
            out.iter_mut().zip(&*m).for_each(|(o, x)| *o += a * x);
        }
    }

    /// Bins every cluster with a delay of `shift` fine samples; the normal equations against
    /// `h` into `gm` (`C × C`) and `b` (`C`).
    /// Only the bins a cluster's support reaches are binned and summed: the others are zero,
    /// so the sums are the full ones (the same terms in the same order, less exact zeros).
    fn normal(&mut self, pad: usize, shift: isize, h: &[f32], gm: &mut [f64], b: &mut [f64]) {
        let c_n = self.prefix.len();
        let nt = h.len();
        self.spans.resize(c_n, (0, 0));
        let spans = &mut self.spans;
        for (((span, m), prefix), &support) in spans
            .iter_mut()
            .zip(&mut self.bins)
            .zip(&self.prefix)
            .zip(&self.support)
        {
            let (n0, n1) = bin_span(support, pad, shift, nt);
            *span = (n0, n1);
            m.resize(nt, 0.0);
            bin_range(prefix, pad, shift, n0, &mut m[n0..n1]);
        }
        for i in 0..c_n {
            let (a0, a1) = spans[i];
            b[i] = self.bins[i][a0..a1]
                .iter()
                .zip(&h[a0..a1])
                .map(|(m, y)| m * f64::from(*y))
                .sum();
            for j in i..c_n {
                let (lo, hi) = (a0.max(spans[j].0), a1.min(spans[j].1));
                let v: f64 = if lo < hi {
                    self.bins[i][lo..hi]
                        .iter()
                        .zip(&self.bins[j][lo..hi])
                        .map(|(x, y)| x * y)
                        .sum()
                } else {
                    0.0
                };
                gm[i * c_n + j] = v;
                gm[j * c_n + i] = v;
            }
        }
    }
}

impl SynthModel {
    /// Fits the render of `surfels` to the capture `src` (two passes over its rows; see the
    /// module docs).
    ///
    /// # Errors
    /// Options out of range (named), the SPAD tables over [`SynthOptions::max_bytes`]
    /// (`max_bytes`), a paired or confocal capture (`leak_correct`: the model needs a SPAD
    /// grid), a capture with no energy, no surfel return inside the window or a non-finite
    /// fit (`leak_correct`), read errors.
    pub fn fit(
        src: &mut dyn RowSource,
        surfels: Surfels,
        opts: &SynthOptions,
        exec: Exec<'_>,
    ) -> Result<Self> {
        opts.check()?;
        let t = Instant::now();
        let g = src.geometry().clone();
        if g.confocal {
            return Err(Error::arg(
                "leak_correct",
                "the direct-light model needs a SPAD grid seen from every laser row, not a paired or confocal scan",
            ));
        }
        let bytes = Renderer::table_bytes(surfels.len(), g.spads.len());
        if bytes > opts.max_bytes {
            return Err(Error::arg(
                "max_bytes",
                format!(
                    "{} surfels × {} SPADs need {:.1} GB of tables, over the budget of {:.1} GB",
                    surfels.len(),
                    g.spads.len(),
                    bytes as f64 / 1e9,
                    opts.max_bytes as f64 / 1e9
                ),
            ));
        }
        let laser_scale = (0..g.lasers.len())
            .map(|l| {
                if opts.laser_falloff {
                    g.laser_falloff_at(l)
                } else {
                    1.0
                }
            })
            .collect();
        let reach = opts.max_shift + opts.local_shift + 4.0 * opts.max_width;
        let renderer = Renderer::new(&g, surfels, laser_scale, reach);
        let c_n = renderer.surfels.clusters;
        let (l_n, s_n) = (g.lasers.len(), g.spads.len());
        let nt = g.nt;
        // Pass 1: the global fit over a spread subset of histograms.
        let stride = (l_n * s_n).div_ceil(GLOBAL_HISTOGRAMS).max(1);
        let widths: Vec<f64> = {
            let n = (opts.max_width * 4.0).floor() as usize;
            (0..=n).map(|i| i as f64 * 0.25).collect()
        };
        let kerns: Vec<Vec<f64>> = widths.iter().map(|w| kernel(w * SUB as f64)).collect();
        let js = (opts.max_shift * SUB as f64).round() as isize;
        let shifts: Vec<isize> = (-js..=js).collect();
        let combos = widths.len() * shifts.len();
        let pad = renderer.pad;
        let bar = Pass::start(exec, "direct-light model: global fit", l_n);
        let batch = row_batch();
        let mut rows: Vec<(Point, Vec<f32>)> = Vec::new();
        let zero = || {
            (
                vec![0.0; combos * c_n * c_n],
                vec![0.0; combos * c_n],
                0.0f64,
            )
        };
        let (mut gsum, mut bsum, mut energy) = zero();
        for start in (0..l_n).step_by(batch) {
            let end = (start + batch).min(l_n);
            rows.resize_with(end - start, || ([0.0; 3], Vec::new()));
            read(src, start, &mut rows)?;
            let _t = timings::section("direct-light model", Kind::Parallel);
            // One accumulator per row, added in row order: the same bits on any number of
            // threads (a rayon fold/reduce would round as its splits fall).
            let per_row: Vec<_> = rows
                .par_iter()
                .enumerate()
                .map_init(
                    || (Scratch::default(), vec![0.0; c_n * c_n], vec![0.0; c_n]),
                    |(sc, gm, b), (i, (_, h))| {
                        let (mut ga, mut ba, mut e) = zero();
                        let l = start + i;
                        let row = renderer.laser_row(&g, l);
                        // Every `stride`-th histogram, the pattern moved by one SPAD per row.
                        for s in (0..s_n).filter(|s| (l * s_n + s + l) % stride == 0) {
                            let hist = &h[s * nt..(s + 1) * nt];
                            e += hist.iter().map(|x| f64::from(*x).powi(2)).sum::<f64>();
                            renderer.spad(&g, &row, s, &mut sc.fine);
                            for (wi, kern) in kerns.iter().enumerate() {
                                sc.blur(&renderer, kern);
                                for (ji, &j) in shifts.iter().enumerate() {
                                    sc.normal(pad, j, hist, gm, b);
                                    let at = wi * shifts.len() + ji;
                                    ga[at * c_n * c_n..(at + 1) * c_n * c_n]
                                        .iter_mut()
                                        .zip(gm.iter())
                                        .for_each(|(x, y)| *x += y);
                                    ba[at * c_n..(at + 1) * c_n]
                                        .iter_mut()
                                        .zip(b.iter())
                                        .for_each(|(x, y)| *x += y);
                                }
                            }
                        }
                        (ga, ba, e)
                    },
                )
                .collect();
            for (gs, bs, e) in per_row {
                gsum.iter_mut().zip(&gs).for_each(|(p, q)| *p += q);
                bsum.iter_mut().zip(&bs).for_each(|(p, q)| *p += q);
                energy += e;
            }
            bar.advance(end - start);
        }
        drop(bar);
        if !(energy > 0.0 && energy.is_finite()) {
            return Err(Error::arg(
                "leak_correct",
                "the capture holds no (finite) light to fit the direct-light model to",
            ));
        }
        let mut best = (f64::INFINITY, 0, vec![0.0; c_n]);
        for at in 0..combos {
            let (gm, b) = (
                &gsum[at * c_n * c_n..(at + 1) * c_n * c_n],
                &bsum[at * c_n..(at + 1) * c_n],
            );
            let mut a = vec![0.0; c_n];
            nnls(gm, b, &mut a);
            let d = drop_of(gm, b, &a);
            if d < best.0 {
                best = (d, at, a);
            }
        }
        let (d, at, albedo) = best;
        if d.is_nan() || d >= 0.0 || albedo.iter().any(|a| !a.is_finite()) {
            return Err(Error::arg(
                "leak_correct",
                "no surfel's direct return matches the capture inside its time window",
            ));
        }
        let (wi, ji) = (at / shifts.len(), at % shifts.len());
        let mut model = Self {
            geometry: g.clone(),
            kern: kerns[wi].clone(),
            width: widths[wi],
            shift: shifts[ji] as f64 / SUB as f64,
            albedo,
            gains: Vec::new(),
            shifts: vec![shifts[ji] as i16; l_n * s_n],
            kept: Vec::new(),
            explained: 0.0,
            photon_noise: None,
            seconds: 0.0,
            renderer,
        };
        // Pass 2: per-histogram gains and delays (or the global fit's), and the energy
        // explained over every histogram.
        let jl = (opts.local_shift * SUB as f64).round() as isize;
        let local: Vec<isize> = if opts.per_histogram {
            (shifts[ji] - jl..=shifts[ji] + jl).collect()
        } else {
            vec![shifts[ji]]
        };
        let bar = Pass::start(exec, "direct-light model: per histogram", l_n);
        let (mut total, mut resid) = (0.0f64, 0.0f64);
        // Σ H and whether every sample is a count (a non-negative integer).
        let (mut counts, mut integral) = (0.0f64, true);
        // The model's histograms are kept when they and the tables fit the budget.
        let keep_all =
            bytes.saturating_add(l_n.saturating_mul(s_n).saturating_mul(nt * 4)) <= opts.max_bytes;
        let mut kept = if keep_all {
            vec![0.0f32; l_n * s_n * nt]
        } else {
            Vec::new()
        };
        let mut gains = vec![0.0f32; l_n * s_n * c_n];
        let mut hshift = vec![0i16; l_n * s_n];
        for start in (0..l_n).step_by(batch) {
            let end = (start + batch).min(l_n);
            rows.resize_with(end - start, || ([0.0; 3], Vec::new()));
            read(src, start, &mut rows)?;
            let _t = timings::section("direct-light model", Kind::Parallel);
            let m = &model;
            let kept_rows = if keep_all {
                &mut kept[start * s_n * nt..end * s_n * nt]
            } else {
                &mut [][..]
            };
            let mut kept_rows: Vec<&mut [f32]> = if keep_all {
                kept_rows.chunks_mut(s_n * nt).collect()
            } else {
                Vec::new()
            };
            kept_rows.resize_with(end - start, || &mut [][..]);
            let per_row: Vec<RowFit> = rows
                .par_iter()
                .zip(kept_rows.into_par_iter())
                .enumerate()
                .map(|(i, ((_, h), out))| {
                    let l = start + i;
                    let row = m.renderer.laser_row(&g, l);
                    let mut sc = Scratch::default();
                    let (mut gm, mut b, mut a) =
                        (vec![0.0; c_n * c_n], vec![0.0; c_n], vec![0.0; c_n]);
                    let mut out_g = vec![0.0f32; s_n * c_n];
                    let mut out_j = vec![0i16; s_n];
                    let mut mh = vec![0.0f64; nt];
                    let (mut e, mut r) = (0.0, 0.0);
                    // Σ H, and whether every sample is a count.
                    let (mut c, mut int) = (0.0, true);
                    for s in 0..s_n {
                        let hist = &h[s * nt..(s + 1) * nt];
                        let hh: f64 = hist.iter().map(|x| f64::from(*x).powi(2)).sum();
                        e += hh;
                        c += hist.iter().map(|&x| f64::from(x)).sum::<f64>();
                        int = int && hist.iter().all(|&x| x >= 0.0 && x == x.trunc());
                        sc.render(&m.renderer, &g, &row, s, &m.kern);
                        let mut keep = (0.0f64, local[0], m.albedo.clone());
                        for &j in &local {
                            sc.normal(pad, j, hist, &mut gm, &mut b);
                            if opts.per_histogram {
                                nnls(&gm, &b, &mut a);
                            } else {
                                a.copy_from_slice(&m.albedo);
                            }
                            let d = drop_of(&gm, &b, &a);
                            if d < keep.0 {
                                keep = (d, j, a.clone());
                            }
                        }
                        r += (hh + keep.0).max(0.0);
                        out_j[s] = keep.1 as i16;
                        let gs = &mut out_g[s * c_n..(s + 1) * c_n];
                        for (o, a) in gs.iter_mut().zip(&keep.2) {
                            *o = *a as f32;
                        }
                        if !out.is_empty() {
                            sc.model(pad, keep.1, gs, &mut mh);
                            for (o, x) in out[s * nt..(s + 1) * nt].iter_mut().zip(&mh) {
                                *o = *x as f32;
                            }
                        }
                    }
                    (out_g, out_j, e, r, (c, int))
                })
                .collect();
            for (i, (gg, jj, e, r, (c, int))) in per_row.into_iter().enumerate() {
                counts += c;
                integral = integral && int;
                let l = start + i;
                gains[l * s_n * c_n..(l + 1) * s_n * c_n].copy_from_slice(&gg);
                hshift[l * s_n..(l + 1) * s_n].copy_from_slice(&jj);
                total += e;
                resid += r;
            }
            bar.advance(end - start);
        }
        drop(bar);
        model.gains = gains;
        model.shifts = hshift;
        model.kept = kept;
        model.explained = 1.0 - resid / total;
        model.photon_noise = (integral && total > 0.0).then(|| counts / total);
        if !model.explained.is_finite() {
            return Err(Error::arg(
                "leak_correct",
                "the direct-light fit is not finite",
            ));
        }
        model.seconds = t.elapsed().as_secs_f64();
        Ok(model)
    }

    /// The surfels rendered.
    pub fn surfels(&self) -> &Surfels {
        &self.renderer.surfels
    }

    /// Subtracts the model's histograms of laser row `l` from `out` (`S·Nt`, SPAD-major, as
    /// read): those the fit kept, else rendered again (the same values: each histogram summed
    /// over its clusters in `f64`, then rounded to `f32` once).
    pub fn subtract_row(&self, l: usize, out: &mut [f32]) {
        let g = &self.geometry;
        let (nt, s_n, c_n) = (g.nt, g.spads.len(), self.renderer.surfels.clusters);
        if !self.kept.is_empty() {
            let m = &self.kept[l * s_n * nt..(l + 1) * s_n * nt];
            out.iter_mut().zip(m).for_each(|(o, x)| *o -= x);
            return;
        }
        let row = self.renderer.laser_row(g, l);
        out.par_chunks_mut(nt).enumerate().take(s_n).for_each_init(
            || (Scratch::default(), vec![0.0f64; nt]),
            |(sc, m), (s, h)| {
                sc.render(&self.renderer, g, &row, s, &self.kern);
                let j = isize::from(self.shifts[l * s_n + s]);
                let a = &self.gains[(l * s_n + s) * c_n..(l * s_n + s + 1) * c_n];
                sc.model(self.renderer.pad, j, a, m);
                for (o, x) in h.iter_mut().zip(&*m) {
                    *o -= *x as f32;
                }
            },
        );
    }
}

/// One row of the fit's second pass: its per-histogram gains and delays, its energy `Σ H²`,
/// its residual energy, and `(Σ H, whether every sample is a count)`.
type RowFit = (Vec<f32>, Vec<i16>, f64, f64, (f64, bool));

/// Reads rows `start..` into `rows`, timed as the probes time their reads.
fn read(src: &mut dyn RowSource, start: usize, rows: &mut [(Point, Vec<f32>)]) -> Result<()> {
    let kind = if src.reads_in_parallel() {
        Kind::Parallel
    } else {
        Kind::Serial
    };
    let _t = timings::section("read rows", kind);
    src.read_rows(start, rows)?;
    // Non-finite samples read as 0, as the probes read them (their summaries count them).
    for (_, h) in rows.iter_mut() {
        h.iter_mut()
            .filter(|x| !x.is_finite())
            .for_each(|x| *x = 0.0);
    }
    Ok(())
}

/// A [`RowSource`] that returns the capture minus the model's direct light, row by row.
pub struct Synthesized<'a> {
    src: &'a mut dyn RowSource,
    model: &'a SynthModel,
}

impl<'a> Synthesized<'a> {
    /// Wraps `src` with the model fitted to it.
    pub fn new(src: &'a mut dyn RowSource, model: &'a SynthModel) -> Self {
        Self { src, model }
    }
}

impl RowSource for Synthesized<'_> {
    fn geometry(&self) -> &Geometry {
        self.src.geometry()
    }

    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        let x = self.src.read_row(l, out)?;
        self.model.subtract_row(l, out);
        Ok(x)
    }

    fn read_rows(&mut self, first: usize, out: &mut [(Point, Vec<f32>)]) -> Result<()> {
        self.src.read_rows(first, out)?;
        for (i, (_, h)) in out.iter_mut().enumerate() {
            self.model.subtract_row(first + i, h);
        }
        Ok(())
    }

    fn reads_in_parallel(&self) -> bool {
        self.src.reads_in_parallel()
    }

    fn rows(&self) -> std::ops::Range<usize> {
        self.src.rows()
    }
}

#[cfg(test)]
mod tests;
