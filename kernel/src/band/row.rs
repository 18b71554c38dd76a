//! Stage 1, per laser row: the spectra of one row's histograms ([`RowBuffer::load`] →
//! [`Row`]), in a caller-owned buffer, from the tables and band transform of
//! [`Scan`] (module docs of `band/scan.rs`).
//!
//! Per laser row `l` and SPAD `s`, with `x_ls = d1_l + d4_s − t0`:
//!
//! * band spectrum `HG_ls[j] = Ĝ_j · e^{iν_j x_ls} · Σ_n H_ls[n]·e^{−2πi k_j n/N}` (J values;
//!   the sum by the scan's band transform, two-stage or direct, chosen once per scan);
//! * un-gated value `M_ls = e^{iΩ x_ls} · Σ_n H_ls[n]·e^{−iΩ nΔt}` (the monochromatic
//!   phasor at Ω), by a complex recurrence `e^{−iΩΔt}` re-seeded every 64 samples, the block
//!   seeds `e^{−iΩ·64cΔt}` themselves by a recurrence of the block step;
//! * the leg offset `x_ls` itself (for the guard and the time-domain gates).
//!
//! **No `f64` per row** (soft float on an FPU without double precision, such as the
//! Cortex-M4F's FPv4-SP): [`Scan::new`] converts the constants once (`k_lo/NΔt`, `1/NΔt`,
//! `1/λ`, `t0`, the laser origin, the carrier steps `e^{−iΩΔt}` and `e^{−iΩ·64Δt}` from
//! `f64` `libm`), and `load`, `end_photons` and `push_photon` work in `f32`:
//!
//! * legs: `x = (d1 + d4) − t0` in `f32` (`d1` by `sqrtf`), then the phases in turns
//!   `x·k_lo/NΔt`, `x/NΔt` and `x/λ` ([`cis_turns`]). Error: `x` carries `≤ 2u·(|d1| + |d4| +
//!   |t0|)` m, the turns product a relative `u` on top, so a leg phase is off by
//!   `≤ 2π·3u·Φ_x` rad, `Φ_x = max|ν|·(|d1| + |d4| + |t0|)/2π` turns (`u = 2⁻²⁴`), plus
//!   [`cis_turns`]' 2.5e-7. The paper's setup (Φ_x ≈ 25 turns): 2.9e-5 rad. The same order
//!   as the `f32` phases of the probes' path times (`2π·u·Φ`, module docs of
//!   [`Probe`](crate::Probe)), which the proptest tolerance already carries.
//! * un-gated carrier: block `c`'s seed is `c` products of the block step (each rounded to
//!   `f32`, ≤ 2.5e-7 + 2u), so `≤ c·3.5e-7` after `Nt/64` blocks, and the in-block
//!   recurrence `64·(2u + 1e-8)` as before: `M` is within `(Nt/64 + 64)·3.5e-7` of `Σ|H|`.
//! * photon events: the phase `bin·(−Δt/λ)` in `f32` (relative `2u` of `Nt·Δt/λ` turns).
//!
//! `load_matches_f64_reference` checks `HG` and `M` against an `f64` evaluation of the same
//! formulas with this bound.
//!
//! Cost per row: the band transform (+ `Ks·Nt` for `M`, `Ks·J` for the legs); on the
//! Cortex-M4F 2.4 M instructions for Ks = 28, Nt = 255, N = 289, J = 137 (firmware README).
//! Memory: row buffer `Ks·(2J + 3)` `f32` ([`RowBuffer::len`]), owned by the caller, and the
//! band transform's 1.3 KB of stack.

use super::scan::{Scan, as_complex};
use crate::config::{Config, Point};
use crate::error::{ArgumentError, check_len, check_points};
use crate::geometry::dist;
use crate::phase::{TwiddleStep, cis_turns, wrap};
use crate::sample::Sample;
use num_complex::Complex32;

/// Caller-owned scratch for one row's spectra: `Ks·(2J + 3)` `f32`.
#[derive(Debug)]
pub struct RowBuffer<'m> {
    hg: &'m mut [Complex32],
    mono: &'m mut [Complex32],
    offset: &'m mut [f32],
    dropped: u32,
}

/// One laser row, ready for the probes: the laser spot, its histograms, and their band
/// spectra `HG`, un-gated values `M` and leg offsets (see the module docs).
#[derive(Debug)]
pub struct Row<'r, T> {
    laser: Point,
    hists: &'r [T],
    hg: &'r [Complex32],
    mono: &'r [Complex32],
    offset: &'r [f32],
    non_finite: u32,
    dropped: u32,
    /// Nt of the scan the row was made for (checked by the probes).
    nt: usize,
}

impl<'m> RowBuffer<'m> {
    /// Length in `f32` of a row buffer for `n_spads` SPADs: `Ks·(2J + 3)`.
    pub const fn len(cfg: &Config, n_spads: usize) -> usize {
        // Saturating: a size that overflows `usize` matches no real slice, so `new` rejects it.
        n_spads.saturating_mul(2 * cfg.bins() + 3)
    }

    /// Wraps `buf` (length [`RowBuffer::len`]) for rows of `scan`.
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if `buf` has the wrong length.
    pub fn new(scan: &Scan<'_>, buf: &'m mut [f32]) -> Result<Self, ArgumentError> {
        let ks = scan.spads.len();
        let j = scan.cfg.bins();
        check_len("row buffer", Self::len(&scan.cfg, ks), buf.len())?;
        let too_short = ArgumentError::Length {
            what: "row buffer",
            expected: Self::len(&scan.cfg, ks),
            found: buf.len(),
        };
        let (hg, rest) = buf.split_at_mut_checked(2 * ks * j).ok_or(too_short)?;
        let (mono, offset) = rest.split_at_mut_checked(2 * ks).ok_or(too_short)?;
        Ok(Self {
            hg: as_complex("row buffer", hg)?,
            mono: as_complex("row buffer", mono)?,
            offset,
            dropped: 0,
        })
    }

    /// Computes the spectra of one laser row. `hists` holds the Ks histograms one after the
    /// other (SPAD-major, `hists[s·Nt + n]`), in the order of [`Scan::spads`].
    ///
    /// Cost `Ks·J·Nt` MACs. Never fails or panics on sample values (non-finite samples read
    /// as 0 and are counted in [`Row::non_finite`]).
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if `hists.len() ≠ Ks·Nt` or this buffer was made for another scan
    /// size; [`ArgumentError::NonFinite`] for a non-finite laser position. Nothing is changed then.
    pub fn load<'r, T: Sample>(
        &'r mut self,
        scan: &Scan<'_>,
        laser: Point,
        hists: &'r [T],
    ) -> Result<Row<'r, T>, ArgumentError> {
        let cfg = &scan.cfg;
        let (nt, j) = (cfg.nt().max(1), cfg.bins().max(1));
        let (carrier_step, block_step) = (scan.k.carrier_step, scan.k.block_step);
        self.load_with(scan, laser, hists, |hg, mono| {
            for ((h, hg), mono) in hists
                .chunks_exact(nt)
                .zip(hg.chunks_exact_mut(j))
                .zip(mono.iter_mut())
            {
                scan.dft_band(h, hg);
                // Un-gated: Σ H_n e^{−iΩ nΔt}, re-seeded every 64 samples from the block
                // recurrence (module docs).
                let mut acc = Complex32::new(0.0, 0.0);
                let mut seed = Complex32::new(1.0, 0.0);
                for block in h.chunks(64) {
                    let mut ph = seed;
                    for &s in block {
                        acc += ph * s.value();
                        ph *= carrier_step;
                    }
                    seed *= block_step;
                }
                *mono = acc;
            }
        })
    }

    /// Like [`RowBuffer::load`], with the raw spectra computed by the caller (a host with a
    /// matrix-multiply or FFT library): `spectra(band, ungated)` must write
    /// `band[s·J + j] = Σ_n h_s[n]·e^{−2πi k_j n/N}` (`k_j = k_lo + j`) and
    /// `ungated[s] = Σ_n h_s[n]·e^{−iΩ nΔt}`, reading non-finite samples as 0. The kernel then
    /// counts non-finite samples and folds gate weights and legs in, exactly as `load`.
    ///
    /// # Errors
    /// As [`RowBuffer::load`]; `spectra` is not called then.
    pub fn load_with<'r, T: Sample>(
        &'r mut self,
        scan: &Scan<'_>,
        laser: Point,
        hists: &'r [T],
        spectra: impl FnOnce(&mut [Complex32], &mut [Complex32]),
    ) -> Result<Row<'r, T>, ArgumentError> {
        self.load_counted(scan, laser, hists, |hg, mono| {
            spectra(hg, mono);
            hists.iter().map(|s| u32::from(!s.is_valid())).sum()
        })
    }

    /// [`RowBuffer::load_with`] where `spectra` also returns the number of non-finite samples
    /// of `hists`, for a caller that learns it while computing the spectra (for example zero
    /// when its raw sums over the unmodified row came out finite: a NaN or ±∞ sample makes
    /// every sum it enters non-finite), so that the row is not read once more to count them.
    /// The count is reported as [`Row::non_finite`] and is not checked.
    ///
    /// # Errors
    /// As [`RowBuffer::load`]; `spectra` is not called then.
    pub fn load_counted<'r, T: Sample>(
        &'r mut self,
        scan: &Scan<'_>,
        laser: Point,
        hists: &'r [T],
        spectra: impl FnOnce(&mut [Complex32], &mut [Complex32]) -> u32,
    ) -> Result<Row<'r, T>, ArgumentError> {
        let cfg = &scan.cfg;
        let (ks, nt, j) = (scan.spads.len(), cfg.nt(), cfg.bins());
        check_len("row buffer", ks * j, self.hg.len())?;
        check_len("histograms", ks * nt, hists.len())?;
        check_points("laser", &[laser])?;
        let non_finite = spectra(self.hg, self.mono);
        self.fold_legs(scan, &laser);
        Ok(Row {
            laser,
            hists,
            hg: self.hg,
            mono: self.mono,
            offset: self.offset,
            non_finite,
            dropped: 0,
            nt,
        })
    }

    /// Folds the gate weights and the leg phases into the raw spectra of a row:
    /// `HG[s][j] ·= Ĝ_j·e^{iν_j x_s}`, `M_s ·= e^{iΩ x_s}`, `x_s = d1 + d4_s − t0`.
    fn fold_legs(&mut self, scan: &Scan<'_>, laser: &Point) {
        let cfg = &scan.cfg;
        let j = cfg.bins().max(1);
        let k = &scan.k;
        let d1 = match &k.origin {
            None => 0.0,
            Some(origin) => dist(laser, origin),
        };
        for (((hg, mono), off), d4) in self
            .hg
            .chunks_exact_mut(j)
            .zip(self.mono.iter_mut())
            .zip(self.offset.iter_mut())
            .zip(scan.d4)
        {
            let x = (d1 + *d4) - k.t0;
            *off = x;
            let mut p = cis_turns(k.klo * x);
            let step = cis_turns(k.inv_span * x);
            for (v, g) in hg.iter_mut().zip(scan.gate) {
                *v = *v * p * *g;
                p *= step;
            }
            *mono *= cis_turns(k.inv_lambda * x);
        }
    }

    /// Starts a row fed by photon events ([`RowBuffer::push_photon`]) instead of histograms:
    /// zeroes the spectra. For firmware that folds TCSPC events as they arrive, with no
    /// histogram memory at all.
    pub fn begin_photons(&mut self) {
        self.hg.fill(Complex32::new(0.0, 0.0));
        self.mono.fill(Complex32::new(0.0, 0.0));
        self.dropped = 0;
    }

    /// Adds one photon of SPAD `spad` (index into [`Scan::spads`]) in time bin `bin`
    /// (path length `t0 + bin·Δt`). Cost: `J` complex additions (an integer phase
    /// accumulator into the twiddle table) and one phase. Photons with `spad ≥ Ks` or
    /// `bin ≥ Nt` are not added and are counted ([`Row::dropped`]); never fails or panics.
    ///
    /// A row of photon events equals the same row loaded as a histogram of counts (up to
    /// `f32` rounding of the summation order).
    pub fn push_photon(&mut self, scan: &Scan<'_>, spad: usize, bin: usize) {
        let cfg = &scan.cfg;
        let (j, nt, n) = (cfg.bins(), cfg.nt(), cfg.n_fft().max(1));
        let start = spad.saturating_mul(j);
        let Some(hg) = self.hg.get_mut(start..start.saturating_add(j)) else {
            self.dropped += 1;
            return;
        };
        let Some(mono) = self.mono.get_mut(spad) else {
            self.dropped += 1;
            return;
        };
        if bin >= nt {
            self.dropped += 1;
            return;
        }
        // Twiddle index (k_j·bin) mod N, stepping by bin per band bin: the accumulator of
        // frequency `bin` at sample k_lo.
        let mut q = TwiddleStep::new(bin as i64, wrap(cfg.k_lo(), n) as u64, n);
        for v in hg.iter_mut() {
            if let Some(w) = scan.twiddle.get(q.index()) {
                *v += *w;
            }
            q.advance();
        }
        *mono += cis_turns(bin as f32 * scan.k.carrier_turns);
    }

    /// Ends a photon-event row: folds gate weights and legs in and returns the row for the
    /// probes. The row has no histograms, so the higher-order (time-domain) gate cannot use
    /// it ([`Probe::push_row`](crate::Probe::push_row) returns [`ArgumentError::Length`]).
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if this buffer was made for another scan size;
    /// [`ArgumentError::NonFinite`] for a non-finite laser position.
    pub fn end_photons<'r>(
        &'r mut self,
        scan: &Scan<'_>,
        laser: Point,
    ) -> Result<Row<'r, u16>, ArgumentError> {
        check_len(
            "row buffer",
            scan.spads.len() * scan.cfg.bins(),
            self.hg.len(),
        )?;
        check_points("laser", &[laser])?;
        self.fold_legs(scan, &laser);
        Ok(Row {
            laser,
            hists: &[],
            hg: self.hg,
            mono: self.mono,
            offset: self.offset,
            non_finite: 0,
            dropped: self.dropped,
            nt: scan.cfg.nt(),
        })
    }
}

impl<'r, T: Sample> Row<'r, T> {
    /// The laser spot of this row.
    pub const fn laser(&self) -> Point {
        self.laser
    }
    /// Number of non-finite samples in this row (read as 0).
    pub const fn non_finite(&self) -> u32 {
        self.non_finite
    }
    /// Histogram length Nt of the scan this row was made for.
    pub const fn nt(&self) -> usize {
        self.nt
    }
    /// Photon-event rows: photons dropped for an out-of-range SPAD or time bin.
    pub const fn dropped(&self) -> u32 {
        self.dropped
    }
    /// The row's histograms, SPAD-major.
    pub const fn histograms(&self) -> &'r [T] {
        self.hists
    }
    /// Band spectra `HG[s·J + j]` (gate weights and legs folded in).
    pub const fn band(&self) -> &'r [Complex32] {
        self.hg
    }
    /// Un-gated values `M_s` (legs folded in).
    pub const fn ungated(&self) -> &'r [Complex32] {
        self.mono
    }
    /// Leg offsets `x_s = d1_l + d4_s − t0` (m).
    pub const fn offsets(&self) -> &'r [f32] {
        self.offset
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::config::{Legs, Params};
    use crate::geometry::dist64;

    /// `load` (and a photon row through `end_photons`) against an `f64` evaluation of the
    /// same formulas — `HG[j] = Ĝ_j·e^{iν_j x}·Σ_n H[n]e^{−2πik_j n/N}`,
    /// `M = e^{iΩx}·Σ_n H[n]e^{−iΩnΔt}`, `x = d1 + d4 − t0` — with legs and a long time
    /// axis: within the module docs' bound, `(ε_dft + 2π·3u·Φ_x + 2.5e-7)·Σ|H|` for `HG`
    /// and `((Nt/64 + 64)·3.5e-7 + 2π·3u·Φ_x)·Σ|H|` for `M`. No `f64` in the row path.
    #[test]
    fn load_matches_f64_reference() {
        use std::vec;
        use std::vec::Vec;
        for (lam, nt, dt, t0, legs) in [
            (0.13, 255, 0.0255, 0.7, true),
            (0.1, 2000, 0.004, 1.5, true),
            (0.2, 300, 0.01, 0.0, false),
        ] {
            let mut p = Params::new(lam, nt, dt);
            p.t0 = t0;
            if legs {
                p.legs = Legs::FirstAndLast {
                    laser_origin: [0.3, -0.2, -1.1],
                    sensor_origin: [-0.4, 0.1, -0.9],
                };
            }
            let cfg = Config::try_new(&p).unwrap();
            let spads = [[0.05f32, 0.1, 0.0], [-0.3, 0.2, 0.01]];
            let ks = spads.len();
            let mut tables = vec![0.0f32; Scan::tables_len(&cfg, ks)];
            let scan = Scan::new(&cfg, &spads, &mut tables).unwrap();
            let mut buf = vec![0.0f32; RowBuffer::len(&cfg, ks)];
            let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
            let mut seed = 11u32;
            let h: Vec<u16> = (0..ks * nt)
                .map(|_| {
                    seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    (seed >> 28) as u16
                })
                .collect();
            let laser = [0.21f32, -0.13, 0.02];
            let (band, mono): (Vec<Complex32>, Vec<Complex32>) = {
                let row = rows.load(&scan, laser, &h).unwrap();
                (row.band().to_vec(), row.ungated().to_vec())
            };
            // The same counts as photon events.
            rows.begin_photons();
            for (sp, hs) in h.chunks_exact(nt).enumerate() {
                for (n, &c) in hs.iter().enumerate() {
                    for _ in 0..c {
                        rows.push_photon(&scan, sp, n);
                    }
                }
            }
            let photons = rows.end_photons(&scan, laser).unwrap();
            let (pband, pmono) = (photons.band().to_vec(), photons.ungated().to_vec());
            let j = cfg.bins();
            let n_fft = cfg.n_fft() as f64;
            let tau = core::f64::consts::TAU;
            for (s, sp) in spads.iter().enumerate() {
                let (d1, d4) = match cfg.legs() {
                    Legs::WallToWall => (0.0, 0.0),
                    Legs::FirstAndLast {
                        laser_origin,
                        sensor_origin,
                    } => (dist64(&laser, &laser_origin), dist64(sp, &sensor_origin)),
                };
                let x = d1 + d4 - cfg.t0();
                let hs = &h[s * nt..(s + 1) * nt];
                let l1: f64 = hs.iter().map(|&c| f64::from(c)).sum();
                let nu_max = (0..j).map(|i| cfg.nu(i).abs()).fold(cfg.omega(), f64::max);
                let phi_x = nu_max * (d1.abs() + d4.abs() + cfg.t0().abs()) / tau;
                let u = f64::from(f32::EPSILON) / 2.0;
                let leg = tau * 3.0 * u * phi_x;
                let dft = (cfg.n_fft() as f64 + nt as f64) * 6e-8;
                // Per bin, relative to Ĝ_j·Σ|H| (the bin's own scale).
                let tol_band = dft + leg + 2.5e-7;
                let tol_mono = ((nt as f64 / 64.0 + 64.0) * 3.5e-7 + leg) * l1;
                let mut worst = [0.0f64; 2];
                for i in 0..j {
                    let k = (cfg.k_lo() + i as i64) as f64;
                    let (mut re, mut im) = (0.0, 0.0);
                    for (n, &c) in hs.iter().enumerate() {
                        let a = -tau * ((k as i64 * n as i64) as f64 % n_fft) / n_fft;
                        re += f64::from(c) * libm::cos(a);
                        im += f64::from(c) * libm::sin(a);
                    }
                    let (sn, cs) = libm::sincos(cfg.nu(i) * x);
                    let g = cfg.gate_weight(i);
                    let (er, ei) = (g * (re * cs - im * sn), g * (re * sn + im * cs));
                    for (w, z) in worst.iter_mut().zip([band[s * j + i], pband[s * j + i]]) {
                        let e = libm::hypot(f64::from(z.re) - er, f64::from(z.im) - ei);
                        *w = w.max(e / (g * l1));
                    }
                }
                assert!(
                    worst[0] <= tol_band,
                    "band {lam} {nt}: {worst:?} > {tol_band:e}"
                );
                assert!(
                    worst[1] <= tol_band,
                    "photons {lam} {nt}: {worst:?} > {tol_band:e}"
                );
                let (mut re, mut im) = (0.0, 0.0);
                for (n, &c) in hs.iter().enumerate() {
                    let a = -cfg.omega() * n as f64 * cfg.dt();
                    re += f64::from(c) * libm::cos(a);
                    im += f64::from(c) * libm::sin(a);
                }
                let (sn, cs) = libm::sincos(cfg.omega() * x);
                let (er, ei) = (re * cs - im * sn, re * sn + im * cs);
                let mut e_mono = 0.0f64;
                for (what, z) in [("load", mono[s]), ("photons", pmono[s])] {
                    let e = libm::hypot(f64::from(z.re) - er, f64::from(z.im) - ei);
                    assert!(
                        e <= tol_mono,
                        "mono {what} {lam} {nt}: {e:e} > {tol_mono:e}"
                    );
                    e_mono = e_mono.max(e);
                }
                std::println!(
                    "λ {lam} Nt {nt}: band err {:.2e} of Ĝ_j·Σ|H| (bound {tol_band:.2e}), mono err {:.2e} of Σ|H| (bound {:.2e})",
                    worst[0].max(worst[1]),
                    e_mono / l1,
                    tol_mono / l1
                );
            }
        }
    }
}
