//! The factorised Gaussian column `T(x_a, ·)` with **`f32` state and no
//! `f64` arithmetic**, for FPUs without double precision (Cortex-M4F, FPv4-SP), where every
//! `f64` operation of [`Probe`](crate::Probe)'s accumulators is a soft-float call.
//!
//! Same maths and conventions as the factorised column of [`Probe`](crate::Probe) (module
//! docs of `band/probe.rs`): per row `U[s][j] += w(d_la)·e^{iν_j d_la}·HG_ls[j]`, and at the
//! end `A(b) = Σ_s w(d_bs)·Σ_j e^{iν_j(d_ab + d_bs)}·U[s][j]`, `T = |A|²`.
//!
//! # Error bound
//!
//! The state is summed over the R rows of a scan, the one place where `f32` loses accuracy
//! with the scan's length: a plain `f32` sum errs by up to `(R − 1)·u·Σ_l |t_l|` (`u = 2⁻²⁴`;
//! 576 rows: 3.4e-5). Each component of `U` is therefore a **Kahan-compensated** sum (a sum
//! and its running compensation, 4 `f32` per complex value): its error is
//! `≤ 2u·Σ_l |t_l| + O(R·u²)·Σ_l |t_l|`, independent of R (Higham, *Accuracy and Stability of
//! Numerical Algorithms*, §4.3). Each row's term `t_l = HG·p` adds `≈ 2√2·u` (one complex
//! product) and its phase `p_j` the recurrence's `≈ J·u` (two `cis_turns` seeds, `p *= step`).
//! `finish` sums J band terms and Ks SPADs in `f32` with the same phase recurrence as the
//! diagonal: `(J + Ks)·u` of the element's scale. In all, relative to the element's scale
//! `S(a, b) = Σ_l Σ_s w_l w_s Σ_n |H_ls[n]|`:
//! `|A_f32 − A_f64| ≲ u·(2J + Ks + 8)·S` on top of the band path's own `f32` errors (the
//! phase arguments `≈ 2π·u·Φ`, Φ the largest phase in turns) — checked against the `f64`
//! time-domain reference by `tests/proptest_kernel.rs` (`column_f32`).
//!
//! # Cost and memory
//!
//! State: [`ColumnF32::state_len`] = `4·Ks·J + 2J` `f32` (the same bytes as the `f64`
//! [`Probe`](crate::Probe) column's `2J(Ks + 1)` `f64`). Per row: `Ks·J` complex
//! multiply-adds into compensated sums (≈ 26 instructions each on the M4F; 0.1 M per row
//! for the paper's 28 SPADs and J = 137). `finish`: `Kb·Ks·J` band terms (470 M
//! instructions on a Cortex-M4F for a 64×64 slice, 28 SPADs, J = 137: 4.1 s at 168 MHz).
//!
//! # Two finishes
//!
//! * [`ColumnF32::finish`], the **band sum**: `J` terms per (voxel, SPAD) pair, no extra
//!   memory. Exact up to `f32` rounding (the bound above).
//! * [`ColumnF32::finish_lookup`], the **lookup path** of [`crate::LookupProbe`] applied to
//!   the factorised state: per SPAD, `u_s(τ) = Σ_j U[s][j]·e^{iν_j τ}` is synthesised once on
//!   the [`LookupGrid`] by an inverse FFT ([`Lookup::baseband`]), and each voxel reads
//!   `u_s(d_ab + d_bs)` in O(1) by cubic interpolation with the carrier restored
//!   ([`crate::GridReader`]). Its error adds `η·S(a, b)` (`η =` [`LookupGrid::bound`], e.g.
//!   3.4e-6 for L = 1024 on the paper's setup) to the bound above — derivation in
//!   [`ColumnF32::finish_lookup`]. Scratch `2(L + 3) + 2Kv` `f32`; cost `Ks` FFTs of length
//!   `L` plus `Kv·Ks` O(1) reads: 21.8 M instructions for the 64×64 slice above (0.19 s on a
//!   168 MHz Cortex-M4F).
//!
//! Neither `push_row` nor the finishes do any `f64` arithmetic: the configuration's
//! constants are converted to `f32` once, by [`ColumnF32::new`].

use super::probe::{band_consts, band_sum};
use super::row::Row;
use super::scan::{Scan, as_complex};
use crate::config::{Config, Legs, Point, Weights};
use crate::error::{ArgumentError, check_len, check_points};
use crate::geometry::{alias_window, dist, leaves_window, widen};
use crate::lookup::grid::LookupGrid;
use crate::lookup::pair::dist_fast;
use crate::lookup::table::Lookup;
use crate::phase::cis_turns;
use crate::report::Report;
use crate::sample::Sample;
use num_complex::Complex32;

/// Factorised Gaussian column with `f32` Kahan-compensated state (see the module docs).
///
/// ```
/// use vltm_kernel::{ColumnF32, Config, Params, RowBuffer, Scan};
/// let cfg = Config::try_new(&Params::new(0.2, 128, 0.01)).unwrap();
/// let spads = [[0.0f32, 0.0, 0.0]];
/// let mut tables = vec![0.0; Scan::tables_len(&cfg, 1)];
/// let scan = Scan::new(&cfg, &spads, &mut tables).unwrap();
/// let mut state = vec![0.0f32; ColumnF32::state_len(&cfg, 1)];
/// let mut col = ColumnF32::new(&scan, [0.0, 0.0, 0.3], &mut state).unwrap();
/// let mut buf = vec![0.0; RowBuffer::len(&cfg, 1)];
/// let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
/// let mut h = [0u16; 128];
/// h[100] = 50; // a return at 1.00 m: laser → x_a (0.3 m) → x_b = (0, 0, 0.5) (0.2 m) → SPAD (0.5 m)
/// let row = rows.load(&scan, [0.0, 0.0, 0.0], &h).unwrap();
/// col.push_row(&scan, &row).unwrap();
/// let voxels = [[0.0f32, 0.0, 0.5], [0.0, 0.0, 0.8]]; // paths of 1.0 m and 1.6 m
/// let mut out = [0.0f32; 2];
/// col.finish(&scan, &voxels, &mut out).unwrap();
/// assert!(out[0] > 10.0 * out[1]);
/// ```
#[derive(Debug)]
pub struct ColumnF32<'m> {
    focus: Point,
    /// `U` sums (`Ks·J`), then their compensations (`Ks·J`), then the row's phases (`J`).
    sums: &'m mut [Complex32],
    comps: &'m mut [Complex32],
    phase: &'m mut [Complex32],
    report: Report,
    /// Min / max over rows of the projector leg `d1_l + |x_l − x_a|` (m).
    leg_range: (f32, f32),
    cfg: Config,
    n_spads: usize,
    /// The configuration's constants in `f32`, converted once by [`ColumnF32::new`] so that
    /// `push_row` and the finishes do no `f64` arithmetic (soft float on a Cortex-M4F).
    k: Consts,
}

/// [`Config`]'s constants as `push_row` and `finish` use them, in `f32` (same bits as the
/// per-call conversions they replace).
#[derive(Clone, Copy, Debug)]
struct Consts {
    /// `k_lo/(NΔt)` and `1/(NΔt)` ([`band_consts`]).
    klo: f32,
    inv: f32,
    /// The laser origin of [`Legs::FirstAndLast`], `None` for wall-to-wall legs.
    origin: Option<Point>,
    /// `d_min` (m) and whether the leg weight is `1/max(d, d_min)` (else 1).
    d_min: f32,
    inv_weight: bool,
    /// [`alias_window`] (m).
    window: (f32, f32),
}

impl Consts {
    fn new(cfg: &Config) -> Self {
        let (klo, inv) = band_consts(cfg);
        let (w_lo, w_hi) = alias_window(cfg);
        Self {
            klo,
            inv,
            origin: match cfg.legs() {
                Legs::WallToWall => None,
                Legs::FirstAndLast { laser_origin, .. } => Some([
                    laser_origin[0] as f32,
                    laser_origin[1] as f32,
                    laser_origin[2] as f32,
                ]),
            },
            d_min: cfg.params().d_min as f32,
            inv_weight: matches!(cfg.weights(), Weights::Inv),
            window: (w_lo as f32, w_hi as f32),
        }
    }

    /// [`Config::weight`] with the constants hoisted (same bits; `max` by comparison, as
    /// `f32::max` is an out-of-line `fmaxf` on a Cortex-M).
    #[inline(always)]
    fn weight(&self, d: f32) -> f32 {
        if self.inv_weight {
            1.0 / if d > self.d_min { d } else { self.d_min }
        } else {
            1.0
        }
    }
}

/// One compensated addition `s + x` (Kahan): `c` carries what `s` could not hold. Rust does
/// not reassociate floating-point operations, so the compensation survives optimisation.
#[inline(always)]
fn kahan(s: &mut f32, c: &mut f32, x: f32) {
    let y = x - *c;
    let t = *s + y;
    *c = (t - *s) - y;
    *s = t;
}

impl<'m> ColumnF32<'m> {
    /// Length in `f32` of the state: `4·Ks·J + 2J`.
    pub const fn state_len(cfg: &Config, n_spads: usize) -> usize {
        n_spads
            .saturating_mul(4)
            .saturating_add(2)
            .saturating_mul(cfg.bins())
    }

    /// A zeroed column for the focus `focus` with its state in `state`.
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if `state` does not have [`ColumnF32::state_len`] elements;
    /// [`ArgumentError::NonFinite`] for a non-finite focus.
    pub fn new(scan: &Scan<'_>, focus: Point, state: &'m mut [f32]) -> Result<Self, ArgumentError> {
        let cfg = scan.config();
        let ks = scan.spads().len();
        let need = Self::state_len(cfg, ks);
        check_len("state", need, state.len())?;
        check_points("focus", &[focus])?;
        state.fill(0.0);
        let too_short = ArgumentError::Length {
            what: "state",
            expected: need,
            found: state.len(),
        };
        let n = 2 * ks * cfg.bins();
        let (sums, rest) = state.split_at_mut_checked(n).ok_or(too_short)?;
        let (comps, phase) = rest.split_at_mut_checked(n).ok_or(too_short)?;
        Ok(Self {
            focus,
            sums: as_complex("state", sums)?,
            comps: as_complex("state", comps)?,
            phase: as_complex("state", phase)?,
            report: Report::default(),
            leg_range: (f32::INFINITY, f32::NEG_INFINITY),
            cfg: *cfg,
            n_spads: ks,
            k: Consts::new(cfg),
        })
    }

    /// The focus `x_a`.
    pub const fn focus(&self) -> Point {
        self.focus
    }
    /// Counters so far (`aliased` is computed by [`ColumnF32::finish`]).
    pub const fn report(&self) -> Report {
        self.report
    }
    /// The compensated sums `U[s·J + j]` (without their compensations, which are below
    /// half an ulp of each sum).
    pub fn spectra(&self) -> &[Complex32] {
        self.sums
    }

    /// Adds one laser row: `Ks·J` complex multiply-adds into the compensated sums, two phase
    /// seeds and one weight; no `f64`. Infallible on data values and panic-free.
    ///
    /// # Errors
    /// [`ArgumentError::Incompatible`] if `scan` has another configuration or SPAD count than the one
    /// the column was made for; [`ArgumentError::Length`] if `row` was loaded for a scan of another
    /// size. Nothing is changed then.
    pub fn push_row<T: Sample>(
        &mut self,
        scan: &Scan<'_>,
        row: &Row<'_, T>,
    ) -> Result<(), ArgumentError> {
        let cfg = scan.config();
        if !cfg.same(&self.cfg) || scan.spads().len() != self.n_spads {
            return Err(ArgumentError::Incompatible("scan of another configuration"));
        }
        let j = cfg.bins().max(1);
        check_len("row spectra", self.sums.len(), row.band().len())?;
        check_len("row histograms", cfg.nt(), row.nt())?;
        let laser = row.laser();
        let d_la = dist(&laser, &self.focus);
        let d1 = match &self.k.origin {
            None => 0.0,
            Some(origin) => dist(&laser, origin),
        };
        let leg = d1 + d_la;
        self.leg_range = widen(self.leg_range, leg);
        let k = &self.k;
        let mut p = cis_turns(k.klo * d_la) * k.weight(d_la);
        let step = cis_turns(k.inv * d_la);
        for ph in self.phase.iter_mut() {
            *ph = p;
            p *= step;
        }
        // Per SPAD by index, not a zip of two `chunks_exact_mut`: an out-of-line `Zip::new`
        // of those keeps `size_hint`'s division by the chunk length (a panicking branch for
        // the panic-never link, whatever `j ≥ 1` is).
        for (s, hg) in row.band().chunks_exact(j).enumerate() {
            let range = s * j..(s + 1) * j;
            let (Some(us), Some(cs)) =
                (self.sums.get_mut(range.clone()), self.comps.get_mut(range))
            else {
                break;
            };
            for (((u, c), h), ph) in us
                .iter_mut()
                .zip(cs.iter_mut())
                .zip(hg)
                .zip(self.phase.iter())
            {
                let t = *h * *ph;
                kahan(&mut u.re, &mut c.re, t.re);
                kahan(&mut u.im, &mut c.im, t.im);
            }
        }
        self.report.count_row(row);
        Ok(())
    }

    /// Images `voxels`: `out[i] = T(x_a, voxels[i]) = |A|²`, all in `f32`; returns the
    /// counters with [`Report::aliased`] (voxels whose path times left
    /// [`Config::alias_free`]). Does not change the state. Cost `Kb·Ks·J` band terms.
    ///
    /// # Errors
    /// [`ArgumentError::Incompatible`] for a scan of another configuration; [`ArgumentError::Length`] if
    /// `out.len() ≠ voxels.len()`; [`ArgumentError::NonFinite`] for a non-finite voxel.
    pub fn finish(
        &self,
        scan: &Scan<'_>,
        voxels: &[Point],
        out: &mut [f32],
    ) -> Result<Report, ArgumentError> {
        let cfg = scan.config();
        if !cfg.same(&self.cfg) || scan.spads().len() != self.n_spads {
            return Err(ArgumentError::Incompatible("scan of another configuration"));
        }
        check_len("out", voxels.len(), out.len())?;
        check_points("voxels", voxels)?;
        let j = cfg.bins().max(1);
        let Consts {
            klo, inv, window, ..
        } = self.k;
        let mut report = self.report;
        for (o, b) in out.iter_mut().zip(voxels) {
            let d_ab = dist(&self.focus, b);
            let mut sum = Complex32::new(0.0, 0.0);
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            for ((sp, us), d4) in scan
                .spads()
                .iter()
                .zip(self.sums.chunks_exact(j))
                .zip(scan.sensor_legs())
            {
                let d_bs = dist(b, sp);
                let tau = d_ab + d_bs;
                (lo, hi) = widen((lo, hi), tau + d4);
                sum += band_sum(us, tau, klo, inv) * self.k.weight(d_bs);
            }
            if leaves_window(window, self.leg_range, (lo, hi)) {
                report.aliased += 1;
            }
            *o = sum.norm_sqr();
        }
        Ok(report)
    }
}

impl ColumnF32<'_> {
    /// Length in `f32` of [`ColumnF32::finish_lookup`]'s scratch: `2(L + 3) + 2Kv` (one
    /// SPAD's baseband grid, then the voxels' complex sums).
    pub const fn lookup_scratch_len(grid: &LookupGrid, n_voxels: usize) -> usize {
        (2 * Lookup::grid_buf_len(grid)).saturating_add(n_voxels.saturating_mul(2))
    }

    /// [`ColumnF32::finish`] on the **lookup path**: the same image `out[i] = T(x_a, b_i)`
    /// and counters, at O(1) per (voxel, SPAD) pair instead of `J` band terms.
    ///
    /// `A(b) = Σ_s w(d_bs)·u_s(d_ab + d_bs)` with `u_s(τ) = Σ_j U[s][j]·e^{iν_j τ}`, so per
    /// SPAD `u_s` is synthesised once on the grid of `lookup` ([`Lookup::baseband`]: one
    /// inverse FFT of length `L`), and each voxel reads it at its path time
    /// ([`GridReader::read`](crate::GridReader::read): cubic Lagrange interpolation of the
    /// baseband, carrier restored analytically). SPAD-outer: one grid in memory at a time;
    /// `out` holds `d_ab` (and the alias flag in its sign bit) until the last SPAD.
    ///
    /// **Error bound** (module docs of [`Lookup`] for the derivation): per pair
    /// `|u_lookup(τ) − u_band(τ)| ≤ (3/128)·δ⁴·Σ_j |U[s][j]|·(ν_j − Ω_d)⁴`, and
    /// `|U[s][j]| ≤ Ĝ_j·Σ_l w_l‖h_ls‖₁`, so `|A_lookup − A_band| ≤ η·S(a, b)` with
    /// `η =` [`LookupGrid::bound`] and `S(a, b) = Σ_l Σ_s w_l w_s‖h_ls‖₁` — the lookup
    /// diagonal's bound, on top of [`ColumnF32::finish`]'s own; plus the inverse FFT's
    /// `f32` rounding (`≈ u·log₂L` of `Σ_j |U[s][j]|`) and the `f32` grid position `τ/δ`
    /// (a carrier phase error of `≈ 2π·u·k_d τ/(NΔt)` rad, as the band sum's phase
    /// argument). Both finishes evaluate the same `NΔt`-periodic band sum, so they alias
    /// alike, and [`Report::aliased`] is the same test as [`ColumnF32::finish`]'s (with the
    /// lookup path's distance, within 1 ulp of `finish`'s).
    ///
    /// Cost: `Ks` inverse FFTs plus `Kv·Ks` pairs (a distance with a Newton square root, the
    /// alias test, one grid read, one weight); no `f64`. For a 64×64 slice, 28 SPADs, J =
    /// 137, L = 1024: 21.8 M instructions on a Cortex-M4F, against 467 M for the band sum.
    ///
    /// ```
    /// use vltm_kernel::{ColumnF32, Config, Lookup, LookupGrid, LookupParams, Params, RowBuffer, Scan};
    /// let cfg = Config::try_new(&Params::new(0.2, 128, 0.01)).unwrap();
    /// let spads = [[0.0f32, 0.0, 0.0]];
    /// let mut tables = vec![0.0; Scan::tables_len(&cfg, 1)];
    /// let scan = Scan::new(&cfg, &spads, &mut tables).unwrap();
    /// let mut state = vec![0.0f32; ColumnF32::state_len(&cfg, 1)];
    /// let mut col = ColumnF32::new(&scan, [0.0, 0.0, 0.3], &mut state).unwrap();
    /// let mut buf = vec![0.0; RowBuffer::len(&cfg, 1)];
    /// let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
    /// let mut h = [0u16; 128];
    /// h[100] = 50;
    /// let row = rows.load(&scan, [0.0, 0.0, 0.0], &h).unwrap();
    /// col.push_row(&scan, &row).unwrap();
    /// let grid = LookupGrid::try_new(&cfg, &LookupParams::new()).unwrap();
    /// let mut lt = vec![0.0; Lookup::tables_len(&grid)];
    /// let lookup = Lookup::new(&grid, &mut lt).unwrap();
    /// let voxels = [[0.0f32, 0.0, 0.5], [0.0, 0.0, 0.8]];
    /// let mut scratch = vec![0.0; ColumnF32::lookup_scratch_len(&grid, 2)];
    /// let (mut fast, mut band) = ([0.0f32; 2], [0.0f32; 2]);
    /// col.finish_lookup(&scan, &lookup, &voxels, &mut scratch, &mut fast).unwrap();
    /// col.finish(&scan, &voxels, &mut band).unwrap();
    /// assert!((fast[0].sqrt() - band[0].sqrt()).abs() <= 1e-4 * band[0].sqrt());
    /// ```
    ///
    /// # Errors
    /// [`ArgumentError::Incompatible`] for a scan or lookup grid of another configuration;
    /// [`ArgumentError::Length`] if `out.len() ≠ voxels.len()` or `scratch` does not have
    /// [`ColumnF32::lookup_scratch_len`] elements; [`ArgumentError::NonFinite`] for a non-finite
    /// voxel. Nothing is written then.
    pub fn finish_lookup(
        &self,
        scan: &Scan<'_>,
        lookup: &Lookup<'_>,
        voxels: &[Point],
        scratch: &mut [f32],
        out: &mut [f32],
    ) -> Result<Report, ArgumentError> {
        let cfg = scan.config();
        if !cfg.same(&self.cfg) || scan.spads().len() != self.n_spads {
            return Err(ArgumentError::Incompatible("scan of another configuration"));
        }
        let grid = lookup.grid();
        if !grid.config().same(&self.cfg) {
            return Err(ArgumentError::Incompatible(
                "lookup grid of another configuration",
            ));
        }
        if grid.interpolant() != crate::Interpolant::Lagrange {
            return Err(ArgumentError::Incompatible(
                "a Hermite lookup grid (finish_lookup reads the Lagrange cubic)",
            ));
        }
        let kv = voxels.len();
        check_len("out", kv, out.len())?;
        let need = Self::lookup_scratch_len(grid, kv);
        check_len("scratch", need, scratch.len())?;
        check_points("voxels", voxels)?;
        let short = ArgumentError::Length {
            what: "scratch",
            expected: need,
            found: scratch.len(),
        };
        let (g, sums) = scratch
            .split_at_mut_checked(2 * Lookup::grid_buf_len(grid))
            .ok_or(short)?;
        let y = as_complex("scratch", g)?;
        let sums = as_complex("scratch", sums)?;
        sums.fill(Complex32::new(0.0, 0.0));
        for (o, b) in out.iter_mut().zip(voxels) {
            *o = dist_fast(&self.focus, b);
        }
        let j = cfg.bins().max(1);
        let k = &self.k;
        let (window, legs) = (k.window, self.leg_range);
        let reader = lookup.reader_f32(k.inv);
        for ((sp, us), d4) in scan
            .spads()
            .iter()
            .zip(self.sums.chunks_exact(j))
            .zip(scan.sensor_legs())
        {
            lookup.baseband(us, y)?;
            let y: &[Complex32] = y;
            for ((o, b), sum) in out.iter_mut().zip(voxels).zip(sums.iter_mut()) {
                // `o` = d_ab ≥ 0, its sign bit the alias flag (set on the first SPAD whose
                // path time leaves the window; the same test as `finish`'s (min, max)
                // over SPADs, since `leg + x` is monotone in x).
                let d_ab = f32::from_bits(o.to_bits() & 0x7fff_ffff);
                let d_bs = dist_fast(b, sp);
                let tau = d_ab + d_bs;
                let x = tau + d4;
                if leaves_window(window, legs, (x, x)) {
                    *o = -d_ab;
                }
                *sum += reader.read(y, tau) * k.weight(d_bs);
            }
        }
        let mut report = self.report;
        for (o, sum) in out.iter_mut().zip(sums.iter()) {
            if o.is_sign_negative() {
                report.aliased += 1;
            }
            *o = sum.norm_sqr();
        }
        Ok(report)
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::band::row::RowBuffer;
    use crate::config::Params;
    use std::vec;

    /// The compensated state stays within a few ulp of the exact sum over 2¹⁷ identical rows
    /// (the exact sum is `R·t` in `f64`), where a plain `f32` sum of the same terms is off by
    /// orders of magnitude more: the Kahan bound of the module docs, with teeth.
    #[test]
    fn kahan_state_does_not_grow_with_rows() {
        let cfg = Config::try_new(&Params::new(0.2, 64, 0.01)).unwrap();
        let spads = [[0.05f32, 0.0, 0.0]];
        let mut tables = vec![0.0f32; Scan::tables_len(&cfg, 1)];
        let scan = Scan::new(&cfg, &spads, &mut tables).unwrap();
        let mut buf = vec![0.0f32; RowBuffer::len(&cfg, 1)];
        let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
        let mut h = [0u16; 64];
        h[30] = 7;
        h[31] = 3;
        let row = rows.load(&scan, [0.1, 0.0, 0.0], &h).unwrap();
        let mut state = vec![0.0f32; ColumnF32::state_len(&cfg, 1)];
        let mut col = ColumnF32::new(&scan, [0.0, 0.0, 0.4], &mut state).unwrap();
        let r = 1u32 << 17;
        for _ in 0..r {
            col.push_row(&scan, &row).unwrap();
        }
        // The row's terms, as push_row computes them (same f32 operations).
        let (klo, inv) = band_consts(&cfg);
        let d_la = dist(&row.laser(), &col.focus());
        let mut p = cis_turns(klo * d_la) * cfg.weight(d_la);
        let step = cis_turns(inv * d_la);
        let (mut worst_kahan, mut worst_naive) = (0.0f64, 0.0f64);
        for (u, hg) in col.spectra().iter().zip(row.band()) {
            let t = *hg * p;
            p *= step;
            let mut naive = Complex32::new(0.0, 0.0);
            for _ in 0..r {
                naive += t;
            }
            for (got, naive, t) in [(u.re, naive.re, t.re), (u.im, naive.im, t.im)] {
                let exact = f64::from(r) * f64::from(t);
                let scale = f64::from(r) * f64::from(t.abs()) * f64::from(f32::EPSILON);
                if scale > 0.0 {
                    worst_kahan = worst_kahan.max((f64::from(got) - exact).abs() / scale);
                    worst_naive = worst_naive.max((f64::from(naive) - exact).abs() / scale);
                }
            }
        }
        assert!(worst_kahan <= 1.0, "Kahan: {worst_kahan} ulp of R·|t|");
        assert!(
            worst_naive > 100.0,
            "naive: {worst_naive} (the test has no teeth)"
        );
    }
}

#[cfg(test)]
mod lookup_finish {
    extern crate std;
    use crate::{
        ArgumentError, ColumnF32, Config, Lookup, LookupGrid, LookupParams, Params, RowBuffer, Scan,
    };
    use std::vec;
    use std::vec::Vec;

    /// `finish_lookup` equals the band `finish` within `η·S` (plus `f32` rounding), on a
    /// column with several rows and SPADs; a grid half as fine has an error the bound of the
    /// fine grid does not cover (the comparison has teeth); bad buffers are refused.
    #[test]
    fn lookup_finish_matches_band_finish_within_eta() {
        let cfg = Config::try_new(&Params {
            t0: 0.4,
            ..Params::new(0.1, 128, 0.01)
        })
        .unwrap();
        let spads = [[-0.1f32, 0.0, 0.0], [0.0, 0.05, 0.0], [0.12, 0.0, 0.0]];
        let ks = spads.len();
        let mut tables = vec![0.0f32; Scan::tables_len(&cfg, ks)];
        let scan = Scan::new(&cfg, &spads, &mut tables).unwrap();
        let mut state = vec![0.0f32; ColumnF32::state_len(&cfg, ks)];
        let mut col = ColumnF32::new(&scan, [0.02, -0.03, 0.35], &mut state).unwrap();
        let mut buf = vec![0.0f32; RowBuffer::len(&cfg, ks)];
        let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
        let mut seed = 7u32;
        let mut norm1 = 0.0f64;
        for l in 0..5 {
            let h: Vec<u16> = (0..ks * 128)
                .map(|_| {
                    seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    (seed >> 27) as u16
                })
                .collect();
            norm1 += h.iter().map(|&x| f64::from(x)).sum::<f64>();
            let laser = [0.05 * l as f32 - 0.1, 0.02, 0.0];
            let row = rows.load(&scan, laser, &h).unwrap();
            col.push_row(&scan, &row).unwrap();
        }
        let voxels: Vec<[f32; 3]> = (0..40)
            .map(|i| {
                [
                    0.01 * i as f32 - 0.2,
                    0.003 * i as f32,
                    0.3 + 0.005 * i as f32,
                ]
            })
            .collect();
        let mut band = vec![0.0f32; voxels.len()];
        let rb = col.finish(&scan, &voxels, &mut band).unwrap();
        let mut worst = [0.0f64; 2];
        let mut bound = 0.0;
        for (i, len) in [1024usize, 256].into_iter().enumerate() {
            let grid = LookupGrid::try_new(
                &cfg,
                &LookupParams {
                    tolerance: 1.0,
                    grid_len: Some(len),
                    ..LookupParams::new()
                },
            )
            .unwrap();
            if i == 0 {
                // Weights ≤ 1/d_min-free here (all legs < 1 m: w ≤ 1/0.3); S ≤ w_max²·‖h‖₁.
                bound = grid.bound() * norm1 * (1.0 / 0.3f64).powi(2) + 1e-6 * norm1;
            }
            let mut lt = vec![0.0f32; Lookup::tables_len(&grid)];
            let lookup = Lookup::new(&grid, &mut lt).unwrap();
            let mut scratch = vec![0.0f32; ColumnF32::lookup_scratch_len(&grid, voxels.len())];
            let mut fast = vec![0.0f32; voxels.len()];
            let rf = col
                .finish_lookup(&scan, &lookup, &voxels, &mut scratch, &mut fast)
                .unwrap();
            assert_eq!(rf, rb);
            for (f, b) in fast.iter().zip(&band) {
                let e = (f64::from(f.sqrt()) - f64::from(b.sqrt())).abs();
                worst[i] = worst[i].max(e);
            }
            // Bad buffers: refused, nothing written.
            let mut short = vec![0.0f32; scratch.len() - 1];
            let mut o = vec![-1.0f32; voxels.len()];
            assert!(matches!(
                col.finish_lookup(&scan, &lookup, &voxels, &mut short, &mut o),
                Err(ArgumentError::Length {
                    what: "scratch",
                    ..
                })
            ));
            assert!(matches!(
                col.finish_lookup(&scan, &lookup, &voxels, &mut scratch, &mut o[1..]),
                Err(ArgumentError::Length { what: "out", .. })
            ));
            assert!(o.iter().all(|&x| x == -1.0));
        }
        assert!(worst[0] <= bound, "L = 1024: {} > {bound}", worst[0]);
        assert!(
            worst[1] > 10.0 * worst[0],
            "coarse grid {worst:?}: no teeth"
        );
        // A lookup grid of another configuration is refused.
        let other = Config::try_new(&Params::new(0.1, 128, 0.01)).unwrap();
        let g = LookupGrid::try_new(&other, &LookupParams::new()).unwrap();
        let mut lt = vec![0.0f32; Lookup::tables_len(&g)];
        let lookup = Lookup::new(&g, &mut lt).unwrap();
        let mut scratch = vec![0.0f32; ColumnF32::lookup_scratch_len(&g, voxels.len())];
        let mut o = vec![0.0f32; voxels.len()];
        assert!(matches!(
            col.finish_lookup(&scan, &lookup, &voxels, &mut scratch, &mut o),
            Err(ArgumentError::Incompatible(_))
        ));
    }
}

#[cfg(test)]
mod config_checks {
    extern crate std;
    use crate::{ArgumentError, ColumnF32, Config, Gate, Params, Probe, RowBuffer, Scan, Target};
    use std::vec;

    /// `Probe::push_row` and `ColumnF32::push_row` refuse a scan of another configuration (as
    /// `Probe::merge` does) and change nothing.
    #[test]
    fn push_row_rejects_a_scan_of_another_configuration() {
        let a = Config::try_new(&Params::new(0.2, 64, 0.01)).unwrap();
        let b = Config::try_new(&Params {
            t0: 0.1,
            ..Params::new(0.2, 64, 0.01)
        })
        .unwrap();
        let spads = [[0.0f32; 3]];
        let (mut ta, mut tb) = (
            vec![0.0; Scan::tables_len(&a, 1)],
            vec![0.0; Scan::tables_len(&b, 1)],
        );
        let (sa, sb) = (
            Scan::new(&a, &spads, &mut ta).unwrap(),
            Scan::new(&b, &spads, &mut tb).unwrap(),
        );
        let mut buf = vec![0.0; RowBuffer::len(&b, 1)];
        let mut rows = RowBuffer::new(&sb, &mut buf).unwrap();
        let row = rows.load(&sb, [0.0; 3], &[1u16; 64]).unwrap();
        let voxels = [[0.0f32, 0.0, 0.5]];
        let mut st = vec![0.0; Probe::state_len(&a, Target::Diagonal, Gate::Gaussian, 1, 1)];
        let mut probe =
            Probe::new(&sa, Target::Diagonal, Gate::Gaussian, &voxels, &mut st).unwrap();
        assert!(matches!(
            probe.push_row(&sb, &row),
            Err(ArgumentError::Incompatible(_))
        ));
        assert_eq!(probe.report().rows, 0);
        let mut s32 = vec![0.0f32; ColumnF32::state_len(&a, 1)];
        let mut col = ColumnF32::new(&sa, [0.0, 0.0, 0.3], &mut s32).unwrap();
        assert!(matches!(
            col.push_row(&sb, &row),
            Err(ArgumentError::Incompatible(_))
        ));
        assert_eq!(col.report().rows, 0);
    }
}
