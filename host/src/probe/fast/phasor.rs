//! The full-phasor table, voxels in vectors: the diagonal of any scan, one table per
//! histogram. Made for rows of one SPAD (paired and confocal rows), where
//! [`super::LookupDiagonal`] — vectorised over blocks of 8 SPADs — would compute 8 lanes and
//! keep one; on SPAD grids off the FFT path it also beats the lookup (the planner's flop
//! model, `probe::plan`): on the 8 × 8 × 8 × 8 path-traced panel/figure capture over
//! 31 × 31 × 75 voxels at λ = 0.1 m, 1.1 s against the lookup's 4.3 s (2 threads).
//!
//! **Method.** For one histogram `h` (laser `x_l`, SPAD `x_s`, leg offset
//! `x = d1 + d4 − t0`) the band sum of the diagonal is a function of the path time relative
//! to `t0`, `r = τ + x` (`τ = d_lv + d_vs` the hidden path):
//!
//! ```text
//! W(r) = Σ_j Ĝ_j·B_j·e^{iν_j r},   B_j = Σ_n h[n]·e^{−2πi k_j n/N},   A(v) += w(d_lv)·w(d_vs)·W(τ + x)
//! ```
//!
//! (the kernel's `HG_j = B_j·Ĝ_j·e^{iν_j x}` with the legs folded into the argument). Per
//! histogram: one forward FFT of length N gives every `B_j` (non-finite samples read as 0),
//! the band `Ĝ_j·B_j` is placed at bins `k_j mod L` of a length-`L` spectrum and one inverse
//! FFT gives `W` at the nodes `r_m = m·δ`, `δ = NΔt/L` — exactly, the carrier included (no
//! demodulation). The nodes covering the guard interval [`Config::guard`] (one more each side)
//! are kept as a table of `(W_m, W_{m+1} − W_m)` in `f32`. Then, for 8 voxels at a time (a
//! lane loop over `[f32; 8]` that the compiler vectorises): the two leg distances, `r`, the
//! guard test (the kernel's: `r` in `f32` inside the guard, else 0), the node index and its
//! fraction `t`, one table read (a gather), `W_m + t·(W_{m+1} − W_m)`, the weights, and a
//! complex `f32` accumulate.
//!
//! **Error bound** (linear interpolation, step δ, wavelength λ). For one band bin the chord
//! between two nodes misses the phasor by `|(1 − t) + t·e^{iθ} − e^{itθ}| ≤ 1 − cos(θ/2)`
//! (`θ = ν_j δ`, the worst at `t = ½`). Summed over the band with the gate weights:
//!
//! ```text
//! |W_table(r) − W(r)| ≤ ε(δ)·Σ_j Ĝ_j·|B_j|,   ε(δ) = Σ_j Ĝ_j·(1 − cos(ν_j δ/2)) / Σ_j Ĝ_j ≈ (δ²/8)·((2π/λ)² + 1/σ²)
//! ```
//!
//! `Σ_j Ĝ_j|B_j| ≤ Σ_n |h[n]|·Σ_j Ĝ_j` and `Σ_j Ĝ_j` is the peak of one return's gated
//! phasor (≈ 1): ε is the worst error relative to the peak of a single return, and it is
//! **reached** by a single return at a node midpoint (all bins' errors then add in phase;
//! test `bound_is_tight_and_has_teeth`). The step is the largest `δ = NΔt/L` with
//! `ε(δ) ≤ tolerance` ([`TOLERANCE`] = 2e-3: `δ ≈ λ/26` at σ = 2λ/3) and `δ ≤ Δt/2`, `L` a
//! `2^a·3^b·5^c` size. On top of ε: the `f32` rounding of the FFTs (`~u·log₂L`) and of `r`
//! (`u·r/δ` of a step). A tolerance that no table of at most [`MAX_LEN`] nodes meets is a
//! configuration error naming `wavelength` (λ too short for the time span) or `tolerance`
//! (not finite or below the `f32` floor [`MIN_TOLERANCE`]).
//!
//! **Determinism.** The voxels are cut into tiles; each tile sums the rows of a batch in row
//! order into `f32` accumulators that are added to the `f64` ones once per batch (rows of at
//! most 8 SPADs) or once per row (rows of more: a scan split at any row merges to the same
//! sums up to the `f64` rounding of the merge); the batch is fixed by the SPADs per row, not
//! by the threads. No sum depends on which thread ran it: results are bit-identical for
//! every thread count.
//!
//! **SIMD in safe code.** The tile loop is compiled twice: for the CPU's vector extensions
//! behind `pulp`'s runtime dispatch (x86-64-v3: AVX2 + FMA, on x86-64 CPUs from Haswell and
//! Zen 1 on; NEON on aarch64), and portable (baseline x86-64: SSE2, table reads scalar),
//! which CPUs without them take and which [`Phasor::set_portable`] forces (tested). The
//! results of the two differ by `f32` rounding only (no fused multiply-add in either: Rust
//! does not contract).
//!
//! **Cost** per histogram: `5N·log₂N + 5L·log₂L` flops of FFTs and a table of
//! `(guard/δ + 3)` entries (16 bytes each), then about 30 operations per (voxel, histogram),
//! 8 voxels per vector; no allocation per row or voxel (per-thread FFT buffers and the batch's
//! tables are made once per pass).

use super::lookup::fast_len;
use crate::error::{Error, Result};
use num_complex::Complex32;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;
use vltm_kernel::{Config, Weights};

/// Default bound on the interpolation error relative to the peak of one return (ε above).
pub const TOLERANCE: f64 = 2e-3;

/// The smallest tolerance accepted: below it the `f32` tables' own rounding dominates.
pub const MIN_TOLERANCE: f64 = 1e-6;

/// The largest table grid `L` (nodes per DFT period) the path plans.
pub const MAX_LEN: usize = 1 << 22;

/// Voxels per lane group.
const LANES: usize = 8;

/// 2²³: adding it rounds an `f32` in [0, 2²²) to an integer held in the low mantissa bits.
const MAGIC: f32 = 8_388_608.0;

/// Voxels per sub-tile of the lane loops (their index, fraction and weight on the stack).
pub const TILE: usize = 256;

/// One histogram of a batch as the voxel loop sees it: laser and SPAD spots and the leg
/// offset `x = d1 + d4 − t0` (m).
#[derive(Clone, Copy, Debug, Default)]
pub struct Histogram {
    /// Laser spot.
    pub laser: [f32; 3],
    /// SPAD spot.
    pub spad: [f32; 3],
    /// Leg offset `d1 + d4 − t0` (m).
    pub offset: f32,
}

/// Per-thread buffers of [`Phasor::table`]: the forward and inverse FFTs' data and scratch.
#[derive(Clone, Debug)]
pub struct TableScratch {
    fwd: Vec<Complex32>,
    inv: Vec<Complex32>,
    fft: Vec<Complex32>,
}

/// The plan of the full-phasor table for one configuration and tolerance.
pub struct Phasor {
    cfg: Config,
    /// Nodes per DFT period, `L`.
    len: usize,
    /// Table step δ = NΔt/L (m).
    delta: f64,
    /// Node index of table entry 0.
    m_lo: i64,
    /// Entries per table.
    tlen: usize,
    /// Gate weights Ĝ_j.
    gate: Vec<f32>,
    /// The guard in `f32` (the kernel's comparison).
    guard: (f32, f32),
    /// `r` of table entry 0, `m_lo·δ`, and `1/δ`.
    r0: f32,
    inv_delta: f32,
    /// The bound ε(δ) of this table.
    bound: f64,
    portable: bool,
    fwd: Arc<dyn Fft<f32>>,
    inv: Arc<dyn Fft<f32>>,
}

impl std::fmt::Debug for Phasor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Phasor")
            .field("len", &self.len)
            .field("delta", &self.delta)
            .field("entries", &self.tlen)
            .field("bound", &self.bound)
            .field("portable", &self.portable)
            .finish_non_exhaustive()
    }
}

/// The bound ε(δ) of linear interpolation at step `delta` (m) for `cfg` (module docs).
pub fn linear_error(cfg: &Config, delta: f64) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for j in 0..cfg.bins() {
        let g = cfg.gate_weight(j);
        num += g * (1.0 - (0.5 * cfg.nu(j) * delta).cos());
        den += g;
    }
    if den > 0.0 { num / den } else { 0.0 }
}

/// The least `L` (not rounded to a fast size) whose step `NΔt/L` meets `tol`, or `None`
/// when none up to [`MAX_LEN`] does.
pub fn min_len(cfg: &Config, tol: f64) -> Option<usize> {
    let span = cfg.span();
    let ok = |l: usize| linear_error(cfg, span / l as f64) <= tol;
    // ε falls monotonically with L (δ ν_j / 2 < π for every L ≥ N): bisect.
    let (mut lo, mut hi) = (1usize, cfg.n_fft().max(1));
    if ok(hi) {
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if ok(mid) { hi = mid } else { lo = mid + 1 }
        }
        return Some(hi);
    }
    lo = hi;
    while !ok(hi) {
        lo = hi;
        hi = hi.checked_mul(2)?;
        if hi > 2 * MAX_LEN {
            return None;
        }
    }
    while lo + 1 < hi {
        let mid = lo + (hi - lo) / 2;
        if ok(mid) { hi = mid } else { lo = mid }
    }
    (hi <= MAX_LEN).then_some(hi)
}

/// The sizes of a [`Phasor`] plan that its cost and memory depend on ([`Phasor::sizes`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sizes {
    /// Nodes per DFT period, `L`.
    pub grid_len: usize,
    /// Entries of one histogram's table.
    pub table_len: usize,
    /// Bytes of one thread's FFT buffers.
    pub scratch_bytes: usize,
}

impl Phasor {
    /// Plans the table for `cfg` meeting `tol` (module docs).
    ///
    /// # Errors
    /// [`Error::Argument`] naming `tolerance` (not finite, or below [`MIN_TOLERANCE`]) or
    /// `wavelength` (no table of at most [`MAX_LEN`] nodes meets the tolerance).
    pub fn new(cfg: &Config, tol: f64) -> Result<Self> {
        let len = Self::plan_len(cfg, tol)?;
        Ok(Self::with_len(cfg, len))
    }

    /// The table grid `L` of [`Phasor::new`], planning nothing (cost models, budgets).
    ///
    /// # Errors
    /// As [`Phasor::new`].
    pub fn plan_len(cfg: &Config, tol: f64) -> Result<usize> {
        if !(tol.is_finite() && tol >= MIN_TOLERANCE) {
            return Err(Error::arg(
                "tolerance",
                format!(
                    "the phasor table's tolerance {tol} is not a number ≥ {MIN_TOLERANCE} (the f32 floor)"
                ),
            ));
        }
        let need = min_len(cfg, tol).ok_or_else(|| {
            Error::arg(
                "wavelength",
                format!(
                    "λ = {} m is too short for a phasor table of the time span {:.3} m to meet the tolerance {tol}: it would need more than {MAX_LEN} nodes (a longer wavelength, or the lookup or band path)",
                    cfg.wavelength(),
                    cfg.span()
                ),
            )
        })?;
        // δ ≤ Δt/2 as well.
        let len = fast_len(need.max(2 * cfg.n_fft()));
        if len > MAX_LEN {
            return Err(Error::arg(
                "wavelength",
                format!(
                    "λ = {} m is too short for a phasor table of the time span {:.3} m: it would need {len} nodes, more than {MAX_LEN}",
                    cfg.wavelength(),
                    cfg.span()
                ),
            ));
        }
        Ok(len)
    }

    /// The table of `L` nodes per DFT period (any `L ≥ J`: the band's bins stay distinct
    /// modulo `L`; tests pick `L` by hand).
    pub fn with_len(cfg: &Config, len: usize) -> Self {
        let len = len.max(cfg.bins()).max(2);
        let span = cfg.span();
        let delta = span / len as f64;
        let (g_lo, g_hi) = cfg.guard();
        let m_lo = (g_lo / delta).floor() as i64 - 1;
        let m_hi = (g_hi / delta).ceil() as i64 + 1;
        let tlen = (m_hi - m_lo + 1) as usize;
        let mut planner = FftPlanner::<f32>::new();
        Self {
            cfg: *cfg,
            len,
            delta,
            m_lo,
            tlen,
            gate: (0..cfg.bins()).map(|j| cfg.gate_weight(j) as f32).collect(),
            guard: (g_lo as f32, g_hi as f32),
            r0: (m_lo as f64 * delta) as f32,
            inv_delta: (1.0 / delta) as f32,
            bound: linear_error(cfg, delta),
            portable: false,
            fwd: planner.plan_fft_forward(cfg.n_fft()),
            inv: planner.plan_fft_inverse(len),
        }
    }

    /// Forces the portable loop (no runtime dispatch to the CPU's vector extensions).
    pub fn set_portable(&mut self, portable: bool) {
        self.portable = portable;
    }

    /// Nodes per DFT period, `L`.
    pub fn grid_len(&self) -> usize {
        self.len
    }

    /// Table step δ (m).
    pub fn step(&self) -> f64 {
        self.delta
    }

    /// The error bound ε(δ) of this table (relative to one return's peak).
    pub fn bound(&self) -> f64 {
        self.bound
    }

    /// Entries of one histogram's table.
    pub fn table_len(&self) -> usize {
        self.tlen
    }

    /// Bytes of one histogram's table.
    pub fn table_bytes(&self) -> usize {
        16 * self.tlen
    }

    /// Bytes of one [`TableScratch`].
    pub fn scratch_bytes(&self) -> usize {
        8 * (self.cfg.n_fft()
            + self.len
            + self
                .fwd
                .get_inplace_scratch_len()
                .max(self.inv.get_inplace_scratch_len()))
    }

    /// What a planner weighs of this plan in one read: [`Phasor::grid_len`],
    /// [`Phasor::table_len`] and [`Phasor::scratch_bytes`].
    pub fn sizes(&self) -> Sizes {
        Sizes {
            grid_len: self.grid_len(),
            table_len: self.table_len(),
            scratch_bytes: self.scratch_bytes(),
        }
    }

    /// A thread's FFT buffers.
    pub fn scratch(&self) -> TableScratch {
        let z = Complex32::new(0.0, 0.0);
        TableScratch {
            fwd: vec![z; self.cfg.n_fft()],
            inv: vec![z; self.len],
            fft: vec![
                z;
                self.fwd
                    .get_inplace_scratch_len()
                    .max(self.inv.get_inplace_scratch_len())
            ],
        }
    }

    /// The table of one histogram `h` (`Nt` samples; non-finite ones read as 0) into `out`
    /// ([`Phasor::table_len`] entries `[Re W_m, Im W_m, Re ΔW_m, Im ΔW_m]`). Returns the
    /// number of non-finite samples.
    ///
    /// # Panics
    /// If `out` has another length than [`Phasor::table_len`].
    pub fn table(&self, h: &[f32], s: &mut TableScratch, out: &mut [[f32; 4]]) -> u32 {
        assert_eq!(out.len(), self.tlen, "one table");
        let z = Complex32::new(0.0, 0.0);
        let n = self.cfg.n_fft();
        let mut bad = 0u32;
        for (b, &x) in s.fwd.iter_mut().zip(h.iter().take(n)) {
            *b = if x.is_finite() {
                Complex32::new(x, 0.0)
            } else {
                bad += 1;
                z
            };
        }
        bad += h
            .iter()
            .skip(n)
            .map(|x| u32::from(!x.is_finite()))
            .sum::<u32>();
        s.fwd[h.len().min(n)..].fill(z);
        self.fwd.process_with_scratch(&mut s.fwd, &mut s.fft);
        s.inv.fill(z);
        let (nn, ll) = (n as i64, self.len as i64);
        for (j, g) in self.gate.iter().enumerate() {
            let k = self.cfg.k_lo() + j as i64;
            s.inv[k.rem_euclid(ll) as usize] += s.fwd[k.rem_euclid(nn) as usize] * *g;
        }
        self.inv.process_with_scratch(&mut s.inv, &mut s.fft);
        let at = |e: usize| s.inv[(self.m_lo + e as i64).rem_euclid(ll) as usize];
        let mut next = at(0);
        for (e, o) in out.iter_mut().enumerate() {
            let w = next;
            next = if e + 1 < self.tlen { at(e + 1) } else { w };
            *o = [w.re, w.im, next.re - w.re, next.im - w.im];
        }
        bad
    }

    /// Adds to the voxels of one tile (positions `vx, vy, vz`, accumulators `re, im`; all of
    /// one length, a multiple of 8) the amplitudes of the histograms `entries`, in order, from
    /// their tables (`tables`: `entries.len()` tables of [`Phasor::table_len`] entries).
    ///
    /// # Panics
    /// If the lengths disagree.
    #[allow(clippy::too_many_arguments)]
    pub fn accumulate(
        &self,
        entries: &[Histogram],
        tables: &[[f32; 4]],
        vx: &[f32],
        vy: &[f32],
        vz: &[f32],
        re: &mut [f32],
        im: &mut [f32],
    ) {
        let n = vx.len();
        assert!(
            n.is_multiple_of(LANES)
                && vy.len() == n
                && vz.len() == n
                && re.len() == n
                && im.len() == n,
            "tile lengths"
        );
        assert_eq!(
            tables.len(),
            entries.len() * self.tlen,
            "one table per entry"
        );
        let op = Tile {
            k: Consts {
                guard: self.guard,
                r0: self.r0,
                inv_delta: self.inv_delta,
                xmax: (self.tlen - 2) as f32,
                d_min: self.cfg.params().d_min as f32,
                inv: matches!(self.cfg.weights(), Weights::Inv),
                tlen: self.tlen,
            },
            entries,
            tables,
            vx,
            vy,
            vz,
            re,
            im,
        };
        if self.portable {
            return pulp::WithSimd::with_simd(op, pulp::Scalar::new());
        }
        // AVX2 also on AVX-512 CPUs: 512-bit lanes measured no faster here (64³ voxels of
        // the paired bench capture), and `pulp::Arch` would pick them (its `x86-v4` feature
        // is on for `fast::sgemm`).
        #[cfg(target_arch = "x86_64")]
        if let Some(v3) = pulp::x86::V3::try_new() {
            return pulp::Simd::vectorize(v3, op);
        }
        pulp::Arch::new().dispatch(op);
    }
}

/// The constants of the lane loop.
#[derive(Clone, Copy)]
struct Consts {
    guard: (f32, f32),
    r0: f32,
    inv_delta: f32,
    xmax: f32,
    d_min: f32,
    inv: bool,
    tlen: usize,
}

/// One tile's work, run under the dispatched target features.
struct Tile<'a> {
    k: Consts,
    entries: &'a [Histogram],
    tables: &'a [[f32; 4]],
    vx: &'a [f32],
    vy: &'a [f32],
    vz: &'a [f32],
    re: &'a mut [f32],
    im: &'a mut [f32],
}

impl pulp::WithSimd for Tile<'_> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) {
        if self.k.inv {
            lanes::<true>(self);
        } else {
            lanes::<false>(self);
        }
    }
}

/// The lane loops, per entry (outer: its table stays in cache while every voxel reads it)
/// and per sub-tile of [`TILE`] voxels: the positions, guard and weights (no table reads:
/// vectorises), then the table reads and the accumulation.
#[inline(always)]
fn lanes<const INV: bool>(t: Tile<'_>) {
    let k = t.k;
    let mut idx = [0u32; TILE];
    let mut fr = [0.0f32; TILE];
    let mut wt = [0.0f32; TILE];
    for (e, tab) in t.entries.iter().zip(t.tables.chunks_exact(k.tlen)) {
        let last = tab.len() - 1;
        let [lx, ly, lz] = e.laser;
        let [sx, sy, sz] = e.spad;
        let off = e.offset;
        for ((((vx, vy), vz), re), im) in
            t.vx.chunks(TILE)
                .zip(t.vy.chunks(TILE))
                .zip(t.vz.chunks(TILE))
                .zip(t.re.chunks_mut(TILE))
                .zip(t.im.chunks_mut(TILE))
        {
            let n = vx
                .len()
                .min(vy.len())
                .min(vz.len())
                .min(re.len())
                .min(im.len());
            let (idx, fr, wt) = (&mut idx[..n], &mut fr[..n], &mut wt[..n]);
            for i in 0..n {
                let (ax, ay, az) = (vx[i] - lx, vy[i] - ly, vz[i] - lz);
                let d_lv = (ax * ax + ay * ay + az * az).sqrt();
                let (bx, by, bz) = (vx[i] - sx, vy[i] - sy, vz[i] - sz);
                let d_vs = (bx * bx + by * by + bz * bz).sqrt();
                let r = (d_lv + d_vs) + off;
                let inside = (r >= k.guard.0) & (r <= k.guard.1);
                let p = ((r - k.r0) * k.inv_delta).max(0.0).min(k.xmax);
                // floor(p) by the 2²³ rounding trick (p − ½ rounded to nearest; a tie gives
                // the node below with f = 1): float adds and a bit cast, which vectorise
                // where a float-to-int `as` (saturating) does not.
                let b = (p - 0.5) + MAGIC;
                fr[i] = p - (b - MAGIC);
                idx[i] = b.to_bits().wrapping_sub(MAGIC.to_bits());
                let w = if INV {
                    1.0 / (d_lv.max(k.d_min) * d_vs.max(k.d_min))
                } else {
                    1.0
                };
                wt[i] = if inside { w } else { 0.0 };
            }
            for i in 0..n {
                let q = tab[(idx[i] as usize).min(last)];
                re[i] += wt[i] * (q[0] + fr[i] * q[2]);
                im[i] += wt[i] * (q[1] + fr[i] * q[3]);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_complex::Complex64;
    use std::f64::consts::TAU;
    use vltm_kernel::Params;

    fn cfg(lam: f64, nt: usize, dt: f64) -> Config {
        Config::try_new(&Params {
            t0: 0.5,
            ..Params::new(lam, nt, dt)
        })
        .unwrap()
    }

    /// The f64 band sum `W(r)` of histogram `h`.
    fn exact(c: &Config, h: &[f32], r: f64) -> Complex64 {
        let n = c.n_fft();
        (0..c.bins())
            .map(|j| {
                let k = (c.k_lo() + j as i64) as f64;
                let b: Complex64 = h
                    .iter()
                    .enumerate()
                    .map(|(i, &x)| {
                        Complex64::from_polar(f64::from(x), -TAU * k * i as f64 / n as f64)
                    })
                    .sum();
                b * c.gate_weight(j) * Complex64::from_polar(1.0, c.nu(j) * r)
            })
            .sum()
    }

    /// Interpolated `W(r)` from a table (the lane loop's arithmetic, in f64 positions).
    fn interp(p: &Phasor, tab: &[[f32; 4]], r: f64) -> Complex64 {
        let x = (r / p.delta) - p.m_lo as f64;
        let m = x.floor();
        let f = x - m;
        let q = tab[m as usize];
        Complex64::new(
            f64::from(q[0]) + f * f64::from(q[2]),
            f64::from(q[1]) + f * f64::from(q[3]),
        )
    }

    /// Worst |W_table − W| over node midpoints near a single return at `r_p` (with the
    /// return at a node midpoint), relative to Σ_j Ĝ_j (the return's peak).
    fn impulse_error(c: &Config, len: usize) -> f64 {
        let p = Phasor::with_len(c, len);
        let mut s = p.scratch();
        let mut tab = vec![[0.0f32; 4]; p.table_len()];
        // A return at bin 40 (r_p = 40Δt), evaluated at the node midpoints around it.
        let mut h = vec![0.0f32; c.nt()];
        h[40] = 1.0;
        p.table(&h, &mut s, &mut tab);
        let peak: f64 = (0..c.bins()).map(|j| c.gate_weight(j)).sum();
        let rp = 40.0 * c.dt();
        let m0 = (rp / p.delta).floor() as i64;
        (m0 - 3..=m0 + 3)
            .map(|m| {
                let r = (m as f64 + 0.5) * p.delta;
                (interp(&p, &tab, r) - exact(c, &h, r)).norm() / peak
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn worst_fraction_is_the_midpoint() {
        for theta in [0.05f64, 0.3, 1.0, 2.0] {
            let at = |t: f64| {
                (Complex64::new(1.0 - t, 0.0) + Complex64::from_polar(t, theta)
                    - Complex64::from_polar(1.0, t * theta))
                .norm()
            };
            let worst = (0..=1000)
                .map(|i| at(i as f64 / 1000.0))
                .fold(0.0, f64::max);
            let mid = 1.0 - (theta / 2.0).cos();
            assert!(
                (worst - mid).abs() <= 1e-12 * mid.max(1e-300) + 1e-15,
                "{theta}: {worst} {mid}"
            );
        }
    }

    /// The table meets its bound everywhere on random rows, the bound is reached by a single
    /// return at a node midpoint, and a table one node short of the least `L` (one step too
    /// coarse) fails the tolerance.
    #[test]
    fn bound_is_tight_and_has_teeth() {
        for (lam, dt) in [(0.06, 0.01), (0.13, 0.0255), (0.3, 0.01)] {
            let c = cfg(lam, 96, dt);
            for tol in [1e-2, 2e-3] {
                let l = min_len(&c, tol).unwrap();
                assert!(linear_error(&c, c.span() / l as f64) <= tol);
                assert!(linear_error(&c, c.span() / (l - 1) as f64) > tol);
                let fine = impulse_error(&c, l);
                let coarse = impulse_error(&c, l - 1);
                println!(
                    "λ {lam} Δt {dt} tol {tol:.0e}: L {l}, error {fine:.4e} (bound {:.4e}); L − 1: {coarse:.4e}",
                    linear_error(&c, c.span() / l as f64)
                );
                assert!(fine <= tol + 1e-6, "{fine:.3e} > {tol:.0e}");
                // Teeth: the worst midpoint next to the return reaches the bound (up to the
                // gate envelope over half a step, ~δ²/8σ², below the 2/L gap between L and
                // L − 1), so one step too coarse fails.
                assert!(coarse > tol, "L − 1: {coarse:.4e} ≤ {tol:.0e}");
            }
        }
    }

    /// The portable loop (forced) and the dispatched one agree to f32 rounding, and each is
    /// deterministic; with `1/d` and unit weights, voxels inside and outside the guard.
    #[test]
    fn portable_matches_dispatched() {
        for weights in [Weights::Inv, Weights::One] {
            let c = Config::try_new(&Params {
                t0: 0.9,
                weights,
                ..Params::new(0.08, 120, 0.012)
            })
            .unwrap();
            let mut p = Phasor::new(&c, TOLERANCE).unwrap();
            let mut s = p.scratch();
            let entries: Vec<Histogram> = (0..5)
                .map(|i| Histogram {
                    laser: [-0.3 + 0.1 * i as f32, 0.1, 0.0],
                    spad: [-0.1 + 0.1 * i as f32, 0.15, 0.0],
                    offset: 0.01 * i as f32,
                })
                .collect();
            let mut tables = vec![[0.0f32; 4]; entries.len() * p.table_len()];
            for (e, tab) in tables.chunks_exact_mut(p.table_len()).enumerate() {
                let h: Vec<f32> = (0..c.nt())
                    .map(|n| ((n * 7 + e * 13) % 17) as f32 + if n == 30 + e { 50.0 } else { 0.0 })
                    .collect();
                p.table(&h, &mut s, tab);
            }
            let n = 600;
            let vox = |i: usize, a: usize| ((i * (a + 3) * 37) % 101) as f32 / 101.0;
            let vx: Vec<f32> = (0..n).map(|i| vox(i, 0) - 0.5).collect();
            let vy: Vec<f32> = (0..n).map(|i| vox(i, 1) - 0.5).collect();
            let vz: Vec<f32> = (0..n).map(|i| 0.2 + 1.5 * vox(i, 2)).collect();
            let run = |p: &Phasor| {
                let (mut re, mut im) = (vec![0.0f32; n], vec![0.0f32; n]);
                p.accumulate(&entries, &tables, &vx, &vy, &vz, &mut re, &mut im);
                (re, im)
            };
            let fast = run(&p);
            assert_eq!(fast, run(&p));
            p.set_portable(true);
            let slow = run(&p);
            let peak = fast
                .0
                .iter()
                .chain(&fast.1)
                .fold(0.0f32, |m, x| m.max(x.abs()));
            let worst = fast
                .0
                .iter()
                .chain(&fast.1)
                .zip(slow.0.iter().chain(&slow.1))
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f32, f32::max);
            assert!(peak > 0.0 && worst <= 1e-5 * peak, "{worst} vs peak {peak}");
            let zeros = fast.0.iter().filter(|&&x| x == 0.0).count();
            println!(
                "{weights:?}: portable vs dispatched {worst:.2e} of {peak:.3e}; {zeros} voxels outside the guard"
            );
        }
    }

    #[test]
    fn tolerance_and_wavelength_errors() {
        let c = cfg(0.06, 96, 0.01);
        for tol in [0.0, -1.0, f64::NAN, 1e-9] {
            let e = Phasor::new(&c, tol).unwrap_err().to_string();
            assert!(e.contains("tolerance"), "{e}");
        }
        // λ far below the time span: no table of MAX_LEN nodes meets 1e-6.
        let c = Config::try_new(&Params::new(0.001, 20_000, 0.0002)).expect("config");
        let e = Phasor::new(&c, MIN_TOLERANCE).unwrap_err().to_string();
        assert!(e.contains("wavelength"), "{e}");
    }
}
