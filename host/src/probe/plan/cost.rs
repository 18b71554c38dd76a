//! What each path costs and holds: the flop models (units in the planner's docs) and the
//! memory plans that decide whether a path competes.

use crate::budget;
use crate::error::Result;
use crate::exec::EvalPath;
use crate::io::capture::Geometry;
use crate::probe::drive::{pass_name, pass_plan};
use crate::probe::fast::{LookupDiagonal, Phasor, phasor};
use vltm_kernel::Config;

// ---------------------------------------------------------------------------------------
// Flop models

/// Flops per row of the kernel's band sum over `n_voxels` (`Kv·Ks·(14J + E0)`).
pub(super) fn band_flops(g: &Geometry, cfg: &Config, n_voxels: usize) -> f64 {
    band_row_flops(g.spads_per_row(), cfg, n_voxels)
}

/// [`band_flops`] of a row of `ks` SPADs.
pub(super) fn band_row_flops(ks: usize, cfg: &Config, n_voxels: usize) -> f64 {
    n_voxels as f64 * ks as f64 * (14.0 * cfg.bins() as f64 + 60.0)
}

/// The whole-scan flops of the band path on a paired or confocal capture.
pub(super) fn band_total(g: &Geometry, cfg: &Config, n_voxels: usize) -> f64 {
    band_flops(g, cfg, n_voxels) * g.lasers.len() as f64
}

/// Flops of the lookup diagonal per row: one complex inverse FFT per SPAD, then `E0 + 16`
/// flops per (voxel, SPAD) (§B.8).
pub(super) fn lookup_row_flops(g: &Geometry, cfg: &Config, n_voxels: usize) -> f64 {
    let l = LookupDiagonal::plan_len(cfg) as f64;
    let ks = g.spads_per_row() as f64;
    ks * 5.0 * l * l.log2() + n_voxels as f64 * ks * 76.0
}

/// Flops of the whole scan on the lookup path of a paired or confocal capture (one inverse
/// FFT of the grid per row, then `E0 + 16` per voxel), plus the per-row `Scan` (2N twiddles).
pub(super) fn lookup_scan_flops(g: &Geometry, cfg: &Config, n_voxels: usize) -> f64 {
    let l = LookupDiagonal::plan_len(cfg) as f64;
    let rows = g.lasers.len() as f64;
    rows * (5.0 * l * l.log2() + n_voxels as f64 * 76.0 + 40.0 * cfg.n_fft() as f64)
}

/// Flops of the phasor path over the whole scan: per histogram a forward FFT of N and an
/// inverse one of L, the table, then ~30 operations per (voxel, histogram) (8 voxels per
/// vector: counted as 30/4 against the other paths' scalar flops).
pub(super) fn phasor_flops(g: &Geometry, cfg: &Config, ph: &phasor::Sizes, n_voxels: usize) -> f64 {
    let hists = (g.lasers.len() * g.spads_per_row()) as f64;
    let (n, l) = (cfg.n_fft() as f64, ph.grid_len as f64);
    hists
        * (5.0 * n * n.log2()
            + 5.0 * l * l.log2()
            + 4.0 * ph.table_len as f64
            + n_voxels as f64 * 7.5)
}

/// How many of the FFT paths' model flops one nominal flop of the phasor path costs when the
/// two compete: its gathers and scalar table reads run at about a quarter of the FFT paths'
/// rate. Measured on the confocal exit sign (4,096 rows, 2 threads, 2026-11-29): nominal
/// 6.1e9 and 2.6e9 flops took 0.95 s and 0.42 s on this path, the confocal convolution's
/// 6.8e9 and 6.3e9 flops 0.26 s and 0.23 s; without the factor `auto` took the phasor path
/// there at 2–4× the time. Against the lookup and the band sum the nominal flops compare as
/// they are (the lookup's 76 flops per pair-voxel run at about a third of this path's rate,
/// so the phasor path wins there by more than its model says).
pub(super) const PHASOR_COST: f64 = 4.0;

// ---------------------------------------------------------------------------------------
// Memory plans

/// What a diagonal pass over `n_voxels` holds before its path's own buffers: the pass's
/// tables, row buffers and histograms (`pass`, [`pass_plan`]) and its accumulators.
fn direct_plan(pass: &budget::Plan, n_voxels: usize) -> budget::Plan {
    let mut plan = pass.clone();
    plan.add(
        "the states and outputs of direct light",
        budget::bytes(n_voxels, 32),
    );
    plan
}

/// What every diagonal pass over `n_voxels` of `g` holds at once before its path's own
/// buffers (`pass_plan`), checked against the budget: returned for the paths' plans.
///
/// # Errors
/// [`Error::Memory`] naming the pass, the DFT sizes and σ.
pub(super) fn direct_pass(g: &Geometry, cfg: &Config, n_voxels: usize) -> Result<budget::Plan> {
    let pass = pass_plan(g, cfg);
    direct_plan(&pass, n_voxels).check(|| pass_name(g, cfg, "direct light"))?;
    Ok(pass)
}

/// What the diagonal holds at once on the lookup path: the pass's tables and row buffers
/// (`pass`, [`direct_pass`]), its accumulators and the lookup's grid and per-thread scratch.
pub(super) fn lookup_plan(
    pass: &budget::Plan,
    g: &Geometry,
    cfg: &Config,
    n_voxels: usize,
) -> budget::Plan {
    let mut plan = direct_plan(pass, n_voxels);
    let threads = rayon::current_num_threads().max(1);
    LookupDiagonal::add_to_plan(cfg, g.spads_per_row(), n_voxels, threads, &mut plan);
    plan
}

/// Rows of at most this many SPADs (paired and confocal rows, SPAD lines) make a phasor batch
/// of 128 rows and add their `f32` partial sums once per batch; rows of more, once per row.
pub(crate) const PHASOR_FEW_SPADS: usize = 8;

/// Rows of `ks` SPADs per batch of the phasor path: its tables are built in parallel, then
/// every voxel tile sums the batch's rows in order into `f32` partial sums. 128 rows of up to
/// 8 SPADs (paired and confocal rows, SPAD lines); rows of more SPADs the same 1,024
/// histograms, at least one row (a 16 × 16 SPAD grid: 4 rows), so that the batch's tables
/// and its partial sums do not grow with the SPAD grid. The batch does not depend on the
/// number of threads, so neither do the sums.
pub(crate) fn phasor_batch(ks: usize) -> usize {
    (128 * PHASOR_FEW_SPADS / ks.max(PHASOR_FEW_SPADS)).max(1)
}

/// The phasor path's plan for `g` (its table for the default tolerance) and what it holds
/// at once; `Err` says why it does not apply.
pub(super) fn phasor_plan(
    pass: &budget::Plan,
    g: &Geometry,
    cfg: &Config,
    n_voxels: usize,
) -> Result<(Phasor, phasor::Sizes, budget::Plan)> {
    let ks = g.spads_per_row();
    let ph = Phasor::new(cfg, phasor::TOLERANCE)?;
    let sizes = ph.sizes();
    let threads = rayon::current_num_threads().max(1);
    let rows = phasor_batch(ks);
    let mut plan = pass.clone();
    plan.add(
        "the states and outputs of direct light",
        budget::bytes(n_voxels, 16 + 20),
    )
    .add(
        format!(
            "the phasor tables of {rows} rows × {ks} SPADs ({} entries of 16 bytes each)",
            budget::count(sizes.table_len as u128)
        ),
        budget::bytes(rows * ks, 16).saturating_mul(sizes.table_len as u128),
    )
    .add(
        format!("{threads} phasor FFT buffers (N + L complex f32 each)"),
        budget::bytes(threads, sizes.scratch_bytes as u128),
    );
    Ok((ph, sizes, plan))
}

// ---------------------------------------------------------------------------------------
// The rivals of the FFT paths

/// What the diagonal's paths other than the FFT ones cost and hold on a pass under distance
/// weights, and how they compare: the FFT paths compete against the cheapest of them, then
/// they against each other.
pub(super) struct Rivals {
    /// The phasor path's table and plan: when forced, or under [`EvalPath::Auto`] when it applies
    /// and fits the budget.
    pub(super) phasor: Option<(Phasor, budget::Plan)>,
    /// What the lookup path holds ([`lookup_plan`]): it competes only when that fits the
    /// budget (at large σ its carrier and tables grow with N; the band sum then runs in
    /// bounded memory).
    pub(super) lookup: budget::Plan,
    /// The flops the resampled FFT path must beat: the cheapest rival's over the whole scan
    /// (the phasor path's counted [`PHASOR_COST`] times).
    pub(super) resampled: f64,
    /// The flops the exact FFT path must beat: as [`Rivals::resampled`] for the confocal
    /// convolution, per row for the planar one.
    pub(super) fft: f64,
    /// Whether the phasor path costs less than the band sum and the lookup (where it fits).
    pub(super) phasor_wins: bool,
    /// Whether the lookup fits the budget and costs less than the band sum.
    pub(super) lookup_wins: bool,
}

impl Rivals {
    /// The rivals over `n_voxels` of the (cropped) capture `g` for `path`.
    ///
    /// # Errors
    /// A configuration the phasor table cannot meet its bound for, when the phasor path is
    /// forced ([`Phasor::new`]).
    pub(super) fn new(
        pass: &budget::Plan,
        g: &Geometry,
        cfg: &Config,
        n_voxels: usize,
        path: EvalPath,
    ) -> Result<Self> {
        // The phasor path: planned when forced (its errors name why it does not apply) or,
        // under `Auto`, when it applies and fits the budget.
        let planned = match path {
            EvalPath::Phasor => Some(phasor_plan(pass, g, cfg, n_voxels)?),
            EvalPath::Auto => phasor_plan(pass, g, cfg, n_voxels)
                .ok()
                .filter(|(_, _, plan)| plan.fits()),
            _ => None,
        };
        let ph = planned.as_ref().map_or(f64::INFINITY, |(_, sizes, _)| {
            phasor_flops(g, cfg, sizes, n_voxels)
        });
        let phasor = planned.map(|(p, _, plan)| (p, plan));
        let lookup = lookup_plan(pass, g, cfg, n_voxels);
        let fits = lookup.fits();
        if g.confocal {
            // Paired and confocal scans: whole-scan flops.
            let band = band_total(g, cfg, n_voxels);
            let lk = lookup_scan_flops(g, cfg, n_voxels);
            let rival = band.min(lk).min(PHASOR_COST * ph);
            return Ok(Self {
                phasor,
                lookup,
                resampled: rival,
                fft: rival,
                phasor_wins: ph < band && (ph < lk || !fits),
                lookup_wins: lk < band && fits,
            });
        }
        // A SPAD grid: flops per row.
        let rows = g.lasers.len() as f64;
        let band = band_flops(g, cfg, n_voxels);
        let lk = fits.then(|| lookup_row_flops(g, cfg, n_voxels));
        let rival = lk.map_or(band, |l| l.min(band));
        Ok(Self {
            phasor,
            lookup,
            resampled: (rival * rows).min(PHASOR_COST * ph),
            fft: rival.min(PHASOR_COST * ph / rows),
            phasor_wins: ph < rival * rows,
            lookup_wins: lk.is_some_and(|l| l < band),
        })
    }
}
