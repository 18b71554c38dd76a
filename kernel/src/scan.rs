//! Stage 1: the fixed description of a scan ([`Scan`]: configuration, SPAD positions, band
//! tables) and the per-row spectra ([`RowBuffer::load`] → [`Row`]).
//!
//! Per laser row `l` and SPAD `s`, with `x_ls = d1_l + d4_s − t0` (DESIGN §B.2.3):
//!
//! * band spectrum `HG_ls[j] = Ĝ_j · e^{iν_j x_ls} · Σ_n H_ls[n]·e^{−2πi k_j n/N}` (J values),
//!   the DFT by an **integer phase accumulator** `(k_j·n) mod N` into a table of
//!   `e^{−2πiq/N}` made once with `f64` `libm` (table error ≤ 6e-8), so no drift with n;
//! * un-gated value `M_ls = e^{iΩ x_ls} · Σ_n H_ls[n]·e^{−iΩ nΔt}` (the monochromatic
//!   phasor at Ω), by a complex recurrence re-seeded from `f64` every 64 samples;
//! * the leg offset `x_ls` itself (for the guard and the time-domain gates).
//!
//! Cost per row: `Ks·J·Nt` real×complex MACs (+ `Ks·Nt` for `M`, `Ks·J` for the legs).
//! Memory: tables `2N + J + Ks` `f32` ([`Scan::tables_len`]), row buffer
//! `Ks·(2J + 3)` `f32` ([`RowBuffer::len`]). All owned by the caller.

use crate::config::{Config, Legs, Point};
use crate::error::{Error, check_len, check_points};
use crate::sample::Sample;
use crate::trig::cis_turns_f64;
use num_complex::Complex32;

/// Euclidean distance in `f32` (correctly rounded `sqrtf`).
#[inline]
pub(crate) fn dist(a: &Point, b: &Point) -> f32 {
    let (x, y, z) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    libm::sqrtf(x * x + y * y + z * z)
}

fn dist64(a: &Point, b: &[f64; 3]) -> f64 {
    let (x, y, z) = (a[0] as f64 - b[0], a[1] as f64 - b[1], a[2] as f64 - b[2]);
    libm::sqrt(x * x + y * y + z * z)
}

/// Casts a caller's `f32` buffer to complex numbers (always succeeds for even lengths:
/// `Complex32` has the alignment of `f32`).
pub(crate) fn as_complex<'b>(
    what: &'static str,
    buf: &'b mut [f32],
) -> Result<&'b mut [Complex32], Error> {
    let found = buf.len();
    bytemuck::try_cast_slice_mut(buf).map_err(|_| Error::Length {
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
    cfg: Config,
    spads: &'t [Point],
    twiddle: &'t [Complex32],
    gate: &'t [f32],
    d4: &'t [f32],
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
    /// [`Error::Length`] if `tables` has the wrong length, [`Error::NonFinite`] if a SPAD
    /// position is not finite.
    pub fn new(cfg: &Config, spads: &'t [Point], tables: &'t mut [f32]) -> Result<Self, Error> {
        check_len("tables", Self::tables_len(cfg, spads.len()), tables.len())?;
        check_points("spads", spads)?;
        let n = cfg.n_fft();
        // `_checked` (the lengths were checked above): no panicking branch in the ELF.
        let too_short = Error::Length {
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
        for (d, p) in d4.iter_mut().zip(spads) {
            *d = match cfg.legs() {
                Legs::WallToWall => 0.0,
                Legs::FirstAndLast { sensor_origin, .. } => dist64(p, &sensor_origin) as f32,
            };
        }
        Ok(Self {
            cfg: *cfg,
            spads,
            twiddle,
            gate,
            d4,
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
    /// `out[j] = Σ_n h[n]·e^{−2πi k_j n/N}`. Non-finite samples read as 0.
    fn dft_band<T: Sample>(&self, h: &[T], out: &mut [Complex32]) {
        // `max(1)`: N ≥ Nt ≥ 1 already; lets the optimiser drop the division-by-zero branch.
        let n = self.cfg.n_fft().max(1) as u64;
        let k_lo = self.cfg.k_lo();
        for (j, o) in out.iter_mut().enumerate() {
            let step = (k_lo + j as i64).rem_euclid(n as i64) as usize;
            let n = n as usize;
            let (mut re, mut im, mut q) = (0.0f32, 0.0f32, 0usize);
            for &x in h {
                if let Some(w) = self.twiddle.get(q) {
                    let v = x.value();
                    re += v * w.re;
                    im += v * w.im;
                }
                q += step;
                if q >= n {
                    q -= n;
                }
            }
            *o = Complex32::new(re, im);
        }
    }
}

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
    /// [`Error::Length`] if `buf` has the wrong length.
    pub fn new(scan: &Scan<'_>, buf: &'m mut [f32]) -> Result<Self, Error> {
        let ks = scan.spads.len();
        let j = scan.cfg.bins();
        check_len("row buffer", Self::len(&scan.cfg, ks), buf.len())?;
        let too_short = Error::Length {
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
    /// [`Error::Length`] if `hists.len() ≠ Ks·Nt` or this buffer was made for another scan
    /// size; [`Error::NonFinite`] for a non-finite laser position. Nothing is changed then.
    pub fn load<'r, T: Sample>(
        &'r mut self,
        scan: &Scan<'_>,
        laser: Point,
        hists: &'r [T],
    ) -> Result<Row<'r, T>, Error> {
        let cfg = &scan.cfg;
        let (nt, j) = (cfg.nt().max(1), cfg.bins().max(1));
        let turns_per_bin = -cfg.dt() / cfg.wavelength();
        let carrier_step = cis_turns_f64(turns_per_bin);
        self.load_with(scan, laser, hists, |hg, mono| {
            for ((h, hg), mono) in hists
                .chunks_exact(nt)
                .zip(hg.chunks_exact_mut(j))
                .zip(mono.iter_mut())
            {
                scan.dft_band(h, hg);
                // Un-gated: Σ H_n e^{−iΩ nΔt}, re-seeded every 64 samples.
                let mut acc = Complex32::new(0.0, 0.0);
                for (c, block) in h.chunks(64).enumerate() {
                    let mut ph = cis_turns_f64((c * 64) as f64 * turns_per_bin);
                    for &s in block {
                        acc += ph * s.value();
                        ph *= carrier_step;
                    }
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
    ) -> Result<Row<'r, T>, Error> {
        let cfg = &scan.cfg;
        let (ks, nt, j) = (scan.spads.len(), cfg.nt(), cfg.bins());
        check_len("row buffer", ks * j, self.hg.len())?;
        check_len("histograms", ks * nt, hists.len())?;
        check_points("laser", &[laser])?;
        spectra(self.hg, self.mono);
        let non_finite = hists.iter().map(|s| u32::from(!s.is_valid())).sum();
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
        let d1 = scan.laser_leg(laser);
        let span = cfg.span();
        let k_lo = cfg.k_lo() as f64;
        for (((hg, mono), off), d4) in self
            .hg
            .chunks_exact_mut(j)
            .zip(self.mono.iter_mut())
            .zip(self.offset.iter_mut())
            .zip(scan.d4)
        {
            let x = d1 + *d4 as f64 - cfg.t0();
            *off = x as f32;
            let mut p = cis_turns_f64(k_lo * x / span);
            let step = cis_turns_f64(x / span);
            for (v, g) in hg.iter_mut().zip(scan.gate) {
                *v = *v * p * *g;
                p *= step;
            }
            *mono *= cis_turns_f64(x / cfg.wavelength());
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
        // Twiddle index (k_j·bin) mod N, stepping by bin per band bin (all < N ≤ 2³⁰); the
        // first product is taken in u64 (it reaches 2⁶⁰, past a 32-bit usize).
        let k0 = cfg.k_lo().rem_euclid(n as i64) as u64;
        let mut q = ((k0 * bin as u64) % n as u64) as usize;
        let step = bin % n;
        for v in hg.iter_mut() {
            if let Some(w) = scan.twiddle.get(q) {
                *v += *w;
            }
            q += step;
            if q >= n {
                q -= n;
            }
        }
        *mono += cis_turns_f64(bin as f64 * -cfg.dt() / cfg.wavelength());
    }

    /// Ends a photon-event row: folds gate weights and legs in and returns the row for the
    /// probes. The row has no histograms, so the higher-order (time-domain) gate cannot use
    /// it ([`Probe::push_row`](crate::Probe::push_row) returns [`Error::Length`]).
    ///
    /// # Errors
    /// [`Error::Length`] if this buffer was made for another scan size;
    /// [`Error::NonFinite`] for a non-finite laser position.
    pub fn end_photons<'r>(
        &'r mut self,
        scan: &Scan<'_>,
        laser: Point,
    ) -> Result<Row<'r, u16>, Error> {
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
