//! The lookup path's tables and grids: [`Lookup`] holds, in caller memory, the FFT twiddles
//! and the carrier `C[i] = e^{2πi k_d i/L}` (`4L` `f32`, [`Lookup::tables_len`], made once in
//! `f64`); [`Lookup::baseband`] synthesises one SPAD's baseband grid `Y[n]` by an inverse FFT
//! of length `L` (`(L/2)·log₂L` butterflies; the band is placed directly in bit-reversed
//! order, so there is no permutation pass; after a radix-4 pass the radix-2 stages run fused
//! in pairs, three complex products per four butterflies), into a caller buffer of `L + 3`
//! complex values ([`Lookup::grid_buf_len`]); [`GridReader`] reads it at any path time
//! (method and error bound in the module docs of `lookup/mod.rs`).

use super::grid::{Interpolant, LookupGrid};
use super::pair::lagrange4;
use crate::band::scan::as_complex;
use crate::error::{ArgumentError, check_len};
use crate::phase::cis_small_turns;
use num_complex::Complex32;

/// Extra grid entries past `L` (the 4-point stencil reads up to 3 past its start).
pub(crate) const EXTRA: usize = 3;

/// The lookup path's tables for one [`LookupGrid`], in caller memory: the FFT twiddles
/// (`L − 1` used, stage by stage) and the carrier `C[i] = e^{2πi k_d i/L}`.
#[derive(Debug)]
pub struct Lookup<'t> {
    pub(super) grid: LookupGrid,
    pub(super) twiddle: &'t [Complex32],
    pub(super) carrier: &'t [Complex32],
}

impl<'t> Lookup<'t> {
    /// Length in `f32` of the tables: `4L` (`L` complex twiddles, `L` complex carriers).
    pub const fn tables_len(grid: &LookupGrid) -> usize {
        4 * grid.len
    }

    /// Builds the tables into `tables` (once, `f64` `libm`, rounded to `f32`).
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if `tables` does not have [`Lookup::tables_len`] elements.
    pub fn new(grid: &LookupGrid, tables: &'t mut [f32]) -> Result<Self, ArgumentError> {
        let l = grid.len;
        check_len("lookup tables", Self::tables_len(grid), tables.len())?;
        let found = tables.len();
        let all = as_complex("lookup tables", tables)?;
        let Some((tw, car)) = all.split_at_mut_checked(l) else {
            return Err(ArgumentError::Length {
                what: "lookup tables",
                expected: 4 * l,
                found,
            });
        };
        // Stage with half-size h uses e^{+2πi k/(2h)}, k < h, at entries h − 1 .. 2h − 1.
        let mut h = 1;
        while h < l {
            for (k, w) in tw.iter_mut().skip(h - 1).take(h).enumerate() {
                let a = core::f64::consts::PI * k as f64 / h as f64;
                *w = Complex32::new(libm::cos(a) as f32, libm::sin(a) as f32);
            }
            h *= 2;
        }
        if let Some(last) = tw.last_mut() {
            *last = Complex32::new(0.0, 0.0);
        }
        // `max(1)`: L ≥ 2 already; lets the optimiser drop the division-by-zero branch.
        let lm = l.max(1) as u64;
        let step = grid.k_d.rem_euclid(lm as i64) as u64;
        for (i, c) in car.iter_mut().enumerate() {
            let q = (step * i as u64) % lm;
            let a = core::f64::consts::TAU * q as f64 / l as f64;
            *c = Complex32::new(libm::cos(a) as f32, libm::sin(a) as f32);
        }
        Ok(Self {
            grid: *grid,
            twiddle: tw,
            carrier: car,
        })
    }

    /// The grid.
    pub const fn grid(&self) -> &LookupGrid {
        &self.grid
    }

    /// The FFT twiddles, stage with half-size `h` at entries `h − 1 .. 2h − 1`.
    pub(crate) const fn twiddle_table(&self) -> &[Complex32] {
        self.twiddle
    }

    /// The carrier table `C[i] = e^{2πi k_d i/L}`, `L` entries.
    pub(crate) const fn carrier_table(&self) -> &[Complex32] {
        self.carrier
    }

    /// One SPAD's baseband grid `Y[n]` (`n < L`, then `EXTRA` wrapped copies) from its band
    /// spectrum `hg` (J values): the band placed in bit-reversed order, then the radix-2
    /// decimation-in-time stages of an inverse FFT. The reference of the fused synthesis
    /// every path runs (`synthesise_fused`: the same sums, 25–30 % fewer
    /// instructions), checked against it and against the direct sum by the unit tests.
    #[cfg(test)]
    pub(crate) fn synthesise(&self, hg: &[Complex32], y: &mut [Complex32]) {
        let l = self.grid.len;
        let shift = usize::BITS - self.grid.bits;
        let mask = l - 1;
        y.fill(Complex32::new(0.0, 0.0));
        let mut k = self.grid.first;
        for h in hg {
            // `shift` ≥ 1 (L ≤ 2²⁴); reverse_bits of k < L over log₂L bits.
            let r = k.reverse_bits().checked_shr(shift).unwrap_or(0);
            if let Some(v) = y.get_mut(r) {
                *v = *h;
            }
            k = (k + 1) & mask;
        }
        let Some((grid, extra)) = y.split_at_mut_checked(l) else {
            return;
        };
        // Stages h = 1 and 2 together (twiddles 1 and i): one radix-4 pass.
        for q in grid.as_chunks_mut::<4>().0 {
            let (a0, a1) = (q[0] + q[1], q[0] - q[1]);
            let (a2, a3) = (q[2] + q[3], q[2] - q[3]);
            let ia3 = Complex32::new(-a3.im, a3.re);
            *q = [a0 + a2, a1 + ia3, a0 - a2, a1 - ia3];
        }
        let mut h = 4;
        while h < l {
            let (Some(tw), Some(size)) = (
                self.twiddle.get(h - 1..2 * h - 1),
                core::num::NonZeroUsize::new(2 * h),
            ) else {
                break;
            };
            for block in grid.chunks_exact_mut(size.get()) {
                let (a, b) = block.split_at_mut(h);
                for ((a, b), w) in a.iter_mut().zip(b.iter_mut()).zip(tw) {
                    let (av, t) = (*a, *b * *w);
                    *a = av + t;
                    *b = av - t;
                }
            }
            h *= 2;
        }
        for (e, g) in extra.iter_mut().zip(grid.iter()) {
            *e = *g;
        }
    }
}

/// Reads one SPAD's baseband grid (made by [`Lookup::baseband`]) at any path time: the
/// cubic interpolation and carrier restoration of the module docs, with the grid constants
/// converted to `f32` once ([`Lookup::reader`]). `Copy`; cost per read: one `f32→u32`
/// conversion, four Lagrange weights, four complex loads, one carrier table entry and one
/// small-phase polynomial (no square root, no division, no `f64`).
#[derive(Clone, Copy, Debug)]
pub struct GridReader<'l> {
    carrier: &'l [Complex32],
    /// Grid points per metre `L/(NΔt)`.
    per_m: f32,
    /// Carrier turns per grid step `k_d/L`.
    theta: f32,
    mask: usize,
}

impl GridReader<'_> {
    /// `Z_s(τ) = Σ_j hg[j]·e^{iν_j τ}` (module docs) read from the baseband grid `y` at the
    /// path time `tau ≥ 0` (m), within [`LookupGrid::bound`] per unit of `Σ_j |hg[j]|/Ĝ_j`.
    /// The grid is `NΔt`-periodic, so any `τ ≥ 0` is valid; a negative or NaN `τ` reads
    /// node 0, and a `y` shorter than [`Lookup::grid_buf_len`] reads 0 (never a panic).
    #[inline(always)]
    pub fn read(&self, y: &[Complex32], tau: f32) -> Complex32 {
        // τ ≥ 0: the cast floors (and saturates at u32::MAX, masked below).
        let x = tau * self.per_m;
        let i = x as u32 as usize;
        let t = x - i as f32;
        let start = i.wrapping_sub(1) & self.mask;
        let (Some(q), Some(c)) = (
            y.get(start..).and_then(|q| q.first_chunk::<4>()),
            self.carrier.get(i & self.mask),
        ) else {
            return Complex32::new(0.0, 0.0);
        };
        let w = lagrange4(t);
        let base = q[0] * w[0] + q[1] * w[1] + q[2] * w[2] + q[3] * w[3];
        base * (*c * cis_small_turns(self.theta * t))
    }
}

impl Lookup<'_> {
    /// Length in complex values of one SPAD's baseband grid buffer: `L + 3` (the grid and the
    /// wrapped copies the 4-point stencil reads past its end).
    pub const fn grid_buf_len(grid: &LookupGrid) -> usize {
        grid.len + EXTRA
    }

    /// Synthesises the baseband grid `Y[n] = Σ_j hg[j]·e^{2πi(k_lo + j − k_d)n/L}` of one
    /// band spectrum `hg` (J values, sign convention A of the module docs) into `y`, for
    /// reading with [`Lookup::reader`]: one inverse FFT of length `L`, `(L/2)·log₂L`
    /// butterflies. Any spectrum on the configuration's band works: a row's
    /// [`Row::band`](crate::Row::band) chunk, or a factorised column's `U[s][·]`
    /// ([`ColumnF32::finish_lookup`](crate::ColumnF32::finish_lookup)).
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if `hg` does not have `J` values or `y` not
    /// [`Lookup::grid_buf_len`]; [`ArgumentError::Incompatible`] for an [`Interpolant::Hermite`] grid
    /// (the reader is the Lagrange cubic); `y` is unchanged then.
    pub fn baseband(&self, hg: &[Complex32], y: &mut [Complex32]) -> Result<(), ArgumentError> {
        if self.grid.interp != Interpolant::Lagrange {
            return Err(ArgumentError::Incompatible(
                "a Hermite lookup grid (the reader is the Lagrange cubic)",
            ));
        }
        check_len("band spectrum", self.grid.cfg.bins(), hg.len())?;
        check_len("grid buffer", Self::grid_buf_len(&self.grid), y.len())?;
        synthesise_fused(self, hg, y);
        Ok(())
    }

    /// The reader of the grids synthesised by [`Lookup::baseband`] (constants in `f32`, made
    /// once: hoist it out of per-pair loops).
    pub fn reader(&self) -> GridReader<'_> {
        GridReader {
            carrier: self.carrier,
            per_m: (self.grid.len as f64 / self.grid.cfg.span()) as f32,
            theta: (self.grid.k_d as f64 / self.grid.len as f64) as f32,
            mask: self.grid.len - 1,
        }
    }
}

impl Lookup<'_> {
    /// [`Lookup::reader`] without `f64` arithmetic, for the per-scan paths on an FPU without
    /// double precision: from `inv_span = (1/(NΔt)) as f32`, the same bits (`L` is a power
    /// of two, so `L·fl(1/span) = fl(L/span)` and `fl(k_d)/L = fl(k_d/L)`, `|k_d| < 2²⁴`).
    pub(crate) fn reader_f32(&self, inv_span: f32) -> GridReader<'_> {
        let len = self.grid.len as u32;
        GridReader {
            carrier: self.carrier,
            per_m: len as f32 * inv_span,
            theta: self.grid.k_d as i32 as f32 / len as f32,
            mask: self.grid.len - 1,
        }
    }
}

/// One SPAD's baseband grid `Y[n]` (`n < L`, then wrapped copies up to `y.len()`, at most
/// `L`) from its band spectrum `hg`: the inverse FFT of the band placed in bit-reversed
/// order (the unit tests' radix-2 `Lookup::synthesise`), with the radix-2 stages after the first radix-4
/// pass fused in pairs (`h`, `2h`): each group of four values is loaded and stored once per
/// two stages, and the second stage's odd twiddle `e^{iπ(k+h)/2h} = i·e^{iπk/2h}` is a
/// rotation, so three complex products per four butterflies instead of four. Same sums,
/// other rounding (within the FFT's `f32` error).
pub(crate) fn synthesise_fused(lookup: &Lookup<'_>, hg: &[Complex32], y: &mut [Complex32]) {
    let grid = lookup.grid();
    let l = grid.len();
    let bits = l.trailing_zeros();
    let shift = usize::BITS - bits;
    let mask = l - 1;
    let cfg = grid.config();
    let mut k = (cfg.k_lo() - grid.carrier_bin()).rem_euclid(l.max(1) as i64) as usize;
    y.fill(Complex32::new(0.0, 0.0));
    for h in hg {
        let r = k.reverse_bits().checked_shr(shift).unwrap_or(0);
        if let Some(v) = y.get_mut(r) {
            *v = *h;
        }
        k = (k + 1) & mask;
    }
    let Some((g, extra)) = y.split_at_mut_checked(l) else {
        return;
    };
    for q in g.as_chunks_mut::<4>().0 {
        let (a0, a1) = (q[0] + q[1], q[0] - q[1]);
        let (a2, a3) = (q[2] + q[3], q[2] - q[3]);
        let ia3 = Complex32::new(-a3.im, a3.re);
        *q = [a0 + a2, a1 + ia3, a0 - a2, a1 - ia3];
    }
    let tw = lookup.twiddle_table();
    let mut h = 4;
    while 4 * h <= l {
        let (Some(w1), Some(w2), Some(size)) = (
            tw.get(h - 1..2 * h - 1),
            tw.get(2 * h - 1..3 * h - 1),
            core::num::NonZeroUsize::new(4 * h),
        ) else {
            break;
        };
        for block in g.chunks_exact_mut(size.get()) {
            let Some((q01, q23)) = block.split_at_mut_checked(2 * h) else {
                return;
            };
            let (Some((q0, q1)), Some((q2, q3))) =
                (q01.split_at_mut_checked(h), q23.split_at_mut_checked(h))
            else {
                return;
            };
            for ((((a0, a1), (a2, a3)), w1), w2) in q0
                .iter_mut()
                .zip(q1.iter_mut())
                .zip(q2.iter_mut().zip(q3.iter_mut()))
                .zip(w1)
                .zip(w2)
            {
                let (t1, t3) = (*a1 * *w1, *a3 * *w1);
                let (a, b) = (*a0 + t1, *a0 - t1);
                let (c, d) = (*a2 + t3, *a2 - t3);
                let (tc, td) = (c * *w2, d * *w2);
                let itd = Complex32::new(-td.im, td.re);
                *a0 = a + tc;
                *a2 = a - tc;
                *a1 = b + itd;
                *a3 = b - itd;
            }
        }
        h *= 4;
    }
    if h < l {
        let (Some(w), Some(size)) = (
            tw.get(h - 1..2 * h - 1),
            core::num::NonZeroUsize::new(2 * h),
        ) else {
            return;
        };
        for block in g.chunks_exact_mut(size.get()) {
            let Some((a, b)) = block.split_at_mut_checked(h) else {
                return;
            };
            for ((a, b), w) in a.iter_mut().zip(b.iter_mut()).zip(w) {
                let (av, t) = (*a, *b * *w);
                *a = av + t;
                *b = av - t;
            }
        }
    }
    for (e, v) in extra.iter_mut().zip(g.iter()) {
        *e = *v;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Params;

    use super::super::grid::LookupParams;
    use crate::config::Config;

    fn cfg() -> Config {
        Config::try_new(&Params::new(0.2, 64, 0.01)).unwrap()
    }

    /// `reader_f32` (no `f64`) has the same constants as `reader`.
    #[test]
    fn reader_f32_is_reader() {
        for (lam, nt, dt) in [(0.13, 255, 0.0255), (0.2, 64, 0.01), (0.1, 1000, 0.003)] {
            let c = Config::try_new(&Params::new(lam, nt, dt)).unwrap();
            let grid = LookupGrid::try_new(&c, &LookupParams::new()).unwrap();
            let mut t = [0.0f32; 4 * 2048];
            let t = &mut t[..Lookup::tables_len(&grid)];
            let lookup = Lookup::new(&grid, t).unwrap();
            let (a, b) = (lookup.reader(), lookup.reader_f32((1.0 / c.span()) as f32));
            assert_eq!(a.per_m.to_bits(), b.per_m.to_bits());
            assert_eq!(a.theta.to_bits(), b.theta.to_bits());
            assert_eq!(a.mask, b.mask);
        }
    }

    /// The inverse FFT synthesis, radix-2 and fused, equals the direct sum
    /// `Σ_j HG_j e^{2πi(k_j − k_d)n/L}`.
    #[test]
    fn synthesis_matches_direct_sum() {
        let c = cfg();
        let grid = LookupGrid::try_new(&c, &LookupParams::new()).unwrap();
        let l = grid.len();
        let mut tables = [0.0f32; 4 * 512];
        let lookup = Lookup::new(&grid, &mut tables[..4 * l]).unwrap();
        let mut hg = [Complex32::new(0.0, 0.0); 64];
        let j = c.bins();
        assert!(j <= 64 && l <= 512);
        for (i, h) in hg.iter_mut().take(j).enumerate() {
            *h = Complex32::new(libm::sinf(i as f32 * 1.3), libm::cosf(i as f32 * 0.7));
        }
        let mut y = [Complex32::new(0.0, 0.0); 512 + EXTRA];
        lookup.synthesise(&hg[..j], &mut y[..l + EXTRA]);
        let mut fused = [Complex32::new(0.0, 0.0); 512 + EXTRA];
        synthesise_fused(&lookup, &hg[..j], &mut fused[..l + EXTRA]);
        let mut worst = 0.0f64;
        for (n, (yn, fn_)) in y.iter().zip(&fused).enumerate().take(l + EXTRA) {
            let (mut re, mut im) = (0.0f64, 0.0f64);
            for (i, h) in hg.iter().take(j).enumerate() {
                let k = c.k_lo() + i as i64 - grid.k_d;
                let a = core::f64::consts::TAU * (k * n as i64) as f64 / l as f64;
                let (s, co) = (libm::sin(a), libm::cos(a));
                re += h.re as f64 * co - h.im as f64 * s;
                im += h.re as f64 * s + h.im as f64 * co;
            }
            let e = libm::hypot(yn.re as f64 - re, yn.im as f64 - im);
            let f = libm::hypot(fn_.re as f64 - re, fn_.im as f64 - im);
            worst = worst.max(e).max(f);
        }
        assert!(worst < 1e-4 * j as f64, "worst {worst}");
    }

    /// The fused synthesis equals [`Lookup::synthesise`] to `f32` rounding, for grids with
    /// an even and an odd number of radix-2 stages after the radix-4 pass.
    #[test]
    fn fused_synthesis_matches_radix2() {
        let c = Config::try_new(&Params::new(0.2, 64, 0.01)).unwrap();
        for len in [256usize, 512, 1024] {
            let p = LookupParams {
                tolerance: 1.0,
                grid_len: Some(len),
                ..LookupParams::new()
            };
            let grid = LookupGrid::try_new(&c, &p).unwrap();
            let mut tables = [0.0f32; 4 * 1024];
            let lookup = Lookup::new(&grid, &mut tables[..4 * len]).unwrap();
            let j = c.bins();
            let mut hg = [Complex32::new(0.0, 0.0); 64];
            assert!(j <= 64);
            for (i, h) in hg.iter_mut().take(j).enumerate() {
                *h = Complex32::new(libm::sinf(i as f32 * 1.3), libm::cosf(i as f32 * 0.7));
            }
            let mut a = [Complex32::new(0.0, 0.0); 1024 + EXTRA];
            let mut b = [Complex32::new(0.0, 0.0); 1024 + EXTRA];
            lookup.synthesise(&hg[..j], &mut a[..len + EXTRA]);
            synthesise_fused(&lookup, &hg[..j], &mut b[..len + EXTRA]);
            let peak2 = a.iter().fold(0.0f32, |m, z| m.max(z.norm_sqr()));
            assert!(peak2 > 1.0);
            for (x, y) in a.iter().zip(&b).take(len + EXTRA) {
                assert!((x - y).norm_sqr() <= 1e-10 * peak2, "L {len}: {x} vs {y}");
            }
        }
    }
}
