//! Rendering: a validated scene prepared for rows ([`SceneSource`], a [`RowSource`]), the
//! whole capture in parallel ([`Scene::render`]), paths of 3 to 5 vertices with the pulse
//! integrated over each time bin.

use std::path::Path;

use rayon::prelude::*;
use vltm_kernel::Point;

use super::objects::*;
use super::scene::*;
use crate::budget;
use crate::error::Result;
use crate::exec::{Exec, Pass};
use crate::io::capture::{Capture, Geometry, RowSource, check_row};

impl Scene {
    /// Validates the scene and precomputes what rendering rows needs (per-point distances and
    /// factors to every laser and SPAD spot). Use it to stream many rows.
    ///
    /// # Errors
    /// As [`Scene::validate`] (errors name `<scene>`).
    pub fn source(&self) -> Result<SceneSource> {
        self.validate(Path::new(IN_CODE))?;
        self.check_memory()?;
        Ok(SceneSource::new(self))
    }

    /// Checks what rendering holds at once against the memory budget: the capture, the
    /// per-point leg tables to every spot, one row accumulator per thread, and the pulse on the
    /// bins and on the fine grid.
    ///
    /// # Errors
    /// [`crate::Error::Memory`] naming the sizes.
    fn check_memory(&self) -> Result<()> {
        let s = &self.setup;
        let kl = s.lasers.shape()[0].saturating_mul(s.lasers.shape()[1]);
        let ks = match (&s.spads, s.one_per_row()) {
            (_, true) => 1,
            (Some(a), false) => a.shape()[0].saturating_mul(a.shape()[1]),
            (None, false) => 0,
        };
        let points = self
            .objects
            .iter()
            .fold(0usize, |n, o| n.saturating_add(o.sample_count()));
        let values = kl.saturating_mul(ks).saturating_mul(s.nt);
        let threads = rayon::current_num_threads() as u128;
        let pulse = (6.0 * self.pulse_sigma() / s.dt * (1.0 + FINE as f64)).ceil() as u128;
        let mut plan = budget::Plan::new();
        plan.add(
            format!("the capture ({} f32)", budget::count(values as u128)),
            budget::bytes(values, 4),
        )
        .add(
            "the leg tables of every surface sample",
            budget::bytes(points, 16 * (kl as u128 + ks as u128)),
        )
        .add(
            format!("{threads} row accumulators (one per thread, f64)"),
            budget::bytes(ks.saturating_mul(s.nt), 8 * threads),
        )
        .add("the sampled pulse", budget::bytes(pulse, 8));
        plan.check(|| {
            format!(
                "rendering {} lasers × {} SPADs × {} bins and {points} surface samples",
                budget::count(kl as u128),
                budget::count(ks as u128),
                budget::count(s.nt as u128),
            )
        })
    }

    /// Renders the whole capture (rows in parallel), with noise if `noise` is set.
    ///
    /// # Errors
    /// As [`Scene::validate`] (errors name `<scene>`).
    pub fn render(&self) -> Result<Capture> {
        self.render_with(Exec::default())
    }

    /// [`Scene::render`], reporting the rendered laser rows to `exec.progress` (label
    /// `simulate`).
    ///
    /// # Errors
    /// As [`Scene::render`].
    pub fn render_with(&self, exec: Exec<'_>) -> Result<Capture> {
        let src = self.source()?;
        let geometry = src.geometry.clone();
        let row_len = geometry.spads_per_row() * geometry.nt;
        let mut data = vec![0.0f32; geometry.lasers.len() * row_len];
        let bar = Pass::start(exec, "simulate", geometry.lasers.len());
        data.par_chunks_mut(row_len).enumerate().for_each_init(
            Scratch::default,
            |scratch, (l, out)| {
                src.tables.row(l, scratch, out);
                bar.advance(1);
            },
        );
        drop(bar);
        if let Some(noise) = &self.noise {
            noise.apply(&mut data, row_len)?;
        }
        Capture::new(geometry, data, Path::new(IN_CODE))
    }

    /// Renders laser row `l` noise-free into `out` (resized to `spads_per_row·nt`, SPAD-major)
    /// and returns the laser spot. Precomputes the scene each call: to stream many rows use
    /// [`Scene::source`].
    ///
    /// # Errors
    /// As [`Scene::validate`]; [`Error::Argument`](crate::Error::Argument) if `l` is not a
    /// laser row.
    pub fn render_row(&self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        self.source()?.read_row(l, out)
    }
}

// ---------------------------------------------------------------------------------------------
// rendering
// ---------------------------------------------------------------------------------------------

/// A validated scene prepared for rendering rows: implements [`RowSource`] (noise-free).
#[derive(Clone, Debug)]
pub struct SceneSource {
    pub(super) geometry: Geometry,
    pub(super) tables: Tables,
    pub(super) scratch: Scratch,
}

impl SceneSource {
    fn new(scene: &Scene) -> Self {
        let geometry = scene.geometry();
        let tables = Tables::new(scene, &geometry);
        Self {
            geometry,
            tables,
            scratch: Scratch::default(),
        }
    }

    /// Number of surface sample points.
    pub fn points(&self) -> usize {
        self.tables.pts.len()
    }
}

impl RowSource for SceneSource {
    fn geometry(&self) -> &Geometry {
        &self.geometry
    }

    fn read_row(&mut self, l: usize, out: &mut Vec<f32>) -> Result<Point> {
        check_row(l, self.geometry.lasers.len())?;
        out.clear();
        out.resize(self.geometry.spads_per_row() * self.geometry.nt, 0.0);
        self.tables.row(l, &mut self.scratch, out);
        Ok(self.geometry.lasers[l])
    }
}

/// Per-thread scratch of the row renderer.
#[derive(Clone, Debug, Default)]
pub(super) struct Scratch {
    /// Row accumulator, `ns × nt`, f64.
    acc: Vec<f64>,
    /// Light arriving at each point after two bounces: (time, amplitude incl. k of the point).
    second: Vec<Vec<(f64, f64)>>,
    /// Light arriving at the current end point.
    arrivals: Vec<(f64, f64)>,
    /// Paths arriving at the current end point pre-summed on the fine grid: (u0, F).
    fine: (i64, Vec<f64>),
}

/// Sampled Gaussian pulse (sim.py `_deposit`) on a grid of unit spacing: the histogram bins,
/// or the fine grid of [`FINE`] points per bin.
#[derive(Clone, Debug)]
pub(super) struct Pulse {
    /// σ in grid steps.
    pub(super) s: f64,
    /// 1/s².
    pub(super) inv_s2: f64,
    /// Peak weight (1/(σ_bins·√(2π)) on both grids: unit sum over histogram bins).
    pub(super) norm: f64,
    /// Half window in grid steps: ⌈6s⌉ + 1.
    pub(super) r: usize,
    /// `c[k] = exp(−(2k+1)/(2s²))`: ratio of neighbouring weights (recurrence).
    pub(super) c: Vec<f64>,
}

impl Pulse {
    pub(super) fn new(s: f64, norm: f64) -> Self {
        let inv_s2 = 1.0 / (s * s);
        let r = (6.0 * s).ceil() as usize + 1;
        let c = (0..=r)
            .map(|k| (-((2 * k + 1) as f64) * 0.5 * inv_s2).exp())
            .collect();
        Self {
            s,
            inv_s2,
            norm,
            r,
            c,
        }
    }

    /// Adds `amp·norm·exp(−½((n − x)/s)²)` into `h[n]` for `n = round(x) ± r` (inside `h`).
    #[inline]
    pub(super) fn deposit(&self, h: &mut [f64], x: f64, amp: f64) {
        let nt = h.len() as i64;
        let n0 = x.round_ties_even();
        let rf = self.r as f64;
        if !(n0 + rf >= 0.0 && n0 - rf < nt as f64) {
            return; // outside the window (or NaN)
        }
        let f = x - n0; // in [−½, ½]
        let n0 = n0 as i64;
        let r = self.r as i64;
        let a = amp * self.norm;
        if self.s >= 0.5 {
            // w_k = a·exp(−½(k − f)²/s²) by recurrence: w_{k+1} = w_k·c_k·e^{f/s²},
            // w_{−(m+1)} = w_{−m}·c_m·e^{−f/s²}. Every factor is bounded for s ≥ ½.
            let w0 = a * (-0.5 * f * f * self.inv_s2).exp();
            let up = (f * self.inv_s2).exp();
            let down = 1.0 / up;
            let mut w = w0;
            for k in 0..=r {
                let n = n0 + k;
                if n >= nt {
                    break;
                }
                if n >= 0 {
                    h[n as usize] += w;
                }
                w *= self.c[k as usize] * up;
            }
            let mut w = w0;
            for m in 0..r {
                w *= self.c[m as usize] * down;
                let n = n0 - 1 - m;
                if n < 0 {
                    break;
                }
                if n < nt {
                    h[n as usize] += w;
                }
            }
        } else {
            for k in -r..=r {
                let n = n0 + k;
                if (0..nt).contains(&n) {
                    let z = k as f64 - f;
                    h[n as usize] += a * (-0.5 * z * z * self.inv_s2).exp();
                }
            }
        }
    }
}

/// Fine-grid points per histogram bin for paths pre-summed at their end point.
pub(super) const FINE: i64 = 32;

/// How the paths arriving at one end point are deposited (see [`Tables::row`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Mode {
    /// Choose per end point by operation count.
    Auto,
    /// One sampled pulse per path and SPAD (exact sim.py `_deposit`).
    Direct,
    /// Pre-summed on the fine grid, interpolated per SPAD (pulses of σ ≥ 1 bin only).
    #[cfg_attr(not(test), allow(dead_code))]
    Fine,
}

/// Precomputed per-point quantities.
#[derive(Clone, Debug)]
pub(super) struct Tables {
    pub(super) pts: Vec<[f64; 3]>,
    pub(super) nrm: Vec<Option<[f64; 3]>>,
    /// albedo·area/π.
    pub(super) k: Vec<f64>,
    pub(super) group: Vec<usize>,
    /// `[l][p]`: `d1_l + |x_l − p| − t0`.
    pub(super) tl: Vec<f64>,
    /// `[l][p]`: laser-leg factor (cosines)/d².
    pub(super) gl: Vec<f64>,
    /// `[p][s]`: `|p − x_s| + d4_s`.
    pub(super) ts: Vec<f64>,
    /// `[p][s]`: SPAD-leg factor (cosines)/d².
    pub(super) gs: Vec<f64>,
    pub(super) ks: usize,
    pub(super) confocal: bool,
    pub(super) cosines: bool,
    pub(super) direct: bool,
    pub(super) four: bool,
    pub(super) five: bool,
    pub(super) nt: usize,
    pub(super) inv_dt: f64,
    /// The pulse on the histogram bins.
    pub(super) pulse: Pulse,
    /// The pulse on the fine grid (`None` if σ < 1 bin: then every deposit is direct).
    pub(super) fine: Option<Pulse>,
    pub(super) mode: Mode,
}

impl Tables {
    pub(super) fn new(scene: &Scene, geo: &Geometry) -> Self {
        let samples = scene.sample_points();
        let pts: Vec<[f64; 3]> = samples.iter().map(|p| p.position).collect();
        let nrm: Vec<Option<[f64; 3]>> = samples.iter().map(|p| p.normal).collect();
        let k = samples
            .iter()
            .map(|p| p.albedo * p.area / std::f64::consts::PI)
            .collect();
        let group = samples.iter().map(|p| p.group).collect();
        let cosines = scene.cosines;
        let f64s = |v: &[Point]| -> Vec<[f64; 3]> { v.iter().map(|p| p.map(f64::from)).collect() };
        let (lasers, spads) = (f64s(&geo.lasers), f64s(&geo.spads));
        let dist = |a: [f64; 3], b: [f64; 3]| dot(sub(a, b), sub(a, b)).sqrt();
        let d1: Vec<f64> = lasers
            .iter()
            .map(|&x| {
                if geo.legs_in_time {
                    dist(x, geo.laser_origin)
                } else {
                    0.0
                }
            })
            .collect();
        let d4: Vec<f64> = spads
            .iter()
            .map(|&x| {
                if geo.legs_in_time {
                    dist(x, geo.sensor_origin)
                } else {
                    0.0
                }
            })
            .collect();
        // Leg wall spot x ↔ point p: distance and factor cos_wall·cos_p/d² (sim.py gl, gs).
        let leg = |x: [f64; 3], p: usize| -> (f64, f64) {
            let v = sub(pts[p], x);
            let d2 = dot(v, v);
            let d = d2.sqrt();
            if d2.is_nan() || d2 <= 0.0 {
                return (d, 0.0);
            }
            let mut g = 1.0 / d2;
            if cosines {
                g *= (v[2] / d).max(0.0);
                if let Some(n) = nrm[p] {
                    g *= (-dot(n, v) / d).max(0.0);
                }
            }
            (d, g)
        };
        let np = pts.len();
        let (mut tl, mut gl) = (vec![0.0; lasers.len() * np], vec![0.0; lasers.len() * np]);
        for (l, &x) in lasers.iter().enumerate() {
            for p in 0..np {
                let (d, g) = leg(x, p);
                tl[l * np + p] = d1[l] + d - geo.t0;
                gl[l * np + p] = g;
            }
        }
        let ks = spads.len();
        let (mut ts, mut gs) = (vec![0.0; ks * np], vec![0.0; ks * np]);
        for p in 0..np {
            for (s, &x) in spads.iter().enumerate() {
                let (d, g) = leg(x, p);
                ts[p * ks + s] = d + d4[s];
                gs[p * ks + s] = g;
            }
        }
        let s = scene.pulse_sigma() / geo.dt;
        let norm = 1.0 / (s * (2.0 * std::f64::consts::PI).sqrt());
        let (direct, indirect) = match scene.bounces {
            Bounces::All => (true, true),
            Bounces::Direct => (true, false),
            Bounces::Indirect => (false, true),
        };
        Self {
            pts,
            nrm,
            k,
            group,
            tl,
            gl,
            ts,
            gs,
            ks,
            confocal: geo.confocal,
            cosines,
            direct,
            four: indirect && scene.max_vertices >= 4,
            five: indirect && scene.max_vertices >= 5,
            nt: geo.nt,
            inv_dt: 1.0 / geo.dt,
            pulse: Pulse::new(s, norm),
            fine: (s >= 1.0).then(|| Pulse::new(s * FINE as f64, norm)),
            mode: Mode::Auto,
        }
    }

    /// The segment `i → j` between points of different objects: `(d_ij, factor/d_ij²)` with the
    /// cosines at both ends, or `None` if it carries no light.
    #[inline]
    pub(super) fn link(&self, i: usize, j: usize) -> Option<(f64, f64)> {
        if self.group[i] == self.group[j] {
            return None;
        }
        let v = sub(self.pts[j], self.pts[i]);
        let d2 = dot(v, v);
        if d2.is_nan() || d2 <= 0.0 {
            return None;
        }
        let d = d2.sqrt();
        let mut g = 1.0 / d2;
        if self.cosines {
            if let Some(n) = self.nrm[i] {
                g *= (dot(n, v) / d).max(0.0);
            }
            if let Some(n) = self.nrm[j] {
                g *= (-dot(n, v) / d).max(0.0);
            }
        }
        (g > 0.0).then_some((d, g))
    }

    /// Renders laser row `l` (noise-free) into `out` (`spads_per_row·nt`).
    ///
    /// For every end point `j` (the last scattering point) the paths arriving there are
    /// collected as (time from the laser spot to `j`, amplitude up to `j`); each SPAD then sees
    /// them shifted by `|j − x_s| (+ d4)` and scaled by its leg factor.
    pub(super) fn row(&self, l: usize, scratch: &mut Scratch, out: &mut [f32]) {
        let nt = self.nt;
        let np = self.pts.len();
        let spads = if self.confocal { l..l + 1 } else { 0..self.ks };
        let Scratch {
            acc,
            second,
            arrivals,
            fine,
        } = scratch;
        acc.clear();
        acc.resize(spads.len() * nt, 0.0);
        let tl = &self.tl[l * np..(l + 1) * np];
        let gl = &self.gl[l * np..(l + 1) * np];
        // Light leaving the laser spot and scattered once at p: (time, k_p·g_lp).
        let first = |p: usize| (tl[p], self.k[p] * gl[p]);
        // Light arriving at b after a → b: (time, k_a·g_la·g_ab·k_b) over every a.
        let push_second = |b: usize, into: &mut Vec<(f64, f64)>| {
            for a in 0..np {
                let (t, amp) = first(a);
                if amp == 0.0 {
                    continue;
                }
                if let Some((d, g)) = self.link(a, b) {
                    into.push((t + d, amp * g * self.k[b]));
                }
            }
        };
        if self.five {
            second.resize_with(np, Vec::new);
            for (b, list) in second.iter_mut().enumerate() {
                list.clear();
                push_second(b, list);
            }
        }
        for j in 0..np {
            arrivals.clear();
            if self.direct {
                let (t, amp) = first(j);
                if amp != 0.0 {
                    arrivals.push((t, amp));
                }
            }
            if self.five {
                arrivals.extend_from_slice(&second[j]);
                for (b, list) in second.iter().enumerate() {
                    if list.is_empty() {
                        continue;
                    }
                    if let Some((d, g)) = self.link(b, j) {
                        let f = g * self.k[j];
                        arrivals.extend(list.iter().map(|&(t, amp)| (t + d, amp * f)));
                    }
                }
            } else if self.four {
                push_second(j, arrivals);
            }
            if arrivals.is_empty() {
                continue;
            }
            let ts = &self.ts[j * self.ks..(j + 1) * self.ks];
            let gs = &self.gs[j * self.ks..(j + 1) * self.ks];
            if self.presum(arrivals, spads.len(), fine) {
                let (u0, fine) = (fine.0, &fine.1);
                let len = fine.len() as i64;
                for (h, s) in acc.chunks_exact_mut(nt).zip(spads.clone()) {
                    let g = gs[s];
                    if g != 0.0 {
                        interpolate(h, fine, u0, len, ts[s] * self.inv_dt, g);
                    }
                }
            } else {
                for (h, s) in acc.chunks_exact_mut(nt).zip(spads.clone()) {
                    let g = gs[s];
                    if g == 0.0 {
                        continue;
                    }
                    let t = ts[s];
                    for &(ta, amp) in arrivals.iter() {
                        self.pulse.deposit(h, (ta + t) * self.inv_dt, amp * g);
                    }
                }
            }
        }
        for (o, &a) in out.iter_mut().zip(acc.iter()) {
            *o = a as f32;
        }
    }

    /// Decides whether to pre-sum `arrivals` (for `ns` SPADs) on the fine grid and, if so,
    /// fills `fine = (u0, F)`: `F[k] = Σ_a amp_a·pulse(u0 + k/FINE − y_a)`, `y_a` the arrival
    /// time in bins, `u0` an integer bin. Pre-summing costs one fine-grid pulse per path, then
    /// a 4-tap interpolation per bin and SPAD, instead of one pulse per path and SPAD.
    pub(super) fn presum(
        &self,
        arrivals: &[(f64, f64)],
        ns: usize,
        fine: &mut (i64, Vec<f64>),
    ) -> bool {
        let Some(fp) = &self.fine else { return false };
        if self.mode == Mode::Direct || arrivals.len() < 2 {
            return false;
        }
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for &(t, _) in arrivals {
            lo = lo.min(t * self.inv_dt);
            hi = hi.max(t * self.inv_dt);
        }
        let margin = self.pulse.r as f64 + 3.0;
        let span = hi - lo + 2.0 * margin + 1.0; // bins
        if !(span.is_finite() && span * (FINE as f64) < (1u64 << 20) as f64) {
            return false;
        }
        let (m, w, ns) = (
            arrivals.len() as f64,
            (2 * self.pulse.r + 1) as f64,
            ns as f64,
        );
        let direct = m * ns * (2.0 * w + 30.0);
        let presum = m * (2.0 * w * FINE as f64 + 30.0) + ns * (span + w) * 10.0;
        if self.mode == Mode::Auto && presum >= direct {
            return false;
        }
        let u0 = (lo - margin).floor() as i64;
        let len = ((hi + margin).ceil() as i64 - u0) * FINE + 1;
        fine.0 = u0;
        fine.1.clear();
        fine.1.resize(len as usize, 0.0);
        for &(t, amp) in arrivals {
            fp.deposit(
                &mut fine.1,
                (t * self.inv_dt - u0 as f64) * FINE as f64,
                amp,
            );
        }
        true
    }
}

/// Adds `g·F(n − z)` into every bin `n` of `h`, `F` sampled at `u0 + k/FINE` (length `len`),
/// by 4-point Lagrange interpolation. `z·FINE`'s fractional part is the same for every bin, so
/// the weights are computed once.
pub(super) fn interpolate(h: &mut [f64], f: &[f64], u0: i64, len: i64, z: f64, g: f64) {
    let zq = z * FINE as f64;
    if !zq.is_finite() || zq.abs() > 1e15 {
        return;
    }
    let cz = zq.ceil();
    let t = cz - zq; // in [0, 1): F at fine index k + t
    let cz = cz as i64;
    let w = [
        -t * (t - 1.0) * (t - 2.0) / 6.0 * g,
        (t + 1.0) * (t - 1.0) * (t - 2.0) / 2.0 * g,
        -(t + 1.0) * t * (t - 2.0) / 2.0 * g,
        (t + 1.0) * t * (t - 1.0) / 6.0 * g,
    ];
    // Fine index of bin n: k = (n − u0)·FINE − cz; taps k−1 ..= k+2 inside 0..len.
    let lo = (u0 + (1 + cz + FINE - 1).div_euclid(FINE)).max(0);
    let hi = (u0 + (len - 3 + cz).div_euclid(FINE)).min(h.len() as i64 - 1);
    for n in lo..=hi {
        let k = ((n - u0) * FINE - cz) as usize;
        let v = w[0] * f[k - 1] + w[1] * f[k] + w[2] * f[k + 1] + w[3] * f[k + 2];
        h[n as usize] += v;
    }
}
