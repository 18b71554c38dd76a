//! Any regular volume at FFT speed: a wall-parallel voxel grid whose x–y pitch does **not**
//! divide the wall's is computed on the FFT paths (planar, confocal) on a *support* grid that
//! does — the wall's lattice refined `k` times per axis, `h = p/k`, covering the volume plus
//! [`TAPS`] support voxels on each side — and the complex amplitude `A` is then resampled to
//! the asked voxels by a separable Kaiser-windowed sinc of [`TAPS`] taps per side. The
//! intensity `|A|²` is taken after the resampling. Axes that already sit on the support
//! lattice (within `1e-6` of a support pitch) take their support value as it is (one tap);
//! the depth axis is never resampled (each slice is its own convolution).
//!
//! # Why the amplitude can be resampled, and the error bound
//!
//! The amplitude of a voxel is a sum over (laser, SPAD, band bin) of terms
//! `w·e^{iν_j (d_L + d_S)}`, `d_L = |x_l − x_v|`, `d_S = |x_v − x_s|`. Along x, the phase of
//! a term changes at `ν_j·(sin θ_L + sin θ_S)` rad/m (θ the angle of the leg to the wall's
//! normal, projected on x): the local lateral frequency never exceeds
//!
//! ```text
//! Ω_x = 1.05·ν_max·(max sin θ_L,x + max sin θ_S,x) + 4/z_min
//! ```
//!
//! (`ν_max` the band's largest |ν_j| in rad/m of path, the sines maxed over the support box
//! and the slices, 5 % and `4/z_min` for the slow variation of the weights `w`; for a confocal
//! capture both legs go to the same wall points). With the support pitch `h`, the band
//! fraction is `β = Ω_x·h/π` (β = 1: two samples per period). The interpolator is the sinc
//! windowed by a Kaiser window of shape `π·TAPS·(1 − β)`; its worst error on a plane wave
//! `e^{iωx}`, `|ω| ≤ Ω_x`, over every fractional position, is measured when the plan is made
//! ([`tone_error`]: 64 positions × 64 frequencies; e.g. 2.2e-6 at β = 0.5, 2.4e-5 at β = 0.6,
//! 3.4e-4 at β = 0.7, 4.5e-3 at β = 0.8 with 8 taps per side). Along x and y together the
//! error on a wave is at most `e_x + e_y + e_x·e_y` ([`Resample::bound`]). The amplitude is
//! a sum of such (locally plane) waves with magnitudes bounded by the scale
//! `S = Σ_l Σ_s w·w·Σ_n |H_ls[n]|`, so the resampled amplitude is within `bound·S` of the
//! band sum at the asked voxel. The refinement `k` (1 … [`MAX_REFINE`]) is the least per
//! axis whose error is at most `MAX_ERROR/2`; when none is, the volume is not resampled and
//! the probe falls back to the lookup or band path (the reason is returned).
//!
//! `tests/proptest_fast.rs` (`resampled_volumes_match_reference_and_band`) checks random
//! off-lattice grids against the `f64` reference within `(ε + bound)·S` and against the band
//! path within `(ε_pb + bound)·S`.
//!
//! # The guard interval
//!
//! The support grid is convolved *without* the guard (the band sum, periodic in the path
//! length, is smooth in x); asked voxels with a path outside the guard are evaluated on the
//! band path as on the aligned FFT paths, so that they get exactly the band path's value.
//!
//! Cost: the FFT path on the support grid (about `k_x·k_y` times the aligned grid's slices,
//! the FFT size grown by `2·TAPS` support voxels per axis) plus `2·TAPS` complex
//! multiply-adds per (support x row, asked y) and per asked voxel. Memory: the support
//! grid's amplitudes (16 bytes per support voxel) and one intermediate of
//! `support x × asked y × slices` amplitudes.

use crate::io::capture::Geometry;
use crate::probe::fast::lattice::wall_lattice;
use crate::volume::Volume;
use num_complex::Complex64;
use rayon::prelude::*;
use vltm_kernel::{Config, Point};

/// Half-width of the interpolation kernel: taps on each side of the asked voxel.
pub const TAPS: usize = 8;

/// The resampling error accepted, relative to the scale `S` of a voxel (module docs): above
/// it the volume is not resampled.
pub const MAX_ERROR: f64 = 1e-4;

/// The largest refinement of the wall's pitch per axis (`k_x·k_y` sub-grids).
pub const MAX_REFINE: usize = 4;

/// Worst error of the Kaiser-windowed sinc interpolator (module docs) on a plane wave of band
/// fraction at most `beta` (`β = ω·h/π`), over 64 fractional positions in [0, 1) and 64
/// frequencies in [0, β] (the error is even in ω). `f64::INFINITY` for `beta ≥ 1`.
pub fn tone_error(beta: f64) -> f64 {
    if !(0.0..1.0).contains(&beta) {
        return f64::INFINITY;
    }
    let mut worst = 0.0f64;
    let mut w = [0.0; 2 * TAPS];
    // The taps' phases e^{iπbn} per frequency (they do not depend on the position).
    let phases: Vec<[Complex64; 2 * TAPS]> = (0..=64)
        .map(|ib| {
            let b = beta * ib as f64 / 64.0;
            std::array::from_fn(|t| {
                let n = t as f64 - (TAPS as f64 - 1.0);
                Complex64::from_polar(1.0, std::f64::consts::PI * b * n)
            })
        })
        .collect();
    for iu in 0..64 {
        let u = iu as f64 / 64.0;
        kernel(u, beta, &mut w);
        for (ib, ph) in phases.iter().enumerate() {
            let b = beta * ib as f64 / 64.0;
            let mut s = Complex64::new(0.0, 0.0);
            for (wt, p) in w.iter().zip(ph) {
                s += p * *wt;
            }
            let e = (Complex64::from_polar(1.0, std::f64::consts::PI * b * u) - s).norm();
            worst = worst.max(e);
        }
    }
    worst
}

/// Modified Bessel function I₀ (power series; |x| ≤ 40 here, relative error < 1e-15).
fn bessel_i0(x: f64) -> f64 {
    let q = x * x / 4.0;
    let mut term = 1.0;
    let mut sum = 1.0;
    for k in 1..200 {
        term *= q / (k * k) as f64;
        sum += term;
        if term < 1e-17 * sum {
            break;
        }
    }
    sum
}

/// The 2·TAPS weights for fractional position `u ∈ [0, 1)`: tap `t` weighs support sample
/// `i0 + t − (TAPS − 1)`, the asked point being at `i0 + u`.
fn kernel(u: f64, beta: f64, w: &mut [f64; 2 * TAPS]) {
    let width = TAPS as f64;
    let shape = std::f64::consts::PI * width * (1.0 - beta);
    let norm = bessel_i0(shape);
    for (t, wt) in w.iter_mut().enumerate() {
        let x = u - (t as f64 - (width - 1.0));
        let r = 1.0 - (x / width).powi(2);
        let sinc = if x.abs() < 1e-12 {
            1.0
        } else {
            (std::f64::consts::PI * x).sin() / (std::f64::consts::PI * x)
        };
        *wt = if r <= 0.0 {
            0.0
        } else {
            sinc * bessel_i0(shape * r.sqrt()) / norm
        };
    }
}

/// The taps of one asked coordinate along one axis: first support index and weights (one
/// weight when the coordinate sits on the support lattice).
#[derive(Clone, Debug)]
struct Taps {
    first: usize,
    w: Vec<f64>,
}

/// One axis of the plan: the support axis and the asked coordinates' taps.
#[derive(Clone, Debug)]
struct AxisPlan {
    /// First and last support coordinate (m), support points.
    lo: f64,
    hi: f64,
    n: usize,
    /// Refinement of the wall's pitch (1 on an axis where the wall has one point).
    k: usize,
    /// Interpolation error bound along this axis (0 when every coordinate is on the lattice).
    error: f64,
    taps: Vec<Taps>,
}

/// The plan of a resampled volume: the support grid the FFT path computes, and the taps
/// that take its amplitudes to the asked voxels.
#[derive(Clone, Debug)]
pub struct Resample {
    /// The support grid (a wall-parallel grid whose x–y pitch divides the wall's).
    pub support: Volume,
    axes: [AxisPlan; 2],
    /// The asked grid's shape.
    shape: [usize; 3],
}

impl Resample {
    /// Plans the resampling of `volume` (a grid) for the wall of `g` (the SPADs; a confocal
    /// capture's wall points) under `cfg`, or says why it does not apply (a point list, an
    /// irregular or tilted wall, an error bound above [`MAX_ERROR`] at every refinement).
    /// Cost O(lasers + SPADs + voxels).
    ///
    /// # Errors
    /// A one-line reason.
    pub fn new(g: &Geometry, cfg: &Config, volume: &Volume) -> Result<Self, String> {
        let axes = volume
            .axes
            .ok_or_else(|| "the volume is a point list, not a grid".to_string())?;
        let wall = if g.confocal { &g.lasers } else { &g.spads };
        let (origin, pitch, nw, wz) = wall_lattice(wall, 1e-5 * cfg.wavelength())?;
        let [_, ny, nz] = volume.shape;
        let coord = |i: usize, k: usize| -> f64 {
            let idx = match i {
                0 => (k * ny) * nz,
                _ => k * nz,
            };
            f64::from(volume.points[idx][i])
        };
        let zs: Vec<f64> = (0..nz).map(|k| f64::from(volume.points[k][2])).collect();
        let dz_min = zs
            .iter()
            .map(|z| (z - wz).abs())
            .fold(f64::INFINITY, f64::min);
        if dz_min <= 0.0 {
            return Err("a slice lies in the wall's plane".into());
        }
        let nu = {
            let span = cfg.span();
            let k_hi = cfg.k_lo() + cfg.bins() as i64 - 1;
            std::f64::consts::TAU * (cfg.k_lo().abs().max(k_hi.abs()) as f64) / span
        };
        let mut plans = Vec::with_capacity(2);
        for i in 0..2 {
            let n = volume.shape[i];
            let cs: Vec<f64> = (0..n).map(|k| coord(i, k)).collect();
            let (cmin, cmax) = cs
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &c| {
                    (a.min(c), b.max(c))
                });
            if nw[i] < 2 {
                // One wall point along this axis: any voxel pitch is exact (planar's layout).
                let exact = cs
                    .iter()
                    .enumerate()
                    .map(|(k, _)| Taps {
                        first: if cs.len() > 1 && cs[cs.len() - 1] < cs[0] {
                            n - 1 - k
                        } else {
                            k
                        },
                        w: vec![1.0],
                    })
                    .collect();
                plans.push(AxisPlan {
                    lo: cmin,
                    hi: cmax,
                    n,
                    k: 1,
                    error: 0.0,
                    taps: exact,
                });
                continue;
            }
            // The lateral band over the box grown by the widest margin (k = 1).
            let margin = TAPS as f64 * pitch[i];
            let (blo, bhi) = (cmin - margin, cmax + margin);
            let sine = |pts: &[Point]| {
                pts.iter()
                    .map(|p| {
                        let dx = (blo - f64::from(p[i]))
                            .abs()
                            .max((bhi - f64::from(p[i])).abs());
                        let dz = zs
                            .iter()
                            .map(|z| (z - f64::from(p[2])).abs())
                            .fold(f64::INFINITY, f64::min);
                        dx / (dx * dx + dz * dz).sqrt()
                    })
                    .fold(0.0, f64::max)
            };
            let s = if g.confocal {
                2.0 * sine(&g.lasers)
            } else {
                sine(&g.lasers) + sine(&g.spads)
            };
            let omega = 1.05 * nu * s + 4.0 / dz_min;
            let mut chosen = None;
            for k in 1..=MAX_REFINE {
                let h = pitch[i] / k as f64;
                let beta = omega * h / std::f64::consts::PI;
                let e = tone_error(beta);
                if e <= MAX_ERROR / 2.0 {
                    chosen = Some((k, h, beta, e));
                    break;
                }
            }
            let name = ["x", "y"][i];
            let Some((k, h, beta, e)) = chosen else {
                return Err(format!(
                    "resampling along {name} would exceed an error of {MAX_ERROR:e} of the scale even at {MAX_REFINE}× the wall's sampling (lateral frequency up to {omega:.0} rad/m, wall pitch {:.6} m)",
                    pitch[i]
                ));
            };
            // Taps per coordinate, on the support lattice origin + m·h.
            let mut raw: Vec<(i64, Vec<f64>)> = Vec::with_capacity(n);
            let mut any_off = false;
            let mut w = [0.0; 2 * TAPS];
            for &c in &cs {
                let t = (c - origin[i]) / h;
                let i0 = t.floor();
                let u = t - i0;
                if !(1e-6..=1.0 - 1e-6).contains(&u) {
                    raw.push((t.round() as i64, vec![1.0]));
                } else {
                    any_off = true;
                    kernel(u, beta, &mut w);
                    raw.push((i0 as i64 - (TAPS as i64 - 1), w.to_vec()));
                }
            }
            let lo = raw.iter().map(|r| r.0).min().unwrap_or(0);
            let hi = raw
                .iter()
                .map(|r| r.0 + r.1.len() as i64 - 1)
                .max()
                .unwrap_or(0);
            let taps = raw
                .into_iter()
                .map(|(f, w)| Taps {
                    first: (f - lo) as usize,
                    w,
                })
                .collect();
            plans.push(AxisPlan {
                lo: origin[i] + lo as f64 * h,
                hi: origin[i] + hi as f64 * h,
                n: (hi - lo + 1) as usize,
                k,
                error: if any_off { e } else { 0.0 },
                taps,
            });
        }
        let ay = plans.pop().expect("two axes");
        let ax = plans.pop().expect("two axes");
        let (sx, sy) = (ax.n, ay.n);
        let step = |a: &AxisPlan, m: usize| {
            if a.n > 1 {
                a.lo + (a.hi - a.lo) * m as f64 / (a.n - 1) as f64
            } else {
                a.lo
            }
        };
        let total = sx
            .checked_mul(sy)
            .and_then(|t| t.checked_mul(nz))
            .filter(|&t| t <= crate::volume::MAX_VOXELS)
            .ok_or_else(|| {
                format!(
                    "its support grid of {sx}×{sy}×{nz} voxels exceeds {} voxels \
                     (docs/limits.md): use a coarser grid or a smaller volume",
                    crate::volume::MAX_VOXELS
                )
            })?;
        let nz_ = zs.len();
        let points: Vec<Point> = (0..total)
            .into_par_iter()
            .map(|i| {
                let (mx, my, iz) = (i / (sy * nz_), (i / nz_) % sy, i % nz_);
                [step(&ax, mx) as f32, step(&ay, my) as f32, zs[iz] as f32]
            })
            .collect();
        let support = Volume {
            points,
            shape: [sx, sy, nz],
            axes: Some([
                [ax.lo as f32, ax.hi as f32],
                [ay.lo as f32, ay.hi as f32],
                axes[2],
            ]),
        };
        Ok(Self {
            support,
            axes: [ax, ay],
            shape: volume.shape,
        })
    }

    /// The bound of the resampling error relative to a voxel's scale `S` (module docs):
    /// `e_x + e_y + e_x·e_y`, 0 when the asked grid lies on the support lattice.
    pub fn bound(&self) -> f64 {
        let [a, b] = [self.axes[0].error, self.axes[1].error];
        a + b + a * b
    }

    /// The refinement of the wall's pitch per axis (x, y).
    pub fn refine(&self) -> [usize; 2] {
        [self.axes[0].k, self.axes[1].k]
    }

    /// Whether any asked coordinate is off the support lattice (else the support values are
    /// the asked ones, picked).
    pub fn interpolates(&self) -> bool {
        self.bound() > 0.0
    }

    /// The `--volume` SPEC of the support grid (for the user's information: the grid the FFT
    /// path computed on).
    pub fn support_spec(&self) -> String {
        let a = self.support.axes.expect("a grid");
        let s = self.support.shape;
        let f = |x: f32| {
            let t = format!("{x:.7}");
            t.trim_end_matches('0').trim_end_matches('.').to_string()
        };
        format!(
            "{}:{}:{},{}:{}:{},{}:{}:{}",
            f(a[0][0]),
            f(a[0][1]),
            s[0],
            f(a[1][0]),
            f(a[1][1]),
            s[1],
            a[2][0],
            a[2][1],
            s[2]
        )
    }

    /// Flops of [`Resample::apply`] (8 per complex multiply-add).
    pub fn flops(&self) -> f64 {
        let [nx, ny, nz] = self.shape;
        let sx = self.support.shape[0];
        (8 * 2 * TAPS * (sx * ny + nx * ny) * nz) as f64
    }

    /// The asked voxels' amplitudes (C order over the asked shape) from the support grid's
    /// (C order over [`Resample::support`]'s shape): y first, then x.
    ///
    /// # Panics
    /// If `support` is not the support grid's length.
    pub fn apply(&self, support: &[Complex64]) -> Vec<Complex64> {
        let [nx, ny, nz] = self.shape;
        let [sx, sy, _] = self.support.shape;
        assert_eq!(support.len(), sx * sy * nz, "support amplitudes");
        let zero = Complex64::new(0.0, 0.0);
        // Along y: mid[(mx·ny + iy)·nz + iz]; support x rows in parallel.
        let mut mid = vec![zero; sx * ny * nz];
        mid.par_chunks_mut(ny * nz)
            .enumerate()
            .for_each(|(mx, mid)| {
                for (iy, t) in self.axes[1].taps.iter().enumerate() {
                    let out = &mut mid[iy * nz..(iy + 1) * nz];
                    for (k, w) in t.w.iter().enumerate() {
                        let row = &support[(mx * sy + t.first + k) * nz..][..nz];
                        for (o, v) in out.iter_mut().zip(row) {
                            *o += v * *w;
                        }
                    }
                }
            });
        // Along x, asked x planes in parallel.
        let mut acc = vec![zero; nx * ny * nz];
        acc.par_chunks_mut(ny * nz)
            .zip(self.axes[0].taps.par_iter())
            .for_each(|(out, t)| {
                for (k, w) in t.w.iter().enumerate() {
                    let row = &mid[(t.first + k) * ny * nz..][..ny * nz];
                    for (o, v) in out.iter_mut().zip(row) {
                        *o += v * *w;
                    }
                }
            });
        acc
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bound table of the module docs, and its growth with β.
    #[test]
    fn tone_errors() {
        let e5 = tone_error(0.5);
        let e6 = tone_error(0.6);
        let e7 = tone_error(0.7);
        assert!(e5 < 3e-6, "{e5}");
        assert!(e6 < 3e-5, "{e6}");
        assert!(e7 < 4e-4 && e7 > e6 && e6 > e5, "{e7}");
        assert!(tone_error(1.0).is_infinite());
    }

    /// A plane wave well inside the band is resampled to within the stated bound, and a
    /// sample on the lattice is taken as it is.
    #[test]
    fn kernel_interpolates_a_plane_wave() {
        let beta = 0.55;
        let bound = tone_error(beta);
        let mut w = [0.0; 2 * TAPS];
        for &om in &[0.0, 0.3, -0.5, 0.55] {
            for iu in 1..10 {
                let u = iu as f64 / 10.0 + 0.013;
                kernel(u, beta, &mut w);
                let mut s = Complex64::new(0.0, 0.0);
                for (t, wt) in w.iter().enumerate() {
                    let n = t as f64 - (TAPS as f64 - 1.0);
                    s += Complex64::from_polar(*wt, std::f64::consts::PI * om * n);
                }
                let e = (Complex64::from_polar(1.0, std::f64::consts::PI * om * u) - s).norm();
                assert!(e <= 1.05 * bound, "ω = {om}, u = {u}: {e} > {bound}");
            }
        }
    }
}
