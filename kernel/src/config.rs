//! The validated, immutable configuration: virtual wave, gate, time axis, legs and weights,
//! and the frequency band derived from them.
//!
//! All lengths and times are **metres of optical path** (c ≡ 1). The relay wall is the
//! plane z = 0 with the hidden scene at z > 0.
//!
//! | symbol | field | meaning |
//! |---|---|---|
//! | λ | [`Params::wavelength`] | virtual wavelength; Ω = 2π/λ rad/m |
//! | σ | [`Params::sigma`] | time-domain std of the Gaussian gate `g(u) = exp(−u²/2σ²)`; default 2λ/3 |
//! | m | [`Params::band_half_width`] | band half-width in units of σ_ν = 1/σ (default 5: error ≈ erfc(5/√2) = 5.7e-7) |
//! | c_g | [`Params::gate_support`] | gate support in σ for padding and the guard (default 5) |
//! | Nt, Δt, t0 | `nt`, `dt`, `t0` | bin n is the point sample at `t_n = t0 + n·Δt` |
//!
//! Derived: the virtual DFT length `N = Nt + ⌈2·c_g·σ/Δt⌉ + ⌈2·margin/Δt⌉` (a negative
//! margin, down to `−c_g·σ`, shrinks it and [`Config::guard`] with it), the band bins
//! `k_lo..=k_hi` around `k_c = NΔt/λ` with half-width `h = m·NΔt/(2πσ)` (DC and negative
//! bins kept when the band reaches them), `ν_k = 2πk/(NΔt)` and the gate weights
//! `Ĝ_k = σ√(2π)·exp(−σ²(ν_k − Ω)²/2)/(NΔt)`. Cost of validation: O(1); no memory.

use crate::error::ConfigError;
use core::f64::consts::PI;

/// A point in metres, `[x, y, z]`, wall at z = 0.
pub type Point = [f32; 3];

/// Whether the histograms' time axis includes the legs from the laser device to the laser
/// spot and from the SPAD spot to the sensor device (y-tal's
/// `t_accounts_first_and_last_bounces`).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Legs {
    /// Wall-to-wall times (the paper's H): `d1 = d4 = 0`.
    WallToWall,
    /// The time axis includes `d1 = |x_l − laser_origin|` and `d4 = |x_s − sensor_origin|`.
    FirstAndLast {
        /// Position of the laser device (y-tal `laser_xyz`).
        laser_origin: [f64; 3],
        /// Position of the sensor device (y-tal `sensor_xyz`).
        sensor_origin: [f64; 3],
    },
}

/// Per-leg aperture weight of the virtual lenses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Weights {
    /// The paper's `1/max(d, d_min)` per leg (Eqs. 5, 11–14). Default.
    Inv,
    /// No weights (y-tal's default).
    One,
}

/// User-facing parameters, validated by [`Config::try_new`]. Construct with
/// [`Params::new`] and adjust fields; every field has a documented default.
///
/// ```
/// use vltm_kernel::{Params, Weights};
/// let p = Params { weights: Weights::One, ..Params::new(0.2, 500, 0.01) };
/// assert_eq!(p.band_half_width, 5.0);
/// assert!((p.sigma_or_default() - 0.2 * 2.0 / 3.0).abs() < 1e-15);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Params {
    /// Virtual wavelength λ in metres (> 0).
    pub wavelength: f64,
    /// Gate std σ in metres; `None` = 2λ/3 (±3σ spans 4λ).
    pub sigma: Option<f64>,
    /// Band half-width m in units of σ_ν = 1/σ (> 0, default 5).
    pub band_half_width: f64,
    /// Gate support c_g in units of σ (> 0, default 5): padding of the DFT and the guard.
    pub gate_support: f64,
    /// Alias-free range in metres added on both sides of the guard interval (≥ `−c_g·σ`,
    /// default 0; the DFT period grows by `2·margin`, and `J` ∝ `N` with it).
    ///
    /// * **Positive:** path times within `margin` of the guarded window are still evaluated
    ///   without wrap-around by the factorised column (see [`Probe`](crate::Probe)).
    /// * **Negative:** the period shrinks and the guard with it, by `2·|margin|` on each side
    ///   ([`Config::guard`]); every probe zeroes the paths outside it, as it does at the
    ///   default guard. For a caller that knows the span of path times it probes (a host
    ///   that crops the time axis to its voxels' reach): a guard no wider than that span
    ///   gives the same sums with a band up to `2·c_g·σ/(NΔt)` smaller.
    pub margin: f64,
    /// Number of bins per histogram (> 0).
    pub nt: usize,
    /// Bin width Δt in metres of path (> 0).
    pub dt: f64,
    /// Path time of bin 0 in metres (y-tal `t_start`; default 0).
    pub t0: f64,
    /// Leg handling (default [`Legs::WallToWall`]).
    pub legs: Legs,
    /// Leg weights (default [`Weights::Inv`]).
    pub weights: Weights,
    /// Minimum distance for the `1/d` weights in metres (> 0, default 1e-3).
    pub d_min: f64,
}

impl Params {
    /// Parameters with the defaults: σ = 2λ/3, m = 5, c_g = 5, t0 = 0,
    /// wall-to-wall legs, `1/d` weights, d_min = 1 mm.
    pub const fn new(wavelength: f64, nt: usize, dt: f64) -> Self {
        Self {
            wavelength,
            sigma: None,
            band_half_width: 5.0,
            gate_support: 5.0,
            margin: 0.0,
            nt,
            dt,
            t0: 0.0,
            legs: Legs::WallToWall,
            weights: Weights::Inv,
            d_min: 1e-3,
        }
    }

    /// σ, with the default 2λ/3 applied.
    pub fn sigma_or_default(&self) -> f64 {
        self.sigma.unwrap_or(self.wavelength * 2.0 / 3.0)
    }
}

/// Validated configuration with the derived band. `Copy`, 200-odd bytes, no tables: the
/// tables live in caller memory (see [`Scan`](crate::Scan)).
///
/// ```
/// use vltm_kernel::{Config, Params};
/// // A test bench: Nt = 500, Δt = 1 cm, λ = 0.2 m, m = 5, c_g = 5.
/// let c = Config::try_new(&Params::new(0.2, 500, 0.01)).unwrap();
/// assert_eq!(c.n_fft(), 634);
/// assert_eq!(c.bins(), 78);
/// assert!(c.k_lo() <= 0); // the band reaches DC for m > σΩ = 4.19
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    params: Params,
    sigma: f64,
    n_fft: usize,
    k_lo: i64,
    bins: usize,
}

fn finite(name: &'static str, x: f64) -> Result<f64, ConfigError> {
    if x.is_finite() {
        Ok(x)
    } else {
        Err(ConfigError::NotFinite(name))
    }
}

fn positive(name: &'static str, x: f64) -> Result<f64, ConfigError> {
    if finite(name, x)? > 0.0 {
        Ok(x)
    } else {
        Err(ConfigError::NotPositive(name))
    }
}

/// Largest DFT length accepted: keeps `k·n mod N` products in `u64` and tables addressable.
const MAX_N: f64 = (1u64 << 30) as f64;

/// `f64` equality by bits (NaN never occurs in a validated configuration, and `+0.0` /
/// `−0.0` are told apart, which only makes a comparison stricter): integer compares, so no
/// soft-float routine on an FPU without double precision.
#[inline]
fn same_f64(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits()
}

fn same_point(a: &[f64; 3], b: &[f64; 3]) -> bool {
    a.iter().zip(b).all(|(x, y)| same_f64(*x, *y))
}

impl Config {
    /// `self == other` without `f64` arithmetic (bitwise on the `f64` fields): the check
    /// the per-row paths make that a scan, row or grid belongs to their configuration. Every
    /// field is destructured, so a new field cannot be forgotten here.
    pub(crate) fn same(&self, other: &Self) -> bool {
        let Self {
            params: p,
            sigma,
            n_fft,
            k_lo,
            bins,
        } = self;
        let Params {
            wavelength,
            sigma: p_sigma,
            band_half_width,
            gate_support,
            margin,
            nt,
            dt,
            t0,
            legs,
            weights,
            d_min,
        } = p;
        let q = &other.params;
        let legs_same = match (legs, &q.legs) {
            (Legs::WallToWall, Legs::WallToWall) => true,
            (
                Legs::FirstAndLast {
                    laser_origin: a,
                    sensor_origin: b,
                },
                Legs::FirstAndLast {
                    laser_origin: c,
                    sensor_origin: d,
                },
            ) => same_point(a, c) && same_point(b, d),
            _ => false,
        };
        let sigma_same = match (p_sigma, q.sigma) {
            (None, None) => true,
            (Some(a), Some(b)) => same_f64(*a, b),
            _ => false,
        };
        same_f64(*wavelength, q.wavelength)
            && sigma_same
            && same_f64(*band_half_width, q.band_half_width)
            && same_f64(*gate_support, q.gate_support)
            && same_f64(*margin, q.margin)
            && *nt == q.nt
            && same_f64(*dt, q.dt)
            && same_f64(*t0, q.t0)
            && legs_same
            && *weights == q.weights
            && same_f64(*d_min, q.d_min)
            && same_f64(*sigma, other.sigma)
            && *n_fft == other.n_fft
            && *k_lo == other.k_lo
            && *bins == other.bins
    }
}

impl Config {
    /// Validates `p` and derives the band.
    ///
    /// # Errors
    /// [`ConfigError`] naming the parameter: λ, σ, Δt, m, c_g, d_min ≤ 0 or non-finite;
    /// d_min whose f32 reciprocal overflows; t0, margin or a leg origin non-finite;
    /// margin < −c_g·σ; `nt = 0`; a band crossing the Nyquist bin; a DFT length over 2³⁰.
    pub fn try_new(p: &Params) -> Result<Self, ConfigError> {
        let lam = positive("wavelength", p.wavelength)?;
        let sigma = positive("sigma", p.sigma_or_default())?;
        let m = positive("band_half_width", p.band_half_width)?;
        let cg = positive("gate_support", p.gate_support)?;
        let dt = positive("dt", p.dt)?;
        if !(1.0 / (positive("d_min", p.d_min)? as f32)).is_finite() {
            // The weights are f32: a d_min that rounds to 0 or a subnormal would give w = ∞.
            return Err(ConfigError::OutOfRange("d_min"));
        }
        finite("t0", p.t0)?;
        if finite("margin", p.margin)? < -cg * sigma {
            return Err(ConfigError::BelowMinimum("margin"));
        }
        if let Legs::FirstAndLast {
            laser_origin,
            sensor_origin,
        } = p.legs
        {
            for c in laser_origin {
                finite("laser_origin", c)?;
            }
            for c in sensor_origin {
                finite("sensor_origin", c)?;
            }
        }
        if p.nt == 0 {
            return Err(ConfigError::EmptyTimeAxis);
        }
        let pad = libm::ceil(2.0 * cg * sigma / dt) + libm::ceil(2.0 * p.margin / dt);
        let n = p.nt as f64 + pad;
        if n >= MAX_N || n.is_nan() {
            return Err(ConfigError::SizeOverflow("n_fft"));
        }
        let n_fft = n as usize;
        let span = n * dt;
        let kc = span / lam;
        let h = m * span / (2.0 * PI * sigma);
        let lo = libm::floor(kc - h);
        let hi = libm::ceil(kc + h);
        let half = (n_fft / 2) as f64;
        if hi > half || lo < -(half - 1.0) || !lo.is_finite() || !hi.is_finite() {
            return Err(ConfigError::BandCrossesNyquist);
        }
        let k_lo = lo as i64;
        let bins = (hi - lo) as usize + 1;
        Ok(Self {
            params: *p,
            sigma,
            n_fft,
            k_lo,
            bins,
        })
    }

    /// The parameters this configuration was built from.
    pub const fn params(&self) -> &Params {
        &self.params
    }
    /// Virtual wavelength λ (m).
    pub const fn wavelength(&self) -> f64 {
        self.params.wavelength
    }
    /// Gate std σ (m) (default applied).
    pub const fn sigma(&self) -> f64 {
        self.sigma
    }
    /// Angular wavenumber Ω = 2π/λ (rad/m).
    pub fn omega(&self) -> f64 {
        2.0 * PI / self.params.wavelength
    }
    /// Histogram length Nt.
    pub const fn nt(&self) -> usize {
        self.params.nt
    }
    /// Bin width Δt (m).
    pub const fn dt(&self) -> f64 {
        self.params.dt
    }
    /// Time of bin 0 (m).
    pub const fn t0(&self) -> f64 {
        self.params.t0
    }
    /// Virtual DFT length N (only the Nt samples are summed; the rest is implicit zeros).
    pub const fn n_fft(&self) -> usize {
        self.n_fft
    }
    /// First band bin `k_lo` (may be ≤ 0).
    pub const fn k_lo(&self) -> i64 {
        self.k_lo
    }
    /// Last band bin `k_hi`.
    pub const fn k_hi(&self) -> i64 {
        self.k_lo + self.bins as i64 - 1
    }
    /// Number of band bins J.
    pub const fn bins(&self) -> usize {
        self.bins
    }
    /// Frequency ν_j = 2π(k_lo + j)/(NΔt) of band bin j (rad/m).
    pub fn nu(&self, j: usize) -> f64 {
        2.0 * PI * (self.k_lo + j as i64) as f64 / self.span()
    }
    /// Bin spacing Δν = 2π/(NΔt) (rad/m).
    pub fn dnu(&self) -> f64 {
        2.0 * PI / self.span()
    }
    /// Gate weight Ĝ_j = σ√(2π)·exp(−σ²(ν_j − Ω)²/2)/(NΔt) of band bin j.
    pub fn gate_weight(&self, j: usize) -> f64 {
        let s = self.sigma;
        let d = self.nu(j) - self.omega();
        s * libm::sqrt(2.0 * PI) * libm::exp(-0.5 * s * s * d * d) / self.span()
    }
    /// Leg handling.
    pub const fn legs(&self) -> Legs {
        self.params.legs
    }
    /// Leg weights.
    pub const fn weights(&self) -> Weights {
        self.params.weights
    }
    /// Length of the virtual DFT period N·Δt (m).
    pub fn span(&self) -> f64 {
        self.n_fft as f64 * self.params.dt
    }
    /// Last sample time relative to t0, `(Nt − 1)·Δt` (m).
    pub fn window(&self) -> f64 {
        (self.params.nt - 1) as f64 * self.params.dt
    }
    /// Guard interval of `τ − t0` (m): the Gaussian gate contributes nothing outside
    /// `[−c_g·σ, (Nt−1)Δt + c_g·σ]`, and every probe zeroes the paths outside it. A negative
    /// [`Params::margin`] shrinks it on both sides by the period's shortfall
    /// `s = (Nt−1)Δt + 2c_gσ − NΔt` (≈ `2·|margin|`), so that it never exceeds
    /// [`Config::alias_free`].
    pub fn guard(&self) -> (f64, f64) {
        let a = self.params.gate_support * self.sigma;
        if self.span() < self.window() + 2.0 * a {
            self.alias_free()
        } else {
            (-a, self.window() + a)
        }
    }
    /// Interval of `τ − t0` (m) on which the band sum has no wrap-around:
    /// `[(Nt−1)Δt + c_gσ − NΔt, NΔt − c_gσ]`, i.e. the guard interval at margin 0 widened by
    /// the DFT's slack `NΔt − (Nt−1)Δt − 2c_gσ` (≥ `2·margin`), and the guard itself when the
    /// margin is negative. (A gate centred at `τ` reaches the samples' copies one period away
    /// only beyond these bounds.)
    pub fn alias_free(&self) -> (f64, f64) {
        let a = self.params.gate_support * self.sigma;
        (self.window() + a - self.span(), self.span() - a)
    }
    /// Samples of the higher-order gate's correction, `⌈c_g·σ/Δt⌉ + 1`.
    pub fn ho_support(&self) -> usize {
        libm::ceil(self.params.gate_support * self.sigma / self.params.dt) as usize + 1
    }
    /// The leg weight `w(d)`: `1/max(d, d_min)` or 1.
    #[inline]
    pub fn weight(&self, d: f32) -> f32 {
        match self.params.weights {
            Weights::Inv => 1.0 / d.max(self.params.d_min as f32),
            Weights::One => 1.0,
        }
    }
}

#[cfg(test)]
mod same_tests {
    use super::*;

    /// `Config::same` agrees with `==` (the derived `f64` comparison) on equal configurations
    /// and on each single-field change.
    #[test]
    fn same_is_equality() {
        let base = Params {
            t0: 0.3,
            legs: Legs::FirstAndLast {
                laser_origin: [0.1, 0.2, -1.0],
                sensor_origin: [0.0, 0.0, -1.0],
            },
            ..Params::new(0.1, 128, 0.01)
        };
        let a = Config::try_new(&base).unwrap();
        assert!(a.same(&a) && a.same(&Config::try_new(&base).unwrap()));
        let variants = [
            Params {
                wavelength: 0.11,
                ..base
            },
            Params {
                sigma: Some(0.07),
                ..base
            },
            Params {
                band_half_width: 4.0,
                ..base
            },
            Params {
                gate_support: 4.5,
                ..base
            },
            Params {
                margin: 0.1,
                ..base
            },
            Params { nt: 129, ..base },
            Params { dt: 0.011, ..base },
            Params { t0: 0.31, ..base },
            Params {
                legs: Legs::WallToWall,
                ..base
            },
            Params {
                legs: Legs::FirstAndLast {
                    laser_origin: [0.1, 0.2, -1.0],
                    sensor_origin: [0.0, 1e-9, -1.0],
                },
                ..base
            },
            Params {
                weights: Weights::One,
                ..base
            },
            Params {
                d_min: 0.002,
                ..base
            },
        ];
        for p in variants {
            let b = Config::try_new(&p).unwrap();
            assert_eq!(a.same(&b), a == b, "{p:?}");
            assert!(!a.same(&b), "{p:?}");
        }
    }
}

#[cfg(test)]
mod margin_tests {
    use super::*;

    /// A negative margin shrinks the period, the band and the guard together: the guard never
    /// leaves the alias-free interval, equals it below margin 0, and is unchanged at margin 0;
    /// below `−c_g·σ` the margin is refused by name.
    #[test]
    fn a_negative_margin_shrinks_the_period_and_the_guard() {
        let base = Params::new(0.2, 500, 0.01);
        let c0 = Config::try_new(&base).unwrap();
        let a = base.gate_support * c0.sigma();
        assert_eq!(c0.guard(), (-a, c0.window() + a));
        let (af0, af1) = c0.alias_free();
        assert!(af0 <= -a && af1 >= c0.window() + a);
        let mut last = c0;
        for m in [-0.1, -0.3, -0.5, -a] {
            let c = Config::try_new(&Params { margin: m, ..base }).unwrap();
            assert!(c.n_fft() < last.n_fft() && c.bins() <= last.bins(), "{m}");
            assert!(c.n_fft() >= base.nt, "{m}");
            let (g0, g1) = c.guard();
            assert_eq!(c.alias_free(), (g0, g1), "{m}");
            // Shrunk by 2·|margin| on each side, less N's slack at margin 0 (under 2 bins).
            assert!((g0 - (-a - 2.0 * m)).abs() <= 2.0 * base.dt, "{m}: {g0}");
            assert!(
                (g1 - (c.window() + a + 2.0 * m)).abs() <= 2.0 * base.dt,
                "{m}: {g1}"
            );
            last = c;
        }
        assert_eq!(
            Config::try_new(&Params {
                margin: -a - 1e-9,
                ..base
            }),
            Err(ConfigError::BelowMinimum("margin"))
        );
    }
}
