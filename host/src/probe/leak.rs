//! Leak correction (beyond the paper): the capture's **direct** (3-vertex) light removed, row
//! by row, before the off-diagonal probes (by default in `vltm indirect`, `column`, `row`,
//! `relight` and `matrix` with `--volume`; `--no-leak-correct` skips it).
//!
//! # Why
//!
//! The 4-vertex gate of `T(x_a, x_b)` selects path times `|x_l−x_a| + |x_a−x_b| + |x_b−x_s|`.
//! For a focus `x_a` between the wall and a surface at `x_b`, that time is close to the
//! surface's own direct return `|x_l−x_b| + |x_b−x_s|` for many laser/SPAD pairs, so direct
//! light passes the gate — at 10–100× the true indirect light in the in-focus sum (Eq. 17).
//! Γ cannot mask it: it sits on the surface.
//!
//! # Model and assumptions
//!
//! The hidden surfaces that return direct light lie at the voxels of Γ (direct light above
//! ε·max): each voxel `v` is a point scatterer seen through the wall as the simulator's point
//! scatterers are (`sim`): path time `τ_lvs = d1_l + d_lv + d_vs + d4_s` (device legs as the
//! capture's time axis), amplitude `a_lvs = c_l·cos_l·cos_s / (d_lv² d_vs²)` (Lambertian wall,
//! `1/d²` per leg, isotropic at `v`; `c_l` the physical laser's `cos θ/d²` when the probes
//! compensate it, i.e. when the capture holds it). No occlusion, no inter-reflection.
//!
//! # Methods ([`LeakMethod`])
//!
//! * **Gate** (default): per (laser, SPAD), the bins where a 3-vertex return of any Γ voxel can
//!   arrive, `τ_lvs ± (r_cell + 3Δt)` (`r_cell` half a voxel's diagonal: a surface anywhere in
//!   the voxel's cell; 3Δt for the pulse and binning), are set to 0. Only the timing of the
//!   model is used, so it holds whatever the surface's reflectance, orientation or shape
//!   within its voxels. What is left: light arriving when no Γ voxel's direct return can —
//!   necessarily multi-bounce light, or direct light from surfaces outside Γ. What is lost:
//!   indirect light that arrives inside a window (measured: the corrected `I_i` keeps 0.53–0.59
//!   of the indirect-only truth `I_i(H − H_control)` with vltm's defaults, 0.10–0.19 with the
//!   paper's wider σ, small ε and r0 = 0, whose larger Γ covers more of the time axis).
//! * **Fit**: the scatterers' complex reflectances `ρ_v` at the carrier `ω0 = 2π/λ` (magnitude
//!   albedo·area/π, phase a path offset within ±λ/2) fitted so that the model reproduces the
//!   capture as the phasor gate sees it: every histogram demodulated and smoothed,
//!   `b_ls(t_c) = Σ_n H_ls[n] e^{−iω0 t_n} w(t_c − t_n)`, `w(x) = exp(−x²/2σ²)`, sampled every
//!   σ/2; `Σ |b − model|²` minimised by conjugate gradients on the normal equations
//!   ([`LeakOptions::iterations`] steps from 0), and the model's render subtracted: per
//!   (laser, SPAD, voxel) the wavelet `2·a·Re[ρ_v e^{iω0(t − τ)}]·g(t − τ)`, `g` a unit-sum
//!   Gaussian of σ_p = max(Δt, σ/10), whose demodulated envelope is the fitted model's (the
//!   fit uses σ_m² = σ² + σ_p²). Pairs whose `τ_lvs` lies outside the window are left out of
//!   fit and model. It keeps the indirect light but needs voxels finer than about λ/4 (a
//!   surface between two voxel centres must be reproducible at the carrier): 3.8× the control
//!   on the path-traced two_patches (pitch 0.1/0.05 m, λ = 0.4 m), but 1.01× on the 16×16 panel
//!   scene (pitch 0.06 m, λ = 0.133 m), where it explains only 83 % of the demodulated energy.
//!
//! [`DirectModel::explained`] reports the fraction of the capture's energy `Σ H²` in the zeroed
//! windows (gate) or of the demodulated energy the model explains (fit).
//!
//! # Measured on path-traced captures: what leaks, and what the gate keeps
//!
//! On `fixtures/pathtraced` (mitransient 1.3.1, 8×8 lasers × 8×8 SPADs, 300 bins of 1 cm; per
//! scene three renders with the same seed: all paths, direct only, two hidden vertices only =
//! the indirect-only truth), volume `-0.75:0.75:16,-0.75:0.75:16,0.5:1.4:19`, vltm's defaults
//! (λ = 0.4 m, σ = 0.267 m, ε = 0.1, r0 = 0.4 m) plus `--compensate-laser` (off by default:
//! docs/indirect-light.md, "The laser falloff"), means over the
//! objects' voxels (`cargo bench --bench pathtraced -- diagnose`). Panel/figure scene (a
//! 0.6 × 0.9 m panel, 2 cm thick, facing the wall and a box figure): the gate gives the figure
//! 21.6× and the projector's own panel 8.1× their direct-only controls. The candidates:
//!
//! * **Direct light of surfaces outside Γ** (the cause of what is left on the panel). After the
//!   gate the direct-only control keeps 0.09 % of its energy (0.8 % of its counts), and all of
//!   it lies inside the panel's own direct time range: it comes from the panel's far half
//!   (x −0.25…−0.05 m, z 0.99–1.13 m), 0.25–0.32 m from the nearest Γ voxel, whose direct
//!   image is below ε·max. It is not the render's time response: the surface points whose
//!   returns miss every window lie a median 0.25 m (panel) and 0.10 m (figure) from the
//!   nearest Γ voxel, outside its cell (r_cell = 0.075 m).
//! * **Window width and the gate's reach.** The 4-vertex gate's envelope (σ = 0.267 m) spans
//!   ±0.8 m of path, so any such residual near a pair's time passes. Wider windows remove it
//!   and the indirect light with it: 2·r_cell gives 75×/36× (figure/panel) but keeps only
//!   0.08/0.10 of the truth; 4·r_cell 14 000×/7 500× and ≤ 0.01. ε = 0.03 (Γ 620 voxels, its
//!   windows cover the far half) gives 2 200×/900× and keeps 0.04/0.07, Pearson 0.62/0.46.
//! * **Pairs on the same flat surface.** With Γ cut to the panel for the pairs (the windows
//!   of the whole Γ), such pairs make 59 % of the panel's corrected control, 25 % of its
//!   corrected `I_i` and 0.2 % of its truth (a flat surface does not light itself); on the
//!   figure 9 %, 1 % and 0.06 %. r0 = 0.6 m instead of 0.4 m drops most of them: 25×/16×,
//!   kept 0.24, Pearson 0.84/0.93.
//! * **`--compensate-laser`**: without it Γ changes (321 voxels) and the ratios fall to
//!   5.0×/2.1× (kept 1.0/1.7, i.e. the corrected `I_i` holds other light than the truth's).
//! * **Thickness**: the 2 cm panel lies within one voxel (pitch 5 cm in depth); its edges
//!   return little; no measurable effect separate from the above.
//! * **Monte Carlo noise** (a second render with seed 1, the same 30 000 samples; the
//!   noise-only capture `(H_seed0 − H_seed1)/√2` through the same windows): 0.1–0.2 % of the
//!   corrected `I_i` on panel/figure (the two seeds' corrected `I_i` correlate at 0.999), the
//!   ratios 21.6×/8.1× at seed 0 and 19.8×/8.4× at seed 1. Not a cause there.
//!
//! The corner scene (two 0.5 × 0.6 m panels at 90°, each lighting the other) gives 19.2×
//! (the projector's panel) and 28.1× (the lit one), kept 0.18/0.25, Pearson 0.41/0.63;
//! same-surface pairs make 28 % of each panel's corrected control; windows 2·r_cell, ε = 0.03
//! and r0 = 0.6 m all lower kept and Pearson there (Pearson −0.04, 0.25, −0.07 over Γ). There
//! the noise is 5–7 % of the corrected `I_i` and 1.4× the corrected control: the ratios move to
//! 22.6×/21.2× and Pearson to 0.35/0.44 at seed 1 (noise enters `|·|²` through its cross term
//! with the signal, ≈ 2·√0.06 per voxel). The seed-0 Pearson is favoured because the truth
//! shares the full capture's seed.
//!
//! # Ceilings: what any window-based correction can reach
//!
//! The truth put through the same windows keeps only 0.18 (figure) and 0.20 (panel) of its own
//! `I_i` (0.13 and 0.14 on the corner), and its Pearson with the truth is 0.89/0.95 (figure/
//! panel) but only 0.67/0.68 on the corner. The corrected `I_i` correlates at 0.93–0.99 with this
//! windowed truth on every object, and the oracle subtraction `H_all − H_control` (no windows)
//! keeps 0.99–1.07 of the truth with Pearson ≥ 0.995, so the chain measures what it should and
//! the gap to the truth is the windows'. At this aperture (λ = 0.4 m) the two-bounce returns of
//! nearby surfaces arrive inside the direct windows of Γ: `kept ≥ 0.5` is out of reach on both
//! scenes, and Pearson ≥ 0.8 on the corner, whatever the window width (wider only lowers both).
//! On the corner, Γ (ε = 0.1) holds only the panels' wall-side halves (z 0.70–0.95 m), not the
//! apex, and within Γ the half nearer the other panel holds 3/4 of the truth but keeps only
//! 0.12–0.13 of it (0.16–0.17 on the farther half): the windows flatten the truth's gradient
//! toward the apex. The defaults are unchanged: the ratios reach 8–28× on every object of both
//! scenes, and no setting measured keeps more indirect light or correlates better on both
//! scenes (docs/indirect-light.md has the table; `cargo bench --bench pathtraced`).
//!
//! # Cost and memory
//!
//! Gate: one pass over the capture to measure the removed energy, then per row read `Ks·V`
//! window computations (`V = |Γ|`) and ≤ `2(r_cell + 3Δt)/Δt` bins zeroed each. Fit: one pass
//! for `Aᴴb`, then per iteration one application of `AᴴA` without the data:
//! `2·Kl·Ks·V·(2K + 1)` complex multiply-adds (`2K + 1 ≈ 17` coarse samples per return);
//! per row read, `Ks·V` wavelets of `≈ 8σ_p/Δt` bins. Memory: `8·V·Ks` bytes of voxel–SPAD
//! tables (fit), `V` complex values per thread, one row per thread; never the capture.

use super::wave::Wave;
use crate::error::{Error, Result};
use crate::exec::{Exec, Pass, row_batch};
use crate::io::capture::{Geometry, RowSource};
use crate::timings::{self, Kind};
use crate::volume::Volume;
use num_complex::Complex64;
use rayon::prelude::*;
use std::time::Instant;
use vltm_kernel::Point;
use vltm_kernel::geometry::dist64;

/// How the direct light is removed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LeakMethod {
    /// Zero, per (laser, SPAD), the bins where a 3-vertex return of a Γ voxel can arrive:
    /// `τ_lvs ± (r_cell + 3Δt)` (`r_cell` half a voxel's diagonal).
    Gate,
    /// Fit the one-bounce model's reflectances (CGNR) and subtract its render.
    Fit,
}

/// Options of the direct-light removal (the CLI's `--leak-correct`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LeakOptions {
    /// Time-gating of the 3-vertex windows or the model fit (default gate).
    pub method: LeakMethod,
    /// Conjugate-gradient iterations of the fit (default 30).
    pub iterations: usize,
    /// Complex reflectances of the fit (a path offset per voxel, default) or real ones only.
    pub complex: bool,
    /// Gate: half-width of the zeroed windows in units of `r_cell` (default 1), plus 3Δt.
    pub cells: f64,
}

impl Default for LeakOptions {
    fn default() -> Self {
        Self {
            method: LeakMethod::Gate,
            iterations: 30,
            complex: true,
            cells: 1.0,
        }
    }
}

/// Half the diagonal of a voxel cell of `volume` (0 for point lists).
pub fn cell_radius(volume: &Volume) -> f64 {
    match volume.axes {
        Some(axes) => {
            let p2: f64 = (0..3)
                .map(|i| {
                    let n = volume.shape[i];
                    if n > 1 {
                        (f64::from(axes[i][1] - axes[i][0]) / (n - 1) as f64).powi(2)
                    } else {
                        0.0
                    }
                })
                .sum();
            0.5 * p2.sqrt()
        }
        None => 0.0,
    }
}

/// The fitted direct-light model of a capture (see the module docs).
#[derive(Clone, Debug)]
pub struct DirectModel {
    geometry: Geometry,
    points: Vec<Point>,
    /// Fitted complex reflectance per point.
    pub rho: Vec<Complex64>,
    basis: Basis,
    /// Fraction of the demodulated capture's energy the model explains (fit), or of the
    /// capture's energy `Σ H²` in the zeroed windows (gate) (0..1).
    pub explained: f64,
    /// Half-width of the zeroed windows (gate method) (m of path).
    gate: Option<f64>,
    /// Wall-clock seconds of the fit.
    pub seconds: f64,
}

/// Carrier, envelopes and the coarse time grid of the fit.
#[derive(Clone, Debug)]
struct Basis {
    omega: f64,
    sigma: f64,
    sigma_p: f64,
    sigma_m: f64,
    /// Coarse step (σ/2) and first coarse time (relative to t0), number of samples.
    h: f64,
    c0: f64,
    nc: usize,
    /// Half window in coarse samples of a model return.
    k: usize,
    /// Per-laser factor (the physical laser's falloff when the probes compensate it).
    laser_scale: Vec<f64>,
    d1: Vec<f64>,
    d4: Vec<f64>,
    window: f64,
}

/// Voxel–SPAD tables: `d_vs + d4_s` and `cos_s / d_vs²`, `[v][s]`.
#[derive(Clone, Debug)]
struct SpadTables {
    t: Vec<f32>,
    g: Vec<f32>,
    ks: usize,
}

/// Leg from a wall spot to a voxel: (distance, cos at the wall / d²).
fn leg(spot: Point, v: Point) -> (f64, f64) {
    let p = v.map(f64::from);
    let d = dist64(&spot, &p);
    if d.is_nan() || d <= 0.0 {
        return (d, 0.0);
    }
    let cos = ((p[2] - f64::from(spot[2])) / d).max(0.0);
    (d, cos / (d * d))
}

impl Basis {
    fn new(g: &Geometry, wave: &Wave) -> Result<Self> {
        let cfg = wave.config(g)?;
        let sigma = cfg.sigma();
        let omega = std::f64::consts::TAU / cfg.wavelength();
        let sigma_p = g.dt.max(sigma / 10.0);
        let sigma_m = (sigma * sigma + sigma_p * sigma_p).sqrt();
        let h = sigma / 2.0;
        let k = (4.0 * sigma_m / h).ceil() as usize;
        let window = (g.nt.saturating_sub(1)) as f64 * g.dt;
        let c0 = -(k as f64) * h;
        let nc = ((window - c0) / h).ceil() as usize + k + 1;
        let laser_scale = (0..g.lasers.len())
            .map(|l| {
                if wave.compensate_laser {
                    g.laser_falloff_at(l)
                } else {
                    1.0
                }
            })
            .collect();
        let leg_len = |x: &Point, o: [f64; 3]| if g.legs_in_time { dist64(x, &o) } else { 0.0 };
        Ok(Self {
            omega,
            sigma,
            sigma_p,
            sigma_m,
            h,
            c0,
            nc,
            k,
            laser_scale,
            d1: g
                .lasers
                .iter()
                .map(|x| leg_len(x, g.laser_origin))
                .collect(),
            d4: g
                .spads
                .iter()
                .map(|x| leg_len(x, g.sensor_origin))
                .collect(),
            window,
        })
    }

    /// First coarse index and the envelope weights of a return at `tau` (relative to t0):
    /// `(σ/σ_m)·exp(−(t_c − τ)²/2σ_m²)` for `2k + 1` samples from the returned index.
    fn envelope(&self, tau: f64, w: &mut [f64]) -> usize {
        let centre = ((tau - self.c0) / self.h).round() as i64;
        let first = (centre - self.k as i64).max(0) as usize;
        let inv = 0.5 / (self.sigma_m * self.sigma_m);
        let scale = self.sigma / self.sigma_m;
        let x0 = self.c0 + first as f64 * self.h - tau;
        // w_j = exp(−(x0 + jh)²·inv) by recurrence: ratio r_j = exp(−(2(x0 + jh)h + h²)·inv),
        // r_{j+1} = r_j·exp(−2h²·inv).
        let mut wj = scale * (-x0 * x0 * inv).exp();
        let mut r = (-(2.0 * x0 * self.h + self.h * self.h) * inv).exp();
        let q = (-2.0 * self.h * self.h * inv).exp();
        for x in w.iter_mut() {
            *x = wj;
            wj *= r;
            r *= q;
        }
        first
    }
}

impl SpadTables {
    fn new(g: &Geometry, pts: &[Point], basis: &Basis) -> Self {
        let ks = g.spads.len();
        let mut t = vec![0.0f32; pts.len() * ks];
        let mut gg = vec![0.0f32; pts.len() * ks];
        t.par_chunks_mut(ks)
            .zip(gg.par_chunks_mut(ks))
            .zip(pts.par_iter())
            .for_each(|((t, gg), &v)| {
                for (s, &x) in g.spads.iter().enumerate() {
                    let (d, f) = leg(x, v);
                    t[s] = (d + basis.d4[s]) as f32;
                    gg[s] = f as f32;
                }
            });
        Self { t, g: gg, ks }
    }
}

/// One laser row of the model: per voxel `(d1 + d_lv − t0, c_l·cos_l/d_lv²)`.
fn laser_legs(g: &Geometry, basis: &Basis, pts: &[Point], l: usize) -> Vec<(f64, f64)> {
    let x = g.lasers[l];
    pts.iter()
        .map(|&v| {
            let (d, f) = leg(x, v);
            (basis.d1[l] + d - g.t0, f * basis.laser_scale[l])
        })
        .collect()
}

/// The SPADs of row `l` (the row's own SPAD for paired and confocal captures).
fn row_spads(g: &Geometry, l: usize) -> std::ops::Range<usize> {
    if g.confocal {
        l..l + 1
    } else {
        0..g.spads.len()
    }
}

/// The per-(laser, SPAD, voxel) return: time relative to t0 and amplitude, or `None` outside
/// the window.
#[inline]
fn ret(
    basis: &Basis,
    tab: &SpadTables,
    lrow: &[(f64, f64)],
    v: usize,
    s: usize,
    confocal_spad: Option<(f64, f64)>,
) -> Option<(f64, f64)> {
    let (tl, al) = lrow[v];
    let (ts, gs) = match confocal_spad {
        Some(x) => x,
        None => (
            f64::from(tab.t[v * tab.ks + s]),
            f64::from(tab.g[v * tab.ks + s]),
        ),
    };
    let tau = tl + ts;
    let a = al * gs;
    (a != 0.0 && (0.0..=basis.window).contains(&tau)).then_some((tau, a))
}

/// Scratch of one worker.
struct Work {
    m: Vec<Complex64>,
    w: Vec<f64>,
}

impl Work {
    fn new(basis: &Basis) -> Self {
        Self {
            m: vec![Complex64::new(0.0, 0.0); basis.nc],
            w: vec![0.0; 2 * basis.k + 1],
        }
    }
}

/// The fit's operator over one row: `y += A_lᴴ (A_l p)` (`b = None`) or `y += A_lᴴ b_l`
/// (the demodulated row `b`, `Ks × nc`).
#[allow(clippy::too_many_arguments)]
fn apply_row(
    g: &Geometry,
    basis: &Basis,
    tab: &SpadTables,
    pts: &[Point],
    l: usize,
    p: &[Complex64],
    b: Option<&[Complex64]>,
    work: &mut Work,
    y: &mut [Complex64],
) {
    let lrow = laser_legs(g, basis, pts, l);
    let nk = 2 * basis.k + 1;
    for (si, s) in row_spads(g, l).enumerate() {
        let m = &mut work.m;
        match b {
            Some(b) => m.copy_from_slice(&b[si * basis.nc..(si + 1) * basis.nc]),
            None => {
                m.iter_mut().for_each(|z| *z = Complex64::new(0.0, 0.0));
                for (v, &pv) in p.iter().enumerate() {
                    if pv == Complex64::new(0.0, 0.0) {
                        continue;
                    }
                    let Some((tau, a)) = ret_any(g, basis, tab, &lrow, pts, l, v, s) else {
                        continue;
                    };
                    let z = pv * a * Complex64::from_polar(1.0, -basis.omega * tau);
                    let first = basis.envelope(tau, &mut work.w);
                    let end = (first + nk).min(basis.nc);
                    for (mc, &wk) in m[first..end].iter_mut().zip(&work.w) {
                        *mc += z * wk;
                    }
                }
            }
        }
        for (v, yv) in y.iter_mut().enumerate() {
            let Some((tau, a)) = ret_any(g, basis, tab, &lrow, pts, l, v, s) else {
                continue;
            };
            let first = basis.envelope(tau, &mut work.w);
            let end = (first + nk).min(basis.nc);
            let mut acc = Complex64::new(0.0, 0.0);
            for (mc, &wk) in m[first..end].iter().zip(&work.w) {
                acc += mc * wk;
            }
            *yv += acc * a * Complex64::from_polar(1.0, basis.omega * tau);
        }
    }
}

/// [`ret`] for grids and confocal rows alike.
#[allow(clippy::too_many_arguments)]
#[inline]
fn ret_any(
    g: &Geometry,
    basis: &Basis,
    tab: &SpadTables,
    lrow: &[(f64, f64)],
    pts: &[Point],
    l: usize,
    v: usize,
    s: usize,
) -> Option<(f64, f64)> {
    if g.confocal {
        // The row's own SPAD spot (the laser spot's for a confocal scan).
        let (d, f) = leg(g.spads[l], pts[v]);
        ret(basis, tab, lrow, v, s, Some((d + basis.d4[l], f)))
    } else {
        ret(basis, tab, lrow, v, s, None)
    }
}

/// Demodulates and smooths one row of histograms onto the coarse grid (`Ks × nc`), adding
/// `Σ|b|²` to `energy`.
fn demodulate(g: &Geometry, basis: &Basis, row: &[f32], out: &mut [Complex64]) -> f64 {
    let nt = g.nt;
    let nk = 2 * basis.k + 1;
    let mut w = vec![0.0; nk];
    out.iter_mut().for_each(|z| *z = Complex64::new(0.0, 0.0));
    let inv = 0.5 / (basis.sigma * basis.sigma);
    for (hist, o) in row.chunks_exact(nt).zip(out.chunks_exact_mut(basis.nc)) {
        for (n, &x) in hist.iter().enumerate() {
            if x == 0.0 || !x.is_finite() {
                continue;
            }
            let t = n as f64 * g.dt;
            let z = f64::from(x) * Complex64::from_polar(1.0, -basis.omega * t);
            let centre = ((t - basis.c0) / basis.h).round() as i64;
            let first = (centre - basis.k as i64).max(0) as usize;
            let end = (first + nk).min(basis.nc);
            for (c, wc) in (first..end).zip(w.iter_mut()) {
                let dx = basis.c0 + c as f64 * basis.h - t;
                *wc = (-dx * dx * inv).exp();
            }
            for (oc, &wc) in o[first..end].iter_mut().zip(&w) {
                *oc += z * wc;
            }
        }
    }
    out.iter().map(|z| z.norm_sqr()).sum()
}

/// The energy the gate method removes, summed over rows (any order, any split):
/// `Σ H²` of the capture and of the zeroed samples.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GateEnergy {
    /// `Σ H²` over the finite samples read.
    pub total: f64,
    /// `Σ H²` over the samples the gate zeroed.
    pub cut: f64,
}

impl GateEnergy {
    /// Adds one row: `raw` as read, `kept` after [`DirectModel::subtract_row`].
    pub fn add(&mut self, raw: &[f32], kept: &[f32]) {
        for (a, b) in raw.iter().zip(kept) {
            let a = f64::from(*a);
            if a.is_finite() {
                self.total += a * a;
                if *b == 0.0 {
                    self.cut += a * a;
                }
            }
        }
    }

    /// The fraction removed ([`DirectModel::explained`]).
    ///
    /// # Errors
    /// [`Error::Argument`] (`leak_correct`) when nothing was removed: the capture holds no
    /// light at the direct return times.
    pub fn explained(&self) -> Result<f64> {
        if self.cut.is_nan() || self.cut <= 0.0 {
            return Err(Error::arg(
                "leak_correct",
                "the capture holds no light at the direct (3-vertex) return times of Γ's \
                 voxels: there is no direct light to remove",
            ));
        }
        Ok(self.cut / self.total)
    }
}

fn dot(a: &[Complex64], b: &[Complex64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x.conj() * y).re).sum()
}

impl DirectModel {
    /// The carrier basis and voxel–SPAD tables over `points`, after the checks every method
    /// shares: `points` not empty, and some 3-vertex return inside the capture's window.
    fn check(g: &Geometry, points: &[Point], wave: &Wave) -> Result<(Basis, SpadTables)> {
        if points.is_empty() {
            return Err(Error::arg(
                "leak_correct",
                "Γ is empty: no voxel to fit the direct light at (lower $epsilon or check $volume)",
            ));
        }
        let basis = Basis::new(g, wave)?;
        let tab = SpadTables::new(g, points, &basis);
        let v_n = points.len();
        let any = (0..g.lasers.len()).into_par_iter().any(|l| {
            let lrow = laser_legs(g, &basis, points, l);
            row_spads(g, l).any(|s| {
                (0..v_n).any(|v| ret_any(g, &basis, &tab, &lrow, points, l, v, s).is_some())
            })
        });
        if !any {
            return Err(Error::arg(
                "leak_correct",
                format!(
                    "no direct (3-vertex) return of Γ's {v_n} voxels falls in the capture's window \
                     [{:.3}, {:.3}] m: there is no direct light to remove",
                    g.t0,
                    g.t0 + basis.window
                ),
            ));
        }
        Ok((basis, tab))
    }

    /// The gate method's model ([`LeakMethod::Gate`]) without reading the capture: it uses
    /// the timing of the returns only, so each row is corrected on its own (a part of a scan
    /// split by rows is corrected exactly as in one pass). [`DirectModel::explained`] is 0
    /// until measured ([`GateEnergy`]).
    ///
    /// # Errors
    /// As [`DirectModel::fit`] before its pass over the data (empty `points`, no return in
    /// the window); configuration errors.
    pub fn gate(
        g: &Geometry,
        points: &[Point],
        cell: f64,
        wave: &Wave,
        opts: &LeakOptions,
    ) -> Result<Self> {
        let (basis, _) = Self::check(g, points, wave)?;
        Ok(Self {
            geometry: g.clone(),
            points: points.to_vec(),
            rho: Vec::new(),
            basis,
            explained: 0.0,
            gate: Some(opts.cells * cell + 3.0 * g.dt),
            seconds: 0.0,
        })
    }

    /// Fits the model over the voxels `points` (Γ) to the capture `src` (one pass over the
    /// rows), with the carrier and envelope of `wave` on this capture.
    ///
    /// # Errors
    /// [`Error::Argument`] (`leak_correct`) when `points` is empty, when no 3-vertex return
    /// of any point falls in the capture's window, or when the capture holds no light at those
    /// returns; configuration and read errors.
    pub fn fit(
        src: &mut dyn RowSource,
        points: &[Point],
        cell: f64,
        wave: &Wave,
        opts: &LeakOptions,
        exec: Exec<'_>,
    ) -> Result<Self> {
        wave.refuse_cosine("the leak fit")?;
        let t = Instant::now();
        let g = src.geometry().clone();
        if opts.method == LeakMethod::Gate {
            let mut model = Self::gate(&g, points, cell, wave, opts)?;
            let bar = Pass::start(exec, "leak gate", g.lasers.len());
            let mut energy = GateEnergy::default();
            // Batches of rows: read (in parallel where the source can), then each row's
            // windows cut and its energy measured in parallel, the energies added in row order.
            let batch = row_batch();
            let mut rows: Vec<(Point, Vec<f32>)> = Vec::new();
            for start in (0..g.lasers.len()).step_by(batch) {
                let end = (start + batch).min(g.lasers.len());
                rows.resize_with(end - start, || ([0.0; 3], Vec::new()));
                {
                    let kind = if src.reads_in_parallel() {
                        Kind::Parallel
                    } else {
                        Kind::Serial
                    };
                    let _t = timings::section("read rows", kind);
                    src.read_rows(start, &mut rows)?;
                }
                let _t = timings::section("leak windows", Kind::Parallel);
                let per_row: Vec<GateEnergy> = rows
                    .par_iter()
                    .enumerate()
                    .map(|(i, (_, row))| {
                        let mut kept = row.clone();
                        model.subtract_row(start + i, &mut kept);
                        let mut e = GateEnergy::default();
                        e.add(row, &kept);
                        e
                    })
                    .collect();
                for e in per_row {
                    energy.total += e.total;
                    energy.cut += e.cut;
                }
                bar.advance(end - start);
            }
            drop(bar);
            model.explained = energy.explained()?;
            model.seconds = t.elapsed().as_secs_f64();
            return Ok(model);
        }
        let (basis, tab) = Self::check(&g, points, wave)?;
        let pts = points;
        let v_n = pts.len();
        let zero = Complex64::new(0.0, 0.0);
        // Pass over the data: rhs = Aᴴ b, energy = ‖b‖².
        let ks = g.spads_per_row();
        let bar = Pass::start(exec, "leak fit", g.lasers.len());
        let mut rhs = vec![zero; v_n];
        let mut energy = 0.0;
        let batch = row_batch();
        let mut rows: Vec<(usize, Vec<f32>)> = Vec::new();
        for start in (0..g.lasers.len()).step_by(batch) {
            let end = (start + batch).min(g.lasers.len());
            rows.resize_with(end - start, || (0, Vec::new()));
            for (l, (i, hist)) in (start..end).zip(rows.iter_mut()) {
                *i = l;
                src.read_row(l, hist)?;
            }
            let (y, e) = rows
                .par_iter()
                .fold(
                    || (vec![zero; v_n], 0.0, Work::new(&basis), Vec::new()),
                    |(mut y, mut e, mut work, mut b), (l, hist)| {
                        b.resize(ks * basis.nc, zero);
                        e += demodulate(&g, &basis, hist, &mut b);
                        apply_row(&g, &basis, &tab, pts, *l, &[], Some(&b), &mut work, &mut y);
                        (y, e, work, b)
                    },
                )
                .map(|(y, e, _, _)| (y, e))
                .reduce(
                    || (vec![zero; v_n], 0.0),
                    |(mut a, ea), (b, eb)| {
                        a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                        (a, ea + eb)
                    },
                );
            rhs.iter_mut().zip(&y).for_each(|(x, y)| *x += y);
            energy += e;
            bar.advance(end - start);
        }
        drop(bar);
        let project = |y: &mut [Complex64]| {
            if !opts.complex {
                y.iter_mut().for_each(|z| z.im = 0.0);
            }
        };
        project(&mut rhs);
        if energy.is_nan() || energy <= 0.0 || rhs.iter().all(|z| *z == zero) {
            return Err(Error::arg(
                "leak_correct",
                "the capture holds no light at the direct (3-vertex) return times of Γ's voxels: \
                 there is no direct light to remove",
            ));
        }
        let normal = |p: &[Complex64]| -> Vec<Complex64> {
            let mut y = (0..g.lasers.len())
                .into_par_iter()
                .fold(
                    || (vec![zero; v_n], Work::new(&basis)),
                    |(mut y, mut work), l| {
                        apply_row(&g, &basis, &tab, pts, l, p, None, &mut work, &mut y);
                        (y, work)
                    },
                )
                .map(|(y, _)| y)
                .reduce(
                    || vec![zero; v_n],
                    |mut a, b| {
                        a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                        a
                    },
                );
            project(&mut y);
            y
        };
        // CGNR from 0.
        let mut x = vec![zero; v_n];
        let mut r = rhs.clone();
        let mut p = r.clone();
        let mut rr = dot(&r, &r);
        let rr0 = rr;
        let bar = Pass::start(exec, "leak fit (iterations)", opts.iterations);
        for _ in 0..opts.iterations {
            if rr.is_nan() || rr <= 1e-30 * rr0 {
                break;
            }
            let q = normal(&p);
            let pq = dot(&p, &q);
            if pq.is_nan() || pq <= 0.0 {
                break;
            }
            let alpha = rr / pq;
            x.iter_mut().zip(&p).for_each(|(xi, pi)| *xi += alpha * pi);
            r.iter_mut().zip(&q).for_each(|(ri, qi)| *ri -= alpha * qi);
            let rr_new = dot(&r, &r);
            let beta = rr_new / rr;
            rr = rr_new;
            p.iter_mut()
                .zip(&r)
                .for_each(|(pi, ri)| *pi = ri + beta * *pi);
            bar.advance(1);
        }
        drop(bar);
        let nx = normal(&x);
        let resid = energy - 2.0 * dot(&x, &rhs) + dot(&x, &nx);
        Ok(Self {
            geometry: g,
            points: pts.to_vec(),
            rho: x,
            basis,
            explained: (1.0 - resid / energy).clamp(0.0, 1.0),
            gate: None,
            seconds: t.elapsed().as_secs_f64(),
        })
    }

    /// The points the model scatters from.
    pub fn points(&self) -> &[Point] {
        &self.points
    }

    /// Renders the model's histograms of laser row `l` into `out` (`spads_per_row·Nt`,
    /// SPAD-major), **subtracting** them from what `out` holds.
    pub fn subtract_row(&self, l: usize, out: &mut [f32]) {
        let g = &self.geometry;
        let basis = &self.basis;
        let tab_row = laser_legs(g, basis, &self.points, l);
        let nt = g.nt;
        let sp = basis.sigma_p / g.dt; // bins
        let r = (4.0 * sp).ceil() as i64;
        let norm = 1.0 / (sp * (2.0 * std::f64::consts::PI).sqrt());
        let inv = 0.5 / (sp * sp);
        let rot = Complex64::from_polar(1.0, basis.omega * g.dt);
        let spads: Vec<usize> = row_spads(g, l).collect();
        if let Some(half) = self.gate {
            out.par_chunks_mut(nt).zip(spads).for_each(|(h, s)| {
                for (v, &(tl, _)) in tab_row.iter().enumerate() {
                    let (d, _) = leg(g.spads[s], self.points[v]);
                    let tau = tl + d + basis.d4[s];
                    let lo = ((tau - half) / g.dt).ceil().max(0.0);
                    let hi = ((tau + half) / g.dt).floor().min(nt as f64 - 1.0);
                    if lo <= hi {
                        h[lo as usize..=hi as usize]
                            .iter_mut()
                            .for_each(|x| *x = 0.0);
                    }
                }
            });
            return;
        }
        out.par_chunks_mut(nt).zip(spads).for_each(|(h, s)| {
            let mut acc = vec![0.0f64; nt];
            for (v, &rho) in self.rho.iter().enumerate() {
                if rho == Complex64::new(0.0, 0.0) {
                    continue;
                }
                let (tl, al) = tab_row[v];
                let (d, f) = leg(g.spads[s], self.points[v]);
                let ts = d + basis.d4[s];
                let a = al * f;
                let tau = tl + ts;
                if a == 0.0 || !(0.0..=basis.window).contains(&tau) {
                    continue;
                }
                let x = tau / g.dt;
                let n0 = x.round() as i64;
                let lo = (n0 - r).max(0);
                let hi = (n0 + r).min(nt as i64 - 1);
                if lo > hi {
                    continue;
                }
                // 2·a·Re[ρ e^{iω0(t_n − τ)}]·g(t_n − τ), g unit-sum sampled Gaussian.
                let mut z = 2.0
                    * a
                    * norm
                    * rho
                    * Complex64::from_polar(1.0, basis.omega * (lo as f64 - x) * g.dt);
                for n in lo..=hi {
                    let u = n as f64 - x;
                    acc[n as usize] += z.re * (-u * u * inv).exp();
                    z *= rot;
                }
            }
            for (o, a) in h.iter_mut().zip(&acc) {
                *o -= *a as f32;
            }
        });
    }
}

/// A [`RowSource`] that returns `H − H_d`: the capture with the fitted direct light removed,
/// row by row (nothing held but one row).
pub struct LeakCorrected<'a> {
    src: &'a mut dyn RowSource,
    model: &'a DirectModel,
    /// The energy removed from the rows read, and a copy of the last raw row (when measuring).
    energy: Option<(GateEnergy, Vec<f32>)>,
}

impl<'a> LeakCorrected<'a> {
    /// Wraps `src` with the model fitted to it.
    pub fn new(src: &'a mut dyn RowSource, model: &'a DirectModel) -> Self {
        Self {
            src,
            model,
            energy: None,
        }
    }

    /// As [`LeakCorrected::new`], also summing the energy the gate removes from the rows
    /// read ([`LeakCorrected::energy`]; one row copy per read).
    pub fn measuring(src: &'a mut dyn RowSource, model: &'a DirectModel) -> Self {
        Self {
            src,
            model,
            energy: Some((GateEnergy::default(), Vec::new())),
        }
    }

    /// The energy removed so far (when measuring).
    pub fn energy(&self) -> Option<GateEnergy> {
        self.energy.as_ref().map(|(e, _)| *e)
    }
}

impl RowSource for LeakCorrected<'_> {
    fn geometry(&self) -> &Geometry {
        self.src.geometry()
    }

    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        let x = self.src.read_row(l, out)?;
        match &mut self.energy {
            Some((e, raw)) => {
                raw.clone_from(out);
                self.model.subtract_row(l, out);
                e.add(raw, out);
            }
            None => self.model.subtract_row(l, out),
        }
        Ok(x)
    }

    fn read_rows(&mut self, first: usize, out: &mut [(Point, Vec<f32>)]) -> Result<()> {
        if self.energy.is_some() {
            // Measuring: the energies summed row by row, in order.
            for (l, (x, h)) in (first..).zip(out.iter_mut()) {
                *x = self.read_row(l, h)?;
            }
            return Ok(());
        }
        self.src.read_rows(first, out)?;
        let model = self.model;
        out.par_iter_mut()
            .enumerate()
            .for_each(|(i, (_, h))| model.subtract_row(first + i, h));
        Ok(())
    }

    fn reads_in_parallel(&self) -> bool {
        self.energy.is_none()
    }

    fn rows(&self) -> std::ops::Range<usize> {
        self.src.rows()
    }
}
