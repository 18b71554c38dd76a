//! The planner: every choice of how a probe's voxel sums are evaluated is made here, once per
//! pass and before any row is read, and handed on as a decision ([`Choice`] of a diagonal; a
//! column's `(EvalPath, Option<Planar>)`). The algorithms — `direct` with its `confocal`, `cosine`
//! and `phasor_path` parts, the column imaging — carry the decision out and never choose. This
//! module owns the flop models, the memory plans that decide whether a path competes, the
//! refusals of forced paths that do not apply ([`EvalPath`]: the CLI's `--path`), and the notes
//! that say which path ran and which grid the FFT path would take.
//!
//! # Cost models
//!
//! Flops count a complex multiply-add as 8 and a complex FFT of `M` points as `5·M·log₂M`
//! (§B.8). `Kv` voxels, `Ks` SPADs per row (1 on paired and confocal scans), `R` laser rows,
//! `J` band bins, `N` the DFT period, `L` the lookup grid, `M = Mx·My` the wall plane's FFT
//! size, `S` slices (depths × polyphases), `T` entries of a phasor table.
//!
//! | path | flops | applies to | memory beyond the pass's tables and row buffers |
//! |---|---|---|---|
//! | band | `Kv·Ks·(14J + 60)` per row ([`band_flops`]) | any geometry, every gate | a kernel probe state per voxel chunk |
//! | lookup | per row `Ks·5L·log₂L + 76·Kv·Ks` on a SPAD grid ([`lookup_row_flops`]); per scan `R·(5L·log₂L + 76·Kv + 40N)` on paired and confocal scans ([`lookup_scan_flops`]) | the Gaussian diagonal, any geometry | the grid's carrier and FFT plan, per thread a scratch (`L` spectrum, `Ks·(L + 8)` tables) and `Kv` accumulators ([`lookup_plan`]) |
//! | planar | per row `J·(F + S·(6M + 0.75F)) + 8·Kv·J`, `F = 5M·log₂M`; a column images once and adds `S·J·F` for its table ([`planar_flops`]) | a regular SPAD lattice and a wall-parallel voxel grid whose x–y pitch divides it (the diagonal, Gaussian-gated columns) | the kernel table `S·J·M` and per thread `3·J·M` scratch (complex `f32`) |
//! | confocal convolution | per scan `J·F/2 + S·J·(F + 12M) + S·F/2` ([`convolution_flops`]) | a confocal scan on a regular lattice, such a voxel grid | the wall spectra `J·M` (twice with transposed twins), a batch of rows, per worker `~5M` (complex `f32`) |
//! | resampled FFT | the FFT path's flops on the support grid plus `32·TAPS·(sx·ny + nx·ny)·nz` (`Resample::flops`) | a regular wall-parallel grid off the lattice whose resampling bound is at most [`resample::MAX_ERROR`](crate::probe::resample::MAX_ERROR) | the support grid's buffers (as above, over the support grid) and the resampling's intermediate and output (16 bytes per value) |
//! | phasor | per scan `R·Ks·(5N·log₂N + 5L·log₂L + 4T + 7.5·Kv)` ([`phasor_flops`]), counted [`PHASOR_COST`] times against the FFT paths | the Gaussian diagonal, any geometry (rows of any number of SPADs) | the tables of a batch of rows (16 bytes per entry) and per thread an FFT buffer of `N + L` complex `f32` ([`phasor_plan`]) |
//!
//! # When each is chosen
//!
//! A forced path ([`EvalPath::Band`], [`EvalPath::Planar`], [`EvalPath::Lookup`], [`EvalPath::Phasor`]) runs
//! where it applies and is refused in one line naming why where it does not (the planar path:
//! neither on the lattice nor resampled within the bound; the lookup and phasor paths for
//! columns; any fast path for the
//! un-gated and higher-order diagonals). Under [`EvalPath::Auto`] the diagonal ([`diagonal`])
//! takes, in this order:
//!
//! 1. the resampled FFT path, on a grid off the wall's lattice, when its buffers fit the budget
//!    and its flops are below the whole-scan flops of the cheapest rival (band; lookup where
//!    its plan fits; phasor × [`PHASOR_COST`] where it applies and fits);
//! 2. on a confocal or paired scan: the confocal convolution when it applies and is cheaper
//!    than those rivals, else the phasor path when it beats band (and lookup, where that
//!    fits), else the lookup when it fits and beats band, else band;
//! 3. on a SPAD grid: the planar convolution when it applies and is cheaper per row than the
//!    cheapest of band, lookup (where it fits) and phasor × [`PHASOR_COST`], else the phasor
//!    path when it beats band and lookup, else the lookup when it fits and beats band, else
//!    band.
//!
//! Under `cos` weights ([`cosine`]) only the lookup and band paths compute the per-leg
//! cosines: the lookup when it fits and costs fewer flops. A Gaussian-gated column ([`column`])
//! images by the planar convolution when it applies and costs less than the band sum's row,
//! else by the kernel; the un-gated and higher-order gates take the band path.
//!
//! Memory: a path whose plan does not fit the budget ([`crate::budget`]) does not compete
//! under [`EvalPath::Auto`]; forced, its plan's check names the largest buffer.
//!
//! Beside the choice: `cost` (the flop models of the band, lookup and phasor paths, their
//! memory plans and how they compare, `Rivals`) and `note` (the progress notes, the aligned
//! grid a probe reports, [`fft_note`]). The FFT paths' flop model and memory plan sit with
//! their choosers here: they need the engine's layout first.

mod cost;
mod note;

pub(super) use cost::{PHASOR_FEW_SPADS, phasor_batch};
pub use note::fft_note;

use super::fast::lattice::{self, Layout};
use super::fast::resample::Resample;
use super::fast::{Confocal, Phasor, Planar, confocal};
use super::gate::ColumnGate;
use crate::budget;
use crate::error::{Error, Result};
use crate::exec::EvalPath;
use crate::io::capture::Geometry;
use crate::volume::Volume;
use cost::*;
use note::diagonal_notes;
use vltm_kernel::{Config, Gate, Point};

// ---------------------------------------------------------------------------------------
// The FFT paths' flop model

/// What the planar convolution is used for (its cost differs).
#[derive(Clone, Copy, PartialEq, Eq)]
enum PlanarUse {
    /// Per row, for the diagonal.
    Diagonal,
    /// Once, to image a factorised column.
    Column,
}

/// Flops of the planar convolution of FFT size `(Mx, My)` over `slices` sub-grids of
/// `n_voxels` voxels: per row for the diagonal, once for a column's imaging.
fn planar_flops(
    (mx, my, slices): (usize, usize, usize),
    cfg: &Config,
    n_voxels: usize,
    usage: PlanarUse,
) -> f64 {
    let m = (mx * my) as f64;
    let j = cfg.bins() as f64;
    // Complex FFTs of M points, 5·M·log₂M (§B.8), pruned inverse ones about half that.
    let f = 5.0 * m * m.log2();
    let per_row = j * (f + slices as f64 * (6.0 * m + 0.75 * f)) + n_voxels as f64 * 8.0 * j;
    // The column images once; its table costs `slices·J` forward FFTs.
    match usage {
        PlanarUse::Diagonal => per_row,
        PlanarUse::Column => per_row + slices as f64 * j * f,
    }
}

/// Flops of the confocal convolution of FFT size `(Mx, My)` over `slices` sub-grids, per
/// scan: the forward transforms `J·F/2` and the image `S·J·(F + 12M) + S·F/2` (`F = 5M·log₂M`;
/// an upper bound, `fast::confocal`'s module docs).
fn convolution_flops((mx, my, slices): (usize, usize, usize), cfg: &Config) -> f64 {
    let m = (mx * my) as f64;
    let f = 5.0 * m * m.log2();
    let (j, s) = (cfg.bins() as f64, slices as f64);
    j * f / 2.0 + s * j * (f + 12.0 * m) + s * f / 2.0
}

// ---------------------------------------------------------------------------------------
// The diagonal's decision

/// The FFT engine of a resampled volume: the planar convolution per row, or the confocal one.
pub(super) enum Engine {
    Planar(Box<Planar>),
    Confocal(Box<Confocal>),
}

/// How the diagonal is evaluated: the planner's decision, carried out by `direct`.
pub(super) enum Diagonal {
    /// The FFT path on a support grid, resampled to the volume.
    Resampled(Box<Resample>, Engine),
    /// The planar convolution per row over a SPAD grid.
    Planar(Box<Planar>),
    /// The confocal convolution over the scanned wall grid.
    Convolution(Box<Confocal>),
    /// The phasor path, with what it holds.
    Phasor(Box<Phasor>, budget::Plan),
    /// The baseband lookup, with what it holds.
    Lookup(budget::Plan),
    /// The kernel's band sum.
    Band,
    /// Under the wall cosines: the lookup (with what it holds) or the band sum (`None`).
    Cosine(Option<budget::Plan>),
}

impl Diagonal {
    /// The path reported for this decision (the convolutions and the resampled FFT path are
    /// [`EvalPath::Planar`]).
    fn path(&self) -> EvalPath {
        match self {
            Self::Resampled(..) | Self::Planar(_) | Self::Convolution(_) => EvalPath::Planar,
            Self::Phasor(..) => EvalPath::Phasor,
            Self::Lookup(_) | Self::Cosine(Some(_)) => EvalPath::Lookup,
            Self::Band | Self::Cosine(None) => EvalPath::Band,
        }
    }
}

/// The planner's decision for a diagonal pass: how it is evaluated, the path reported, the
/// pass's progress note and the aligned grid the probe reports
/// ([`crate::probe::Output::aligned`]).
pub(super) struct Choice {
    pub(super) how: Diagonal,
    pub(super) path: EvalPath,
    pub(super) note: String,
    pub(super) aligned: Option<String>,
}

impl Choice {
    /// `how` with its path and notes (the resampled FFT path's support grid, the `cos`
    /// weights, or the grid the FFT path would take).
    fn new(how: Diagonal, g: &Geometry, volume: &Volume, cfg: &Config) -> Self {
        let path = how.path();
        let support = match &how {
            Diagonal::Resampled(rs, _) => Some(rs.support_spec()),
            _ => None,
        };
        let cosine = matches!(how, Diagonal::Cosine(_));
        let (note, aligned) = diagonal_notes(g, volume, cfg.wavelength(), path, support, cosine);
        Self {
            how,
            path,
            note,
            aligned,
        }
    }
}

/// The diagonal's path over `volume` of the (cropped) capture `g` under distance weights
/// (module docs: the order of the choice), after the pass's own buffers are checked against
/// the budget.
///
/// # Errors
/// [`Error::Memory`] naming the pass when its tables, row buffers and accumulators do not fit
/// the budget; [`Error::Argument`] (`path`) naming why a forced path does not apply;
/// [`Error::Memory`] when the forced resampled FFT path's buffers do not fit the budget.
pub(super) fn diagonal(
    g: &Geometry,
    cfg: &Config,
    volume: &Volume,
    path: EvalPath,
) -> Result<Choice> {
    let pass = direct_pass(g, cfg, volume.len())?;
    let how = diagonal_path(&pass, g, cfg, volume, path)?;
    Ok(Choice::new(how, g, volume, cfg))
}

/// [`diagonal`]'s path. The exact FFT path is built first: off the wall's lattice it fails at
/// once (its layout), and only then is the resampled FFT path weighed (on the lattice it never
/// applies).
fn diagonal_path(
    pass: &budget::Plan,
    g: &Geometry,
    cfg: &Config,
    volume: &Volume,
    path: EvalPath,
) -> Result<Diagonal> {
    let r = Rivals::new(pass, g, cfg, volume.len(), path)?;
    // The confocal convolution of a confocal scan, the planar one over a SPAD grid: their
    // layout first (the engine is built only if it is chosen).
    let exact = if g.confocal {
        convolution_layout(g, cfg, volume, path)
    } else {
        planar_layout(&g.spads, cfg, volume, path)
    };
    // Off the wall's lattice: the FFT path on a support grid, resampled.
    if let Some(Err(why)) = &exact
        && let Some((rs, engine)) = resampled(g, cfg, volume, path, r.resampled, why)?
    {
        return Ok(Diagonal::Resampled(Box::new(rs), engine));
    }
    if g.confocal {
        if let Some(c) = decide_convolution(exact, cfg, path, r.fft)? {
            return Ok(Diagonal::Convolution(Box::new(c)));
        }
    } else {
        let n = volume.len();
        if let Some(p) = decide_planar(exact, cfg, n, path, PlanarUse::Diagonal, r.fft)? {
            return Ok(Diagonal::Planar(Box::new(p)));
        }
    }
    if let Some((p, plan)) = r
        .phasor
        .filter(|_| path == EvalPath::Phasor || r.phasor_wins)
    {
        return Ok(Diagonal::Phasor(Box::new(p), plan));
    }
    if path == EvalPath::Lookup || (path == EvalPath::Auto && r.lookup_wins) {
        return Ok(Diagonal::Lookup(r.lookup));
    }
    Ok(Diagonal::Band)
}

/// Refuses `cos` weights where no path computes them: a scan with a SPAD grid, or a forced
/// FFT or phasor path.
///
/// # Errors
/// [`Error::Argument`] (`weights` or `path`) with one line that says why.
pub(super) fn check_cosine(g: &Geometry, path: EvalPath) -> Result<()> {
    if !g.confocal {
        return Err(Error::arg(
            "weights",
            "`cos` weights need one SPAD per row (a paired or confocal scan): over a SPAD grid \
             the sum over SPADs runs inside the kernel, where the per-SPAD cosine does not fit \
             (use `inv` or `one`)",
        ));
    }
    if path == EvalPath::Phasor {
        return Err(Error::arg(
            "path",
            "the phasor path does not take `$weights cos` (the wall cosines per leg are not in \
             its lane loop; the band and lookup paths compute them)",
        ));
    }
    if path == EvalPath::Planar {
        return Err(Error::arg(
            "path",
            "the planar FFT path does not apply: `$weights cos` multiplies each leg by the \
             cosine at its own wall point, which the convolution's distance-only kernel \
             cannot (the band and lookup paths compute it)",
        ));
    }
    Ok(())
}

/// The diagonal's path under the wall cosines ([`Diagonal::Cosine`]): the lookup when forced
/// or, under [`EvalPath::Auto`], when it fits the budget and costs fewer flops than the band sum.
///
/// # Errors
/// As [`check_cosine`].
pub(super) fn cosine(
    g: &Geometry,
    cfg: &Config,
    volume: &Volume,
    path: EvalPath,
) -> Result<Choice> {
    check_cosine(g, path)?;
    let n = volume.len();
    let pass = direct_pass(g, cfg, n)?;
    let lookup = lookup_plan(&pass, g, cfg, n);
    let band = band_total(g, cfg, n);
    let lookup_cost = lookup_scan_flops(g, cfg, n);
    let use_lookup =
        path == EvalPath::Lookup || (path == EvalPath::Auto && lookup_cost < band && lookup.fits());
    let how = Diagonal::Cosine(use_lookup.then_some(lookup));
    Ok(Choice::new(how, g, volume, cfg))
}

/// Refuses the forced planar path with why the exact FFT path does not apply (`why`); under
/// another path nothing.
fn refuse_fft(why: String, path: EvalPath) -> Result<()> {
    if path == EvalPath::Planar {
        return Err(Error::arg(
            "path",
            format!("the planar FFT path does not apply: {why}"),
        ));
    }
    Ok(())
}

/// The planar convolution for this probe, if `path` allows it, it applies and (for
/// [`EvalPath::Auto`]) it costs fewer flops than `rival`, the cheapest other path (by the cost
/// model, per row for the diagonal, once for a column's imaging). `spads`: the SPAD spots.
fn planar(
    spads: &[Point],
    cfg: &Config,
    volume: &Volume,
    path: EvalPath,
    usage: PlanarUse,
    rival: f64,
) -> Result<Option<Planar>> {
    let lay = planar_layout(spads, cfg, volume, path);
    decide_planar(lay, cfg, volume.len(), path, usage, rival)
}

/// [`planar`]'s layout of the SPADs and `volume` (lattice tolerance `1e-5·λ`), or why it does
/// not apply; `None` when `path` excludes it.
fn planar_layout(
    spads: &[Point],
    cfg: &Config,
    volume: &Volume,
    path: EvalPath,
) -> Option<Result<Layout, String>> {
    if matches!(path, EvalPath::Band | EvalPath::Lookup | EvalPath::Phasor) {
        return None;
    }
    Some(if volume.axes.is_none() {
        Err("the volume is a point list, not a grid".to_string())
    } else {
        lattice::layout(spads, &volume.points, volume.shape, 1e-5 * cfg.wavelength())
    })
}

/// [`planar`]'s decision on the layout `lay` ([`planar_layout`]) over `n_voxels`: the
/// convolution built when it is forced or costs less than `rival`.
///
/// # Errors
/// [`Error::Argument`] (`path`) when the planar path is forced and does not apply.
fn decide_planar(
    lay: Option<Result<Layout, String>>,
    cfg: &Config,
    n_voxels: usize,
    path: EvalPath,
    usage: PlanarUse,
    rival: f64,
) -> Result<Option<Planar>> {
    let lay = match lay {
        None => return Ok(None),
        Some(Err(e)) => return refuse_fft(e, path).map(|()| None),
        Some(Ok(lay)) => lay,
    };
    if path != EvalPath::Planar && planar_flops(lay.size(), cfg, n_voxels, usage) >= rival {
        return Ok(None);
    }
    match Planar::with_layout(cfg, lay) {
        Ok(p) => Ok(Some(p)),
        Err(e) => refuse_fft(e, path).map(|()| None),
    }
}

/// The confocal convolution's layout of the scanned wall points and `volume`, or why it does
/// not apply; `None` when `path` excludes it.
fn convolution_layout(
    g: &Geometry,
    cfg: &Config,
    volume: &Volume,
    path: EvalPath,
) -> Option<Result<Layout, String>> {
    if matches!(path, EvalPath::Band | EvalPath::Lookup | EvalPath::Phasor) {
        return None;
    }
    Some(if g.paired_apart() {
        Err(
            "it needs the laser and SPAD at the same wall point (a confocal scan); this paired \
             scan has them apart, so each row's path is not a function of one wall point"
                .to_string(),
        )
    } else if volume.axes.is_none() {
        Err("the volume is a point list, not a grid".to_string())
    } else {
        lattice::layout(
            &g.lasers,
            &volume.points,
            volume.shape,
            1e-5 * cfg.wavelength(),
        )
    })
}

/// The confocal convolution on the layout `lay` ([`convolution_layout`]), built if it applies
/// and is forced or (for [`EvalPath::Auto`]) costs fewer flops than `rival` (the cheapest
/// other path, whole scan).
///
/// # Errors
/// [`Error::Argument`] (`path`) when the planar path is forced and does not apply.
fn decide_convolution(
    lay: Option<Result<Layout, String>>,
    cfg: &Config,
    path: EvalPath,
    rival: f64,
) -> Result<Option<Confocal>> {
    let lay = match lay {
        None => return Ok(None),
        Some(Err(e)) => return refuse_fft(e, path).map(|()| None),
        Some(Ok(lay)) => lay,
    };
    if path != EvalPath::Planar && convolution_flops(lay.size(), cfg) >= rival {
        return Ok(None);
    }
    match Confocal::with_layout(cfg, lay) {
        Ok(c) => Ok(Some(c)),
        Err(e) => refuse_fft(e, path).map(|()| None),
    }
}

/// The resampled FFT path ([`crate::probe::resample`]) for `volume`: `None` when it is not the
/// one to take — a forced band, lookup or phasor path, a point list, a paired scan or, under
/// [`EvalPath::Auto`], when resampling does not apply, its buffers do not fit the budget or it
/// costs more than `rival` (flops of the whole scan). Called only for a volume off the wall's
/// lattice: `exact` says why the exact FFT path does not lay it out.
///
/// # Errors
/// With the planar path forced: [`Error::Argument`] (`path`) naming why neither the exact nor
/// the resampled FFT path applies; [`Error::Memory`] naming the largest buffer when the
/// support grid's do not fit the budget.
fn resampled(
    g: &Geometry,
    cfg: &Config,
    volume: &Volume,
    path: EvalPath,
    rival: f64,
    exact: &str,
) -> Result<Option<(Resample, Engine)>> {
    // A paired scan (laser and SPAD apart) has no FFT path, exact or resampled: the
    // confocal path's choice names why.
    if matches!(path, EvalPath::Band | EvalPath::Lookup | EvalPath::Phasor)
        || volume.axes.is_none()
        || g.paired_apart()
    {
        return Ok(None);
    }
    let _t = crate::timings::section("planning: FFT path", crate::timings::Kind::Serial);
    let wall = if g.confocal { &g.lasers } else { &g.spads };
    let tol = 1e-5 * cfg.wavelength();
    let forced = path == EvalPath::Planar;
    let fail = |why: String| -> Result<Option<(Resample, Engine)>> {
        if forced {
            Err(Error::arg(
                "path",
                format!(
                    "the planar FFT path does not apply: {exact}; nor on a resampled grid: {why}"
                ),
            ))
        } else {
            Ok(None)
        }
    };
    let rs = match Resample::new(g, cfg, volume) {
        Ok(r) => r,
        Err(e) => return fail(e),
    };
    let sup = &rs.support;
    let lay = match lattice::layout(wall, &sup.points, sup.shape, tol) {
        Ok(l) => l,
        Err(e) => return fail(e),
    };
    let (mx, my, slices) = lay.size();
    let (m, j) = (mx * my, cfg.bins());
    let threads = rayon::current_num_threads().max(1);
    let [sx, sy, nz] = sup.shape;
    let mut plan = budget::Plan::new();
    if g.confocal {
        // Twice with transposed twins (the wall spectra and their transpose).
        let copies = if confocal::twins(&lay, 1e-6 * cfg.wavelength())
            .iter()
            .any(Option::is_some)
        {
            2
        } else {
            1
        };
        plan.add(
            format!("the support grid's wall spectra ({copies} × {j} × {mx} × {my} complex f32)"),
            budget::bytes(j, 8 * copies).saturating_mul(m as u128),
        )
        .add(
            format!("the support grid's amplitudes ({sx} × {sy} × {nz})"),
            budget::bytes(sup.len(), 16),
        );
    } else {
        plan.add(
            format!("the support grid's kernel table ({slices} × {j} × {mx} × {my} complex f32)"),
            budget::bytes(slices, 8)
                .saturating_mul(j as u128)
                .saturating_mul(m as u128),
        )
        .add(
            format!("{threads} planar scratch buffers (3 × {j} × {mx} × {my} complex f32 each)"),
            budget::bytes(threads, 24)
                .saturating_mul(j as u128)
                .saturating_mul(m as u128),
        )
        .add(
            format!("{threads} support-grid accumulators ({sx} × {sy} × {nz} each)"),
            budget::bytes(threads, 16).saturating_mul(sup.len() as u128),
        );
    }
    plan.add(
        "the resampling's intermediate and output",
        budget::bytes(sx * volume.shape[1] * nz + volume.len(), 16),
    );
    if let Err(e) = plan.check(|| {
        format!(
            "direct light on the FFT path over the support grid {} (resampled to the volume)",
            rs.support_spec()
        )
    }) {
        return if forced { Err(e) } else { Ok(None) };
    }
    let engine = if g.confocal {
        if !forced && convolution_flops(lay.size(), cfg) + rs.flops() >= rival {
            return Ok(None);
        }
        match Confocal::with_layout(cfg, lay) {
            Ok(c) => Engine::Confocal(Box::new(c)),
            Err(e) => return fail(e),
        }
    } else {
        let rows = g.lasers.len() as f64;
        let cost = planar_flops((mx, my, slices), cfg, sup.len(), PlanarUse::Diagonal) * rows;
        if !forced && cost + rs.flops() >= rival {
            return Ok(None);
        }
        match Planar::with_layout(cfg, lay) {
            Ok(p) => Engine::Planar(Box::new(p)),
            Err(e) => return fail(e),
        }
    };
    Ok(Some((rs, engine)))
}

// ---------------------------------------------------------------------------------------
// Columns and the other gates

/// Refuses an evaluation path that cannot image a column with `gate`.
///
/// # Errors
/// [`Error::Argument`] (`path`): the lookup and phasor paths (diagonal only), the planar path
/// for the un-gated and higher-order gates.
pub(super) fn check_column(path: EvalPath, gate: ColumnGate) -> Result<()> {
    match (path, gate) {
        (EvalPath::Lookup | EvalPath::Phasor, _) => Err(Error::arg(
            "path",
            format!(
                "the {} path evaluates the diagonal only (use auto, band or planar for columns)",
                path.name()
            ),
        )),
        (EvalPath::Planar, ColumnGate::HigherOrder | ColumnGate::None) => Err(Error::arg(
            "path",
            "the planar path images Gaussian-gated (two-bounce) columns only (use auto or band)",
        )),
        _ => Ok(()),
    }
}

/// The path of the un-gated and higher-order diagonals: the band sum.
///
/// # Errors
/// [`Error::Argument`] (`path`) when another path is forced.
pub(super) fn other_gates(path: EvalPath) -> Result<EvalPath> {
    if !matches!(path, EvalPath::Auto | EvalPath::Band) {
        return Err(Error::arg(
            "path",
            "the un-gated and higher-order diagonals are evaluated on the band path only",
        ));
    }
    Ok(EvalPath::Band)
}

/// The imaging path of a factorised column with kernel gate `gate`, decided before its pass:
/// the planar convolution (when [`column_imaging`] takes it), the band sum, or — `defer`red
/// under [`EvalPath::Auto`], for parts of a split scan that leave it to the merged state —
/// [`EvalPath::Auto`], decided by [`column_imaging`] when the column is imaged. Building the
/// planar tables costs about as much as imaging.
///
/// # Errors
/// As [`column_imaging`].
pub(super) fn column(
    spads: &[Point],
    cfg: &Config,
    volume: &Volume,
    path: EvalPath,
    gate: Gate,
    defer: bool,
) -> Result<(EvalPath, Option<Planar>)> {
    let decide = gate == Gate::Gaussian && !(defer && path == EvalPath::Auto);
    let planar = if decide {
        column_imaging(spads, cfg, volume, path, gate)?
    } else {
        None
    };
    let path = if planar.is_some() {
        EvalPath::Planar
    } else if decide || gate != Gate::Gaussian {
        EvalPath::Band
    } else {
        EvalPath::Auto
    };
    Ok((path, planar))
}

/// The planar convolution that images a column with kernel gate `gate` over `volume`
/// (`spads`: the SPAD grid) when `path` is [`EvalPath::Planar`] or [`EvalPath::Auto`], the gate is the
/// Gaussian one, the convolution applies and (for [`EvalPath::Auto`]) it costs fewer flops than
/// the band sum's row; `None`: the kernel images it.
///
/// # Errors
/// [`Error::Argument`] (`path`) when the planar path is forced and does not apply.
pub(super) fn column_imaging(
    spads: &[Point],
    cfg: &Config,
    volume: &Volume,
    path: EvalPath,
    gate: Gate,
) -> Result<Option<Planar>> {
    if !matches!(path, EvalPath::Planar | EvalPath::Auto) || gate != Gate::Gaussian {
        return Ok(None);
    }
    let rival = band_row_flops(spads.len(), cfg, volume.len());
    planar(spads, cfg, volume, path, PlanarUse::Column, rival)
}
