//! [`FixedDiagonal`]: the Gaussian diagonal in fixed point (and its integer band sum).

use super::arith::{round_shift, scale};
use super::config::FixedConfig;
use super::nco::{cis_q15, phase_step};
use super::row::FixedRow;
use super::scan::FixedScan;
use crate::config::Point;
use crate::error::{ArgumentError, check_len, check_points};
use crate::geometry::dist;

/// `Σ_j HG_j·e^{iν_j τ}` in `HG` LSB (the `i64` sums `>> 15`, rounded): the NCO phase steps
/// by `round(2³²τ/(NΔt))` from `k_lo·step`.
#[inline]
pub(super) fn band_sum(hg: &[i32], tau: f32, fc: &FixedConfig) -> (i64, i64) {
    let step = phase_step(f64::from(tau), fc.two32_per_span);
    let mut phi = (fc.cfg.k_lo() as i32 as u32).wrapping_mul(step);
    let (mut re, mut im) = (0i64, 0i64);
    for [hr, hi] in hg.as_chunks::<2>().0 {
        let (c, s) = cis_q15(phi);
        let (hr, hi) = (i64::from(*hr), i64::from(*hi));
        let (c, s) = (i64::from(c), i64::from(s));
        re = re.wrapping_add(hr * c - hi * s);
        im = im.wrapping_add(hr * s + hi * c);
        phi = phi.wrapping_add(step);
    }
    (
        round_shift(i128::from(re), 15),
        round_shift(i128::from(im), 15),
    )
}

/// Gaussian diagonal `T(x_v, x_v)` in fixed point: `i64` complex accumulators (`2Kv`),
/// LSB [`FixedConfig::diag_lsb`]. Per row: `Kv·Ks` pairs of (two `sqrtf`, one weight, one
/// phase step in soft float) + `J` integer complex MACs.
#[derive(Debug)]
pub struct FixedDiagonal<'m> {
    pub(super) voxels: &'m [Point],
    pub(super) acc: &'m mut [i64],
    pub(super) rows: u32,
}

impl<'m> FixedDiagonal<'m> {
    /// State length in `i64`: `2Kv`.
    pub const fn state_len(n_voxels: usize) -> usize {
        2 * n_voxels
    }

    /// A diagonal probe over `voxels` with zeroed `state` (length [`Self::state_len`]).
    ///
    /// # Errors
    /// [`ArgumentError::Length`] / [`ArgumentError::NonFinite`].
    pub fn new(voxels: &'m [Point], state: &'m mut [i64]) -> Result<Self, ArgumentError> {
        check_len("state", Self::state_len(voxels.len()), state.len())?;
        check_points("voxels", voxels)?;
        state.fill(0);
        Ok(Self {
            voxels,
            acc: state,
            rows: 0,
        })
    }

    /// Adds one row (guard interval as in the float path).
    ///
    /// # Errors
    /// [`ArgumentError::Incompatible`] past [`FixedLimits::max_rows`](crate::FixedLimits::max_rows) (the budget); [`ArgumentError::Length`]
    /// for a row of another scan size. Nothing is changed then.
    pub fn push_row(
        &mut self,
        scan: &FixedScan<'_>,
        row: &FixedRow<'_>,
    ) -> Result<(), ArgumentError> {
        let fc = &scan.fc;
        let j = fc.cfg.bins();
        let ks = scan.spads.len();
        check_len("row spectra", 2 * ks * j, row.hg.len())?;
        if self.rows >= fc.limits.max_rows {
            return Err(ArgumentError::Incompatible("FixedLimits::max_rows reached"));
        }
        let (g_lo, g_hi) = fc.cfg.guard();
        let (g_lo, g_hi) = (g_lo as f32, g_hi as f32);
        let laser = row.laser;
        for ([a_re, a_im], v) in self.acc.as_chunks_mut::<2>().0.iter_mut().zip(self.voxels) {
            let d_lv = dist(&laser, v);
            let w_l = fc.weight(d_lv);
            let (mut re, mut im) = (0i64, 0i64);
            for (s, sp) in scan.spads.iter().enumerate() {
                let Some(hg) = row.hg.get(2 * s * j..2 * (s + 1) * j) else {
                    break;
                };
                let d_vs = dist(v, sp);
                let tau = d_lv + d_vs;
                let rel = tau + row.offset(s);
                if rel >= g_lo && rel <= g_hi {
                    let (zr, zi) = band_sum(hg, tau, fc);
                    let w = w_l * fc.weight(d_vs);
                    re = re.wrapping_add(scale(zr, w, fc.ad));
                    im = im.wrapping_add(scale(zi, w, fc.ad));
                }
            }
            *a_re = a_re.wrapping_add(re);
            *a_im = a_im.wrapping_add(im);
        }
        self.rows += 1;
        Ok(())
    }

    /// Rows accumulated.
    pub const fn rows(&self) -> u32 {
        self.rows
    }

    /// The raw accumulators `[re, im]` per voxel (LSB [`FixedConfig::diag_lsb`]).
    pub fn raw(&self) -> &[i64] {
        self.acc
    }

    /// Intensities `T = |A|²` in counts² (`f64`, once).
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if `out.len() ≠ Kv`.
    pub fn finish(&self, fc: &FixedConfig, out: &mut [f64]) -> Result<(), ArgumentError> {
        check_len("out", self.voxels.len(), out.len())?;
        let lsb = fc.diag_lsb();
        for (o, [re, im]) in out.iter_mut().zip(self.acc.as_chunks::<2>().0) {
            let (re, im) = (*re as f64 * lsb, *im as f64 * lsb);
            *o = re * re + im * im;
        }
        Ok(())
    }
}
