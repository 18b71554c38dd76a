//! In-focus indirect light (Eqs. 15–17): Γ from the diagonal, then the Γ-masked sum of
//! columns over pairs in a distance shell — factorised two-bounce (Eq. 14) or un-gated
//! columns, or higher-order columns (Eq. 18: the paper's "≥ 3rd bounce" in focus, element-wise,
//! `Kb·Ks·(E0 + 7R)` per row and focus) — for one shell or several (near, middle, far) in
//! the same pass.

use super::column::*;
use super::crop::{Reach, with_crop};
use super::drive::*;
use super::gamma::Gamma;
use super::gate::ColumnGate;
use super::leak::{DirectModel, LeakCorrected, LeakOptions, cell_radius};
use super::output::check_finite;
use super::wave::*;
use crate::error::{Error, Result};
use crate::exec::{Exec, Pass};
use crate::io::capture::RowSource;
use crate::volume::Volume;
use rayon::prelude::*;
use std::time::Instant;
use vltm_kernel::geometry::dist;
use vltm_kernel::{Config, Gate, Point, Probe, Report, Scan, Target};

/// Options of the in-focus indirect sum.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IndirectOptions {
    /// Relative threshold ε: Γ = {v : I_d(v) > ε·max I_d} (default 0.1).
    pub epsilon: f32,
    /// Pair distances accumulated: `r0 ≤ |x_a − x_b| < r1`; `r0` default 1.5σ.
    pub shell: Option<Shell>,
    /// Largest accumulator memory accepted (bytes) (default 8 GiB).
    pub max_bytes: usize,
    /// The gate of the summed columns: two-bounce (Eq. 14, the default: first-order indirect
    /// light), higher-order (Eq. 18 with Eq. 17: the paper's "≥ 3rd bounce") or none.
    pub gate: ColumnGate,
    /// Remove the capture's fitted direct light before the columns (`--leak-correct`,
    /// [`DirectModel`]); `None` = the paper's Eq. 17 on the capture as it is.
    pub leak: Option<LeakOptions>,
}

impl Default for IndirectOptions {
    fn default() -> Self {
        Self {
            epsilon: 0.1,
            shell: None,
            max_bytes: 8 << 30,
            gate: ColumnGate::TwoBounce,
            leak: None,
        }
    }
}

/// Result of [`indirect`].
#[derive(Clone, Debug, PartialEq)]
pub struct IndirectOutput {
    /// In-focus indirect light `I_i(b)` (0 outside Γ).
    pub values: Vec<f32>,
    /// The direct light `I_d` of pass 1.
    pub direct: Vec<f32>,
    /// Γ membership per voxel.
    pub gamma: Vec<bool>,
    /// The pair shell used.
    pub shell: Shell,
    /// Counters of pass 2: its rows and samples, and the aliased pairs of every focus.
    pub report: Report,
    /// The configuration pass 2 ran on (the two-bounce gate's column configuration, whose
    /// band and DFT length cover every Γ pair; pass 1's diagonal may differ).
    pub config: Config,
    /// With leak correction: the fraction of the demodulated capture's energy the direct
    /// model explains ([`DirectModel::explained`]).
    pub explained: Option<f64>,
    /// Wall-clock seconds for both passes.
    pub seconds: f64,
}

/// In-focus indirect light (Eqs. 15–17): pass 1 the diagonal, Γ = {I_d > ε·max}, pass 2
/// one factorised column per `a ∈ Γ`, and `I_i(b) = Σ_{a∈Γ, a≠b, r0≤|a−b|<r1} T(a, b)` for
/// `b ∈ Γ`. Reads the source twice.
///
/// # Errors
/// ε out of range, Γ too large for `max_bytes`, configuration, read and kernel errors.
pub fn indirect(
    src: &mut dyn RowSource,
    volume: &Volume,
    opts: &IndirectOptions,
    wave: &Wave,
    exec: Exec<'_>,
) -> Result<IndirectOutput> {
    wave.refuse_cosine("`indirect`")?;
    let t = Instant::now();
    let (gamma, d) = Gamma::measure(src, volume, opts.epsilon, "epsilon", wave, exec)?;
    let mut out = indirect_over(src, volume, &gamma.mask, opts, wave, exec)?;
    out.direct = d.values;
    out.seconds = t.elapsed().as_secs_f64();
    Ok(out)
}

/// Pass 2 of [`indirect`] for a given Γ (e.g. from a direct-light image computed once and
/// reused for several captures, such as a scene and its direct-only control).
/// `IndirectOutput::direct` is left empty.
///
/// # Errors
/// Γ of the wrong length or too large for `max_bytes`, configuration, read and kernel errors.
pub fn indirect_over(
    src: &mut dyn RowSource,
    volume: &Volume,
    gamma: &[bool],
    opts: &IndirectOptions,
    wave: &Wave,
    exec: Exec<'_>,
) -> Result<IndirectOutput> {
    wave.refuse_cosine("`indirect`")?;
    let t = Instant::now();
    let mut p = pair_sums(src, volume, gamma, opts, None, wave, exec)?;
    let values = p.sums.pop().unwrap_or_default();
    check_finite(&values, &volume.points, "in-focus indirect light")?;
    Ok(IndirectOutput {
        values,
        direct: Vec::new(),
        gamma: gamma.to_vec(),
        shell: p.shell,
        report: p.report,
        config: p.config,
        explained: p.explained,
        seconds: t.elapsed().as_secs_f64(),
    })
}

/// Pass 2 of [`indirect`] for several pair shells at once (e.g. near, middle and far): one
/// pass over the capture, one sum `I(b) = Σ_{a∈Γ, a≠b, |a−b| ∈ shell} T(a, b)` per shell,
/// in the order of `shells` (`opts.shell` is ignored).
///
/// # Errors
/// As [`indirect_over`].
pub fn indirect_shells(
    src: &mut dyn RowSource,
    volume: &Volume,
    gamma: &[bool],
    opts: &IndirectOptions,
    shells: &[Shell],
    wave: &Wave,
    exec: Exec<'_>,
) -> Result<PairSums> {
    wave.refuse_cosine("`indirect`")?;
    pair_sums(src, volume, gamma, opts, Some(shells), wave, exec)
}

/// What pass 2 of the in-focus indirect sum computed.
#[derive(Clone, Debug, PartialEq)]
pub struct PairSums {
    /// The pair sums, one volume per shell.
    pub sums: Vec<Vec<f32>>,
    /// Counters of the pass: its rows and samples, and the aliased pairs of every focus.
    pub report: Report,
    /// The (last) shell.
    pub shell: Shell,
    /// With leak correction: the fraction of the capture's energy the direct model explained.
    pub explained: Option<f64>,
    /// The configuration the pass ran on.
    pub config: Config,
}

/// The Γ-masked pair sums of pass 2, one per shell (`shells`, or the single shell of `opts`
/// with its default r0 = 1.5σ), with the counters and the (last) shell.
fn pair_sums(
    src: &mut dyn RowSource,
    volume: &Volume,
    gamma: &[bool],
    opts: &IndirectOptions,
    shells: Option<&[Shell]>,
    wave: &Wave,
    exec: Exec<'_>,
) -> Result<PairSums> {
    if gamma.len() != volume.len() {
        return Err(Error::arg(
            "gamma",
            format!("expected {} flags, found {}", volume.len(), gamma.len()),
        ));
    }
    // The window rule on the volume's diagonal, as pass 1 (`direct`) applies it: the same
    // error when Γ comes from a file (pass 1 already warned otherwise).
    let base = wave.config(src.geometry())?;
    super::window::window_coverage(src.geometry(), &base, None, &volume.points, opts.gate)?;
    let idx: Vec<usize> = (0..gamma.len()).filter(|&i| gamma[i]).collect();
    let pts: Vec<Point> = idx.iter().map(|&i| volume.points[i]).collect();
    let kgate = match opts.gate {
        ColumnGate::TwoBounce => Gate::Gaussian,
        ColumnGate::HigherOrder => Gate::HigherOrder,
        ColumnGate::None => Gate::None,
    };
    let cfg = if kgate == Gate::Gaussian {
        wave.column_config(src.geometry(), &pts, &pts)?
    } else {
        wave.config(src.geometry())?
    };
    let default = Shell {
        r0: 1.5 * cfg.sigma() as f32,
        r1: f32::INFINITY,
    };
    let one = [opts.shell.unwrap_or(default)];
    let shells = shells.unwrap_or(&one);
    let mut values = vec![vec![0.0f32; volume.len()]; shells.len()];
    let mut report = Report::default();
    let mut explained = None;
    if idx.is_empty() && opts.leak.is_some() {
        return Err(Error::arg(
            "leak_correct",
            "Γ is empty: no voxel has direct light above ε·max (no direct return in the window for this volume?)",
        ));
    }
    if !idx.is_empty() {
        let ks = src.geometry().spads_per_row();
        let n_vox = if kgate == Gate::HigherOrder {
            idx.len()
        } else {
            0
        };
        let bytes =
            idx.len() * Probe::state_bytes(&cfg, Target::Column([0.0, 0.0, 1.0]), kgate, n_vox, ks);
        if bytes > opts.max_bytes {
            return Err(Error::arg(
                "epsilon",
                format!(
                    "Γ has {} voxels and needs {:.1} GB of accumulators; raise $epsilon",
                    idx.len(),
                    bytes as f64 / 1e9
                ),
            ));
        }
        let model = match &opts.leak {
            Some(lo) => Some(DirectModel::fit(
                src,
                &pts,
                cell_radius(volume),
                wave,
                lo,
                exec,
            )?),
            None => None,
        };
        explained = model.as_ref().map(|m| m.explained);
        let mut corrected;
        let src: &mut dyn RowSource = match &model {
            Some(m) => {
                corrected = LeakCorrected::new(src, m);
                &mut corrected
            }
            None => src,
        };
        // The time axis cropped to the Γ pairs' reach (not for the un-gated columns).
        let reach = Reach {
            foci: Some(&pts),
            voxels: &pts,
            late: kgate == Gate::HigherOrder,
        };
        let wave_crop = Wave {
            crop: wave.crop && kgate != Gate::None,
            ..*wave
        };
        let cols = with_crop(src, &wave_crop, exec, reach, |src, exec, _| {
            let cfg = if kgate == Gate::Gaussian {
                wave.column_config(src.geometry(), &pts, &pts)?
            } else {
                wave.config(src.geometry())?
            };
            let job = Job {
                cfg: &cfg,
                wave,
                exec,
            };
            if kgate == Gate::HigherOrder {
                higher_order_columns(src, job, &pts, "indirect")
            } else {
                let spads = src.geometry().spads.clone();
                factorised_columns(src, job, &pts, kgate, "indirect")?
                    .image(&cfg, &spads, &pts, kgate, &pts, exec, "indirect")
            }
        })?;
        report = summed_reports(&cols);
        let _t = crate::timings::section("pair sums", crate::timings::Kind::Parallel);
        let bar = Pass::start(exec, "indirect: pair sums", shells.len() * pts.len());
        let sums = shells
            .iter()
            .map(|sh| pair_sum(&cols, &pts, &bar, |ai, bi, d| ai != bi && sh.contains(d)))
            .collect::<Vec<_>>();
        drop(bar);
        for (v, sum) in values.iter_mut().zip(sums) {
            for (&i, s) in idx.iter().zip(sum) {
                v[i] = s as f32;
            }
        }
    }
    Ok(PairSums {
        sums: values,
        report,
        shell: shells[shells.len() - 1],
        explained,
        config: cfg,
    })
}

/// `Σ_a T(a, b)` per `b` over the pairs that `keep(a, b, |x_a − x_b|)` accepts, from one
/// imaged column per focus (`cols[a][b]`), in parallel over `b` (each sum in the order of
/// `a`, as a serial loop adds them: the same result for any thread count); each `b` summed
/// advances `bar` by one.
fn pair_sum(
    cols: &[(Vec<f64>, Report)],
    pts: &[Point],
    bar: &Pass<'_>,
    keep: impl Fn(usize, usize, f32) -> bool + Sync,
) -> Vec<f64> {
    (0..pts.len())
        .into_par_iter()
        .map(|bi| {
            let mut s = 0.0f64;
            for (ai, (col, _)) in cols.iter().enumerate() {
                if keep(ai, bi, dist(&pts[ai], &pts[bi])) {
                    s += col[bi];
                }
            }
            bar.advance(1);
            s
        })
        .collect()
}

/// The counters of a pass that imaged one column per focus: the rows and samples of the pass
/// (the same for every focus) and the aliased pairs of all foci together.
fn summed_reports(cols: &[(Vec<f64>, Report)]) -> Report {
    let aliased = cols.iter().map(|(_, r)| r.aliased).sum();
    cols.last()
        .map_or_else(Report::default, |(_, r)| Report { aliased, ..*r })
}

/// One higher-order column (Eq. 18) per focus, each over `foci` itself, in one pass over the
/// capture (element-wise kernel probes, pushed in parallel; state `2(K + Nt + 1)` f64 each).
fn higher_order_columns(
    src: &mut dyn RowSource,
    job: Job<'_>,
    foci: &[Point],
    label: &str,
) -> Result<Vec<(Vec<f64>, Report)>> {
    let cfg = job.cfg;
    let ks = src.geometry().spads_per_row();
    let n_state = Probe::state_len(
        cfg,
        Target::Column(foci[0]),
        Gate::HigherOrder,
        foci.len(),
        ks,
    );
    let mut states: Vec<Vec<f64>> = foci.iter().map(|_| vec![0.0; n_state]).collect();
    let probes = drive_probes(
        src,
        job,
        label,
        states.iter_mut().map(Vec::as_mut_slice),
        |scan, k, s| Probe::new(scan, Target::Column(foci[k]), Gate::HigherOrder, foci, s),
    )?;
    let g = src.geometry().clone();
    let mut tables = vec![0.0f32; Scan::tables_len(cfg, ks)];
    let scan = Scan::new(cfg, &g.spads, &mut tables)?;
    probes
        .par_iter()
        .map(|p| {
            let mut out = vec![0.0f64; foci.len()];
            let r = p.finish(&scan, &mut out)?;
            Ok((out, r))
        })
        .collect()
}

/// Pass 2's sum from the accumulated Γ columns: `I_i(b) = Σ_{a∈Γ, a≠b, r0≤|a−b|<r1} T(a, b)`
/// over the Γ points `pts` (at volume indices `idx`), as a volume of `n` voxels, with the
/// counters of all columns (aliased pairs summed over the foci); the columns and the pair
/// sums go to `exec`'s progress.
#[allow(clippy::too_many_arguments)]
pub(super) fn indirect_sum(
    cols: &mut Columns,
    cfg: &vltm_kernel::Config,
    spads: &[Point],
    pts: &[Point],
    idx: &[usize],
    shell: Shell,
    n: usize,
    exec: Exec<'_>,
) -> Result<(Vec<f32>, Report)> {
    let mut values = vec![0.0f32; n];
    let mut report = Report::default();
    if pts.is_empty() {
        return Ok((values, report));
    }
    let imaged = cols.image(cfg, spads, pts, Gate::Gaussian, pts, exec, "indirect")?;
    report = summed_reports(&imaged);
    let bar = Pass::start(exec, "indirect: pair sums", pts.len());
    let sum = pair_sum(&imaged, pts, &bar, |ai, bi, d| {
        ai != bi && shell.contains(d)
    });
    for (&i, s) in idx.iter().zip(sum) {
        values[i] = s as f32;
    }
    Ok((values, report))
}

/// The fit for a single column (`vltm column --leak-correct`): pass 1 the diagonal over
/// `volume`, Γ = {I_d > ε·max}, then [`DirectModel::fit`] over Γ. Reads the source twice.
///
/// # Errors
/// ε out of range (`--leak-epsilon`), as [`DirectModel::fit`] (an empty Γ names
/// `--leak-correct`), configuration and read errors.
pub fn fit_over_volume(
    src: &mut dyn RowSource,
    volume: &Volume,
    epsilon: f32,
    wave: &Wave,
    opts: &LeakOptions,
    exec: Exec<'_>,
) -> Result<DirectModel> {
    wave.refuse_cosine("the leak fit")?;
    let (gamma, _) = Gamma::measure(src, volume, epsilon, "leak_epsilon", wave, exec)?;
    fit_over_gamma(src, volume, &gamma.mask, wave, opts, exec)
}

/// The windows [`indirect`] zeroes before its pair sums (`opts.leak`), over a Γ `gamma` of
/// `volume` ([`DirectModel::fit`], one pass over `src`), for a caller that must see them first
/// (the command line's `--leak-correct auto` reads their [`DirectModel::adjacency`]).
///
/// # Errors
/// As [`DirectModel::fit`].
pub fn fit_over_gamma(
    src: &mut dyn RowSource,
    volume: &Volume,
    gamma: &[bool],
    wave: &Wave,
    opts: &LeakOptions,
    exec: Exec<'_>,
) -> Result<DirectModel> {
    let pts = super::gamma::gamma_points(volume, gamma);
    DirectModel::fit(src, &pts, cell_radius(volume), wave, opts, exec)
}
