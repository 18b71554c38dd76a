//! The validated grid of the lookup path ([`LookupGrid`]): its length `L` (a power of two)
//! chosen from, or checked against, the interpolation error bound `η` of the
//! [`Interpolant`] (the derivation is in the module docs of `lookup/mod.rs`, "Error bound").
//! Cost: `O(J)` per candidate length, once; no tables, no memory.

use crate::config::Config;
use crate::error::ConfigError;

/// Largest grid accepted (`2²⁴` points: tables and `f32` grid positions stay exact).
const MAX_LEN: usize = 1 << 24;

/// How a grid cell is interpolated between its nodes `n` and `n + 1` (module docs, "Error
/// bound"). Both are cubics in the cell's fraction `t`, so a precomputed cell costs the same
/// per read (four complex coefficients, a Horner step).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Interpolant {
    /// The 4-point cubic Lagrange interpolant on the nodes `n − 1 … n + 2`
    /// ([`lagrange4`](crate::lagrange4)): `η = (3/128)·Σ_j Ĝ_j ω_j⁴`. Read by every lookup
    /// path.
    #[default]
    Lagrange,
    /// The cubic Hermite interpolant on the nodes `n`, `n + 1` with slopes from the
    /// sixth-order central difference of the nodes `n − 3 … n + 4`:
    /// `η = Σ_j Ĝ_j·(ω_j⁴/384 + ε(ω_j)/4)`, about 9× below [`Interpolant::Lagrange`] on the
    /// same grid, so a grid half as long meets the same tolerance whenever
    /// `ε` is small (the band well inside the grid's Nyquist range). Read only by the
    /// structured slice ([`LookupSlice`](crate::LookupSlice)), which converts each grid cell
    /// to a cubic once per row; [`LookupProbe`](crate::LookupProbe),
    /// [`Lookup::baseband`](crate::Lookup::baseband) and
    /// [`ColumnF32::finish_lookup`](crate::ColumnF32::finish_lookup) refuse it.
    Hermite,
}

/// What the lookup path must achieve, validated by [`LookupGrid::try_new`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LookupParams {
    /// Largest interpolation error `η` per count of `‖h_s‖₁` (module docs; > 0, default 1e-5).
    pub tolerance: f64,
    /// Grid length `L` (a power of two); `None` = the smallest that meets `tolerance`.
    pub grid_len: Option<usize>,
    /// The interpolant whose bound picks (or checks) `L` (default [`Interpolant::Lagrange`]).
    pub interpolant: Interpolant,
}

impl LookupParams {
    /// Tolerance 1e-5, grid chosen from it, [`Interpolant::Lagrange`].
    pub const fn new() -> Self {
        Self {
            tolerance: 1e-5,
            grid_len: None,
            interpolant: Interpolant::Lagrange,
        }
    }

    /// Tolerance 1e-5, grid chosen from it, [`Interpolant::Hermite`]: the structured slice's
    /// choice (for the paper's setup `L` = 512 instead of 1024 at the same tolerance).
    pub const fn hermite() -> Self {
        Self {
            tolerance: 1e-5,
            grid_len: None,
            interpolant: Interpolant::Hermite,
        }
    }
}

impl Default for LookupParams {
    fn default() -> Self {
        Self::new()
    }
}

/// The validated grid of the lookup path for one [`Config`]: `Copy`, no tables.
///
/// ```
/// use vltm_kernel::{Config, LookupGrid, LookupParams, Params};
/// let cfg = Config::try_new(&Params::new(0.13, 255, 0.0255)).unwrap();
/// let g = LookupGrid::try_new(&cfg, &LookupParams::new()).unwrap();
/// assert_eq!(g.len(), 1024);
/// assert!(g.bound() < 1e-5);
/// let coarse = LookupParams { grid_len: Some(512), ..LookupParams::new() };
/// assert!(LookupGrid::try_new(&cfg, &coarse).is_err()); // η = 5.5e-5 > 1e-5
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LookupGrid {
    pub(super) cfg: Config,
    pub(super) len: usize,
    /// log₂ L.
    pub(super) bits: u32,
    /// Carrier bin k_d.
    pub(super) k_d: i64,
    /// `(k_lo − k_d) mod L`: grid bin of band bin 0.
    pub(super) first: usize,
    /// η.
    pub(super) bound: f64,
    /// The interpolant `bound` is for.
    pub(super) interp: Interpolant,
}

/// `η(L)` of the interpolant: with `ω_j = 2π(k_lo + j − k_d)/L` (radians per grid step),
/// Lagrange `(3/128)·Σ_j Ĝ_j ω_j⁴`, Hermite `Σ_j Ĝ_j·(ω_j⁴/384 + ε(ω_j)/4)` with the
/// central difference's slope error `ε(ω) = |ω − (3/2 sin ω − 3/10 sin 2ω + 1/30 sin 3ω)|`.
fn eta(cfg: &Config, len: usize, k_d: i64, interp: Interpolant) -> f64 {
    let span = cfg.span();
    let dnu = cfg.dnu();
    let delta = span / len as f64;
    let mut sum = 0.0;
    for j in 0..cfg.bins() {
        let d = (cfg.k_lo() + j as i64 - k_d) as f64 * dnu;
        sum += cfg.gate_weight(j)
            * match interp {
                // (ν_j − Ω_d)⁴, times δ⁴ below: `(3/128)·δ⁴·M₄` as the module docs write it.
                Interpolant::Lagrange => d * d * d * d,
                Interpolant::Hermite => {
                    let w = d * delta;
                    w * w * w * w / 384.0 + slope_error(w) / 4.0
                }
            };
    }
    match interp {
        Interpolant::Lagrange => 3.0 / 128.0 * delta * delta * delta * delta * sum,
        Interpolant::Hermite => sum,
    }
}

/// `ε(ω)`: the error of the sixth-order central difference
/// `D y(0) = (45(y₁ − y₋₁) − 9(y₂ − y₋₂) + (y₃ − y₋₃))/60` on `e^{iωx}`, relative to the
/// exact slope `iω` (≈ `ω⁷/140` for small `ω`).
fn slope_error(w: f64) -> f64 {
    let d = 1.5 * libm::sin(w) - 0.3 * libm::sin(2.0 * w) + libm::sin(3.0 * w) / 30.0;
    libm::fabs(w - d)
}

impl LookupGrid {
    /// `self == other` without `f64` arithmetic (bitwise on the `f64` fields, through
    /// [`Config::same`]): the check the per-row paths make that a grid belongs to their probe,
    /// with no soft-double compare on a Cortex-M4F. Every field is destructured, so a new
    /// field cannot be forgotten here.
    pub(crate) fn same(&self, other: &Self) -> bool {
        let Self {
            cfg,
            len,
            bits,
            k_d,
            first,
            bound,
            interp,
        } = self;
        cfg.same(&other.cfg)
            && *len == other.len
            && *bits == other.bits
            && *k_d == other.k_d
            && *first == other.first
            && bound.to_bits() == other.bound.to_bits()
            && *interp == other.interp
    }

    /// Validates `p` for `cfg` and derives the grid.
    ///
    /// # Errors
    /// [`ConfigError`] naming the parameter: `tolerance` not finite or ≤ 0;
    /// `grid_len` not a power of two ([`ConfigError::NotPowerOfTwo`]), or too coarse
    /// ([`ConfigError::TooCoarse`]: fewer points than band bins `J`, fewer than 8 per carrier
    /// wavelength, or an error bound `η` above `tolerance`); a grid over 2²⁴ points
    /// ([`ConfigError::SizeOverflow`]).
    pub fn try_new(cfg: &Config, p: &LookupParams) -> Result<Self, ConfigError> {
        let tol = p.tolerance;
        if !tol.is_finite() {
            return Err(ConfigError::NotFinite("tolerance"));
        }
        if tol <= 0.0 {
            return Err(ConfigError::NotPositive("tolerance"));
        }
        let k_d = libm::round(cfg.span() / cfg.wavelength()) as i64;
        // At least J points (distinct bins), 8 per carrier turn (θ ≤ 1/8), and 4 (the first
        // FFT pass is radix 4).
        let floor = cfg.bins().max(8 * k_d.unsigned_abs() as usize).max(4);
        let len = match p.grid_len {
            Some(l) => {
                if !l.is_power_of_two() {
                    return Err(ConfigError::NotPowerOfTwo("grid_len"));
                }
                if l > MAX_LEN {
                    return Err(ConfigError::SizeOverflow("grid_len"));
                }
                if l < floor || eta(cfg, l, k_d, p.interpolant) > tol {
                    return Err(ConfigError::TooCoarse("grid_len"));
                }
                l
            }
            None => {
                let mut l = floor.next_power_of_two();
                while eta(cfg, l, k_d, p.interpolant) > tol {
                    if l >= MAX_LEN {
                        return Err(ConfigError::SizeOverflow("grid_len"));
                    }
                    l *= 2;
                }
                if l > MAX_LEN {
                    return Err(ConfigError::SizeOverflow("grid_len"));
                }
                l
            }
        };
        Ok(Self {
            cfg: *cfg,
            len,
            bits: len.trailing_zeros(),
            k_d,
            first: (cfg.k_lo() - k_d).rem_euclid(len.max(1) as i64) as usize,
            bound: eta(cfg, len, k_d, p.interpolant),
            interp: p.interpolant,
        })
    }

    /// The configuration the grid was made for.
    pub const fn config(&self) -> &Config {
        &self.cfg
    }
    /// Grid length `L` (a power of two).
    #[allow(clippy::len_without_is_empty)]
    pub const fn len(&self) -> usize {
        self.len
    }
    /// Grid step `δ = NΔt/L` (m).
    pub fn step(&self) -> f64 {
        self.cfg.span() / self.len as f64
    }
    /// Carrier bin `k_d = round(NΔt/λ)` (the demodulation frequency is `2πk_d/(NΔt)`).
    pub const fn carrier_bin(&self) -> i64 {
        self.k_d
    }
    /// The interpolation error bound `η` (per count of `‖h_s‖₁`, see the module docs).
    pub const fn bound(&self) -> f64 {
        self.bound
    }
    /// The interpolant the grid is made for.
    pub const fn interpolant(&self) -> Interpolant {
        self.interp
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Params;

    use super::super::table::{EXTRA, Lookup};
    use crate::error::ArgumentError;
    use num_complex::Complex32;

    fn cfg() -> Config {
        Config::try_new(&Params::new(0.2, 64, 0.01)).unwrap()
    }

    /// `LookupGrid::same` (bitwise, what the per-row paths compare) agrees with `==`: equal
    /// grids, another length, another tolerance's grid of the same length (`bound` differs
    /// only if the configuration does), another configuration.
    #[test]
    fn grid_same_is_equality() {
        let c = cfg();
        let g = |cfg: &Config, grid_len| {
            LookupGrid::try_new(
                cfg,
                &LookupParams {
                    tolerance: 1.0,
                    grid_len,
                    ..LookupParams::new()
                },
            )
            .unwrap()
        };
        let a = g(&c, Some(256));
        assert!(a.same(&a) && a.same(&g(&c, Some(256))) && a == g(&c, Some(256)));
        let other = Config::try_new(&Params::new(0.21, 64, 0.01)).unwrap();
        for b in [g(&c, Some(512)), g(&other, Some(256))] {
            assert_eq!(a.same(&b), a == b);
            assert!(!a.same(&b), "{b:?}");
        }
    }

    #[test]
    fn grid_validation_names_the_parameter() {
        let c = cfg();
        let p = |tolerance, grid_len| LookupParams {
            tolerance,
            grid_len,
            ..LookupParams::new()
        };
        let g = LookupGrid::try_new(&c, &LookupParams::new()).unwrap();
        assert!(g.len().is_power_of_two() && g.len() >= c.bins() && g.bound() <= 1e-5);
        // The smallest grid that meets the tolerance: at the floor, or half of it does not.
        let floor = c.bins().max(8 * g.carrier_bin() as usize).max(4);
        assert!(
            g.len() == floor.next_power_of_two()
                || eta(&c, g.len() / 2, g.k_d, Interpolant::Lagrange) > 1e-5
        );
        for (params, err) in [
            (p(f64::NAN, None), ConfigError::NotFinite("tolerance")),
            (p(0.0, None), ConfigError::NotPositive("tolerance")),
            (p(-1.0, None), ConfigError::NotPositive("tolerance")),
            (p(1e-5, Some(100)), ConfigError::NotPowerOfTwo("grid_len")),
            (p(1e-5, Some(8)), ConfigError::TooCoarse("grid_len")),
            (
                p(1e-5, Some(g.len() / 2)),
                ConfigError::TooCoarse("grid_len"),
            ),
            (
                p(1e-5, Some(1 << 30)),
                ConfigError::SizeOverflow("grid_len"),
            ),
            (p(1e-300, None), ConfigError::SizeOverflow("grid_len")),
        ] {
            assert_eq!(LookupGrid::try_new(&c, &params), Err(err), "{params:?}");
        }
        assert_eq!(LookupGrid::try_new(&c, &p(1e-5, Some(g.len()))), Ok(g));
    }

    /// The Hermite interpolant's bound: about 9× below Lagrange's on one grid (its slope
    /// term small), so the paper's setup meets 1e-5 with `L` = 512 instead of 1024; the
    /// slope error `ε(ω)` is `ω⁷/140` to leading order; grids of the two interpolants differ.
    #[test]
    fn hermite_bound_halves_the_grid() {
        let c = Config::try_new(&Params::new(0.13, 255, 0.0255)).unwrap();
        let lag = LookupGrid::try_new(&c, &LookupParams::new()).unwrap();
        let her = LookupGrid::try_new(&c, &LookupParams::hermite()).unwrap();
        assert_eq!((lag.len(), her.len()), (1024, 512));
        assert!(her.bound() <= 1e-5 && her.bound() > 5e-6, "{}", her.bound());
        let lag512 = eta(&c, 512, lag.k_d, Interpolant::Lagrange);
        let ratio = lag512 / her.bound();
        assert!((8.0..9.0).contains(&ratio), "{ratio}");
        for w in [0.05f64, 0.1, 0.2] {
            let e = slope_error(w);
            let lead = w.powi(7) / 140.0;
            assert!((e - lead).abs() < 0.05 * lead, "{w}: {e} vs {lead}");
        }
        assert!(
            !lag.same(
                &LookupGrid::try_new(
                    &c,
                    &LookupParams {
                        grid_len: Some(1024),
                        ..LookupParams::hermite()
                    }
                )
                .unwrap()
            )
        );
        let mut t = [0.0f32; 4 * 512];
        let lookup = Lookup::new(&her, &mut t).unwrap();
        let hg = [Complex32::new(0.0, 0.0); 137];
        let mut y = [Complex32::new(0.0, 0.0); 512 + EXTRA];
        assert!(matches!(
            lookup.baseband(&hg[..c.bins()], &mut y),
            Err(ArgumentError::Incompatible(_))
        ));
    }
}
