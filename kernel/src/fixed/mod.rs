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
//!   rows beyond [`FixedLimits::max_rows`] ([`ArgumentError::Incompatible`]) and scans with more than
//!   [`FixedLimits::max_spads`] SPADs ([`ArgumentError::Length`]). The additions are written
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
//! # Lookup path
//!
//! [`FixedLookupProbe`] images the diagonal or a column from the same [`FixedRow`]s at O(1)
//! per (voxel, SPAD) pair: a block-exponent `i32` inverse FFT per SPAD, an integer grid
//! index, Q15 cubic weights and the NCO carrier, into accumulators of the diagonal's LSB
//! [`FixedConfig::diag_lsb`] within the same headroom budget (module `lookup`'s docs derive
//! its error bound).
//!
//! Not in fixed point (use the float path): the un-gated and higher-order gates, `f32`
//! histograms.

mod arith;
mod column;
mod config;
mod diagonal;
mod lookup;
mod nco;
mod photons;
mod row;
mod scan;

pub use column::FixedColumn;
pub use config::{FixedConfig, FixedLimits};
pub use diagonal::FixedDiagonal;
pub use lookup::{FixedLookup, FixedLookupGrid, FixedLookupProbe, LAGRANGE_Q15_ERR, lagrange4_q15};
pub use nco::{CIS_ERR, cis_q15};
pub use photons::FixedPhotons;
pub use row::{FixedRow, FixedRowBuffer};
pub use scan::FixedScan;
