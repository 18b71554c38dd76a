//! [`FixedColumn`]: the factorised Gaussian column in fixed point.

use super::arith::scale;
use super::config::FixedConfig;
use super::nco::{cis_q15, phase_step};
use super::row::FixedRow;
use super::scan::FixedScan;
use crate::config::Point;
use crate::error::{ArgumentError, check_len, check_points};
use crate::geometry::{alias_window, dist, leaves_window, widen};

/// Factorised Gaussian column `T(x_a, ·)` in fixed point: per row
/// `U[s][j] += w_la·e^{iν_j d_la}·HG_ls[j]` (`i64` complex, `2·Ks·J`, LSB
/// [`FixedConfig::column_lsb`]), imaged at [`FixedColumn::finish`] with the same NCO and
/// `i128` sums. Exact while path times stay inside [`Config::alias_free`](crate::Config::alias_free) (counted in the
/// return value of `finish`, as [`Report::aliased`](crate::Report)).
#[derive(Debug)]
pub struct FixedColumn<'m> {
    pub(super) focus: Point,
    pub(super) state: &'m mut [i64],
    pub(super) rows: u32,
    pub(super) leg_range: (f64, f64),
}

impl<'m> FixedColumn<'m> {
    /// State length in `i64`: `2·Ks·J`.
    pub const fn state_len(fc: &FixedConfig, n_spads: usize) -> usize {
        2 * n_spads * fc.cfg.bins()
    }

    /// A column probe for focus `focus` with zeroed `state`.
    ///
    /// # Errors
    /// [`ArgumentError::Length`] / [`ArgumentError::NonFinite`].
    pub fn new(
        scan: &FixedScan<'_>,
        focus: Point,
        state: &'m mut [i64],
    ) -> Result<Self, ArgumentError> {
        check_len(
            "state",
            Self::state_len(&scan.fc, scan.spads.len()),
            state.len(),
        )?;
        check_points("focus", &[focus])?;
        state.fill(0);
        Ok(Self {
            focus,
            state,
            rows: 0,
            leg_range: (f64::INFINITY, f64::NEG_INFINITY),
        })
    }

    /// Adds one row: `Ks·J` integer complex MACs, one phase step and one weight.
    ///
    /// # Errors
    /// As [`FixedDiagonal::push_row`](crate::FixedDiagonal::push_row).
    pub fn push_row(
        &mut self,
        scan: &FixedScan<'_>,
        row: &FixedRow<'_>,
    ) -> Result<(), ArgumentError> {
        let fc = &scan.fc;
        let j = fc.cfg.bins();
        check_len("row spectra", self.state.len(), row.hg.len())?;
        if self.rows >= fc.limits.max_rows {
            return Err(ArgumentError::Incompatible("FixedLimits::max_rows reached"));
        }
        let d_la = dist(&row.laser, &self.focus);
        let leg = scan.laser_leg(&row.laser) + f64::from(d_la);
        self.leg_range = widen(self.leg_range, leg);
        let w = fc.weight(d_la);
        let step = phase_step(f64::from(d_la), fc.two32_per_span);
        let phi0 = (fc.cfg.k_lo() as i32 as u32).wrapping_mul(step);
        // State and spectra have the same `Ks·J` layout; the phase restarts every J bins.
        let (mut phi, mut k) = (phi0, 0usize);
        for ([ur, ui], [hr, hi]) in self
            .state
            .as_chunks_mut::<2>()
            .0
            .iter_mut()
            .zip(row.hg.as_chunks::<2>().0)
        {
            let (c, s) = cis_q15(phi);
            let (hr, hi) = (i64::from(*hr), i64::from(*hi));
            let (c, s) = (i64::from(c), i64::from(s));
            *ur = ur.wrapping_add(scale(hr * c - hi * s, w, fc.ac - 15));
            *ui = ui.wrapping_add(scale(hr * s + hi * c, w, fc.ac - 15));
            phi = phi.wrapping_add(step);
            k += 1;
            if k == j {
                (phi, k) = (phi0, 0);
            }
        }
        self.rows += 1;
        Ok(())
    }

    /// Rows accumulated.
    pub const fn rows(&self) -> u32 {
        self.rows
    }

    /// The raw state `U[s][j]` as `[re, im]` pairs (LSB [`FixedConfig::column_lsb`]).
    pub fn raw(&self) -> &[i64] {
        self.state
    }

    /// Images `voxels`: `out[i] = T(x_a, voxels[i])` in counts²; returns the number of
    /// voxels whose path times left [`Config::alias_free`](crate::Config::alias_free). `Σ_j U·c` in `i128` with the NCO,
    /// then the `1/d` weight and the intensity in `f64` (once per voxel and SPAD).
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if `out.len() ≠ voxels.len()`; [`ArgumentError::NonFinite`].
    pub fn finish(
        &self,
        scan: &FixedScan<'_>,
        voxels: &[Point],
        out: &mut [f64],
    ) -> Result<usize, ArgumentError> {
        check_len("out", voxels.len(), out.len())?;
        check_points("voxels", voxels)?;
        let fc = &scan.fc;
        let cfg = &fc.cfg;
        let j = cfg.bins();
        let lsb = fc.column_lsb() / 32768.0;
        let window = alias_window(cfg);
        let mut aliased = 0;
        for (o, b) in out.iter_mut().zip(voxels) {
            let d_ab = dist(&self.focus, b);
            let (mut re, mut im) = (0.0f64, 0.0f64);
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for (si, sp) in scan.spads.iter().enumerate() {
                let Some(us) = self.state.get(2 * si * j..2 * (si + 1) * j) else {
                    break;
                };
                let d_bs = dist(b, sp);
                let tau = d_ab + d_bs;
                let t = f64::from(tau) + scan.sensor_leg(sp);
                (lo, hi) = widen((lo, hi), t);
                let step = phase_step(f64::from(tau), fc.two32_per_span);
                let mut phi = (cfg.k_lo() as i32 as u32).wrapping_mul(step);
                let (mut zr, mut zi) = (0i128, 0i128);
                for [ur, ui] in us.as_chunks::<2>().0 {
                    let (c, s) = cis_q15(phi);
                    let (ur, ui) = (i128::from(*ur), i128::from(*ui));
                    let (c, s) = (i128::from(c), i128::from(s));
                    zr += ur * c - ui * s;
                    zi += ur * s + ui * c;
                    phi = phi.wrapping_add(step);
                }
                let w = f64::from(fc.weight(d_bs)) * lsb;
                re += zr as f64 * w;
                im += zi as f64 * w;
            }
            if leaves_window(window, self.leg_range, (lo, hi)) {
                aliased += 1;
            }
            *o = re * re + im * im;
        }
        Ok(aliased)
    }
}
