//! High-level LTM probes over a capture, streamed row by row through the kernel and
//! multi-threaded with rayon.
//!
//! | call | computes | passes over the data |
//! |---|---|---|
//! | [`direct`] | diagonal `T(x_v, x_v)` over a volume (Eqs. 11–12) | 1 |
//! | [`column()`] | `T(x_a, ·)` with [`ColumnGate`] two-bounce (Eq. 14), higher-order (Eq. 18) or none, optionally restricted to a shell `r0 ≤ |x_a − x_b| < r1` | 1 |
//! | [`diagonal`] | the diagonal un-gated (Fig. 6) or under the late gate (Eq. 18) | 1 |
//! | [`indirect`] | in-focus indirect light (Eqs. 15–17): Γ from the diagonal, then `Σ_{a∈Γ} T(a, b)` over Γ-masked pairs with `r0 ≤ |x_a − x_b| < r1` (two-bounce, higher-order or un-gated columns) | 2 |
//! | [`Gamma`] | Γ = {I_d > ε·max I_d}: ε checked once, from a diagonal pass or a given direct-light volume | 1 or 0 |
//! | [`indirect_shells`] | pass 2 of [`indirect`] for several shells at once (near, middle, far) | 1 |
//! | [`matrix()`] | amplitudes `A(x_a, x_b)` for `x_a` in one voxel set, `x_b` in another (two-bounce) | 1 (more if the accumulators exceed the memory budget) |
//! | [`relight`] | `A_p(b) = Σ_a p_a A(x_a, b)`: the image under a weighted sum of projector foci | 1 (idem) |
//! | [`row()`] | `T(·, x_b)` streamed by laser rows (reciprocity without a transpose) | 1 |
//! | [`surface()`] | direct light on a plane fitted to it: the brightest depth per column, a weighted least-squares plane, the slab sampled on it, optional local contrast | 1 |
//! | [`partial::accumulate`] | direct, column, indirect (optionally leak-corrected) or the matrix over a part of the rows, kept as a [`Partial`] state that merges by addition and finishes elsewhere | 1 |
//! | [`DirectModel`], [`LeakCorrected`] | the capture's direct light removed before the off-diagonal probes (module `leak`: 3-vertex windows of Γ zeroed, or a one-bounce fit subtracted) | 1 to fit, then streamed |
//!
//! Threads: the diagonal and the higher-order column split the voxels into chunks, each with
//! its own kernel probe, and every row's band spectra (computed once) are pushed into all
//! chunks in parallel; factorised columns accumulate per row in one probe (cheap) and image
//! the voxels in parallel at the end; the indirect sum keeps one factorised column per focus
//! `a ∈ Γ`, pushed in parallel. Memory never grows with the number of laser rows.

mod column;
mod crop;
mod direct;
mod drive;
pub mod fast;
mod gamma;
mod gate;
mod indirect;
mod leak;
mod matrix;
mod output;
pub mod partial;
mod plan;
mod row;
mod surface;
pub mod synth;
mod wave;
pub mod window;

pub use crate::exec::{EvalPath, Exec};
pub use column::{Shell, check_column, check_focus, column, diagonal};
pub use crop::Crop;
pub use direct::direct;
pub use fast::aligned::{aligned_volume, suggested_volume, window_depths};
pub use fast::resample;
pub use gamma::{Gamma, gamma_mask};
pub use gate::ColumnGate;
pub use indirect::{
    IndirectOptions, IndirectOutput, PairSums, fit_over_gamma, fit_over_volume, indirect,
    indirect_over, indirect_shells,
};
pub use leak::{
    AUTO_ADJACENCY, BOUNDS_MARGIN, DirectModel, GateEnergy, IMAGE_HISTOGRAMS, LeakCorrected,
    LeakMethod, LeakOptions, MAX_FACETS, MAX_GROWN, MAX_SWEEPS, ModelOptions, ModelOutcome,
    SurfaceModel, cell_radius, model_of_capture,
};
pub use matrix::{
    MATRIX_BYTES_PER_ELEMENT, Matrix, Pattern, Relit, check_relight, matrix, relight,
};
pub use output::Output;
pub use partial::{Finished, Partial, Task};
pub use plan::fft_note;
pub use row::{check_row, row};
pub use surface::{
    PlaneFit, Surface, SurfaceOptions, fit_plane, local_contrast, sample_plane, surface,
};
pub use wave::{Wave, default_wavelength};
pub use window::{Coverage, WARN_FRACTION, window_coverage};
