//! The **lookup path**: the Gaussian-gated diagonal and column with an O(1) cost per
//! (voxel, SPAD) pair instead of the band path's `J`-term sum.
//!
//! Per laser row and per SPAD, the gated, filtered signal `Z_s(τ)` is synthesised **once** on
//! a fine time grid from the row's band spectrum `HG_s[j]` ([`Row::band`](crate::Row::band), gate weights and
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
//! `e^{2πiθt}` (`|θt| ≤ 1/8` turn) the small-phase polynomial
//! [`cis_small_turns`](crate::cis_small_turns). `Y_s` and
//! `C` are `L`-periodic (the band sum is `span`-periodic), so indices wrap with `& (L − 1)`.
//! The pair adds `w(d_vs)·Z_s(τ)` to its voxel's row sum (`Complex32`) when `τ + x_s` lies in
//! the guard interval [`Config::guard`](crate::Config::guard) (the same `f32` test as the band diagonal); once per
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
//! of at least 8 points per carrier wavelength λ) for
//! [`cis_small_turns`](crate::cis_small_turns). Summed over the
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
//! `lookup/slice.rs`), about 9× below the Lagrange bound `(3/128)·Σ_j Ĝ_j ω_j⁴` on the same
//! grid: the paper's setup meets 1e-5 with `L = 512` (η = 6.2e-6). [`LookupGrid::try_new`]
//! picks `L` with the bound of [`LookupParams::interpolant`].
//!
//! # Files
//!
//! | file | items |
//! |---|---|
//! | `grid.rs` | [`LookupParams`], [`Interpolant`] → [`LookupGrid`]: the grid length `L` chosen (or checked) against the bound `η` |
//! | `table.rs` | [`Lookup`]: the twiddle and carrier tables in caller memory, the inverse FFT synthesis of a baseband grid ([`Lookup::baseband`]) and its reader ([`GridReader`]) |
//! | `pair.rs` | the per-pair arithmetic every lookup path shares: [`lagrange4`] and the Newton square-root distance |
//! | `kahan.rs` | the accumulators both probes share: per voxel a Kahan-compensated `f32` complex sum in caller memory |
//! | `probe.rs` | [`LookupProbe`]: the Gaussian diagonal or column over a voxel list |
//! | `lattice.rs` | [`Lattice`] → [`SliceLayout`]: a structured slice's voxels and SPADs, validated |
//! | `slice.rs` | [`LookupSlice`]: the Gaussian diagonal or column over a structured slice, with the laser-independent part of every pair tabulated once |

pub(crate) mod grid;
pub(crate) mod kahan;
pub(crate) mod lattice;
pub(crate) mod pair;
pub(crate) mod probe;
pub(crate) mod slice;
pub(crate) mod table;

pub use grid::{Interpolant, LookupGrid, LookupParams};
pub use lattice::{Lattice, SliceLayout};
pub use pair::lagrange4;
pub use probe::LookupProbe;
pub use slice::LookupSlice;
pub use table::{GridReader, Lookup};
