//! Probes: which LTM elements `T(x_a, x_b)` to accumulate, streamed row by row into
//! caller-owned complex accumulators.
//!
//! | [`Target`] × [`Gate`] | per-row cost | state ([`Probe::state_len`], `f64`) |
//! |---|---|---|
//! | diagonal × Gaussian (Eq. 11–12) | `Kv·Ks·(14J + E0)` | `2Kv` |
//! | diagonal × none (Fig. 6) | `Kv·Ks·E0` | `2Kv` |
//! | diagonal × higher-order | `Kv·Ks·(E0 + 7R)` + `Ks·8Nt` | `2Kv + 2(Nt+1)` |
//! | column × Gaussian (Eq. 13–14, factorised) | `Ks·8J` (+ once `Kb·Ks·14J`) | `2J(Ks+1)` |
//! | column × none | `Ks·8` (+ once `Kb·Ks·E0`) | `2Ks` |
//! | column × higher-order (Eq. 18) | `Kb·Ks·(E0 + 7R)` + `Ks·8Nt` | `2Kb + 2(Nt+1)` |
//!
//! (`E0` ≈ 60 flops: a distance, weights, two phase seeds; `R = ⌈c_gσ/Δt⌉ + 1`.)
//!
//! Amplitudes (sign convention A, as y-tal: the gated phasor `Z`):
//! `A(a,b) = Σ_l Σ_s w(|x_l − x_a|)·w(|x_b − x_s|)·Z_ls(τ_ls)` with
//! `τ_ls = d1_l + |x_l − x_a| + |x_a − x_b| + |x_b − x_s| + d4_s` (a = b on the diagonal),
//! and intensities `T = |A|²` from [`Probe::finish`].
//!
//! * The Gaussian gate is the band sum (Z-F); on the diagonal a path time outside the guard
//!   interval ([`Config::guard`]) contributes nothing. The factorised column cannot apply a
//!   per-path guard: it is exact while every path time stays inside
//!   [`Config::alias_free`], and [`Report::aliased`] counts the voxels for which it did not
//!   (widen [`Params::margin`](crate::Params::margin) to remove them).
//! * The higher-order gate (Eq. 18) is evaluated in the time domain with suffix sums,
//!   exactly; the un-gated probe uses the monochromatic phasor.
//! * Accumulators are `f64` complex; each row's contribution to an element is summed over the
//!   SPADs in `f32` first (the phasor arithmetic is `f32`).

use super::row::Row;
use super::scan::Scan;
use crate::config::{Config, Point};
use crate::error::{ArgumentError, check_len, check_points};
use crate::geometry::{alias_window, dist, leaves_window, widen};
use crate::phase::{cis_turns, cis_turns_f64};
use crate::report::Report;
use crate::sample::Sample;
use num_complex::{Complex32, Complex64};

/// Which elements of the light transport matrix a probe accumulates.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Target {
    /// The diagonal `T(x_v, x_v)` over the voxel list: direct light (3-vertex path).
    Diagonal,
    /// The column `T(x_a, ·)` over the voxel list for the focus `x_a` (4-vertex path).
    Column(Point),
}

/// The time gate applied around the path time τ.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Gate {
    /// Gaussian gate `g(t − τ)` (Eqs. 11–14), evaluated in the frequency band.
    Gaussian,
    /// The paper's late gate (Eq. 18): 0 for `t ≤ τ`, `1 − g(t − τ)` after.
    HigherOrder,
    /// No gate: the monochromatic phasor over the whole histogram (paper Fig. 6).
    None,
}

/// A probe: a [`Target`], a [`Gate`], a voxel list and caller-owned accumulator state.
///
/// ```
/// use vltm_kernel::{Config, Gate, Params, Probe, RowBuffer, Scan, Target};
/// let cfg = Config::try_new(&Params::new(0.2, 128, 0.01)).unwrap();
/// let spads = [[0.0f32, 0.0, 0.0]];
/// let voxels = [[0.0f32, 0.0, 0.5], [0.0, 0.0, 0.8]]; // paths of 1.0 m and 1.6 m
/// let mut tables = vec![0.0; Scan::tables_len(&cfg, 1)];
/// let scan = Scan::new(&cfg, &spads, &mut tables).unwrap();
/// let mut state = vec![0.0; Probe::state_len(&cfg, Target::Diagonal, Gate::Gaussian, 2, 1)];
/// let mut diag = Probe::new(&scan, Target::Diagonal, Gate::Gaussian, &voxels, &mut state).unwrap();
/// let mut buf = vec![0.0; RowBuffer::len(&cfg, 1)];
/// let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
/// let mut h = [0u16; 128];
/// h[100] = 50; // a return at path length 1.00 m = 2 × 0.5 m
/// let row = rows.load(&scan, [0.0, 0.0, 0.0], &h).unwrap();
/// diag.push_row(&scan, &row).unwrap();
/// let mut out = [0.0f64; 2];
/// diag.finish(&scan, &mut out).unwrap();
/// assert!(out[0] > 10.0 * out[1]);
/// ```
#[derive(Debug)]
pub struct Probe<'m> {
    target: Target,
    gate: Gate,
    voxels: &'m [Point],
    state: &'m mut [Complex64],
    report: Report,
    /// Min / max over rows of the projector leg `d1_l + |x_l − x_a|` (columns).
    leg_range: (f64, f64),
    /// The configuration of the scan the probe was made for (checked by `merge`).
    cfg: Config,
}

impl<'m> Probe<'m> {
    /// Length in `f64` of the state of a probe (see the table in the module docs).
    pub const fn state_len(
        cfg: &Config,
        target: Target,
        gate: Gate,
        n_voxels: usize,
        n_spads: usize,
    ) -> usize {
        // Saturating: a size that overflows `usize` matches no real slice, so `new` rejects it.
        let complex = match (target, gate) {
            (Target::Column(_), Gate::Gaussian) => {
                n_spads.saturating_add(1).saturating_mul(cfg.bins())
            }
            (Target::Column(_), Gate::None) => n_spads,
            (_, Gate::HigherOrder) => n_voxels.saturating_add(cfg.nt() + 1),
            (Target::Diagonal, _) => n_voxels,
        };
        complex.saturating_mul(2)
    }

    /// Bytes of state: `8 ·` [`Probe::state_len`].
    pub const fn state_bytes(
        cfg: &Config,
        target: Target,
        gate: Gate,
        n_voxels: usize,
        n_spads: usize,
    ) -> usize {
        Self::state_len(cfg, target, gate, n_voxels, n_spads).saturating_mul(8)
    }

    /// A zeroed probe over `voxels` with its state in `state`.
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if `state` does not have [`Probe::state_len`] elements;
    /// [`ArgumentError::NonFinite`] for a non-finite voxel or focus.
    pub fn new(
        scan: &Scan<'_>,
        target: Target,
        gate: Gate,
        voxels: &'m [Point],
        state: &'m mut [f64],
    ) -> Result<Self, ArgumentError> {
        let p = Self::resume(
            scan,
            target,
            gate,
            voxels,
            state,
            Report::default(),
            (f64::INFINITY, f64::NEG_INFINITY),
        )?;
        p.state.fill(Complex64::new(0.0, 0.0));
        Ok(p)
    }

    /// A probe over accumulators saved from an earlier one: `state` is taken as it is (not
    /// zeroed), with that probe's counters ([`Probe::report`]) and projector leg range
    /// ([`Probe::leg_range`]). Lets a host keep a scan's state between processes (a scan
    /// split by rows, merged and finished elsewhere).
    ///
    /// # Errors
    /// As [`Probe::new`].
    pub fn resume(
        scan: &Scan<'_>,
        target: Target,
        gate: Gate,
        voxels: &'m [Point],
        state: &'m mut [f64],
        report: Report,
        leg_range: (f64, f64),
    ) -> Result<Self, ArgumentError> {
        let cfg = scan.config();
        let need = Self::state_len(cfg, target, gate, voxels.len(), scan.spads().len());
        check_len("state", need, state.len())?;
        check_points("voxels", voxels)?;
        if let Target::Column(a) = target {
            check_points("focus", &[a])?;
        }
        let found = state.len();
        let state: &mut [Complex64] =
            bytemuck::try_cast_slice_mut(state).map_err(|_| ArgumentError::Length {
                what: "state",
                expected: need,
                found,
            })?;
        Ok(Self {
            target,
            gate,
            voxels,
            state,
            report,
            leg_range,
            cfg: *cfg,
        })
    }

    /// The accumulators as they are (the state given to [`Probe::new`], as complex numbers):
    /// what a host saves to [resume](Probe::resume) the probe elsewhere.
    pub fn accumulators(&self) -> &[Complex64] {
        self.state
    }

    /// Min / max over the rows so far of the projector leg `d1_l + |x_l − x_a|` (m) of a
    /// column; `(+∞, −∞)` before the first row and for the diagonal.
    pub const fn leg_range(&self) -> (f64, f64) {
        self.leg_range
    }

    /// The target.
    pub const fn target(&self) -> Target {
        self.target
    }
    /// The gate.
    pub const fn gate(&self) -> Gate {
        self.gate
    }
    /// The voxel list.
    pub const fn voxels(&self) -> &'m [Point] {
        self.voxels
    }
    /// Counters so far (`aliased` is computed by [`Probe::finish`]).
    pub const fn report(&self) -> Report {
        self.report
    }

    /// Zeroes the accumulators and counters (keeps target, gate, voxels and memory).
    pub fn reset(&mut self) {
        self.state.fill(Complex64::new(0.0, 0.0));
        self.report = Report::default();
        self.leg_range = (f64::INFINITY, f64::NEG_INFINITY);
    }

    /// Adds one laser row. Rows may come in any order; a scan split over several probes and
    /// [merged](Probe::merge) gives the same result.
    ///
    /// Infallible on data values and panic-free.
    ///
    /// # Errors
    /// [`ArgumentError::Incompatible`] if `scan` has another configuration than the probe's (as
    /// [`Probe::merge`]); [`ArgumentError::Length`] if `row` was loaded for a scan of another size
    /// (checked once). Nothing is changed then.
    pub fn push_row<T: Sample>(
        &mut self,
        scan: &Scan<'_>,
        row: &Row<'_, T>,
    ) -> Result<(), ArgumentError> {
        let cfg = scan.config();
        if *cfg != self.cfg {
            // As `merge`: a scan of another configuration has other frequencies and legs.
            return Err(ArgumentError::Incompatible("scan of another configuration"));
        }
        let ks = scan.spads().len();
        check_len("row spectra", ks * cfg.bins(), row.band().len())?;
        // A row made for another time axis has spectra of other frequencies.
        check_len("row histograms", ks * cfg.nt(), ks * row.nt())?;
        if self.gate == Gate::HigherOrder {
            // The time-domain gate needs the histograms (photon-event rows have none).
            check_len("row histograms", ks * cfg.nt(), row.histograms().len())?;
        }
        let n_vox = self.voxels.len();
        let split = match self.gate {
            Gate::HigherOrder => n_vox,
            _ => self.state.len(),
        };
        // `min`: the state is at least `n_vox` long (`new` checked it); no panicking branch.
        let (acc, scratch) = self.state.split_at_mut(split.min(self.state.len()));
        let laser = row.laser();
        match (self.target, self.gate) {
            (Target::Diagonal, Gate::Gaussian) => diag_band(scan, row, self.voxels, acc),
            (Target::Diagonal, Gate::None) => diag_ungated(scan, row, self.voxels, acc),
            (Target::Column(a), Gate::Gaussian) => {
                let d_la = dist(&laser, &a);
                self.leg_range = widen(self.leg_range, scan.laser_leg(&laser) + d_la as f64);
                column_band_push(scan, row, cfg.weight(d_la), d_la, acc);
            }
            (Target::Column(a), Gate::None) => {
                let d_la = dist(&laser, &a);
                let w = cfg.weight(d_la) as f64;
                let p = cis_turns((d_la as f64 / cfg.wavelength()) as f32);
                for (u, m) in acc.iter_mut().zip(row.ungated()) {
                    *u += c64(p * *m) * w;
                }
            }
            (target, Gate::HigherOrder) => {
                higher_order(scan, row, target, self.voxels, acc, scratch);
            }
        }
        self.report.count_row(row);
        Ok(())
    }

    /// Adds another probe's accumulators (same configuration, target, gate and voxels):
    /// the merge of a scan split over workers or devices.
    ///
    /// # Errors
    /// [`ArgumentError::Incompatible`] if the probes differ; nothing is changed then.
    pub fn merge(&mut self, other: &Probe<'_>) -> Result<(), ArgumentError> {
        if self.target != other.target || self.gate != other.gate {
            return Err(ArgumentError::Incompatible("different target or gate"));
        }
        if self.voxels != other.voxels
            || self.state.len() != other.state.len()
            || self.cfg != other.cfg
        {
            return Err(ArgumentError::Incompatible(
                "different voxels or configuration",
            ));
        }
        let n = match self.gate {
            Gate::HigherOrder => self.voxels.len(),
            _ => self.state.len(),
        };
        for (a, b) in self.state.iter_mut().zip(other.state.iter()).take(n) {
            *a += *b;
        }
        self.report.add_part(&other.report);
        // Union of the two ranges; an empty one is (+∞, −∞) and must leave the other as is.
        let (lo, hi) = other.leg_range;
        self.leg_range = (self.leg_range.0.min(lo), self.leg_range.1.max(hi));
        Ok(())
    }

    /// Writes the intensities `T = |A|²` of every voxel into `out` (length = voxels) and
    /// returns the counters. Factorised columns image all voxels here (cost
    /// `Kb·Ks·14J` for the Gaussian gate). Does not change the accumulators, so a scan can be
    /// finished, continued and finished again.
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if `out` has the wrong length.
    pub fn finish(&self, scan: &Scan<'_>, out: &mut [f64]) -> Result<Report, ArgumentError> {
        check_len("out", self.voxels.len(), out.len())?;
        if self.is_factorised() {
            return self.image(scan, self.voxels, out);
        }
        for (o, a) in out.iter_mut().zip(self.state.iter()) {
            *o = a.norm_sqr();
        }
        Ok(self.report)
    }

    /// Factorised Gaussian columns only: the accumulated spectra
    /// `U_a[s·J + j] = Σ_l w(|x_l − x_a|)·e^{iν_j|x_l − x_a|}·HG_ls[j]` and the
    /// range (min, max) of the projector legs `d1_l + |x_l − x_a|` seen so far (m), for hosts
    /// that image the column by other means (an FFT convolution over a SPAD grid). `None`
    /// for other probes.
    pub fn column_spectra(&self) -> Option<(&[Complex64], (f64, f64))> {
        match (self.target, self.gate) {
            (Target::Column(_), Gate::Gaussian) => Some((
                self.state
                    .split_at(self.state.len().saturating_sub(self.cfg.bins()))
                    .0,
                self.leg_range,
            )),
            _ => None,
        }
    }

    /// Whether the probe is a factorised column (Gaussian or un-gated), whose state does not
    /// depend on the imaged voxels and can be imaged anywhere with [`Probe::image`].
    pub const fn is_factorised(&self) -> bool {
        matches!(
            (self.target, self.gate),
            (Target::Column(_), Gate::Gaussian | Gate::None)
        )
    }

    /// Factorised columns only: images arbitrary voxels `b` (not only the probe's own list)
    /// from the accumulated state, `out[i] = T(x_a, voxels[i])`. Lets a host split the
    /// imaging over threads or image a Γ set.
    ///
    /// # Errors
    /// [`ArgumentError::Incompatible`] for probes that are not factorised columns; [`ArgumentError::Length`]
    /// if `out.len() ≠ voxels.len()`; [`ArgumentError::NonFinite`] for a non-finite voxel.
    pub fn image(
        &self,
        scan: &Scan<'_>,
        voxels: &[Point],
        out: &mut [f64],
    ) -> Result<Report, ArgumentError> {
        check_len("out", voxels.len(), out.len())?;
        check_points("voxels", voxels)?;
        let mut report = self.report;
        match (self.target, self.gate) {
            (Target::Column(a), Gate::Gaussian) => {
                report.aliased =
                    column_band_finish(scan, a, voxels, self.state, self.leg_range, out);
            }
            (Target::Column(a), Gate::None) => {
                let cfg = scan.config();
                for (o, b) in out.iter_mut().zip(voxels) {
                    let d_ab = dist(&a, b);
                    let mut sum = Complex64::new(0.0, 0.0);
                    for (u, sp) in self.state.iter().zip(scan.spads()) {
                        let d_bs = dist(b, sp);
                        let p = cis_turns(((d_ab + d_bs) as f64 / cfg.wavelength()) as f32);
                        sum += c64(p) * *u * cfg.weight(d_bs) as f64;
                    }
                    *o = sum.norm_sqr();
                }
            }
            _ => {
                return Err(ArgumentError::Incompatible(
                    "only factorised columns can image other voxels",
                ));
            }
        }
        Ok(report)
    }
}

#[inline]
fn c64(z: Complex32) -> Complex64 {
    Complex64::new(z.re as f64, z.im as f64)
}

/// `Σ_j hg[j]·e^{iν_j τ}` with `e^{iν_j τ}` by recurrence from two seeds,
/// in four interleaved chains (`p_{j+4} = p_j·step⁴`) so that the complex multiplies do not
/// wait on each other; the phase error still grows as ≈ (J/4)·6e-8.
#[inline]
pub(crate) fn band_sum(hg: &[Complex32], tau: f32, klo_per_span: f32, inv_span: f32) -> Complex32 {
    let step = cis_turns(inv_span * tau);
    let p0 = cis_turns(klo_per_span * tau);
    let step2 = step * step;
    let step4 = step2 * step2;
    let mut p = [p0, p0 * step, p0 * step2, p0 * step2 * step];
    let mut z = [Complex32::new(0.0, 0.0); 4];
    let mut quads = hg.chunks_exact(4);
    for q in &mut quads {
        for i in 0..4 {
            z[i] += q[i] * p[i];
            p[i] *= step4;
        }
    }
    for (h, pi) in quads.remainder().iter().zip(p) {
        z[0] += *h * pi;
    }
    (z[0] + z[1]) + (z[2] + z[3])
}

/// Band constants in `f32`: (k_lo/(NΔt), 1/(NΔt)); phases in turns are `k·τ/(NΔt)`.
pub(crate) fn band_consts(cfg: &Config) -> (f32, f32) {
    let span = cfg.span();
    ((cfg.k_lo() as f64 / span) as f32, (1.0 / span) as f32)
}

fn diag_band<T: Sample>(
    scan: &Scan<'_>,
    row: &Row<'_, T>,
    voxels: &[Point],
    acc: &mut [Complex64],
) {
    let cfg = scan.config();
    let j = cfg.bins().max(1);
    let (klo, inv) = band_consts(cfg);
    let (g_lo, g_hi) = cfg.guard();
    let (g_lo, g_hi) = (g_lo as f32, g_hi as f32);
    let laser = row.laser();
    for (a, v) in acc.iter_mut().zip(voxels) {
        let d_lv = dist(&laser, v);
        let mut sum = Complex32::new(0.0, 0.0);
        for ((sp, hg), off) in scan
            .spads()
            .iter()
            .zip(row.band().chunks_exact(j))
            .zip(row.offsets())
        {
            let d_vs = dist(v, sp);
            let tau = d_lv + d_vs;
            let rel = tau + off;
            if rel >= g_lo && rel <= g_hi {
                sum += band_sum(hg, tau, klo, inv) * cfg.weight(d_vs);
            }
        }
        *a += c64(sum * cfg.weight(d_lv));
    }
}

fn diag_ungated<T: Sample>(
    scan: &Scan<'_>,
    row: &Row<'_, T>,
    voxels: &[Point],
    acc: &mut [Complex64],
) {
    let cfg = scan.config();
    let inv_lam = (1.0 / cfg.wavelength()) as f32;
    let laser = row.laser();
    for (a, v) in acc.iter_mut().zip(voxels) {
        let d_lv = dist(&laser, v);
        let mut sum = Complex32::new(0.0, 0.0);
        for (sp, m) in scan.spads().iter().zip(row.ungated()) {
            let d_vs = dist(v, sp);
            sum += *m * cis_turns((d_lv + d_vs) * inv_lam) * cfg.weight(d_vs);
        }
        *a += c64(sum * cfg.weight(d_lv));
    }
}

/// Factorised column, per row: `U[s][j] += w_la e^{iν_j d_la} HG_ls[j]`.
fn column_band_push<T: Sample>(
    scan: &Scan<'_>,
    row: &Row<'_, T>,
    w: f32,
    d_la: f32,
    state: &mut [Complex64],
) {
    let cfg = scan.config();
    let j = cfg.bins().max(1);
    let (klo, inv) = band_consts(cfg);
    let (u, phase) = state.split_at_mut(state.len().saturating_sub(cfg.bins()));
    let mut p = cis_turns(klo * d_la) * w;
    let step = cis_turns(inv * d_la);
    for ph in phase.iter_mut() {
        *ph = c64(p);
        p *= step;
    }
    // Not `zip`: an out-of-line `Zip::new` re-derives the chunks' `size_hint` by a division
    // whose divisor (`j ≥ 1`) it cannot see, a panicking branch in the no-panic link.
    let mut hgs = row.band().chunks_exact(j);
    for us in u.chunks_exact_mut(j) {
        let Some(hg) = hgs.next() else { break };
        for ((u, h), ph) in us.iter_mut().zip(hg).zip(phase.iter()) {
            *u += c64(*h) * *ph;
        }
    }
}

/// Factorised column, at the end: `A(b) = Σ_s w_bs Σ_j e^{iν_j(d_ab + d_bs)} U[s][j]`.
fn column_band_finish(
    scan: &Scan<'_>,
    a: Point,
    voxels: &[Point],
    state: &[Complex64],
    leg_range: (f64, f64),
    out: &mut [f64],
) -> usize {
    let cfg = scan.config();
    let j = cfg.bins().max(1);
    let (klo, inv) = band_consts(cfg);
    let window = alias_window(cfg);
    let u = state.split_at(state.len().saturating_sub(cfg.bins())).0;
    let mut aliased = 0;
    for (o, b) in out.iter_mut().zip(voxels) {
        let d_ab = dist(&a, b);
        let mut sum = Complex64::new(0.0, 0.0);
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for ((sp, us), d4) in scan
            .spads()
            .iter()
            .zip(u.chunks_exact(j))
            .zip(scan.sensor_legs())
        {
            let d_bs = dist(b, sp);
            let tau = d_ab + d_bs;
            (lo, hi) = widen((lo, hi), f64::from(tau + d4));
            let mut p = cis_turns(klo * tau);
            let step = cis_turns(inv * tau);
            let mut z = Complex64::new(0.0, 0.0);
            for x in us {
                z += *x * c64(p);
                p *= step;
            }
            sum += z * cfg.weight(d_bs) as f64;
        }
        if leaves_window(window, leg_range, (lo, hi)) {
            aliased += 1;
        }
        *o = sum.norm_sqr();
    }
    aliased
}

/// Eq. 18 by suffix sums, SPAD-outer so one histogram's sums are in scratch:
/// `S[n] = Σ_{m ≥ n} H_m e^{−iΩ(t_m − t0)}`, `D[n] = S[n] − S[n+1]`,
/// `Z = e^{iΩ(τ − t0)}·(S[n*] − Σ_{n*}^{n*+R−1} D[n]·g(t_n − τ))`.
fn higher_order<T: Sample>(
    scan: &Scan<'_>,
    row: &Row<'_, T>,
    target: Target,
    voxels: &[Point],
    acc: &mut [Complex64],
    s_buf: &mut [Complex64],
) {
    let cfg = scan.config();
    let nt = cfg.nt();
    let (dt, lam, sigma) = (cfg.dt(), cfg.wavelength(), cfg.sigma());
    let r = cfg.ho_support();
    let inv2s2 = 0.5 / (sigma * sigma);
    let q = libm::exp(-dt * dt / (sigma * sigma));
    let laser = row.laser();
    let d1 = scan.laser_leg(&laser);
    let turns_per_bin = -dt / lam;
    let step = c64(cis_turns_f64(turns_per_bin));
    for ((h, sp), d4) in row
        .histograms()
        .chunks_exact(nt.max(1))
        .zip(scan.spads())
        .zip(scan.sensor_legs())
    {
        // Suffix sums, carrier re-seeded every 64 samples (phase reference t0).
        if let Some(last) = s_buf.last_mut() {
            *last = Complex64::new(0.0, 0.0);
        }
        let mut next = Complex64::new(0.0, 0.0);
        for (c, block) in h.chunks(64).enumerate().rev() {
            let base = c * 64;
            let mut ph = c64(cis_turns_f64(
                (base + block.len() - 1) as f64 * turns_per_bin,
            ));
            let inv_step = step.conj();
            for (i, x) in block.iter().enumerate().rev() {
                next += ph * x.value() as f64;
                if let Some(s) = s_buf.get_mut(base + i) {
                    *s = next;
                }
                ph *= inv_step;
            }
        }
        let off = d1 + *d4 as f64 - cfg.t0();
        for (a_acc, v) in acc.iter_mut().zip(voxels) {
            let (a, b) = match target {
                Target::Diagonal => (*v, *v),
                Target::Column(a) => (a, *v),
            };
            let d_la = dist(&laser, &a) as f64;
            let d_bs = dist(&b, sp) as f64;
            let tau_rel = d_la + dist(&a, &b) as f64 + d_bs + off; // τ − t0
            let x = tau_rel / dt;
            let n_star = (libm::floor(x) + 1.0).clamp(0.0, nt as f64) as usize;
            let head = s_buf.get(n_star).copied().unwrap_or_default();
            let u0 = (n_star as f64 - x) * dt; // t_{n*} − τ ≥ 0
            let mut g = libm::exp(-u0 * u0 * inv2s2);
            let mut ratio = libm::exp(-(2.0 * u0 * dt + dt * dt) * inv2s2);
            let mut corr = Complex64::new(0.0, 0.0);
            for n in n_star..(n_star + r).min(nt) {
                let (Some(s0), Some(s1)) = (s_buf.get(n), s_buf.get(n + 1)) else {
                    break;
                };
                corr += (*s0 - *s1) * g;
                g *= ratio;
                ratio *= q;
            }
            let z = c64(cis_turns_f64(tau_rel / lam)) * (head - corr);
            *a_acc += z * (cfg.weight(d_la as f32) * cfg.weight(d_bs as f32)) as f64;
        }
    }
}
