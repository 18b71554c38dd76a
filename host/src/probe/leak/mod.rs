//! Leak correction (beyond the paper): the capture's **direct** (3-vertex) light removed, row
//! by row, before the off-diagonal probes (by default in `vltm indirect`, `column`, `row`,
//! `relight` and `matrix` with `--volume`; `--no-leak-correct` skips it).
//!
//! # Why
//!
//! The 4-vertex gate of `T(x_a, x_b)` selects path times `|x_l−x_a| + |x_a−x_b| + |x_b−x_s|`.
//! For a focus `x_a` between the wall and a surface at `x_b`, that time is close to the
//! surface's own direct return `|x_l−x_b| + |x_b−x_s|` for many laser/SPAD pairs, so direct
//! light passes the gate — at 10–100× the true indirect light in the in-focus sum (Eq. 17).
//! Γ cannot mask it: it sits on the surface.
//!
//! # Model and assumptions
//!
//! The hidden surfaces that return direct light lie at the voxels of Γ (direct light above
//! ε·max): each voxel `v` is a point scatterer seen through the wall as the simulator's point
//! scatterers are (`sim`): path time `τ_lvs = d1_l + d_lv + d_vs + d4_s` (device legs as the
//! capture's time axis), amplitude `a_lvs = c_l·cos_l·cos_s / (d_lv² d_vs²)` (Lambertian wall,
//! `1/d²` per leg, isotropic at `v`; `c_l` the physical laser's `cos θ/d²` when the probes
//! compensate it, i.e. when the capture holds it). No occlusion, no inter-reflection.
//!
//! # Methods ([`LeakMethod`])
//!
//! * **Gate** (default): per (laser, SPAD), the bins where a 3-vertex return of any Γ voxel can
//!   arrive, `τ_lvs ± (r_cell + 3Δt)` (`r_cell` half a voxel's diagonal: a surface anywhere in
//!   the voxel's cell; 3Δt for the pulse and binning), are set to 0. Only the timing of the
//!   model is used, so it holds whatever the surface's reflectance, orientation or shape
//!   within its voxels. What is left: light arriving when no Γ voxel's direct return can —
//!   necessarily multi-bounce light, or direct light from surfaces outside Γ. What is lost:
//!   indirect light that arrives inside a window (measured: the corrected `I_i` keeps 0.53–0.59
//!   of the indirect-only truth `I_i(H − H_control)` with vltm's defaults, 0.10–0.19 with the
//!   paper's wider σ, small ε and r0 = 0, whose larger Γ covers more of the time axis).
//! * **Fit**: the scatterers' complex reflectances `ρ_v` at the carrier `ω0 = 2π/λ` (magnitude
//!   albedo·area/π, phase a path offset within ±λ/2) fitted so that the model reproduces the
//!   capture as the phasor gate sees it: every histogram demodulated and smoothed,
//!   `b_ls(t_c) = Σ_n H_ls[n] e^{−iω0 t_n} w(t_c − t_n)`, `w(x) = exp(−x²/2σ²)`, sampled every
//!   σ/2; `Σ |b − model|²` minimised by conjugate gradients on the normal equations
//!   ([`LeakOptions::iterations`] steps from 0), and the model's render subtracted: per
//!   (laser, SPAD, voxel) the wavelet `2·a·Re[ρ_v e^{iω0(t − τ)}]·g(t − τ)`, `g` a unit-sum
//!   Gaussian of σ_p = max(Δt, σ/10), whose demodulated envelope is the fitted model's (the
//!   fit uses σ_m² = σ² + σ_p²). Pairs whose `τ_lvs` lies outside the window are left out of
//!   fit and model. It keeps the indirect light but needs voxels finer than about λ/4 (a
//!   surface between two voxel centres must be reproducible at the carrier): 3.8× the control
//!   on the path-traced two_patches (pitch 0.1/0.05 m, λ = 0.4 m), but 1.01× on the 16×16 panel
//!   scene (pitch 0.06 m, λ = 0.133 m), where it explains only 83 % of the demodulated energy.
//!
//! * **The surface model** ([`model_of_capture`], module `synthesis`; `--leak-correct model`):
//!   not a [`LeakMethod`] but a source of its own. Planar surfaces read from the capture's
//!   direct-light image, refined against the capture and fitted by [`crate::probe::synth`];
//!   the probes run on the capture minus its render ([`crate::probe::synth::Synthesized`]),
//!   uncorrected. It keeps the indirect light in the direct light's bins; when it explains
//!   less than 99 % of the capture's energy (or cannot be built) the caller falls back to the
//!   gate ([`ModelOutcome::Unexplained`] says why).
//!
//! [`DirectModel::explained`] reports the fraction of the capture's energy `Σ H²` in the zeroed
//! windows (gate) or of the demodulated energy the model explains (fit).
//!
//! # Measured on path-traced captures: what leaks, and what the gate keeps
//!
//! On `fixtures/pathtraced` (mitransient 1.3.1, 8×8 lasers × 8×8 SPADs, 300 bins of 1 cm; per
//! scene three renders with the same seed: all paths, direct only, two hidden vertices only =
//! the indirect-only truth), volume `-0.75:0.75:16,-0.75:0.75:16,0.5:1.4:19`, vltm's defaults
//! (λ = 0.4 m, σ = 0.267 m, ε = 0.1, r0 = 0.4 m) plus `--compensate-laser` (off by default:
//! docs/indirect-light.md, "The laser falloff"), means over the
//! objects' voxels (`cargo bench --bench pathtraced -- diagnose`). Panel/figure scene (a
//! 0.6 × 0.9 m panel, 2 cm thick, facing the wall and a box figure): the gate gives the figure
//! 21.6× and the projector's own panel 8.1× their direct-only controls. The candidates:
//!
//! * **Direct light of surfaces outside Γ** (the cause of what is left on the panel). After the
//!   gate the direct-only control keeps 0.09 % of its energy (0.8 % of its counts), and all of
//!   it lies inside the panel's own direct time range: it comes from the panel's far half
//!   (x −0.25…−0.05 m, z 0.99–1.13 m), 0.25–0.32 m from the nearest Γ voxel, whose direct
//!   image is below ε·max. It is not the render's time response: the surface points whose
//!   returns miss every window lie a median 0.25 m (panel) and 0.10 m (figure) from the
//!   nearest Γ voxel, outside its cell (r_cell = 0.075 m).
//! * **Window width and the gate's reach.** The 4-vertex gate's envelope (σ = 0.267 m) spans
//!   ±0.8 m of path, so any such residual near a pair's time passes. Wider windows remove it
//!   and the indirect light with it: 2·r_cell gives 75×/36× (figure/panel) but keeps only
//!   0.08/0.10 of the truth; 4·r_cell 14 000×/7 500× and ≤ 0.01. ε = 0.03 (Γ 620 voxels, its
//!   windows cover the far half) gives 2 200×/900× and keeps 0.04/0.07, Pearson 0.62/0.46.
//! * **Pairs on the same flat surface.** With Γ cut to the panel for the pairs (the windows
//!   of the whole Γ), such pairs make 59 % of the panel's corrected control, 25 % of its
//!   corrected `I_i` and 0.2 % of its truth (a flat surface does not light itself); on the
//!   figure 9 %, 1 % and 0.06 %. r0 = 0.6 m instead of 0.4 m drops most of them: 25×/16×,
//!   kept 0.24, Pearson 0.84/0.93.
//! * **`--compensate-laser`**: without it Γ changes (321 voxels) and the ratios fall to
//!   5.0×/2.1× (kept 1.0/1.7, i.e. the corrected `I_i` holds other light than the truth's).
//! * **Thickness**: the 2 cm panel lies within one voxel (pitch 5 cm in depth); its edges
//!   return little; no measurable effect separate from the above.
//! * **Monte Carlo noise** (a second render with seed 1, the same 30 000 samples; the
//!   noise-only capture `(H_seed0 − H_seed1)/√2` through the same windows): 0.1–0.2 % of the
//!   corrected `I_i` on panel/figure (the two seeds' corrected `I_i` correlate at 0.999), the
//!   ratios 21.6×/8.1× at seed 0 and 19.8×/8.4× at seed 1. Not a cause there.
//!
//! The corner scene (two 0.5 × 0.6 m panels at 90°, each lighting the other) gives 19.2×
//! (the projector's panel) and 28.1× (the lit one), kept 0.18/0.25, Pearson 0.41/0.63;
//! same-surface pairs make 28 % of each panel's corrected control; windows 2·r_cell, ε = 0.03
//! and r0 = 0.6 m all lower kept and Pearson there (Pearson −0.04, 0.25, −0.07 over Γ). There
//! the noise is 5–7 % of the corrected `I_i` and 1.4× the corrected control: the ratios move to
//! 22.6×/21.2× and Pearson to 0.35/0.44 at seed 1 (noise enters `|·|²` through its cross term
//! with the signal, ≈ 2·√0.06 per voxel). The seed-0 Pearson is favoured because the truth
//! shares the full capture's seed.
//!
//! # Ceilings: what any window-based correction can reach
//!
//! The truth put through the same windows keeps only 0.18 (figure) and 0.20 (panel) of its own
//! `I_i` (0.13 and 0.14 on the corner), and its Pearson with the truth is 0.89/0.95 (figure/
//! panel) but only 0.67/0.68 on the corner. The corrected `I_i` correlates at 0.93–0.99 with this
//! windowed truth on every object, and the oracle subtraction `H_all − H_control` (no windows)
//! keeps 0.99–1.07 of the truth with Pearson ≥ 0.995, so the chain measures what it should and
//! the gap to the truth is the windows'. At this aperture (λ = 0.4 m) the two-bounce returns of
//! nearby surfaces arrive inside the direct windows of Γ: `kept ≥ 0.5` is out of reach on both
//! scenes, and Pearson ≥ 0.8 on the corner, whatever the window width (wider only lowers both).
//! On the corner, Γ (ε = 0.1) holds only the panels' wall-side halves (z 0.70–0.95 m), not the
//! apex, and within Γ the half nearer the other panel holds 3/4 of the truth but keeps only
//! 0.12–0.13 of it (0.16–0.17 on the farther half): the windows flatten the truth's gradient
//! toward the apex. The defaults are unchanged: the ratios reach 8–28× on every object of both
//! scenes, and no setting measured keeps more indirect light or correlates better on both
//! scenes (docs/indirect-light.md has the table; `cargo bench --bench pathtraced`).
//!
//! # Cost and memory
//!
//! Gate: one pass over the capture to measure the removed energy, then per row read `Ks·V`
//! window computations (`V = |Γ|`) and ≤ `2(r_cell + 3Δt)/Δt` bins zeroed each. Fit: one pass
//! for `Aᴴb`, then per iteration one application of `AᴴA` without the data:
//! `2·Kl·Ks·V·(2K + 1)` complex multiply-adds (`2K + 1 ≈ 17` coarse samples per return);
//! per row read, `Ks·V` wavelets of `≈ 8σ_p/Δt` bins. Memory: `8·V·Ks` bytes of voxel–SPAD
//! tables (fit), `V` complex values per thread, one row per thread; never the capture.

mod corrected;
mod energy;
mod fit;
mod model;
mod options;
mod synthesis;

pub use corrected::LeakCorrected;
pub use energy::GateEnergy;
pub use fit::DirectModel;
pub use options::{AUTO_ADJACENCY, LeakMethod, LeakOptions, cell_radius};
pub use synthesis::{
    BOUNDS_MARGIN, IMAGE_HISTOGRAMS, MAX_FACETS, MAX_GROWN, MAX_SWEEPS, ModelOptions, ModelOutcome,
    SurfaceModel, model_of_capture,
};
