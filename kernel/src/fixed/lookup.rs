//! [`FixedLookupGrid`], [`FixedLookup`], [`FixedLookupProbe`]: the lookup path's Gaussian
//! diagonal and column in integer arithmetic, for MCUs without an FPU (module docs of [`crate::fixed`]
//! for the band path it shares its row spectra and accumulator scale with; module docs of
//! [`LookupProbe`](crate::LookupProbe) for the method in `f32` and its interpolation bound `η`).
//!
//! # Method (integers; grid, carrier and weights as in the `f32` lookup path)
//!
//! Per row and SPAD `s`, from the fixed-point band spectrum `HG_s[j]` (`i32`,
//! [`FixedRow::band`], LSB [`FixedConfig::hg_lsb`]):
//!
//! 1. **Block exponent**: `S₁ = Σ_j (|Re HG_j| + |Im HG_j|)` (`i64`), `e = max(bitlen(S₁) − 29,
//!    −16)`, `X_j = round(HG_j·2^−e)` (`i32`; a left shift, exact, when `e < 0`). Then
//!    `Σ_j (|Re X_j| + |Im X_j|) < 2²⁹`, and the grid LSB is `u = 2^e` `HG` LSB,
//!    `u ≤ max(S₁·2⁻²⁸, 2⁻¹⁶)`: the rounding below is relative to the row's own signal, not to
//!    the worst-case histogram.
//! 2. **Inverse FFT** of length `L` (radix 2, decimation in time, the band placed in
//!    bit-reversed order at grid bins `k_lo + j − k_d mod L`): `Y[n] = Σ_j X_j·e^{2πi(k_lo+j−k_d)n/L}`
//!    in `i32`, twiddles `e^{2πik/L}` Q1.15 ([`I1F15`], `L/2` complex, built once), the
//!    product `X·w` rounded once per component (exact through 15-bit halves, `i32`
//!    multiplies only: no 64-bit multiply on an M0); `w = 1` (stage 1, and `k = 0` of every
//!    stage) is not multiplied. Every node is a partial sum of the `X_j` times unit
//!    twiddles, so `|Re|, |Im| ≤ Σ|X_j|·(1 + 2⁻¹⁵)^log₂L + L < 2³⁰`: no overflow, no scaling.
//! 3. **Per pair** (voxel `v`, SPAD `s`; `τ = d_lv + d_vs` on the diagonal,
//!    `d_la + d_av + d_vs` on a column `T(a, ·)`, `f32` distances as in the band path; the
//!    lead distance and weight are made once per row and voxel): the phase `φ = ⌊τ·(2³²/NΔt)⌋ mod 2³²` (one `f32` product, a `u64` conversion):
//!    its top `log₂L` bits are the grid index `i`, the next 16 the fraction `t` (Q16), and
//!    `k_d·φ` (wrapping) the carrier's phase in turns for [`cis_q15`]: the index is
//!    integer, and the carrier needs no table of its own.
//! 4. **Cubic Lagrange weights** `ℓ_q(t)` in Q15 from `t` by `u32` products
//!    ([`lagrange4_q15`]; `Σ_q ℓ_q = 2¹⁵` exactly), `Z₀ = Σ_q ℓ_q·Y[i+q−1]` rounded once
//!    (exact through 15-bit halves), `Z = Z₀·cis_q15(k_d·φ)` rounded once: `|Z| < 1.26·2²⁹`.
//! 5. The pair adds `round(Z·w_lead·w_s·2^(ad+e))` (`w = 1/max(d, d_w)` in `f32`, `w_lead =
//!    w(d_lv)`, or `w(d_la)` on a column, entering by
//!    its mantissa and exponent, `i64` product) to the voxel's `i64` accumulator when
//!    `τ + x_s` lies in the guard interval (the band path's `f32` test; a column is imaged
//!    pair by pair like the diagonal, so every path gets the guard and nothing aliases, as in
//!    the `f32` [`LookupProbe`](crate::LookupProbe)). The accumulator LSB
//!    is the band diagonal's, [`FixedConfig::diag_lsb`], and so is the headroom: a term is
//!    `≤ 1.26·2²⁹·√2·G1·Wl²` `HG` LSB against the band budget's `2³¹·G1·Wl²`.
//!
//! # Error bound (per pair, before the weights)
//!
//! With `m = log₂L`, `‖h‖₁` the histogram's count sum, `G = Σ_j Ĝ_j`, `H₁ = Σ_j |HG_j|`
//! (complex moduli, `H₁·hg_lsb ≤ G·‖h‖₁ + J·(√2/2)·hg_lsb` counts) and `S₁ ≤ √2·H₁`:
//!
//! | source | bound (`HG` LSB) |
//! |---|---|
//! | interpolation (the `f32` path's, [`LookupGrid::bound`]) | `η·‖h‖₁/hg_lsb` |
//! | `HG` errors of the band path (twiddles, gate, the leg phase's NCO factor, ½ LSB roundings) through `Σ_q|ℓ_q| ≤ 1.25` | `1.25×` the band path's terms |
//! | FFT twiddles (`|Δw| ≤ √2·2⁻¹⁶`; `1` and `i` exact; ≤ `m − 1` per path) | `1.25·(m − 1)·√2·2⁻¹⁶·H₁` |
//! | Lagrange weights ([`LAGRANGE_Q15_ERR`] each, incl. `t` truncated to 2⁻¹⁶) | `4·LAGRANGE_Q15_ERR·1.0004·H₁` |
//! | carrier [`cis_q15`] (`≤ CIS_ERR` per component) | `1.251·√2·CIS_ERR·H₁` |
//! | block exponent (`e > 0`) and FFT roundings (`≤ L/2` per output, ½ LSB per component), interpolation and carrier roundings | `(1.25·(J + L/2)·(√2/2) + 1.42)·u` |
//! | accumulator rounding | `(√2/2)·diag_lsb` |
//!
//! with `u ≤ max(S₁·2⁻²⁸, 2⁻¹⁶)`. Per pair, relative to `‖h‖₁`:
//!
//! ```text
//! ε = η + 1.25·ε_band + G·(1.25(m−1)·√2·2⁻¹⁶ + 4.002·LAGRANGE_Q15_ERR + 1.251·√2·CIS_ERR)
//!       + √2·G·2⁻²⁸·(1.25(J + L/2)·0.71 + 1.42)
//! ```
//!
//! plus absolute terms in `hg_lsb` and `diag_lsb`; `ε_band` is the band path's relative
//! terms that reach `HG` (twiddles, gate weights, one NCO factor, phase steps:
//! `tests/fixed_point.rs`). For the paper's setup (L = 1024, J = 137) the lookup's own terms
//! come to `G·(2.4e-4 + 1.7e-4 + 6.5e-5) + G·3.0e-6`, the same class as the band path's
//! `≈ 1.9e-4·G` (`2⁻¹²` of the element's scale), far above the `f32` lookup's `η + 1e-6`.
//! `tests/fixed_point.rs` checks the bound against the `f64` time-domain reference
//! (`fixed_lookup_matches_reference`, saturated histograms included; measured errors ≤ 5 %
//! of it), and that it catches half a grid step of path time (13.6× over) and a one-bit
//! wrong shift (740× over).
//!
//! # Cost and memory
//!
//! Per row: `Ks` syntheses of `(L/2)·log₂L` butterflies (`L/2 + L/4 + …` of them without a
//! multiply) plus `J` block-exponent steps, then `Kv·Ks` pairs: one `f32` distance (`sqrtf`),
//! one `f32` weight division and product, one `f32→u64` conversion, integer weights (7 `u32`
//! multiplies), 16 `i32` multiplies for the interpolation, 8 for the carrier, one table
//! read, two `i64` products into the accumulators — against the band diagonal's `J` complex
//! `i64` MACs per pair. Why an FFT and not a direct sum over `J`: the direct sum costs `L·J`
//! complex MACs per SPAD (140,288 at the paper's L = 1024, J = 137) against 5,120
//! butterflies. Memory, caller-owned: tables `L` [`I1F15`] ([`FixedLookup::tables_len`]);
//! per probe the state `2Kv` `i64` (as [`FixedDiagonal`](crate::FixedDiagonal)) and the
//! scratch `2(L + 3) + 2Kv` `i32` ([`FixedLookupProbe::scratch_len`]: one SPAD's grid,
//! the voxels' lead distances and weights). No allocation, no panic, no `unsafe`; configuration checked
//! once ([`FixedLookupGrid::try_new`]).

use super::config::FixedConfig;
use super::nco::{cis_q15, q15};
use super::row::FixedRow;
use super::scan::FixedScan;
use crate::band::probe::Target;
use crate::config::{Point, Weights};
use crate::error::{ArgumentError, ConfigError, check_len, check_points};
use crate::geometry::dist;
use crate::lookup::grid::{Interpolant, LookupGrid, LookupParams};
use crate::lookup::table::EXTRA;
use ::fixed::types::I1F15;

/// Largest grid of the fixed-point path: `2¹⁶` points (index bits + 16 fraction bits ≤ 32).
const MAX_LEN: usize = 1 << 16;

/// Smallest block exponent `e`: a grid LSB of `2⁻¹⁶` `HG` LSB (rows with almost no signal).
const E_MIN: i32 = -16;

/// Bound on the error of [`lagrange4_q15`] per weight, relative to 1, against the exact
/// `ℓ_q(t)` at any `t` of the Q16 step (`t` is truncated to 2⁻¹⁶): `1.4·2⁻¹⁵` (measured
/// `1.35·2⁻¹⁵` over all 65,536 steps by the unit test `lagrange_q15_error`: ½ LSB of the
/// final rounding, the intermediate roundings, and up to `|ℓ'|·2⁻¹⁶` for the truncated `t`).
pub const LAGRANGE_Q15_ERR: f64 = 1.4 / 32768.0;

/// The 4-point cubic Lagrange weights (nodes −1, 0, 1, 2, as [`lagrange4`](crate::lagrange4))
/// in Q15 at `t = t16/2¹⁶` (`t16 < 2¹⁶`; higher bits are ignored), by `u32` products only,
/// with `A = t(1−t)` (Q17) and `(1+t)(2−t) = 2 + A`: `ℓ₀ = −A(2−t)/6`, `ℓ₁ = (2+A)(1−t)/2`,
/// `ℓ₂ = (2+A)t/2`, `ℓ₃ = −A(1+t)/6`. Error ≤ [`LAGRANGE_Q15_ERR`] per weight.
///
/// ```
/// assert_eq!(vltm_kernel::lagrange4_q15(0), [0, 32768, 0, 0]);
/// assert_eq!(vltm_kernel::lagrange4_q15(1 << 15), [-2048, 18432, 18432, -2048]);
/// ```
#[inline(always)]
pub fn lagrange4_q15(t16: u32) -> [i32; 4] {
    const T: u32 = 1 << 16;
    let t = t16 & 0xffff; // Q16
    // A = t(1−t) in Q17 (≤ 2¹⁵); (1+t)(2−t) = 2 + A.
    let a = (t * (T - t) + (1 << 14)) >> 15;
    // −A(2−t)/6, −A(1+t)/6: Q33 (≤ 0.385·2³³ < 2³²); ÷6 → Q15 via ·10923/2¹⁶ on Q18.
    let sixth = |x: u32| ((((x + (1 << 14)) >> 15) * 10923 + (1 << 18)) >> 19) as i32;
    let l0 = -sixth(a * (2 * T - t));
    let l3 = -sixth(a * (T + t));
    // (2 + A)·t/2 = t + A·t/2 and (2 + A)(1 − t)/2 in Q16 (A·t ≤ 2³¹), then rounded to Q15.
    let l2 = (t + ((a * t + (1 << 17)) >> 18) + 1) >> 1;
    let l1 = ((T - t) + ((a * (T - t) + (1 << 17)) >> 18) + 1) >> 1;
    [l0, l1 as i32, l2 as i32, l3]
}

/// `round(Σ_q y_q·w_q / 2¹⁵)` exactly, with `i32` multiplies only: `y = yh·2¹⁵ + yl`,
/// `0 ≤ yl < 2¹⁵`. Requires `|y_q| < 2³⁰` and `Σ_q |w_q| ≤ 1.26·2¹⁵` (the callers' bounds):
/// both partial sums then stay below 2³¹.
#[inline(always)]
fn dot_q15<const K: usize>(y: [i32; K], w: [i32; K]) -> i32 {
    let (mut hi, mut lo) = (0i32, 0i32);
    for (y, w) in y.into_iter().zip(w) {
        hi = hi.wrapping_add((y >> 15).wrapping_mul(w));
        lo = lo.wrapping_add((y & 0x7fff).wrapping_mul(w));
    }
    hi.wrapping_add(lo.wrapping_add(1 << 14) >> 15)
}

/// `(a·w) >> 15` for complex `a` (`|Re|, |Im| < 2³⁰`) and Q15 `w` (`|w| ≤ 1 + 2⁻¹⁴`), each
/// component rounded once ([`dot_q15`]).
#[inline(always)]
fn cmul_q15(ar: i32, ai: i32, wr: i32, wi: i32) -> (i32, i32) {
    (
        dot_q15([ar, ai], [wr, wi.wrapping_neg()]),
        dot_q15([ar, ai], [wi, wr]),
    )
}

/// `round(z·w·2^sh)` for a finite `w ≥ 0` (its exact `f32` mantissa and exponent), `i64`
/// product (`|z| < 2³¹`, mantissa `< 2²⁴`), saturated to `i64` (unreachable within the
/// budget).
#[inline(always)]
fn scale32(z: i32, w: f32, sh: i32) -> i64 {
    let b = w.to_bits();
    let e = ((b >> 23) & 0xff) as i32;
    if e == 0 || e == 0xff {
        return 0;
    }
    let m = i64::from((b & 0x7f_ffff) | 0x80_0000);
    let p = i64::from(z) * m; // |p| < 2⁵⁵
    let s = e - 150 + sh;
    if s >= 0 {
        let s = s.min(62) as u32;
        let lim = i64::MAX >> s;
        p.clamp(-lim, lim) << s
    } else {
        let k = (-s).min(62) as u32;
        (p + (1i64 << (k - 1))) >> k
    }
}

/// The validated grid of the fixed-point lookup path: a [`LookupGrid`] (length `L`, carrier
/// bin `k_d`, bound `η`) for a [`FixedConfig`], `L ≤ 2¹⁶`. `Copy`, no tables.
///
/// ```
/// use vltm_kernel::{Config, FixedConfig, FixedLimits, FixedLookupGrid, LookupParams, Params};
/// let cfg = Config::try_new(&Params::new(0.13, 255, 0.0255)).unwrap();
/// let fc = FixedConfig::try_new(&cfg, &FixedLimits::new(576, 28, 0.5)).unwrap();
/// let g = FixedLookupGrid::try_new(&fc, &LookupParams::new()).unwrap();
/// assert_eq!(g.grid().len(), 1024);
/// let coarse = LookupParams { grid_len: Some(512), ..LookupParams::new() };
/// assert!(FixedLookupGrid::try_new(&fc, &coarse).is_err()); // η = 5.5e-5 > 1e-5
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FixedLookupGrid {
    fc: FixedConfig,
    grid: LookupGrid,
    /// log₂ L.
    bits: u32,
    /// `(k_lo − k_d) mod L`.
    first: usize,
}

impl FixedLookupGrid {
    /// Validates `p` for `fc` (as [`LookupGrid::try_new`]) and the fixed-point limits.
    ///
    /// # Errors
    /// [`LookupGrid::try_new`]'s ([`ConfigError::TooCoarse`] for a grid whose bound `η`
    /// exceeds `tolerance`, …); [`ConfigError::SizeOverflow`]`("grid_len")` for a grid over
    /// 2¹⁶ points (the Q16 fraction of the integer index); [`ConfigError::OutOfRange`]`
    /// ("interpolant")` for [`Interpolant::Hermite`] (the fixed-point reader is the Lagrange
    /// cubic, whose bound the grid's length must be chosen for).
    pub fn try_new(fc: &FixedConfig, p: &LookupParams) -> Result<Self, ConfigError> {
        if p.interpolant != Interpolant::Lagrange {
            return Err(ConfigError::OutOfRange("interpolant"));
        }
        let grid = LookupGrid::try_new(&fc.cfg, p)?;
        let len = grid.len();
        if len > MAX_LEN {
            return Err(ConfigError::SizeOverflow("grid_len"));
        }
        Ok(Self {
            fc: *fc,
            grid,
            bits: len.trailing_zeros(),
            first: (fc.cfg.k_lo() - grid.carrier_bin()).rem_euclid(len.max(1) as i64) as usize,
        })
    }
    /// The grid (length, carrier bin, interpolation bound `η`).
    pub const fn grid(&self) -> &LookupGrid {
        &self.grid
    }
    /// The fixed-point configuration.
    pub const fn config(&self) -> &FixedConfig {
        &self.fc
    }
    /// Bitwise equality (no `f64` compare on an M0).
    fn same(&self, other: &Self) -> bool {
        self.grid.same(&other.grid)
            && self.bits == other.bits
            && self.first == other.first
            && same_fc(&self.fc, &other.fc)
    }
}

/// Bitwise equality of two fixed-point configurations' inputs (the derived fields follow).
fn same_fc(a: &FixedConfig, b: &FixedConfig) -> bool {
    a.cfg.same(&b.cfg)
        && a.limits.max_rows == b.limits.max_rows
        && a.limits.max_spads == b.limits.max_spads
        && a.limits.min_distance.to_bits() == b.limits.min_distance.to_bits()
}

/// The fixed-point lookup path's tables in caller memory: the inverse FFT's Q1.15 twiddles
/// `e^{2πik/L}`, `k < L/2` (`L` [`I1F15`], re/im pairs).
#[derive(Debug)]
pub struct FixedLookup<'t> {
    g: FixedLookupGrid,
    twiddle: &'t [I1F15],
}

impl<'t> FixedLookup<'t> {
    /// Length of the tables in [`I1F15`]: `L`.
    pub const fn tables_len(g: &FixedLookupGrid) -> usize {
        g.grid.len()
    }

    /// Builds the twiddles (`f64` `libm`, rounded to Q1.15; soft float, once).
    ///
    /// # Errors
    /// [`ArgumentError::Length`] for a wrong `tables` length.
    pub fn new(g: &FixedLookupGrid, tables: &'t mut [I1F15]) -> Result<Self, ArgumentError> {
        let l = g.grid.len();
        check_len("fixed lookup tables", Self::tables_len(g), tables.len())?;
        for (k, [c, s]) in tables.as_chunks_mut::<2>().0.iter_mut().enumerate() {
            let a = core::f64::consts::TAU * k as f64 / l as f64;
            *c = q15(libm::cos(a));
            *s = q15(libm::sin(a));
        }
        Ok(Self {
            g: *g,
            twiddle: tables,
        })
    }

    /// The grid.
    pub const fn grid(&self) -> &FixedLookupGrid {
        &self.g
    }

    /// One SPAD's grid `Y` (`2(L + 3)` `i32`: `L` points as re/im pairs, then 3 wrapped
    /// copies) in LSB `2^e` `HG` LSB; returns the block exponent `e`.
    pub(crate) fn synthesise(&self, hg: &[i32], y: &mut [i32]) -> i32 {
        let l = self.g.grid.len();
        let mask = l - 1;
        let shift = usize::BITS - self.g.bits;
        // Block exponent (module docs, step 1).
        let mut s1 = 0i64;
        for h in hg {
            s1 = s1.wrapping_add(i64::from(h.unsigned_abs()));
        }
        let bitlen = (64 - s1.leading_zeros()) as i32;
        let e = (bitlen - 29).clamp(E_MIN, 62);
        y.fill(0);
        let Some((grid, extra)) = y.split_at_mut_checked(2 * l) else {
            return e;
        };
        let grid = grid.as_chunks_mut::<2>().0;
        let mut k = self.g.first;
        for [hr, hi] in hg.as_chunks::<2>().0 {
            let r = k.reverse_bits().checked_shr(shift).unwrap_or(0);
            if let Some(v) = grid.get_mut(r) {
                *v = [block(*hr, e), block(*hi, e)];
            }
            k = (k + 1) & mask;
        }
        // Stage h = 1: twiddle 1, no multiply.
        for q in grid.as_chunks_mut::<2>().0 {
            let ([ar, ai], [br, bi]) = (q[0], q[1]);
            *q = [
                [ar.wrapping_add(br), ai.wrapping_add(bi)],
                [ar.wrapping_sub(br), ai.wrapping_sub(bi)],
            ];
        }
        let tw = self.twiddle.as_chunks::<2>().0;
        // Stage with half-size h uses e^{2πik/(2h)} = W[k·L/(2h)]: stride L/(2h), halved
        // per stage (shifts, not a division: no divide-by-zero branch in the no-panic link).
        let (mut h, mut stride) = (2, l >> 2);
        while h < l {
            let Some(size) = core::num::NonZeroUsize::new(2 * h) else {
                break;
            };
            for block in grid.chunks_exact_mut(size.get()) {
                let Some((a, b)) = block.split_at_mut_checked(h) else {
                    break;
                };
                for (k, (a, b)) in a.iter_mut().zip(b.iter_mut()).enumerate() {
                    let [br, bi] = *b;
                    let (tr, ti) = if k == 0 {
                        (br, bi)
                    } else if 2 * k == h {
                        (bi.wrapping_neg(), br) // w = i, exact
                    } else if let Some([wr, wi]) = tw.get(k * stride) {
                        cmul_q15(br, bi, i32::from(wr.to_bits()), i32::from(wi.to_bits()))
                    } else {
                        (0, 0)
                    };
                    let [ar, ai] = *a;
                    *a = [ar.wrapping_add(tr), ai.wrapping_add(ti)];
                    *b = [ar.wrapping_sub(tr), ai.wrapping_sub(ti)];
                }
            }
            h *= 2;
            stride >>= 1;
        }
        for (x, g) in extra.iter_mut().zip(grid.as_flattened().iter()) {
            *x = *g;
        }
        e
    }
}

/// `round(h·2^−e)` (`e > 0`) or `h·2^−e` (`e ≤ 0`, exact within the block bound).
#[inline(always)]
fn block(h: i32, e: i32) -> i32 {
    if e > 0 {
        let k = e.min(62) as u32;
        ((i64::from(h) + (1i64 << (k - 1))) >> k) as i32
    } else {
        h.wrapping_shl((-e) as u32)
    }
}

/// The Gaussian diagonal `T(x_v, x_v)` or column `T(x_a, ·)` on the fixed-point lookup path:
/// `i64` complex accumulators (`2Kv`), LSB [`FixedConfig::diag_lsb`] (the band diagonal's).
/// Per row: `Ks` integer syntheses, then `Kv·Ks` O(1) integer reads (module docs).
#[derive(Debug)]
pub struct FixedLookupProbe<'m> {
    target: Target,
    voxels: &'m [Point],
    acc: &'m mut [i64],
    grid_buf: &'m mut [i32],
    lead: &'m mut [i32],
    rows: u32,
    g: FixedLookupGrid,
}

impl<'m> FixedLookupProbe<'m> {
    /// State length in `i64`: `2Kv`.
    pub const fn state_len(n_voxels: usize) -> usize {
        n_voxels.saturating_mul(2)
    }

    /// Scratch length in `i32`: `2(L + 3) + 2Kv` (one SPAD's grid; per voxel the lead distance
    /// and weight).
    pub const fn scratch_len(g: &FixedLookupGrid, n_voxels: usize) -> usize {
        (2 * (g.grid.len() + EXTRA)).saturating_add(n_voxels.saturating_mul(2))
    }

    /// A probe for `target` over `voxels` with zeroed `state`.
    ///
    /// # Errors
    /// [`ArgumentError::Length`] for a wrong `state` or `scratch` length; [`ArgumentError::NonFinite`] for a
    /// non-finite voxel or focus.
    pub fn new(
        lookup: &FixedLookup<'_>,
        target: Target,
        voxels: &'m [Point],
        state: &'m mut [i64],
        scratch: &'m mut [i32],
    ) -> Result<Self, ArgumentError> {
        let g = lookup.g;
        let kv = voxels.len();
        check_len("state", Self::state_len(kv), state.len())?;
        check_len("scratch", Self::scratch_len(&g, kv), scratch.len())?;
        check_points("voxels", voxels)?;
        if let Target::Column(a) = target {
            check_points("focus", &[a])?;
        }
        let (grid_buf, lead) = scratch
            .split_at_mut_checked(2 * (g.grid.len() + EXTRA))
            .ok_or(ArgumentError::Length {
                what: "scratch",
                expected: Self::scratch_len(&g, kv),
                found: 0,
            })?;
        state.fill(0);
        Ok(Self {
            target,
            voxels,
            acc: state,
            grid_buf,
            lead,
            rows: 0,
            g,
        })
    }

    /// Adds one row (guard interval as in the band path). Per-pair work is integer but for
    /// the `f32` distance, weight and phase (module docs); no panic, no allocation.
    ///
    /// # Errors
    /// [`ArgumentError::Incompatible`] if `lookup` or `scan` is not the probe's configuration, or
    /// past [`FixedLimits::max_rows`](crate::FixedLimits::max_rows); [`ArgumentError::Length`] for a
    /// row of another scan size. Nothing is changed then.
    pub fn push_row(
        &mut self,
        scan: &FixedScan<'_>,
        lookup: &FixedLookup<'_>,
        row: &FixedRow<'_>,
    ) -> Result<(), ArgumentError> {
        if !lookup.g.same(&self.g) || !same_fc(&scan.fc, &self.g.fc) {
            return Err(ArgumentError::Incompatible(
                "fixed lookup grid of another configuration",
            ));
        }
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
        let per_span = fc.two32_per_span as f32;
        let bits = self.g.bits;
        let mask = self.g.grid.len() - 1;
        let k_d = self.g.grid.carrier_bin() as i32 as u32;
        let d_w = fc.d_w;
        let inv = matches!(fc.cfg.weights(), Weights::Inv);
        let weight = |d: f32| {
            if inv {
                1.0 / if d > d_w { d } else { d_w }
            } else {
                1.0
            }
        };
        // The lead per voxel: (d_lv, w(d_lv)) on the diagonal, (d_la + d_av, w(d_la)) on a
        // column.
        let d_la = match self.target {
            Target::Diagonal => None,
            Target::Column(a) => Some((a, dist(&laser, &a))),
        };
        for ([d, w], v) in self.lead.as_chunks_mut::<2>().0.iter_mut().zip(self.voxels) {
            let (lead, w_lead) = match d_la {
                None => {
                    let d_lv = dist(&laser, v);
                    (d_lv, weight(d_lv))
                }
                Some((a, d_la)) => (d_la + dist(&a, v), weight(d_la)),
            };
            *d = lead.to_bits() as i32;
            *w = w_lead.to_bits() as i32;
        }
        for (s, sp) in scan.spads.iter().enumerate() {
            let Some(hg) = row.hg.get(2 * s * j..2 * (s + 1) * j) else {
                break;
            };
            let e = lookup.synthesise(hg, self.grid_buf);
            let sh = fc.ad + e;
            let off = row.offset(s);
            let y = self.grid_buf.as_chunks::<2>().0;
            for (([a_re, a_im], v), [d_lv, w_l]) in self
                .acc
                .as_chunks_mut::<2>()
                .0
                .iter_mut()
                .zip(self.voxels)
                .zip(self.lead.as_chunks::<2>().0)
            {
                let d_lv = f32::from_bits(*d_lv as u32);
                let d_vs = dist(v, sp);
                let tau = d_lv + d_vs;
                let rel = tau + off;
                if !(rel >= g_lo && rel <= g_hi) {
                    continue;
                }
                let (zr, zi) = read(y, phase(tau, per_span), bits, mask, k_d);
                let w = f32::from_bits(*w_l as u32) * weight(d_vs);
                *a_re = a_re.wrapping_add(scale32(zr, w, sh));
                *a_im = a_im.wrapping_add(scale32(zi, w, sh));
            }
        }
        self.rows += 1;
        Ok(())
    }

    /// Rows accumulated.
    pub const fn rows(&self) -> u32 {
        self.rows
    }

    /// The target.
    pub const fn target(&self) -> Target {
        self.target
    }

    /// The raw accumulators `[re, im]` per voxel (LSB [`FixedConfig::diag_lsb`]).
    pub fn raw(&self) -> &[i64] {
        self.acc
    }

    /// Intensities `T = |A|²` in counts² (`f64`, once).
    ///
    /// # Errors
    /// [`ArgumentError::Length`] if `out.len() ≠ Kv`.
    pub fn finish(&self, out: &mut [f64]) -> Result<(), ArgumentError> {
        check_len("out", self.voxels.len(), out.len())?;
        let lsb = self.g.fc.diag_lsb();
        for (o, [re, im]) in out.iter_mut().zip(self.acc.as_chunks::<2>().0) {
            let (re, im) = (*re as f64 * lsb, *im as f64 * lsb);
            *o = re * re + im * im;
        }
        Ok(())
    }
}

/// `⌊τ·2³²/NΔt⌋ mod 2³²` for `τ ≥ 0` (`f32` product; the `u64` cast saturates, a negative or
/// NaN `τ` gives 0).
#[inline(always)]
fn phase(tau: f32, per_span: f32) -> u32 {
    (tau * per_span) as u64 as u32
}

/// `Z(τ)` from one SPAD's grid `y` at the phase `φ` (module docs, steps 3–4), in grid LSB.
#[inline(always)]
fn read(y: &[[i32; 2]], phi: u32, bits: u32, mask: usize, k_d: u32) -> (i32, i32) {
    let i = phi.checked_shr(32 - bits).unwrap_or(0) as usize;
    let t16 = phi.wrapping_shl(bits) >> 16;
    let start = i.wrapping_sub(1) & mask;
    let Some(q) = y.get(start..).and_then(|q| q.first_chunk::<4>()) else {
        return (0, 0);
    };
    let w = lagrange4_q15(t16);
    let br = dot_q15([q[0][0], q[1][0], q[2][0], q[3][0]], w);
    let bi = dot_q15([q[0][1], q[1][1], q[2][1], q[3][1]], w);
    let (cr, ci) = cis_q15(k_d.wrapping_mul(phi));
    cmul_q15(br, bi, cr, ci)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lagrange_q15_error() {
        let mut worst = 0.0f64;
        for t16 in 0..65536u32 {
            let w = lagrange4_q15(t16);
            assert!((w.iter().sum::<i32>() - 32768).abs() <= 2);
            for frac in [0.0, 0.5, 0.999_999] {
                let t = (f64::from(t16) + frac) / 65536.0;
                let exact = [
                    -t * (1.0 - t) * (2.0 - t) / 6.0,
                    (1.0 + t) * (1.0 - t) * (2.0 - t) / 2.0,
                    (1.0 + t) * t * (2.0 - t) / 2.0,
                    -(1.0 + t) * t * (1.0 - t) / 6.0,
                ];
                for (q, e) in w.iter().zip(exact) {
                    worst = worst.max((f64::from(*q) / 32768.0 - e).abs());
                }
            }
        }
        assert!(worst <= LAGRANGE_Q15_ERR, "{}", worst * 32768.0);
        assert!(worst >= 0.5 / 32768.0, "teeth: {}", worst * 32768.0);
    }

    #[test]
    fn dot_and_cmul_round_exactly() {
        let mut x = 0x1234_5678u32;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x
        };
        for _ in 0..100_000 {
            let y = [0; 4].map(|_: i32| (next() as i32) >> 2); // |y| < 2³⁰
            let w = lagrange4_q15(next() & 0xffff);
            let exact: i64 = y
                .iter()
                .zip(w)
                .map(|(y, w)| i64::from(*y) * i64::from(w))
                .sum();
            assert_eq!(i64::from(dot_q15(y, w)), (exact + (1 << 14)) >> 15);
            let (ar, ai) = ((next() as i32) >> 2, (next() as i32) >> 2);
            let (wr, wi) = cis_q15(next());
            let (r, i) = cmul_q15(ar, ai, wr, wi);
            let er = i64::from(ar) * i64::from(wr) - i64::from(ai) * i64::from(wi);
            let ei = i64::from(ar) * i64::from(wi) + i64::from(ai) * i64::from(wr);
            assert_eq!(
                (i64::from(r), i64::from(i)),
                ((er + (1 << 14)) >> 15, (ei + (1 << 14)) >> 15)
            );
        }
    }

    #[test]
    fn scale32_rounds() {
        assert_eq!(scale32(1000, 0.5, 0), 500);
        assert_eq!(scale32(-3, 0.5, 0), -1);
        assert_eq!(scale32(7, 3.0, -1), 11);
        assert_eq!(scale32(5, 0.0, 0), 0);
        assert_eq!(scale32(1 << 30, 1.0, 20), 1 << 50);
    }
}
