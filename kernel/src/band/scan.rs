//! Stage 1, the fixed part of a scan: [`Scan`] (the validated configuration, the SPAD
//! positions and the band tables, in caller memory) and the band transform that
//! [`RowBuffer::load`](crate::RowBuffer::load) runs on each histogram (the per-row spectra,
//! gate, legs and un-gated values: module docs of `band/row.rs`).
//!
//! The band spectrum of a histogram, `Σ_n H[n]·e^{−2πi k_j n/N}` (J values), comes from a
//! table of `e^{−2πiq/N}` made once with `f64` `libm` (table error ≤ 6e-8). Each sample is
//! converted to `f32` once. The transform is chosen once per scan from N, Nt and J by an
//! operation count ([`Scan::new`]):
//!
//! - **two-stage** (pruned Cooley–Tukey) when `N = N1·N2` with `2 ≤ N2 ≤ 64`, `N1 ≤ 64`:
//!   `(⌊N2/2⌋ + 1)·Nt` real×complex MACs for the `N2`-point DFTs of the decimated samples,
//!   then `J·N1` complex multiply-adds for the band bins only (Horner's rule over the
//!   decimation phases, the table read in contiguous runs). Error ≲ `(N2 + 2N1)·6e-8` of
//!   `Σ|H|` (measured 3.4e-8 for N = 289 = 17², J = 137);
//! - **direct** otherwise: `J·Nt` real×complex MACs by an integer phase accumulator
//!   ([`TwiddleStep`], no drift with n), in blocks of 64 samples. Error ≈ `Nt·6e-8` of
//!   `Σ|H|` at worst (measured ≤ 3e-7).
//!
//! **No `f64` per row** (soft float on an FPU without double precision, such as the
//! Cortex-M4F's FPv4-SP): [`Scan::new`] converts the constants once (`k_lo/NΔt`, `1/NΔt`,
//! `1/λ`, `t0`, the laser origin, the carrier steps `e^{−iΩΔt}` and `e^{−iΩ·64Δt}` from
//! `f64` `libm`), for the rows' `f32` arithmetic (error bounds in the module docs of
//! `band/row.rs`).
//!
//! Memory: tables `2N + J + Ks` `f32` ([`Scan::tables_len`]), owned by the caller; the
//! transforms use 1.3 KB of stack.

use crate::config::{Config, Legs, Point};
use crate::error::{ArgumentError, check_len, check_points};
use crate::geometry::dist64;
use crate::phase::{TwiddleStep, cis_turns_f64, wrap};
use crate::sample::Sample;
use num_complex::Complex32;

/// Casts a caller's `f32` buffer to complex numbers (always succeeds for even lengths:
/// `Complex32` has the alignment of `f32`).
pub(crate) fn as_complex<'b>(
    what: &'static str,
    buf: &'b mut [f32],
) -> Result<&'b mut [Complex32], ArgumentError> {
    let found = buf.len();
    bytemuck::try_cast_slice_mut(buf).map_err(|_| ArgumentError::Length {
        what,
        expected: found & !1,
        found,
    })
}

/// The fixed part of a scan: the validated [`Config`], the SPAD positions and the band
/// tables (DFT twiddles `e^{−2πiq/N}`, gate weights `Ĝ_j`, sensor legs `d4_s`), all in
/// caller-owned memory.
///
/// ```
/// use vltm_kernel::{Config, Params, Scan};
/// let cfg = Config::try_new(&Params::new(0.2, 64, 0.01)).unwrap();
/// let spads = [[0.0f32, 0.0, 0.0], [0.1, 0.0, 0.0]];
/// let mut tables = vec![0.0f32; Scan::tables_len(&cfg, spads.len())];
/// let scan = Scan::new(&cfg, &spads, &mut tables).unwrap();
/// assert_eq!(scan.spads().len(), 2);
/// ```
#[derive(Debug)]
pub struct Scan<'t> {
    pub(super) cfg: Config,
    pub(super) spads: &'t [Point],
    pub(super) twiddle: &'t [Complex32],
    pub(super) gate: &'t [f32],
    pub(super) d4: &'t [f32],
    plan: BandPlan,
    pub(super) k: RowConsts,
}

/// The configuration's per-row constants in `f32`, converted once by [`Scan::new`] (module
/// docs: no `f64` per row).
#[derive(Clone, Copy, Debug)]
pub(super) struct RowConsts {
    /// `k_lo/(NΔt)`, `1/(NΔt)` and `1/λ` (turns per metre).
    pub(super) klo: f32,
    pub(super) inv_span: f32,
    pub(super) inv_lambda: f32,
    /// `t0` (m).
    pub(super) t0: f32,
    /// The laser origin of [`Legs::FirstAndLast`], `None` for wall-to-wall legs.
    pub(super) origin: Option<Point>,
    /// `−Δt/λ`: carrier turns per sample.
    pub(super) carrier_turns: f32,
    /// `e^{−iΩΔt}` and `e^{−iΩ·64Δt}`.
    pub(super) carrier_step: Complex32,
    pub(super) block_step: Complex32,
}

impl RowConsts {
    fn new(cfg: &Config) -> Self {
        let span = cfg.span();
        let turns_per_bin = -cfg.dt() / cfg.wavelength();
        Self {
            klo: (cfg.k_lo() as f64 / span) as f32,
            inv_span: (1.0 / span) as f32,
            inv_lambda: (1.0 / cfg.wavelength()) as f32,
            t0: cfg.t0() as f32,
            origin: match cfg.legs() {
                Legs::WallToWall => None,
                Legs::FirstAndLast { laser_origin, .. } => Some([
                    laser_origin[0] as f32,
                    laser_origin[1] as f32,
                    laser_origin[2] as f32,
                ]),
            },
            carrier_turns: turns_per_bin as f32,
            carrier_step: cis_turns_f64(turns_per_bin),
            block_step: cis_turns_f64(64.0 * turns_per_bin),
        }
    }
}

/// The sensor legs `|x_s − sensor_origin|` of `spads` into `d4` (0 for wall-to-wall time axes).
fn fill_sensor_legs(cfg: &Config, spads: &[Point], d4: &mut [f32]) {
    for (d, p) in d4.iter_mut().zip(spads) {
        *d = match cfg.legs() {
            Legs::WallToWall => 0.0,
            Legs::FirstAndLast { sensor_origin, .. } => dist64(p, &sensor_origin) as f32,
        };
    }
}

impl<'t> Scan<'t> {
    /// Length in `f32` of the tables buffer: `2N + J + Ks`.
    pub const fn tables_len(cfg: &Config, n_spads: usize) -> usize {
        // Saturating: a size that overflows `usize` matches no real slice, so `new` rejects it.
        (2 * cfg.n_fft() + cfg.bins()).saturating_add(n_spads)
    }

    /// Builds the tables into `tables` (length [`Scan::tables_len`]).
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if `tables` has the wrong length, [`ArgumentError::NonFinite`] if a SPAD
    /// position is not finite.
    pub fn new(
        cfg: &Config,
        spads: &'t [Point],
        tables: &'t mut [f32],
    ) -> Result<Self, ArgumentError> {
        check_len("tables", Self::tables_len(cfg, spads.len()), tables.len())?;
        check_points("spads", spads)?;
        let n = cfg.n_fft();
        // `_checked` (the lengths were checked above): no panicking branch in the ELF.
        let too_short = ArgumentError::Length {
            what: "tables",
            expected: Self::tables_len(cfg, spads.len()),
            found: tables.len(),
        };
        let (tw, rest) = tables.split_at_mut_checked(2 * n).ok_or(too_short)?;
        let (gate, d4) = rest.split_at_mut_checked(cfg.bins()).ok_or(too_short)?;
        let twiddle = as_complex("tables", tw)?;
        for (q, w) in twiddle.iter_mut().enumerate() {
            let a = -core::f64::consts::TAU * q as f64 / n as f64;
            *w = Complex32::new(libm::cos(a) as f32, libm::sin(a) as f32);
        }
        for (j, g) in gate.iter_mut().enumerate() {
            *g = cfg.gate_weight(j) as f32;
        }
        fill_sensor_legs(cfg, spads, d4);
        Ok(Self {
            cfg: *cfg,
            spads,
            twiddle,
            gate,
            d4,
            plan: BandPlan::choose(cfg),
            k: RowConsts::new(cfg),
        })
    }

    /// The same scan for other SPAD spots: shares this scan's twiddle and gate tables (no
    /// trigonometry, no allocation) and computes only the sensor legs of `spads` into `d4`
    /// (length `spads.len()`). A paired or confocal row, whose one SPAD spot changes from row
    /// to row, costs `O(Ks)` here instead of [`Scan::new`]'s `O(N + J)` sines and cosines.
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if `d4` has the wrong length, [`ArgumentError::NonFinite`] if a SPAD position
    /// is not finite.
    pub fn with_spads<'s>(
        &'s self,
        spads: &'s [Point],
        d4: &'s mut [f32],
    ) -> Result<Scan<'s>, ArgumentError> {
        check_len("sensor legs", spads.len(), d4.len())?;
        check_points("spads", spads)?;
        fill_sensor_legs(&self.cfg, spads, d4);
        Ok(Scan {
            cfg: self.cfg,
            spads,
            twiddle: self.twiddle,
            gate: self.gate,
            d4,
            plan: self.plan,
            k: self.k,
        })
    }

    /// The configuration.
    pub const fn config(&self) -> &Config {
        &self.cfg
    }
    /// SPAD positions.
    pub const fn spads(&self) -> &'t [Point] {
        self.spads
    }
    /// Sensor legs `d4_s` (0 for wall-to-wall time axes) (m).
    pub const fn sensor_legs(&self) -> &'t [f32] {
        self.d4
    }

    /// The laser leg `d1_l` for a laser spot (0 for wall-to-wall time axes) (m).
    pub fn laser_leg(&self, laser: &Point) -> f64 {
        match self.cfg.legs() {
            Legs::WallToWall => 0.0,
            Legs::FirstAndLast { laser_origin, .. } => dist64(laser, &laser_origin),
        }
    }

    /// Band spectrum of one histogram into `out` (J values), without legs or gate weights:
    /// `out[j] = Σ_n h[n]·e^{−2πi k_j n/N}`. Non-finite samples read as 0. Each sample is
    /// converted to `f32` once; the transform is the one [`BandPlan`] chose for N.
    pub(super) fn dft_band<T: Sample>(&self, h: &[T], out: &mut [Complex32]) {
        match self.plan {
            BandPlan::TwoStage { n1, n2 } => self.dft_band_two_stage(h, out, n1, n2),
            BandPlan::Direct => self.dft_band_direct(h, out),
        }
    }

    /// The direct band DFT, in blocks of [`BLOCK`] samples converted to `f32` once on the
    /// stack; the J accumulators live in `out` between blocks. `Nt·J` real×complex MACs.
    fn dft_band_direct<T: Sample>(&self, h: &[T], out: &mut [Complex32]) {
        // `max(1)`: N ≥ Nt ≥ 1 already; lets the optimiser drop the division-by-zero branch.
        let n = self.cfg.n_fft().max(1);
        let k_lo = self.cfg.k_lo();
        out.fill(Complex32::new(0.0, 0.0));
        let mut xs = [0.0f32; BLOCK];
        for (b, block) in h.chunks(BLOCK).enumerate() {
            for (x, s) in xs.iter_mut().zip(block) {
                *x = s.value();
            }
            let xs = xs.get(..block.len()).unwrap_or(&[]);
            let base = (b * BLOCK) as u64;
            for (j, o) in out.iter_mut().enumerate() {
                let mut q = TwiddleStep::new(k_lo + j as i64, base, n);
                let (mut re, mut im) = (o.re, o.im);
                for &v in xs {
                    if let Some(w) = self.twiddle.get(q.index()) {
                        re += v * w.re;
                        im += v * w.im;
                    }
                    q.advance();
                }
                *o = Complex32::new(re, im);
            }
        }
    }

    /// The band DFT as a pruned two-stage (Cooley–Tukey) transform, `N = N1·N2`,
    /// `n = a + N1·m`:
    ///
    /// 1. for each `a < N1`, the `N2`-point DFT of the decimated samples,
    ///    `Y_a[r] = Σ_m x[a + N1·m]·e^{−2πi rm/N2}` (real input: `r ≤ N2/2`, the rest by
    ///    conjugate symmetry; two `a` at a time so that each twiddle load serves both);
    /// 2. only the J band bins of `X[k] = Σ_a e^{−2πi k·a/N}·Y_a[k mod N2]`, by Horner's rule
    ///    in `a` (from `N1 − 1` down), two `a` per pass over the band:
    ///    `X[k] ← (X[k]·W^k + Y_{a+1}[k mod N2])·W^k + Y_a[k mod N2]`, `W^k = e^{−2πik/N}` from
    ///    the table, read in contiguous runs (no index arithmetic, no bounds check inside).
    ///
    /// Cost `(⌊N2/2⌋ + 1)·Nt` real×complex MACs + `J·N1` complex multiply-adds. Error: the
    /// stage-1 sums (≤ N2 terms) and the Horner recursion (N1 steps, each rounding and the
    /// table's 6e-8) give ≲ (N2 + 2·N1)·6e-8 of `Σ|x|` (unit test
    /// `band_transforms_match_f64_dft`).
    fn dft_band_two_stage<T: Sample>(&self, h: &[T], out: &mut [Complex32], n1: usize, n2: usize) {
        const ZERO: Complex32 = Complex32::new(0.0, 0.0);
        let n = self.cfg.n_fft().max(1);
        let n1 = n1.max(1);
        let n2 = n2.clamp(1, BLOCK);
        out.fill(ZERO);
        // e^{−2πi m/N2} = twiddle[m·N1]. Indices into the stack arrays are masked
        // (`& (BLOCK − 1)`, exact since every index is < N2 ≤ BLOCK): no bounds branch.
        let mut w2 = [ZERO; BLOCK];
        for (m, w) in w2.iter_mut().take(n2).enumerate() {
            *w = self.twiddle.get(m * n1).copied().unwrap_or_default();
        }
        let k0 = wrap(self.cfg.k_lo(), n);
        let r0 = wrap(self.cfg.k_lo(), n2);
        let half = n2 / 2;
        let mut xs = [[0.0f32; BLOCK]; 2];
        let mut ys = [[ZERO; BLOCK]; 2];
        // Pairs (a + 1, a) from the top; an odd N1 starts with a phantom a = N1 (Y = 0).
        let mut top = if n1 % 2 == 1 { n1 } else { n1 - 1 };
        loop {
            // Stage 1: decimated samples of a + 1 (xs[0]) and a (xs[1]), zero-padded.
            let mut len = 0;
            for (x, a) in xs.iter_mut().zip([top, top.saturating_sub(1)]) {
                x.fill(0.0);
                if a < n1 {
                    let mut l = 0;
                    for (x, s) in x.iter_mut().zip(h.iter().skip(a).step_by(n1)) {
                        *x = s.value();
                        l += 1;
                    }
                    len = len.max(l);
                }
            }
            let [xa, xb] = &xs;
            let (xa, xb) = (xa.get(..len).unwrap_or(&[]), xb.get(..len).unwrap_or(&[]));
            for r in 0..=half {
                let (mut za, mut zb, mut m) = (ZERO, ZERO, 0usize);
                for (&va, &vb) in xa.iter().zip(xb) {
                    let w = w2[m & (BLOCK - 1)];
                    za.re += va * w.re;
                    za.im += va * w.im;
                    zb.re += vb * w.re;
                    zb.im += vb * w.im;
                    m += r;
                    if m >= n2 {
                        m -= n2;
                    }
                }
                let [ya, yb] = &mut ys;
                ya[r & (BLOCK - 1)] = za;
                yb[r & (BLOCK - 1)] = zb;
                if r > 0 && r < n2 - r {
                    ya[(n2 - r) & (BLOCK - 1)] = za.conj();
                    yb[(n2 - r) & (BLOCK - 1)] = zb.conj();
                }
            }
            // Stage 2: Horner step for the pair over the band, in runs where neither the
            // table index k mod N nor the residue k mod N2 wraps.
            let [ya, yb] = &ys;
            let (mut j, mut q, mut r) = (0usize, k0, r0);
            while j < out.len() {
                let run = (out.len() - j).min(n - q).min(n2 - r).max(1);
                let (Some(o), Some(w), Some(ya), Some(yb)) = (
                    out.get_mut(j..j + run),
                    self.twiddle.get(q..q + run),
                    ya.get(r..r + run),
                    yb.get(r..r + run),
                ) else {
                    break;
                };
                for (((o, w), ya), yb) in o.iter_mut().zip(w).zip(ya).zip(yb) {
                    *o = (*o * *w + *ya) * *w + *yb;
                }
                j += run;
                q += run;
                if q >= n {
                    q = 0;
                }
                r += run;
                if r >= n2 {
                    r = 0;
                }
            }
            if top < 2 {
                break;
            }
            top -= 2;
        }
    }
}

/// Samples per stack block of the band transforms, and the largest second factor `N2` of the
/// two-stage transform (a power of two: indices are masked, not bounds-checked).
const BLOCK: usize = 64;

/// How [`RowBuffer::load`](crate::RowBuffer::load) computes the band spectra, chosen once per scan from N, Nt and J
/// by an operation count (real multiplies and table steps, the direct DFT's inner step
/// costing as much as a two-stage one).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum BandPlan {
    /// `Nt·J` real×complex MACs.
    Direct,
    /// `N = n1·n2`, `2 ≤ n2 ≤ 64`: `(⌊n2/2⌋ + 1)·Nt` real×complex + `J·n1` complex MACs.
    TwoStage { n1: usize, n2: usize },
}

impl BandPlan {
    fn choose(cfg: &Config) -> Self {
        let (n, nt, j) = (cfg.n_fft(), cfg.nt(), cfg.bins());
        // Weights measured on the Cortex-M4F (instructions per inner step): direct 10,
        // stage 1 7, stage 2 (a complex MAC into memory) 18.
        let mut best = (10 * nt * j, Self::Direct);
        for n2 in 2..=BLOCK.min(n) {
            let n1 = n / n2;
            // N1 ≤ 64 keeps the Horner recursion's error ≤ (N2 + 2·N1)·6e-8 of Σ|x| small.
            if n % n2 != 0 || n1 > BLOCK {
                continue;
            }
            let cost = 7 * (n2 / 2 + 1) * nt + 18 * j * n1;
            if cost < best.0 {
                best = (cost, Self::TwoStage { n1, n2 });
            }
        }
        best.1
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::band::row::RowBuffer;
    use crate::config::Params;

    /// A scan re-pointed at other SPAD spots ([`Scan::with_spads`]) loads rows bit-identically
    /// to a scan built for those spots, with legs or without; a wrong length or a NaN spot is
    /// refused.
    #[test]
    fn with_spads_equals_a_fresh_scan() {
        use std::vec;
        use std::vec::Vec;
        for legs in [false, true] {
            let mut p = Params::new(0.13, 300, 0.01);
            p.t0 = 0.4;
            if legs {
                p.legs = Legs::FirstAndLast {
                    laser_origin: [0.3, -0.2, -1.1],
                    sensor_origin: [-0.4, 0.1, -0.9],
                };
            }
            let cfg = Config::try_new(&p).unwrap();
            let first = [[0.0f32, 0.0, 0.0]];
            let mut tables = vec![0.0f32; Scan::tables_len(&cfg, 1)];
            let base = Scan::new(&cfg, &first, &mut tables).unwrap();
            let h: Vec<f32> = (0..300).map(|n| ((n * 37) % 11) as f32).collect();
            let laser = [0.21f32, -0.13, 0.02];
            for spot in [[0.05f32, 0.1, 0.0], [-0.3, 0.2, 0.01]] {
                let spads = [spot];
                let mut fresh_tables = vec![0.0f32; Scan::tables_len(&cfg, 1)];
                let fresh = Scan::new(&cfg, &spads, &mut fresh_tables).unwrap();
                let mut d4 = [0.0f32; 1];
                let moved = base.with_spads(&spads, &mut d4).unwrap();
                assert_eq!(moved.sensor_legs(), fresh.sensor_legs());
                let load = |scan: &Scan<'_>| {
                    let mut buf = vec![0.0f32; RowBuffer::len(&cfg, 1)];
                    let mut rows = RowBuffer::new(scan, &mut buf).unwrap();
                    let row = rows.load(scan, laser, &h).unwrap();
                    (
                        row.band().to_vec(),
                        row.ungated().to_vec(),
                        row.offsets().to_vec(),
                    )
                };
                assert_eq!(load(&moved), load(&fresh), "legs {legs}, spot {spot:?}");
            }
            let mut d4 = [0.0f32; 2];
            assert!(base.with_spads(&first, &mut d4).is_err());
            let mut d4 = [0.0f32; 1];
            assert!(base.with_spads(&[[f32::NAN, 0.0, 0.0]], &mut d4).is_err());
        }
    }

    /// Both transforms against an `f64` DFT, for N with and without a small factor, `u16`
    /// and `f32` samples (a NaN reads as 0): error ≤ 4e-7·Σ|h|.
    #[test]
    fn band_transforms_match_f64_dft() {
        for (lam, nt, dt) in [
            (0.13, 255, 0.0255),
            (0.2, 500, 0.01),
            (0.1, 128, 0.01),
            (0.3, 97, 0.02),
        ] {
            let cfg = Config::try_new(&Params::new(lam, nt, dt)).unwrap();
            let mut tables = [0.0f32; 4096];
            let len = Scan::tables_len(&cfg, 1);
            let scan = Scan::new(&cfg, &[[0.0; 3]], &mut tables[..len]).unwrap();
            let n = cfg.n_fft();
            let mut rng = 12345u32;
            let h: [f32; 512] = core::array::from_fn(|_| {
                rng = rng.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                (rng >> 20) as f32 - 1000.0
            });
            let mut h = h;
            h[3] = f32::NAN;
            let h = &h[..nt];
            let l1: f64 = h.iter().map(|x| f64::from(x.value()).abs()).sum();
            // The chosen plan, and a two-stage one with the largest factor ≤ 64 (to test the
            // transform where the chooser keeps the direct DFT).
            let n2 = (2..=BLOCK)
                .rev()
                .find(|d| n.is_multiple_of(*d))
                .unwrap_or(1);
            let forced = BandPlan::TwoStage { n1: n / n2, n2 };
            for plan in [BandPlan::Direct, BandPlan::choose(&cfg), forced] {
                let bound = match plan {
                    BandPlan::Direct => 5e-7,
                    BandPlan::TwoStage { n1, n2 } => (n2 + 2 * n1) as f64 * 6e-8,
                };
                let mut worst = 0.0f64;
                let mut out = [Complex32::new(0.0, 0.0); 512];
                let out = &mut out[..cfg.bins()];
                match plan {
                    BandPlan::Direct => scan.dft_band_direct(h, out),
                    BandPlan::TwoStage { n1, n2 } => scan.dft_band_two_stage(h, out, n1, n2),
                }
                for (j, o) in out.iter().enumerate() {
                    let k = (cfg.k_lo() + j as i64) as f64;
                    let (mut re, mut im) = (0.0f64, 0.0f64);
                    for (i, x) in h.iter().enumerate() {
                        let a = -core::f64::consts::TAU * k * i as f64 / n as f64;
                        re += f64::from(x.value()) * libm::cos(a);
                        im += f64::from(x.value()) * libm::sin(a);
                    }
                    let e = (f64::from(o.re) - re)
                        .abs()
                        .max((f64::from(o.im) - im).abs());
                    worst = worst.max(e / l1);
                }
                std::println!(
                    "N={n} Nt={nt} J={} {plan:?}: max error {worst:.2e} of Σ|x|",
                    cfg.bins()
                );
                assert!(
                    worst <= bound,
                    "N={n} {plan:?}: error {worst:e} > {bound:e}"
                );
            }
        }
    }

    #[test]
    fn plan_for_the_real_setup_is_17_by_17() {
        let cfg = Config::try_new(&Params::new(0.13, 255, 0.0255)).unwrap();
        assert_eq!((cfg.n_fft(), cfg.bins()), (289, 137));
        assert_eq!(
            BandPlan::choose(&cfg),
            BandPlan::TwoStage { n1: 17, n2: 17 }
        );
    }
}
