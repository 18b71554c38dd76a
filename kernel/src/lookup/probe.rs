//! [`LookupProbe`]: the lookup path's Gaussian diagonal or column over a voxel list (method
//! and error bound in the module docs of `lookup/mod.rs`).
//!
//! # Cost and memory
//!
//! Per row: `Ks` inverse FFTs of length `L` (`(L/2)·log₂L` butterflies each; the band is
//! placed directly in bit-reversed order, so there is no permutation pass; after a radix-4
//! pass the radix-2 stages run fused in pairs, three complex products per four
//! butterflies), then `Kv·Ks`
//! pairs of O(1) work (a distance, the guard test, four Lagrange weights, four complex
//! loads, one table carrier, one small-phase polynomial, one weight), against the band
//! path's `Kv·Ks·14J` flops. Memory, all caller-owned: shared tables `4L` `f32`
//! ([`Lookup::tables_len`]: twiddles and carrier); per probe the state `4Kv` `f32` (the
//! bytes of the band diagonal's `2Kv` `f64`) and the scratch `2(L + 3) + 3Kv` `f32` ([`LookupProbe::scratch_len`]: the
//! SPAD's grid, the voxels' row sums and lead distances). SPAD-outer: one grid in memory at a
//! time. No allocation, no panic on data; configuration checked once.

use super::grid::{Interpolant, LookupGrid};
use super::kahan::{self, KahanSums};
use super::pair::{dist_nr, lagrange4};
use super::table::{EXTRA, Lookup, synthesise_fused};
use crate::band::probe::Target;
use crate::band::row::Row;
use crate::band::scan::{Scan, as_complex};
use crate::config::{Point, Weights};
use crate::error::{ArgumentError, check_len, check_points};
use crate::phase::cis_small_turns;
use crate::report::Report;
use crate::sample::Sample;
use num_complex::{Complex32, Complex64};

/// A Gaussian-gated diagonal or column on the lookup path: the [`Probe`](crate::Probe) of
/// [`Target`] × [`Gate::Gaussian`](crate::Gate::Gaussian) with an O(1) cost per pair (module
/// docs). Accumulators of the same size as the band diagonal's (`4Kv` `f32`: a Kahan-compensated
/// complex sum per voxel), merge and `finish` like it; the result equals the band path's within
/// [`LookupGrid::bound`].
///
/// ```
/// use vltm_kernel::{Config, Lookup, LookupGrid, LookupParams, LookupProbe, Params, RowBuffer, Scan, Target};
/// let cfg = Config::try_new(&Params::new(0.2, 128, 0.01)).unwrap();
/// let spads = [[0.0f32, 0.0, 0.0]];
/// let voxels = [[0.0f32, 0.0, 0.5], [0.0, 0.0, 0.8]];
/// let mut tables = vec![0.0; Scan::tables_len(&cfg, 1)];
/// let scan = Scan::new(&cfg, &spads, &mut tables).unwrap();
/// let grid = LookupGrid::try_new(&cfg, &LookupParams::new()).unwrap();
/// let mut lt = vec![0.0; Lookup::tables_len(&grid)];
/// let lookup = Lookup::new(&grid, &mut lt).unwrap();
/// let mut state = vec![0.0; LookupProbe::state_len(2)];
/// let mut scratch = vec![0.0; LookupProbe::scratch_len(&grid, 2)];
/// let mut diag =
///     LookupProbe::new(&scan, &lookup, Target::Diagonal, &voxels, &mut state, &mut scratch)
///         .unwrap();
/// let mut buf = vec![0.0; RowBuffer::len(&cfg, 1)];
/// let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
/// let mut h = [0u16; 128];
/// h[100] = 50; // a return at path length 1.00 m = 2 × 0.5 m
/// let row = rows.load(&scan, [0.0, 0.0, 0.0], &h).unwrap();
/// diag.push_row(&scan, &lookup, &row).unwrap();
/// let mut out = [0.0f64; 2];
/// diag.finish(&mut out).unwrap();
/// assert!(out[0] > 10.0 * out[1]);
/// ```
#[derive(Debug)]
pub struct LookupProbe<'m> {
    target: Target,
    voxels: &'m [Point],
    /// Per voxel: the amplitude as a Kahan-compensated `f32` sum.
    acc: KahanSums<'m>,
    /// One SPAD's grid, `L + EXTRA`.
    grid_buf: &'m mut [Complex32],
    /// Per voxel: this row's sum over the SPADs.
    sums: &'m mut [Complex32],
    /// Per voxel: the lead distance (`d_lv`, or `d_la + d_ab`).
    lead: &'m mut [f32],
    report: Report,
    grid: LookupGrid,
    /// Per-row constants, rounded to `f32` once by [`LookupProbe::new`] (no soft `f64` per
    /// row on a Cortex-M4F): grid points per metre of path `L/span`, the carrier
    /// `θ = k_d/L`, the guard interval (m) and the weights' `d_min` (m).
    per_m: f32,
    theta: f32,
    guard_m: (f32, f32),
    d_min: f32,
}

impl<'m> LookupProbe<'m> {
    /// Length in `f32` of the state: `4Kv` (per voxel a Kahan-compensated complex sum: the
    /// bytes of the band diagonal's `2Kv` `f64`, with no soft `f64` per row on a
    /// Cortex-M4F).
    pub const fn state_len(n_voxels: usize) -> usize {
        KahanSums::state_len(n_voxels)
    }

    /// Length in `f32` of the scratch: `2(L + 3) + 3Kv`.
    pub const fn scratch_len(grid: &LookupGrid, n_voxels: usize) -> usize {
        (2 * (grid.len + EXTRA)).saturating_add(n_voxels.saturating_mul(3))
    }

    /// A zeroed probe over `voxels`.
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if `state` or `scratch` does not have [`Self::state_len`] /
    /// [`Self::scratch_len`] elements; [`ArgumentError::Incompatible`] if `lookup` was made for
    /// another configuration than `scan` or for [`Interpolant::Hermite`];
    /// [`ArgumentError::NonFinite`] for a non-finite voxel or focus.
    pub fn new(
        scan: &Scan<'_>,
        lookup: &Lookup<'_>,
        target: Target,
        voxels: &'m [Point],
        state: &'m mut [f32],
        scratch: &'m mut [f32],
    ) -> Result<Self, ArgumentError> {
        let grid = lookup.grid;
        if !grid.cfg.same(scan.config()) {
            return Err(ArgumentError::Incompatible(
                "lookup grid of another configuration",
            ));
        }
        if grid.interp != Interpolant::Lagrange {
            return Err(ArgumentError::Incompatible(
                "a Hermite lookup grid (the voxel list reads the Lagrange cubic)",
            ));
        }
        let kv = voxels.len();
        check_len("state", Self::state_len(kv), state.len())?;
        check_len("scratch", Self::scratch_len(&grid, kv), scratch.len())?;
        check_points("voxels", voxels)?;
        if let Target::Column(a) = target {
            check_points("focus", &[a])?;
        }
        let mut acc = KahanSums::new(state, 4 * kv)?;
        let short = ArgumentError::Length {
            what: "scratch",
            expected: Self::scratch_len(&grid, kv),
            found: scratch.len(),
        };
        let (g, rest) = scratch
            .split_at_mut_checked(2 * (grid.len + EXTRA))
            .ok_or(short)?;
        let (sums, lead) = rest.split_at_mut_checked(2 * kv).ok_or(short)?;
        acc.reset();
        let cfg = &grid.cfg;
        let (g_lo, g_hi) = cfg.guard();
        Ok(Self {
            target,
            voxels,
            acc,
            grid_buf: as_complex("scratch", g)?,
            sums: as_complex("scratch", sums)?,
            lead,
            report: Report::default(),
            grid,
            per_m: (grid.len as f64 / cfg.span()) as f32,
            theta: (grid.k_d as f64 / grid.len as f64) as f32,
            guard_m: (g_lo as f32, g_hi as f32),
            d_min: cfg.params().d_min as f32,
        })
    }

    /// The target.
    pub const fn target(&self) -> Target {
        self.target
    }
    /// The voxel list.
    pub const fn voxels(&self) -> &'m [Point] {
        self.voxels
    }
    /// Counters so far (`aliased` is always 0: every path gets the guard).
    pub const fn report(&self) -> Report {
        self.report
    }
    /// The complex amplitude accumulated so far at voxel `i` (0 past the end), the
    /// compensated sum's value `s − c` in `f64`.
    pub fn amplitude(&self, i: usize) -> Complex64 {
        self.acc.amplitude(i)
    }
    /// Zeroes the accumulators and counters.
    pub fn reset(&mut self) {
        self.acc.reset();
        self.report = Report::default();
    }

    /// Adds one laser row: `Ks` grid syntheses, then `Kv·Ks` O(1) lookups. Infallible on
    /// data values and panic-free.
    ///
    /// # Errors
    /// [`ArgumentError::Incompatible`] if `lookup` or `scan` is not the probe's configuration;
    /// [`ArgumentError::Length`] if `row` was loaded for a scan of another size. Nothing is
    /// changed then.
    pub fn push_row<T: Sample>(
        &mut self,
        scan: &Scan<'_>,
        lookup: &Lookup<'_>,
        row: &Row<'_, T>,
    ) -> Result<(), ArgumentError> {
        let cfg = scan.config();
        if !lookup.grid.same(&self.grid) || !cfg.same(&self.grid.cfg) {
            return Err(ArgumentError::Incompatible(
                "lookup grid of another configuration",
            ));
        }
        let ks = scan.spads().len();
        let j = cfg.bins().max(1);
        check_len("row spectra", ks * cfg.bins(), row.band().len())?;
        check_len("row histograms", ks * cfg.nt(), ks * row.nt())?;
        check_len("row offsets", ks, row.offsets().len())?;
        let laser = row.laser();
        // The weight w(d) = 1/max(d, d_min) or 1 (`Config::weight` with the hoisted `d_min`:
        // it converts d_min from f64 per call, soft float on a Cortex-M4F; same bits. `max`
        // by comparison: `f32::max` is an out-of-line `fmaxf` on a Cortex-M).
        let d_min = self.d_min;
        let inv = matches!(cfg.weights(), Weights::Inv);
        let weight = |d: f32| {
            if inv {
                1.0 / if d > d_min { d } else { d_min }
            } else {
                1.0
            }
        };
        let w_lead = match self.target {
            Target::Diagonal => {
                for (d, v) in self.lead.iter_mut().zip(self.voxels) {
                    *d = dist_nr(&laser, v);
                }
                None
            }
            Target::Column(a) => {
                let d_la = dist_nr(&laser, &a);
                for (d, v) in self.lead.iter_mut().zip(self.voxels) {
                    *d = d_la + dist_nr(&a, v);
                }
                Some(weight(d_la))
            }
        };
        self.sums.fill(Complex32::new(0.0, 0.0));
        let (g_lo, g_hi) = self.guard_m;
        let (per_m, theta) = (self.per_m, self.theta);
        let mask = self.grid.len - 1;
        for ((sp, hg), off) in scan
            .spads()
            .iter()
            .zip(row.band().chunks_exact(j))
            .zip(row.offsets())
        {
            synthesise_fused(lookup, hg, self.grid_buf);
            let y: &[Complex32] = self.grid_buf;
            for ((v, d_lead), sum) in self
                .voxels
                .iter()
                .zip(self.lead.iter())
                .zip(self.sums.iter_mut())
            {
                let d_vs = dist_nr(v, sp);
                let tau = *d_lead + d_vs;
                let rel = tau + off;
                if !(rel >= g_lo && rel <= g_hi) {
                    continue;
                }
                // τ ≥ 0: the cast floors (and saturates at u32::MAX, masked below).
                let x = tau * per_m;
                let i = x as u32 as usize;
                let t = x - i as f32;
                let start = i.wrapping_sub(1) & mask;
                let (Some(q), Some(c)) = (
                    y.get(start..).and_then(|q| q.first_chunk::<4>()),
                    lookup.carrier.get(i & mask),
                ) else {
                    continue;
                };
                let w = lagrange4(t);
                let base = q[0] * w[0] + q[1] * w[1] + q[2] * w[2] + q[3] * w[3];
                *sum += base * (*c * cis_small_turns(theta * t)) * weight(d_vs);
            }
        }
        for ((a, s), d) in self
            .acc
            .iter_mut()
            .zip(self.sums.iter())
            .zip(self.lead.iter())
        {
            let w = match w_lead {
                Some(w) => w,
                None => weight(*d),
            };
            kahan::add(a, *s * w);
        }
        self.report.count_row(row);
        Ok(())
    }

    /// Adds another lookup probe's accumulators (same grid, target and voxels).
    ///
    /// # Errors
    /// [`ArgumentError::Incompatible`] if the probes differ; nothing is changed then.
    pub fn merge(&mut self, other: &LookupProbe<'_>) -> Result<(), ArgumentError> {
        if self.target != other.target
            || self.voxels != other.voxels
            || !self.grid.same(&other.grid)
        {
            return Err(ArgumentError::Incompatible(
                "different target, voxels or grid",
            ));
        }
        self.acc.merge(&other.acc);
        self.report.add_part(&other.report);
        Ok(())
    }

    /// Writes the intensities `T = |A|²` into `out` (length = voxels) and returns the
    /// counters. Does not change the accumulators.
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if `out` has the wrong length.
    pub fn finish(&self, out: &mut [f64]) -> Result<Report, ArgumentError> {
        check_len("out", self.voxels.len(), out.len())?;
        self.acc.intensities(out);
        Ok(self.report)
    }

    /// [`LookupProbe::finish`] in `f32` (no `f64` on a Cortex-M4F): `T = |s − c|²` with the
    /// compensated sum's value rounded once to `f32` (a relative `2u` more than `finish`).
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if `out` has the wrong length.
    pub fn finish_f32(&self, out: &mut [f32]) -> Result<Report, ArgumentError> {
        check_len("out", self.voxels.len(), out.len())?;
        self.acc.intensities_f32(out);
        Ok(self.report)
    }
}
