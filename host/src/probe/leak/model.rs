//! The one-bounce point-scatterer model of the leak fit and the gate: the carrier basis, the
//! voxel–SPAD tables, the returns and the demodulated histograms (see the parent module).

use crate::error::Result;
use crate::io::capture::Geometry;
use crate::probe::wave::Wave;
use num_complex::Complex64;
use rayon::prelude::*;
use vltm_kernel::Point;
use vltm_kernel::geometry::dist64;

/// Carrier, envelopes and the coarse time grid of the fit.
#[derive(Clone, Debug)]
pub(super) struct Basis {
    pub(super) omega: f64,
    pub(super) sigma: f64,
    pub(super) sigma_p: f64,
    pub(super) sigma_m: f64,
    /// Coarse step (σ/2) and first coarse time (relative to t0), number of samples.
    pub(super) h: f64,
    pub(super) c0: f64,
    pub(super) nc: usize,
    /// Half window in coarse samples of a model return.
    pub(super) k: usize,
    /// Per-laser factor (the physical laser's falloff when the probes compensate it).
    pub(super) laser_scale: Vec<f64>,
    pub(super) d1: Vec<f64>,
    pub(super) d4: Vec<f64>,
    pub(super) window: f64,
}

/// Voxel–SPAD tables: `d_vs + d4_s` and `cos_s / d_vs²`, `[v][s]`.
#[derive(Clone, Debug)]
pub(super) struct SpadTables {
    pub(super) t: Vec<f32>,
    pub(super) g: Vec<f32>,
    pub(super) ks: usize,
}

/// Leg from a wall spot to a voxel: (distance, cos at the wall / d²).
pub(super) fn leg(spot: Point, v: Point) -> (f64, f64) {
    let p = v.map(f64::from);
    let d = dist64(&spot, &p);
    if d.is_nan() || d <= 0.0 {
        return (d, 0.0);
    }
    let cos = ((p[2] - f64::from(spot[2])) / d).max(0.0);
    (d, cos / (d * d))
}

impl Basis {
    pub(super) fn new(g: &Geometry, wave: &Wave) -> Result<Self> {
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
    pub(super) fn envelope(&self, tau: f64, w: &mut [f64]) -> usize {
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
    pub(super) fn new(g: &Geometry, pts: &[Point], basis: &Basis) -> Self {
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
pub(super) fn laser_legs(g: &Geometry, basis: &Basis, pts: &[Point], l: usize) -> Vec<(f64, f64)> {
    let x = g.lasers[l];
    pts.iter()
        .map(|&v| {
            let (d, f) = leg(x, v);
            (basis.d1[l] + d - g.t0, f * basis.laser_scale[l])
        })
        .collect()
}

/// The SPADs of row `l` (the row's own SPAD for paired and confocal captures).
pub(super) fn row_spads(g: &Geometry, l: usize) -> std::ops::Range<usize> {
    if g.confocal {
        l..l + 1
    } else {
        0..g.spads.len()
    }
}

/// The per-(laser, SPAD, voxel) return: time relative to t0 and amplitude, or `None` outside
/// the window.
#[inline]
pub(super) fn ret(
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
pub(super) struct Work {
    pub(super) m: Vec<Complex64>,
    pub(super) w: Vec<f64>,
}

impl Work {
    pub(super) fn new(basis: &Basis) -> Self {
        Self {
            m: vec![Complex64::new(0.0, 0.0); basis.nc],
            w: vec![0.0; 2 * basis.k + 1],
        }
    }
}

/// The fit's operator over one row: `y += A_lᴴ (A_l p)` (`b = None`) or `y += A_lᴴ b_l`
/// (the demodulated row `b`, `Ks × nc`).
#[allow(clippy::too_many_arguments)]
pub(super) fn apply_row(
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
pub(super) fn ret_any(
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
pub(super) fn demodulate(g: &Geometry, basis: &Basis, row: &[f32], out: &mut [Complex64]) -> f64 {
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

pub(super) fn dot(a: &[Complex64], b: &[Complex64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x.conj() * y).re).sum()
}
