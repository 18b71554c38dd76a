//! [`FixedLimits`] (what must fit) and [`FixedConfig`] (the shifts derived from them, and the
//! headroom budget checked once).

use super::nco::q15;
use crate::config::{Config, Weights};
use crate::error::ConfigError;

/// What the fixed-point path must hold without overflow (the headroom budget's inputs).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedLimits {
    /// Largest number of laser rows a probe accumulates (≥ 1).
    pub max_rows: u32,
    /// Largest number of SPADs of a scan (≥ 1).
    pub max_spads: u32,
    /// Smallest leg distance `|x_l − x_a|`, `|x_b − x_s|` the weights must represent (m);
    /// shorter legs are clamped (`w = 1/max(d, max(d_min, min_distance))`). Ignored for
    /// [`Weights::One`].
    pub min_distance: f64,
}

impl FixedLimits {
    /// Limits for `max_rows` rows, `max_spads` SPADs and legs of at least `min_distance` m.
    pub const fn new(max_rows: u32, max_spads: u32, min_distance: f64) -> Self {
        Self {
            max_rows,
            max_spads,
            min_distance,
        }
    }
}

/// A [`Config`] with the fixed-point scales derived from [`FixedLimits`] (see the module
/// docs' headroom budget).
///
/// ```
/// use vltm_kernel::{Config, FixedConfig, FixedLimits, Params};
/// let cfg = Config::try_new(&Params::new(0.2, 500, 0.01)).unwrap();
/// let fc = FixedConfig::try_new(&cfg, &FixedLimits::new(4096, 32, 0.25)).unwrap();
/// assert_eq!((fc.hg_shift(), fc.diag_shift(), fc.column_shift()), (11, 5, 16));
/// assert!((fc.gate_sum() - 18.98).abs() < 0.01);
/// // Legs down to d_min = 1 mm cost 2¹⁶ of diagonal resolution; 2³² rows do not fit at all:
/// let mm = FixedConfig::try_new(&cfg, &FixedLimits::new(4096, 32, 1e-3)).unwrap();
/// assert_eq!(mm.diag_shift(), -11);
/// assert!(FixedConfig::try_new(&cfg, &FixedLimits::new(u32::MAX, 4096, 1e-3)).is_err());
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedConfig {
    pub(super) cfg: Config,
    pub(super) limits: FixedLimits,
    pub(super) d_w: f32,
    pub(super) sh: u32,
    pub(super) ad: i32,
    pub(super) ac: i32,
    pub(super) g_max: f64,
    pub(super) g1: f64,
    pub(super) two32_per_span: f64,
}

impl FixedConfig {
    /// Derives the shifts and checks the headroom budget.
    ///
    /// # Errors
    /// [`ConfigError::NotPositive`] for zero limits or a non-positive `min_distance`;
    /// [`ConfigError::SizeOverflow`] naming the budget line that would overflow.
    pub fn try_new(cfg: &Config, limits: &FixedLimits) -> Result<Self, ConfigError> {
        if limits.max_rows == 0 {
            return Err(ConfigError::NotPositive("max_rows"));
        }
        if limits.max_spads == 0 {
            return Err(ConfigError::NotPositive("max_spads"));
        }
        if !limits.min_distance.is_finite() {
            return Err(ConfigError::NotFinite("min_distance"));
        }
        if limits.min_distance <= 0.0 {
            return Err(ConfigError::NotPositive("min_distance"));
        }
        let nt = cfg.nt() as f64;
        if nt > (1u64 << 31) as f64 || cfg.bins() > 1 << 30 {
            return Err(ConfigError::SizeOverflow("fixed: nt or bins"));
        }
        let hmax = 65535.0 * nt;
        let b = libm::ceil(libm::log2(hmax + 1.0)) as i32;
        let sh = (b - 14).max(0) as u32;
        let g_max = (0..cfg.bins())
            .map(|j| cfg.gate_weight(j))
            .fold(0.0f64, f64::max);
        if g_max.is_nan() || g_max <= 0.0 {
            return Err(ConfigError::SizeOverflow("fixed: gate weights"));
        }
        let g1: f64 = (0..cfg.bins())
            .map(|j| f64::from(q15(cfg.gate_weight(j) / g_max).to_bits()) / 32768.0)
            .sum();
        if g1 > 65536.0 {
            return Err(ConfigError::SizeOverflow("fixed: band sum"));
        }
        let d_w = limits.min_distance.max(cfg.params().d_min);
        let wl = match cfg.weights() {
            Weights::Inv => 1.0 / d_w,
            Weights::One => 1.0,
        };
        let (r, ks) = (f64::from(limits.max_rows), f64::from(limits.max_spads));
        let ad = libm::floor(31.0 - libm::log2(r * ks * g1.max(1.0) * wl * wl));
        let ac = libm::floor(30.5 - libm::log2(r * wl));
        if ad < -32.0 {
            return Err(ConfigError::SizeOverflow("fixed: diagonal accumulator"));
        }
        if ac < -32.0 {
            return Err(ConfigError::SizeOverflow("fixed: column accumulator"));
        }
        Ok(Self {
            cfg: *cfg,
            limits: *limits,
            d_w: d_w as f32,
            sh,
            ad: (ad as i32).min(40),
            ac: (ac as i32).min(40),
            g_max,
            g1,
            two32_per_span: 4_294_967_296.0 / cfg.span(),
        })
    }
    /// The float configuration.
    pub const fn config(&self) -> &Config {
        &self.cfg
    }
    /// The limits.
    pub const fn limits(&self) -> &FixedLimits {
        &self.limits
    }
    /// `sh`: `HG` is stored `>> (30 + sh)`.
    pub const fn hg_shift(&self) -> u32 {
        self.sh
    }
    /// `ad`: diagonal accumulator LSB = `2^−ad` `HG` LSB (may be negative).
    pub const fn diag_shift(&self) -> i32 {
        self.ad
    }
    /// `ac`: column state LSB = `2^−ac` `HG` LSB (may be negative).
    pub const fn column_shift(&self) -> i32 {
        self.ac
    }
    /// `Ĝ_max`, the gate weight that Q1.15 `ĝ_j` are relative to.
    pub const fn gate_max(&self) -> f64 {
        self.g_max
    }
    /// `G1 = Σ_j ĝ_j / 2¹⁵`.
    pub const fn gate_sum(&self) -> f64 {
        self.g1
    }
    /// One `HG` LSB in counts: `Ĝ_max·2^(sh−15)`.
    pub fn hg_lsb(&self) -> f64 {
        self.g_max * libm::exp2(f64::from(self.sh as i32 - 15))
    }
    /// One diagonal accumulator LSB in counts (weights included).
    pub fn diag_lsb(&self) -> f64 {
        self.hg_lsb() * libm::exp2(f64::from(-self.ad))
    }
    /// One column state LSB in counts (weights included).
    pub fn column_lsb(&self) -> f64 {
        self.hg_lsb() * libm::exp2(f64::from(-self.ac))
    }
    /// Weight `1/max(d, d_w)` (or 1) in `f32`.
    #[inline]
    pub(super) fn weight(&self, d: f32) -> f32 {
        match self.cfg.weights() {
            Weights::Inv => 1.0 / d.max(self.d_w),
            Weights::One => 1.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn budget_rejects_overflow() {
        let cfg = Config::try_new(&crate::Params::new(0.2, 500, 0.01)).unwrap();
        assert!(FixedConfig::try_new(&cfg, &FixedLimits::new(0, 1, 0.1)).is_err());
        assert!(FixedConfig::try_new(&cfg, &FixedLimits::new(1, 1, 0.0)).is_err());
        assert!(FixedConfig::try_new(&cfg, &FixedLimits::new(u32::MAX, u32::MAX, 1e-3)).is_err());
        let fc = FixedConfig::try_new(&cfg, &FixedLimits::new(4096, 32, 0.25)).unwrap();
        assert_eq!(fc.hg_shift(), 11);
    }
}
