//! The lookup path on a **structured slice**: the Gaussian diagonal or column of a plane of
//! voxels on a regular lattice, seen by SPADs on a line commensurate with the lattice, with
//! the laser-independent part of every (voxel, SPAD) pair precomputed once.
//!
//! Where it applies (the voxels on a [`Lattice`](crate::Lattice), the SPADs on its x lattice) is checked by
//! [`SliceLayout::try_new`] (module docs of `lookup/lattice.rs`); otherwise the caller uses
//! the general [`LookupProbe`](crate::LookupProbe).
//!
//! # Method (same maths as [`LookupProbe`](crate::LookupProbe), other factorisation)
//!
//! In grid units (`x = τ·L/span`), the lookup path's value is
//! `Z_s(τ) = e^{2πiθx}·Y_s(x)` (`θ = k_d/L`, `Y_s` the baseband grid interpolated by the
//! 4-point cubic). With `x = x_lead(v) + x_vs(v, s)` the carrier splits into a per-voxel factor
//! `e^{2πiθ x_lead}` (once per voxel and row, outside the SPAD loop) and a per-pair factor
//! `P = w(d_vs)·e^{2πiθ x_vs}` that does not depend on the laser: it is stored in the table
//! with `x_vs`, computed once in `f64`. Per row and SPAD, the baseband grid is synthesised
//! ([`Lookup`]) and turned into the cubic's power-basis coefficients per grid cell
//! (`p(t) = a₀ + a₁t + a₂t² + a₃t³`: the same cubic as the Lagrange form of
//! [`lagrange4`](crate::lagrange4), or with [`Interpolant::Hermite`] the cubic Hermite
//! interpolant of the cell's two nodes with sixth-order central-difference slopes
//! `(45(y₁ − y₋₁) − 9(y₂ − y₋₂) + (y₃ − y₋₃))/60`), so a pair is: one add (`x`), the floor and fraction, one
//! bounds-checked cell read, a complex Horner step of three multiply-adds, the complex product
//! with `P` and the row sum. The guard interval ([`Config::guard`](crate::Config::guard)) is
//! proved once per SPAD and row from the extreme lead and leg values (`f32`, in grid units);
//! only when it cannot be proved is it tested per pair. The loops run over SPADs two at a time
//! (outer; each voxel's sum and lead are loaded and stored once per two SPADs, additions in
//! the same order as one SPAD after the other) and voxel rows inner, over contiguous table
//! rows (no index arithmetic per pair).
//!
//! # Error bound
//!
//! With [`Interpolant::Lagrange`] the interpolated function, grid and carrier are those of
//! [`LookupProbe`](crate::LookupProbe), so its module's bound holds unchanged:
//! `|Z_slice − Z_band| ≤ η·‖h_s‖₁` per pair with `η` = [`LookupGrid::bound`]. With
//! [`Interpolant::Hermite`], `η` = [`LookupGrid::bound`] is the Hermite bound: with exact
//! slopes the remainder is `|Y⁽⁴⁾|·t²(1 − t)²/4! ≤ max|Y⁽⁴⁾|/384` (Hermite–Genocchi with
//! the nodes 0, 0, 1, 1; per band bin `|Y⁽⁴⁾| ≤ ω_j⁴` in grid units), and a slope error `e`
//! at the nodes adds `|h₁₀(t)e₀ + h₁₁(t)e₁| ≤ t(1 − t)·max|e| ≤ max|e|/4`; the central
//! difference on `e^{iωx}` errs by exactly `ε(ω) = |ω − (3/2 sin ω − 3/10 sin 2ω + 1/30 sin 3ω)|`
//! (`≈ ω⁷/140`), so `η = Σ_j Ĝ_j·(ω_j⁴/384 + ε(ω_j)/4)`, 9× below the Lagrange bound on the
//! same grid when `ε` is negligible. Plus `f32` rounding in both: the power-basis
//! coefficients are combinations of four (Lagrange) or eight (Hermite) grid values
//! (`|a_q| ≤ 2·max|Y|`, resp. `≤ 12·max|Y|`), so the conversion and the Horner step at
//! `0 ≤ t < 1` add ≈ 6u, resp. ≈ 30u, of `max|Y|` (inside the property test's `f32`
//! allowance, which also covers the FFT's `u·log₂L` per stage); the carrier phases are
//! `θ·x_lead` in `f32` (a relative `u` of the path in grid units, as the general path's grid
//! position) and `θ·x_vs` rounded once from `f64`. The lattice positions are computed in
//! `f64` from the `f32` origin and steps, and the SPADs are taken at `s_0 + m_k·a` (within a
//! few `f32` ulps of the given ones, checked).
//!
//! # Cost and memory
//!
//! Per row: `Ks` inverse FFTs of length `L` and at most `Ks·L` cell conversions (≈ 25 flops
//! each; only the cells a SPAD reads), `Kv` lead distances and carriers, then `Kv·Ks` pairs
//! of ≈ 20 flops with no square root, no carrier polynomial and no weight (≈ 33 instructions
//! per pair on a Cortex-M4F); the row's sums join the state as Kahan-compensated `f32` sums
//! (no soft `f64` on a Cortex-M4F; error `≤ 2u·Σ_rows |row sum|` plus `O(n u²)`, far below
//! the lookup tolerance). Memory, all caller-owned: the slice tables `4·Ks + 4·ny·width`
//! `f32` ([`SliceLayout::tables_len`]; `width = nx + max m − min m`), the state `4Kv` `f32`
//! (the bytes of `2Kv` `f64`), the scratch `2(L + 8) + 16L + 4Kv` `f32`
//! ([`LookupSlice::scratch_len`]: one SPAD's grid with three wrapped values before and five
//! after, two SPADs' cubic cells, the voxels' row
//! sums and leads). No allocation, no panic on data; configuration and geometry checked once.

use super::grid::{Interpolant, LookupGrid};
use super::kahan::{self, KahanSums};
use super::lattice::{SliceLayout, lattice_offset};
use super::pair::dist_nr;
use super::table::{Lookup, synthesise_fused};
use crate::band::probe::Target;
use crate::band::row::Row;
use crate::band::scan::{Scan, as_complex};
use crate::config::Weights;
use crate::error::{ArgumentError, check_len};
use crate::phase::cis_small_turns;
use crate::report::Report;
use crate::sample::Sample;
use num_complex::{Complex32, Complex64};

/// Wrapped grid values kept before node 0 (`y[−3 .. 0]`) and after node `L − 1`
/// (`y[L .. L + 5]`): a cell's Hermite slopes read three nodes before it and four after.
const PRE: usize = 3;
const POST: usize = 5;

/// A Gaussian-gated diagonal or column over a structured slice on the lookup path (module
/// docs): the result equals [`LookupProbe`](crate::LookupProbe)'s over the voxel list
/// [`Lattice::point`](crate::Lattice::point)`(0..Kv)` within the lookup path's bound.
///
/// ```
/// use vltm_kernel::{Config, Lattice, Lookup, LookupGrid, LookupParams, LookupSlice, Params,
///     RowBuffer, Scan, SliceLayout, Target};
/// let cfg = Config::try_new(&Params::new(0.2, 128, 0.01)).unwrap();
/// let spads = [[0.0f32, 0.0, 0.0], [0.1, 0.0, 0.0]];
/// let mut tables = vec![0.0; Scan::tables_len(&cfg, 2)];
/// let scan = Scan::new(&cfg, &spads, &mut tables).unwrap();
/// let grid = LookupGrid::try_new(&cfg, &LookupParams::new()).unwrap();
/// let mut lt = vec![0.0; Lookup::tables_len(&grid)];
/// let lookup = Lookup::new(&grid, &mut lt).unwrap();
/// // 4 × 2 voxels at z = 0.5 m, 10 cm pitch along the SPAD line (= the SPAD pitch), 40 cm in y.
/// let lattice = Lattice {
///     origin: [-0.3, 0.0, 0.5], step_x: [0.1, 0.0, 0.0], step_y: [0.0, 0.4, 0.0], nx: 4, ny: 2,
/// };
/// let layout = SliceLayout::try_new(&scan, &grid, &lattice, usize::MAX).unwrap();
/// let mut st = vec![0.0; layout.tables_len()];
/// let mut state = vec![0.0f32; LookupSlice::state_len(lattice.len())];
/// let mut scratch = vec![0.0; LookupSlice::scratch_len(&grid, lattice.len())];
/// let mut diag = LookupSlice::new(&scan, &lookup, &layout, Target::Diagonal, &mut st,
///     &mut state, &mut scratch).unwrap();
/// let mut buf = vec![0.0; RowBuffer::len(&cfg, 2)];
/// let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
/// let mut h = [0u16; 256];
/// h[100] = 50; // SPAD 0: a return at 1.00 m = 2 × 0.5 m
/// let row = rows.load(&scan, [0.0, 0.0, 0.0], &h).unwrap();
/// diag.push_row(&scan, &lookup, &row).unwrap();
/// let mut out = [0.0f64; 8];
/// diag.finish(&mut out).unwrap();
/// assert!(out[3] > 10.0 * out[4]); // voxel (3, 0) is at (0, 0, 0.5); (0, 1) 41 cm further
/// ```
#[derive(Debug)]
pub struct LookupSlice<'m> {
    target: Target,
    layout: SliceLayout,
    /// Per SPAD: `[row offset m_max − m_k, min x_vs, max x_vs, 0]`.
    spad_info: &'m [[f32; 4]],
    /// Per (iy, u): `[x_vs, P.re, P.im, 0]`, `ny × width`.
    table: &'m [[f32; 4]],
    /// Per voxel: the amplitude as a Kahan-compensated `f32` sum.
    acc: KahanSums<'m>,
    /// One SPAD's grid with wrapped copies, `PRE + L + POST`: `y[−3 .. L + 5]`.
    grid_buf: &'m mut [Complex32],
    /// Two SPADs' cubic cells `[a₀, a₁, a₂, a₃]` (re, im interleaved), `2L`.
    cells: &'m mut [[f32; 8]],
    /// Per voxel: `[sum.re, sum.im, x_lead, 0]`, this row's sum over the SPADs and the lead
    /// path in grid units.
    voxel: &'m mut [[f32; 4]],
    /// Per-row constants, rounded to `f32` once here (no soft `f64` per row on a
    /// Cortex-M4F): grid points per metre of path `L/span`, the carrier `θ = k_d/L`, and the
    /// guard interval in metres (`Config::guard`), metres of path per grid point `span/L`
    /// and the weights' `d_min`.
    per_m: f32,
    theta: f32,
    guard_m: (f32, f32),
    per_grid: f32,
    d_min: f32,
    report: Report,
}

impl<'m> LookupSlice<'m> {
    /// Length in `f32` of the state: `4Kv` (per voxel a Kahan-compensated complex sum: the
    /// bytes of the general path's `2Kv` `f64`, with no soft `f64` per row on a Cortex-M4F).
    pub const fn state_len(n_voxels: usize) -> usize {
        KahanSums::state_len(n_voxels)
    }

    /// Length in `f32` of the scratch: `2(L + 8) + 16L + 4Kv`.
    pub const fn scratch_len(grid: &LookupGrid, n_voxels: usize) -> usize {
        (2 * (PRE + grid.len() + POST) + 16 * grid.len()).saturating_add(n_voxels.saturating_mul(4))
    }

    /// Fills the slice tables (once, in `f64`) and returns a zeroed probe.
    ///
    /// # Errors
    /// [`ArgumentError::Incompatible`] if `layout` or `lookup` was made for another scan or
    /// configuration; [`ArgumentError::Length`] if `tables`, `state` or `scratch` does not have
    /// [`SliceLayout::tables_len`] / [`Self::state_len`] / [`Self::scratch_len`] elements;
    /// [`ArgumentError::NonFinite`] for a non-finite column focus.
    pub fn new(
        scan: &Scan<'_>,
        lookup: &Lookup<'_>,
        layout: &SliceLayout,
        target: Target,
        tables: &'m mut [f32],
        state: &'m mut [f32],
        scratch: &'m mut [f32],
    ) -> Result<Self, ArgumentError> {
        let grid = *lookup.grid();
        let cfg = scan.config();
        if !grid.same(&layout.grid) || !grid.config().same(cfg) {
            return Err(ArgumentError::Incompatible(
                "lookup grid of another configuration",
            ));
        }
        let lat = layout.lattice;
        let a = lat.step_x.map(f64::from);
        let a2 = a[0] * a[0] + a[1] * a[1] + a[2] * a[2];
        let s0 = scan
            .spads()
            .first()
            .copied()
            .unwrap_or([0.0; 3])
            .map(f64::from);
        // The SPADs' offsets, re-derived: the layout must be this scan's.
        if scan.spads().len() != layout.ks
            || scan.spads().iter().any(|s| {
                lattice_offset(&a, a2, &s0, s).is_none_or(|m| m < layout.m_min || m > layout.m_max)
            })
        {
            return Err(ArgumentError::Incompatible("slice layout of another scan"));
        }
        let kv = lat.len();
        check_len("slice tables", layout.tables_len(), tables.len())?;
        check_len("state", Self::state_len(kv), state.len())?;
        check_len("scratch", Self::scratch_len(&grid, kv), scratch.len())?;
        if let Target::Column(f) = target {
            crate::error::check_points("focus", &[f])?;
        }
        let l = grid.len();
        let short = |what, expected, found| ArgumentError::Length {
            what,
            expected,
            found,
        };
        let found = tables.len();
        let (info, entries) = tables.split_at_mut_checked(4 * layout.ks).ok_or(short(
            "slice tables",
            layout.tables_len(),
            found,
        ))?;
        let info: &mut [[f32; 4]] = bytemuck::try_cast_slice_mut(info)
            .map_err(|_| short("slice tables", layout.tables_len(), found))?;
        let entries: &mut [[f32; 4]] = bytemuck::try_cast_slice_mut(entries)
            .map_err(|_| short("slice tables", layout.tables_len(), found))?;
        // Entries: x_vs and P = w(d_vs)·e^{2πiθ x_vs}, from f64 positions.
        let span = cfg.span();
        let per_m = l as f64 / span;
        let theta = grid.carrier_bin() as f64 / l as f64;
        let width = layout.width;
        for (n, e) in entries.iter_mut().enumerate() {
            let (iy, u) = (n / width.max(1), n % width.max(1));
            // Entry u holds v − s_k for ix − m_k = u − m_max: the lattice point there, − s_0.
            let ix = u as f64 - layout.m_max as f64;
            let p = lat.point64(ix, iy as f64);
            let (dx, dy, dz) = (p[0] - s0[0], p[1] - s0[1], p[2] - s0[2]);
            let d = libm::sqrt(dx * dx + dy * dy + dz * dz);
            let x = d * per_m;
            let turns = theta * x;
            let ph = core::f64::consts::TAU * (turns - libm::rint(turns));
            let w = f64::from(cfg.weight(d as f32));
            *e = [
                x as f32,
                (w * libm::cos(ph)) as f32,
                (w * libm::sin(ph)) as f32,
                0.0,
            ];
        }
        // Per SPAD: its row offset and the extreme legs of its window.
        for (s, inf) in scan.spads().iter().zip(info.iter_mut()) {
            let m = lattice_offset(&a, a2, &s0, s).unwrap_or(layout.m_max);
            // u = ix − m_k + m_max: SPAD k's voxel row starts at u = m_max − m_k.
            let start = (layout.m_max - m) as usize;
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            for row in entries.chunks_exact(width.max(1)) {
                for e in row.iter().skip(start).take(lat.nx) {
                    lo = if e[0] < lo { e[0] } else { lo };
                    hi = if e[0] > hi { e[0] } else { hi };
                }
            }
            *inf = [start as f32, lo, hi, 0.0];
        }
        let mut acc = KahanSums::new(state, 4 * kv)?;
        let sl = Self::scratch_len(&grid, kv);
        let found = scratch.len();
        let (g, rest) = scratch
            .split_at_mut_checked(2 * (PRE + l + POST))
            .ok_or(short("scratch", sl, found))?;
        let (cells, rest) = rest
            .split_at_mut_checked(16 * l)
            .ok_or(short("scratch", sl, found))?;
        let voxel = bytemuck::try_cast_slice_mut(rest).map_err(|_| short("scratch", sl, found))?;
        acc.reset();
        let l = grid.len();
        let (g_lo, g_hi) = cfg.guard();
        Ok(Self {
            per_m: (l as f64 / cfg.span()) as f32,
            theta: (grid.carrier_bin() as f64 / l as f64) as f32,
            guard_m: (g_lo as f32, g_hi as f32),
            per_grid: (cfg.span() / l as f64) as f32,
            d_min: cfg.params().d_min as f32,
            target,
            layout: *layout,
            spad_info: info,
            table: entries,
            acc,
            grid_buf: as_complex("scratch", g)?,
            cells: bytemuck::try_cast_slice_mut(cells).map_err(|_| short("scratch", sl, found))?,
            voxel,
            report: Report::default(),
        })
    }

    /// The target.
    pub const fn target(&self) -> Target {
        self.target
    }
    /// The layout (lattice, grid).
    pub const fn layout(&self) -> &SliceLayout {
        &self.layout
    }
    /// Counters so far (`aliased` is always 0: every path gets the guard).
    pub const fn report(&self) -> Report {
        self.report
    }
    /// The complex amplitude accumulated so far at voxel `i` (`iy·nx + ix`; 0 past the end).
    pub fn amplitude(&self, i: usize) -> Complex64 {
        self.acc.amplitude(i)
    }
    /// Zeroes the accumulators and counters.
    pub fn reset(&mut self) {
        self.acc.reset();
        self.report = Report::default();
    }

    /// Adds one laser row: `Ks` grid syntheses and cell conversions, then `Kv·Ks` O(1)
    /// lookups. Infallible on data values and panic-free.
    ///
    /// # Errors
    /// [`ArgumentError::Incompatible`] if `lookup` or `scan` is not the probe's configuration or
    /// SPAD count; [`ArgumentError::Length`] if `row` was loaded for a scan of another size. Nothing
    /// is changed then.
    pub fn push_row<T: Sample>(
        &mut self,
        scan: &Scan<'_>,
        lookup: &Lookup<'_>,
        row: &Row<'_, T>,
    ) -> Result<(), ArgumentError> {
        let grid = self.layout.grid;
        let cfg = scan.config();
        if !lookup.grid().same(&grid)
            || !cfg.same(grid.config())
            || scan.spads().len() != self.layout.ks
        {
            return Err(ArgumentError::Incompatible(
                "lookup grid of another configuration",
            ));
        }
        let ks = scan.spads().len();
        let j = cfg.bins().max(1);
        check_len("row spectra", ks * cfg.bins(), row.band().len())?;
        check_len("row histograms", ks * cfg.nt(), ks * row.nt())?;
        check_len("row offsets", ks, row.offsets().len())?;
        let l = grid.len();
        let mask = l - 1;
        let (per_m, theta) = (self.per_m, self.theta);
        let lat = self.layout.lattice;
        let nx = lat.nx.max(1);
        // Leads in grid units, and their extremes.
        let laser = row.laser();
        let (focus, d_la) = match self.target {
            Target::Diagonal => (laser, 0.0),
            Target::Column(a) => (a, dist_nr(&laser, &a)),
        };
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        let (o, a, b) = (lat.origin, lat.step_x, lat.step_y);
        for (iy, leads) in self.voxel.chunks_exact_mut(nx).enumerate() {
            let iy = iy as f32;
            let r = [o[0] + iy * b[0], o[1] + iy * b[1], o[2] + iy * b[2]];
            for (ix, g) in leads.iter_mut().enumerate() {
                let ix = ix as f32;
                let v = [r[0] + ix * a[0], r[1] + ix * a[1], r[2] + ix * a[2]];
                let x = (d_la + dist_nr(&focus, &v)) * per_m;
                lo = if x < lo { x } else { lo };
                hi = if x > hi { x } else { hi };
                *g = [0.0, 0.0, x, 0.0];
            }
        }
        let (g_lo, g_hi) = (self.guard_m.0 * per_m, self.guard_m.1 * per_m);
        let width = self.layout.width.max(1);
        let Some((cells_a, cells_b)) = self.cells.split_at_mut_checked(l) else {
            return Ok(());
        };
        let guard = (lo, hi, g_lo, g_hi, per_m, mask);
        // SPADs two at a time: one pass over the voxels per pair of SPADs (the voxel's sum
        // and lead are loaded and stored once for both; same order of additions as one SPAD
        // after the other).
        let mut bands = row.band().chunks_exact(j);
        let mut offs = row.offsets().iter();
        for infos in self.spad_info.chunks(2) {
            let (Some(ia), Some(hg_a), Some(oa)) = (infos.first(), bands.next(), offs.next())
            else {
                break;
            };
            let a = prepare(lookup, hg_a, self.grid_buf, cells_a, ia, *oa, guard);
            let b = match infos.get(1) {
                Some(ib) => {
                    let (Some(hg_b), Some(ob)) = (bands.next(), offs.next()) else {
                        break;
                    };
                    Some(prepare(
                        lookup,
                        hg_b,
                        self.grid_buf,
                        cells_b,
                        ib,
                        *ob,
                        guard,
                    ))
                }
                None => None,
            };
            for (tab, vox) in self
                .table
                .chunks_exact(width)
                .zip(self.voxel.chunks_exact_mut(nx))
            {
                let Some(ta) = tab.get(a.0..).and_then(|t| t.get(..nx)) else {
                    continue;
                };
                match b {
                    Some(b) => {
                        let Some(tb) = tab.get(b.0..).and_then(|t| t.get(..nx)) else {
                            continue;
                        };
                        let g = (a.1, b.1, g_lo, g_hi);
                        if a.2 && b.2 {
                            pairs2::<false>(cells_a, cells_b, mask, ta, tb, vox, g);
                        } else {
                            pairs2::<true>(cells_a, cells_b, mask, ta, tb, vox, g);
                        }
                    }
                    None => {
                        if a.2 {
                            pairs::<false>(cells_a, mask, ta, vox, (a.1, g_lo, g_hi));
                        } else {
                            pairs::<true>(cells_a, mask, ta, vox, (a.1, g_lo, g_hi));
                        }
                    }
                }
            }
        }
        // Per voxel: the lead's carrier e^{2πiθ x_lead} (exact table at the integer part,
        // small-phase polynomial for the fraction) and weight.
        let carrier = lookup.carrier_table();
        let (d_min, per_grid) = (self.d_min, self.per_grid);
        let inv = matches!(cfg.weights(), Weights::Inv);
        // `Config::weight(d_la)` with the hoisted `d_min` (`max` by comparison: the same bits,
        // a NaN gives `d_min` either way).
        let w_col = if inv {
            1.0 / if d_la > d_min { d_la } else { d_min }
        } else {
            1.0
        };
        for (a, &[s_re, s_im, x, _]) in self.acc.iter_mut().zip(self.voxel.iter()) {
            let s = Complex32::new(s_re, s_im);
            let i = x as u32 as usize;
            let t = x - i as f32;
            let c = carrier
                .get(i & mask)
                .copied()
                .unwrap_or(Complex32::new(0.0, 0.0));
            let w = match self.target {
                Target::Column(_) => w_col,
                Target::Diagonal if inv => {
                    let d = x * per_grid;
                    1.0 / if d > d_min { d } else { d_min }
                }
                Target::Diagonal => 1.0,
            };
            kahan::add(a, s * (c * cis_small_turns(theta * t)) * w);
        }
        self.report.count_row(row);
        Ok(())
    }

    /// Adds another slice probe's accumulators (same layout and target).
    ///
    /// # Errors
    /// [`ArgumentError::Incompatible`] if the probes differ; nothing is changed then.
    pub fn merge(&mut self, other: &LookupSlice<'_>) -> Result<(), ArgumentError> {
        if self.target != other.target || self.layout != other.layout {
            return Err(ArgumentError::Incompatible(
                "different target or slice layout",
            ));
        }
        self.acc.merge(&other.acc);
        self.report.add_part(&other.report);
        Ok(())
    }

    /// Writes the intensities `T = |A|²` into `out` (length `nx·ny`, index `iy·nx + ix`) and
    /// returns the counters. Does not change the accumulators.
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if `out` has the wrong length.
    pub fn finish(&self, out: &mut [f64]) -> Result<Report, ArgumentError> {
        check_len("out", self.acc.len(), out.len())?;
        self.acc.intensities(out);
        Ok(self.report)
    }
}

/// The cubic of cell `n` (between the nodes `n` and `n + 1`) in power form,
/// `p(t) = a₀ + a₁t + a₂t² + a₃t³`, for the `count` cells from `first` on (wrapping at `L`;
/// all `L` when `count ≥ L`): the cubic of [`lagrange4`](crate::lagrange4) (nodes
/// `n − 1 … n + 2`) or the Hermite cubic with central-difference slopes (nodes `n − 3 … n + 4`;
/// [`Interpolant`]). `pad` holds `y[−PRE .. L + POST]` (wrapped copies at both ends). Cells
/// outside the range keep their values.
fn cubic_cells(
    pad: &[Complex32],
    cells: &mut [[f32; 8]],
    first: usize,
    count: usize,
    interp: Interpolant,
) {
    let l = cells.len();
    let (first, count) = if count >= l { (0, l) } else { (first, count) };
    // The range as at most two runs: first .. min(first + count, L), then 0 .. the rest.
    let head = count.min(l.saturating_sub(first));
    for (from, n) in [(first, head), (0, count - head)] {
        // Cell k reads pad[k .. k + 8] = y[k − 3 .. k + 5].
        let (Some(c), Some(w)) = (cells.get_mut(from..), pad.get(from..)) else {
            continue;
        };
        match interp {
            Interpolant::Lagrange => lagrange_run(w, c, n),
            Interpolant::Hermite => hermite_run(w, c, n),
        }
    }
}

/// [`cubic_cells`] over one run of `n` Lagrange cells: `cells[k]` from
/// `y[k − 1], y[k], y[k + 1], y[k + 2]` (= `pad[k + 2 .. k + 6]`).
#[inline(always)]
fn lagrange_run(pad: &[Complex32], cells: &mut [[f32; 8]], n: usize) {
    for (c, w) in cells.iter_mut().zip(pad.windows(8)).take(n) {
        let [ym, y0, y1, y2] = [w[2], w[3], w[4], w[5]];
        let a1 = y1 - ym * (1.0 / 3.0) - y0 * 0.5 - y2 * (1.0 / 6.0);
        let a2 = (ym + y1) * 0.5 - y0;
        let a3 = (y2 - ym) * (1.0 / 6.0) + (y0 - y1) * 0.5;
        *c = [y0.re, y0.im, a1.re, a1.im, a2.re, a2.im, a3.re, a3.im];
    }
}

/// The sixth-order central difference at the middle of `s` (7 nodes, grid units):
/// `(45(s₄ − s₂) − 9(s₅ − s₁) + (s₆ − s₀))/60`.
#[inline(always)]
fn slope(s: &[Complex32]) -> Complex32 {
    match s.first_chunk::<7>() {
        Some(&[a, b, c, _, e, f, g]) => (e - c) * 0.75 - (f - b) * 0.15 + (g - a) * (1.0 / 60.0),
        None => Complex32::new(0.0, 0.0),
    }
}

/// [`cubic_cells`] over one run of `n` Hermite cells: `cells[k]` from `y[k]`, `y[k + 1]` and
/// their slopes (the slope of node `k + 1` is carried to the next cell).
#[inline(always)]
fn hermite_run(pad: &[Complex32], cells: &mut [[f32; 8]], n: usize) {
    let mut d0 = slope(pad);
    for (c, w) in cells.iter_mut().zip(pad.windows(8)).take(n) {
        let d1 = slope(&w[1..]);
        let (y0, dy) = (w[3], w[4] - w[3]);
        let a2 = dy * 3.0 - d0 * 2.0 - d1;
        let a3 = d0 + d1 - dy * 2.0;
        *c = [y0.re, y0.im, d0.re, d0.im, a2.re, a2.im, a3.re, a3.im];
        d0 = d1;
    }
}

/// One SPAD's grid and cells for a row: synthesis, then the cubic cells its pairs read
/// (`x ∈ [lo + min x_vs, hi + max x_vs]`: rounding is monotone, so every `f32` `x` of a pair
/// lies in the rounded interval). Returns the SPAD's table offset, its leg offset in grid
/// units and whether the guard holds for all its pairs (proved from the extremes).
#[inline(always)]
fn prepare(
    lookup: &Lookup<'_>,
    hg: &[Complex32],
    y: &mut [Complex32],
    cells: &mut [[f32; 8]],
    info: &[f32; 4],
    off: f32,
    guard: (f32, f32, f32, f32, f32, usize),
) -> (usize, f32, bool) {
    let (lo, hi, g_lo, g_hi, per_m, mask) = guard;
    let l = mask + 1;
    if let Some((pre, grid)) = y.split_at_mut_checked(PRE) {
        // grid = y[0 .. L + POST]: the synthesis writes the wrapped copies after L.
        synthesise_fused(lookup, hg, grid);
        for (p, v) in pre
            .iter_mut()
            .zip(grid.get(l.saturating_sub(PRE)..).unwrap_or(&[]))
        {
            *p = *v;
        }
    }
    let first = (lo + info[1]) as u32 as usize;
    let last = (hi + info[2]) as u32 as usize;
    let count = last.wrapping_sub(first).saturating_add(1);
    cubic_cells(y, cells, first & mask, count, lookup.grid().interpolant());
    let off = off * per_m;
    let proved = lo + info[1] + off >= g_lo && hi + info[2] + off <= g_hi;
    (info[0] as usize, off, proved)
}

/// Two SPADs over one voxel row, as [`pairs`] for SPAD A then SPAD B per voxel.
#[inline(never)]
fn pairs2<const GUARD: bool>(
    cells_a: &[[f32; 8]],
    cells_b: &[[f32; 8]],
    mask: usize,
    tab_a: &[[f32; 4]],
    tab_b: &[[f32; 4]],
    vox: &mut [[f32; 4]],
    guard: (f32, f32, f32, f32),
) {
    let (Some(ca), Some(cb)) = (cells_a.get(..=mask), cells_b.get(..=mask)) else {
        return;
    };
    let (off_a, off_b, g_lo, g_hi) = guard;
    for ((ea, eb), v) in tab_a.iter().zip(tab_b).zip(vox.iter_mut()) {
        let mut s = [v[0], v[1]];
        mac::<GUARD>(ca, mask, ea, v[2], (off_a, g_lo, g_hi), &mut s);
        mac::<GUARD>(cb, mask, eb, v[2], (off_b, g_lo, g_hi), &mut s);
        v[0] = s[0];
        v[1] = s[1];
    }
}

/// One SPAD over one voxel row: `sum += P·p(t)` at `x = x_lead + x_vs` for each voxel
/// `[sum.re, sum.im, x_lead, _]`, with the guard tested per pair when `GUARD`
/// (`(off, g_lo, g_hi)` in grid units). Two pairs per iteration (fewer loop instructions).
#[inline(never)]
fn pairs<const GUARD: bool>(
    cells: &[[f32; 8]],
    mask: usize,
    tab: &[[f32; 4]],
    vox: &mut [[f32; 4]],
    guard: (f32, f32, f32),
) {
    // `cells` has `mask + 1` entries, so `i & mask` is in range (lets the check go).
    let Some(cells) = cells.get(..=mask) else {
        return;
    };
    let (t2, t1) = tab.as_chunks::<2>();
    let (v2, v1) = vox.as_chunks_mut::<2>();
    for (e, v) in t2.iter().zip(v2.iter_mut()) {
        pair::<GUARD>(cells, mask, &e[0], &mut v[0], guard);
        pair::<GUARD>(cells, mask, &e[1], &mut v[1], guard);
    }
    for (e, v) in t1.iter().zip(v1.iter_mut()) {
        pair::<GUARD>(cells, mask, e, v, guard);
    }
}

/// One pair of [`pairs`].
#[inline(always)]
fn pair<const GUARD: bool>(
    cells: &[[f32; 8]],
    mask: usize,
    e: &[f32; 4],
    v: &mut [f32; 4],
    guard: (f32, f32, f32),
) {
    let mut s = [v[0], v[1]];
    mac::<GUARD>(cells, mask, e, v[2], guard, &mut s);
    v[0] = s[0];
    v[1] = s[1];
}

/// `s += P·p(t)` for the pair with table entry `e = [x_vs, P.re, P.im, _]` and lead `lead`
/// (grid units), skipped outside the guard when `GUARD`.
#[inline(always)]
fn mac<const GUARD: bool>(
    cells: &[[f32; 8]],
    mask: usize,
    e: &[f32; 4],
    lead: f32,
    guard: (f32, f32, f32),
    s: &mut [f32; 2],
) {
    let (off, g_lo, g_hi) = guard;
    let x = lead + e[0];
    if GUARD {
        let rel = x + off;
        if !(rel >= g_lo && rel <= g_hi) {
            return;
        }
    }
    // x ≥ 0: the cast floors (and saturates at u32::MAX, masked below).
    let i = x as u32 as usize;
    let t = x - i as f32;
    let Some(c) = cells.get(i & mask) else {
        return;
    };
    let re = ((c[6] * t + c[4]) * t + c[2]) * t + c[0];
    let im = ((c[7] * t + c[5]) * t + c[3]) * t + c[1];
    // Multiply-accumulate form (`vmla`/`vmls` on the M4F, no separate product).
    s[0] = s[0] + re * e[1] - im * e[2];
    s[1] = s[1] + re * e[2] + im * e[1];
}
