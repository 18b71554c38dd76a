//! Fixed-point path for MCUs without an FPU (Cortex-M0, `thumbv6m-none-eabi`): band spectra
//! of `u16` histograms, the Gaussian **diagonal** and the **factorised Gaussian column** in
//! integer arithmetic (issue 5 item 3). The float path ([`Scan`](crate::Scan),
//! [`RowBuffer`](crate::RowBuffer), [`Probe`](crate::Probe)) is unchanged; this module
//! reuses its [`Config`] and computes the same amplitudes `A(a, b)` (module docs of
//! [`crate::Probe`]) up to the quantisation bounds below.
//!
//! # Design
//!
//! * **Design in float, run in fixed** (STYLE §8.13): [`FixedConfig::try_new`] takes a
//!   validated [`Config`] and the caller's [`FixedLimits`] (rows, SPADs, smallest leg
//!   distance), derives every shift once and rejects configurations whose headroom budget
//!   would overflow. [`FixedScan::new`] builds the tables once from `f64` `libm` values rounded
//!   to Q1.15 ([`I1F15`]): the DFT twiddles `e^{−2πiq/N}` and the normalised gate weights
//!   `ĝ_j = Ĝ_j/Ĝ_max`.
//! * **Band DFT**: `D_j = Σ_n h[n]·W[(k_j·n) mod N]`, `u16` count × Q15 twiddle → `i32`
//!   product (< 2³¹), summed in `i64`; the twiddle index is the same integer phase
//!   accumulator as the float path, so there is no drift with n.
//! * **Phases** `e^{iν_j τ}` by an **integer NCO** (STYLE §8.14): a `u32` phase in turns,
//!   `step = round(2³²·τ/(NΔt)) mod 2³²`, `φ_j = k_lo·step + j·step` with `wrapping_*`
//!   (exact modulo 2³²: no drift over the band), into a 1025-entry Q1.15 cos/sin table over
//!   one turn built at **compile time** (`const fn`, in flash) with linear interpolation.
//! * **Band spectra** `HG_j = round(D_j·ĝ_j·p_j / 2^(30+sh))` stored as `i32` (`p_j` the leg
//!   phase `e^{iν_j x_s}`), the per-config shift `sh` making the worst-case row fit.
//! * **Complex MACs on raw integers** (STYLE §8.15): `i32 × Q15 → i64`, never
//!   `Complex<FixedI32>`.
//! * **Soft float, documented**: distances use `f32` `libm::sqrtf` and the `1/d` weights an
//!   `f32` division, **per (voxel, SPAD) pair and per row** only (two phase seeds and one
//!   weight each: ~10 soft-float operations against `J` integer MACs); the weight enters the
//!   integer accumulators through its exact `f32` mantissa and exponent (`i128` product, then
//!   a rounding shift). The per-bin loops (`Ks·J·Nt` DFT MACs, `J` band MACs per pair) use
//!   integers only. [`FixedDiagonal::finish`] / [`FixedColumn::finish`] convert to `f64` once.
//!
//! # Units
//!
//! An `HG` LSB is `Ĝ_max·2^(sh−15)` counts ([`FixedConfig::hg_lsb`]). The diagonal
//! accumulator LSB is `2^−ad` `HG` LSB and the column state LSB `2^−ac` `HG` LSB (weights
//! included); [`FixedConfig::diag_lsb`] and [`FixedConfig::column_lsb`] give them in counts.
//!
//! # Headroom budget
//!
//! `Hmax = 65535·Nt` (largest row sum of one `u16` histogram), `B = ⌈log2(Hmax + 1)⌉`,
//! `G1 = Σ_j ĝ_j/2¹⁵` (≈ `1/Ĝ_max`), `Wl = 1/max(d_min, min_distance)` (1 for
//! [`Weights::One`](crate::Weights)), `R` = [`FixedLimits::max_rows`], `Ks` =
//! [`FixedLimits::max_spads`].
//!
//! | step | operands | bound | type | condition (checked by `try_new`) |
//! |---|---|---|---|---|
//! | DFT product | `u16 × Q15` | `65535·32767 < 2³¹` | `i32` | always |
//! | DFT sum `D_j` | `Nt` products | `Hmax·2¹⁵ = 2^(B+15)` per component | `i64` | `B + 16 ≤ 62`: Nt ≤ 2³¹ |
//! | `D·ĝ·p` | `i64 × Q15 × Q15` | `2^(B+16+30)` | `i128` | always |
//! | `HG_j` | `>> (30 + sh)` | `2^(B+16−sh) ≤ 2³⁰` | `i32` | `sh = max(0, B − 14)` |
//! | band sum `Σ_j HG_j·c_j` | `J` products `i32 × Q15` | `2³⁰·G1·2¹⁵·√2` | `i64` | `G1 ≤ 2¹⁶` |
//! | diagonal term `Z·w_l·w_s·2^ad` | `Z ≤ 2³¹·G1` (HG LSB) | `2³¹·G1·Wl²·2^ad` | `i128` → `i64` | — |
//! | diagonal accumulator | `R·Ks` terms | `R·Ks·2³¹·G1·Wl²·2^ad ≤ 2⁶²` | `i64` | `ad = ⌊31 − log2(R·Ks·G1·Wl²)⌋ ≥ −32` |
//! | column term `HG·c·w_l·2^(ac−15)` | | `2^(31+0.5)·Wl·2^ac` | `i128` → `i64` | — |
//! | column state `U[s][j]` | `R` terms | `R·2^31.5·Wl·2^ac ≤ 2⁶²` | `i64` | `ac = ⌊30.5 − log2(R·Wl)⌋ ≥ −32` |
//! | column finish `Σ_j U·c` | `J` products | `J·2⁶²·2¹⁶` | `i128` | `J ≤ 2³⁰` |
//!
//! Example: Nt = 500, Δt = 1 cm, λ = 0.2 m (J = 78, G1 = 18.98), R = 4096 rows, Ks = 32
//! SPADs, weights `1/d` with `min_distance` = 0.25 m (Wl = 4): `B = 25`, `sh = 11`, `ad = 5`,
//! `ac = 16`. With `min_distance` = d_min = 1 mm (Wl = 1000) the diagonal needs `ad = −11`
//! (2¹⁶ coarser): declare the real smallest leg of the geometry.
//!
//! # Overflow policy
//!
//! * **Phases** wrap by design: `wrapping_add`/`wrapping_mul` on `u32` turns (modulo 2³² is
//!   modulo one turn).
//! * **Accumulators and products cannot overflow** (proven by the table above, enforced by
//!   [`FixedConfig::try_new`]): every row is bounded by the `u16` range, and a probe refuses
//!   rows beyond [`FixedLimits::max_rows`] ([`Error::Incompatible`]) and scans with more than
//!   [`FixedLimits::max_spads`] SPADs ([`Error::Length`]). The additions are written
//!   `wrapping_add` so the no-panic build has no overflow branch; the `i128 → i64` narrowing
//!   saturates (unreachable within the budget). The property test `tests/fixed_point.rs`
//!   runs all-65535 histograms at the budget's edge.
//! * **Distances below `min_distance`** are clamped in the weight, `w = 1/max(d, d_w)` with
//!   `d_w = max(d_min, min_distance)`: identical to the float path whenever every leg is at
//!   least `min_distance` long.
//!
//! # Quantisation error (derived in `tests/fixed_point.rs`)
//!
//! Per component: twiddles and gate weights ≤ 2⁻¹⁵ (rounding, and the clamp of +1 to
//! 32767/32768), NCO cos/sin ≤ [`CIS_ERR`] = 1.2·2⁻¹⁵ (the clamp of +1, or table rounding
//! 2⁻¹⁶ + final rounding 2⁻¹⁶, plus interpolation `(2π/1024)²/8 = 4.7e-6`; measured 3.1e-5
//! by `cis_q15_accuracy`), phase steps ≤ 2⁻³³ turns
//! per unit of `k`. The HG rounding (½ LSB each) is an absolute term of `J·Ĝ_max·2^(sh−15)`
//! counts per (laser, SPAD) pair, times the pair's weights.
//!
//! # Photon events
//!
//! [`FixedPhotons`] folds TCSPC events as they arrive into the integer DFT sums `D_j` of each
//! SPAD (`J` integer additions per photon); [`FixedRowBuffer::load_photons`] finishes the row
//! with the same code as [`FixedRowBuffer::load`]. Integer sums are exact in any order, so a
//! row of photons is **bit-identical** to the row of their histogram (`tests/fixed_point.rs`).
//!
//! Not in fixed point (use the float path): the un-gated and higher-order gates, `f32`
//! histograms.

use crate::config::{Config, Legs, Point, Weights};
use crate::error::{ConfigError, Error, check_len, check_points};
use crate::geometry::{alias_window, dist, dist64 as dist_f64, leaves_window, widen};
use crate::phase::TwiddleStep;
use ::fixed::types::I1F15;

/// Bits of the cos/sin table index (1024 intervals over one turn).
const CIS_BITS: u32 = 10;
const CIS_LEN: usize = (1 << CIS_BITS) + 1;

/// `sin x` and `cos x` for |x| ≤ π/2 by Taylor series in `f64` (const; error < 1e-17).
const fn sin_cos_quadrant(x: f64) -> (f64, f64) {
    let (mut s, mut c) = (0.0, 0.0);
    let (mut ts, mut tc) = (x, 1.0);
    let mut n = 0;
    while n < 30 {
        s += ts;
        c += tc;
        let k = (2 * n + 2) as f64;
        ts *= -x * x / (k * (k + 1.0));
        tc *= -x * x / ((k - 1.0) * k);
        n += 1;
    }
    (s, c)
}

const fn q15(v: f64) -> I1F15 {
    let y = v * 32768.0;
    let r = if y >= 0.0 {
        (y + 0.5) as i32
    } else {
        (y - 0.5) as i32
    };
    let r = if r > 32767 {
        32767
    } else if r < -32767 {
        -32767
    } else {
        r
    };
    I1F15::from_bits(r as i16)
}

/// `[cos, sin](2π·i/1024)` in Q1.15 for i = 0..=1024, built at compile time.
static CIS_TABLE: [[I1F15; 2]; CIS_LEN] = {
    let mut t = [[I1F15::ZERO; 2]; CIS_LEN];
    let quarter = 1usize << (CIS_BITS - 2);
    let mut i = 0;
    while i < CIS_LEN {
        let q = i / quarter;
        let r = i % quarter;
        let x = core::f64::consts::FRAC_PI_2 * r as f64 / quarter as f64;
        let (s, c) = sin_cos_quadrant(x);
        let (cs, sn) = match q % 4 {
            0 => (c, s),
            1 => (-s, c),
            2 => (-c, -s),
            _ => (s, -c),
        };
        t[i] = [q15(cs), q15(sn)];
        i += 1;
    }
    t
};

/// Bound of the error of [`cis_q15`] per component (relative to 1): `1.2·2⁻¹⁵`.
pub const CIS_ERR: f64 = 1.2 / 32768.0;

/// `2¹⁵·e^{2πi·φ/2³²}` (Q1.15 as `i32`) for a phase `φ` in turns: table and linear
/// interpolation, integers only. Error ≤ [`CIS_ERR`] = 1.2·2⁻¹⁵ per component (see the
/// module docs).
///
/// ```
/// let (c, s) = vltm_kernel::cis_q15(1 << 30); // a quarter turn
/// assert!(c.abs() <= 1 && (s - 32767).abs() <= 1);
/// ```
#[inline]
pub fn cis_q15(phase: u32) -> (i32, i32) {
    let idx = (phase >> (32 - CIS_BITS)) as usize;
    let frac = ((phase >> (17 - CIS_BITS)) & 0x7fff) as i32;
    let (Some(a), Some(b)) = (CIS_TABLE.get(idx), CIS_TABLE.get(idx + 1)) else {
        return (0, 0);
    };
    let lerp = |x: I1F15, y: I1F15| {
        let (x, y) = (i32::from(x.to_bits()), i32::from(y.to_bits()));
        x + (((y - x) * frac + (1 << 14)) >> 15)
    };
    (lerp(a[0], b[0]), lerp(a[1], b[1]))
}

/// `round(2³²·x/span) mod 2³²`: a phase step in turns (soft float on an M0, once per pair).
#[inline]
fn phase_step(x: f64, two32_per_span: f64) -> u32 {
    let t = libm::rint(x * two32_per_span);
    // |t| < 2⁶³ for every path shorter than 2³¹·NΔt; `as i64` saturates beyond.
    (t as i64) as u32
}

/// `round(z·w·2^sh)` for a finite `w ≥ 0`, through the exact `f32` mantissa and exponent of
/// `w` (`i128` product, rounding shift), saturated to `i64` (unreachable within the budget).
#[inline]
fn scale(z: i64, w: f32, sh: i32) -> i64 {
    let b = w.to_bits();
    let e = ((b >> 23) & 0xff) as i32;
    if e == 0 || e == 0xff {
        return 0; // zero or subnormal (w < 1.2e-38), or non-finite (cannot happen)
    }
    let m = i128::from((b & 0x7f_ffff) | 0x80_0000);
    let s = e - 150 + sh; // w·2^sh = m·2^s
    let p = i128::from(z) * m;
    let r = if s >= 0 {
        p << s.min(40)
    } else {
        let k = (-s).min(126) as u32;
        (p + (1i128 << (k - 1))) >> k
    };
    r.clamp(i128::from(i64::MIN), i128::from(i64::MAX)) as i64
}

/// Rounding arithmetic shift right of an `i128` by `k ≥ 1`, narrowed to `i64` (saturating).
#[inline]
fn round_shift(x: i128, k: u32) -> i64 {
    let r = (x + (1i128 << (k - 1))) >> k;
    r.clamp(i128::from(i64::MIN), i128::from(i64::MAX)) as i64
}

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
    cfg: Config,
    limits: FixedLimits,
    d_w: f32,
    sh: u32,
    ad: i32,
    ac: i32,
    g_max: f64,
    g1: f64,
    two32_per_span: f64,
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
    fn weight(&self, d: f32) -> f32 {
        match self.cfg.weights() {
            Weights::Inv => 1.0 / d.max(self.d_w),
            Weights::One => 1.0,
        }
    }
}

/// Fixed-point tables in caller memory: Q1.15 twiddles `e^{−2πiq/N}` (`2N`) and gate
/// weights `ĝ_j` (`J`).
#[derive(Debug)]
pub struct FixedScan<'t> {
    fc: FixedConfig,
    spads: &'t [Point],
    twiddle: &'t [I1F15],
    gate: &'t [I1F15],
}

impl<'t> FixedScan<'t> {
    /// Length of the tables in [`I1F15`]: `2N + J`.
    pub const fn tables_len(fc: &FixedConfig) -> usize {
        2 * fc.cfg.n_fft() + fc.cfg.bins()
    }

    /// Builds the tables (`f64` `libm`, rounded to Q1.15; soft float, once).
    ///
    /// # Errors
    /// [`Error::Length`] for a wrong `tables` length or more SPADs than
    /// [`FixedLimits::max_spads`]; [`Error::NonFinite`] for a non-finite SPAD.
    pub fn new(
        fc: &FixedConfig,
        spads: &'t [Point],
        tables: &'t mut [I1F15],
    ) -> Result<Self, Error> {
        check_len("tables", Self::tables_len(fc), tables.len())?;
        check_points("spads", spads)?;
        if spads.len() > fc.limits.max_spads as usize {
            return Err(Error::Length {
                what: "spads (over FixedLimits::max_spads)",
                expected: fc.limits.max_spads as usize,
                found: spads.len(),
            });
        }
        let n = fc.cfg.n_fft();
        let too_short = Error::Length {
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

    fn laser_leg(&self, laser: &Point) -> f64 {
        match self.fc.cfg.legs() {
            Legs::WallToWall => 0.0,
            Legs::FirstAndLast { laser_origin, .. } => dist_f64(laser, &laser_origin),
        }
    }

    fn sensor_leg(&self, spad: &Point) -> f64 {
        match self.fc.cfg.legs() {
            Legs::WallToWall => 0.0,
            Legs::FirstAndLast { sensor_origin, .. } => dist_f64(spad, &sensor_origin),
        }
    }
}

/// Caller-owned `i32` buffer for one row's band spectra: `Ks·(2J + 1)` (`HG` as re/im
/// pairs, then the leg offsets `x_s` as `f32` bits).
#[derive(Debug)]
pub struct FixedRowBuffer<'m> {
    buf: &'m mut [i32],
}

/// One laser row in fixed point: band spectra `HG` (`i32`, LSB [`FixedConfig::hg_lsb`]).
#[derive(Debug)]
pub struct FixedRow<'r> {
    laser: Point,
    hg: &'r [i32],
    offsets: &'r [i32],
}

impl FixedRow<'_> {
    /// The laser spot.
    pub const fn laser(&self) -> Point {
        self.laser
    }
    /// `HG[s·2J + 2j]` (re), `HG[s·2J + 2j + 1]` (im).
    pub const fn band(&self) -> &[i32] {
        self.hg
    }
    fn offset(&self, s: usize) -> f32 {
        self.offsets
            .get(s)
            .map_or(0.0, |&b| f32::from_bits(b as u32))
    }
}

impl<'m> FixedRowBuffer<'m> {
    /// Length in `i32`: `Ks·(2J + 1)`.
    pub const fn len(fc: &FixedConfig, n_spads: usize) -> usize {
        n_spads * (2 * fc.cfg.bins() + 1)
    }

    /// Wraps `buf` (length [`FixedRowBuffer::len`]).
    ///
    /// # Errors
    /// [`Error::Length`] for a wrong length.
    pub fn new(scan: &FixedScan<'_>, buf: &'m mut [i32]) -> Result<Self, Error> {
        check_len(
            "row buffer",
            Self::len(&scan.fc, scan.spads.len()),
            buf.len(),
        )?;
        Ok(Self { buf })
    }

    /// Band spectra of one row of `u16` histograms (SPAD-major, `hists[s·Nt + n]`): the DFT
    /// in `i32`/`i64` integers (`Ks·J·Nt` MACs), then gate weights and leg phases.
    ///
    /// # Errors
    /// [`Error::Length`] for a wrong `hists` length or a buffer made for another scan;
    /// [`Error::NonFinite`] for a non-finite laser position.
    pub fn load<'r>(
        &'r mut self,
        scan: &FixedScan<'_>,
        laser: Point,
        hists: &[u16],
    ) -> Result<FixedRow<'r>, Error> {
        let cfg = &scan.fc.cfg;
        let (nt, n, k_lo) = (cfg.nt(), cfg.n_fft().max(1), cfg.k_lo());
        check_len("histograms", scan.spads.len() * nt, hists.len())?;
        let twiddle = scan.twiddle.as_chunks::<2>().0;
        self.fill(scan, laser, |s, jj| {
            let h = hists.get(s * nt..(s + 1) * nt).unwrap_or(&[]);
            let mut q = TwiddleStep::new(k_lo + jj as i64, 0, n);
            let (mut re, mut im) = (0i64, 0i64);
            for &c in h {
                if let Some([wr, wi]) = twiddle.get(q.index()) {
                    let c = i32::from(c);
                    re += i64::from(c * i32::from(wr.to_bits()));
                    im += i64::from(c * i32::from(wi.to_bits()));
                }
                q.advance();
            }
            (re, im)
        })
    }

    /// Band spectra of one row from its photon events ([`FixedPhotons`]): **bit-identical**
    /// to [`FixedRowBuffer::load`] on the histograms of the same photons, since the DFT sums
    /// are integers (exact, in any order) and the rest of the computation is shared.
    ///
    /// # Errors
    /// [`Error::Length`] for a buffer or `photons` made for another scan;
    /// [`Error::NonFinite`] for a non-finite laser position.
    pub fn load_photons<'r>(
        &'r mut self,
        scan: &FixedScan<'_>,
        laser: Point,
        photons: &FixedPhotons<'_>,
    ) -> Result<FixedRow<'r>, Error> {
        let j = scan.fc.cfg.bins();
        check_len(
            "photon sums",
            FixedPhotons::len(&scan.fc, scan.spads.len()),
            photons.d.len(),
        )?;
        let d = photons.d.as_chunks::<2>().0;
        self.fill(scan, laser, |s, jj| {
            d.get(s * j + jj).map_or((0, 0), |&[re, im]| (re, im))
        })
    }

    /// The shared tail of [`FixedRowBuffer::load`] and [`FixedRowBuffer::load_photons`]:
    /// `HG_j = round(D_j·ĝ_j·p_j / 2^(30+sh))` from the DFT sums `dft(s, j) = D_j` of SPAD `s`.
    fn fill<'r>(
        &'r mut self,
        scan: &FixedScan<'_>,
        laser: Point,
        mut dft: impl FnMut(usize, usize) -> (i64, i64),
    ) -> Result<FixedRow<'r>, Error> {
        let fc = &scan.fc;
        let cfg = &fc.cfg;
        let (ks, j) = (scan.spads.len(), cfg.bins());
        check_len("row buffer", Self::len(fc, ks), self.buf.len())?;
        check_points("laser", &[laser])?;
        let d1 = scan.laser_leg(&laser);
        let k_lo = cfg.k_lo();
        let too_short = Error::Length {
            what: "row buffer",
            expected: Self::len(fc, ks),
            found: 0,
        };
        let (hg_all, offsets) = self.buf.split_at_mut_checked(2 * ks * j).ok_or(too_short)?;
        let sh = 30 + fc.sh;
        // Not `zip` over `chunks_exact`: its out-of-line `Zip::new` divides by the chunk
        // length, a panicking branch in the no-panic link (see scan.rs).
        for (s, (off, sp)) in offsets.iter_mut().zip(scan.spads).enumerate() {
            let Some(hg) = hg_all.get_mut(2 * s * j..2 * (s + 1) * j) else {
                break;
            };
            let x = d1 + scan.sensor_leg(sp) - cfg.t0();
            *off = (x as f32).to_bits() as i32;
            let step_x = phase_step(x, fc.two32_per_span);
            let mut phi = (k_lo as i32 as u32).wrapping_mul(step_x);
            for (jj, (out, g)) in hg
                .as_chunks_mut::<2>()
                .0
                .iter_mut()
                .zip(scan.gate)
                .enumerate()
            {
                let (re, im) = dft(s, jj);
                // HG = D·ĝ·p >> (30 + sh), in i128 (see the budget).
                let g = i128::from(g.to_bits());
                let (pc, ps) = cis_q15(phi);
                let (pc, ps) = (i128::from(pc), i128::from(ps));
                let (re, im) = (i128::from(re) * g, i128::from(im) * g);
                out[0] = round_shift(re * pc - im * ps, sh) as i32;
                out[1] = round_shift(re * ps + im * pc, sh) as i32;
                phi = phi.wrapping_add(step_x);
            }
        }
        Ok(FixedRow {
            laser,
            hg: hg_all,
            offsets,
        })
    }
}

/// Caller-owned integer accumulators of one row's **photon events** for the fixed-point path:
/// the DFT sums `D_j` of every SPAD (`i64` re/im) and a photon count per SPAD, so firmware
/// without an FPU folds TCSPC events as they arrive and never stores histograms
/// ([`FixedRowBuffer::load_photons`] then gives the row, bit-identical to the histogram path).
///
/// Per photon: `J` integer complex additions (one twiddle each, the index stepped by the
/// photon's bin). Memory: [`FixedPhotons::len`] `i64`. A SPAD's photons beyond the budget's
/// `Hmax = 65535·Nt` (what one `u16` histogram can hold), an unknown SPAD or a bin outside
/// `0..Nt` are dropped and counted ([`FixedPhotons::dropped`]), never an error or a panic.
#[derive(Debug)]
pub struct FixedPhotons<'m> {
    d: &'m mut [i64],
    dropped: u64,
}

impl<'m> FixedPhotons<'m> {
    /// Length in `i64`: `Ks·2J` sums, then `Ks` photon counts.
    pub const fn len(fc: &FixedConfig, n_spads: usize) -> usize {
        n_spads * (2 * fc.cfg.bins() + 1)
    }

    /// Wraps `buf` (length [`FixedPhotons::len`]) and zeroes it: an empty row.
    ///
    /// # Errors
    /// [`Error::Length`] for a wrong length.
    pub fn new(scan: &FixedScan<'_>, buf: &'m mut [i64]) -> Result<Self, Error> {
        check_len(
            "photon sums",
            Self::len(&scan.fc, scan.spads.len()),
            buf.len(),
        )?;
        buf.fill(0);
        Ok(Self { d: buf, dropped: 0 })
    }

    /// Empties the row (all sums, counts and the dropped counter to 0).
    pub fn reset(&mut self) {
        self.d.fill(0);
        self.dropped = 0;
    }

    /// Photons dropped since the last [`FixedPhotons::reset`].
    pub const fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Folds one photon of SPAD `spad` in time bin `bin` into the row. Infallible.
    pub fn push(&mut self, scan: &FixedScan<'_>, spad: usize, bin: usize) {
        let cfg = &scan.fc.cfg;
        let (j, nt, n) = (cfg.bins(), cfg.nt(), cfg.n_fft().max(1));
        let ks = scan.spads.len();
        let Some((sums, counts)) = self.d.split_at_mut_checked(ks.saturating_mul(2 * j)) else {
            self.dropped += 1;
            return;
        };
        let start = spad.saturating_mul(2 * j);
        let (Some(d), Some(count)) = (
            sums.get_mut(start..start.saturating_add(2 * j)),
            counts.get_mut(spad),
        ) else {
            self.dropped += 1;
            return;
        };
        if bin >= nt || *count >= 65535 * nt as i64 {
            self.dropped += 1;
            return;
        }
        *count += 1;
        // Twiddle index (k_j·bin) mod N, stepped by `bin` per band bin; the first product in
        // u64 (it reaches 2⁶⁰).
        let mut q = TwiddleStep::new(bin as i64, cfg.k_lo().rem_euclid(n as i64) as u64, n);
        let twiddle = scan.twiddle.as_chunks::<2>().0;
        for pair in d.as_chunks_mut::<2>().0 {
            if let Some([wr, wi]) = twiddle.get(q.index()) {
                pair[0] = pair[0].wrapping_add(i64::from(wr.to_bits()));
                pair[1] = pair[1].wrapping_add(i64::from(wi.to_bits()));
            }
            q.advance();
        }
    }
}

/// `Σ_j HG_j·e^{iν_j τ}` in `HG` LSB (the `i64` sums `>> 15`, rounded): the NCO phase steps
/// by `round(2³²τ/(NΔt))` from `k_lo·step`.
#[inline]
fn band_sum(hg: &[i32], tau: f32, fc: &FixedConfig) -> (i64, i64) {
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
    voxels: &'m [Point],
    acc: &'m mut [i64],
    rows: u32,
}

impl<'m> FixedDiagonal<'m> {
    /// State length in `i64`: `2Kv`.
    pub const fn state_len(n_voxels: usize) -> usize {
        2 * n_voxels
    }

    /// A diagonal probe over `voxels` with zeroed `state` (length [`Self::state_len`]).
    ///
    /// # Errors
    /// [`Error::Length`] / [`Error::NonFinite`].
    pub fn new(voxels: &'m [Point], state: &'m mut [i64]) -> Result<Self, Error> {
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
    /// [`Error::Incompatible`] past [`FixedLimits::max_rows`] (the budget); [`Error::Length`]
    /// for a row of another scan size. Nothing is changed then.
    pub fn push_row(&mut self, scan: &FixedScan<'_>, row: &FixedRow<'_>) -> Result<(), Error> {
        let fc = &scan.fc;
        let j = fc.cfg.bins();
        let ks = scan.spads.len();
        check_len("row spectra", 2 * ks * j, row.hg.len())?;
        if self.rows >= fc.limits.max_rows {
            return Err(Error::Incompatible("FixedLimits::max_rows reached"));
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
    /// [`Error::Length`] if `out.len() ≠ Kv`.
    pub fn finish(&self, fc: &FixedConfig, out: &mut [f64]) -> Result<(), Error> {
        check_len("out", self.voxels.len(), out.len())?;
        let lsb = fc.diag_lsb();
        for (o, [re, im]) in out.iter_mut().zip(self.acc.as_chunks::<2>().0) {
            let (re, im) = (*re as f64 * lsb, *im as f64 * lsb);
            *o = re * re + im * im;
        }
        Ok(())
    }
}

/// Factorised Gaussian column `T(x_a, ·)` in fixed point: per row
/// `U[s][j] += w_la·e^{iν_j d_la}·HG_ls[j]` (`i64` complex, `2·Ks·J`, LSB
/// [`FixedConfig::column_lsb`]), imaged at [`FixedColumn::finish`] with the same NCO and
/// `i128` sums. Exact while path times stay inside [`Config::alias_free`] (counted in the
/// return value of `finish`, as [`Report::aliased`](crate::Report)).
#[derive(Debug)]
pub struct FixedColumn<'m> {
    focus: Point,
    state: &'m mut [i64],
    rows: u32,
    leg_range: (f64, f64),
}

impl<'m> FixedColumn<'m> {
    /// State length in `i64`: `2·Ks·J`.
    pub const fn state_len(fc: &FixedConfig, n_spads: usize) -> usize {
        2 * n_spads * fc.cfg.bins()
    }

    /// A column probe for focus `focus` with zeroed `state`.
    ///
    /// # Errors
    /// [`Error::Length`] / [`Error::NonFinite`].
    pub fn new(scan: &FixedScan<'_>, focus: Point, state: &'m mut [i64]) -> Result<Self, Error> {
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
    /// As [`FixedDiagonal::push_row`].
    pub fn push_row(&mut self, scan: &FixedScan<'_>, row: &FixedRow<'_>) -> Result<(), Error> {
        let fc = &scan.fc;
        let j = fc.cfg.bins();
        check_len("row spectra", self.state.len(), row.hg.len())?;
        if self.rows >= fc.limits.max_rows {
            return Err(Error::Incompatible("FixedLimits::max_rows reached"));
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
    /// voxels whose path times left [`Config::alias_free`]. `Σ_j U·c` in `i128` with the NCO,
    /// then the `1/d` weight and the intensity in `f64` (once per voxel and SPAD).
    ///
    /// # Errors
    /// [`Error::Length`] if `out.len() ≠ voxels.len()`; [`Error::NonFinite`].
    pub fn finish(
        &self,
        scan: &FixedScan<'_>,
        voxels: &[Point],
        out: &mut [f64],
    ) -> Result<usize, Error> {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cis_q15_accuracy() {
        let mut worst = 0.0f64;
        let mut phase = 0u32;
        for _ in 0..1_000_003u32 {
            phase = phase.wrapping_add(4293); // odd stride: covers every table interval
            let (c, s) = cis_q15(phase);
            let a = core::f64::consts::TAU * f64::from(phase) / 4_294_967_296.0;
            let e = (f64::from(c) / 32768.0 - libm::cos(a))
                .abs()
                .max((f64::from(s) / 32768.0 - libm::sin(a)).abs());
            worst = worst.max(e);
        }
        // Bound of the module docs: 1.2·2⁻¹⁵ per component (clamp of +1 to 32767 = 2⁻¹⁵,
        // plus interpolation (2π/1024)²/8 = 4.7e-6 next to it).
        assert!(worst <= CIS_ERR, "max error {worst:e}");
        assert_eq!(cis_q15(0), (32767, 0));
        assert_eq!(cis_q15(1 << 31), (-32767, 0));
    }

    #[test]
    fn scale_rounds_exactly() {
        assert_eq!(scale(1000, 0.5, 0), 500);
        assert_eq!(scale(1000, 0.25, 2), 1000);
        assert_eq!(scale(-3, 0.5, 0), -1); // −1.5 rounds half up
        assert_eq!(scale(7, 3.0, -1), 11); // 10.5 → 11
        assert_eq!(scale(i64::MAX, 2.0, 10), i64::MAX); // saturates
        assert_eq!(scale(5, 0.0, 0), 0);
    }

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
