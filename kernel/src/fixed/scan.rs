//! [`FixedScan`]: the Q1.15 twiddle and gate tables in caller memory.

use super::config::FixedConfig;
use super::nco::q15;
use crate::config::{Legs, Point};
use crate::error::{ArgumentError, check_len, check_points};
use crate::geometry::dist64 as dist_f64;
use ::fixed::types::I1F15;

/// Fixed-point tables in caller memory: Q1.15 twiddles `e^{−2πiq/N}` (`2N`) and gate
/// weights `ĝ_j` (`J`).
#[derive(Debug)]
pub struct FixedScan<'t> {
    pub(super) fc: FixedConfig,
    pub(super) spads: &'t [Point],
    pub(super) twiddle: &'t [I1F15],
    pub(super) gate: &'t [I1F15],
}

impl<'t> FixedScan<'t> {
    /// Length of the tables in [`I1F15`]: `2N + J`.
    pub const fn tables_len(fc: &FixedConfig) -> usize {
        2 * fc.cfg.n_fft() + fc.cfg.bins()
    }

    /// Builds the tables (`f64` `libm`, rounded to Q1.15; soft float, once).
    ///
    /// # Errors
    /// [`ArgumentError::Length`] for a wrong `tables` length or more SPADs than
    /// [`FixedLimits::max_spads`](crate::FixedLimits::max_spads); [`ArgumentError::NonFinite`] for a non-finite SPAD.
    pub fn new(
        fc: &FixedConfig,
        spads: &'t [Point],
        tables: &'t mut [I1F15],
    ) -> Result<Self, ArgumentError> {
        check_len("tables", Self::tables_len(fc), tables.len())?;
        check_points("spads", spads)?;
        if spads.len() > fc.limits.max_spads as usize {
            return Err(ArgumentError::Length {
                what: "spads (over FixedLimits::max_spads)",
                expected: fc.limits.max_spads as usize,
                found: spads.len(),
            });
        }
        let n = fc.cfg.n_fft();
        let too_short = ArgumentError::Length {
            what: "tables",
            expected: Self::tables_len(fc),
            found: 0,
        };
        let (tw, gate) = tables.split_at_mut_checked(2 * n).ok_or(too_short)?;
        for (q, [c, s]) in tw.as_chunks_mut::<2>().0.iter_mut().enumerate() {
            let a = -core::f64::consts::TAU * q as f64 / n as f64;
            *c = q15(libm::cos(a));
            *s = q15(libm::sin(a));
        }
        for (j, g) in gate.iter_mut().enumerate() {
            *g = q15(fc.cfg.gate_weight(j) / fc.g_max);
        }
        Ok(Self {
            fc: *fc,
            spads,
            twiddle: tw,
            gate,
        })
    }

    /// The fixed-point configuration.
    pub const fn config(&self) -> &FixedConfig {
        &self.fc
    }

    /// SPAD positions.
    pub const fn spads(&self) -> &'t [Point] {
        self.spads
    }

    pub(super) fn laser_leg(&self, laser: &Point) -> f64 {
        match self.fc.cfg.legs() {
            Legs::WallToWall => 0.0,
            Legs::FirstAndLast { laser_origin, .. } => dist_f64(laser, &laser_origin),
        }
    }

    pub(super) fn sensor_leg(&self, spad: &Point) -> f64 {
        match self.fc.cfg.legs() {
            Legs::WallToWall => 0.0,
            Legs::FirstAndLast { sensor_origin, .. } => dist_f64(spad, &sensor_origin),
        }
    }
}
