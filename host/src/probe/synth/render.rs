//! The three-bounce renderer of surfels: per laser row, every SPAD's histogram of every
//! cluster on a fine time grid (`SUB` samples per bin), blurred by the response and binned
//! with a delay.

use super::surfels::Surfels;
use crate::io::capture::Geometry;
use vltm_kernel::geometry::dist64;

/// Fine samples per capture bin: delays are resolved to `Δt / SUB`.
pub(super) const SUB: usize = 8;

/// Leg from a wall spot (normal `nw`) to surfel `k`: `(distance, cos_wall·cos_surfel / d²)`,
/// written as `(v·n_w)(−v·n)/d⁴` with `v = p − spot` (one square root and one division; the
/// distance as [`vltm_kernel::geometry::dist64`] computes it).
#[inline]
pub(super) fn leg(spot: [f32; 3], nw: [f64; 3], p: [f64; 3], n: [f64; 3]) -> (f64, f64) {
    let v: [f64; 3] = core::array::from_fn(|i| f64::from(spot[i]) - p[i]);
    let d2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    let d = d2.sqrt();
    if d.is_nan() || d <= 0.0 {
        return (d, 0.0);
    }
    // v points from the surfel to the spot: cos_wall = −v̂·n_w, cos_surfel = v̂·n.
    let cw = (-(v[0] * nw[0] + v[1] * nw[1] + v[2] * nw[2])).max(0.0);
    let cs = (v[0] * n[0] + v[1] * n[1] + v[2] * n[2]).max(0.0);
    (d, cw * cs / (d2 * d2))
}

/// What the renderer needs of a capture and its surfels: SPAD legs per surfel (`[s][k]`),
/// the per-laser scale (the physical laser's falloff), device legs and the fine grid.
#[derive(Clone, Debug)]
pub(super) struct Renderer {
    pub surfels: Surfels,
    /// `d_ks + d4_s` (m), `[s * K + k]`: a SPAD's surfels are contiguous.
    ts: Vec<f32>,
    /// `cos·cos / d²` of the SPAD leg, `[s * K + k]`.
    gs: Vec<f32>,
    laser_scale: Vec<f64>,
    d1: Vec<f64>,
    /// Padding of the fine grid on each side, in fine samples.
    pub pad: usize,
    /// Fine grid length: `nt·SUB + 2·pad`.
    pub nf: usize,
}

impl Renderer {
    /// Bytes of the SPAD tables for `k` surfels and `spads` SPADs.
    pub fn table_bytes(k: usize, spads: usize) -> usize {
        8 * k * spads
    }

    /// Tables for `surfels` on capture `g`; `laser_scale` per laser row; `reach` the largest
    /// delay plus blur the fine grid must hold on each side (bins).
    pub fn new(g: &Geometry, surfels: Surfels, laser_scale: Vec<f64>, reach: f64) -> Self {
        let spads = g.spads.len();
        let k_n = surfels.len();
        let leg_len = |x: &[f32; 3], o: [f64; 3]| if g.legs_in_time { dist64(x, &o) } else { 0.0 };
        let d4: Vec<f64> = g
            .spads
            .iter()
            .map(|x| leg_len(x, g.sensor_origin))
            .collect();
        let d1: Vec<f64> = g
            .lasers
            .iter()
            .map(|x| leg_len(x, g.laser_origin))
            .collect();
        let mut ts = vec![0.0f32; k_n * spads];
        let mut gs = vec![0.0f32; k_n * spads];
        use rayon::prelude::*;
        ts.par_chunks_mut(k_n.max(1))
            .zip(gs.par_chunks_mut(k_n.max(1)))
            .enumerate()
            .for_each(|(s, (t, w))| {
                let (x, nw) = (g.spads[s], g.spad_normal(s));
                for k in 0..k_n {
                    let (d, f) = leg(x, nw, surfels.points[k], surfels.normals[k]);
                    t[k] = (d + d4[s]) as f32;
                    w[k] = f as f32;
                }
            });
        let pad = ((reach.max(0.0) + 2.0) * SUB as f64).ceil() as usize;
        Self {
            surfels,
            ts,
            gs,
            laser_scale,
            d1,
            pad,
            nf: g.nt * SUB + 2 * pad,
        }
    }

    /// The laser leg of row `l` per surfel: `(d1 + d_lk − t0, scale·area·cos·cos/d²)`.
    pub fn laser_row(&self, g: &Geometry, l: usize) -> Vec<(f64, f64)> {
        let (x, nw) = (g.lasers[l], g.laser_normal(l));
        let s = &self.surfels;
        (0..s.len())
            .map(|k| {
                let (d, f) = leg(x, nw, s.points[k], s.normals[k]);
                (self.d1[l] + d - g.t0, f * s.areas[k] * self.laser_scale[l])
            })
            .collect()
    }

    /// The fine histograms of SPAD `s` for the laser leg `row`: `fine[c·nf + i]` for cluster
    /// `c`, every surfel's return deposited at `floor(τ/Δt·SUB)` (the render's own binning).
    /// `fine` is resized to `C·nf + 1` and cleared; its last value is a dump for the returns
    /// outside the grid (no branch per surfel).
    pub fn spad(&self, g: &Geometry, row: &[(f64, f64)], s: usize, fine: &mut Vec<f64>) {
        let nf = self.nf;
        let dump = self.surfels.clusters * nf;
        fine.clear();
        fine.resize(dump + 1, 0.0);
        let scale = SUB as f64 / g.dt;
        let pad = self.pad as f64;
        let k_n = self.surfels.len();
        let (ts, gs) = (&self.ts[s * k_n..][..k_n], &self.gs[s * k_n..][..k_n]);
        for (((&(tl, al), &t), &w), &c) in row.iter().zip(ts).zip(gs).zip(&self.surfels.cluster) {
            let at = bin_of((tl + f64::from(t)) * scale + pad, nf).map_or(dump, |f| c * nf + f);
            fine[at] += al * f64::from(w);
        }
    }
}

/// `floor(x)` when it lies in `0..n`, else `None` (NaN included): the renders' binning.
///
/// A truncating cast, not `f64::floor`: the same bins for every `x`, but without the libm
/// call that `floor` is on baseline x86-64 (16 % of a refinement's time, measured with
/// `perf` on panel/figure).
#[inline]
fn bin_of(x: f64, n: usize) -> Option<usize> {
    // For x ≥ 0 truncation is floor; NaN fails both comparisons (and casts to 0, unused).
    (x >= 0.0 && x < n as f64).then_some(x as usize)
}

/// A Gaussian blur of `sigma` fine samples (none when 0), unit sum, radius 4σ.
pub(super) fn kernel(sigma: f64) -> Vec<f64> {
    if sigma <= 0.0 {
        return vec![1.0];
    }
    let r = (4.0 * sigma).ceil() as isize;
    let mut k: Vec<f64> = (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect();
    let s: f64 = k.iter().sum();
    k.iter_mut().for_each(|x| *x /= s);
    k
}

/// The prefix sums of `fine` blurred by `kern`: `out[i] = Σ_{j<i} (fine ⊛ kern)[j]`,
/// `fine.len() + 1` values.
pub(super) fn blurred_prefix(fine: &[f64], kern: &[f64], out: &mut Vec<f64>) {
    let n = fine.len();
    let r = kern.len() / 2;
    out.clear();
    out.resize(n + 1, 0.0);
    let mut acc = 0.0;
    if kern.len() == 1 {
        for (i, &x) in fine.iter().enumerate() {
            acc += x;
            out[i + 1] = acc;
        }
        return;
    }
    // The blur written into `out[1..]`, then summed in place (no buffer per call).
    for (i, &x) in fine.iter().enumerate() {
        if x == 0.0 {
            continue;
        }
        let lo = i.saturating_sub(r);
        let hi = (i + r).min(n - 1);
        for j in lo..=hi {
            out[j + 1] += x * kern[j + r - i];
        }
    }
    for o in out[1..].iter_mut() {
        acc += *o;
        *o = acc;
    }
}

/// Bin `nt` values from a prefix sum with a delay of `shift` fine samples (positive: later):
/// bin `n` sums the fine samples `[n·SUB − shift, (n + 1)·SUB − shift)` past the padding.
#[inline]
pub(super) fn bin(prefix: &[f64], pad: usize, shift: isize, out: &mut [f64]) {
    bin_range(prefix, pad, shift, 0, out);
}

/// [`bin`] of the bins `first..first + out.len()` only.
#[inline]
pub(super) fn bin_range(prefix: &[f64], pad: usize, shift: isize, first: usize, out: &mut [f64]) {
    let base = pad as isize - shift;
    for (n, o) in (first..).zip(out.iter_mut()) {
        let a = base + (n * SUB) as isize;
        let b = a + SUB as isize;
        let at = |i: isize| prefix[i.clamp(0, prefix.len() as isize - 1) as usize];
        *o = at(b) - at(a);
    }
}

/// The bins `[n0, n1)` (within `0..nt`) of [`bin`] that can be nonzero when the prefix is
/// constant outside the fine samples `support = [lo, hi)`: bin `n` spans
/// `[a, a + SUB)`, `a = pad − shift + n·SUB`, and differs from zero only when `a < hi` and
/// `a + SUB > lo`. An empty support gives an empty range.
pub(super) fn bin_span(
    support: (usize, usize),
    pad: usize,
    shift: isize,
    nt: usize,
) -> (usize, usize) {
    let (lo, hi) = (support.0 as isize, support.1 as isize);
    if hi <= lo {
        return (0, 0);
    }
    let (base, sub, n) = (pad as isize - shift, SUB as isize, nt as isize);
    let n0 = ((lo - base - sub).div_euclid(sub) + 1).clamp(0, n);
    let n1 = ((hi - 1 - base).div_euclid(sub) + 1).clamp(n0, n);
    (n0 as usize, n1 as usize)
}
