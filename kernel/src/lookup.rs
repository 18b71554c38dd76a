//! The **lookup path**: the Gaussian-gated diagonal and column with an O(1) cost per
//! (voxel, SPAD) pair instead of the band path's `J`-term sum.
//!
//! Per laser row and per SPAD, the gated, filtered signal `Z_s(τ)` is synthesised **once** on
//! a fine time grid from the row's band spectrum `HG_s[j]` ([`Row::band`], gate weights and
//! legs folded in), demodulated (baseband); each voxel then reads its value at its exact path
//! time by cubic interpolation, and the carrier is restored analytically.
//!
//! # Units and conventions
//!
//! Metres of optical path throughout (c ≡ 1); `τ` is the hidden path only (`d_lv + d_vs` on
//! the diagonal, `d_la + d_ab + d_bs` on a column), the legs `x_s = d1 + d4_s − t0` being
//! folded into `HG_s` as in the band path. Sign convention A (module docs of [`Probe`](crate::Probe)):
//! `Z_s(τ) = Σ_j HG_s[j]·e^{iν_j τ}`, `ν_j = 2π(k_lo + j)/span`, `span = NΔt`.
//!
//! # Method
//!
//! With `k_d = round(span/λ)` (the band centre), a grid of `L` points (a power of two,
//! `L ≥ J`) of step `δ = span/L` and `θ = k_d/L` (carrier turns per grid step):
//!
//! ```text
//! Y_s[n] = Σ_j HG_s[j]·e^{2πi (k_lo + j − k_d) n/L}          (one inverse FFT of length L)
//!        = e^{−2πi k_d τ_n/span}·Z_s(τ_n),   τ_n = n·δ        (exact at the nodes)
//! Z_s(τ) ≈ C[i]·e^{2πi θ t}·Σ_{q=−1..2} ℓ_q(t)·Y_s[i + q],   i + t = τ/δ, 0 ≤ t < 1
//! ```
//!
//! `ℓ_q` are the 4-point cubic Lagrange weights ([`lagrange4`]) on the nodes −1, 0, 1, 2,
//! `C[i] = e^{2πi k_d i/L}` a table made once in `f64` (exact integer phase `k_d·i mod L`), and
//! `e^{2πiθt}` (`|θt| ≤ 1/8` turn) the small-phase polynomial [`cis_small_turns`]. `Y_s` and
//! `C` are `L`-periodic (the band sum is `span`-periodic), so indices wrap with `& (L − 1)`.
//! The pair adds `w(d_vs)·Z_s(τ)` to its voxel's row sum (`Complex32`) when `τ + x_s` lies in
//! the guard interval [`Config::guard`] (the same `f32` test as the band diagonal); once per
//! row the sum times the lead weight (`w(d_lv)`, or `w(d_la)` on a column) is added to the
//! voxel's accumulator, a Kahan-compensated `f32` complex sum (error `≤ 2u·Σ_rows |row sum|`
//! plus `O(n u²)`, far below the lookup tolerance; no `f64` anywhere per row, so no soft
//! double on a Cortex-M4F: the constants are rounded to `f32` once by [`LookupProbe::new`]).
//! A column is imaged pair by pair like the diagonal (not factorised), so every path gets the
//! guard and nothing aliases.
//!
//! # Error bound
//!
//! The cubic Lagrange remainder (Hermite–Genocchi, valid for complex functions) at
//! `t ∈ [0, 1)` is `|Y(τ) − p(τ)| ≤ δ⁴·max|Y⁽⁴⁾|·|(t+1)t(t−1)(t−2)|/4! ≤ (3/128)·δ⁴·max|Y⁽⁴⁾|`
//! (`max_{[0,1]} |(t+1)t(t−1)(t−2)| = 9/16` at `t = ½`). The baseband's fourth derivative is
//! `Y⁽⁴⁾ = Σ_j (ν_j − Ω_d)⁴·HG_s[j]·e^{i(ν_j − Ω_d)τ}` with `Ω_d = 2πk_d/span`, and
//! `|HG_s[j]| ≤ Ĝ_j·‖h_s‖₁` (`‖h_s‖₁ = Σ_n |H_s[n]|`, counts), so per pair
//!
//! ```text
//! |Z_lookup(τ) − Z_band(τ)| ≤ η·‖h_s‖₁,   η = (3/128)·δ⁴·M₄,   M₄ = Σ_j Ĝ_j·(ν_j − Ω_d)⁴  (m⁻⁴)
//! ```
//!
//! [`LookupGrid::bound`] is `η` (dimensionless, per count of `‖h_s‖₁`). For the Gaussian gate
//! `M₄ ≈ 3/σ⁴·(1 + 2(εσ)² + (εσ)⁴/3)` (the gate spectrum's fourth moment, `ε = Ω − Ω_d`,
//! `|ε| ≤ π/span`), so `η ≈ (9/128)·(δ/σ)⁴`: the grid step in units of σ (itself `2λ/3` by
//! default, and the bandwidth `≈ 1/σ`) sets the error; the carrier frequency sets no error
//! term because the carrier is restored analytically, it only requires `θ ≤ 1/8` (a grid
//! of at least 8 points per carrier wavelength λ) for [`cis_small_turns`]. Summed over the
//! scan, an element's amplitude error is `≤ η·S(a, b)` with `S = Σ_l Σ_s w_l w_s ‖h_ls‖₁`,
//! the scale of the band path's tolerance (`tests/proptest_kernel.rs`): the lookup path's
//! tolerance is the band path's plus `η`, plus `f32` rounding (the FFT: `≈ u·log₂L` per
//! stage sum; the grid position `τ/δ`: a relative `u`, i.e. a carrier phase error of
//! `2π·u·k_dτ/span` rad, the same order as the band path's `f32` phase).
//!
//! Example (the paper's setup: λ = 0.13 m, σ = 8.67 cm, Δt = 2.55 cm, Nt = 255: N = 289,
//! span = 7.37 m, J = 137, k_d = 57): `L = 512` (δ = 1.44 cm = σ/6.0) gives η = 5.5e-5;
//! `L = 1024` (δ = σ/12) gives η = 3.4e-6 (the default tolerance 1e-5 picks 1024).
//!
//! **The Hermite interpolant** ([`Interpolant::Hermite`], read only by the structured slice
//! [`LookupSlice`](crate::LookupSlice), which converts every cell it reads to a cubic once per
//! row): the cubic Hermite interpolant of the cell's two nodes with sixth-order
//! central-difference slopes has the bound
//! `η = Σ_j Ĝ_j·(ω_j⁴/384 + ε(ω_j)/4)`, `ω_j = δ·(ν_j − Ω_d)` (derived in the module docs of
//! `lookup_slice.rs`), about 9× below the Lagrange bound `(3/128)·Σ_j Ĝ_j ω_j⁴` on the same
//! grid: the paper's setup meets 1e-5 with `L = 512` (η = 6.2e-6). [`LookupGrid::try_new`]
//! picks `L` with the bound of [`LookupParams::interpolant`].
//!
//! # Cost and memory
//!
//! Per row: `Ks` inverse FFTs of length `L` (`(L/2)·log₂L` butterflies each; the band is
//! placed directly in bit-reversed order, so there is no permutation pass; after a radix-4
//! pass the radix-2 stages run fused in pairs, three complex products per four
//! butterflies), then `Kv·Ks`
//! pairs of O(1) work (a distance, the guard test, four Lagrange weights, four complex
//! loads, one table carrier, one small-phase polynomial, one weight), against the band
//! path's `Kv·Ks·14J` flops. Memory, all caller-owned: shared tables `3L` `f32`
//! ([`Lookup::tables_len`]: twiddles and carrier); per probe the state `4Kv` `f32` (the
//! bytes of the band diagonal's `2Kv` `f64`) and the scratch `2(L + 3) + 3Kv` `f32` ([`LookupProbe::scratch_len`]: the
//! SPAD's grid, the voxels' row sums and lead distances). SPAD-outer: one grid in memory at a
//! time. No allocation, no panic on data; configuration checked once.

use crate::band::probe::Target;
use crate::band::row::Row;
use crate::band::scan::{Scan, as_complex};
use crate::config::{Config, Point, Weights};
use crate::error::{ConfigError, Error, check_len, check_points};
use crate::phase::cis_small_turns;
use crate::report::Report;
use crate::sample::Sample;
use num_complex::{Complex32, Complex64};

/// Largest grid accepted (`2²⁴` points: tables and `f32` grid positions stay exact).
const MAX_LEN: usize = 1 << 24;

/// Extra grid entries past `L` (the 4-point stencil reads up to 3 past its start).
pub(crate) const EXTRA: usize = 3;

/// `√x` for finite `x ≥ 0` in plain `f32` arithmetic: an integer first guess of `1/√x`, two
/// Newton steps for `1/√x` and one for `√x`. Within 1 ulp of the correctly rounded square
/// root (relative error ≤ 8.9e-8, measured over 2·10⁷ values in [1e-6, 1e4]), exactly 0 at 0,
/// and the same bits on every target. Why not `libm::sqrtf`: it is a bit-by-bit software
/// routine on a Cortex-M (≈ 100 instructions; `f32::sqrt` and the FPU's `vsqrt` are not
/// reachable from stable `no_std` Rust without `unsafe`): this is ≈ 14.
#[inline(always)]
pub(crate) fn sqrt_nr(x: f32) -> f32 {
    let mut y = f32::from_bits(0x5f37_59df_u32.wrapping_sub(x.to_bits() >> 1));
    let h = 0.5 * x;
    y = y * (1.5 - h * y * y);
    y = y * (1.5 - h * y * y);
    let r = x * y;
    r + 0.5 * y * (x - r * r)
}

/// Euclidean distance with [`sqrt_nr`] (within 1 ulp of the correctly rounded `f32` one).
#[inline(always)]
pub(crate) fn dist_nr(a: &Point, b: &Point) -> f32 {
    let (x, y, z) = (a[0] - b[0], a[1] - b[1], a[2] - b[2]);
    sqrt_nr(x * x + y * y + z * z)
}

/// The 4-point cubic Lagrange weights at `t ∈ [0, 1)` for the nodes −1, 0, 1, 2:
/// `p(t) = Σ_q w[q]·y[q − 1]`. Exact for cubics; `Σ_q w[q] = 1`.
///
/// ```
/// let w = vltm_kernel::lagrange4(0.5);
/// assert_eq!(w, [-0.0625, 0.5625, 0.5625, -0.0625]);
/// ```
#[inline(always)]
pub fn lagrange4(t: f32) -> [f32; 4] {
    let (tp, tm, t2) = (t + 1.0, t - 1.0, t - 2.0);
    let a = t * tm;
    let b = tp * t2;
    [
        a * t2 * (-1.0 / 6.0),
        b * tm * 0.5,
        b * t * -0.5,
        a * tp * (1.0 / 6.0),
    ]
}

/// How a grid cell is interpolated between its nodes `n` and `n + 1` (module docs, "Error
/// bound"). Both are cubics in the cell's fraction `t`, so a precomputed cell costs the same
/// per read (four complex coefficients, a Horner step).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Interpolant {
    /// The 4-point cubic Lagrange interpolant on the nodes `n − 1 … n + 2` ([`lagrange4`]):
    /// `η = (3/128)·Σ_j Ĝ_j ω_j⁴`. Read by every lookup path.
    #[default]
    Lagrange,
    /// The cubic Hermite interpolant on the nodes `n`, `n + 1` with slopes from the
    /// sixth-order central difference of the nodes `n − 3 … n + 4`:
    /// `η = Σ_j Ĝ_j·(ω_j⁴/384 + ε(ω_j)/4)`, about 9× below [`Interpolant::Lagrange`] on the
    /// same grid, so a grid half as long meets the same tolerance whenever
    /// `ε` is small (the band well inside the grid's Nyquist range). Read only by the
    /// structured slice ([`LookupSlice`](crate::LookupSlice)), which converts each grid cell
    /// to a cubic once per row; [`LookupProbe`], [`Lookup::baseband`] and
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
    cfg: Config,
    len: usize,
    /// log₂ L.
    bits: u32,
    /// Carrier bin k_d.
    k_d: i64,
    /// `(k_lo − k_d) mod L`: grid bin of band bin 0.
    first: usize,
    /// η.
    bound: f64,
    /// The interpolant `bound` is for.
    interp: Interpolant,
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

/// The lookup path's tables for one [`LookupGrid`], in caller memory: the FFT twiddles
/// (`L − 1` used, stage by stage) and the carrier `C[i] = e^{2πi k_d i/L}`.
#[derive(Debug)]
pub struct Lookup<'t> {
    grid: LookupGrid,
    twiddle: &'t [Complex32],
    carrier: &'t [Complex32],
}

impl<'t> Lookup<'t> {
    /// Length in `f32` of the tables: `4L` (`L` complex twiddles, `L` complex carriers).
    pub const fn tables_len(grid: &LookupGrid) -> usize {
        4 * grid.len
    }

    /// Builds the tables into `tables` (once, `f64` `libm`, rounded to `f32`).
    ///
    /// # Errors
    /// [`Error::Length`] if `tables` does not have [`Lookup::tables_len`] elements.
    pub fn new(grid: &LookupGrid, tables: &'t mut [f32]) -> Result<Self, Error> {
        let l = grid.len;
        check_len("lookup tables", Self::tables_len(grid), tables.len())?;
        let found = tables.len();
        let all = as_complex("lookup tables", tables)?;
        let Some((tw, car)) = all.split_at_mut_checked(l) else {
            return Err(Error::Length {
                what: "lookup tables",
                expected: 4 * l,
                found,
            });
        };
        // Stage with half-size h uses e^{+2πi k/(2h)}, k < h, at entries h − 1 .. 2h − 1.
        let mut h = 1;
        while h < l {
            for (k, w) in tw.iter_mut().skip(h - 1).take(h).enumerate() {
                let a = core::f64::consts::PI * k as f64 / h as f64;
                *w = Complex32::new(libm::cos(a) as f32, libm::sin(a) as f32);
            }
            h *= 2;
        }
        if let Some(last) = tw.last_mut() {
            *last = Complex32::new(0.0, 0.0);
        }
        // `max(1)`: L ≥ 2 already; lets the optimiser drop the division-by-zero branch.
        let lm = l.max(1) as u64;
        let step = grid.k_d.rem_euclid(lm as i64) as u64;
        for (i, c) in car.iter_mut().enumerate() {
            let q = (step * i as u64) % lm;
            let a = core::f64::consts::TAU * q as f64 / l as f64;
            *c = Complex32::new(libm::cos(a) as f32, libm::sin(a) as f32);
        }
        Ok(Self {
            grid: *grid,
            twiddle: tw,
            carrier: car,
        })
    }

    /// The grid.
    pub const fn grid(&self) -> &LookupGrid {
        &self.grid
    }

    /// The FFT twiddles, stage with half-size `h` at entries `h − 1 .. 2h − 1`.
    pub(crate) const fn twiddle_table(&self) -> &[Complex32] {
        self.twiddle
    }

    /// The carrier table `C[i] = e^{2πi k_d i/L}`, `L` entries.
    pub(crate) const fn carrier_table(&self) -> &[Complex32] {
        self.carrier
    }

    /// One SPAD's baseband grid `Y[n]` (`n < L`, then `EXTRA` wrapped copies) from its band
    /// spectrum `hg` (J values): the band placed in bit-reversed order, then the radix-2
    /// decimation-in-time stages of an inverse FFT. The reference of the fused synthesis
    /// every path runs (`lookup_slice::synthesise_fused`: the same sums, 25–30 % fewer
    /// instructions), checked against it and against the direct sum by the unit tests.
    #[cfg(test)]
    pub(crate) fn synthesise(&self, hg: &[Complex32], y: &mut [Complex32]) {
        let l = self.grid.len;
        let shift = usize::BITS - self.grid.bits;
        let mask = l - 1;
        y.fill(Complex32::new(0.0, 0.0));
        let mut k = self.grid.first;
        for h in hg {
            // `shift` ≥ 1 (L ≤ 2²⁴); reverse_bits of k < L over log₂L bits.
            let r = k.reverse_bits().checked_shr(shift).unwrap_or(0);
            if let Some(v) = y.get_mut(r) {
                *v = *h;
            }
            k = (k + 1) & mask;
        }
        let Some((grid, extra)) = y.split_at_mut_checked(l) else {
            return;
        };
        // Stages h = 1 and 2 together (twiddles 1 and i): one radix-4 pass.
        for q in grid.as_chunks_mut::<4>().0 {
            let (a0, a1) = (q[0] + q[1], q[0] - q[1]);
            let (a2, a3) = (q[2] + q[3], q[2] - q[3]);
            let ia3 = Complex32::new(-a3.im, a3.re);
            *q = [a0 + a2, a1 + ia3, a0 - a2, a1 - ia3];
        }
        let mut h = 4;
        while h < l {
            let (Some(tw), Some(size)) = (
                self.twiddle.get(h - 1..2 * h - 1),
                core::num::NonZeroUsize::new(2 * h),
            ) else {
                break;
            };
            for block in grid.chunks_exact_mut(size.get()) {
                let (a, b) = block.split_at_mut(h);
                for ((a, b), w) in a.iter_mut().zip(b.iter_mut()).zip(tw) {
                    let (av, t) = (*a, *b * *w);
                    *a = av + t;
                    *b = av - t;
                }
            }
            h *= 2;
        }
        for (e, g) in extra.iter_mut().zip(grid.iter()) {
            *e = *g;
        }
    }
}

/// Reads one SPAD's baseband grid (made by [`Lookup::baseband`]) at any path time: the
/// cubic interpolation and carrier restoration of the module docs, with the grid constants
/// converted to `f32` once ([`Lookup::reader`]). `Copy`; cost per read: one `f32→u32`
/// conversion, four Lagrange weights, four complex loads, one carrier table entry and one
/// small-phase polynomial (no square root, no division, no `f64`).
#[derive(Clone, Copy, Debug)]
pub struct GridReader<'l> {
    carrier: &'l [Complex32],
    /// Grid points per metre `L/(NΔt)`.
    per_m: f32,
    /// Carrier turns per grid step `k_d/L`.
    theta: f32,
    mask: usize,
}

impl GridReader<'_> {
    /// `Z_s(τ) = Σ_j hg[j]·e^{iν_j τ}` (module docs) read from the baseband grid `y` at the
    /// path time `tau ≥ 0` (m), within [`LookupGrid::bound`] per unit of `Σ_j |hg[j]|/Ĝ_j`.
    /// The grid is `NΔt`-periodic, so any `τ ≥ 0` is valid; a negative or NaN `τ` reads
    /// node 0, and a `y` shorter than [`Lookup::grid_buf_len`] reads 0 (never a panic).
    #[inline(always)]
    pub fn read(&self, y: &[Complex32], tau: f32) -> Complex32 {
        // τ ≥ 0: the cast floors (and saturates at u32::MAX, masked below).
        let x = tau * self.per_m;
        let i = x as u32 as usize;
        let t = x - i as f32;
        let start = i.wrapping_sub(1) & self.mask;
        let (Some(q), Some(c)) = (
            y.get(start..).and_then(|q| q.first_chunk::<4>()),
            self.carrier.get(i & self.mask),
        ) else {
            return Complex32::new(0.0, 0.0);
        };
        let w = lagrange4(t);
        let base = q[0] * w[0] + q[1] * w[1] + q[2] * w[2] + q[3] * w[3];
        base * (*c * cis_small_turns(self.theta * t))
    }
}

impl Lookup<'_> {
    /// Length in complex values of one SPAD's baseband grid buffer: `L + 3` (the grid and the
    /// wrapped copies the 4-point stencil reads past its end).
    pub const fn grid_buf_len(grid: &LookupGrid) -> usize {
        grid.len + EXTRA
    }

    /// Synthesises the baseband grid `Y[n] = Σ_j hg[j]·e^{2πi(k_lo + j − k_d)n/L}` of one
    /// band spectrum `hg` (J values, sign convention A of the module docs) into `y`, for
    /// reading with [`Lookup::reader`]: one inverse FFT of length `L`, `(L/2)·log₂L`
    /// butterflies. Any spectrum on the configuration's band works: a row's
    /// [`Row::band`] chunk, or a factorised column's `U[s][·]`
    /// ([`ColumnF32::finish_lookup`](crate::ColumnF32::finish_lookup)).
    ///
    /// # Errors
    /// [`Error::Length`] if `hg` does not have `J` values or `y` not
    /// [`Lookup::grid_buf_len`]; [`Error::Incompatible`] for an [`Interpolant::Hermite`] grid
    /// (the reader is the Lagrange cubic); `y` is unchanged then.
    pub fn baseband(&self, hg: &[Complex32], y: &mut [Complex32]) -> Result<(), Error> {
        if self.grid.interp != Interpolant::Lagrange {
            return Err(Error::Incompatible(
                "a Hermite lookup grid (the reader is the Lagrange cubic)",
            ));
        }
        check_len("band spectrum", self.grid.cfg.bins(), hg.len())?;
        check_len("grid buffer", Self::grid_buf_len(&self.grid), y.len())?;
        synthesise_fused(self, hg, y);
        Ok(())
    }

    /// The reader of the grids synthesised by [`Lookup::baseband`] (constants in `f32`, made
    /// once: hoist it out of per-pair loops).
    pub fn reader(&self) -> GridReader<'_> {
        GridReader {
            carrier: self.carrier,
            per_m: (self.grid.len as f64 / self.grid.cfg.span()) as f32,
            theta: (self.grid.k_d as f64 / self.grid.len as f64) as f32,
            mask: self.grid.len - 1,
        }
    }
}

impl Lookup<'_> {
    /// [`Lookup::reader`] without `f64` arithmetic, for the per-scan paths on an FPU without
    /// double precision: from `inv_span = (1/(NΔt)) as f32`, the same bits (`L` is a power
    /// of two, so `L·fl(1/span) = fl(L/span)` and `fl(k_d)/L = fl(k_d/L)`, `|k_d| < 2²⁴`).
    pub(crate) fn reader_f32(&self, inv_span: f32) -> GridReader<'_> {
        let len = self.grid.len as u32;
        GridReader {
            carrier: self.carrier,
            per_m: len as f32 * inv_span,
            theta: self.grid.k_d as i32 as f32 / len as f32,
            mask: self.grid.len - 1,
        }
    }
}

/// [`dist_nr`] for the other modules of the kernel (the lookup paths' per-pair distance).
#[inline(always)]
pub(crate) fn dist_fast(a: &Point, b: &Point) -> f32 {
    dist_nr(a, b)
}

/// A Gaussian-gated diagonal or column on the lookup path: the [`Probe`](crate::Probe) of
/// [`Target`] × [`Gate::Gaussian`](crate::Gate::Gaussian) with an O(1) cost per pair (module
/// docs). Accumulators of the same size as the band diagonal's (`4Kv` `f32`: a Kahan-compensated
/// complex sum per voxel), merge and `finish` like it; the result equals the band path's within
/// [`LookupGrid::bound`].
///
/// ```
/// use vltm_kernel::{Config, Lookup, LookupGrid, LookupParams, LookupProbe, Params, RowBuffer, Scan, Target};
/// let cfg = Config::try_new(&Params::new(0.2, 128, 0.01)).unwrap();
/// let spads = [[0.0f32, 0.0, 0.0]];
/// let voxels = [[0.0f32, 0.0, 0.5], [0.0, 0.0, 0.8]];
/// let mut tables = vec![0.0; Scan::tables_len(&cfg, 1)];
/// let scan = Scan::new(&cfg, &spads, &mut tables).unwrap();
/// let grid = LookupGrid::try_new(&cfg, &LookupParams::new()).unwrap();
/// let mut lt = vec![0.0; Lookup::tables_len(&grid)];
/// let lookup = Lookup::new(&grid, &mut lt).unwrap();
/// let mut state = vec![0.0; LookupProbe::state_len(2)];
/// let mut scratch = vec![0.0; LookupProbe::scratch_len(&grid, 2)];
/// let mut diag =
///     LookupProbe::new(&scan, &lookup, Target::Diagonal, &voxels, &mut state, &mut scratch)
///         .unwrap();
/// let mut buf = vec![0.0; RowBuffer::len(&cfg, 1)];
/// let mut rows = RowBuffer::new(&scan, &mut buf).unwrap();
/// let mut h = [0u16; 128];
/// h[100] = 50; // a return at path length 1.00 m = 2 × 0.5 m
/// let row = rows.load(&scan, [0.0, 0.0, 0.0], &h).unwrap();
/// diag.push_row(&scan, &lookup, &row).unwrap();
/// let mut out = [0.0f64; 2];
/// diag.finish(&mut out).unwrap();
/// assert!(out[0] > 10.0 * out[1]);
/// ```
#[derive(Debug)]
pub struct LookupProbe<'m> {
    target: Target,
    voxels: &'m [Point],
    /// Per voxel: the amplitude as a Kahan-compensated `f32` sum `[s.re, s.im, c.re, c.im]`.
    acc: &'m mut [[f32; 4]],
    /// One SPAD's grid, `L + EXTRA`.
    grid_buf: &'m mut [Complex32],
    /// Per voxel: this row's sum over the SPADs.
    sums: &'m mut [Complex32],
    /// Per voxel: the lead distance (`d_lv`, or `d_la + d_ab`).
    lead: &'m mut [f32],
    report: Report,
    grid: LookupGrid,
    /// Per-row constants, rounded to `f32` once by [`LookupProbe::new`] (no soft `f64` per
    /// row on a Cortex-M4F): grid points per metre of path `L/span`, the carrier
    /// `θ = k_d/L`, the guard interval (m) and the weights' `d_min` (m).
    per_m: f32,
    theta: f32,
    guard_m: (f32, f32),
    d_min: f32,
}

impl<'m> LookupProbe<'m> {
    /// Length in `f32` of the state: `4Kv` (per voxel a Kahan-compensated complex sum: the
    /// bytes of the band diagonal's `2Kv` `f64`, with no soft `f64` per row on a
    /// Cortex-M4F).
    pub const fn state_len(n_voxels: usize) -> usize {
        n_voxels.saturating_mul(4)
    }

    /// Length in `f32` of the scratch: `2(L + 3) + 3Kv`.
    pub const fn scratch_len(grid: &LookupGrid, n_voxels: usize) -> usize {
        (2 * (grid.len + EXTRA)).saturating_add(n_voxels.saturating_mul(3))
    }

    /// A zeroed probe over `voxels`.
    ///
    /// # Errors
    /// [`Error::Length`] if `state` or `scratch` does not have [`Self::state_len`] /
    /// [`Self::scratch_len`] elements; [`Error::Incompatible`] if `lookup` was made for
    /// another configuration than `scan` or for [`Interpolant::Hermite`];
    /// [`Error::NonFinite`] for a non-finite voxel or focus.
    pub fn new(
        scan: &Scan<'_>,
        lookup: &Lookup<'_>,
        target: Target,
        voxels: &'m [Point],
        state: &'m mut [f32],
        scratch: &'m mut [f32],
    ) -> Result<Self, Error> {
        let grid = lookup.grid;
        if !grid.cfg.same(scan.config()) {
            return Err(Error::Incompatible("lookup grid of another configuration"));
        }
        if grid.interp != Interpolant::Lagrange {
            return Err(Error::Incompatible(
                "a Hermite lookup grid (the voxel list reads the Lagrange cubic)",
            ));
        }
        let kv = voxels.len();
        check_len("state", Self::state_len(kv), state.len())?;
        check_len("scratch", Self::scratch_len(&grid, kv), scratch.len())?;
        check_points("voxels", voxels)?;
        if let Target::Column(a) = target {
            check_points("focus", &[a])?;
        }
        let found = state.len();
        let acc: &mut [[f32; 4]] =
            bytemuck::try_cast_slice_mut(state).map_err(|_| Error::Length {
                what: "state",
                expected: 4 * kv,
                found,
            })?;
        let short = Error::Length {
            what: "scratch",
            expected: Self::scratch_len(&grid, kv),
            found: scratch.len(),
        };
        let (g, rest) = scratch
            .split_at_mut_checked(2 * (grid.len + EXTRA))
            .ok_or(short)?;
        let (sums, lead) = rest.split_at_mut_checked(2 * kv).ok_or(short)?;
        acc.fill([0.0; 4]);
        let cfg = &grid.cfg;
        let (g_lo, g_hi) = cfg.guard();
        Ok(Self {
            target,
            voxels,
            acc,
            grid_buf: as_complex("scratch", g)?,
            sums: as_complex("scratch", sums)?,
            lead,
            report: Report::default(),
            grid,
            per_m: (grid.len as f64 / cfg.span()) as f32,
            theta: (grid.k_d as f64 / grid.len as f64) as f32,
            guard_m: (g_lo as f32, g_hi as f32),
            d_min: cfg.params().d_min as f32,
        })
    }

    /// The target.
    pub const fn target(&self) -> Target {
        self.target
    }
    /// The voxel list.
    pub const fn voxels(&self) -> &'m [Point] {
        self.voxels
    }
    /// Counters so far (`aliased` is always 0: every path gets the guard).
    pub const fn report(&self) -> Report {
        self.report
    }
    /// The complex amplitude accumulated so far at voxel `i` (0 past the end), the
    /// compensated sum's value `s − c` in `f64`.
    pub fn amplitude(&self, i: usize) -> Complex64 {
        self.acc.get(i).map_or(Complex64::new(0.0, 0.0), value)
    }
    /// Zeroes the accumulators and counters.
    pub fn reset(&mut self) {
        self.acc.fill([0.0; 4]);
        self.report = Report::default();
    }

    /// Adds one laser row: `Ks` grid syntheses, then `Kv·Ks` O(1) lookups. Infallible on
    /// data values and panic-free.
    ///
    /// # Errors
    /// [`Error::Incompatible`] if `lookup` or `scan` is not the probe's configuration;
    /// [`Error::Length`] if `row` was loaded for a scan of another size. Nothing is
    /// changed then.
    pub fn push_row<T: Sample>(
        &mut self,
        scan: &Scan<'_>,
        lookup: &Lookup<'_>,
        row: &Row<'_, T>,
    ) -> Result<(), Error> {
        let cfg = scan.config();
        if !lookup.grid.same(&self.grid) || !cfg.same(&self.grid.cfg) {
            return Err(Error::Incompatible("lookup grid of another configuration"));
        }
        let ks = scan.spads().len();
        let j = cfg.bins().max(1);
        check_len("row spectra", ks * cfg.bins(), row.band().len())?;
        check_len("row histograms", ks * cfg.nt(), ks * row.nt())?;
        check_len("row offsets", ks, row.offsets().len())?;
        let laser = row.laser();
        // The weight w(d) = 1/max(d, d_min) or 1 (`Config::weight` with the hoisted `d_min`:
        // it converts d_min from f64 per call, soft float on a Cortex-M4F; same bits. `max`
        // by comparison: `f32::max` is an out-of-line `fmaxf` on a Cortex-M).
        let d_min = self.d_min;
        let inv = matches!(cfg.weights(), Weights::Inv);
        let weight = |d: f32| {
            if inv {
                1.0 / if d > d_min { d } else { d_min }
            } else {
                1.0
            }
        };
        let w_lead = match self.target {
            Target::Diagonal => {
                for (d, v) in self.lead.iter_mut().zip(self.voxels) {
                    *d = dist_nr(&laser, v);
                }
                None
            }
            Target::Column(a) => {
                let d_la = dist_nr(&laser, &a);
                for (d, v) in self.lead.iter_mut().zip(self.voxels) {
                    *d = d_la + dist_nr(&a, v);
                }
                Some(weight(d_la))
            }
        };
        self.sums.fill(Complex32::new(0.0, 0.0));
        let (g_lo, g_hi) = self.guard_m;
        let (per_m, theta) = (self.per_m, self.theta);
        let mask = self.grid.len - 1;
        for ((sp, hg), off) in scan
            .spads()
            .iter()
            .zip(row.band().chunks_exact(j))
            .zip(row.offsets())
        {
            synthesise_fused(lookup, hg, self.grid_buf);
            let y: &[Complex32] = self.grid_buf;
            for ((v, d_lead), sum) in self
                .voxels
                .iter()
                .zip(self.lead.iter())
                .zip(self.sums.iter_mut())
            {
                let d_vs = dist_nr(v, sp);
                let tau = *d_lead + d_vs;
                let rel = tau + off;
                if !(rel >= g_lo && rel <= g_hi) {
                    continue;
                }
                // τ ≥ 0: the cast floors (and saturates at u32::MAX, masked below).
                let x = tau * per_m;
                let i = x as u32 as usize;
                let t = x - i as f32;
                let start = i.wrapping_sub(1) & mask;
                let (Some(q), Some(c)) = (
                    y.get(start..).and_then(|q| q.first_chunk::<4>()),
                    lookup.carrier.get(i & mask),
                ) else {
                    continue;
                };
                let w = lagrange4(t);
                let base = q[0] * w[0] + q[1] * w[1] + q[2] * w[2] + q[3] * w[3];
                *sum += base * (*c * cis_small_turns(theta * t)) * weight(d_vs);
            }
        }
        for ((a, s), d) in self
            .acc
            .iter_mut()
            .zip(self.sums.iter())
            .zip(self.lead.iter())
        {
            let w = match w_lead {
                Some(w) => w,
                None => weight(*d),
            };
            kahan(a, *s * w);
        }
        self.report.count_row(row);
        Ok(())
    }

    /// Adds another lookup probe's accumulators (same grid, target and voxels).
    ///
    /// # Errors
    /// [`Error::Incompatible`] if the probes differ; nothing is changed then.
    pub fn merge(&mut self, other: &LookupProbe<'_>) -> Result<(), Error> {
        if self.target != other.target
            || self.voxels != other.voxels
            || !self.grid.same(&other.grid)
        {
            return Err(Error::Incompatible("different target, voxels or grid"));
        }
        for (a, b) in self.acc.iter_mut().zip(other.acc.iter()) {
            kahan(a, Complex32::new(b[0] - b[2], b[1] - b[3]));
        }
        self.report.add_part(&other.report);
        Ok(())
    }

    /// Writes the intensities `T = |A|²` into `out` (length = voxels) and returns the
    /// counters. Does not change the accumulators.
    ///
    /// # Errors
    /// [`Error::Length`] if `out` has the wrong length.
    pub fn finish(&self, out: &mut [f64]) -> Result<Report, Error> {
        check_len("out", self.voxels.len(), out.len())?;
        for (o, a) in out.iter_mut().zip(self.acc.iter()) {
            *o = value(a).norm_sqr();
        }
        Ok(self.report)
    }

    /// [`LookupProbe::finish`] in `f32` (no `f64` on a Cortex-M4F): `T = |s − c|²` with the
    /// compensated sum's value rounded once to `f32` (a relative `2u` more than `finish`).
    ///
    /// # Errors
    /// [`Error::Length`] if `out` has the wrong length.
    pub fn finish_f32(&self, out: &mut [f32]) -> Result<Report, Error> {
        check_len("out", self.voxels.len(), out.len())?;
        for (o, a) in out.iter_mut().zip(self.acc.iter()) {
            *o = Complex32::new(a[0] - a[2], a[1] - a[3]).norm_sqr();
        }
        Ok(self.report)
    }
}

/// One SPAD's baseband grid `Y[n]` (`n < L`, then wrapped copies up to `y.len()`, at most
/// `L`) from its band spectrum `hg`: the inverse FFT of the band placed in bit-reversed
/// order (the unit tests' radix-2 `Lookup::synthesise`), with the radix-2 stages after the first radix-4
/// pass fused in pairs (`h`, `2h`): each group of four values is loaded and stored once per
/// two stages, and the second stage's odd twiddle `e^{iπ(k+h)/2h} = i·e^{iπk/2h}` is a
/// rotation, so three complex products per four butterflies instead of four. Same sums,
/// other rounding (within the FFT's `f32` error).
pub(crate) fn synthesise_fused(lookup: &Lookup<'_>, hg: &[Complex32], y: &mut [Complex32]) {
    let grid = lookup.grid();
    let l = grid.len();
    let bits = l.trailing_zeros();
    let shift = usize::BITS - bits;
    let mask = l - 1;
    let cfg = grid.config();
    let mut k = (cfg.k_lo() - grid.carrier_bin()).rem_euclid(l.max(1) as i64) as usize;
    y.fill(Complex32::new(0.0, 0.0));
    for h in hg {
        let r = k.reverse_bits().checked_shr(shift).unwrap_or(0);
        if let Some(v) = y.get_mut(r) {
            *v = *h;
        }
        k = (k + 1) & mask;
    }
    let Some((g, extra)) = y.split_at_mut_checked(l) else {
        return;
    };
    for q in g.as_chunks_mut::<4>().0 {
        let (a0, a1) = (q[0] + q[1], q[0] - q[1]);
        let (a2, a3) = (q[2] + q[3], q[2] - q[3]);
        let ia3 = Complex32::new(-a3.im, a3.re);
        *q = [a0 + a2, a1 + ia3, a0 - a2, a1 - ia3];
    }
    let tw = lookup.twiddle_table();
    let mut h = 4;
    while 4 * h <= l {
        let (Some(w1), Some(w2), Some(size)) = (
            tw.get(h - 1..2 * h - 1),
            tw.get(2 * h - 1..3 * h - 1),
            core::num::NonZeroUsize::new(4 * h),
        ) else {
            break;
        };
        for block in g.chunks_exact_mut(size.get()) {
            let Some((q01, q23)) = block.split_at_mut_checked(2 * h) else {
                return;
            };
            let (Some((q0, q1)), Some((q2, q3))) =
                (q01.split_at_mut_checked(h), q23.split_at_mut_checked(h))
            else {
                return;
            };
            for ((((a0, a1), (a2, a3)), w1), w2) in q0
                .iter_mut()
                .zip(q1.iter_mut())
                .zip(q2.iter_mut().zip(q3.iter_mut()))
                .zip(w1)
                .zip(w2)
            {
                let (t1, t3) = (*a1 * *w1, *a3 * *w1);
                let (a, b) = (*a0 + t1, *a0 - t1);
                let (c, d) = (*a2 + t3, *a2 - t3);
                let (tc, td) = (c * *w2, d * *w2);
                let itd = Complex32::new(-td.im, td.re);
                *a0 = a + tc;
                *a2 = a - tc;
                *a1 = b + itd;
                *a3 = b - itd;
            }
        }
        h *= 4;
    }
    if h < l {
        let (Some(w), Some(size)) = (
            tw.get(h - 1..2 * h - 1),
            core::num::NonZeroUsize::new(2 * h),
        ) else {
            return;
        };
        for block in g.chunks_exact_mut(size.get()) {
            let Some((a, b)) = block.split_at_mut_checked(h) else {
                return;
            };
            for ((a, b), w) in a.iter_mut().zip(b.iter_mut()).zip(w) {
                let (av, t) = (*a, *b * *w);
                *a = av + t;
                *b = av - t;
            }
        }
    }
    for (e, v) in extra.iter_mut().zip(g.iter()) {
        *e = *v;
    }
}

/// Kahan step: `acc = [s.re, s.im, c.re, c.im]` += `z` (`c` the running compensation, the
/// rounding error still to subtract).
#[inline(always)]
pub(crate) fn kahan(acc: &mut [f32; 4], z: Complex32) {
    let [s_re, s_im, c_re, c_im] = *acc;
    let (y_re, y_im) = (z.re - c_re, z.im - c_im);
    let (t_re, t_im) = (s_re + y_re, s_im + y_im);
    *acc = [t_re, t_im, (t_re - s_re) - y_re, (t_im - s_im) - y_im];
}

/// The compensated sum's value `s − c`, in `f64`.
#[inline]
pub(crate) fn value(a: &[f32; 4]) -> Complex64 {
    Complex64::new(
        f64::from(a[0]) - f64::from(a[2]),
        f64::from(a[1]) - f64::from(a[3]),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Params;

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
            Err(Error::Incompatible(_))
        ));
    }

    /// `reader_f32` (no `f64`) has the same constants as `reader`.
    #[test]
    fn reader_f32_is_reader() {
        for (lam, nt, dt) in [(0.13, 255, 0.0255), (0.2, 64, 0.01), (0.1, 1000, 0.003)] {
            let c = Config::try_new(&Params::new(lam, nt, dt)).unwrap();
            let grid = LookupGrid::try_new(&c, &LookupParams::new()).unwrap();
            let mut t = [0.0f32; 4 * 2048];
            let t = &mut t[..Lookup::tables_len(&grid)];
            let lookup = Lookup::new(&grid, t).unwrap();
            let (a, b) = (lookup.reader(), lookup.reader_f32((1.0 / c.span()) as f32));
            assert_eq!(a.per_m.to_bits(), b.per_m.to_bits());
            assert_eq!(a.theta.to_bits(), b.theta.to_bits());
            assert_eq!(a.mask, b.mask);
        }
    }

    #[test]
    fn newton_sqrt_within_one_ulp() {
        let mut x = 1e-6f32;
        while x < 1e4 {
            let r = sqrt_nr(x);
            let e = libm::sqrtf(x);
            assert!(r.to_bits().abs_diff(e.to_bits()) <= 1, "{x}: {r} vs {e}");
            x *= 1.0007;
        }
        assert_eq!(sqrt_nr(0.0), 0.0);
    }

    #[test]
    fn lagrange_weights_reproduce_cubics() {
        for i in 0..16 {
            let t = i as f32 / 16.0;
            let w = lagrange4(t);
            let f = |x: f32| 0.5 - 2.0 * x + 0.25 * x * x * x;
            let p = w[0] * f(-1.0) + w[1] * f(0.0) + w[2] * f(1.0) + w[3] * f(2.0);
            assert!((p - f(t)).abs() < 1e-5, "{t}: {p} vs {}", f(t));
        }
    }

    /// The inverse FFT synthesis, radix-2 and fused, equals the direct sum
    /// `Σ_j HG_j e^{2πi(k_j − k_d)n/L}`.
    #[test]
    fn synthesis_matches_direct_sum() {
        let c = cfg();
        let grid = LookupGrid::try_new(&c, &LookupParams::new()).unwrap();
        let l = grid.len();
        let mut tables = [0.0f32; 4 * 512];
        let lookup = Lookup::new(&grid, &mut tables[..4 * l]).unwrap();
        let mut hg = [Complex32::new(0.0, 0.0); 64];
        let j = c.bins();
        assert!(j <= 64 && l <= 512);
        for (i, h) in hg.iter_mut().take(j).enumerate() {
            *h = Complex32::new(libm::sinf(i as f32 * 1.3), libm::cosf(i as f32 * 0.7));
        }
        let mut y = [Complex32::new(0.0, 0.0); 512 + EXTRA];
        lookup.synthesise(&hg[..j], &mut y[..l + EXTRA]);
        let mut fused = [Complex32::new(0.0, 0.0); 512 + EXTRA];
        synthesise_fused(&lookup, &hg[..j], &mut fused[..l + EXTRA]);
        let mut worst = 0.0f64;
        for (n, (yn, fn_)) in y.iter().zip(&fused).enumerate().take(l + EXTRA) {
            let (mut re, mut im) = (0.0f64, 0.0f64);
            for (i, h) in hg.iter().take(j).enumerate() {
                let k = c.k_lo() + i as i64 - grid.k_d;
                let a = core::f64::consts::TAU * (k * n as i64) as f64 / l as f64;
                let (s, co) = (libm::sin(a), libm::cos(a));
                re += h.re as f64 * co - h.im as f64 * s;
                im += h.re as f64 * s + h.im as f64 * co;
            }
            let e = libm::hypot(yn.re as f64 - re, yn.im as f64 - im);
            let f = libm::hypot(fn_.re as f64 - re, fn_.im as f64 - im);
            worst = worst.max(e).max(f);
        }
        assert!(worst < 1e-4 * j as f64, "worst {worst}");
    }
}
